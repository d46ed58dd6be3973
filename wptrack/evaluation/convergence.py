"""Tracking metrics for point trackers: 3D error per frame and convergence."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def position_errors(estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Euclidean 3D error per frame. ``estimates``, ``truth``: (F, 3) metres -> (F,) metres."""
    estimates = np.asarray(estimates, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    if estimates.shape != truth.shape:
        raise ValueError(f"shape mismatch: estimates {estimates.shape} vs truth {truth.shape}")
    return np.linalg.norm(estimates - truth, axis=1)


def convergence_frame(errors: np.ndarray, tol: float = 0.05, hold: int = 10, start: int = 0) -> int | None:
    """First frame ``f >= start`` from which the error stays below ``tol`` metres for ``hold`` frames
    (or until the end of the sequence, if fewer remain). ``None`` if it never converges."""
    errors = np.asarray(errors, dtype=np.float64)
    below = errors < tol
    n = len(errors)
    for f in range(start, n):
        stop = min(n, f + hold)
        if stop - f >= min(hold, n - start) and np.all(below[f:stop]):
            return f
    return None


@dataclass(frozen=True)
class ConvergenceSummary:
    """Error statistics of one run against ground truth (metres, frames)."""

    frames: int
    converged_at: int | None
    mean_error_after: float | None
    median_error_after: float | None
    max_error_after: float | None
    final_error: float

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def summarize(errors: np.ndarray, tol: float = 0.05, hold: int = 10) -> ConvergenceSummary:
    """Convergence frame and the error after convergence (mean, median, max over the remaining frames)."""
    errors = np.asarray(errors, dtype=np.float64)
    f = convergence_frame(errors, tol, hold)
    after = errors[f:] if f is not None else np.array([])
    return ConvergenceSummary(
        frames=len(errors),
        converged_at=f,
        mean_error_after=float(after.mean()) if after.size else None,
        median_error_after=float(np.median(after)) if after.size else None,
        max_error_after=float(after.max()) if after.size else None,
        final_error=float(errors[-1]) if errors.size else float("nan"),
    )
