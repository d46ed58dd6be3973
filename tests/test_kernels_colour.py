"""Colour classification, integral images and S1 window scores (eqs. 5-7) against NumPy references."""

from __future__ import annotations

import kernel_harness as harness
import numpy as np
import pytest
import warp as wp

from wptrack.cameras.rig import Camera, Rig
from wptrack.cameras.structs import ColourMaps, DeviceRig, camera_struct
from wptrack.kernels.colour import hsi as kcolour
from wptrack.kernels.colour import scoring as kscoring
from wptrack.trackers.colour.tracker import HSITarget


def hsi_ref(bgr: np.ndarray):
    """HSI of BGR uint8 pixels in float64: hue degrees, saturation [0, 1], intensity [0, 255]."""
    b, g, r = (bgr[..., k].astype(np.float64) for k in range(3))
    total = r + g + b
    i = total / 3
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(total > 0, 1 - 3 * np.minimum(np.minimum(r, g), b) / total, 0.0)
        num = 0.5 * ((r - g) + (r - b))
        den = np.sqrt((r - g) ** 2 + (r - b) * (g - b))
        h = np.where(den > 1e-6, np.degrees(np.arccos(np.clip(num / den, -1, 1))), 0.0)
    h = np.where((den > 1e-6) & (b > g), 360 - h, h)
    return h, s, i


def match_ref(bgr: np.ndarray, t: HSITarget, eps: float = 0.0):
    """Reference classification; with eps > 0 returns (match, near_threshold) to exclude float32 ties."""
    h, s, i = hsi_ref(bgr)
    hue = (h >= t.hue[0]) & (h <= t.hue[1]) if t.hue[0] <= t.hue[1] else (h >= t.hue[0]) | (h <= t.hue[1])
    m = hue & (s >= t.sat[0]) & (s <= t.sat[1]) & (i >= t.intensity[0]) & (i <= t.intensity[1])
    near = np.zeros_like(m)
    for v, (lo, hi), scale in ((h, t.hue, 360), (s, t.sat, 1), (i, t.intensity, 255)):
        near |= (np.abs(v - lo) < eps * scale) | (np.abs(v - hi) < eps * scale)
    return m, near


def make_rig(rng) -> Rig:
    c1 = Camera.look_at("a", 64, 48, (0.5, 0.0, 0.2), (0.4, 0.45, 0.05), 60.0, dist=[-0.05, 0, 0, 0, 0])
    c2 = Camera.look_at("b", 40, 56, (0.07, 0.485, 0.085), (0.45, 0.45, 0.05), 50.0, roll_deg=90)
    return Rig((c1, c2))


def random_frames(rig: Rig, rng) -> list[np.ndarray]:
    frames = []
    for cam in rig.cameras:
        img = rng.integers(0, 256, (cam.height, cam.width, 3), dtype=np.uint8)
        # plant pink blobs so that windows have a range of counts
        for _ in range(6):
            y, x = rng.integers(0, cam.height), rng.integers(0, cam.width)
            img[max(0, y - 3) : y + 4, max(0, x - 3) : x + 4] = (170, 60, 230)
        frames.append(img)
    return frames


TARGETS = [
    HSITarget(hue=(300, 340), sat=(0.3, 1.0), intensity=(30, 230)),
    HSITarget(hue=(330, 30), sat=(0.2, 0.9)),  # wraps through 0
    HSITarget(hue=(170, 20), sat=(0.05, 1.0)),  # wraps, and covers both halves of the hue circle
    HSITarget(hue=(100, 260), sat=(0.1, 0.8)),  # crosses 180
    HSITarget(hue=(0, 360), sat=(0.5, 1.0)),  # every hue
]


def upload(frames, device):
    return wp.array(np.concatenate([f.reshape(-1) for f in frames]), dtype=wp.uint8, device=device)


