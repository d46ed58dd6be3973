"""All log-weights -inf (or NaN): the documented recovery "keep the prior" (uniform weights over the predicted
cloud), finite estimates and the ``degenerate`` flag, on every device; one live particle among floored ones
still takes all the weight."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_kernels_reduce import run_reduction
from wptrack.kernels.core import reduce as kred
from wptrack.trackers.colour.gaussian3d import Gaussian3DTracker


@pytest.mark.parametrize("bad", [-np.inf, np.nan, -3.0e38])
@pytest.mark.parametrize("n,chunk", [(1, 256), (3000, 256)])
def test_all_dead_weights_give_uniform_finite_estimate(device, rng, bad, n, chunk):
    x = rng.normal(size=(n, 3)).astype(np.float32)
    est, best, _ = run_reduction(device, np.full(n, bad, np.float32), x, chunk)
    assert np.all(np.isfinite(est[: kred.EST_SIZE - 3]))
    assert est[kred.EST_DEGENERATE] == 1.0
    np.testing.assert_allclose(est[kred.EST_MEAN : kred.EST_MEAN + 3], x.astype(np.float64).mean(0), atol=1e-5)
    np.testing.assert_allclose(est[kred.EST_STD : kred.EST_STD + 3], x.astype(np.float64).std(0), atol=1e-4)
    assert est[kred.EST_ESS] == pytest.approx(n)
    assert best == 0  # ties pick the lowest index: a valid particle, not NO_INDEX


def test_one_live_particle_takes_all_weight(device, rng):
    n = 3000
    x = rng.normal(size=(n, 3)).astype(np.float32)
    logw = np.full(n, -np.inf, np.float32)
    logw[::7] = np.nan
    logw[1234] = -50.0
    est, best, _ = run_reduction(device, logw, x, 256)
    assert est[kred.EST_DEGENERATE] == 0.0 and best == 1234
    np.testing.assert_allclose(est[kred.EST_MEAN : kred.EST_MEAN + 3], x[1234], atol=1e-6)
    assert est[kred.EST_ESS] == pytest.approx(1.0)


def test_tracker_frame_with_zero_likelihood_everywhere(device):
    """A NaN observation makes every particle's log-likelihood NaN: the filter keeps the predicted cloud, flags the
    frame, stays finite, and tracks again on the next good observation."""
    trk = Gaussian3DTracker(particles=2000, sigma=0.02, sigma_obs=0.05, init=(0.1, 0.2, 0.3), device=device, seed=3)
    good = trk.step((0.1, 0.2, 0.3))
    assert not good.degenerate
    lost = trk.step((np.nan, np.nan, np.nan))
    assert lost.degenerate
    for v in (lost.mean, lost.std, lost.map, [lost.ess, lost.loglik]):
        assert np.all(np.isfinite(v))
    assert np.linalg.norm(lost.mean - [0.1, 0.2, 0.3]) < 0.01  # the prior (predicted cloud) is kept
    assert lost.ess == pytest.approx(2000, rel=1e-3)
    back = trk.step((0.1, 0.2, 0.3))
    assert not back.degenerate and np.linalg.norm(back.mean - [0.1, 0.2, 0.3]) < 0.01
