"""NumPy reference of the S2 multi-view colour descriptor (eqs. 19-21, ``kernels/people/descriptor.py``) for the
``people`` benchmark: the same definition written independently (projection by ``cv2.projectPoints``, hexcone HSV,
two-bin linear interpolation with circular hue, a normalised 2D Gaussian of deviation r_i over the disc), float64, one
particle at a time. It imports neither Warp nor ``wptrack.kernels``."""

from __future__ import annotations

import numpy as np


def hsv(bgr: np.ndarray) -> np.ndarray:
    """``(..., 3)`` uint8 BGR -> ``(..., 3)`` float64 (H in [0, 1), S, V in [0, 1]); grey pixels get H = 0."""
    rgb = bgr[..., ::-1].astype(np.float64) / 255.0
    mx, mn = rgb.max(-1), rgb.min(-1)
    d = mx - mn
    s = np.where(mx > 0, 1.0 - mn / np.where(mx > 0, mx, 1.0), 0.0)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    dd = np.where(d > 0, d, 1.0)
    h = np.where(mx == r, ((g - b) / dd) % 6.0, np.where(mx == g, 2.0 + (b - r) / dd, 4.0 + (r - g) / dd))
    h = np.where(d > 0, h / 6.0, 0.0)
    h = np.where(h >= 1.0, h - 1.0, h)
    return np.stack([h, s, mx], axis=-1)


def _bins(x: np.ndarray, nb: int, wrap: bool) -> np.ndarray:
    """Two-bin linear interpolation of values in [0, 1] into ``nb`` bins centred at (k + 1/2) / nb: (P, nb)."""
    out = np.zeros((len(x), nb))
    t = x * nb - 0.5
    k0 = np.floor(t).astype(int)
    f = t - k0
    rows = np.arange(len(x))
    if wrap:
        np.add.at(out, (rows, k0 % nb), 1.0 - f)
        np.add.at(out, (rows, (k0 + 1) % nb), f)
    else:
        lo, hi = k0 < 0, k0 >= nb - 1
        mid = ~(lo | hi)
        np.add.at(out, (rows[lo], 0), 1.0)
        np.add.at(out, (rows[hi], nb - 1), 1.0)
        np.add.at(out, (rows[mid], k0[mid]), 1.0 - f[mid])
        np.add.at(out, (rows[mid], k0[mid] + 1), f[mid])
    return out


def descriptor(
    cameras: list,
    images: list[np.ndarray],
    points: np.ndarray,
    r_n: float,
    nb: int,
    r_min: float,
    r_max: float,
    step: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """D(P) of every point: ``(desc (N, 3 nb), mass (N,))`` over all cameras together (eqs. 19-21).

    Args:
        cameras: objects with ``K``, ``dist``, ``rvec``, ``t``, ``R``, ``width``, ``height``, ``fx``, ``fy``
            (``wptrack.cameras.rig.Camera``). images: one (H, W, 3) uint8 BGR image per camera. points: (N, 3) metres.
    """
    import cv2

    n = len(points)
    desc = np.zeros((n, 3 * nb))
    mass = np.zeros(n)
    for cam, img in zip(cameras, images, strict=True):
        planes = hsv(img)
        uv, _ = cv2.projectPoints(points.reshape(-1, 1, 3), cam.rvec, cam.t, cam.K, cam.dist)
        uv = uv.reshape(-1, 2)
        depth = (points @ cam.R.T + cam.t)[:, 2]
        f = 0.5 * (cam.fx + cam.fy)
        for i in range(n):
            if depth[i] <= 1e-6:
                continue
            r = float(np.clip(f * r_n / depth[i], r_min, r_max))
            u, v = uv[i]
            x0, x1 = max(int(np.ceil(u - r)), 0), min(int(np.floor(u + r)), cam.width - 1)
            y0, y1 = max(int(np.ceil(v - r)), 0), min(int(np.floor(v + r)), cam.height - 1)
            if x1 < x0 or y1 < y0:
                continue
            ys, xs = np.mgrid[y0 : y1 + 1 : step, x0 : x1 + 1 : step]  # every step-th pixel from the disc's corner
            d2 = (xs - u) ** 2 + (ys - v) ** 2
            sel = d2 <= r * r
            if not sel.any():
                continue
            w = step * step * np.exp(-0.5 * d2[sel] / (r * r)) / (2 * np.pi * r * r)
            px = planes[ys[sel], xs[sel]]
            for k, wrap in enumerate((True, False, False)):
                desc[i, k * nb : (k + 1) * nb] += (w[:, None] * _bins(px[:, k], nb, wrap)).sum(0)
            mass[i] += w.sum()
    ok = mass > 0
    desc[ok] /= mass[ok, None]
    return desc, mass