def mask_and_integral(drig: DeviceRig, target: HSITarget, bgr, device):
    """Mask and integral image (integral form), and the window map in its forms (per pixel; fused with the mask as
    ColourMaps builds it on a GPU, asserted equal here; per row as on the CPU): returns mask, integral, window,
    window_by_rows."""
    t = target.to_struct(device)
    maps = ColourMaps(drig, device, window=False)
    maps.launch(t, bgr)
    win = ColourMaps(drig, device, window=True)
    win.launch(t, bgr)
    np.testing.assert_array_equal(win.mask.numpy(), maps.mask.numpy())
    m = drig.num_cameras
    per_pixel = wp.zeros(drig.total_pixels, dtype=wp.uint8, device=device)
    wp.launch(
        harness.window_from_mask_kernel,
        dim=(m, drig.max_height, drig.max_width),
        inputs=[drig.cams, maps.mask],
        outputs=[per_pixel],
        device=device,
    )
    mask2 = wp.zeros(drig.total_pixels, dtype=wp.uint8, device=device)
    hsum = wp.zeros(drig.total_pixels, dtype=wp.uint8, device=device)
    by_rows = wp.zeros(drig.total_pixels, dtype=wp.uint8, device=device)
    wp.launch(
        kcolour.mask_rows_kernel,
        dim=(m, drig.max_height),
        inputs=[drig.cams, t, bgr],
        outputs=[mask2, hsum],
        device=device,
    )
    wp.launch(
        kcolour.window_cols_kernel, dim=(m, drig.max_width), inputs=[drig.cams, hsum], outputs=[by_rows], device=device
    )
    np.testing.assert_array_equal(mask2.numpy(), maps.mask.numpy())
    np.testing.assert_array_equal(win.window.numpy(), per_pixel.numpy() if not win.by_rows else by_rows.numpy())
    return maps.mask, maps.integral, per_pixel, by_rows


