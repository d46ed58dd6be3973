"""Block reductions (max/argmax, weighted moments, ESS) against NumPy, at sizes that are not multiples of
the block, on every device (the CPU backend runs one thread per block: the pattern must hold there too)."""

from __future__ import annotations

import kernel_harness as harness
import numpy as np
import pytest
import warp as wp

from wptrack.kernels.core import reduce as kred

BLOCK = 256


def run_reduction(device, logw: np.ndarray, x: np.ndarray, chunk: int, threshold: float = 0.5):
    """One-pass block partials (max, MAP index, online-rescaled sums), then the one-block final combination."""
    n = len(logw)
    nb = (n + chunk - 1) // chunk
    L = wp.array(logw.astype(np.float32), device=device)
    X = wp.array(x.astype(np.float32), dtype=wp.vec3, device=device)
    pm = wp.zeros(nb, dtype=wp.float32, device=device)
    pa = wp.zeros(nb, dtype=wp.int32, device=device)
    est = wp.zeros(kred.EST_SIZE, dtype=wp.float64, device=device)
    bi = wp.zeros(1, dtype=wp.int32, device=device)
    part = wp.zeros((nb, kred.N_SUMS), dtype=wp.float64, device=device)
    thr = wp.array([threshold], dtype=wp.float32, device=device)
    flag = wp.zeros(1, dtype=wp.int32, device=device)
    wp.launch_tiled(
        harness.block_partials_kernel,
        dim=[nb],
        inputs=[L, X, n, chunk],
        outputs=[pm, pa, part],
        block_dim=BLOCK,
        device=device,
    )
    wp.launch_tiled(
        kred.final_moments_kernel,
        dim=[1],
        inputs=[pm, pa, part, nb, n, X, thr],
        outputs=[est, bi, flag],
        block_dim=BLOCK,
        device=device,
    )
    return est.numpy(), int(bi.numpy()[0]), int(flag.numpy()[0])


@pytest.mark.parametrize("order", ["random", "increasing", "decreasing"])
@pytest.mark.parametrize("n,chunk", [(1, 256), (255, 256), (257, 256), (5000, 256), (70_001, 1024)])
def test_moments_match_numpy(device, rng, n, chunk, order):
    """The running-max rescaling gives the two-pass result whatever the order: increasing log-weights rescale the
    partials at every particle, a spread of 60 nats makes early partials underflow to zero."""
    logw = (rng.normal(size=n) * (15 if order != "random" else 4) - 50).astype(np.float32)
    if order != "random":
        logw = np.sort(logw) if order == "increasing" else np.sort(logw)[::-1].copy()
    x = (rng.normal(size=(n, 3)) * [1.0, 0.1, 3.0] + [0.5, -2.0, 1.0]).astype(np.float32)
    est, best, flag = run_reduction(device, logw, x, chunk)
    l64 = logw.astype(np.float64)
    wr = np.exp(l64 - l64.max())
    x64 = x.astype(np.float64)
    mean = (wr[:, None] * x64).sum(0) / wr.sum()
    std = np.sqrt((wr[:, None] * (x64 - mean) ** 2).sum(0) / wr.sum())
    ess = wr.sum() ** 2 / (wr**2).sum()
    assert best == int(np.argmax(logw))  # the lowest index of the maximum, as np.argmax
    # weights are float32 exponentials of the float32 log-weights (relative error ~1e-7), summed in float64
    np.testing.assert_allclose(est[kred.EST_MEAN : kred.EST_MEAN + 3], mean, rtol=3e-7, atol=1e-9)
    # the spread is E[x^2] - mean^2: its absolute precision is that of E[x^2] (float32 weights: ~1e-7 relative)
    ex2 = (wr[:, None] * x64**2).sum(0) / wr.sum()
    np.testing.assert_allclose(est[kred.EST_STD : kred.EST_STD + 3] ** 2, std**2, rtol=1e-6, atol=1e-6 * ex2.max())
    np.testing.assert_allclose(est[kred.EST_MAP : kred.EST_MAP + 3], x[best], rtol=1e-7)
    np.testing.assert_allclose(est[kred.EST_ESS], ess, rtol=3e-7)
    np.testing.assert_allclose(est[kred.EST_LOGLIK], l64.max() + np.log(wr.mean()), rtol=0, atol=3e-7)
    assert est[kred.EST_MAXLOGW] == pytest.approx(float(logw.max()))
    assert flag == int(ess <= 0.5 * n)


def test_argmax_ties_pick_lowest_index(device):
    n = 3000
    logw = np.zeros(n, dtype=np.float32)
    logw[[2999, 1700, 700]] = 5.0
    _, best, _ = run_reduction(device, logw, np.zeros((n, 3)), 256)
    assert best == 700


def test_uniform_weights_full_ess_and_resample_flag(device):
    n = 1000
    est, _, flag = run_reduction(device, np.full(n, -3.0, np.float32), np.ones((n, 3)), 256, threshold=0.5)
    assert est[kred.EST_ESS] == pytest.approx(n)
    assert flag == 0  # ESS = N > N/2: no resampling
    est, _, flag = run_reduction(device, np.full(n, -3.0, np.float32), np.ones((n, 3)), 256, threshold=1.0)
    assert flag == 1  # threshold 1: every frame


def test_subsample_weights_relative_to_best(device, rng):
    n, stride = 1000, 7
    logw = (rng.normal(size=n) * 3).astype(np.float32)
    x = rng.normal(size=(n, 3)).astype(np.float32)
    est = np.zeros(kred.EST_SIZE)
    est[kred.EST_MAXLOGW] = float(logw.max())
    k = n // stride
    sx = wp.zeros(k, dtype=wp.vec3, device=device)
    sw = wp.zeros(k, dtype=wp.float32, device=device)
    wp.launch(
        kred.subsample_kernel,
        dim=k,
        inputs=[
            wp.array(x, dtype=wp.vec3, device=device),
            wp.array(logw, device=device),
            wp.array(est, dtype=wp.float64, device=device),
            stride,
        ],
        outputs=[sx, sw],
        device=device,
    )
    idx = np.arange(k) * stride
    np.testing.assert_array_equal(sx.numpy(), x[idx])
    np.testing.assert_allclose(sw.numpy(), np.exp(logw[idx].astype(np.float64) - logw.max()), rtol=1e-6)
