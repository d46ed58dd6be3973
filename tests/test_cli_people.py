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
    assert run["summary"]["births_refused"] == 0  # the pool (max_people 8) had room for both
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
        ("no_overlap", "see no common ground"),
        ("volume_outside", "outside every camera's view"),
        ("different_lengths", "different frame counts"),
        ("frame_size", "differs from camera 'c2' calibration"),
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
    elif change in ("no_overlap", "volume_outside"):
        from wptrack.cameras.rig import Camera

        rig = Rig.load(scene / "rig.yaml")
        if change == "no_overlap":  # each camera looks away from the others
            cams = tuple(
                Camera.look_at(c.name, c.width, c.height, c.center, c.center + [3 * dx, 3 * dy, -1.5], 90.0)
                for c, (dx, dy) in zip(rig.cameras, ((-1, 0), (1, 0), (0, 1)), strict=True)
            )
            bad = Rig(cams)
        else:
            bad = Rig(rig.cameras, volume=(np.array([40.0, 40.0, 0.0]), np.array([42.0, 42.0, 2.0])))
        bad.save(tmp_path / "bad.yaml")
        argv = _args(scene, out, masks=False)
        argv[argv.index("--rig") + 1] = str(tmp_path / "bad.yaml")
    elif change == "different_lengths":
        from wptrack.io.frames import open_source

        short = [f for i, f in enumerate(open_source(str(scene / "cam2.avi"))) if i < 50]
        write_video(tmp_path / "short.avi", short, fps=25)
        argv = _args(scene, out, masks=False, cams=(0, 1)) + ["--video", str(tmp_path / "short.avi")]
    elif change == "frame_size":
        write_video(tmp_path / "big.avi", [np.zeros((240, 300, 3), np.uint8)] * 60, fps=25)  # another aspect ratio
        argv = _args(scene, out, masks=False, cams=(0, 1)) + ["--video", str(tmp_path / "big.avi")]
    else:
        argv = _args(scene, out, masks=False, cams=(0, 1))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("wptrack: error:") and message in err and "Traceback" not in err
    assert not out.exists()


def test_person_removed_in_a_frame_with_occupancy_grids(scene, tmp_path):
    """The crash of issue 31: a person removed after a frame whose occupancy grids are written (everybody leaves
    while ``--occupancy-every 1`` asks for every frame's grids). The grids come with the frame's estimate, so
    every person of a frame has one, also the ones removed after it."""
    root = tmp_path / "leave"
    root.mkdir()
    rig = Rig.load(scene / "rig.yaml")
    rig.save(root / "rig.yaml")
    rng = np.random.default_rng(4)
    frames, masks = [[], [], []], [[], [], []]
    for t in range(40):
        people = [(np.array([0.6 + 0.05 * t, 1.65]), COLOURS[0]), (np.array([3.4 - 0.05 * t, 2.35]), COLOURS[1])]
        images, ms = render(rig, people if t < 20 else [], rng)  # everybody vanishes at frame 20
        for k in range(3):
            frames[k].append(images[k])
            masks[k].append(np.repeat(ms[k][..., None], 3, axis=2))
    for k in range(3):
        write_video(root / f"cam{k}.avi", frames[k], fps=25)
        write_video(root / f"mask{k}.avi", masks[k], fps=25)
    out = tmp_path / "run"
    assert main([*_args(root, out), "--occupancy-every", "1"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "complete" and run["summary"]["people"] == 2
    t = read_tracks(out / "tracks.csv")
    with np.load(out / "occupancy.npz") as z:
        index = {(int(f), int(i)) for f, i in z["index"]}
    rows = set(zip(t["frame"].tolist(), t["id"].tolist(), strict=True))
    assert index == rows  # one grid per (frame, person) row, the last frames of both people included
    assert max(f for f, _ in rows) >= 20  # they were still reported when the masks emptied, then removed


def test_internal_error_is_not_a_user_error_and_keeps_the_run(scene, tmp_path, capsys, monkeypatch):
    """A bug in the middle of a run: exit code 70 (not 2), the traceback and one 'internal error' line; the rows
    written so far stay readable and run.json says 'failed' with the reason."""
    from wptrack.cli import EXIT_INTERNAL
    from wptrack.trackers.people.tracker import PeopleTracker

    step = PeopleTracker.step

    def failing(self, images, masks, **kw):
        if self.frames_done == 25:
            raise RuntimeError("injected fault")
        return step(self, images, masks, **kw)

    monkeypatch.setattr(PeopleTracker, "step", failing)
    out = tmp_path / "run"
    assert main(_args(scene, out)) == EXIT_INTERNAL != 2
    err = capsys.readouterr().err
    assert "Traceback" in err and "wptrack: internal error: RuntimeError: injected fault" in err
    assert f"the run in {out} keeps its outputs so far" in err
    assert "wptrack: error:" not in err
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "failed" and "injected fault" in run["error"] and run["last_frame"] == 24
    t = read_tracks(out / "tracks.csv")
    assert t["frame"].max() == 24 and set(np.unique(t["id"])) == {0, 1}
    idx, _ = read_chunks(out / "hulls")
    assert len(idx) == len(t["frame"])


def test_image_folders_need_a_frame_rate(scene, tmp_path, capsys):
    """Image folders carry no frame rate: without --fps a clear one-line error, with --fps the run records it."""
    import cv2

    from wptrack.io.frames import open_source

    folders = []
    for k in range(3):
        folder = tmp_path / f"img{k}"
        folder.mkdir()
        for i, frame in enumerate(open_source(str(scene / f"cam{k}.avi"))):
            if i >= 20:
                break
            cv2.imwrite(str(folder / f"{i:04d}.png"), frame)
        folders.append(folder)
    argv = ["track", "people", "--rig", str(scene / "rig.yaml"), "--device", "cpu", "-q", "--particles", "200"]
    for k in range(3):
        argv += ["--video", str(folders[k]), "--masks", str(scene / f"mask{k}.avi")]
    out = tmp_path / "run"
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("wptrack: error:") and "--fps" in err and not out.exists()
    assert main([*argv, "--out", str(out), "--fps", "12.5"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["config"]["tracker"]["fps"] == 12.5
    video = tmp_path / "video"
    assert main([*_args(scene, video), "--max-frames", "5"]) == 0
    assert json.loads((video / "run.json").read_text())["config"]["tracker"]["fps"] == 25.0  # the videos' own


def test_saved_masks_are_the_masks_used_as_1bit_png_frames(scene, tmp_path):
    """--save-masks writes each camera's masks as an AVI of 1-bit PNG images (wptrack.io.avi), frame for frame the
    given masks (0/255)."""
    import cv2

    from wptrack.io.frames import open_source

    out = tmp_path / "run"
    assert main([*_args(scene, out), "--occupancy-every", "0", "--save-masks"]) == 0
    names = Rig.load(scene / "rig.yaml").names
    for k, name in enumerate(names):
        path = out / f"masks_{name}.avi"
        cap = cv2.VideoCapture(str(path))
        code = int(cap.get(cv2.CAP_PROP_FOURCC))
        cap.release()
        assert "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)) == "MPNG"
        saved = [np.asarray(f)[..., 0] for f in open_source(str(path))]
        given = [np.asarray(f)[..., 0] for f in open_source(str(scene / f"mask{k}.avi"))]
        assert len(saved) == len(given) == 60 and sum(int((g > 127).sum()) for g in given) > 1000
        for s, g in zip(saved, given, strict=True):
            np.testing.assert_array_equal(s, np.where(g > 127, 255, 0))
