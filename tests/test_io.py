"""Run outputs: atomic writes, writable folders, RunWriter (incl. interruption), read_tracks, versions."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from wptrack.core.errors import OutputError, WptrackError
from wptrack.io.atomic import (
    atomic_file,
    atomic_save_npz,
    atomic_write_json,
    atomic_write_text,
    ensure_writable_dir,
    ensure_writable_file,
)
from wptrack.io.run import RunWriter, versions
from wptrack.io.tables import read_tracks

COLUMNS = ["frame", "id", "x", "y", "z", "sx", "sy", "sz", "label"]


def _row(frame: int, tid: int = 0) -> tuple:
    return (frame, tid, 0.1 * frame, -1.25, np.float32(2.5), 1e-7, float("nan"), 3, "ball")


# ------------------------------------------------------------------------------------------ atomic writes


def test_atomic_writes_leave_no_temp_files(tmp_path):
    atomic_write_text(tmp_path / "a.txt", "hello\n")
    atomic_write_text(tmp_path / "a.txt", "replaced\n")
    atomic_write_json(tmp_path / "b.json", {"x": np.float32(1.5), "n": np.int64(3), "bad": float("nan"), "p": tmp_path})
    atomic_save_npz(tmp_path / "c.npz", a=np.arange(3), b=np.ones((2, 2), np.float32))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.json", "c.npz"]
    assert (tmp_path / "a.txt").read_text() == "replaced\n"
    assert json.loads((tmp_path / "b.json").read_text()) == {"x": 1.5, "n": 3, "bad": None, "p": str(tmp_path)}
    with np.load(tmp_path / "c.npz") as z:
        np.testing.assert_array_equal(z["a"], np.arange(3))
        assert z["b"].dtype == np.float32


def test_atomic_write_failure_keeps_old_file(tmp_path):
    atomic_write_json(tmp_path / "b.json", {"ok": 1})
    with pytest.raises(KeyboardInterrupt):
        with atomic_file(tmp_path / "b.json") as f:  # interrupted in the middle of a write
            f.write(b'{"half":')
            raise KeyboardInterrupt
    assert json.loads((tmp_path / "b.json").read_text()) == {"ok": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.json"]


# ------------------------------------------------------------------------------------------ output folders


def test_ensure_writable_dir_creates_parents(tmp_path):
    out = ensure_writable_dir(tmp_path / "a" / "b")
    assert out.is_dir() and list(out.iterdir()) == []


def test_ensure_writable_dir_on_file(tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("x")
    with pytest.raises(OutputError, match="not writable") as err:
        ensure_writable_dir(f)
    assert str(f) in str(err.value)
    with pytest.raises(OutputError, match="not writable") as err:
        ensure_writable_dir(f / "sub" / "dir")
    assert str(f / "sub" / "dir") in str(err.value)


def test_ensure_writable_file(tmp_path):
    """An output file's folder is created; a folder or a path under a file is an OutputError naming the path."""
    from wptrack.core.errors import OutputError

    target = ensure_writable_file(tmp_path / "a" / "b" / "out.json")
    assert target.parent.is_dir() and not target.exists()
    with pytest.raises(OutputError, match="is a folder"):
        ensure_writable_file(tmp_path / "a")
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(OutputError, match="not writable"):
        ensure_writable_file(f / "out.json")


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root ignores directory permissions")
def test_ensure_writable_dir_read_only(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(OutputError, match="not writable"):
            ensure_writable_dir(ro)
        with pytest.raises(OutputError, match="not writable"):
            ensure_writable_dir(ro / "sub")
    finally:
        ro.chmod(0o700)


# ------------------------------------------------------------------------------------------ RunWriter


def test_run_writer_complete(tmp_path, rng):
    config = {"particles": 500, "sigma": np.float64(0.01), "cams": ("a", "b")}
    with RunWriter(tmp_path / "run", "pf", COLUMNS, config, particles_every=2, particles_max=100) as rw:
        run = json.loads((tmp_path / "run" / "run.json").read_text())
        assert run["status"] == "running" and run["tracker"] == "pf" and run["config"]["cams"] == ["a", "b"]
        assert set(run["versions"]) == {"wptrack", "warp", "numpy", "cv2", "python"}
        rw.set_info(device="cpu", seed=7)
        for frame in range(4):
            rw.add_rows([_row(frame, 0), _row(frame, 1)])
            rw.add_particles(
                frame, rng.normal(size=(300 if frame == 0 else 50, 3)), rng.random(300 if frame == 0 else 50)
            )
            rw.add_timing("step", 0.001 * (frame + 1))
        rw.add_timing("load", 0.5)
    lines = (tmp_path / "run" / "tracks.csv").read_text().splitlines()
    assert lines[0] == ",".join(COLUMNS)
    assert len(lines) == 9
    assert lines[4] == "1,1,0.100000,-1.250000,2.500000,0.000000,nan,3,ball"

    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["status"] == "complete" and run["finished"] and run["started"]
    assert (run["frames"], run["rows"], run["device"], run["seed"]) == (4, 8, "cpu", 7)
    step = run["timings"]["step"]
    assert step["count"] == 4
    assert step["total_s"] == pytest.approx(0.010)
    assert step["mean_ms"] == pytest.approx(2.5)
    assert step["median_ms"] == pytest.approx(2.5)
    assert run["timings"]["load"] == {"total_s": 0.5, "count": 1, "mean_ms": 500.0, "median_ms": 500.0}

    with np.load(tmp_path / "run" / "particles.npz") as z:
        np.testing.assert_array_equal(z["frames"], [0, 2])
        assert z["frames"].dtype == np.int32
        assert z["positions"].shape == (2, 100, 3) and z["positions"].dtype == np.float32
        assert z["weights"].shape == (2, 100) and z["weights"].dtype == np.float32
        assert np.isfinite(z["positions"][0]).all()  # 300 subsampled to 100
        assert np.isfinite(z["positions"][1, :50]).all() and np.isnan(z["positions"][1, 50:]).all()  # padded
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["particles.npz", "run.json", "tracks.csv"]


def test_run_writer_interrupted_leaves_partial_results(tmp_path, rng):
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        with RunWriter(out, "pf", COLUMNS[:5], {"n": 1}, flush_seconds=3600) as rw:
            for frame in range(3):
                rw.add_rows([(frame, 0, 1.0, 2.0, 3.0)])
                rw.add_particles(frame, rng.normal(size=(20, 3)).astype(np.float32))
            raise KeyboardInterrupt
    tracks = read_tracks(out / "tracks.csv")
    np.testing.assert_array_equal(tracks["frame"], [0, 1, 2])
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "interrupted" and run["frames"] == 3
    with np.load(out / "particles.npz") as z:
        assert z["positions"].shape == (3, 20, 3)
        np.testing.assert_allclose(z["weights"], 1 / 20)
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_run_writer_failed_and_idempotent_close(tmp_path):
    out = tmp_path / "run"
    with pytest.raises(RuntimeError, match="boom"):
        with RunWriter(out, "pf", COLUMNS[:5], {}) as rw:
            rw.add_rows([(0, 0, 1.0, 2.0, 3.0)])
            raise RuntimeError("boom")
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "failed" and "boom" in run["error"]
    rw.close("complete")  # already closed: no change
    assert json.loads((out / "run.json").read_text())["status"] == "failed"
    assert not (out / "particles.npz").exists()
    with pytest.raises(RuntimeError):
        rw.add_rows([(1, 0, 1.0, 2.0, 3.0)])


def test_rows_are_on_disk_before_close(tmp_path):
    rw = RunWriter(tmp_path, "pf", COLUMNS[:5], {}, flush_seconds=3600)
    rw.add_rows([(0, 0, 1.0, 2.0, 3.0), (0, 1, 4.0, 5.0, 6.0)])
    assert (tmp_path / "tracks.csv").read_text().count("\n") == 3
    rw.close(summary={"lost": 0})
    assert json.loads((tmp_path / "run.json").read_text())["summary"] == {"lost": 0}


def test_run_writer_bad_input(tmp_path):
    with pytest.raises(ValueError):
        RunWriter(tmp_path, "pf", ["id", "frame", "x", "y", "z"], {})
    rw = RunWriter(tmp_path, "pf", COLUMNS[:5], {})
    with pytest.raises(ValueError):
        rw.add_rows([(0, 0, 1.0)])
    with pytest.raises(ValueError):
        rw.add_particles(0, np.zeros((4, 2)))
    with pytest.raises(ValueError):
        rw.set_info(status="x")
    rw.close()
    with pytest.raises(OutputError):
        RunWriter(tmp_path / "tracks.csv", "pf", COLUMNS[:5], {})


# ------------------------------------------------------------------------------------------ read_tracks


def test_read_tracks_round_trip(tmp_path):
    rows = [(f, i, 0.5 * f, -0.25 * i, 1.0 + f, "a,b" if i else "plain") for f in range(3) for i in range(2)]
    with RunWriter(tmp_path, "pf", [*COLUMNS[:5], "tag"], {}) as rw:
        rw.add_rows(rows)
    tracks = read_tracks(tmp_path / "tracks.csv")
    assert list(tracks) == ["frame", "id", "x", "y", "z", "tag"]
    assert tracks["frame"].dtype == np.int64 and tracks["id"].dtype == np.int64
    assert tracks["x"].dtype == np.float64
    np.testing.assert_array_equal(tracks["frame"], [r[0] for r in rows])
    np.testing.assert_allclose(tracks["y"], [r[3] for r in rows])
    assert tracks["tag"].tolist() == [r[5] for r in rows]


def test_read_tracks_groundtruth_and_partial_line(tmp_path):
    gt = tmp_path / "groundtruth.csv"
    gt.write_text("# comment\nframe, id, x, y, z, t\n0,0,1,2,3,\n1,0,1.5,2,3,0.04\n2,0,1.7")
    tracks = read_tracks(gt)
    np.testing.assert_array_equal(tracks["frame"], [0, 1])
    assert tracks["x"].dtype == np.float64  # mixed int/float -> float
    assert np.isnan(tracks["t"][0]) and tracks["t"][1] == pytest.approx(0.04)
    (tmp_path / "h.csv").write_text("frame,id,x,y,z\n")
    assert read_tracks(tmp_path / "h.csv")["frame"].shape == (0,)
    (tmp_path / "bad.csv").write_text("frame,id,x,y,z\n0,0,1\n1,0,1,2,3\n")
    with pytest.raises(WptrackError, match="line 2"):
        read_tracks(tmp_path / "bad.csv")
    with pytest.raises(WptrackError, match="not found"):
        read_tracks(tmp_path / "missing.csv")


def test_versions():
    v = versions()
    assert set(v) == {"wptrack", "warp", "numpy", "cv2", "python"}
    assert v["numpy"] == np.__version__ and v["python"]


def test_periodic_flush_while_running(tmp_path, rng):
    rw = RunWriter(tmp_path, "pf", COLUMNS[:5], {}, flush_seconds=0)
    rw.add_rows([(0, 0, 1.0, 2.0, 3.0)])
    rw.add_particles(0, rng.normal(size=(5, 3)))
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["status"] == "running" and run["frames"] == 1 and run["files"]["particles"] == "particles.npz"
    with np.load(tmp_path / "particles.npz") as z:
        assert z["positions"].shape == (1, 5, 3)
    rw.close()


def test_complete_run_leaves_short_tracks_out(tmp_path):
    """RunWriter.close('complete', min_track_frames=3): tracks.csv keeps the tracks with >= 3 rows or reported in the
    last frame (every row of them, from their first frame, in the original order), tracks_all.csv every row, run.json
    the count left out; an interrupted run keeps every track in tracks.csv and writes no tracks_all.csv."""
    # 1 and 4 are short; 3 is short but still there at the end (frame 9); 12 must not be taken for 1
    lives = {0: range(0, 10), 1: range(2, 4), 2: range(5, 8), 3: range(8, 10), 4: range(6, 7), 12: range(0, 3)}
    rows = [(f, t, 1.0, 2.0, 3.0) for f in range(10) for t in sorted(lives) if f in lives[t]]
    out = tmp_path / "done"
    with RunWriter(out, "pf", COLUMNS[:5], {}) as rw:
        rw.add_rows(rows)
        rw.close("complete", {"n": 1}, min_track_frames=3)
    kept = read_tracks(out / "tracks.csv")
    everything = read_tracks(out / "tracks_all.csv")
    assert sorted(set(kept["id"].tolist())) == [0, 2, 3, 12]
    expect = [r for r in rows if len(lives[r[1]]) >= 3 or lives[r[1]][-1] == 9]
    np.testing.assert_array_equal(kept["frame"], [r[0] for r in expect])
    np.testing.assert_array_equal(kept["id"], [r[1] for r in expect])
    np.testing.assert_array_equal(everything["id"], [r[1] for r in rows])
    run = json.loads((out / "run.json").read_text())
    assert (run["status"], run["min_track_frames"], run["short_tracks_dropped"]) == ("complete", 3, 2)
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]

    stopped = tmp_path / "stopped"
    with RunWriter(stopped, "pf", COLUMNS[:5], {}) as rw:
        rw.add_rows(rows)
        rw.close("interrupted", min_track_frames=3)
    np.testing.assert_array_equal(read_tracks(stopped / "tracks.csv")["id"], [r[1] for r in rows])
    assert not (stopped / "tracks_all.csv").exists()


