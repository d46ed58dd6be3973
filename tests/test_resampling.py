"""Resampling schemes: exact agreement with NumPy references, statistical properties, flags and errors."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from wptrack.core.errors import ConfigError
from wptrack.core.resampling import MAX_BLOCKS, SCHEMES, Resampler, make_resampler, offspring_counts
from wptrack.kernels.core import random as wrand
from wptrack.kernels.core import resample as kres

SEED = wp.vec2ui(0x1234ABCD, 0x0BADF00D)
UNIT64 = 2.3283064365386963e-10  # word_to_unit64: (w + 0.5) * 2^-32


def _weights(rng: np.random.Generator, n: int, zero_fraction: float = 0.2) -> np.ndarray:
    """Random unnormalised weights with a spread of magnitudes and some exact zeros."""
    w = rng.gamma(0.7, size=n)
    w[rng.random(n) < zero_fraction] = 0.0
    w[0] = 0.0
    w[-1] = 0.0
    return w


def _uniforms(seed: wp.vec2ui, frame: int, stream: int, n: int, device: str) -> np.ndarray:
    """The float64 uniforms the kernels draw for counter indices ``0..n-1`` (word 0 through word_to_unit64)."""
    words = wp.zeros((n, 4), dtype=wp.uint32, device=device)
    wp.launch(wrand.philox_kernel, dim=n, inputs=[seed, frame, stream], outputs=[words], device=device)
    return (words.numpy()[:, 0].astype(np.float64) + 0.5) * UNIT64


def _positive_parent(w: np.ndarray, k: np.ndarray) -> np.ndarray:
    """NumPy twin of the kernel's zero-weight skip (nearest positive index below, then above)."""
    k = k.copy()
    for j in np.flatnonzero(w[k] <= 0):
        below = np.flatnonzero(w[: k[j]] > 0)
        k[j] = below[-1] if below.size else k[j] + np.flatnonzero(w[k[j] :] > 0)[0]
    return k


def _search(cdf: np.ndarray, w: np.ndarray, x: np.ndarray) -> np.ndarray:
    k = np.minimum(np.searchsorted(cdf, x, side="right"), len(cdf) - 1)
    return _positive_parent(w, k)


def reference(scheme: str, w: np.ndarray, r: Resampler, frame: int, device: str) -> np.ndarray:
    """NumPy implementation of each scheme with the same Philox uniforms and the device's own prefix sums
    (identical to ``np.cumsum`` on the CPU; on CUDA the CUB scan may differ in the last ulp)."""
    n = len(w)
    cdf = r.cdf.numpy()[:n]
    np.testing.assert_allclose(cdf, np.cumsum(w), rtol=1e-12)
    total = cdf[-1]
    if scheme == "systematic":
        u = _uniforms(SEED, frame, wrand.STREAM_RESAMPLE, 1, device)[0]
        bounds = np.clip(np.floor(n * cdf / total + u), 0, n).astype(np.int64)
        bounds = np.concatenate([[0], bounds[:-1], [n]])
        return np.repeat(np.arange(n), np.diff(bounds))
    if scheme == "stratified":
        u = _uniforms(SEED, frame, wrand.STREAM_RESAMPLE, n, device)
        return _search(cdf, w, (np.arange(n) + u) / n * total)
    if scheme == "multinomial":
        u = _uniforms(SEED, frame, wrand.STREAM_RESAMPLE, n, device)
        return _search(cdf, w, u * total)
    x = n * w / total
    counts = np.floor(x).astype(np.int64)
    resid = x - counts
    np.testing.assert_array_equal(resid, r.residuals.numpy()[:n])
    rcdf = r.residual_cdf.numpy()[:n]
    det = np.repeat(np.arange(n), counts)
    u = _uniforms(SEED, frame, wrand.STREAM_RESIDUAL, n - len(det), device)
    return np.concatenate([det, _search(rcdf, resid, u * rcdf[-1])])


def _run(r: Resampler, w_dev: wp.array, frame: int, device: str, enabled: int | None = None) -> np.ndarray:
    n = w_dev.shape[0]
    anc = wp.full(n, -1, dtype=wp.int32, device=device)
    frame_arr = wp.array([frame], dtype=wp.int32, device=device)
    flag = None if enabled is None else wp.array([enabled], dtype=wp.int32, device=device)
    r(w_dev, SEED, frame_arr, anc, enabled=flag)
    return anc.numpy()


