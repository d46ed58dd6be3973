"""Interrupt a run (SIGTERM between frames), resume it with --resume, and get what an uninterrupted run gives:
tracks.csv byte for byte and the same summary, for the colour and the template tracker."""

from __future__ import annotations

import json
import os
import signal

import pytest

from wptrack.cli import main
from wptrack.core.errors import ConfigError
from wptrack.runs import RunInterrupted, run_tracker
from wptrack.runs.loop import CHECKPOINT_FILE
from wptrack.synth import render_scene
from wptrack.trackers.colour.run import ColourRun
from wptrack.trackers.colour.tracker import ColorConfig, HSITarget
from wptrack.trackers.templates.run import TemplateRun
from wptrack.trackers.templates.tracker import TemplateConfig

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGTERM") or os.name == "nt", reason="POSIX signals")

TARGET = HSITarget(hue=(312, 348), sat=(0.3, 0.8), intensity=(20, 240))


def _interrupting(job_cls, at: int):
    """A job class that sends itself SIGTERM while tracking frame ``at`` (the loop stops after that frame)."""

    class Interrupting(job_cls):
        def step(self, item):
            est = super().step(item)
            if est.frame == at:
                os.kill(os.getpid(), signal.SIGTERM)
            return est

    return Interrupting


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    return render_scene("s1-lab", tmp_path_factory.mktemp("lab"), frames=12, seed=0)


@pytest.fixture(scope="module")
def plaza(tmp_path_factory):
    return render_scene("s3-people", tmp_path_factory.mktemp("plaza"), frames=14, seed=1)


def _colour_args(lab):
    cfg = ColorConfig(particles=400, sigma=0.03, init=(0.4, 0.1, 0.2), seed=5, keep_particles=50)
    return (lab.rig_path, lab.videos, TARGET, cfg), {"device": "cpu", "groundtruth": lab.groundtruth_path}


def _template_args(plaza):
    cfg = TemplateConfig(particles=200, max_objects=4, seed=2, fps=15.0)
    masks = os.path.join(plaza.out_dir, "cam0_mask.avi")
    return (plaza.rig_path, cfg), {"masks": masks, "device": "cpu"}


@pytest.mark.parametrize("tracker", ["color", "templates"])
def test_resume_equals_uninterrupted_run(tmp_path, lab, plaza, tracker):
    if tracker == "color":
        job_cls, (args, kw) = ColourRun, _colour_args(lab)
    else:
        job_cls, (args, kw) = TemplateRun, _template_args(plaza)
    full = run_tracker(job_cls(*args, **kw), tmp_path / "full", checkpoint_seconds=0)

    out = tmp_path / "cut"
    with pytest.raises(RunInterrupted):
        run_tracker(_interrupting(job_cls, 5)(*args, **kw), out, checkpoint_seconds=0)
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "interrupted" and run["last_frame"] == 5
    assert (out / CHECKPOINT_FILE).exists()

    resumed = run_tracker(job_cls(*args, **kw), out, resume=True)
    assert resumed == full
    assert (out / "tracks.csv").read_bytes() == (tmp_path / "full" / "tracks.csv").read_bytes()
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "complete" and run["resumed"][0]["after_frame"] == 5
    assert not (out / CHECKPOINT_FILE).exists()
    if tracker == "templates":
        assert (out / "best.csv").read_bytes() == (tmp_path / "full" / "best.csv").read_bytes()


def test_rows_after_the_checkpoint_are_dropped_on_resume(tmp_path, lab):
    """A crash after the last checkpoint leaves later rows (and a torn line) behind: resume replaces them."""
    args, kw = _colour_args(lab)
    full = tmp_path / "full"
    run_tracker(ColourRun(*args, **kw), full, checkpoint_seconds=0)
    out = tmp_path / "cut"
    with pytest.raises(RunInterrupted):
        run_tracker(_interrupting(ColourRun, 3)(*args, **kw), out, checkpoint_seconds=0)
    lines = (full / "tracks.csv").read_text().splitlines(keepends=True)
    with open(out / "tracks.csv", "a") as f:  # rows of frames 4-6 written after the checkpoint, then a torn line
        f.write("".join(lines[5:8]) + lines[8][:10])
    run_tracker(ColourRun(*args, **kw), out, resume=True)
    assert (out / "tracks.csv").read_bytes() == (full / "tracks.csv").read_bytes()