def test_drop_short_tracks_needs_an_id_column(tmp_path):
    """A tracks file without an id column is refused by name, and left as it was."""
    from wptrack.io.tables import drop_short_tracks

    path = tmp_path / "t.csv"
    path.write_text("frame,x\n0,1.0\n")
    with pytest.raises(OutputError, match="no 'frame' and 'id' columns"):
        drop_short_tracks(path, tmp_path / "all.csv", 2)
    assert path.read_text() == "frame,x\n0,1.0\n" and not (tmp_path / "all.csv").exists()


def test_short_tracks_left_in_when_the_filter_cannot_write(tmp_path):
    """A completed run whose tracks_all.csv cannot be written keeps every row in tracks.csv, completes, and says why
    in run.json; no temporary file is left."""
    out = tmp_path / "run"
    rows = [(f, t, 1.0, 2.0, 3.0) for f in range(6) for t in (0, 1) if t == 0 or f < 2]
    with RunWriter(out, "pf", COLUMNS[:5], {}) as rw:
        rw.add_rows(rows)
        (out / "tracks_all.csv").mkdir()  # a folder in the way
        rw.close("complete", min_track_frames=3)
    np.testing.assert_array_equal(read_tracks(out / "tracks.csv")["id"], [r[1] for r in rows])
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "complete" and run["min_track_frames"] == 3 and "short_tracks_dropped" not in run
    assert "tracks_all.csv" in run["short_tracks_error"]
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