def _chi2_upper(df: int, z: float) -> float:
    """Upper quantile of chi-square(df) by the Wilson-Hilferty approximation (z: the normal quantile)."""
    return df * (1.0 - 2.0 / (9.0 * df) + z * np.sqrt(2.0 / (9.0 * df))) ** 3


def _expected_count_variance(scheme: str, w: np.ndarray) -> np.ndarray:
    """Exact per-parent variance of the offspring count of each scheme."""
    n = len(w)
    x = n * w / w.sum()
    frac = x - np.floor(x)
    if scheme == "multinomial":
        return x * (1.0 - w / w.sum())
    if scheme == "systematic":
        return frac * (1.0 - frac)
    if scheme == "residual":
        rest = n - np.floor(x).sum()
        p = frac / rest
        return rest * p * (1.0 - p)
    # stratified: the strata fully inside parent i's interval [a, b) contribute no variance; the (at most two)
    # partially covered strata are independent Bernoulli draws with success probability = the overlap.
    b = np.cumsum(x)
    a = np.concatenate([[0.0], b[:-1]])
    fa, fb = np.floor(a), np.floor(b)
    same = fa == fb
    p1 = np.where(same, b - a, np.minimum(b, fa + 1.0) - a)
    p2 = np.where(same, 0.0, b - fb)
    return p1 * (1.0 - p1) + p2 * (1.0 - p2)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_matches_numpy_reference(device, rng, scheme):
    n = 2000
    w = _weights(rng, n)
    r = make_resampler(scheme, n, device)
    w_dev = wp.array(w, dtype=wp.float64, device=device)
    for frame in (0, 1, 77):
        anc = _run(r, w_dev, frame, device)
        np.testing.assert_array_equal(anc, reference(scheme, w, r, frame, device))


@pytest.mark.parametrize("scheme", SCHEMES)
def test_offspring_statistics(device, rng, scheme):
    """R independent frames: the mean offspring count is N w_i, the per-scheme variance is the exact one, the
    count bounds that distinguish the schemes hold in every frame and the resampled mean of f(x) is unbiased."""
    n, frames = 2000, 200
    w = _weights(rng, n)
    p = w / w.sum()
    x = n * p
    lo, hi = np.floor(x), np.ceil(x)
    f = rng.normal(size=n)
    r = make_resampler(scheme, n, device)
    w_dev = wp.array(w, dtype=wp.float64, device=device)
    anc = wp.zeros(n, dtype=wp.int32, device=device)
    frame = wp.zeros(1, dtype=wp.int32, device=device)
    counts = np.empty((frames, n))
    means = np.empty(frames)
    for k in range(frames):
        frame.fill_(k)
        r(w_dev, SEED, frame, anc)
        a = anc.numpy()
        assert a.min() >= 0 and a.max() < n
        c = offspring_counts(a, n)
        assert c[w == 0].sum() == 0, "a zero-weight particle was selected"
        if scheme == "systematic":
            assert np.all((c == lo) | (c == hi))
        elif scheme == "residual":
            assert np.all(c >= lo)
            placed = int(lo.sum())
            np.testing.assert_array_equal(offspring_counts(a[:placed], n), lo)  # deterministic part first
        elif scheme == "stratified":
            assert np.all((c >= lo - 1) & (c <= hi + 1))
        counts[k] = c
        means[k] = f[a].mean()

    # Unbiasedness of the offspring counts: Pearson chi-square of the counts pooled over the R frames against
    # R N w_i, rejected at significance 1e-4 (z = 3.719). Exact (asymptotically) for multinomial, whose pooled
    # counts are Multinomial(R N, w); conservative for the other schemes, whose count variance is smaller.
    live = w > 0
    pooled = counts.sum(axis=0)[live]
    expected = frames * x[live]
    chi2 = float(((pooled - expected) ** 2 / expected).sum())
    assert chi2 < _chi2_upper(int(live.sum()) - 1, 3.719), chi2

    # Variance: the summed per-particle sample variance is within 5% of the scheme's exact value (> 10 standard
    # errors here), which separates multinomial > residual, stratified > systematic.
    var_emp = counts.var(axis=0, ddof=1).sum()
    var_exact = _expected_count_variance(scheme, w).sum()
    assert abs(var_emp / var_exact - 1.0) < 0.05, (var_emp, var_exact)
    if scheme != "multinomial":
        assert var_emp < 0.8 * _expected_count_variance("multinomial", w).sum()

    # E[mean f(x[ancestors])] = sum_i w_i f(x_i): the average over R frames is within 5 multinomial standard
    # errors (two-sided significance ~6e-7; the other schemes have a smaller error).
    target = float(p @ f)
    se = np.sqrt(float(p @ (f - target) ** 2) / n / frames)
    assert abs(means.mean() - target) < 5.0 * se


