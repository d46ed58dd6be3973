"""Bad input of issues 26 and 31 that no other test covered (the audit table of the fix4 report lists every item and
the test that covers it): a rig whose ground plane lies above a camera or faces away from it, a video whose frames
are all identical, image folders of different lengths, and the blind-camera warning's wording. Small, CPU only."""

from __future__ import annotations

import logging
import re

import cv2
import numpy as np
import pytest

from wptrack.cameras.rig import Camera, Rig
from wptrack.core.errors import FrameError, RigError
from wptrack.io.frames import open_frames
from wptrack.io.video import write_video

W, H = 160, 120


def _camera() -> Camera:
    return Camera.look_at("cam0", W, H, position=[0, -6, 5], target=[0, 8, 0], fx=130)  # 5 m up, looking down


@pytest.mark.parametrize(
    ("ground", "below"),
    [
        ({"origin": [0, 0, 10], "normal": [0, 0, 1]}, "5.00 m below"),  # the plane 10 m up: behind the camera
        ({"origin": [0, 0, 0], "normal": [0, 0, -1]}, "5.00 m below"),  # the normal points down, away from it
    ],
)
def test_ground_plane_behind_the_camera_is_refused_at_load(tmp_path, capsys, ground, below):
    import yaml

    from wptrack.cli import main

    Rig(cameras=(_camera(),)).save(tmp_path / "ok.yaml")
    data = yaml.safe_load((tmp_path / "ok.yaml").read_text())
    data["ground"] = ground
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(RigError) as e:
        Rig.load(tmp_path / "rig.yaml")
    text = str(e.value)
    assert "rig.yaml: ground: camera 'cam0' is " + below in text and "check the sign of 'normal'" in text
    masks = tmp_path / "m.avi"
    write_video(masks, [np.zeros((H, W, 3), np.uint8)] * 3, fps=10)
    out = tmp_path / "out"
    code = main(["track", "templates", "--rig", str(tmp_path / "rig.yaml"), "--masks", str(masks), "--out", str(out)])
    err = capsys.readouterr().err
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("Warp CUDA warning")]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("wptrack: error: ") and below in lines[0], err
    assert not out.exists()
    data["ground"] = {"origin": [0, 0, 0.5], "normal": [0, 0.2, 1]}  # a sloped plane below the camera: fine
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(data))
    assert Rig.load(tmp_path / "rig.yaml").ground is not None


