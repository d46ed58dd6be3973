"""Offline backfill of completed tracks (``wptrack.trackers.templates.backfill``,
``TemplateConfig.backfill_seconds``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wptrack.core.errors import ConfigError, OutputError
from wptrack.trackers.templates.backfill import backfill_rows, backfill_tracks_file, stitch_tracks_file
from wptrack.trackers.templates.tracker import TemplateConfig

HEADER = "frame,id,x,y,z,class,length,width,height,orientation,speed,existence,gx,gy,sx,sy,degenerate"


def _to_world(g: np.ndarray) -> np.ndarray:
    return np.concatenate([g, np.zeros((len(g), 1))], axis=1)


def _always(ground, size, heading):
    return np.ones(len(ground), dtype=bool)


def _table(tracks: dict[int, tuple[int, int, tuple[float, float], tuple[float, float], float]]) -> dict:
    """Rows of straight tracks: id -> (first frame, rows, start ground point, velocity per frame, length)."""
    rows = []
    for tid, (f0, n, p0, v, length) in tracks.items():
        for k in range(n):
            g = (p0[0] + v[0] * k, p0[1] + v[1] * k)
            rows.append((f0 + k, tid, g[0], g[1], length))
    rows.sort(key=lambda r: (r[0], r[1]))
    a = np.array(rows, dtype=np.float64)
    n = len(a)
    return {
        "frame": a[:, 0].astype(np.int64),
        "id": a[:, 1].astype(np.int64),
        "x": a[:, 2],
        "y": a[:, 3],
        "z": np.zeros(n),
        "class": np.array(["human"] * n, dtype=object),
        "length": a[:, 4],
        "width": a[:, 4],
        "height": np.full(n, 1.7),
        "orientation": np.full(n, 0.3),
        "speed": np.full(n, 9.0),
        "existence": np.full(n, 0.9),
        "gx": a[:, 2],
        "gy": a[:, 3],
        "sx": np.full(n, 0.05),
        "sy": np.full(n, 0.05),
        "degenerate": np.zeros(n, dtype=np.int64),
    }


def test_a_straight_track_is_extended_on_its_line():
    # a track first reported at frame 10 (frames 0-39 in the run), moving 0.1 m/frame along x: 10 rows before it
    t = _table({1: (10, 30, (5.0, 2.0), (0.1, 0.0), 0.4), 2: (0, 40, (-20.0, 0.0), (0.0, 0.0), 0.4)})
    added, src = backfill_rows(t, _to_world, _always, frames=20, min_rows=15, fps=15.0)
    assert added["frame"].tolist() == list(range(9, -1, -1))  # stops at the run's first frame
    np.testing.assert_allclose(added["gx"], 5.0 - 0.1 * np.arange(1, 11), atol=1e-9)
    np.testing.assert_allclose(added["gy"], 2.0, atol=1e-9)
    np.testing.assert_allclose(
        np.c_[added["x"], added["y"], added["z"]], np.c_[added["gx"], added["gy"], 0 * added["gx"]]
    )
    np.testing.assert_allclose(added["speed"], 0.1 * 15.0)  # m/frame x fps
    assert np.all(added["existence"] == 0) and np.all(added["id"] == 1) and set(added["class"]) == {"human"}
    assert np.all(t["id"][src] == 1) and np.all(t["frame"][src] == 10)  # copied from the track's first row
    # horizon
    added, _ = backfill_rows(t, _to_world, _always, frames=4, min_rows=15)
    assert added["frame"].tolist() == [9, 8, 7, 6]


def test_short_tracks_and_zero_frames_add_nothing():
    t = _table({1: (10, 14, (5.0, 2.0), (0.1, 0.0), 0.4), 2: (0, 40, (-20.0, 0.0), (0.0, 0.0), 0.4)})
    added, src = backfill_rows(t, _to_world, _always, frames=20, min_rows=15)
    assert len(added["frame"]) == 0 and len(src) == 0 and set(added) == set(t)
    added, _ = backfill_rows(t, _to_world, _always, frames=20, min_rows=14)
    assert len(added["frame"]) == 10
    added, _ = backfill_rows(t, _to_world, _always, frames=0, min_rows=1)
    assert len(added["frame"]) == 0


def test_backfill_stops_where_the_object_leaves_the_view():
    t = _table({1: (10, 30, (5.0, 2.0), (0.1, 0.0), 0.4), 2: (0, 40, (-20.0, 0.0), (0.0, 0.0), 0.4)})

    def right_half(ground, size, heading):  # the view ends at x = 4.45 m
        assert size.shape == (len(ground), 3) and np.allclose(size, [0.4, 0.4, 1.7]) and np.allclose(heading, 0.3)
        return ground[:, 0] >= 4.45

    added, _ = backfill_rows(t, _to_world, right_half, frames=20, min_rows=15)
    np.testing.assert_allclose(added["gx"], [4.9, 4.8, 4.7, 4.6, 4.5])


def test_backfill_stops_on_another_track_and_on_footprints():
    # track 1 came back along y = 2 at 0.1 m/frame from x = 6.0 (frame 10); track 2 stood at x = 5.0 in frames 0-6:
    # frame 6 would put track 1 at 5.6 m, 0.6 m from track 2 (guard 1 m)
    t = _table({1: (10, 30, (6.0, 2.0), (0.1, 0.0), 0.4), 2: (0, 7, (5.0, 2.0), (0.0, 0.0), 0.4)})
    added, _ = backfill_rows(t, _to_world, _always, frames=20, min_rows=15)
    assert added["frame"].tolist() == [9, 8, 7]
    # a car (length 4.4 m) and a person standing at x = 3.05: the guard is (4.4 + 0.4) / 2 = 2.4 m, reached at frame 4
    # (5.4 - 3.05 = 2.35 m); with the 1 m guard alone the car would be extended to frame 0
    t = _table({1: (10, 30, (6.0, 2.0), (0.1, 0.0), 4.4), 2: (0, 40, (3.05, 2.0), (0.0, 0.0), 0.4)})
    added, _ = backfill_rows(t, _to_world, _always, frames=20, min_rows=15)
    assert added["frame"].tolist() == [9, 8, 7, 6, 5]
    added, _ = backfill_rows(t, _to_world, _always, frames=20, min_rows=15, guard=2.5)
    assert added["frame"].tolist() == [9, 8, 7, 6]  # 5.5 - 3.05 = 2.45 m < 2.5 m


def test_backfilled_rows_guard_each_other():
    # two tracks first reported at frame 10, 0.5 m apart: nothing before the run's first frame
    t = _table({1: (10, 30, (6.0, 2.0), (0.1, 0.0), 0.4), 2: (10, 30, (6.0, 2.5), (0.1, 0.0), 0.4)})
    added, _ = backfill_rows(t, _to_world, _always, frames=20, min_rows=15)
    assert len(added["frame"]) == 0
    t = _table({
        1: (10, 30, (6.0, 2.0), (0.1, 0.0), 0.4),
        2: (10, 30, (6.0, 2.5), (0.1, 0.0), 0.4),
        3: (0, 40, (-20.0, 0.0), (0.0, 0.0), 0.4),
    })  # fmt: skip
    added, _ = backfill_rows(t, _to_world, _always, frames=20, min_rows=15)  # the first one (by id) is extended
    assert set(added["id"].tolist()) == {1} and len(added["frame"]) == 10


def test_backfill_tracks_file_keeps_every_line_and_the_frame_order(tmp_path):
    lines = [HEADER]
    for f in range(40):  # id 7 everywhere, id 3 from frame 10 on, moving 0.1 m/frame
        lines.append(f"{f},7,-20.000000,0.000000,0.000000,human,0.4,0.4,1.7,0.0,0.0,0.9,-20.000000,0.000000,0,0,0")
        if f >= 10:
            x = 6.0 + 0.1 * (f - 10)
            lines.append(f"{f},3,{x:.6f},2.000000,0.000000,human,0.4,0.4,1.7,0.3,1.5,0.8,{x:.6f},2.000000,0.1,0.1,0")
    path = tmp_path / "tracks.csv"
    path.write_text("\n".join(lines) + "\n")
    n = backfill_tracks_file(path, _to_world, _always, frames=4, min_rows=15, fps=15.0)
    assert n == 4
    out = path.read_text().splitlines()
    assert out[0] == HEADER and len(out) == len(lines) + 4
    old = [ln for ln in out if ln in lines]
    assert old == lines  # every old line, byte for byte, in its order
    frames = [int(ln.split(",")[0]) for ln in out[1:]]
    assert frames == sorted(frames)
    new = [ln.split(",") for ln in out if ln not in lines]
    assert [int(r[0]) for r in new] == [6, 7, 8, 9] and all(r[1] == "3" and r[11] == "0.000000" for r in new)
    assert [float(r[2]) for r in new] == pytest.approx([5.6, 5.7, 5.8, 5.9])
    assert not list(tmp_path.glob("*.tmp"))


def test_backfill_reaches_the_runs_first_frame(tmp_path):
    """A run's first frame has no row (the filter adds objects after a frame's estimate): with ``first_frame`` the
    tracks are extended down to it, rows and file alike, and never before it; without it the table's first frame
    bounds them (as before)."""
    t = _table({1: (1, 30, (6.0, 2.0), (0.1, 0.0), 0.4), 2: (3, 30, (-6.0, 2.0), (0.0, 0.1), 0.4)})
    added, _ = backfill_rows(t, _to_world, _always, frames=20, min_rows=15)
    assert added["frame"].tolist() == [2, 1]  # track 2 only, down to frame 1: the table's first frame
    added, _ = backfill_rows(t, _to_world, _always, frames=20, min_rows=15, first_frame=0)
    assert sorted(zip(added["id"].tolist(), added["frame"].tolist(), strict=True)) == [(1, 0), (2, 0), (2, 1), (2, 2)]
    np.testing.assert_allclose(added["gx"][added["id"] == 1], [5.9])
    added, _ = backfill_rows(t, _to_world, _always, frames=2, min_rows=15, first_frame=0)
    assert sorted(zip(added["id"].tolist(), added["frame"].tolist(), strict=True)) == [(1, 0), (2, 1), (2, 2)]
    lines = [HEADER]
    for f in range(1, 30):
        x = 6.0 + 0.1 * (f - 1)
        lines.append(f"{f},3,{x:.6f},2.000000,0.000000,human,0.4,0.4,1.7,0.3,1.5,0.8,{x:.6f},2.000000,0.1,0.1,0")
    path = tmp_path / "tracks.csv"
    path.write_text("\n".join(lines) + "\n")
    assert backfill_tracks_file(path, _to_world, _always, frames=4, min_rows=15) == 0
    assert path.read_text().splitlines() == lines
    assert backfill_tracks_file(path, _to_world, _always, frames=4, min_rows=15, first_frame=0) == 1
    out = path.read_text().splitlines()
    assert out[0] == HEADER and out[2:] == lines[1:]
    row = out[1].split(",")
    assert row[0] == "0" and row[1] == "3" and float(row[2]) == pytest.approx(5.9)


def test_backfill_tracks_file_errors_name_the_file(tmp_path):
    path = tmp_path / "tracks.csv"
    path.write_text("frame,id,x,y\n0,1,0.0,0.0\n")
    with pytest.raises(OutputError, match=r"tracks\.csv: no z, gx, gy"):
        backfill_tracks_file(path, _to_world, _always, frames=4, min_rows=1)
    bad = HEADER + "\n0,1,0,0,0,human,0.4,0.4,1.7,0,0,1,a,0,0,0,0\n"
    path.write_text(bad)
    with pytest.raises(OutputError, match=r"tracks\.csv: column 'gx' holds a value that is not a number"):
        backfill_tracks_file(path, _to_world, _always, frames=4, min_rows=1)
    assert path.read_text() == bad  # left as it was
    row = "{},1,0,0,0,human,0.4,0.4,1.7,0,0,1,0,0,0,0,0"
    unordered = "\n".join([HEADER, row.format(5), row.format(3)]) + "\n"
    path.write_text(unordered)
    with pytest.raises(OutputError, match=r"tracks\.csv: rows are not in frame order \(frame 3 after 5\)"):
        backfill_tracks_file(path, _to_world, _always, frames=4, min_rows=1)
    assert path.read_text() == unordered and not list(tmp_path.glob("*.tmp"))
    path.write_text("")
    with pytest.raises(OutputError, match=r"tracks\.csv: empty file"):
        backfill_tracks_file(path, _to_world, _always, frames=4, min_rows=1)
    path.write_text(HEADER + "\n")  # no rows: nothing to do
    assert backfill_tracks_file(path, _to_world, _always, frames=4, min_rows=1) == 0


def test_config_backfill():
    c = TemplateConfig()
    assert c.backfill_frames == 20 and TemplateConfig(fps=7.0).backfill_frames == 9
    assert TemplateConfig(backfill_seconds=0).backfill_frames == 0
    assert c.stitch_frames == 30 and TemplateConfig(fps=10.0).stitch_frames == 20 and c.stitch_distance == 2.0
    with pytest.raises(ConfigError, match="stitch_distance"):
        TemplateConfig(stitch_distance=-0.5)
    assert c.to_dict()["backfill_seconds"] == 1.35 and "backfill_frames" not in c.to_dict()
    with pytest.raises(ConfigError, match="backfill_seconds"):
        TemplateConfig(backfill_seconds=-1)
    with pytest.raises(ConfigError, match="backfill_min_frames"):
        TemplateConfig(backfill_min_frames=0)


def test_a_completed_template_run_is_backfilled(tmp_path, capsys):
    """The run loop backfills tracks.csv when the run completes; tracks_all.csv keeps the tracker's rows."""
    pytest.importorskip("motmetrics")
    from wptrack.cli import main
    from wptrack.io.tables import read_tracks

    assert main(["synth", "s3-people", "--out", str(tmp_path / "scene"), "--frames", "30", "-q"]) == 0
    out = tmp_path / "run"
    args = [
        "track", "templates", "--rig", str(tmp_path / "scene/rig.yaml"),
        "--masks", str(tmp_path / "scene/cam0_mask.avi"),
        "--out", str(out), "--device", "cpu", "--particles", "200", "-q", "--backfill-min-frames", "8",
    ]  # fmt: skip
    assert main(args) == 0
    capsys.readouterr()
    run = json.loads((out / "run.json").read_text())
    kept, every = read_tracks(out / "tracks.csv"), read_tracks(out / "tracks_all.csv")
    filled = kept["existence"] == 0
    assert run["backfill_frames"] == 20 and run["backfill_min_frames"] == 8
    assert run["stitch_frames"] == 30 and run["stitch_distance"] == 2.0 and run["stitched_tracks"] >= 0
    assert run["backfilled_rows"] == int(filled.sum()) > 0  # the people entering the scene are first seen late
    assert not np.any(every["existence"] == 0)
    for tid in np.unique(kept["id"][filled]):  # backfilled rows come before the track's first own row
        own = every["frame"][every["id"] == tid]
        assert kept["frame"][filled & (kept["id"] == tid)].max() < own.min()
    # the run's first frame has no row of the tracker's own; the backfill reaches it (the people in view from the
    # start)
    assert every["frame"].min() > 0 and kept["frame"].min() == 0
    if run["stitched_tracks"] == 0:
        assert len(kept["frame"]) - int(filled.sum()) == int(np.isin(every["id"], kept["id"]).sum())


