"""Offline background model (wptrack.motion.background, wptrack.kernels.core.background, MaskConfig(method="offline")):
kernels vs the NumPy reference on every device, no ghost of an object that stands still at the start (where MOG2
leaves one), cast shadows vs dark objects, short recordings, bad input, and ``wptrack masks``."""

from __future__ import annotations

import json
import logging

import cv2
import numpy as np
import pytest
import warp as wp

from wptrack.bench import numpy_masks
from wptrack.cli import main
from wptrack.core.errors import ConfigError, FrameError
from wptrack.io.frames import open_source
from wptrack.io.video import write_video
from wptrack.kernels.core import background as kbg
from wptrack.motion.masks import MaskConfig, open_masks
from wptrack.motion.windows import SEEK_GAP, bracket, plan_windows

H, W = 72, 96

#: MaskConfig fields of the first offline model (before hysteresis, spread cap, learnt shadows, neighbourhoods).
ROUND_ONE = dict(
    fg_low=0.0, spread_cap=0.0, shadow_band=0.0, neighbourhood=0, illum_tiles=0, illum_veto=0.0, mode_band=0.0
)


def _texture(rng: np.random.Generator, lo: float = 60, hi: float = 200) -> np.ndarray:
    base = rng.uniform(lo, hi, size=(H // 8, W // 8, 3)).astype(np.float32)
    return cv2.resize(base, (W, H), interpolation=cv2.INTER_LINEAR)


def _noisy(rng: np.random.Generator, bg: np.ndarray, frames: int, noise: float = 3.0) -> np.ndarray:
    return np.clip(bg + rng.normal(0.0, noise, size=(frames, *bg.shape)), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("k", [1, 2, 7, 25, 64])
def test_median_mad_kernel_matches_numpy(device, rng, k):
    stack = rng.integers(0, 256, (k, 3 * 500), dtype=np.uint8)
    stack[:, :30] = stack[0, :30]  # ties: constant columns
    stack[:, 30:60] = rng.choice([0, 255], (k, 30)).astype(np.uint8)  # extremes
    stack[:, 60:300] = rng.integers(100, 121, (k, 240))  # narrow ranges (the selection skips common high bits)
    stack[:, 300:400] = rng.integers(250, 256, (k, 100))
    stack[:, 400:500] = rng.integers(0, 4, (k, 100))
    median = wp.zeros(stack.shape[1], dtype=wp.uint8, device=device)
    mad = wp.zeros(stack.shape[1], dtype=wp.uint8, device=device)
    # illumination gains: 3/4, 1 and 5/4 divide exactly (no .5 ties between float32 and float64 rounding)
    for gains in (np.ones((k, 3)), rng.choice([0.75, 1.0, 1.25], (k, 3))):
        wp.launch(
            kbg.median_mad_kernel,
            dim=stack.shape[1],
            inputs=[wp.array(stack, dtype=wp.uint8, device=device), wp.array(gains, dtype=wp.vec3, device=device), 1],
            outputs=[median, mad],
            device=device,
        )
        ref_median, ref_mad = numpy_masks.median_mad(stack, gains)
        np.testing.assert_array_equal(median.numpy(), ref_median)
        np.testing.assert_array_equal(mad.numpy(), ref_mad)
        # every 7th pixel only (the noise scale's pixels): those as above, the others left as they were
        sub_median = wp.full(stack.shape[1], 17, dtype=wp.uint8, device=device)
        sub_mad = wp.full(stack.shape[1], 17, dtype=wp.uint8, device=device)
        pixels = stack.shape[1] // 3
        wp.launch(
            kbg.median_mad_kernel,
            dim=3 * ((pixels + 6) // 7),
            inputs=[wp.array(stack, dtype=wp.uint8, device=device), wp.array(gains, dtype=wp.vec3, device=device), 7],
            outputs=[sub_median, sub_mad],
            device=device,
        )
        chosen = (np.arange(pixels) % 7 == 0).repeat(3)
        for got, ref in ((sub_median.numpy(), ref_median), (sub_mad.numpy(), ref_mad)):
            np.testing.assert_array_equal(got[chosen], ref[chosen])
            assert (got[~chosen] == 17).all()
    if k % 2:  # odd K: the lower median is np.median
        ref_median, _ = numpy_masks.median_mad(stack)
        np.testing.assert_array_equal(ref_median, np.median(stack, axis=0).astype(np.uint8))


def test_gather_columns_kernel_matches_numpy(device, rng):
    """A window's subsample gathered on the device is NumPy's fancy indexing of the stack's rows."""
    stack = rng.integers(0, 256, (7, 3 * 900), dtype=np.uint8)
    columns = np.ascontiguousarray(rng.permutation(stack.shape[1])[:500].astype(np.int32))
    out = wp.full((7, 500), 3, dtype=wp.uint8, device=device)
    wp.launch(
        kbg.gather_columns_kernel,
        dim=out.shape,
        inputs=[wp.array(stack, dtype=wp.uint8, device=device), wp.array(columns, dtype=wp.int32, device=device)],
        outputs=[out],
        device=device,
    )
    np.testing.assert_array_equal(out.numpy(), stack[:, columns])


def test_window_build_reads_the_same_samples_on_every_device(device, rng):
    """What a build's host statistics read of its compensated samples (the neighbourhood scale's samples and the
    subsample's channel values; on CUDA gathered and downloaded alone) is the stack's rows and columns."""
    from wptrack.io.frames import ArraySource
    from wptrack.motion.background import OfflineBackground

    frames = _noisy(rng, _texture(rng), 30)
    model = OfflineBackground(ArraySource(frames), MaskConfig(method="offline", window=30, samples=9), device)
    host = rng.integers(0, 256, (9, 3 * H * W), dtype=np.uint8)
    picks = [0, 4, 8]
    got, sub = model._compensated_samples(wp.array(host, dtype=wp.uint8, device=device), picks)
    assert [r for r, f in enumerate(got) if f is not None] == picks
    for r in picks:
        np.testing.assert_array_equal(got[r].reshape(-1), host[r])
    channels = model._sub_channels
    assert sub.shape == (9, *channels.shape)
    np.testing.assert_array_equal(sub, host[:, channels.reshape(-1)].reshape(9, *channels.shape))
    model.close()


@pytest.mark.parametrize(
    ("shadow", "gain", "low", "cap", "hi", "edge_hi"),
    [
        (True, (1.0, 1.0, 1.0), 4.0, 0.0, 0.95, 0.95),
        (False, (1.0, 1.0, 1.0), 4.0, 0.0, 0.95, 0.95),
        (True, (0.8, 0.9, 1.1), 4.0, 0.0, 0.95, 0.95),
        (True, (1.0, 1.0, 1.0), 2.0, 6.0, 0.6, 0.95),  # hysteresis levels, spread cap, penumbra candidates
    ],
)
def test_foreground_kernel_matches_numpy(device, rng, shadow, gain, low, cap, hi, edge_hi):
    n = 4000
    bg0 = rng.integers(0, 256, (n, 3), dtype=np.uint8)
    bg1 = np.clip(bg0.astype(int) + rng.integers(-20, 21, (n, 3)), 0, 255).astype(np.uint8)
    mad0 = rng.integers(0, 12, (n, 3), dtype=np.uint8)
    mad1 = rng.integers(0, 12, (n, 3), dtype=np.uint8)
    frame = rng.integers(0, 256, (n, 3), dtype=np.uint8)
    frame[: n // 4] = np.clip(bg0[: n // 4] * rng.uniform(0.3, 1.0, (n // 4, 1)), 0, 255).astype(np.uint8)  # shadows
    lit = np.clip(np.round(bg0[n // 4 : n // 2] * np.array(gain)), 0, 255)
    frame[n // 4 : n // 2] = lit.astype(np.uint8)  # background under the frame's global gain
    frame[0] = 0
    bg0[1] = bg1[1] = 0  # black background: no shadow test
    w = 0.3
    p = kbg.ForegroundParams()
    p.threshold, p.soft_scale, p.noise_floor, p.shadow = 4.0, 1.5, 3.0, int(shadow)
    p.low_threshold, p.spread_cap = low, cap
    p.shadow_lo, p.shadow_hi, p.shadow_edge_hi, p.chroma_max = 0.4, hi, edge_hi, 0.1
    dev = [wp.array(a.reshape(-1), dtype=wp.uint8, device=device) for a in (frame, bg0, mad0, bg1, mad1)]
    mask = wp.zeros(n, dtype=wp.uint8, device=device)
    prob = wp.zeros(n, dtype=wp.float32, device=device)
    shad = wp.zeros(n, dtype=wp.uint8, device=device)
    diff = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(
        kbg.foreground_kernel,
        dim=n,
        inputs=[
            *dev,
            w,
            wp.vec3(*gain),
            p,
            wp.zeros(1, dtype=wp.vec3, device=device),
            wp.zeros(1, dtype=kbg.rows_vec, device=device),
            wp.zeros(1, dtype=wp.vec3, device=device),
            3,
            1,
        ],
        outputs=[wp.zeros(1, dtype=kbg.patch_vec, device=device), mask, prob, shad, diff],
        device=device,
    )
    ref = numpy_masks.foreground(
        frame, bg0, mad0, bg1, mad1, w, 4.0, 1.5, 3.0, shadow, 0.4, hi, 0.1, np.array(gain), low, cap, edge_hi
    )
    near = (
        (np.abs(ref["z"] - 4.0) < 1e-4)
        | (np.abs(ref["z"] - low) < 1e-4)
        | (np.abs(ref["a"] - 0.4) < 1e-5)
        | (np.abs(ref["a"] - hi) < 1e-5)
        | (np.abs(ref["a"] - edge_hi) < 1e-5)
        | (np.abs(ref["cd"] - 0.1) < 1e-5)
    )
    assert near.sum() < 5
    ok = ~near
    np.testing.assert_array_equal(mask.numpy()[ok], ref["packed"][ok])
    np.testing.assert_array_equal(shad.numpy()[ok], (2 * ref["shadow"] + ref["penumbra"])[ok])
    assert (ref["penumbra"].sum() > 10) == (shadow and edge_hi > hi)
    np.testing.assert_allclose(prob.numpy()[ok], ref["prob"][ok], atol=1e-5)
    np.testing.assert_allclose(diff.numpy(), ref["diff"], rtol=1e-4, atol=1e-4)
    assert ref["mask"].sum() > n // 10 and (ref["shadow"].sum() > n // 20) == shadow  # the test sees all cases
    assert not ref["mask"][n // 4 : n // 2].any()
    assert ((ref["level"] == 1).sum() > 10) == (low < 4.0)  # weak pixels only with a lower threshold
    np.testing.assert_array_equal(ref["packed"] & 3, ref["level"])
    if cap:  # the cap changes z where the MAD exceeds it (MADs up to 11: sigma up to 16)
        uncapped = numpy_masks.foreground(
            frame, bg0, mad0, bg1, mad1, w, 4.0, 1.5, 3.0, shadow, 0.4, 0.95, 0.1, np.array(gain), low
        )
        assert (uncapped["z"] < ref["z"] - 1e-3).sum() > n // 10


def test_plan_windows_and_bracket(caplog):
    windows = plan_windows(1000, 300, 25)
    assert windows[0].samples[0] < 12 and windows[-1].samples[-1] >= 988
    assert all(len(w.samples) == 25 for w in windows)
    starts = [w.samples[0] for w in windows]
    assert len(windows) == 6 and max(np.diff(starts)) <= 150  # half overlap
    centres = [w.centre for w in windows]
    assert bracket(centres, 0) == (0, 0, 0.0) and bracket(centres, 999) == (5, 5, 0.0)
    i, j, w = bracket(centres, int(np.ceil(centres[2])))
    assert (i, j) == (2, 3) and 0 <= w < 1
    with caplog.at_level(logging.WARNING):
        short = plan_windows(10, 300, 25, name="clip.avi")
    assert len(short) == 1 and short[0].samples == tuple(range(10))
    assert "clip.avi: 10 frames, shorter than the background window" in caplog.text


def _stand_then_move(rng: np.random.Generator, frames: int = 60, still: int = 20):
    """A green box standing at x = 10..22 for ``still`` frames, then moving right 3 px per frame."""
    video = _noisy(rng, _texture(rng), frames)
    for t in range(frames):
        x = 10 + 3 * max(t - still, 0)
        video[t, 26:46, x : x + 12] = (40, 200, 40)
    return video


def test_offline_leaves_no_ghost_where_mog2_does(rng):
    still, frames = 40, 100  # the box stands for 40 % of the window: the median sees the road there
    video = _stand_then_move(rng, frames=frames, still=still)
    start = np.zeros((H, W), bool)
    start[26:46, 10:22] = True  # where the box stood, all uncovered from frame still + 4 on
    offline = np.stack(list(open_masks(video=video, config=MaskConfig(window=frames, device="cpu"))))
    mog2 = np.stack(list(open_masks(video=video, config=MaskConfig(method="mog2"))))
    assert offline[still + 4 :][:, start].mean() < 0.01  # no ghost
    assert mog2[still + 4 : still + 10][:, start].mean() > 0.5  # MOG2 learnt the standing box: a ghost
    for t in range(still + 4, still + 20):  # the moving box itself is found by both
        x = 10 + 3 * (t - still)
        assert offline[t, 28:44, x + 2 : x + 10].mean() > 0.95
        assert mog2[t, 28:44, x + 2 : x + 10].mean() > 0.95
    # the standing box is foreground from frame 0 on (the online model cannot know it yet)
    assert offline[:still][:, start].mean() > 0.95
    assert mog2[1:still][:, start].mean() < 0.05


def test_shadow_is_background_dark_object_is_not(rng):
    grey = np.full((H, W, 3), 130.0, np.float32)
    frames = 30
    video = _noisy(rng, grey, frames, noise=2.0)
    t = frames - 1
    last = grey.copy()
    last[10:40, 10:40] *= 0.6  # cast shadow: same chromaticity, darkened by 0.6
    last[10:40, 56:86] = (40, 55, 100)  # dark red car: brightness ratio ~0.5, different chromaticity
    video[t] = np.clip(last + rng.normal(0, 2.0, last.shape), 0, 255).astype(np.uint8)
    config = MaskConfig(window=frames, device="cpu", open_px=0, close_px=0)
    masks = open_masks(video=video, config=config)
    mask, prob = list(masks.evidence())[t]
    assert mask[12:38, 12:38].mean() < 0.01 and prob[12:38, 12:38].max() == 0.0
    assert mask[12:38, 58:84].mean() > 0.99 and prob[12:38, 58:84].min() > 0.99
    assert mask[50:, :].sum() == 0 and prob[50:, :].max() < 0.5
    no_shadows = list(open_masks(video=video, config=MaskConfig(window=frames, device="cpu", detect_shadows=False)))
    assert no_shadows[t][12:38, 12:38].mean() > 0.99  # the test is what removes the shadow


def test_empty_scene_and_background(rng):
    bg = _texture(rng)
    video = _noisy(rng, bg, 12)
    masks = open_masks(video=video, config=MaskConfig(window=12, device="cpu"))
    out = list(masks.evidence())
    assert all(m.sum() == 0 for m, _ in out) and max(float(p.max()) for _, p in out) < 0.5
    assert np.abs(masks.background().astype(float) - bg).mean() < 2.0
    assert masks.background().shape == (H, W, 3)
    assert open_masks(video=video, config=MaskConfig(method="mog2")).background() is None


def test_short_recording_falls_back_with_warning(rng, caplog):
    video = _stand_then_move(rng, frames=6, still=0)
    with caplog.at_level(logging.WARNING):
        out = list(open_masks(video=video, config=MaskConfig(device="cpu")))  # default window: 300 frames
    assert len(out) == 6 and "shorter than the background window of 300 frames" in caplog.text
    assert out[5][28:44, 27:35].mean() > 0.9
    with caplog.at_level(logging.WARNING):
        one = list(open_masks(video=video[:1], config=MaskConfig(device="cpu")))
    assert len(one) == 1 and one[0].sum() == 0 and "background from 1 frame(s)" in caplog.text


def test_windows_follow_illumination_drift(rng):
    bg = _texture(rng)
    frames = 120
    gain = np.linspace(0.7, 1.3, frames)[:, None, None, None]  # 60 % brighter over the recording
    video = np.clip(bg * gain + rng.normal(0, 2.0, (frames, H, W, 3)), 0, 255).astype(np.uint8)
    t = 60
    video[t, 20:40, 30:50] = np.clip(video[t, 20:40, 30:50] + np.array([40, -40, 40]), 0, 255)  # a faint object
    drift = np.stack(list(open_masks(video=video, config=MaskConfig(window=20, samples=9, device="cpu"))))
    single = np.stack(list(open_masks(video=video, config=MaskConfig(window=frames, device="cpu"))))
    assert np.delete(drift, t, axis=0).mean() < 0.001  # the drift is followed: no false foreground
    assert drift[t, 20:40, 30:50].mean() > 0.95
    # one window over the whole drift: the global gain compensation keeps the MAD small and finds the object too
    assert np.delete(single, t, axis=0).mean() < 0.001
    assert single[t, 20:40, 30:50].mean() > 0.95


def test_video_file_offline_default_matches_array(tmp_path, rng):
    video = _stand_then_move(rng, frames=40)
    path = tmp_path / "v.avi"
    write_video(path, video)
    assert MaskConfig().method == "offline"
    from_file = np.stack(list(open_masks(video=path, config=MaskConfig(window=40, device="cpu"))))
    decoded = np.stack(list(open_source(path)))
    from_array = np.stack(list(open_masks(video=decoded, config=MaskConfig(window=40, device="cpu"))))
    np.testing.assert_array_equal(from_file, from_array)  # the sampler's seeks read the same frames


def test_given_masks_of_wrong_size(tmp_path):
    from wptrack.cameras.rig import Camera

    cam = Camera.look_at("cam0", 80, 60, (0, -5, 3), (0, 0, 0), 60.0)
    with pytest.raises(FrameError, match=r"mask size 96x72 differs from camera 'cam0' calibration 80x60"):
        open_masks(masks=np.zeros((2, H, W), np.uint8), camera=cam)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"window": 0}, "window"),
        ({"samples": 65}, "samples"),
        ({"fg_threshold": 0}, "fg_threshold"),
        ({"noise_floor": float("nan")}, "noise_floor"),
        ({"soft_scale": -1}, "soft_scale"),
        ({"shadow_lo": 0}, "shadow_lo"),
        ({"shadow_lo": 0.5, "shadow_hi": 0.5}, "shadow_hi"),
        ({"shadow_chroma": -0.1}, "shadow_chroma"),
        ({"shadow_texture": 1.0}, "shadow_texture"),
        ({"shadow_peak": 0.5}, "shadow_peak"),
        ({"device": "gpu"}, "device"),
    ],
)
def test_bad_offline_config_names_field(kwargs, field):
    with pytest.raises(ConfigError, match=rf"^MaskConfig\.{field}: expected .*, got "):
        MaskConfig(**kwargs)


def test_cli_masks_happy_path(tmp_path, rng, capsys):
    video = _stand_then_move(rng, frames=30)
    path = tmp_path / "v.avi"
    write_video(path, video)
    out = tmp_path / "out"
    code = main(
        ["masks", "--video", str(path), "--out", str(out), "--window", "30", "--device", "cpu", "--probability"]
    )
    assert code == 0, capsys.readouterr().err
    masks = np.stack(list(open_source(out / "masks.avi")))[..., 0]
    expected = np.stack(list(open_masks(video=path, config=MaskConfig(window=30, device="cpu"))))
    np.testing.assert_array_equal(masks > 127, expected.astype(bool))  # lossless
    assert len(list(open_source(out / "probability.avi"))) == 30
    assert cv2.imread(str(out / "background.png")).shape == (H, W, 3)
    info = json.loads((out / "masks.json").read_text())
    assert info["config"]["method"] == "offline" and info["frames"] == 30 and info["config"]["window"] == 30


def test_cli_masks_of_a_truncated_video_say_where_it_ended(tmp_path, rng, capsys):
    """masks.json records a truncated video as run.json does (``stopped_early``), and its windows list the frames
    read, not the planned samples past the end (the audit: frames 4-9 listed for a video that ended after 4)."""
    video = _stand_then_move(rng, frames=30)
    path = tmp_path / "v.avi"
    write_video(path, video)
    data = path.read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: len(data) // 2])
    out = tmp_path / "out"
    assert main(["masks", "--video", str(cut), "--out", str(out), "--device", "cpu", "-q"]) == 0, capsys.readouterr()
    info = json.loads((out / "masks.json").read_text())
    read = info["frames"]
    assert 0 < read < 30 and len(list(open_source(out / "masks.avi"))) == read
    assert info["stopped_early"]["frame"] == read and info["stopped_early"]["expected"] == 30
    assert info["windows"] and all(0 <= f < read for w in info["windows"] for f in w)
    whole = tmp_path / "whole"
    assert main(["masks", "--video", str(path), "--out", str(whole), "--device", "cpu", "-q"]) == 0
    info = json.loads((whole / "masks.json").read_text())
    assert "stopped_early" not in info and max(max(w) for w in info["windows"]) >= read


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--video", "{tmp}/missing.avi"], "video file not found"),
        (["--video", "{video}", "--window", "0"], "MaskConfig.window"),
        (["--video", "{video}", "--shadow-lo", "0.9", "--shadow-hi", "0.5"], "MaskConfig.shadow_hi"),
        (["--video", "{video}", "--fg-low", "5"], "MaskConfig.fg_low"),
        (["--video", "{video}", "--fg-low", "0"], "MaskConfig.neighbourhood"),  # the neighbourhood needs it
        (["--video", "{video}", "--spread-cap", "0.5"], "MaskConfig.spread_cap"),
        (["--video", "{video}", "--shadow-band", "0.9"], "MaskConfig.shadow_band"),
    ],
)
def test_cli_masks_bad_input(tmp_path, rng, capsys, argv, message):
    video = tmp_path / "v.avi"
    write_video(video, _noisy(rng, _texture(rng), 3))
    out = tmp_path / "out"
    argv = [a.format(tmp=tmp_path, video=video) for a in argv]
    code = main(["masks", *argv, "--out", str(out), "--device", "cpu"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("wptrack: error: ") and message in err and err.count("\n") == 1
    assert not (out / "masks.avi").exists()


def test_sampler_seeks_read_the_sampled_frames(tmp_path, rng):
    frames = 130
    video = _noisy(rng, _texture(rng), frames, noise=20.0)  # every frame differs
    path = tmp_path / "v.avi"
    write_video(path, video)
    decoded = np.stack(list(open_source(path)))
    # samples 26 frames apart: seeks; the plain median of the samples read (no local light field, no densest cluster)
    config = MaskConfig(window=frames, samples=5, device="cpu", illum_tiles=0, mode_band=0.0)
    masks = open_masks(video=path, config=config)
    samples = masks.model.windows[0].samples
    assert min(np.diff(samples)) >= SEEK_GAP
    expected, _ = numpy_masks.median_mad(decoded[list(samples)])
    np.testing.assert_array_equal(masks.background(), expected)


def _hysteresis_ref(levels: np.ndarray) -> np.ndarray:
    """Breadth-first flood from the strong pixels through 8-connected weak/strong ones."""
    h, w = levels.shape
    out = np.zeros((h, w), np.uint8)
    todo = [tuple(p) for p in np.argwhere(levels == 2)]
    for p in todo:
        out[p] = 1
    while todo:
        y, x = todo.pop()
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                v, u = y + dy, x + dx
                if 0 <= v < h and 0 <= u < w and levels[v, u] > 0 and not out[v, u]:
                    out[v, u] = 1
                    todo.append((v, u))
    return out


def test_hysteresis_matches_flood_reference(rng):
    from wptrack.motion.levels import hysteresis

    for density in (0.05, 0.3, 0.6):
        levels = (rng.random((40, 50)) < density).astype(np.uint8)
        levels[rng.random((40, 50)) < 0.02] = 2
        got = hysteresis(levels)
        np.testing.assert_array_equal(got, _hysteresis_ref(levels))
        assert got.sum() >= (levels == 2).sum()
    assert hysteresis(np.ones((5, 5), np.uint8)).sum() == 0  # weak only: nothing
    diag = np.eye(6, dtype=np.uint8)
    diag[0, 0] = 2
    assert hysteresis(diag).sum() == 6  # 8-connected along the diagonal


def test_low_contrast_part_kept_when_attached(rng):
    """A box whose lower half barely differs from the background (camouflage) is kept whole with the hysteresis;
    the same faint patch alone (not attached to a contrasted part) stays background."""
    grey = np.full((H, W, 3), 120.0, np.float32)
    frames = 25
    video = _noisy(rng, grey, frames, noise=1.0)
    last = grey.copy()
    last[10:25, 20:35] = (40, 160, 60)  # contrasted top
    last[25:50, 20:35] += 5.5  # faint legs: z about 2.75 (noise scale: the floor, 2)
    last[25:50, 60:75] += 5.5  # a faint patch alone
    t = frames - 1
    video[t] = np.clip(last + rng.normal(0, 1.0, last.shape), 0, 255).astype(np.uint8)
    base = dict(window=frames, device="cpu", open_px=3, close_px=5, noise_floor=2.0)
    plain = list(open_masks(video=video, config=MaskConfig(**base, **ROUND_ONE)))[t]
    hyst = list(open_masks(video=video, config=MaskConfig(**base, **{**ROUND_ONE, "fg_low": 2.0})))[t]
    assert plain[27:48, 22:33].mean() < 0.3 and hyst[27:48, 22:33].mean() > 0.9
    assert hyst[27:48, 62:73].mean() < 0.05 and hyst[12:23, 22:33].mean() > 0.99
    assert hyst[:, 40:56].sum() == 0 and hyst[55:, :].sum() == 0


def test_spread_cap_finds_object_standing_in_many_samples(rng):
    """An object standing in 10 of 25 samples inflates its pixels' MAD: without the cap it hides (z under the
    threshold), with the image-wide cap it is foreground while it stands."""
    bg = _texture(rng)
    frames = 25
    video = _noisy(rng, bg, frames)
    colour = np.clip(bg[20:40, 30:50] + 22.0, 0, 255)
    for t in range(10):
        video[t, 20:40, 30:50] = np.clip(colour + rng.normal(0, 3.0, colour.shape), 0, 255).astype(np.uint8)
    base = dict(window=frames, samples=frames, device="cpu")
    plain = np.stack(list(open_masks(video=video, config=MaskConfig(**base, **ROUND_ONE))))
    capped = np.stack(list(open_masks(video=video, config=MaskConfig(**base, **{**ROUND_ONE, "spread_cap": 1.5}))))
    assert plain[:10, 22:38, 32:48].mean() < 0.5
    assert capped[:10, 22:38, 32:48].mean() > 0.95
    assert capped[10:].sum() == 0 and np.delete(capped[:10], np.s_[20:40], axis=1).sum() == 0


def test_resolve_levels_penumbra_near_shadow_only():
    from wptrack.motion.levels import PENUMBRA_PX, resolve_levels

    packed = np.zeros((30, 60), np.uint8)
    packed[5:25, 5:15] = 8  # cast shadow (umbra)
    packed[5:25, 15:17] = 4 + 2  # its rim: penumbra candidates, strong by z
    packed[5:25, 40:50] = 4 + 2  # penumbra-like pixels far from any umbra: an object's part
    packed[5:25, 50:52] = 1  # weak, attached to them
    prob = np.ones((30, 60), np.float32)
    mask = resolve_levels(packed.copy(), prob)
    assert mask[:, :20].sum() == 0 and prob[5:25, 15:17].max() == 0.0
    assert mask[5:25, 40:52].all() and prob[5:25, 40:50].min() == 1.0
    assert mask.sum() == 20 * 12
    far = np.zeros((30, 60), np.uint8)
    far[5:25, 5:15] = 8
    far[5:25, 15 + PENUMBRA_PX + 1 : 30] = 4 + 2  # beyond the rim width: kept
    assert resolve_levels(far.copy()).sum() == 20 * (15 - PENUMBRA_PX - 1)


def _shadow_and_object(rng, shadow: float, dark: float):
    """Masks of a grey floor (140) crossed by a moving cast shadow (brightness ratio ``shadow``) and a moving neutral
    dark object (ratio ``dark``), with the fixed shadow bounds and with the learnt band: ``(fixed, learnt, learnt
    ratio, shadow region, object region)`` at frame 12."""
    grey = np.full((H, W, 3), 140.0, np.float32)
    frames = 25
    video = _noisy(rng, grey, frames, noise=2.0)
    for t in range(frames):
        img = grey.copy()
        img[5:35, 4 * t : 4 * t + 14] *= shadow
        img[45:65, 86 - 3 * t : 86 - 3 * t + 10] *= dark
        video[t] = np.clip(img + rng.normal(0, 2.0, img.shape), 0, 255).astype(np.uint8)
    base = dict(window=frames, samples=frames, device="cpu", fg_low=2.0, neighbourhood=0)
    fixed = np.stack(list(open_masks(video=video, config=MaskConfig(**base, shadow_band=0.0))))
    learnt_masks = open_masks(video=video, config=MaskConfig(**base, shadow_band=0.08))
    learnt = np.stack(list(learnt_masks))
    t = 12
    shadow_px, obj_px = np.s_[7:33, 4 * t + 2 : 4 * t + 12], np.s_[47:63, 88 - 3 * t : 86 - 3 * t + 8]
    return fixed[t], learnt[t], learnt_masks.model._ratio[0], shadow_px, obj_px


def test_learnt_shadow_ratio_removes_deep_shadows_keeps_dark_objects(rng):
    """Hard shadows darker than shadow_lo (ratio 0.36) move across a grey floor next to a dark grey object
    (ratio 0.7, neutral: the fixed test takes it for a shadow). The learnt ratio removes the shadows and keeps the
    object; the fixed bounds do the opposite."""
    from wptrack.motion.stats import shadow_ratio

    fixed, learnt, ratio, shadow, obj = _shadow_and_object(rng, 0.36, 0.7)
    assert ratio is not None and abs(ratio - 0.36) < 0.03
    assert fixed[shadow].mean() > 0.95 and fixed[obj].mean() < 0.05
    assert learnt[shadow].mean() < 0.01 and learnt[obj].mean() > 0.95
    flat = np.full((4, 100, 3), 100, np.uint8)
    assert shadow_ratio(flat, np.ones((4, 3)), flat[0].astype(float), np.ones((100, 3)), 4.0, 3.0, 0.1) is None


def test_learnt_faint_shadow_ratio_keeps_dark_clothes(rng):
    """Overcast footage (the PETS clip's learnt ratio is 0.91): faint shadows (ratio 0.9) move across a grey floor
    next to dark neutral clothes (ratio 0.6, jeans on asphalt). The fixed bounds [0.4, 0.95] take both for shadow;
    the learnt ratio bounds the umbra from below too (r - band = 0.82: nothing darker than this scene's shadows is
    one of them), so the clothes stay foreground and the shadows go."""
    fixed, learnt, ratio, shadow, obj = _shadow_and_object(rng, 0.9, 0.6)
    assert ratio is not None and abs(ratio - 0.9) < 0.03
    assert fixed[shadow].mean() < 0.05 and fixed[obj].mean() < 0.05
    assert learnt[shadow].mean() < 0.05 and learnt[obj].mean() > 0.95


@pytest.mark.parametrize(("radius", "scale", "shadow"), [(1, 1.0, True), (2, 0.7, True), (1, 1.0, False)])
def test_neighbourhood_kernel_matches_numpy(device, rng, radius, scale, shadow):
    """The neighbourhood's weak foreground against the NumPy reference: faint coherent regions are marked; with the
    shadow test on, a region darkened like a cast shadow (the background's colour scaled by 0.88, inside the shadow
    band, its neighbourhood means over the noise) is not, a region of the same size and strength whose colour
    changes is."""
    h, w = 70, 81  # several runs of RUN pixels per row and column, the last ones partial
    packed = rng.choice(np.array([0, 0, 0, 1, 2, 4, 8], np.uint8), (h, w))
    diff = rng.normal(0.0, 1.0, (h, w, 3)).astype(np.float32)
    diff[5:15, 5:20] += 1.6  # a faint coherent region
    diff[40:60, 30:70] -= 1.6
    bg = rng.integers(40, 200, (h, w, 3)).astype(np.uint8)
    bg[18:36] = (90, 120, 150)  # one ground colour under the shadow and the coloured change (neighbours alike)
    mad = np.full((h, w, 3), 2, np.uint8)  # s = max(noise floor 3, 1.4826 * 2) = 3
    u = bg.astype(np.float32) / 3.0
    diff[20:34, 40:75] = -0.12 * u[20:34, 40:75]  # the soft edge of a cloud's shadow: a = 0.88, no colour change
    diff[20:34, 5:38] = 0.12 * np.linalg.norm(u[20:34, 5:38], axis=-1, keepdims=True) * np.array([0.9, -0.3, -0.3])
    params = kbg.ForegroundParams()
    params.shadow, params.shadow_lo, params.shadow_hi, params.chroma_max = int(shadow), 0.8, 0.95, 0.1
    params.spread_cap, params.noise_floor = 0.0, 3.0
    dev_bg = wp.array(bg.reshape(-1), dtype=wp.uint8, device=device)
    dev_mad = wp.array(mad.reshape(-1), dtype=wp.uint8, device=device)
    out = wp.zeros(h * w, dtype=wp.uint8, device=device)
    rows = wp.zeros(h * w, dtype=wp.vec4, device=device)
    dev_packed = wp.array(packed.reshape(-1), dtype=wp.uint8, device=device)
    dev_diff = wp.array(diff.reshape(-1, 3), dtype=wp.vec3, device=device)
    run = int(kbg.RUN)
    wp.launch(
        kbg.neighbourhood_rows_kernel,
        dim=h * ((w + run - 1) // run),
        inputs=[dev_packed, dev_diff, w, h, radius],
        outputs=[rows],
        device=device,
    )
    wp.launch(
        kbg.neighbourhood_kernel,
        dim=w * ((h + run - 1) // run),
        inputs=[dev_packed, rows, w, h, radius, 2.0, scale, dev_bg, dev_mad, dev_bg, dev_mad, 0.0, params],
        outputs=[out],
        device=device,
    )
    cast = (0.8, 0.95, 0.1) if shadow else None
    ref = numpy_masks.neighbourhood(packed, diff.astype(np.float64), radius, 2.0, scale, u.astype(np.float64), cast)
    got = out.numpy().reshape(h, w)
    np.testing.assert_array_equal(got, ref)
    changed = got != packed
    assert changed.sum() > 20 and np.all(got[changed] == packed[changed] + 1)
    assert np.all((packed[changed] & 3) == 0) and np.all((packed[changed] >> 2) != 2)
    assert changed[5:15, 5:20].mean() > 2 * changed.mean()
    eligible = ((packed & 3) == 0) & ((packed >> 2) < 2)
    inner = np.zeros((h, w), bool)
    inner[22:32, 42:73] = True  # away from the region's rim, where neighbourhoods mix it with the noise around
    colour = np.zeros((h, w), bool)
    colour[22:32, 7:36] = True
    assert changed[colour & eligible].mean() > 0.9  # a coloured change of the same size is an object
    if shadow:
        assert not changed[inner & eligible].any()  # the shadow-like darkening is not
    else:
        assert changed[inner & eligible].mean() > 0.9  # without the shadow test it is marked like any change


def test_neighbourhood_scale_independent_vs_correlated_noise(rng):
    from wptrack.motion.stats import neighbourhood_scale

    k, h, w = 5, 60, 80
    bg = np.full((h, w, 3), 120, np.uint8)
    mad = np.full((h, w, 3), 2, np.uint8)
    iid = np.clip(120 + rng.normal(0, 3.0, (k, h, w, 3)), 0, 255).astype(np.uint8)
    blocks = rng.normal(0, 3.0, (k, h // 4, w // 4, 3))
    corr = np.clip(120 + np.repeat(np.repeat(blocks, 4, axis=1), 4, axis=2), 0, 255).astype(np.uint8)
    ones = np.ones((k, 3))
    assert 0.85 < neighbourhood_scale(iid, ones, bg, mad, 1, 3.0) <= 1.0
    assert neighbourhood_scale(corr, ones, bg, mad, 1, 3.0) < 0.6  # 4 x 4 blocks: neighbours move together
    from wptrack.motion import stats

    alone = neighbourhood_scale(corr, ones, bg, mad, 1, 3.0)
    for threads in (1, 3):  # the samples in threads, the rows of their medians too: the same number
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(stats, "host_threads", lambda t=threads: t)
            mp.setattr(stats, "PARALLEL_MIN", 64)
            assert neighbourhood_scale(corr, ones, bg, mad, 1, 3.0) == alone


def test_write_masks_keeps_the_first_background_of_its_pass(tmp_path, rng, monkeypatch):
    """background.png is the first window's background as the pass built it (equal to building it again), and the
    pass reads each window once: the first window is not read a second time for the image (at 1080p that read was
    ~2 s of a 15 s run)."""
    from wptrack.motion import windows as Wn
    from wptrack.motion.writing import write_masks

    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "1")
    video = _stand_then_move(rng, frames=48)
    path = tmp_path / "v.avi"
    write_video(path, video)
    reads: list[tuple[int, ...]] = []
    sampler_read = Wn._Sampler.read

    def read(self, indices, ahead=()):
        reads.append(tuple(indices))
        return sampler_read(self, indices, ahead)

    monkeypatch.setattr(Wn._Sampler, "read", read)
    config = MaskConfig(window=16, samples=4, device="cpu")
    summary = write_masks(path, tmp_path / "out", config)
    windows = summary["windows"]
    assert len(windows) >= 3 and reads == [tuple(w) for w in windows]  # each window read once, in order
    again = open_masks(video=path, config=config).background(0)
    np.testing.assert_array_equal(cv2.imread(str(tmp_path / "out" / "background.png")), again)


def _textured_shadow_and_dark_object(rng, texture: float):
    """A floor of neutral grey 4 x 4 blocks (135..155) crossed by a moving cast shadow (ratio 0.8: it darkens the
    blocks, their texture stays) and a larger moving object of uniform dark grey (60: ratios 0.39..0.44, the
    blocks' texture replaced), the most frequent dark neutral foreground: the masks with the learnt band and the
    given ``shadow_texture``: ``(mask at frame 6, learnt ratio, shadow region, object region)``."""
    blocks = rng.uniform(135, 155, (H // 4, W // 4, 1)).astype(np.float32)
    floor = np.repeat(cv2.resize(blocks, (W, H), interpolation=cv2.INTER_NEAREST)[..., None], 3, axis=2)
    frames = 25
    video = np.empty((frames, H, W, 3), np.uint8)
    for t in range(frames):
        img = floor.copy()
        img[2:28, 3 * t : 3 * t + 21] *= 0.8
        img[30:72, max(110 - 6 * t, 0) : max(158 - 6 * t, 0)] = 60.0
        video[t] = np.clip(img + rng.normal(0, 2.0, img.shape), 0, 255).astype(np.uint8)
    config = MaskConfig(window=frames, samples=frames, device="cpu", fg_low=2.0, neighbourhood=0, illum_tiles=0,
                        illum_veto=0.0, shadow_texture=texture, shadow_peak=0.0)  # fmt: skip
    masks = open_masks(video=video, config=config)
    got = np.stack(list(masks))
    t = 6
    shadow, obj = np.s_[4:26, 3 * t + 2 : 3 * t + 19], np.s_[32:70, 112 - 6 * t : 156 - 6 * t]
    return got[t], masks.model._ratio[0], shadow, obj


def test_learnt_shadow_ratio_from_textured_votes_keeps_dark_clothes(rng):
    """Dark uniform clothes outnumber the cast shadows' pixels: every vote (the highest peak, shadow_peak 0) teaches
    the band the clothes' ratio and eats them (TownCentre learnt 0.43 where its textured votes say 0.87); the votes
    that keep the floor's texture teach the shadows' 0.8: the shadow goes, the clothes stay."""
    old, old_ratio, shadow, obj = _textured_shadow_and_dark_object(rng, 0.0)
    assert old_ratio is not None and old_ratio < 0.6
    assert old[obj].mean() < 0.6
    new, new_ratio, shadow, obj = _textured_shadow_and_dark_object(rng, 0.7)
    assert new_ratio is not None and abs(new_ratio - 0.8) < 0.03
    assert new[obj].mean() > 0.95 and new[shadow].mean() < 0.05


def test_shadow_ratio_texture_votes_fall_back_to_all_on_a_flat_floor(rng):
    """The votes kept by the texture test decide only when there are enough of them (min_count): none kept (a flat
    floor) gives the ratio of every vote; enough kept give theirs."""
    from wptrack.motion.stats import shadow_ratio

    n = 2000
    background = np.full((n, 3), 150.0)
    samples = np.repeat(background[None], 4, axis=0).astype(np.uint8)
    samples[:, :600] = 61  # dark clothes: ratio 0.41
    samples[:, 600:900] = 121  # shadows: ratio 0.81
    args = (np.ones((4, 3)), background, np.ones((n, 3)), 4.0, 3.0, 0.1)
    keep = np.zeros((4, n), bool)
    everything = shadow_ratio(samples, *args)
    assert abs(everything - 0.41) < 0.011
    assert shadow_ratio(samples, *args, keep=keep) == everything
    keep[:, 600:900] = True
    assert abs(shadow_ratio(samples, *args, keep=keep) - 0.81) < 0.011
    keep[:, 640:900] = False  # 4 x 40 = 160 votes kept < min_count 200
    assert shadow_ratio(samples, *args, keep=keep) == everything


def test_shadow_ratio_sharp_peak_beats_a_higher_broad_hump(rng):
    """Faint shadows of one sky (ratio 0.88, narrow: 600 votes) and dark clothes spread over 0.32-0.48 (a broad hump,
    more votes per bin at its top): the highest peak is the clothes', the sharpest the shadows'; a spike of a few
    votes above the hump's flat part does not stand out by 3 Poisson deviations and is not chosen."""
    from wptrack.motion.stats import shadow_ratio

    clothes = rng.uniform(0.32, 0.48, 3000)  # 375 votes per 0.02 bin
    shadows = rng.normal(0.88, 0.01, 600)  # ~230 votes in its top bin
    a = np.concatenate([clothes, shadows])
    n = len(a)
    background = np.full((n, 3), 200.0)
    samples = np.repeat(np.round(a * 200)[:, None], 3, axis=1)[None].astype(np.uint8)
    args = (np.ones((1, 3)), background, np.zeros((n, 3)), 0.0, 1e-3, 0.1)
    highest = shadow_ratio(samples, *args)
    assert 0.32 < highest < 0.48
    assert abs(shadow_ratio(samples, *args, sharp=0.1) - 0.88) < 0.021
    spike = np.concatenate([clothes, np.full(20, 0.405)])  # a few votes on the hump: not significant
    n2 = len(spike)
    s2 = np.repeat(np.round(spike * 200)[:, None], 3, axis=1)[None].astype(np.uint8)
    args2 = (np.ones((1, 3)), np.full((n2, 3), 200.0), np.zeros((n2, 3)), 0.0, 1e-3, 0.1)
    assert shadow_ratio(s2, *args2, sharp=0.1) == shadow_ratio(s2, *args2)  # no standing peak: the highest


@pytest.mark.parametrize("workers", [1, 3])
def test_a_short_recording_is_said_once(caplog, monkeypatch, workers):
    """The windows' plan is made once per source: its warnings (a clip shorter than the window) are logged once,
    whatever models share the windows (the build worker, several mask threads)."""
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", str(workers))
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, size=(12, 24, 32, 3), dtype=np.uint8)
    with caplog.at_level(logging.WARNING):
        masks = open_masks(frames, config=MaskConfig(method="offline", window=300, samples=5, device="cpu"))
        assert len(list(masks)) == 12
    assert caplog.text.count("shorter than the background window") == 1


def test_models_sharing_windows_plan_them_alike():
    from wptrack.io.frames import ArraySource
    from wptrack.motion.background import OfflineBackground

    frames = np.random.default_rng(1).integers(0, 255, size=(40, 24, 32, 3), dtype=np.uint8)
    src = ArraySource(frames)
    first = OfflineBackground(src, MaskConfig(method="offline", window=20, samples=5, device="cpu"), "cpu")
    same = OfflineBackground(src, MaskConfig(method="offline", window=20, samples=5, device="cpu"), "cpu",
                             share=first._share)  # fmt: skip
    assert same.windows is first.windows and len(first.windows) == 3
    with pytest.raises(ValueError, match="planned for"):
        OfflineBackground(src, MaskConfig(method="offline", window=10, samples=5, device="cpu"), "cpu",
                          share=first._share)  # fmt: skip
    for m in (first, same):
        m.close()


def test_resolve_levels_scratch_buffers_per_thread_and_size(rng):
    """The host resolution's scratch buffers (levels.LevelsWork) are the calling thread's, one set per frame size:
    frames of two sizes in turn and two threads at once give the masks of fresh buffers, and the buffers are reused
    (no allocation per frame)."""
    import threading

    from wptrack.motion.levels import LevelsWork, resolve_levels, thread_work

    def frame(h: int, w: int) -> np.ndarray:
        levels = (rng.random((h, w)) < 0.4).astype(np.uint8)
        levels[rng.random((h, w)) < 0.02] = 2
        shadow = (rng.random((h, w)) < 0.1).astype(np.uint8) * rng.integers(1, 3, (h, w)).astype(np.uint8)
        return (levels + 4 * shadow).astype(np.uint8)

    frames = [frame(30, 40), frame(25, 60), frame(30, 40), frame(25, 60)]
    expected = [resolve_levels(f.copy(), None, LevelsWork(f.shape)) for f in frames]
    for f, e in zip(frames, expected, strict=True):
        np.testing.assert_array_equal(resolve_levels(f.copy()), e)
    assert thread_work((30, 40)) is thread_work((30, 40)) and thread_work((25, 60)).fits((25, 60))
    packed = frames[0].copy()
    before = packed.copy()
    resolve_levels(packed)
    np.testing.assert_array_equal(packed, before)  # the kernel's output is not changed
    got: dict[int, list[np.ndarray]] = {}
    mine = thread_work((30, 40))

    def work(k: int) -> None:
        got[k] = [resolve_levels(f.copy()) for f in frames * 5]
        assert thread_work((30, 40)) is not mine

    threads = [threading.Thread(target=work, args=(k,)) for k in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for k in range(3):
        for g, e in zip(got[k], expected * 5, strict=True):
            np.testing.assert_array_equal(g, e)


@pytest.mark.parametrize(("open_px", "close_px"), [(3, 5), (5, 0), (0, 7), (0, 0)])
def test_clean_mask_equals_opencv_opening_and_closing(rng, open_px, close_px):
    """clean_mask's erosions and dilations into scratch images give cv2.morphologyEx's opening then closing, the
    border included (foreground touching it is not eroded from outside), and a new array the caller owns."""
    from wptrack.motion.masks import MaskConfig, clean_mask

    mask = (rng.random((33, 47)) < 0.5).astype(np.uint8)
    mask[0, :] = 1
    mask[:, -1] = 1
    expected = mask.copy()
    for px, op in ((open_px, cv2.MORPH_OPEN), (close_px, cv2.MORPH_CLOSE)):
        if px > 1:
            expected = cv2.morphologyEx(expected, op, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (px, px)))
    first = clean_mask(mask, MaskConfig(open_px=open_px, close_px=close_px))
    np.testing.assert_array_equal(first, expected)
    again = clean_mask((rng.random((33, 47)) < 0.5).astype(np.uint8), MaskConfig(open_px=open_px, close_px=close_px))
    np.testing.assert_array_equal(first, expected)  # the next call does not overwrite what the first returned
    assert again.shape == first.shape
