"""Issue 14 inputs not covered elsewhere: a camera blind to the working volume, videos cut mid-stream or with no
frame, unequal frame rates, grey and 16-bit images, seeds and intensity out of range, frames without target
pixels and extreme distortion coefficients (finite estimates)."""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.test_cli import _replace, track_args
from tests.test_frames import _frames, _write_avi
from tests.test_tracker_colour import TARGET, small_rig
from wptrack.cameras.rig import Camera, Rig
from wptrack.cli import main
from wptrack.core.errors import ConfigError, FrameError
from wptrack.io.frames import open_frames, open_source
from wptrack.trackers.colour.tracker import ColorTracker, HSITarget

VOLUME = ((-0.5, -0.5, 0.0), (0.5, 0.5, 1.0))


def test_blind_camera_warns(caplog):
    sees = Camera.look_at("sees", 64, 48, (3.0, 0.0, 1.0), (0.0, 0.0, 0.5), 60.0)
    away = Camera.look_at("away", 64, 48, (3.0, 0.0, 1.0), (6.0, 0.0, 0.5), 60.0)  # looks away from the volume
    with caplog.at_level(logging.WARNING, logger="wptrack.cameras.rig"):
        rig = Rig((sees, away), volume=VOLUME, source="r.yaml")
    assert rig.blind_cameras() == ["away"]
    msgs = [r.getMessage() for r in caplog.records]
    assert len(msgs) == 1 and "camera 'away' sees nothing of the working volume" in msgs[0] and "r.yaml" in msgs[0]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="wptrack.cameras.rig"):
        Rig((sees,), volume=VOLUME)
    assert not caplog.records


def test_video_truncated_mid_stream(tmp_path, rng, caplog):
    """A file cut in the middle: the frames before the break are delivered, the log says where it stopped."""
    path = _write_avi(tmp_path / "cut.avi", _frames(rng, 20, 64, 48))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    try:
        src = open_source(path)
    except FrameError:  # an OpenCV build that rejects the cut index outright: still the documented error
        return
    with caplog.at_level(logging.WARNING, logger="wptrack.io.frames"):
        got = list(open_frames([path]))
    assert 0 < len(got) < 20
    if len(src) > len(got):
        assert any(f"ended after {len(got)}" in r.getMessage() for r in caplog.records)


def test_video_with_no_frame(tmp_path, rng):
    path = _write_avi(tmp_path / "v.avi", _frames(rng, 3, 64, 48))
    header = path.read_bytes()[:200]  # the container's header, no frame data
    path.write_bytes(header)
    with pytest.raises(FrameError, match="v.avi"):
        open_source(path)


def test_different_frame_rates_warn(tmp_path, rng, caplog):
    a = _write_avi(tmp_path / "a.avi", _frames(rng, 4))
    h, w = 24, 32
    writer = cv2.VideoWriter(str(tmp_path / "b.avi"), cv2.VideoWriter_fourcc(*"FFV1"), 10, (w, h))
    for f in _frames(rng, 4):
        writer.write(f)
    writer.release()
    with caplog.at_level(logging.WARNING, logger="wptrack.io.frames"):
        frames = open_frames([a, tmp_path / "b.avi"])
    assert len(frames) == 4
    assert any("frame rates differ" in r.getMessage() and "25 fps" in r.getMessage() for r in caplog.records)


def test_grey_and_16bit_images(tmp_path, rng):
    folder = tmp_path / "imgs"
    folder.mkdir()
    grey = rng.integers(0, 256, (24, 32), dtype=np.uint8)
    deep = grey.astype(np.uint16) * 257  # 16-bit grey, same picture
    deep_colour = np.stack([deep, deep, deep], axis=-1)
    assert cv2.imwrite(str(folder / "f0.png"), grey)
    assert cv2.imwrite(str(folder / "f1.png"), deep)
    assert cv2.imwrite(str(folder / "f2.png"), deep_colour)
    frames = list(open_source(folder))
    assert len(frames) == 3
    for f in frames:
        assert f.dtype == np.uint8 and f.shape == (24, 32, 3)
        np.testing.assert_array_equal(f[..., 0], grey)