def test_run_writer_finish_tracks(tmp_path):
    """RunWriter.close('complete', finish_tracks=f): f gets tracks.csv after the short tracks are left out, its dict
    goes into run.json, tracks_all.csv holds the rows before it; an error leaves tracks.csv as it was and is
    recorded; an interrupted run does not call it."""
    from wptrack.io.run import RunWriter
    from wptrack.io.tables import read_tracks

    cols = ["frame", "id", "x", "y", "z"]
    rows = [(f, 1, 1.0, 2.0, 0.0) for f in range(5)]
    seen = []

    def finish(path):
        seen.append(read_tracks(path)["frame"].tolist())
        with open(path, "a", encoding="utf-8") as fh:
            fh.write("5,1,1.000000,2.000000,0.000000\n")
        return {"filled": 1}

    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "tracks_all.csv").write_text("frame,id\n99,99\n")  # a stale file from an earlier run
    for name, min_frames in (("a", 1), ("b", 3)):
        with RunWriter(tmp_path / name, "pf", cols, {}) as rw:
            rw.add_rows(rows)
            rw.close("complete", min_track_frames=min_frames, finish_tracks=finish)
        run = json.loads((tmp_path / name / "run.json").read_text())
        assert run["filled"] == 1 and seen[-1] == [0, 1, 2, 3, 4]
        assert read_tracks(tmp_path / name / "tracks.csv")["frame"].tolist() == [0, 1, 2, 3, 4, 5]
        assert read_tracks(tmp_path / name / "tracks_all.csv")["frame"].tolist() == [0, 1, 2, 3, 4]

    def broken(path):
        raise OutputError(f"{path}: no gx column")

    with RunWriter(tmp_path / "c", "pf", cols, {}) as rw:
        rw.add_rows(rows)
        rw.close("complete", finish_tracks=broken)
    run = json.loads((tmp_path / "c" / "run.json").read_text())
    assert "no gx column" in run["finish_tracks_error"] and run["status"] == "complete"
    assert read_tracks(tmp_path / "c" / "tracks.csv")["frame"].tolist() == [0, 1, 2, 3, 4]

    with RunWriter(tmp_path / "d", "pf", cols, {}) as rw:
        rw.add_rows(rows)
        rw.close("interrupted", finish_tracks=finish)
    assert len(seen) == 2 and not (tmp_path / "d" / "tracks_all.csv").exists()


