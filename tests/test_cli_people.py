"""`wptrack track people` end to end on small videos written to disk: outputs (tracks.csv, hulls/, occupancy.npz,
run.json), evaluation, resume, and bad input (one camera, masks of the wrong size, camera count) with one-line
errors, exit code 2 and nothing written."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from wptrack.cameras.rig import Rig
from wptrack.cli import main
from wptrack.io.chunklog import read_chunks
from wptrack.io.tables import read_tracks
from wptrack.io.video import write_video

sys.path.insert(0, str(Path(__file__).parent))
from test_tracker_people import COLOURS, render, rig3  # noqa: E402


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """Two people walking towards each other (60 frames, 160x120, 3 cameras), videos + masks + rig + truth."""
    root = tmp_path_factory.mktemp("people")
    rig = rig3()
    rig.save(root / "rig.yaml")
    rng = np.random.default_rng(0)
    frames, masks, truth = [[], [], []], [[], [], []], []
    for t in range(60):
        people = [] if t < 3 else [(np.array([0.6 + 0.05 * (t - 3), 1.65]), COLOURS[0])]
        if t >= 3:
            people.append((np.array([3.4 - 0.05 * (t - 3), 2.35]), COLOURS[1]))
        images, ms = render(rig, people, rng)
        for k in range(3):
            frames[k].append(images[k])
            masks[k].append(np.repeat(ms[k][..., None], 3, axis=2))
        truth += [(t, i, xy[0], xy[1], 0.85) for i, (xy, _) in enumerate(people)]
    for k in range(3):
        write_video(root / f"cam{k}.avi", frames[k], fps=25)
        write_video(root / f"mask{k}.avi", masks[k], fps=25)
    lines = ["frame,id,x,y,z"] + [f"{f},{i},{x:.4f},{y:.4f},{z:.4f}" for f, i, x, y, z in truth]
    (root / "groundtruth.csv").write_text("\n".join(lines) + "\n")
    return root


def _args(scene, out, masks=True, cams=(0, 1, 2)):
    argv = ["track", "people", "--rig", str(scene / "rig.yaml"), "--out", str(out), "--device", "cpu", "-q"]
    for k in cams:
        argv += ["--video", str(scene / f"cam{k}.avi")]
    if masks:
        for k in cams:
            argv += ["--masks", str(scene / f"mask{k}.avi")]
    return argv + ["--particles", "300"]


def test_track_people_writes_outputs(scene, tmp_path, capsys):
    out = tmp_path / "run"
    pytest.importorskip("motmetrics")  # --groundtruth scores the run
    assert main([*_args(scene, out), "--groundtruth", str(scene / "groundtruth.csv"), "--occupancy-every", "5"]) == 0
    text = capsys.readouterr().out
    assert "2 people" in text and "MOTA" in text
    t = read_tracks(out / "tracks.csv")
    assert list(t)[:5] == ["frame", "id", "x", "y", "z"] and {"cloud_z", "top", "degenerate"} <= set(t)
    assert (t["degenerate"] == 0).all()
    assert set(np.unique(t["id"])) == {0, 1}
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "complete" and run["tracker"] == "people" and run["summary"]["people"] == 2
    assert run["summary"]["degenerate_estimates"] == 0 and run["stopped_early"] is None
    idx, verts = read_chunks(out / "hulls")
    assert len(idx) == len(t["frame"]) and verts.shape[1] == 3 and (idx[:, 3] >= 4).all()
    # each hull lies around its person's centroid
    for frame, pid, start, count in idx[-4:]:
        c = verts[start : start + count].mean(0)
        row = (t["frame"] == frame) & (t["id"] == pid)
        assert np.hypot(c[0] - t["x"][row][0], c[1] - t["y"][row][0]) < 0.3
    with np.load(out / "occupancy.npz") as z:
        assert len(z["index"]) == len(z["grid"]) > 0 and set(z["index"][:, 0] % 5) == {0}
        assert z["grid"].dtype == np.float16 and float(z["voxel"]) > 0


def test_resume_of_a_complete_people_run_is_refused(scene, tmp_path):
    full, cut = tmp_path / "full", tmp_path / "cut"
    assert main(_args(scene, full)) == 0
    assert main([*_args(scene, cut), "--max-frames", "30"]) == 0  # a completed run (shorter) cannot be resumed
    assert main([*_args(scene, cut), "--resume"]) == 2


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("one_camera", "two or more"),
        ("wrong_mask_size", "size"),
        ("camera_count", "video(s) given for a rig of 3"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(scene, tmp_path, capsys, change, message):
    out = tmp_path / "bad"
    if change == "one_camera":
        rig = Rig.load(scene / "rig.yaml")
        Rig(rig.cameras[:1], volume=rig.volume).save(tmp_path / "one.yaml")
        argv = ["track", "people", "--rig", str(tmp_path / "one.yaml"), "--video", str(scene / "cam0.avi")]
        argv += ["--out", str(out), "--device", "cpu", "-q"]
    elif change == "wrong_mask_size":
        small = [np.zeros((60, 80, 3), np.uint8)] * 60
        write_video(tmp_path / "small.avi", small, fps=25)
        argv = _args(scene, out, masks=False) + [
            "--masks",
            str(scene / "mask0.avi"),
            "--masks",
            str(scene / "mask1.avi"),
        ]
        argv += ["--masks", str(tmp_path / "small.avi")]
    else:
        argv = _args(scene, out, masks=False, cams=(0, 1))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("wptrack: error:") and message in err and "Traceback" not in err
    assert not out.exists()