@pytest.mark.parametrize("target", TARGETS)
def test_mask_matches_reference(device, rng, target):
    rig = make_rig(rng)
    frames = random_frames(rig, rng)
    drig = DeviceRig(rig, device)
    mask, integral, window, by_rows = mask_and_integral(drig, target, upload(frames, device), device)
    m = mask.numpy()
    for c, f in enumerate(frames):
        got = m[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(f.shape[:2]).astype(bool)
        ref, near = match_ref(f, target, eps=1e-4)
        assert 20 < ref.sum() < ref.size - 20  # the test must see both classes
        np.testing.assert_array_equal(got[~near], ref[~near])
        # integral image: exact prefix sums of the kernel's own mask
        ii = integral.numpy()[drig.integral_offsets[c] : drig.integral_offsets[c + 1]].reshape(
            f.shape[0] + 1, f.shape[1] + 1
        )
        ref_ii = np.zeros_like(ii)
        ref_ii[1:, 1:] = np.cumsum(np.cumsum(got.astype(np.int64), 0), 1)
        np.testing.assert_array_equal(ii, ref_ii)
        # window map: 5x5 counts around every pixel, clipped at the borders
        padded = np.pad(got.astype(np.int64), 2)
        ref_win = sum(padded[dy : dy + f.shape[0], dx : dx + f.shape[1]] for dy in range(5) for dx in range(5))
        for w in (window, by_rows):
            win = w.numpy()[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(f.shape[:2])
            np.testing.assert_array_equal(win, ref_win)


def test_hue_wraparound_and_intensity_limits(device):
    t = HSITarget(hue=(340, 20), sat=(0.2, 1.0), intensity=(30, 220))
    # BGR pixels: pure-ish red (hue ~0), magenta-red (hue ~350), orange (hue ~30), too dark red, too bright
    px = np.array([[[20, 20, 200], [70, 30, 200], [0, 120, 230], [2, 2, 20], [250, 250, 255]]], dtype=np.uint8)
    cam = Camera.look_at("p", 5, 1, (0, 0, 0), (0, 1, 0), 5.0)
    drig = DeviceRig(Rig((cam,)), device)
    mask = wp.full(6, 7, dtype=wp.uint8, device=device)
    wp.launch(
        kcolour.target_mask_kernel,
        dim=2,  # 4 pixels per thread: the second thread classifies the fifth pixel and stops at the total
        inputs=[t.to_struct(device), upload([px], device), drig.total_pixels],
        outputs=[mask],
        device=device,
    )
    np.testing.assert_array_equal(mask.numpy(), [1, 1, 0, 0, 0, 7])


def window_ref(cam: Camera, mask2d: np.ndarray, pts: np.ndarray):
    """Reference window counts from cv2 projections (float64); -1 outside; plus points near a pixel edge."""
    uv, depth = cam.project(pts)
    xc = pts @ cam.R.T + cam.t
    r2 = np.sum((xc[:, :2] / xc[:, 2:]) ** 2, axis=1)
    depth = np.where(r2 > camera_struct(cam).r2_max, -1.0, depth)  # beyond the fold radius: not seen
    px = np.floor(uv + 0.5).astype(np.int64)
    frac = np.abs((uv + 0.5) - np.round(uv + 0.5))
    ambiguous = np.any(frac < 1e-3, axis=1)
    out = np.full(len(pts), -1, dtype=np.int64)
    for k, ((x, y), d) in enumerate(zip(px, depth, strict=True)):
        if d <= 0 or x < 0 or y < 0 or x >= cam.width or y >= cam.height:
            continue
        out[k] = mask2d[max(0, y - 2) : y + 3, max(0, x - 2) : x + 3].sum()
    return out, ambiguous


def test_window_counts_direct_equals_integral_and_reference(device, rng):
    rig = make_rig(rng)
    frames = random_frames(rig, rng)
    drig = DeviceRig(rig, device)
    target = TARGETS[0]
    bgr = upload(frames, device)
    mask, integral, window, _ = mask_and_integral(drig, target, bgr, device)
    n = 3000
    pts = rng.uniform([0.0, 0.0, -0.1], [0.9, 0.9, 0.4], (n, 3))
    P = wp.array(pts, dtype=wp.vec3, device=device)
    counts = {}
    for mode in (kscoring.SCORE_DIRECT, kscoring.SCORE_INTEGRAL, kscoring.SCORE_MAP):
        out = wp.zeros((2, n), dtype=wp.int32, device=device)
        wp.launch(
            kscoring.window_count_kernel,
            dim=(2, n),
            inputs=[drig.cams, target.to_struct(device), bgr, integral, window, mode, P],
            outputs=[out],
            device=device,
        )
        counts[mode] = out.numpy()
    np.testing.assert_array_equal(counts[kscoring.SCORE_DIRECT], counts[kscoring.SCORE_INTEGRAL])
    np.testing.assert_array_equal(counts[kscoring.SCORE_DIRECT], counts[kscoring.SCORE_MAP])
    m = mask.numpy()
    inside_total = 0
    for c, cam in enumerate(rig.cameras):
        m2 = m[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(cam.height, cam.width).astype(np.int64)
        ref, amb = window_ref(cam, m2, pts)
        np.testing.assert_array_equal(counts[0][c][~amb], ref[~amb])
        inside_total += int((ref >= 0).sum())
        assert (ref > 0).sum() > 10, "the test scene must produce non-zero windows"
    assert inside_total > 500

    # log-likelihood (eqs. 5-7) from the counts
    loglik = wp.zeros(n, dtype=wp.float32, device=device)
    wp.launch(
        harness.colour_score_kernel,
        dim=n,
        inputs=[drig.cams, target.to_struct(device), bgr, integral, window, kscoring.SCORE_DIRECT, P],
        outputs=[loglik],
        device=device,
    )
    c = counts[0]
    ref_ll = np.sum(np.where(c < 0, np.log(1 / 25), np.log(np.maximum(c, 1) / 25)), axis=0)
    np.testing.assert_allclose(loglik.numpy(), ref_ll, rtol=1e-5, atol=1e-5)


def test_window_map_on_odd_sizes(device, rng):
    """ColourMaps' window map (fused with the mask on a GPU, by rows on the CPU) against the padded NumPy sum of its
    own mask, and that mask against the flat classification kernel, on sizes that are no multiple of the strip or
    the warp's columns (and images narrower or shorter than the window)."""
    sizes = [(1, 1), (5, 3), (3, 9), (13, 21), (40, 17), (57, 30)]
    cams = [Camera.look_at(f"c{k}", w, h, (0.0, -2.0, 1.0), (0.0, 0.0, 0.5), 50.0) for k, (w, h) in enumerate(sizes)]
    drig = DeviceRig(Rig(tuple(cams)), device)
    target = HSITarget(hue=(300, 340), sat=(0.3, 1.0), intensity=(30, 230))
    frames = []
    for w, h in sizes:
        img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        img[rng.random((h, w)) < 0.4] = (170, 60, 230)  # pink: about 40 % of the pixels in the target class
        frames.append(img)
    bgr = upload(frames, device)
    maps = ColourMaps(drig, device, window=True)
    maps.launch(target.to_struct(device), bgr)
    flat = wp.full(drig.total_pixels, 9, dtype=wp.uint8, device=device)
    per = int(kcolour.MASK_PIXELS_PER_THREAD)
    wp.launch(
        kcolour.target_mask_kernel,
        dim=(drig.total_pixels + per - 1) // per,
        inputs=[target.to_struct(device), bgr, drig.total_pixels],
        outputs=[flat],
        device=device,
    )
    mask, window = maps.mask.numpy(), maps.window.numpy()
    np.testing.assert_array_equal(mask, flat.numpy())
    for c, (w, h) in enumerate(sizes):
        m = mask[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(h, w).astype(np.int64)
        assert m.max() <= 1
        if m.size >= 100:
            assert 0.2 < m.mean() < 0.6  # both classes present
        padded = np.pad(m, 2)
        ref = sum(padded[dy : dy + h, dx : dx + w] for dy in range(5) for dx in range(5))
        win = window[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(h, w)
        np.testing.assert_array_equal(win, ref)