def _write(path, rows):
    """rows: (frame, id, gx, gy, class) -> a tracks CSV in frame order."""
    lines = [HEADER]
    for f, tid, gx, gy, cls in sorted(rows, key=lambda r: (r[0], r[1])):
        lines.append(f"{f},{tid},{gx:.6f},{gy:.6f},0.000000,{cls},0.4,0.4,1.7,0.0,1.0,0.9,{gx:.6f},{gy:.6f},0,0,0")
    path.write_text("\n".join(lines) + "\n")
    return lines


def test_stitch_gives_a_continuing_track_its_predecessors_id(tmp_path):
    # id 4 walks along x at 0.1 m/frame in frames 0-19 and is lost; id 9 starts at frame 25 where 4 was heading
    # (2.5 m on, 0.3 m off its line); id 6 starts at frame 25 too, 3 m away; id 2 lasts to the last frame (frame 49)
    rows = [(f, 4, 0.1 * f, 0.0, "human") for f in range(20)]
    rows += [(f, 9, 0.1 * f, 0.3, "human") for f in range(25, 45)]
    rows += [(f, 6, 0.1 * f, 3.0, "human") for f in range(25, 40)]
    rows += [(f, 2, -10.0, 0.0, "human") for f in range(50)]
    path = tmp_path / "tracks.csv"
    lines = _write(path, rows)
    assert stitch_tracks_file(path, gap=10, distance=1.0) == 1
    out = path.read_text().splitlines()
    assert len(out) == len(lines) and out[0] == HEADER
    ids = [int(ln.split(",")[1]) for ln in out[1:]]
    frames = [int(ln.split(",")[0]) for ln in out[1:]]
    assert sorted(set(ids)) == [2, 4, 6] and frames == sorted(frames)
    assert [f for f, i in zip(frames, ids, strict=True) if i == 4] == list(range(20)) + list(range(25, 45))
    # the changed lines differ only in the id
    assert [ln.split(",", 2)[2] for ln in out[1:]] == [ln.split(",", 2)[2] for ln in lines[1:]]
    assert not list(tmp_path.glob("*.tmp"))