def test_new_run_removes_an_earlier_runs_tracks_all(tmp_path):
    """A new run in a folder that holds an earlier run's tracks_all.csv removes it (it is not this run's)."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "tracks_all.csv").write_text("frame,id,x,y,z\n0,5,1,2,3\n")
    with RunWriter(out, "pf", COLUMNS[:5], {}) as rw:
        rw.add_rows([(0, 0, 1.0, 2.0, 3.0)])
        rw.close("complete")  # min_track_frames 1: no filter, no tracks_all.csv
    assert not (out / "tracks_all.csv").exists()


def test_atomic_path_commits_on_success_and_leaves_the_target_on_failure(tmp_path):
    from wptrack.io.atomic import atomic_path

    target = tmp_path / "cam.yml"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".yml" and tmp != target
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert target.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["cam.yml"]
    with atomic_path(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new" and sorted(p.name for p in tmp_path.iterdir()) == ["cam.yml"]


def test_csv_appender_writes_the_one_cell_format(tmp_path):
    from wptrack.io.tables import CsvAppender, read_tracks

    path = tmp_path / "best.csv"
    w = CsvAppender(path, ["frame", "id", "x", "cls"])
    w.add([[0, 3, 0.1234567891, "human"], [1, 3, float("nan"), "vehicle"]])
    w.close()
    assert path.read_text() == "frame,id,x,cls\n0,3,0.123457,human\n1,3,nan,vehicle\n"
    w = CsvAppender(path, ["frame", "id", "x", "cls"], append=True)
    w.add([[2, 4, np.float32(1.5), "human"]])
    w.close()
    assert read_tracks(path)["x"][2] == 1.5 and path.read_text().endswith("2,4,1.500000,human\n")


@pytest.mark.parametrize(
    ("value", "cell"),
    [
        (0.1234567891, "0.123457"),
        (np.float32(1.5), "1.500000"),
        (np.float64(-2.0000004), "-2.000000"),
        (-0.0, "-0.000000"),
        (1e20, "100000000000000000000.000000"),
        (float("nan"), "nan"),
        (np.float32("nan"), "nan"),
        (np.float64("inf"), "inf"),
        (-math.inf, "-inf"),
        (np.array(2.5), "2.500000"),
        (np.array(np.float32("-inf")), "-inf"),
        (7, "7"),
        (np.int64(-3), "-3"),
        (True, "1"),
        (np.bool_(False), "0"),
        (None, ""),
        ("human", "human"),
    ],
)
def test_format_cell_each_type(value, cell):
    """The one cell format of every CSV the runs write (the float fast path included: most cells of a run)."""
    from wptrack.io.tables import format_cell

    assert format_cell(value) == cell


def test_format_cell_refuses_line_breaks():
    from wptrack.io.tables import format_cell

    with pytest.raises(ValueError, match="line breaks"):
        format_cell("a\nb")