@pytest.mark.parametrize("scheme", SCHEMES)
def test_all_mass_on_one_particle(device, scheme):
    n = 257
    w = np.zeros(n)
    w[123] = 3.5
    r = make_resampler(scheme, n, device)
    w_dev = wp.array(w, dtype=wp.float64, device=device)
    for frame in (0, 5):
        assert np.all(_run(r, w_dev, frame, device) == 123)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_zero_weights_never_selected(device, rng, scheme):
    n = 1000
    w = np.zeros(n)
    alive = rng.choice(n, size=7, replace=False)
    w[alive] = rng.random(7) * [1e-300, 1e300, 1.0, 1e-5, 2.0, 3.0, 1e-12][:7]  # wide dynamic range
    w[alive[1]] = 0.0  # and one huge value dropped: the rest must still be chosen correctly
    r = make_resampler(scheme, n, device)
    w_dev = wp.array(w, dtype=wp.float64, device=device)
    for frame in range(5):
        anc = _run(r, w_dev, frame, device)
        assert anc.min() >= 0 and anc.max() < n
        assert np.all(w[anc] > 0)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_enabled_flag(device, rng, scheme):
    n = 500
    w = _weights(rng, n)
    r = make_resampler(scheme, n, device)
    w_dev = wp.array(w, dtype=wp.float64, device=device)
    np.testing.assert_array_equal(_run(r, w_dev, 3, device, enabled=0), np.arange(n))
    on = _run(r, w_dev, 3, device, enabled=1)
    np.testing.assert_array_equal(on, _run(r, w_dev, 3, device))
    assert np.all(w[on] > 0)


@pytest.mark.parametrize("scheme", SCHEMES)
def test_determinism(device, rng, scheme):
    n = 1000
    w = _weights(rng, n)
    w_dev = wp.array(w, dtype=wp.float64, device=device)
    first = _run(make_resampler(scheme, n, device), w_dev, 9, device)
    again = _run(make_resampler(scheme, n, device), w_dev, 9, device)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, _run(make_resampler(scheme, n, device), w_dev, 10, device))


@pytest.mark.parametrize("scheme", SCHEMES)
def test_n_below_capacity(device, rng, scheme):
    """``n`` < capacity resamples the first n particles only and leaves the rest of ``ancestors`` alone."""
    cap, n = 800, 600
    w = _weights(rng, cap)
    w[:n][np.argmax(w[:n] == 0)] = 0.0
    r = make_resampler(scheme, cap, device)
    w_dev = wp.array(w, dtype=wp.float64, device=device)
    anc = wp.full(cap, -1, dtype=wp.int32, device=device)
    r(w_dev, SEED, wp.array([4], dtype=wp.int32, device=device), anc, n=n)
    a = anc.numpy()
    np.testing.assert_array_equal(a[n:], -1)
    np.testing.assert_array_equal(a[:n], reference(scheme, w[:n], r, 4, device))
    with pytest.raises(ValueError, match="capacity"):
        r(w_dev, SEED, wp.array([4], dtype=wp.int32, device=device), anc, n=cap + 1)


def test_unknown_scheme(device):
    with pytest.raises(ConfigError) as info:
        make_resampler("bootstrap", 10, device)
    for name in SCHEMES:
        assert name in str(info.value)