def test_identical_frames_give_empty_masks_and_no_object(tmp_path, rng):
    """A video whose frames are all the same image (a still, a frozen camera): no motion, no object, no flood, no
    division by a zero noise scale."""
    from wptrack.motion.masks import MaskConfig, open_masks
    from wptrack.trackers.templates.run import run_template_tracking
    from wptrack.trackers.templates.tracker import TemplateConfig

    still = cv2.resize(rng.uniform(40, 220, (H // 6, W // 6, 3)).astype(np.uint8), (W, H), cv2.INTER_NEAREST)
    still[40:90, 70:80] = 20  # a dark "person" standing in every frame: background, as nothing moves
    video = tmp_path / "still.avi"
    write_video(video, [still] * 8, fps=10)
    for method in ("offline", "mog2"):  # (OpenCV's KNN marks its first 4 frames all foreground, a still or not)
        masks = np.stack(list(open_masks(video=str(video), config=MaskConfig(method=method, device="cpu"))))
        assert masks.shape == (8, H, W) and not masks.any(), method
    Rig(cameras=(_camera(),)).save(tmp_path / "rig.yaml")
    summary = run_template_tracking(
        str(tmp_path / "rig.yaml"), tmp_path / "run", TemplateConfig(particles=100), video=str(video), device="cpu"
    )
    assert summary["frames"] == 8 and summary["objects"] == 0 and summary["flooded_frames"] == 0


def test_image_folders_of_different_lengths(tmp_path, rng):
    """Image folders (no frame count in a header) of different lengths: the same one-line error as videos, naming
    each folder and its count; --stop-at-shortest tracks the common part."""
    folders = []
    for name, n in (("a", 6), ("b", 4)):
        d = tmp_path / name
        d.mkdir()
        for i in range(n):
            cv2.imwrite(str(d / f"{i:03d}.png"), rng.integers(0, 255, (24, 32, 3), dtype=np.uint8))
        folders.append(d)
    with pytest.raises(FrameError) as e:
        open_frames(folders)
    text = str(e.value)
    assert f"{folders[0]} 6" in text and f"{folders[1]} 4" in text and "--stop-at-shortest" in text
    assert "\n" not in text
    assert len(list(open_frames(folders, stop_at_shortest=True))) == 4


def test_blind_camera_warning_prints_plain_numbers(caplog):
    """The warning of a camera that sees nothing of the volume wrote ``[np.float64(40.0), ...]`` (NumPy 2 reprs)."""
    cam = _camera()
    with caplog.at_level(logging.WARNING, logger="wptrack.cameras.rig"):
        Rig((cam,), volume=((40.0, 40.0, 0.0), (42.0, 42.0, 2.0)), source="r.yaml")
    text = caplog.text
    assert "sees nothing of the working volume [40.0, 40.0, 0.0]..[42.0, 42.0, 2.0] m" in text and "np." not in text


def test_particles_beyond_memory_name_a_limit_that_exists(tmp_path, capsys, monkeypatch):
    """--particles so many that not one object fits: the error named "max_objects 0" as the limit (not a valid
    value); it now gives the particles that fit and says that no object count does at that many particles."""
    import wptrack.core.memory as memory
    from wptrack.cli import main

    monkeypatch.setattr(memory, "available_bytes", lambda dev: 8 * 2**20)
    Rig(cameras=(_camera(),)).save(tmp_path / "rig.yaml")
    masks = tmp_path / "m.avi"
    write_video(masks, [np.zeros((H, W, 3), np.uint8)] * 3, fps=10)
    out = tmp_path / "out"
    argv = ["track", "templates", "--rig", str(tmp_path / "rig.yaml"), "--masks", str(masks), "--out", str(out)]
    code = main([*argv, "--max-objects", "8", "--particles", "1000000", "--device", "cpu", "-q"])
    err = capsys.readouterr().err
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("Warp CUDA warning")]
    assert code == 2 and len(lines) == 1 and "max_objects 0" not in err, err
    assert "particles at max_objects 8 (not even max_objects 1 fits at 1000000 particles)" in lines[0], err
    assert not out.exists()


# ------------------------------------------------------------------------------------------ a camera that moves
def _scene(rng, frames: int, pan_px: float = 0.0, width: int = W) -> np.ndarray:
    """A textured view (paving tiles) with a dark box walking across; ``pan_px``: the camera pans this many pixels a
    frame (a window sliding over a wider view): (frames, H, width, 3) uint8."""
    wide = cv2.resize(rng.uniform(40, 220, (H // 6, 3 * width // 6, 3)).astype(np.uint8), (3 * width, H),
                      interpolation=cv2.INTER_NEAREST)  # fmt: skip
    out = []
    for t in range(frames):
        left = width + int(round(pan_px * t))  # from the middle third: pans either way
        view = wide[:, left : left + width].copy()
        u = 10 + 3 * t
        view[50:90, u : u + 10] = 20
        out.append(np.clip(view + rng.normal(0, 2, view.shape), 0, 255).astype(np.uint8))
    return np.stack(out)


def test_camera_motion_watch_tells_a_pan_from_a_fixed_camera(rng):
    from wptrack.motion.camera_motion import CameraMotionWatch

    for pan, warned in ((0.0, None), (2.0, 15), (-1.0, 15), (0.5, 20)):
        watch = CameraMotionWatch(name="cam")
        for i, frame in enumerate(_scene(rng, 40, pan)):
            watch.add(i, frame)
        assert watch.moved_at == warned, (pan, watch.moved_at, watch.largest)
        if pan:
            assert watch.largest == pytest.approx(abs(pan) * warned, abs=1.5)
        else:
            assert watch.largest < 1.0
    shaken = _scene(rng, 40)  # a shake of 4 px for 6 frames (the flood guard's case): no warning
    for t in range(10, 16):
        shaken[t] = np.roll(shaken[t], 4 if t % 2 else -4, axis=1)
    watch = CameraMotionWatch()
    for i, frame in enumerate(shaken):
        watch.add(i, frame)
    assert watch.moved_at is None and watch.largest >= 3.0  # it saw the shake, and it did not last
    with pytest.raises(Exception, match="CameraMotionWatch.fraction"):
        CameraMotionWatch(fraction=0.0)


def test_camera_motion_watch_tells_a_fast_pan_and_its_shift(rng, caplog):
    """A pan of 6 % of the width a frame leaves the first frame's view within three samples, where the shift against
    it reads noise or aliases (the audit: 20 px a frame at 320 wide went unwarned; 15 px a frame was warned as 32 px
    for 225). The steps between samples add up: warned at frame 15 with their sum; a shake of the same size back and
    forth is not a pan."""
    from wptrack.motion.camera_motion import CameraMotionWatch

    for pan in (10.0, -10.0):
        watch = CameraMotionWatch(name="cam")
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="wptrack.motion.camera_motion"):
            for i, frame in enumerate(_scene(rng, 16, pan)):  # 150 px: the whole wider view's margin
                watch.add(i, frame)
        assert watch.moved_at == 15, (pan, watch.moved_at)
        assert watch.largest == pytest.approx(150.0, abs=3.0)
        (message,) = [r.getMessage() for r in caplog.records]
        said = re.match(
            r"cam: the view has shifted by about (\d+) px \(\d+ % of its width\) in 15 frames, at frame 15:", message
        )
        assert said and abs(int(said.group(1)) - 150) <= 3, message
    frames = _scene(rng, 40)
    for t in range(40):  # a shake of 10 px each way, every sample seeing a large step
        frames[t] = np.roll(frames[t], 10 if (t // 5) % 2 else -10, axis=1)
    watch = CameraMotionWatch()
    for i, frame in enumerate(frames):
        watch.add(i, frame)
    assert watch.moved_at is None and watch.largest >= 15.0


def test_masks_of_a_moving_camera_warn_once(tmp_path, rng, caplog):
    """``wptrack masks`` (and every tracker, through MotionMasks) on a panning camera: one warning naming the video,
    the shift and the frame; none for the same scene from a fixed camera, none for given masks."""
    from wptrack.motion.masks import MaskConfig, open_masks

    for pan in (0.0, 2.0):
        video = tmp_path / f"pan{pan}.avi"
        write_video(video, list(_scene(rng, 30, pan)), fps=10)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="wptrack.motion.camera_motion"):
            for method in ("offline", "mog2"):
                assert len(list(open_masks(video=str(video), config=MaskConfig(method=method, device="cpu")))) == 30
            list(open_masks(masks=str(video)))  # given masks: not camera frames, not watched
        warnings = [r.getMessage() for r in caplog.records if "the camera seems to move" in r.getMessage()]
        if pan:
            assert len(warnings) == 2 and all(w.startswith(f"{video}: the view has shifted by about 30 px") for w in
                                              warnings) and "at frame 15" in warnings[0], warnings  # fmt: skip
        else:
            assert warnings == []


def test_max_objects_beyond_the_cap_names_it(tmp_path, capsys):
    from wptrack.cli import main

    Rig(cameras=(_camera(),)).save(tmp_path / "rig.yaml")
    masks = tmp_path / "m.avi"
    write_video(masks, [np.zeros((H, W, 3), np.uint8)] * 3, fps=10)
    out = tmp_path / "out"
    argv = ["track", "templates", "--rig", str(tmp_path / "rig.yaml"), "--masks", str(masks), "--out", str(out)]
    assert main([*argv, "--max-objects", "100000", "--device", "cpu", "-q"]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("Warp CUDA warning")]
    assert len(lines) == 1 and lines[0] == "wptrack: error: max_objects: expected a positive integer <= 64, got 100000"
    assert not out.exists()


def test_a_file_that_is_no_video_gets_one_error_line_without_opencv_warnings(tmp_path):
    """A video cut to its header (the audit): OpenCV's own ``[ WARN:0@...] global cap.cpp`` line came before
    wptrack's error; the CLI now sets ``OPENCV_LOG_LEVEL`` to ERROR unless the user set it or asked for -v. Run in a
    process of its own: OpenCV reads the variable once."""
    import os
    import subprocess
    import sys

    path = tmp_path / "v.avi"
    write_video(path, [np.full((H, W, 3), 90, np.uint8)] * 5, fps=10)
    cut = tmp_path / "cut.avi"
    cut.write_bytes(path.read_bytes()[:100])
    env = {k: v for k, v in os.environ.items() if not k.startswith("OPENCV_")}
    argv = [sys.executable, "-m", "wptrack.cli", "masks", "--video", str(cut), "--out", str(tmp_path / "o"), "-q"]
    done = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 2, done.stderr
    assert "[ WARN" not in done.stderr and "Traceback" not in done.stderr, done.stderr
    assert f"wptrack: error: cannot open video {cut}" in done.stderr
    assert not (tmp_path / "o").exists()
