"""``occupancy.log_norm_kernel`` against NumPy on every device: the log normaliser log sum_i exp(logw_i) that the
occupancy grid (eqs. 2-3) divides by, from a filter's estimate vector (its log mean weight) as the people tracker
launches it, equals NumPy's logsumexp of the log-weights (at sizes that are not multiples of the block)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from scipy.special import logsumexp
from test_kernels_reduce import run_reduction

from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.people import occupancy as kocc


def log_norm(device, est: np.ndarray, slot: int, n: int) -> float:
    out = wp.full(1, 7.0, dtype=wp.float64, device=device)
    wp.launch(
        kocc.log_norm_kernel,
        dim=1,
        inputs=[wp.array(est, dtype=wp.float64, device=device), slot, n],
        outputs=[out],
        device=device,
    )
    return float(out.numpy()[0])


@pytest.mark.parametrize(("n", "chunk"), [(1, 256), (777, 256), (5000, 1024)])
def test_log_norm_is_logsumexp_of_the_log_weights(device, rng, n, chunk):
    logw = rng.normal(-40.0, 15.0, n)  # a spread of ~100 nats: exp(logw) alone underflows in float32
    x = rng.normal(size=(n, 3))
    est, _, _ = run_reduction(device, logw, x, chunk)
    got = log_norm(device, est, int(kreduce.EST_LOGLIK), n)
    assert got == pytest.approx(logsumexp(logw.astype(np.float32).astype(np.float64)), abs=1e-5)


def test_log_norm_reads_the_given_slot(device):
    est = np.arange(16, dtype=np.float64) - 5.0
    assert log_norm(device, est, 3, 10) == pytest.approx(-2.0 + np.log(10), abs=1e-12)
    assert log_norm(device, est, 10, 1) == 5.0
