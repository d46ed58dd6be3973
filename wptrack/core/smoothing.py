"""Offline fixed-interval smoothing of a completed run's trajectories (beyond the papers: both trackers report each
frame's filtered estimate, which has seen the frames up to it only; once the whole recording is tracked, the frames
after it are known too).

Each track's positions are replaced by a locally weighted linear regression on time (LOESS of degree 1, Cleveland,
"Robust locally weighted regression and smoothing scatterplots", JASA 1979, without the robustness iterations):
at a row of frame ``t``, the constant-velocity line fitted by weighted least squares to the track's rows within
``t +- W`` frames, tricube weights ``(1 - (|d| / (W + 1))^3)^3``, evaluated at ``t``. A line through the data is
reproduced exactly (a person walking at constant velocity keeps every position), the jitter of a filter's estimate
around it is averaged over ~W frames, a track's first and last rows are fitted on one side without being pulled
inwards, and frames missing from a track (a stitch's gap) only lower the weight there. The smoother is linear in
the positions, so smoothing ``x, y, z`` column by column keeps any affine relation between them (a ground plane's
coordinates and their world point).
"""

from __future__ import annotations

import numpy as np

__all__ = ["smooth_track", "tricube"]


def tricube(half_window: int) -> tuple[np.ndarray, np.ndarray]:
    """``(d, w)``: the offsets ``-W .. W`` (frames) and their tricube weights."""
    d = np.arange(-half_window, half_window + 1, dtype=np.float64)
    return d, (1.0 - (np.abs(d) / (half_window + 1)) ** 3) ** 3


def smooth_track(frames: np.ndarray, values: np.ndarray, half_window: int) -> np.ndarray:
    """One track's positions smoothed (see the module docstring).

    Args:
        frames: ``(n,)`` distinct integer frame indices of the track's rows (any order).
        values: ``(n, k)`` the rows' positions (or any columns to smooth), e.g. metres.
        half_window: ``W``, frames (0: the values as they are).

    Returns:
        ``(n, k)`` float64 smoothed values, row for row; a row whose window holds no two distinct frames keeps its
        value.
    """
    frames = np.asarray(frames, dtype=np.int64)
    vals = np.asarray(values, dtype=np.float64).reshape(len(frames), -1)
    if half_window <= 0 or len(frames) < 2:
        return vals.copy()
    w_half = int(half_window)
    f0 = int(frames.min())
    length = int(frames.max()) - f0 + 1
    idx = frames - f0
    present = np.zeros(length + 2 * w_half)  # the track on a dense frame axis, padded by W on both sides
    present[idx + w_half] = 1.0
    dense = np.zeros((length + 2 * w_half, vals.shape[1]))
    dense[idx + w_half] = vals
    d, w = tricube(w_half)

    def window_sum(a: np.ndarray, kernel: np.ndarray) -> np.ndarray:  # sum_d kernel(d) a(t + d), at every t
        return np.correlate(a, kernel, mode="valid")

    s0, s1, s2 = (window_sum(present, w * d**j) for j in range(3))
    det = s0 * s2 - s1 * s1
    out = vals.copy()
    fit = det[idx] > 1e-9 * np.maximum(s0[idx] * s2[idx], 1.0)  # two distinct frames in the window at least
    rows = idx[fit]
    for c in range(vals.shape[1]):
        t0 = window_sum(dense[:, c], w)
        t1 = window_sum(dense[:, c], w * d)
        out[fit, c] = (s2[rows] * t0[rows] - s1[rows] * t1[rows]) / det[rows]  # the fitted line's value at t
    return out
