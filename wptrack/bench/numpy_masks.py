"""NumPy reference of the offline background model's kernels (:mod:`wptrack.kernels.core.background`), for the tests
and the ``masks`` benchmark: same formulas, float64 instead of float32."""

from __future__ import annotations

import numpy as np

MAD_TO_SIGMA = 1.4826


def median_mad(stack: np.ndarray, gains: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Lower median and MAD over axis 0 of a ``(K, 3 P)`` uint8 stack (0-based order statistic ``(K - 1) // 2``),
    each sample first divided by its ``(K, 3)`` channel gains (rounded half up, clamped to 0..255)."""
    rank = (stack.shape[0] - 1) // 2
    if gains is not None:
        k = stack.shape[0]
        g = np.asarray(gains, dtype=np.float64)[:, None, :]
        stack = np.clip(np.floor(stack.reshape(k, -1, 3) / g + 0.5), 0, 255).astype(np.uint8).reshape(k, -1)
    median = np.partition(stack, rank, axis=0)[rank]
    dev = np.abs(stack.astype(np.int16) - median.astype(np.int16)).astype(np.uint8)
    return median, np.partition(dev, rank, axis=0)[rank]


def neighbourhood(
    packed: np.ndarray, diff: np.ndarray, radius: int, low_threshold: float, scale: float = 1.0
) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.core.background.neighbourhood_kernel` on ``(H, W)`` packed levels and
    ``(H, W, 3)`` normalised differences (box sums over the usable neighbours, zero outside the image)."""
    import cv2

    usable = (((packed & 3) < 2) & ((packed >> 2) == 0)).astype(np.float64)
    k = (2 * radius + 1, 2 * radius + 1)

    def box(a: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(a, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)

    n = box(usable)
    acc = np.stack([box(diff[..., c].astype(np.float64) * usable) for c in range(3)], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        z2 = np.where(n > 0, scale**2 * (acc * acc).sum(axis=-1) / (3.0 * np.maximum(n, 1.0)), 0.0)
    target = ((packed & 3) == 0) & ((packed >> 2) != 2) & (n > 0) & (z2 > low_threshold**2)
    return (packed + target).astype(np.uint8)


def foreground(
    frame: np.ndarray,
    bg0: np.ndarray,
    mad0: np.ndarray,
    bg1: np.ndarray,
    mad1: np.ndarray,
    w: float,
    threshold: float,
    soft_scale: float,
    noise_floor: float,
    shadow: bool,
    shadow_lo: float,
    shadow_hi: float,
    chroma_max: float,
    gain: np.ndarray | None = None,
    low_threshold: float | None = None,
    spread_cap: float = 0.0,
    shadow_edge_hi: float | None = None,
    radius: int = 0,
    nb_scale: float = 1.0,
) -> dict[str, np.ndarray]:
    """Per-pixel ``z``, shadow flag, probability, level (0/1/2) and mask of ``(H, W, 3)`` uint8 images (module
    formulas), the frame divided by its ``(3,)`` channel ``gain`` first; ``low_threshold`` (default: ``threshold``)
    is the hysteresis threshold, ``spread_cap`` the largest noise scale (8-bit units, 0: none), ``shadow_edge_hi``
    (default ``shadow_hi``) the penumbra candidates' upper ratio. ``packed`` is the kernel's ``level + 4 shadow``;
    ``mask`` is :func:`wptrack.motion.background.resolve_levels` of it (after :func:`neighbourhood` with ``radius`` and
    ``nb_scale`` when ``radius > 0``) for 2-D images, ``level == 2`` otherwise."""
    from wptrack.motion.background import resolve_levels

    edge_hi = shadow_hi if shadow_edge_hi is None else shadow_edge_hi
    low = threshold if low_threshold is None else low_threshold
    b = (1.0 - w) * bg0.astype(np.float64) + w * bg1.astype(np.float64)
    m = (1.0 - w) * mad0.astype(np.float64) + w * mad1.astype(np.float64)
    x = frame.astype(np.float64) / (1.0 if gain is None else np.asarray(gain, dtype=np.float64))
    spread = MAD_TO_SIGMA * np.sqrt((m * m).sum(-1) / 3.0)
    if spread_cap > 0:
        spread = np.minimum(spread, spread_cap)
    s = np.maximum(noise_floor, spread)
    z = np.sqrt(((x - b) ** 2).sum(-1) / 3.0) / s
    bb = (b * b).sum(-1)
    ib = (x * b).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(bb >= 1.0, ib / np.maximum(bb, 1.0), 0.0)
        cd = np.linalg.norm(x - a[..., None] * b, axis=-1) / np.sqrt(np.maximum(bb, 1.0))
    candidate = shadow & (bb >= 1.0) & (z > low) & (a >= shadow_lo) & (cd <= chroma_max)
    is_shadow = candidate & (a <= shadow_hi)
    penumbra = candidate & (a > shadow_hi) & (a <= edge_hi)
    prob = np.where(is_shadow, 0.0, 1.0 / (1.0 + np.exp(-(z - threshold) / soft_scale)))
    level = np.where(is_shadow, 0, np.where(z > threshold, 2, np.where(z > low, 1, 0))).astype(np.uint8)
    packed = (level + 4 * (2 * is_shadow + penumbra)).astype(np.uint8)
    diff = (x - b) / s[..., None]
    if level.ndim == 2:
        prob = prob.astype(np.float32)
        final = neighbourhood(packed, diff, radius, low, nb_scale) if radius > 0 else packed
        mask = resolve_levels(final.copy(), prob).astype(bool)
    else:
        mask = level == 2
    return {
        "diff": diff, "z": z, "a": a, "cd": cd, "shadow": is_shadow, "penumbra": penumbra, "prob": prob, "level": level,
        "packed": packed, "mask": mask,
    }  # fmt: skip