def test_resume_refuses_other_config_or_finished_run(tmp_path, lab):
    args, kw = _colour_args(lab)
    with pytest.raises(RunInterrupted):
        run_tracker(_interrupting(ColourRun, 2)(*args, **kw), tmp_path, checkpoint_seconds=0)
    other = ColorConfig(particles=400, sigma=0.03, init=(0.4, 0.1, 0.2), seed=6, keep_particles=50)
    with pytest.raises(ConfigError, match="configuration differs"):
        run_tracker(ColourRun(args[0], args[1], TARGET, other, **kw), tmp_path, resume=True)
    run_tracker(ColourRun(*args, **kw), tmp_path, resume=True)
    with pytest.raises(ConfigError, match="already complete"):
        run_tracker(ColourRun(*args, **kw), tmp_path, resume=True)
    with pytest.raises(ConfigError, match="nothing to resume"):
        run_tracker(ColourRun(*args, **kw), tmp_path / "empty", resume=True)


def test_cli_resume_errors_are_one_line(tmp_path, lab, capsys):
    base = ["track", "color", "--rig", str(lab.rig_path), "--video", str(lab.videos[0]), "--video", str(lab.videos[1])]
    base += ["--hue", "312", "348", "--sat", "0.3", "0.8", "--init", "0.4", "0.1", "0.2", "--device", "cpu", "-q"]
    assert main([*base, "--out", str(tmp_path / "none"), "--resume"]) == 2
    assert "nothing to resume" in capsys.readouterr().err
    assert main([*base, "--out", str(tmp_path / "x"), "--checkpoint-every", "-1"]) == 2
    assert not (tmp_path / "x" / "run.json").exists()


def test_resume_into_a_missing_folder_leaves_nothing(tmp_path, lab, capsys):
    """Issue 30 item 15: --resume into a folder that does not exist said 'nothing to resume' and left an empty
    folder behind."""
    base = ["track", "color", "--rig", str(lab.rig_path), "--video", str(lab.videos[0]), "--video", str(lab.videos[1])]
    base += ["--hue", "312", "348", "--sat", "0.3", "0.8", "--init", "0.4", "0.1", "0.2", "--device", "cpu", "-q"]
    assert main([*base, "--out", str(tmp_path / "new" / "run"), "--resume"]) == 2
    assert "nothing to resume" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def _cli_base(lab):
    base = ["track", "color", "--rig", str(lab.rig_path), "--video", str(lab.videos[0]), "--video", str(lab.videos[1])]
    return base + ["--hue", "312", "348", "--sat", "0.3", "0.8", "--init", "0.4", "0.1", "0.2", "--device", "cpu", "-q"]


def test_ctrl_c_before_the_first_frame(tmp_path, lab, capsys, monkeypatch):
    """Issue 30 item 8: Ctrl-C before the first frame said 'partial results were kept' and --resume then failed.
    Now nothing is left and the message says so; after a tracked frame it says how to continue."""

    def interrupt(self, item):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(ColourRun, "step", interrupt)
        assert main([*_cli_base(lab), "--out", str(tmp_path / "early")]) == 130
    err = capsys.readouterr().err
    assert "before the first frame" in err and "nothing was written" in err and "kept" not in err
    assert not (tmp_path / "early").exists()
    assert main([*_cli_base(lab), "--out", str(tmp_path / "early"), "--max-frames", "3"]) == 0  # no flag needed

    calls = {"n": 0}
    step = ColourRun.step

    def later(self, item):
        calls["n"] += 1
        if calls["n"] == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return step(self, item)

    with monkeypatch.context() as m:
        m.setattr(ColourRun, "step", later)
        assert main([*_cli_base(lab), "--out", str(tmp_path / "late")]) == 143
    assert "--resume continues the run" in capsys.readouterr().err
    assert main([*_cli_base(lab), "--out", str(tmp_path / "late"), "--resume"]) == 0


def test_resume_of_a_run_stopped_before_its_first_frame_starts_it(tmp_path, lab):
    """A run folder whose run stopped before any frame (run.json with last_frame null, no checkpoint, e.g. a killed
    process) is started from the beginning by --resume."""
    args, kw = _colour_args(lab)
    full = tmp_path / "full"
    run_tracker(ColourRun(*args, **kw), full, checkpoint_seconds=0)
    out = tmp_path / "killed"
    out.mkdir()
    config = json.loads((full / "run.json").read_text())["config"]
    killed = {"tracker": "color", "status": "running", "last_frame": None, "config": config}
    (out / "run.json").write_text(json.dumps(killed))
    run_tracker(ColourRun(*args, **kw), out, resume=True)
    assert (out / "tracks.csv").read_bytes() == (full / "tracks.csv").read_bytes()


