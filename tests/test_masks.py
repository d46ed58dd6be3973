"""Motion masks (wptrack.motion.masks): OpenCV background subtraction + clean-up, given masks, size checks, config."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from wptrack.cameras.rig import Camera
from wptrack.core.errors import ConfigError, FrameError
from wptrack.io.frames import open_source
from wptrack.io.video import VideoWriter
from wptrack.motion.masks import MaskConfig, MotionMasks, clean_mask, open_masks

H, W = 90, 120
WARM = 25  # background-only frames before anything moves or changes
RECT_W, RECT_H = 16, 20


def _background(rng: np.random.Generator) -> np.ndarray:
    """(H, W, 3) float32 smooth colour texture, values 40..200."""
    base = rng.uniform(40, 200, size=(H // 6, W // 6, 3)).astype(np.float32)
    return cv2.resize(base, (W, H), interpolation=cv2.INTER_LINEAR)


def _static(rng: np.random.Generator, frames: int, noise: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """(frames, H, W, 3) uint8 frames of one background with per-frame gaussian noise, and the float background."""
    bg = _background(rng)
    out = np.clip(bg + rng.normal(0.0, noise, size=(frames, H, W, 3)), 0, 255).astype(np.uint8)
    return out, bg


def _moving_rectangle(rng: np.random.Generator, frames: int = 50) -> tuple[np.ndarray, list[np.ndarray | None]]:
    """Static background for WARM frames, then a bright rectangle moving right by 3 px per frame.

    Returns:
        ``(frames, H, W, 3)`` uint8 BGR frames and, per frame, the true ``(H, W)`` bool rectangle (None before).
    """
    video, _ = _static(rng, frames)
    truth: list[np.ndarray | None] = []
    for t in range(frames):
        if t < WARM:
            truth.append(None)
            continue
        x, y = 5 + 3 * (t - WARM), 30
        video[t, y : y + RECT_H, x : x + RECT_W] = 250
        gt = np.zeros((H, W), bool)
        gt[y : y + RECT_H, x : x + RECT_W] = True
        truth.append(gt)
    return video, truth


def _iou(mask: np.ndarray, truth: np.ndarray) -> float:
    m = mask.astype(bool)
    return float((m & truth).sum() / (m | truth).sum())


def _camera(width: int, height: int) -> Camera:
    return Camera.look_at("cam0", width, height, position=(2.0, 0.0, 1.0), target=(0.0, 0.0, 0.0), fx=100.0)


# ------------------------------------------------------------------------------------------ background subtraction


@pytest.mark.parametrize("method", ["mog2", "knn"])
def test_subtractor_finds_moving_rectangle(method, rng):
    video, truth = _moving_rectangle(rng)
    masks = open_masks(video=video, config=MaskConfig(method=method))
    assert len(masks) == len(video) and masks.size == (W, H)
    out = list(masks)
    assert len(out) == len(video)
    for m in out:
        assert m.shape == (H, W) and m.dtype == np.uint8
        assert set(np.unique(m)) <= {0, 1}
    assert truth[-1] is not None
    assert _iou(out[-1], truth[-1]) > 0.6
    assert out[-1][~truth[-1]].mean() < 0.01  # (almost) nothing outside the rectangle


@pytest.mark.parametrize("method", ["mog2", "knn"])
def test_static_scene_gives_empty_masks(method, rng):
    video, _ = _static(rng, 40)
    out = np.stack(list(open_masks(video=video, config=MaskConfig(method=method))))
    assert out[10:].mean() < 1e-3


@pytest.mark.parametrize("method", ["mog2", "knn"])
def test_shadows_are_background_when_detected(method, rng):
    video, bg = _static(rng, WARM + 1)
    shadow = np.zeros((H, W), bool)
    shadow[20:60, 30:90] = True
    last = bg.copy()
    last[shadow] *= 0.6  # same hue, 60 % brightness
    video[-1] = np.clip(last + rng.normal(0.0, 3.0, size=last.shape), 0, 255).astype(np.uint8)
    with_shadows = list(open_masks(video=video, config=MaskConfig(method=method, detect_shadows=True)))[-1]
    without = list(open_masks(video=video, config=MaskConfig(method=method, detect_shadows=False)))[-1]
    assert with_shadows[shadow].mean() < 0.2
    assert without[shadow].mean() > 0.8


def test_opening_removes_isolated_pixels(rng):
    video, _ = _static(rng, WARM + 1)
    dots = np.zeros((H, W), bool)
    dots[5::10, 5::10] = True
    video[-1][dots] = 255
    raw = list(open_masks(video=video, config=MaskConfig(method="mog2", open_px=0, close_px=0)))[-1]
    assert raw[dots].mean() > 0.9
    opened = list(open_masks(video=video, config=MaskConfig(method="mog2", open_px=3, close_px=5)))[-1]
    assert not opened.any()


def test_min_area_removes_small_blobs(rng):
    video, _ = _static(rng, WARM + 1)
    video[-1, 10:13, 10:13] = 255  # 9 px
    video[-1, 40:52, 60:72] = 255  # 144 px
    config = MaskConfig(method="mog2", open_px=0, close_px=0)
    kept = list(open_masks(video=video, config=config))[-1]
    assert kept[10:13, 10:13].all() and kept[40:52, 60:72].all()
    filtered = list(open_masks(video=video, config=MaskConfig(method="mog2", open_px=0, close_px=0, min_area=20)))[-1]
    assert not filtered[10:13, 10:13].any()
    assert filtered[40:52, 60:72].all()
    assert filtered.sum() == 144


def test_clean_mask_direct():
    mask = np.zeros((30, 30), np.uint8)
    mask[5, 5] = 1  # isolated pixel: removed by the opening
    mask[10:20, 10:20] = 1
    mask[14, 14] = 0  # one-pixel hole: filled by the closing
    out = clean_mask(mask, MaskConfig())
    assert out.dtype == np.uint8 and set(np.unique(out)) <= {0, 1}
    assert out[5, 5] == 0 and out[14, 14] == 1
    assert clean_mask(mask, MaskConfig(open_px=0, close_px=0)) is mask
    full = np.ones((20, 30), np.uint8)
    np.testing.assert_array_equal(clean_mask(full, MaskConfig(min_area=5)), full)


def test_iterating_twice_gives_same_masks(rng):
    video, _ = _moving_rectangle(rng, frames=35)
    masks = open_masks(video=video, config=MaskConfig(method="mog2"))
    first = np.stack(list(masks))
    second = np.stack(list(masks))
    np.testing.assert_array_equal(first, second)
    assert first[-1].any()
    unprefetched = MotionMasks(open_source(video), MaskConfig(method="mog2"), prefetch_depth=0)
    np.testing.assert_array_equal(np.stack(list(unprefetched)), first)


def test_early_break_then_full_iteration(rng):
    video, _ = _moving_rectangle(rng, frames=35)
    masks = open_masks(video=video, config=MaskConfig(method="knn"))
    for i, _mask in enumerate(masks):
        if i == 3:
            break
    assert len(list(masks)) == 35


# ------------------------------------------------------------------------------------------------- given masks


def _given(rng: np.random.Generator, frames: int = 4) -> np.ndarray:
    """(frames, H, W) uint8 masks of 0/255 blocks."""
    blocks = rng.random((frames, H // 10, W // 10)) < 0.4
    return (np.kron(blocks, np.ones((10, 10))) * 255).astype(np.uint8)


def test_given_masks_from_array(rng):
    grey = _given(rng)
    masks = open_masks(masks=grey)
    assert masks.config.method == "given" and len(masks) == len(grey) and masks.size == (W, H)
    out = np.stack(list(masks))
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out, (grey > 127).astype(np.uint8))
    colour = np.zeros((*grey.shape, 3), np.uint8)
    colour[..., 2] = grey  # only the red channel is set
    np.testing.assert_array_equal(np.stack(list(open_masks(masks=colour))), out)


def test_given_masks_are_not_cleaned(rng):
    grey = np.zeros((2, H, W), np.uint8)
    grey[:, 7, 9] = 255  # a single pixel survives: no opening on given masks
    out = list(open_masks(masks=grey, config=MaskConfig(method="given", open_px=5, min_area=50)))
    assert all(m[7, 9] == 1 and m.sum() == 1 for m in out)


def test_given_masks_from_png_folder(tmp_path, rng):
    grey = _given(rng)
    folder = tmp_path / "masks"
    folder.mkdir()
    for i, m in enumerate(grey):
        assert cv2.imwrite(str(folder / f"mask{i}.png"), m)
    out = np.stack(list(open_masks(masks=folder)))
    np.testing.assert_array_equal(out, (grey > 127).astype(np.uint8))


def test_given_masks_from_grey_video(tmp_path, rng):
    grey = _given(rng, frames=5)
    path = tmp_path / "masks.avi"
    with VideoWriter(path, fps=10) as writer:
        for m in grey:
            writer.write(m)
    out = np.stack(list(open_masks(masks=path)))
    expected = (grey > 127).astype(np.uint8)
    assert out.shape == expected.shape
    if writer.codec == "FFV1":  # lossless
        np.testing.assert_array_equal(out, expected)
    else:
        assert (out == expected).mean() > 0.99


def test_threshold_semantics():
    values = np.array([0, 1, 127, 128, 254, 255], np.uint8)
    frames = np.broadcast_to(values, (2, 4, 6)).copy()
    for threshold, expected in [(127, [0, 0, 0, 1, 1, 1]), (0, [0, 1, 1, 1, 1, 1]), (254, [0, 0, 0, 0, 0, 1])]:
        out = list(open_masks(masks=frames, config=MaskConfig(method="given", threshold=threshold)))
        for m in out:
            np.testing.assert_array_equal(m, np.broadcast_to(np.array(expected, np.uint8), (4, 6)))


def test_all_foreground_given_mask_passes_unchanged():
    out = list(open_masks(masks=np.full((3, H, W), 255, np.uint8)))
    assert all(m.dtype == np.uint8 and (m == 1).all() for m in out)


# ------------------------------------------------------------------------------------------------- size checks


def test_video_size_mismatch_with_camera(tmp_path, rng):
    path = tmp_path / "cam0.avi"
    with VideoWriter(path, fps=10) as writer:
        for frame in rng.integers(0, 255, size=(3, 48, 64, 3), dtype=np.uint8):
            writer.write(frame)
    with pytest.raises(FrameError) as info:
        open_masks(video=path, camera=_camera(80, 60), rig_source="rig.yaml")
    msg = str(info.value)
    assert str(path) in msg and "frame size 64x48" in msg and "'cam0'" in msg
    assert "calibration 80x60 in rig.yaml" in msg
    assert open_masks(video=path, camera=_camera(64, 48)).size == (64, 48)


def test_mask_size_mismatch_with_camera(tmp_path):
    folder = tmp_path / "masks"
    folder.mkdir()
    cv2.imwrite(str(folder / "0.png"), np.zeros((240, 320), np.uint8))
    with pytest.raises(FrameError, match=r"mask size 320x240 differs from camera 'cam0' calibration 640x480"):
        open_masks(masks=folder, camera=_camera(640, 480))
    with pytest.raises(FrameError, match=r"^array: mask size 320x240 .* 640x480$"):
        open_masks(masks=np.zeros((2, 240, 320), np.uint8), camera=_camera(640, 480))


def test_size_change_mid_stream(tmp_path):
    folder = Path(tmp_path)
    cv2.imwrite(str(folder / "0.png"), np.zeros((60, 80), np.uint8))
    cv2.imwrite(str(folder / "1.png"), np.zeros((50, 80), np.uint8))
    masks = open_masks(masks=folder, camera=_camera(80, 60))
    it = iter(masks)
    assert next(it).shape == (60, 80)
    with pytest.raises(FrameError, match=r"frame 1 .*80x50"):
        next(it)


# ------------------------------------------------------------------------------------------------------ config


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"method": "gmm"}, "method"),
        ({"history": 0}, "history"),
        ({"history": 2.5}, "history"),
        ({"var_threshold": 0}, "var_threshold"),
        ({"var_threshold": float("nan")}, "var_threshold"),
        ({"dist2_threshold": -1.0}, "dist2_threshold"),
        ({"detect_shadows": "yes"}, "detect_shadows"),
        ({"learning_rate": 1.5}, "learning_rate"),
        ({"learning_rate": -0.5}, "learning_rate"),
        ({"open_px": -1}, "open_px"),
        ({"close_px": 2.0}, "close_px"),
        ({"min_area": -3}, "min_area"),
        ({"threshold": 255}, "threshold"),
        ({"threshold": True}, "threshold"),
        ({"fg_low": 5.0}, "fg_low"),
        ({"fg_low": -1.0}, "fg_low"),
        ({"spread_cap": 0.5}, "spread_cap"),
        ({"spread_cap": float("inf")}, "spread_cap"),
        ({"shadow_band": 0.6}, "shadow_band"),
        ({"neighbourhood": 4}, "neighbourhood"),
        ({"neighbourhood": 1, "fg_low": 0}, "neighbourhood"),
    ],
)
def test_bad_config_names_field(kwargs, field):
    with pytest.raises(ConfigError, match=rf"^MaskConfig\.{field}: expected .*, got "):
        MaskConfig(**kwargs)


def test_config_defaults_and_edge_values():
    c = MaskConfig()
    assert (c.method, c.history, c.var_threshold, c.dist2_threshold) == ("offline", 200, 16, 400)
    assert c.detect_shadows is True
    assert (c.learning_rate, c.open_px, c.close_px, c.min_area, c.threshold) == (-1, 3, 5, 0, 127)
    assert (c.fg_low, c.spread_cap, c.shadow_band, c.neighbourhood) == (3.0, 1.5, 0.08, 1)
    MaskConfig(fg_low=0, neighbourhood=0, spread_cap=0, shadow_band=0)  # the first offline model (round one)
    MaskConfig(learning_rate=0.0, open_px=0, close_px=0, threshold=0)
    MaskConfig(learning_rate=1, threshold=254)


def test_open_masks_argument_errors(rng):
    video, _ = _static(rng, 2)
    with pytest.raises(ConfigError, match="exactly one"):
        open_masks()
    with pytest.raises(ConfigError, match="exactly one"):
        open_masks(video=video, masks=video)
    with pytest.raises(ConfigError, match="'given' expects masks="):
        open_masks(video=video, config=MaskConfig(method="given"))
    with pytest.raises(FrameError):
        open_masks(video="/nonexistent/video.avi")