def test_large_systematic_float64_cdf(device, rng):
    """At N = 2e6 a float32 CDF loses whole particles; the float64 one keeps every count at floor/ceil(N w)."""
    if wp.get_device(device).is_cpu:
        pytest.skip("N = 2e6 systematic resampling is checked on CUDA devices only")
    n = 2_000_000
    w = _weights(rng, n)
    x = n * w / w.sum()
    r = make_resampler("systematic", n, device)
    w_dev = wp.array(w, dtype=wp.float64, device=device)
    for frame in (0, 1):
        c = offspring_counts(_run(r, w_dev, frame, device), n)
        assert c.sum() == n
        assert np.all((c >= np.floor(x - 1e-9)) & (c <= np.ceil(x + 1e-9)))
        assert c[w == 0].sum() == 0


@pytest.mark.parametrize("scheme", SCHEMES)
def test_cuda_graph_capture(device, rng, scheme):
    """A captured call replays with the frame number and the enabled flag taken from device arrays."""
    if wp.get_device(device).is_cpu:
        pytest.skip("CUDA graph capture needs a CUDA device")
    n = 4096
    w = _weights(rng, n)
    r = make_resampler(scheme, n, device)
    w_dev = wp.array(w, dtype=wp.float64, device=device)
    anc = wp.zeros(n, dtype=wp.int32, device=device)
    frame = wp.zeros(1, dtype=wp.int32, device=device)
    flag = wp.ones(1, dtype=wp.int32, device=device)
    r(w_dev, SEED, frame, anc, enabled=flag)  # warm-up: module load and scan temporaries outside the capture
    with wp.ScopedCapture(device=device) as capture:
        r(w_dev, SEED, frame, anc, enabled=flag)
    for k in (3, 4):
        frame.fill_(k)
        wp.capture_launch(capture.graph)
        np.testing.assert_array_equal(anc.numpy(), _run(r, w_dev, k, device))
    flag.fill_(0)
    wp.capture_launch(capture.graph)
    np.testing.assert_array_equal(anc.numpy(), np.arange(n))


# --- resampling from log-weights (the particle filters' path) -------------------------------------------------------

MAX_SLOT = 11