def test_resume_names_the_options_that_differ(tmp_path, lab):
    """Issue 30 item 10: the error named an internal key ('... in tracker') instead of the option and its values."""
    args, kw = _colour_args(lab)
    with pytest.raises(RunInterrupted):
        run_tracker(_interrupting(ColourRun, 2)(*args, **kw), tmp_path, checkpoint_seconds=0)
    other = ColorConfig(particles=300, sigma=0.03, init=(0.4, 0.1, 0.2), seed=6, keep_particles=50)
    with pytest.raises(ConfigError) as err:
        run_tracker(ColourRun(args[0], args[1], TARGET, other, **kw), tmp_path, resume=True)
    text = str(err.value)
    assert "--particles was 400, now 300" in text and "--seed was 5, now 6" in text
    assert "(tracker)" not in text and "--overwrite" in text


@pytest.mark.parametrize("damage", ["truncated", "garbage", "keys"])
def test_damaged_checkpoint_is_one_clear_error(tmp_path, lab, capsys, damage):
    """Issue 30 item 21: a checkpoint cut short (full disk) gave a zipfile.BadZipFile traceback."""
    import numpy as np

    base = _cli_base(lab)
    calls = {"n": 0}
    step = ColourRun.step

    def later(self, item):
        calls["n"] += 1
        if calls["n"] == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return step(self, item)

    ColourRun.step = later
    try:
        assert main([*base, "--out", str(tmp_path)]) == 143
    finally:
        ColourRun.step = step
    ckpt = tmp_path / CHECKPOINT_FILE
    data = ckpt.read_bytes()
    if damage == "truncated":
        ckpt.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        ckpt.write_bytes(b"\0" * 100)
    else:  # a valid npz without the state
        with open(ckpt, "wb") as fh:
            np.savez(fh, __run_frame__=np.int64(2))
    capsys.readouterr()
    assert main([*base, "--out", str(tmp_path), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "damaged" in err and "--overwrite" in err and "without --resume" in err
    assert main([*base, "--out", str(tmp_path), "--overwrite", "--max-frames", "2"]) == 0


def _video_frames(path):
    import cv2

    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f)
    cap.release()
    return frames


def test_resumed_template_run_writes_one_virtual_video(tmp_path, plaza):
    """Issue 30 item 9: a resumed template run split virtual.avi into virtual.avi + virtual.from6.avi; now it writes
    one virtual.avi (and masks.avi) with the same frames as an uninterrupted run (FFV1: lossless)."""
    import numpy as np

    (args, kw) = _template_args(plaza)
    kw = {**kw, "save_masks": True}
    run_tracker(TemplateRun(*args, **kw), tmp_path / "full", checkpoint_seconds=0)
    out = tmp_path / "cut"
    with pytest.raises(RunInterrupted):
        run_tracker(_interrupting(TemplateRun, 5)(*args, **kw), out, checkpoint_seconds=0)
    assert len(_video_frames(out / "virtual.avi")) == 6
    run_tracker(TemplateRun(*args, **kw), out, resume=True)
    assert sorted(p.name for p in out.glob("*.avi")) == ["masks.avi", "virtual.avi"]
    for name in ("virtual.avi", "masks.avi"):
        full, resumed = _video_frames(tmp_path / "full" / name), _video_frames(out / name)
        assert len(resumed) == len(full) == 14
        assert all(np.array_equal(a, b) for a, b in zip(full, resumed, strict=True)), name


def test_continue_video_fills_missing_frames_black(tmp_path):
    """A video with fewer frames than the resume point (a killed run never closed it): the gap is black, so frame i
    of the video stays frame i of the run."""
    import numpy as np

    from wptrack.io.video import continue_video, write_video

    write_video(tmp_path / "v.avi", [np.full((8, 10, 3), 50 + k, np.uint8) for k in range(2)], fps=5)
    w = continue_video(tmp_path / "v.avi", 4, fps=5)
    w.write(np.full((8, 10, 3), 200, np.uint8))
    w.close()
    got = [int(f.mean()) for f in _video_frames(tmp_path / "v.avi")]
    assert got == [50, 51, 0, 0, 200]
    w = continue_video(tmp_path / "none.avi", 2, fps=5)
    w.write(np.full((8, 10, 3), 9, np.uint8))
    w.close()
    assert [int(f.mean()) for f in _video_frames(tmp_path / "none.avi")] == [0, 0, 9]
