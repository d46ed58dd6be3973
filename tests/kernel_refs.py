"""NumPy references shared by the tests/test_kernels_*_extra.py modules: the counter-based random draws of
``kernels.core.random`` (from the NumPy Philox of test_kernels_random) and the per-block partials of
``kernels.core.reduce``."""

from __future__ import annotations

import numpy as np
from test_kernels_random import philox_ref

from wptrack.kernels.core import reduce as kreduce


def uniform4_ref(seed: tuple[int, int], n: int, frame: int, stream: int) -> np.ndarray:
    """(n, 4) float64 of ``random.uniform4`` from the NumPy Philox of test_kernels_random (exact: 24-bit values)."""
    ctr = np.stack([np.arange(n), np.full(n, frame), np.full(n, stream), np.zeros(n)], axis=1).astype(np.uint64)
    w = philox_ref(ctr, seed)
    return ((w >> np.uint32(8)).astype(np.float64) + 0.5) / 16777216.0


def normal4_ref(seed: tuple[int, int], n: int, frame: int, stream: int) -> np.ndarray:
    """(n, 4) float64 of ``random.normal4``: two Box-Muller transforms of the NumPy Philox uniforms."""
    u = uniform4_ref(seed, n, frame, stream)
    r0, r1 = np.sqrt(-2 * np.log(u[:, 0])), np.sqrt(-2 * np.log(u[:, 2]))
    a0, a1 = 2 * np.pi * u[:, 1], 2 * np.pi * u[:, 3]
    return np.column_stack([r0 * np.cos(a0), r0 * np.sin(a0), r1 * np.cos(a1), r1 * np.sin(a1)])


def partials_ref(logw: np.ndarray, x: np.ndarray, chunk: int):
    """Per block of ``chunk`` particles: max log-weight (after the floor), lowest index attaining it, and the sums of
    w, w^2, w x (3), w x^2 (3) with w = exp(logw - block max), float64."""
    lw = np.where(np.isnan(logw) | (logw < kreduce.LOGW_FLOOR), kreduce.LOGW_FLOOR, logw).astype(np.float64)
    pm, pa, part = [], [], []
    for s in range(0, len(lw), chunk):
        b, xb = lw[s : s + chunk], x[s : s + chunk].astype(np.float64)
        m = b.max()
        w = np.exp(b - m)
        pm.append(m)
        pa.append(s + int(np.argmax(b == m)))
        part.append(np.r_[w.sum(), (w * w).sum(), w @ xb, w @ (xb * xb)])
    return np.array(pm), np.array(pa), np.array(part)


def check_partials(got, logw, x, chunk, rtol: float = 2e-6):
    """Compare a kernel's block partials ``got = (part_max, part_arg, part)`` with :func:`partials_ref` of its own
    log-weights and positions: max and index exactly, the sums to ``rtol`` (the kernels take a float32 exp; pass a
    looser ``rtol`` for modules compiled with fast_math on CUDA, whose __expf error grows with |logw - max|)."""
    pm, pa, part = partials_ref(logw, x, chunk)
    np.testing.assert_array_equal(got[0], pm.astype(np.float32))
    np.testing.assert_array_equal(got[1], pa)
    np.testing.assert_allclose(got[2], part, rtol=rtol, atol=1e-12)