def _pooled_cells(observed: np.ndarray, expected: np.ndarray, least: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """Contiguous parents pooled into cells of at least ``least`` expected offspring (the chi-square approximation
    needs it: with log-weights spread over ~40 nats most parents expect ~1e-6 children over all frames, and one rare
    child would dominate the statistic). A contiguous group of parents owns a contiguous range of slots, so its
    count is again unbiased; the last cell takes the remainder."""
    edges = [0]
    acc = 0.0
    for i, e in enumerate(expected):
        acc += e
        if acc >= least:
            edges.append(i + 1)
            acc = 0.0
    if edges[-1] != len(expected):
        if len(edges) > 1:
            edges[-1] = len(expected)  # the remainder joins the last full cell
        else:
            edges.append(len(expected))
    obs = np.add.reduceat(observed, edges[:-1])
    exp = np.add.reduceat(expected, edges[:-1])
    return obs, exp


def _log_weights(rng: np.random.Generator, n: int) -> np.ndarray:
    """float32 log-weights over ~40 nats with a block of -1e30 (weight exactly 0 after exp)."""
    logw = (rng.normal(size=n) * 8.0).astype(np.float32)
    logw[rng.random(n) < 0.15] = -1e30
    logw[0] = -1e30
    return logw


def _run_log(r: Resampler, logw: np.ndarray, frame: int, device: str, enabled: int = 1):
    n = len(logw)
    est = np.zeros(16)
    est[MAX_SLOT] = float(logw.max())
    est_dev = wp.array(est, dtype=wp.float64, device=device)
    logw_dev = wp.array(logw, dtype=wp.float32, device=device)
    anc = wp.full(n, -1, dtype=wp.int32, device=device)
    flag = wp.array([enabled], dtype=wp.int32, device=device)
    r.from_log_weights(logw_dev, est_dev, MAX_SLOT, SEED, wp.array([frame], dtype=wp.int32, device=device), anc, flag)
    q = wp.zeros(n, dtype=wp.int64, device=device)
    wp.launch(
        kres.quantised_weights_kernel, dim=n, inputs=[logw_dev, est_dev, MAX_SLOT, r.scale], outputs=[q], device=device
    )
    return anc.numpy(), q.numpy()


def systematic_exact_reference(q: np.ndarray, frame: int, device: str) -> np.ndarray:
    """NumPy systematic resampling on the exact integer CDF of the quantised weights q."""
    n = len(q)
    c = np.cumsum(q)
    u = _uniforms(SEED, frame, wrand.STREAM_RESAMPLE, 1, device)[0]
    bounds = np.clip(np.floor(c.astype(np.float64) * (n / float(c[-1])) + u), 0, n).astype(np.int64)
    bounds[-1] = n
    return np.repeat(np.arange(n), np.diff(np.concatenate([[0], bounds])))


@pytest.mark.parametrize("n", [1, 255, 1000, 70_001])
def test_log_weights_systematic_exact_cdf(device, rng, n):
    """Quantised weights are floor(exp(logw - max) 2^k); the ancestors equal the NumPy reference on the same
    integers exactly, whatever the block partition."""
    logw = _log_weights(rng, n)
    logw[n // 2] = 3.0 + max(float(logw.max()), 0.0)  # a live particle in every case
    r = Resampler("systematic", n, device, log_weights=True)
    assert r.cdf is None and r.weights is None  # no per-particle buffer on this path
    for frame in (0, 1, 77):
        anc, q = _run_log(r, logw, frame, device)
        # float32 exponentials (to two float32 ulps: libm and NumPy may differ by one), exact integer sums
        q_np = np.floor(np.exp(logw - logw.max()).astype(np.float64) * r.scale)
        np.testing.assert_allclose(q, q_np, rtol=2.5e-7, atol=1.0)
        assert q.sum() < 2**60 and q.max() <= r.scale
        np.testing.assert_array_equal(anc, systematic_exact_reference(q, frame, device))


def test_log_weights_systematic_cpu_blocks(rng, monkeypatch):
    """The exact systematic kernels' block scans are one-lane identities on the CPU backend: the resampler launches
    them with one lane per block even when ``wp.config.enable_cpu_blocks`` would honour a larger block."""
    n = 5000
    logw = _log_weights(rng, n)
    logw[n // 2] = 3.0 + max(float(logw.max()), 0.0)
    monkeypatch.setattr(wp.config, "enable_cpu_blocks", True)
    r = Resampler("systematic", n, "cpu", log_weights=True)
    anc, q = _run_log(r, logw, 3, "cpu")
    np.testing.assert_array_equal(anc, systematic_exact_reference(q, 3, "cpu"))


def test_log_weights_systematic_offspring(device, rng):
    """Every frame: offspring counts are floor or ceil of N q_i / T, sum to N, zero weights get none; over 200
    frames the pooled counts are unbiased (chi-square at significance 1e-4) and the count variance is the exact
    systematic one (within 5 %). Every frame, ranges above 2 slots filled by the long-range kernel give the same
    ancestors (so the same statistics)."""
    n, frames = 3000, 200
    logw = _log_weights(rng, n)
    r = Resampler("systematic", n, device, log_weights=True)
    r_long = Resampler("systematic", n, device, log_weights=True, long_range=2)
    counts = np.empty((frames, n))
    q = None
    for k in range(frames):
        a, q = _run_log(r, logw, k, device)
        np.testing.assert_array_equal(_run_log(r_long, logw, k, device)[0], a)
        c = offspring_counts(a, n)
        x = n * q / q.sum()
        assert c.sum() == n
        assert np.all((c == np.floor(x)) | (c == np.ceil(x)))
        assert c[q == 0].sum() == 0
        counts[k] = c
    live = q > 0
    observed, expected = _pooled_cells(counts.sum(axis=0)[live], frames * (n * q / q.sum())[live])
    chi2 = float(((observed - expected) ** 2 / expected).sum())
    assert chi2 < _chi2_upper(len(expected) - 1, 3.719), chi2
    var_exact = _expected_count_variance("systematic", q.astype(np.float64)).sum()
    assert abs(counts.var(axis=0, ddof=1).sum() / var_exact - 1.0) < 0.05
    assert (r_long.long_meta.numpy() >> 32).sum() > 0  # the last frame used the long-range list


@pytest.mark.parametrize("scheme", SCHEMES)
def test_log_weights_enabled_flag_and_other_schemes(device, rng, scheme):
    """enabled = 0 gives the identity; the search-based schemes from log-weights equal their weight path on
    exp(logw - max)."""
    n = 1500
    logw = _log_weights(rng, n)
    r = Resampler(scheme, n, device, log_weights=True)
    np.testing.assert_array_equal(_run_log(r, logw, 5, device, enabled=0)[0], np.arange(n))
    anc, _ = _run_log(r, logw, 5, device)
    w = np.exp(logw.astype(np.float64) - logw.max())
    assert np.all(w[anc] > 0)
    if scheme != "systematic":
        np.testing.assert_allclose(r.weights.numpy(), w, rtol=1e-12)
        np.testing.assert_array_equal(anc, reference(scheme, r.weights.numpy(), r, 5, device))


def test_log_weights_errors(device):
    r = Resampler("systematic", 10, device, log_weights=True)
    with pytest.raises(ValueError, match="from_log_weights"):
        r(
            wp.zeros(10, dtype=wp.float64, device=device),
            SEED,
            wp.zeros(1, dtype=wp.int32, device=device),
            wp.zeros(10, dtype=wp.int32, device=device),
        )
    plain = Resampler("systematic", 10, device)
    with pytest.raises(ValueError, match="log_weights=True"):
        plain.from_log_weights(
            wp.zeros(10, dtype=wp.float32, device=device),
            wp.zeros(16, dtype=wp.float64, device=device),
            MAX_SLOT,
            SEED,
            wp.zeros(1, dtype=wp.int32, device=device),
            wp.zeros(10, dtype=wp.int32, device=device),
        )


def test_log_weights_systematic_large(device, rng):
    """At N = 2e6 (many blocks, several rounds per block) the exact CDF keeps every count at floor/ceil."""
    if wp.get_device(device).is_cpu:
        pytest.skip("N = 2e6 is checked on CUDA devices only")
    n = 2_000_000
    logw = _log_weights(rng, n)
    r = Resampler("systematic", n, device, log_weights=True)
    anc, q = _run_log(r, logw, 1, device)
    c = offspring_counts(anc, n)
    x = n * q / q.sum()
    assert c.sum() == n and np.all((c == np.floor(x)) | (c == np.ceil(x)))
    np.testing.assert_array_equal(anc, systematic_exact_reference(q, 1, device))


# --- long offspring ranges: filled by the whole grid (issue 13) -----------------------------------------------------

LONG_N = 40_000  # three blocks of the fused pass on the CPU backend (16384 particles each), 157 on a GPU


def _concentrated_log_weights(rng: np.random.Generator, n: int, case: str) -> np.ndarray:
    """float32 log-weights of the long-range cases: ``spread`` (N(0, 1): short ranges only at the default
    threshold), ``one`` (one parent with almost all the weight), ``few`` (a few heavy parents, two adjacent in the
    first block, the others in later blocks), ``halves`` (two parents, in the first and last block, with half the
    weight each: the first one's range covers the output slots of the middle block's particles)."""
    if case == "spread":
        return rng.normal(size=n).astype(np.float32)
    logw = (rng.normal(size=n) - 25.0).astype(np.float32)  # exp(-25) 2^k: quantised to 0..2 (k = 44 at 4e4)
    heavy = {"one": [n // 3], "few": [5, 6, 9000, n // 2 + 17, n - 2], "halves": [100, n - 100]}[case]
    logw[heavy] = rng.uniform(-0.5, 0.0, size=len(heavy)).astype(np.float32)
    return logw


@pytest.mark.parametrize("case", ["spread", "one", "few", "halves"])
@pytest.mark.parametrize("long_range", [1, 64])
def test_long_ranges_log_weights_exact(device, rng, case, long_range):
    """Systematic resampling from log-weights with long offspring ranges equals the NumPy reference on the same
    integers, and the ancestors with a threshold no range reaches (every range written by its own lane, the code
    before the long-range list); the list is used whenever a range exceeds the threshold."""
    n = LONG_N
    logw = _concentrated_log_weights(rng, n, case)
    r = Resampler("systematic", n, device, log_weights=True, long_range=long_range)
    serial = Resampler("systematic", n, device, log_weights=True, long_range=n)
    strided = Resampler("systematic", n, device, log_weights=True, long_range=long_range)
    strided.fill_blocks = 7  # another grid stride (on the CPU backend: 7 one-lane blocks instead of one)
    for frame in (0, 9):
        anc, q = _run_log(r, logw, frame, device)
        ref = systematic_exact_reference(q, frame, device)
        np.testing.assert_array_equal(anc, ref)
        np.testing.assert_array_equal(_run_log(strided, logw, frame, device)[0], ref)
        lengths = offspring_counts(ref, n)
        recorded = r.long_meta.numpy()
        assert int((recorded >> 32).sum()) == int((lengths > long_range).sum())
        assert int((recorded & 0xFFFFFFFF).sum()) == int((lengths[lengths > long_range] - 1).sum())
        np.testing.assert_array_equal(_run_log(serial, logw, frame, device)[0], anc)
        assert not (serial.long_meta.numpy() >> 32).any()
    if case in ("one", "halves"):
        assert lengths.max() > n // 3  # a range across the output slots of several blocks
    if case == "few":
        assert lengths.max() > n // 10
        assert ((r.long_meta.numpy() >> 32) > 0).sum() >= 2  # long ranges recorded by more than one block
        assert (r.long_meta.numpy()[0] >> 32) >= 2  # and several in the same block


def test_long_ranges_reset_between_frames(device, rng):
    """A concentrated frame, then a spread one and a disabled one on the same resampler: the list of the earlier
    frame is never replayed."""
    n = LONG_N
    r = Resampler("systematic", n, device, log_weights=True, long_range=8)
    for case in ("one", "spread"):
        logw = _concentrated_log_weights(rng, n, case)
        anc, q = _run_log(r, logw, 3, device)
        np.testing.assert_array_equal(anc, systematic_exact_reference(q, 3, device))
    _run_log(r, _concentrated_log_weights(rng, n, "one"), 4, device)
    anc, _ = _run_log(r, _concentrated_log_weights(rng, n, "one"), 4, device, enabled=0)
    np.testing.assert_array_equal(anc, np.arange(n))


@pytest.mark.parametrize("scheme", ["systematic", "residual"])
@pytest.mark.parametrize("long_range", [1, 64])
def test_long_ranges_float_weights(device, rng, scheme, long_range):
    """The float64-weight paths with long ranges (one parent with almost all the weight, then a few heavy ones;
    all of the capacity, then n below it) equal their NumPy references."""
    cap = LONG_N
    r = Resampler(scheme, cap, device, long_range=long_range)
    for n, heavy in ((cap, [cap // 3]), (cap - 1000, [7, 8, 20_000, cap - 1001])):
        w = rng.gamma(0.7, size=n) * 1e-6
        w[heavy] = 1.0 + rng.random(len(heavy))
        w_dev = wp.array(w, dtype=wp.float64, device=device)
        for frame in (0, 5):
            anc = _run(r, w_dev, frame, device)
            np.testing.assert_array_equal(anc, reference(scheme, w, r, frame, device))
            assert (r.long_meta.numpy() >> 32).sum() >= len(heavy)


def test_long_range_config(device):
    assert MAX_BLOCKS <= kres.MAX_GROUPS  # the fill kernel scans the groups as one tile
    with pytest.raises(ConfigError, match="long_range"):
        Resampler("systematic", 10, device, long_range=0)


def test_long_ranges_cuda_graph(device, rng):
    """The fused pass and the fill kernel captured once replay spread and concentrated weights exactly."""
    if wp.get_device(device).is_cpu:
        pytest.skip("CUDA graph capture needs a CUDA device")
    n = LONG_N
    r = Resampler("systematic", n, device, log_weights=True)
    est = wp.zeros(16, dtype=wp.float64, device=device)
    logw_dev = wp.zeros(n, dtype=wp.float32, device=device)
    anc = wp.zeros(n, dtype=wp.int32, device=device)
    frame = wp.array([2], dtype=wp.int32, device=device)
    r.from_log_weights(logw_dev, est, MAX_SLOT, SEED, frame, anc)  # warm-up: module load
    with wp.ScopedCapture(device=device) as capture:
        r.from_log_weights(logw_dev, est, MAX_SLOT, SEED, frame, anc)
    for case in ("spread", "one", "few"):
        logw = _concentrated_log_weights(rng, n, case)
        logw_dev.assign(logw)
        est.assign(np.where(np.arange(16) == MAX_SLOT, float(logw.max()), 0.0))
        wp.capture_launch(capture.graph)
        _, q = _run_log(r, logw, 2, device)
        np.testing.assert_array_equal(anc.numpy(), systematic_exact_reference(q, 2, device))


@pytest.mark.parametrize(
    ("n", "chunk", "blocks", "block"), [(1, 256, 1, 256), (255, 256, 1, 256), (1000, 250, 4, 256),
                                        (4097, 300, 14, 64), (1000, 7, 143, 32), (5, 2, 4, 32)]
)  # fmt: skip
def test_grouped_systematic_rows_match_numpy(device, rng, n, chunk, blocks, block):
    """grouped_systematic_kernel (the template tracker's independent groups): each active row is systematic
    resampling of its own weights on the exact integer CDF floor(w 2^k), with the uniform of Philox counter (row,
    frame, STREAM_RESAMPLE), equal to the NumPy reference; inactive rows get the identity; rows 0 and 1 hold the
    same weights and differ (independent uniforms); a row whose weight is on one parent. Blocks of parents as the
    tracker's (256 of 256 lanes), more parents than lanes (several CDF rounds), many small blocks, and a last block
    with no parents (5 in blocks of 2, 4 blocks); one lane per block on the CPU."""
    from wptrack.core.resampling import quantisation_bits

    g_rows = 5
    w = np.exp(rng.normal(0.0, 2.0, (g_rows, n)))
    w[:, rng.uniform(size=n) < 0.2] = 0.0  # zero weights: no offspring
    w[:, n // 2] = 1.0
    w /= w.max(axis=1, keepdims=True)
    w[1] = w[0]
    w[2] = 0.0  # weights concentrated on one parent: every slot of row 2 searches its way to it
    w[2, n // 3] = 1.0
    active = np.array([1, 1, 1, 0, 1], np.int32)
    scale = float(2 ** quantisation_bits(n))
    q_all = np.floor(w * scale).astype(np.int64)
    part_q = np.zeros((blocks, g_rows), np.int64)  # as kernels.templates.slots.block_slot_moments_kernel writes them
    for b in range(blocks):
        part_q[b] = q_all[:, b * chunk : (b + 1) * chunk].sum(axis=1)
    part_q[:, 3] = -(2**50)  # an inactive row's sums are never read
    anc = wp.full((g_rows, n), -1, dtype=wp.int32, device=device)
    frame = 9
    wp.launch_tiled(
        kres.grouped_systematic_kernel,
        dim=[g_rows, blocks],
        inputs=[wp.array(w, dtype=wp.float64, device=device), wp.array(active, dtype=wp.int32, device=device),
                wp.array(part_q, dtype=wp.int64, device=device), blocks, chunk, scale, SEED,
                wp.array([frame], dtype=wp.int32, device=device), n,
                wp.zeros((g_rows, n), dtype=wp.int64, device=device)],
        outputs=[anc],
        block_dim=1 if wp.get_device(device).is_cpu else block,
        device=device,
    )  # fmt: skip
    got = anc.numpy()
    u = _uniforms(SEED, frame, wrand.STREAM_RESAMPLE, g_rows, device)
    for g in range(g_rows):
        if not active[g]:
            np.testing.assert_array_equal(got[g], np.arange(n))
            continue
        q = np.floor(w[g] * scale).astype(np.int64)
        c = np.cumsum(q)
        bounds = np.clip(np.floor(c.astype(np.float64) * (n / float(c[-1])) + u[g]), 0, n).astype(np.int64)
        bounds[-1] = n
        np.testing.assert_array_equal(got[g], np.repeat(np.arange(n), np.diff(np.concatenate([[0], bounds]))))
        assert not np.any(np.isin(got[g], np.flatnonzero(q == 0)))
    if n > 100:
        assert not np.array_equal(got[0], got[1])