@pytest.mark.parametrize(
    "gap, distance, cls, expect",
    [
        (4, 1.0, "human", 0),  # 5 frames apart, over the gap
        (10, 0.2, "human", 0),  # 0.3 m off the line, over the distance
        (10, 1.0, "vehicle", 0),  # another class
        (0, 1.0, "human", 0),  # off
        (5, 1.0, "human", 1),
    ],
)
def test_stitch_limits(tmp_path, gap, distance, cls, expect):
    rows = [(f, 4, 0.1 * f, 0.0, "human") for f in range(20)] + [(f, 2, -10.0, 0.0, "human") for f in range(50)]
    rows += [(f, 9, 0.1 * f, 0.3, cls) for f in range(24, 45)]
    path = tmp_path / "tracks.csv"
    _write(path, rows)
    assert stitch_tracks_file(path, gap=gap, distance=distance) == expect


def test_stitch_nearest_first_and_chains(tmp_path):
    # two candidates for id 1's successor: 5 (0.5 m off) and 7 (0.2 m off): 7 wins, and 5 stays; 7 ends and 8
    # continues it: 8 takes id 1 too (a chain); a track ending in the last frame has no successor
    rows = [(f, 1, 0.1 * f, 0.0, "human") for f in range(10)]
    rows += [(f, 5, 0.1 * f, 0.5, "human") for f in range(12, 30)]
    rows += [(f, 7, 0.1 * f, 0.2, "human") for f in range(12, 20)]
    rows += [(f, 8, 0.1 * f, 0.2, "human") for f in range(22, 40)]
    path = tmp_path / "tracks.csv"
    _write(path, rows)
    assert stitch_tracks_file(path, gap=5, distance=1.0) == 2
    got = {}
    for ln in path.read_text().splitlines()[1:]:
        f, tid = (int(v) for v in ln.split(",")[:2])
        got.setdefault(tid, []).append(f)
    assert sorted(got) == [1, 5] and got[1] == list(range(10)) + list(range(12, 20)) + list(range(22, 40))


def test_stitch_errors_name_the_file(tmp_path):
    path = tmp_path / "tracks.csv"
    path.write_text("frame,id,x,y\n0,1,0.0,0.0\n")
    with pytest.raises(OutputError, match=r"tracks\.csv: no gx, gy column\(s\) to stitch"):
        stitch_tracks_file(path, gap=5, distance=1.0)
    row = "{},1,0,0,0,human,0.4,0.4,1.7,0,0,1,0,0,0,0,0"
    unordered = "\n".join([HEADER, row.format(5), row.format(3)]) + "\n"
    path.write_text(unordered)
    with pytest.raises(OutputError, match=r"not in frame order"):
        stitch_tracks_file(path, gap=5, distance=1.0)
    assert path.read_text() == unordered
    with pytest.raises(OutputError, match=r"cannot read .*missing\.csv"):
        stitch_tracks_file(tmp_path / "missing.csv", gap=5, distance=1.0)