@pytest.mark.parametrize("seed", [-1, 2**64, 1.5])
def test_seed_out_of_range(seed, device):
    with pytest.raises(ConfigError, match="seed"):
        ColorTracker(small_rig(), TARGET, particles=10, init=(0, 0, 0), seed=seed, device=device)


@pytest.mark.parametrize("intensity", [(-1.0, 200.0), (10.0, 300.0), (200.0, 10.0), (float("nan"), 10.0)])
def test_intensity_out_of_range(intensity):
    with pytest.raises(ConfigError, match="intensity"):
        HSITarget(hue=(300, 340), sat=(0.3, 1.0), intensity=intensity)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from tests.test_cli import scene as make

    return make.__wrapped__(tmp_path_factory)


CLI_CASES = {
    "seed negative": (lambda s: ["--seed", "-1"], "seed"),
    "intensity above 255": (lambda s: ["--intensity", "0", "300"], "intensity"),
    "frame size differs from the rig": (lambda s: ["--video", s["videos"][1], "--video", s["videos"][0]], "differs"),
}


@pytest.mark.parametrize("case", sorted(CLI_CASES))
def test_cli_parameter_errors(scene, tmp_path, capsys, case):
    make, needle = CLI_CASES[case]
    out = tmp_path / "out"
    code = main(_replace(track_args(scene, out), make(scene)))
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("wptrack: error:") and needle in err
    assert not out.exists()


def _noise(rig: Rig, rng) -> list[np.ndarray]:
    return [rng.integers(60, 120, (c.height, c.width, 3)).astype(np.uint8) for c in rig.cameras]


def test_frame_without_target_pixels(device):
    """No pixel of the target colour: every particle has the same likelihood; the estimate stays finite."""
    trk = ColorTracker(small_rig(), TARGET, particles=500, init=(0.4, 0.45, 0.05), device=device, seed=1)
    grey = [np.full((c.height, c.width, 3), 90, np.uint8) for c in trk.rig.cameras]
    for _ in range(3):
        est = trk.step(grey)
        assert np.all(np.isfinite([*est.mean, *est.std, *est.map, est.ess, est.loglik]))
        assert not est.degenerate and est.ess == pytest.approx(500, rel=1e-3)


def test_extreme_distortion_is_finite(device, rng):
    cams = [
        Camera.look_at("c1", 64, 48, (0.5, 0.0, 0.2), (0.4, 0.45, 0.05), 90.0, dist=[80.0, -500.0, 0.5, -0.5, 1e4]),
        Camera.look_at("c2", 48, 64, (0.07, 0.5, 0.08), (0.45, 0.5, 0.03), 90.0, dist=[-50.0, 300.0, 0, 0, -1e4]),
    ]
    rig = Rig(tuple(cams))
    trk = ColorTracker(rig, TARGET, particles=300, init=(0.4, 0.45, 0.05), device=device, seed=2)
    for _ in range(2):
        est = trk.step(_noise(rig, rng))
        assert np.all(np.isfinite([*est.mean, *est.std, *est.map, est.ess, est.loglik]))


def test_extreme_distortion_rig_file_loads(tmp_path):
    cam = Camera.look_at("c", 64, 48, (3.0, 0.0, 1.0), (0.0, 0.0, 0.5), 60.0, dist=[1e6, -1e6, 1.0, 1.0, 1e9])
    Rig((cam,)).save(tmp_path / "rig.yaml")
    rig = Rig.load(tmp_path / "rig.yaml")
    uv, depth = rig[0].project(np.array([[0.0, 0.0, 0.5]]))
    assert depth[0] > 0 and uv.shape == (1, 2)
    assert isinstance(Path(tmp_path / "rig.yaml").read_text(), str)
