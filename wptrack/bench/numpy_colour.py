"""Plain NumPy reference of the S1 colour particle filter (Barrera et al., eqs. 1-7), for the benchmark's
equivalence check and CPU baseline. Same algorithm as ``wptrack.trackers.colour.tracker.ColorTracker`` (gaussian walk,
HSI target mask, 5x5 window counts through an integral image, product over cameras in log space, systematic
resampling every frame), written for clarity with vectorised NumPy; its random numbers come from NumPy, so it
agrees with the Warp tracker statistically, not bit for bit."""

from __future__ import annotations

import numpy as np

from wptrack.cameras.rig import Rig


def hsi_mask(bgr: np.ndarray, hue, sat, intensity) -> np.ndarray:
    """(H, W) bool target mask of a BGR uint8 image (paper, section II.B)."""
    b, g, r = (bgr[..., k].astype(np.float32) for k in range(3))
    total = r + g + b
    i = total / 3.0
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(total > 0, 1.0 - 3.0 * np.minimum(np.minimum(r, g), b) / total, 0.0)
        num = 0.5 * ((r - g) + (r - b))
        den = np.sqrt((r - g) ** 2 + (r - b) * (g - b))
        h = np.where(den > 1e-6, np.degrees(np.arccos(np.clip(num / den, -1.0, 1.0))), 0.0)
    h = np.where((den > 1e-6) & (b > g), 360.0 - h, h)
    hue_ok = (h >= hue[0]) & (h <= hue[1]) if hue[0] <= hue[1] else (h >= hue[0]) | (h <= hue[1])
    return hue_ok & (s >= sat[0]) & (s <= sat[1]) & (i >= intensity[0]) & (i <= intensity[1])


def project(cam, x: np.ndarray):
    """OpenCV pinhole + distortion projection of (N, 3) world points: (u, v, seen) arrays."""
    xc = x @ cam.R.T + cam.t
    z = xc[:, 2]
    seen = z > 1e-6
    zs = np.where(seen, z, 1.0)
    a, b = xc[:, 0] / zs, xc[:, 1] / zs
    r2 = a * a + b * b
    k1, k2, p1, p2, k3 = cam.dist
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    ad = a * radial + 2 * p1 * a * b + p2 * (r2 + 2 * a * a)
    bd = b * radial + p1 * (r2 + 2 * b * b) + 2 * p2 * a * b
    return cam.fx * ad + cam.cx, cam.fy * bd + cam.cy, seen


class NumpyColorFilter:
    """The S1 filter in NumPy. ``step(images)`` returns (mean, std, map) in metres."""

    def __init__(
        self,
        rig: Rig,
        hue,
        sat,
        intensity,
        particles: int,
        sigma: float,
        init,
        seed: int = 0,
        r2_max: list[float] | None = None,
    ) -> None:
        self.rig, self.hue, self.sat, self.intensity = rig, hue, sat, intensity
        self.n, self.sigma = particles, sigma
        self.rng = np.random.default_rng(seed)
        self.x = np.tile(np.asarray(init, dtype=np.float64), (particles, 1))
        self.r2_max = r2_max or [np.inf] * len(rig)

    def step(self, images):
        x = self.x + self.rng.normal(0.0, self.sigma, self.x.shape)  # eqs. 1-3
        logw = np.zeros(self.n)
        for cam, img, r2max in zip(self.rig.cameras, images, self.r2_max, strict=True):
            mask = hsi_mask(img, self.hue, self.sat, self.intensity)
            ii = np.zeros((cam.height + 1, cam.width + 1), dtype=np.int64)
            ii[1:, 1:] = mask.cumsum(0).cumsum(1)
            u, v, seen = project(cam, x)
            xc = x @ cam.R.T + cam.t
            with np.errstate(invalid="ignore", divide="ignore"):
                r2 = (xc[:, 0] ** 2 + xc[:, 1] ** 2) / xc[:, 2] ** 2
            px, py = np.floor(u + 0.5).astype(np.int64), np.floor(v + 0.5).astype(np.int64)
            inside = seen & (r2 <= r2max) & (px >= 0) & (py >= 0) & (px < cam.width) & (py < cam.height)
            x0 = np.clip(px - 2, 0, cam.width - 1)
            x1 = np.clip(px + 2, 0, cam.width - 1) + 1
            y0 = np.clip(py - 2, 0, cam.height - 1)
            y1 = np.clip(py + 2, 0, cam.height - 1) + 1
            m = ii[y1, x1] - ii[y0, x1] - ii[y1, x0] + ii[y0, x0]  # eq. 7 window count
            m = np.where(inside, np.maximum(m, 1), 1)  # eq. 6: outside -> 1/25
            logw += np.log(m / 25.0)  # eq. 5 in log space
        w = np.exp(logw - logw.max())
        wn = w / w.sum()
        mean = wn @ x
        std = np.sqrt(np.maximum(wn @ (x * x) - mean * mean, 0.0))
        best = x[np.argmax(logw)]
        cdf = np.cumsum(wn)  # systematic resampling (float64)
        u = (np.arange(self.n) + self.rng.random()) / self.n
        self.x = x[np.minimum(np.searchsorted(cdf, u, side="right"), self.n - 1)]
        return mean, std, best
