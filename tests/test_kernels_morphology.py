"""Device clean-up of motion masks (issue 27, kernels.core.morphology, wptrack.motion.cleanup) against the host
functions it replaces (OpenCV's morphology, the connected-components hysteresis, resolve_levels + clean_mask), on
every device."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import warp as wp

from wptrack.kernels.core import morphology as km
from wptrack.motion.cleanup import DeviceCleanup, ellipse_runs
from wptrack.motion.levels import hysteresis, resolve_levels
from wptrack.motion.masks import MaskConfig, clean_mask


def _blobs(rng, h: int, w: int, cut: float) -> np.ndarray:
    """A 0/1 mask of smooth random blobs (about ``1 - cut`` of the pixels on)."""
    small = rng.random((max(h // 6, 2), max(w // 6, 2))).astype(np.float32)
    return (cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC) > cut).astype(np.uint8)


@pytest.mark.parametrize("diameter", [3, 5, 7])
def test_morph_kernel_equals_opencv(device, rng, diameter):
    q = _blobs(rng, 37, 53, 0.55)
    q[0, :] = 1  # foreground on the border: the erosion must not eat it from outside
    runs = ellipse_runs(diameter)
    se = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (diameter, diameter))
    assert int(sum(r[2] - r[1] + 1 for r in runs)) == int(se.sum())
    src = wp.array(q, dtype=wp.uint8, device=device)
    dst = wp.zeros_like(src)
    element = wp.array(runs, dtype=wp.vec3i, device=device)
    for erode, op in ((1, cv2.erode), (0, cv2.dilate)):
        wp.launch(km.morph_kernel, dim=q.shape, inputs=[src, element, len(runs), erode], outputs=[dst], device=device)
        np.testing.assert_array_equal(dst.numpy(), op(q, se))


def _packed(rng, h: int, w: int) -> np.ndarray:
    """Levels 0/1/2 and shadow codes 0/1/2 with structure: strong cores, weak fringes and a weak snake that turns
    back on itself (many sweeps), shadow cores with penumbra rims."""
    strong = _blobs(rng, h, w, 0.8)
    weak = _blobs(rng, h, w, 0.45)
    levels = np.where(strong == 1, 2, np.where(weak == 1, 1, 0)).astype(np.uint8)
    snake = np.zeros((h, w), np.uint8)
    for k, y in enumerate(range(2, h - 2, 4)):  # a serpentine of weak pixels from a strong seed
        snake[y, 2 : w - 2] = 1
        x = w - 3 if k % 2 == 0 else 2
        snake[y : y + 4, x] = 1
    levels = np.where((snake == 1) & (levels == 0), 1, levels).astype(np.uint8)
    levels[2, 2] = 2
    shadow = np.zeros((h, w), np.uint8)
    core = _blobs(rng, h, w, 0.85)
    rim = cv2.dilate(core, np.ones((9, 9), np.uint8))
    shadow[(rim == 1) & (rng.random((h, w)) < 0.7)] = 1
    shadow[core == 1] = 2
    shadow[rng.random((h, w)) < 0.02] = 1  # scattered penumbra candidates far from any core
    return (levels + 4 * shadow).astype(np.uint8)


def _device_hysteresis(levels: np.ndarray, device) -> tuple[np.ndarray, np.ndarray]:
    """The union-find kernels' ``(mask, labels)`` of ``levels`` (``(H, W)`` uint8 0/1/2)."""
    h, w = levels.shape
    lv = wp.array(levels, dtype=wp.uint8, device=device)
    labels = wp.zeros(h * w, dtype=wp.int32, device=device)
    strong = wp.zeros(h * w, dtype=wp.uint8, device=device)
    mask = wp.zeros((h, w), dtype=wp.uint8, device=device)
    wp.launch(km.label_init_kernel, dim=(h, w), inputs=[lv], outputs=[labels], device=device)
    wp.launch(km.label_merge_kernel, dim=(h, w), inputs=[lv, labels], device=device)
    wp.launch(km.label_flatten_kernel, dim=(h, w), inputs=[lv, labels], device=device)
    wp.launch(km.strong_roots_kernel, dim=(h, w), inputs=[lv, labels], outputs=[strong], device=device)
    wp.launch(km.hysteresis_kernel, dim=(h, w), inputs=[lv, labels, strong], outputs=[mask], device=device)
    return mask.numpy(), labels.numpy().reshape(h, w)


def _min_index_labels(levels: np.ndarray) -> np.ndarray:
    """NumPy/OpenCV reference of the union-find labels: each pixel of ``levels > 0`` labelled with the smallest
    row-major index of its 8-connected component, -1 elsewhere."""
    count, cc = cv2.connectedComponents((levels > 0).view(np.uint8), connectivity=8)
    flat = cc.reshape(-1)
    first = np.full(count, flat.size, np.int64)
    np.minimum.at(first, flat, np.arange(flat.size))
    out = first[flat].astype(np.int32)
    out[flat == 0] = -1
    return out.reshape(levels.shape)


def test_hysteresis_kernels_equal_connected_components(device, rng):
    """Structured levels (blobs, a serpentine of weak pixels that turns back on itself, scattered shadows) and
    random ones at densities around the percolation threshold (long, branching components whose trees are joined
    from many threads at once): the labels are each component's smallest pixel index, the mask the host's."""
    cases = [_packed(rng, 41, 60) & 3 for _ in range(3)]
    for density, strong in ((0.3, 0.01), (0.6, 0.002), (0.75, 0.0005), (0.9, 0.0)):
        levels = (rng.random((97, 131)) < density).astype(np.uint8)
        levels[(rng.random(levels.shape) < strong) & (levels > 0)] = 2
        cases.append(levels)
    cases.append(np.zeros((5, 7), np.uint8))
    cases.append(np.full((6, 9), 2, np.uint8))
    for levels in cases:
        mask, labels = _device_hysteresis(levels, device)
        np.testing.assert_array_equal(mask, hysteresis(levels.copy()))
        np.testing.assert_array_equal(labels, _min_index_labels(levels))


@pytest.mark.parametrize(("open_px", "close_px"), [(3, 5), (0, 0), (5, 0), (0, 7)])
def test_device_cleanup_equals_resolve_levels_and_clean_mask(device, rng, open_px, close_px):
    h, w = 48, 64
    config = MaskConfig(open_px=open_px, close_px=close_px)
    clean = DeviceCleanup(w, h, open_px, close_px, device)
    for _ in range(3):
        packed = _packed(rng, h, w)
        prob = rng.random((h, w)).astype(np.float32)
        expected_prob = prob.copy()
        expected = clean_mask(resolve_levels(packed.copy(), expected_prob), config)
        d_prob = wp.array(prob, dtype=wp.float32, device=device)
        got = clean(wp.array(packed, dtype=wp.uint8, device=device), d_prob)
        np.testing.assert_array_equal(got.numpy(), expected)
        np.testing.assert_array_equal(d_prob.numpy(), expected_prob)
        assert expected.sum() > 0


def test_device_cleanup_rejects_negative_sizes():
    from wptrack.core.errors import ConfigError

    with pytest.raises(ConfigError, match="DeviceCleanup.open_px"):
        DeviceCleanup(8, 8, -1, 5, "cpu")
