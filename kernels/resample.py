"""Resampling kernels: multinomial, stratified, systematic and residual ancestor selection.

Every kernel reads the unnormalised weights' inclusive float64 prefix sum ``cdf`` (computed by the driver with
``wp.utils.array_scan``) and takes the total ``T = cdf[n - 1]`` from that array, so nothing is read back to the
host. Random numbers come from the counter-based Philox generator with counter ``(index, frame[0], stream)``; the
frame number lives in a device array so that a captured graph can be replayed frame after frame. When
``enabled[0] == 0`` the kernels write the identity ``ancestors[j] = j`` (an ESS trigger without a host sync).

Conventions: ``n`` is the number of live particles (launch dimension), ``ancestors[j]`` is the parent of output
particle ``j``. A parent with zero weight is never selected, even when float rounding in the scan makes the CDF
non-monotone by an ulp (see :func:`positive_parent`).
"""

import warp as wp
from wptrack.kernels.random import STREAM_RESAMPLE, STREAM_RESIDUAL, random_words, word_to_unit64

wp.set_module_options({"enable_backward": False})


@wp.func
def upper_bound(cdf: wp.array(dtype=wp.float64), n: int, u: wp.float64):
    """First index ``k`` in ``[0, n)`` with ``cdf[k] > u``, clamped to ``n - 1`` (binary search, O(log n))."""
    lo = int(0)  # noqa: UP018 (a dynamic variable: Warp forbids mutating a constant in a loop)
    hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        if cdf[mid] > u:
            hi = mid
        else:
            lo = mid + 1
    return wp.min(lo, n - 1)


@wp.func
def positive_parent(w: wp.array(dtype=wp.float64), k: int, n: int):
    """``k`` if ``w[k] > 0``, else the nearest index below (then above) ``k`` with a positive value.

    Only reached in rounding corner cases (a search clamped to ``n - 1``, an ulp-level non-monotone CDF), so the
    linear walk costs nothing in practice. Returns ``k`` when no entry is positive (invalid input: total 0).
    """
    zero = wp.float64(0.0)
    found = int(-1)  # noqa: UP018 (dynamic variable, mutated in the loops below)
    if w[k] > zero:
        found = k
    j = k - 1
    while found < 0 and j >= 0:
        if w[j] > zero:
            found = j
        j -= 1
    j = k + 1
    while found < 0 and j < n:
        if w[j] > zero:
            found = j
        j += 1
    if found < 0:
        found = k
    return found


@wp.func
def systematic_slot(c: wp.float64, nf: wp.float64, total: wp.float64, u: wp.float64, n: int):
    """Output slot boundary ``floor(n * c / total + u)`` clamped to ``[0, n]``.

    Parent ``i`` owns the slots ``[slot(cdf[i - 1]), slot(cdf[i]))``; neighbours evaluate the same expression on the
    same ``cdf`` entry, so the ranges tile ``[0, n)`` without gaps.
    """
    x = wp.floor(nf * c / total + u)
    s = int(0)  # noqa: UP018 (dynamic variable)
    if x >= nf:
        s = n
    elif x > wp.float64(0.0):
        s = int(x)
    return s


@wp.kernel
def systematic_kernel(
    weights: wp.array(dtype=wp.float64),
    cdf: wp.array(dtype=wp.float64),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    enabled: wp.array(dtype=wp.int32),
    n: int,
    ancestors: wp.array(dtype=wp.int32),
):
    """Systematic resampling as an O(n) scatter over parents (one uniform ``U`` per frame, counter index 0).

    Parent ``i`` writes its index to the output slots ``[floor(n C_{i-1}/T + U), floor(n C_i/T + U))``; the first
    parent starts at 0 and the last ends at ``n``, so every slot is written (exactly once for a monotone CDF).

    Args:
        weights: (n,) unnormalised non-negative weights.
        cdf: (n,) inclusive prefix sum of ``weights``.
        seed: the run's 64-bit Philox key.
        frame: (1,) filter iteration.
        enabled: (1,) 0 -> identity.
        n: number of particles (launch dimension).
        ancestors: (n,) output parent indices.
    """
    i = wp.tid()
    if enabled[0] == 0:
        ancestors[i] = i
        return
    total = cdf[n - 1]
    u = word_to_unit64(random_words(seed, 0, frame[0], STREAM_RESAMPLE)[0])
    nf = wp.float64(n)
    lo = int(0)  # noqa: UP018 (a dynamic variable: Warp forbids mutating a constant in a loop)
    if i > 0:
        lo = systematic_slot(cdf[i - 1], nf, total, u, n)
    hi = n
    if i < n - 1:
        hi = systematic_slot(cdf[i], nf, total, u, n)
    if hi <= lo:
        return
    k = positive_parent(weights, i, n)
    for s in range(lo, hi):
        ancestors[s] = k


@wp.kernel
def stratified_kernel(
    weights: wp.array(dtype=wp.float64),
    cdf: wp.array(dtype=wp.float64),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    enabled: wp.array(dtype=wp.int32),
    n: int,
    ancestors: wp.array(dtype=wp.int32),
):
    """Stratified resampling: output ``j`` searches ``u_j = (j + U_j) / n * T`` with its own uniform ``U_j``.

    Args:
        weights: (n,) unnormalised non-negative weights.
        cdf: (n,) inclusive prefix sum of ``weights``.
        seed: the run's 64-bit Philox key.
        frame: (1,) filter iteration.
        enabled: (1,) 0 -> identity.
        n: number of particles (launch dimension).
        ancestors: (n,) output parent indices.
    """
    j = wp.tid()
    if enabled[0] == 0:
        ancestors[j] = j
        return
    total = cdf[n - 1]
    u = word_to_unit64(random_words(seed, j, frame[0], STREAM_RESAMPLE)[0])
    x = (wp.float64(j) + u) / wp.float64(n) * total
    ancestors[j] = positive_parent(weights, upper_bound(cdf, n, x), n)


@wp.kernel
def multinomial_kernel(
    weights: wp.array(dtype=wp.float64),
    cdf: wp.array(dtype=wp.float64),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    enabled: wp.array(dtype=wp.int32),
    n: int,
    ancestors: wp.array(dtype=wp.int32),
):
    """Multinomial resampling: output ``j`` searches ``u_j = U_j * T`` (i.i.d. draws from the weights).

    Args:
        weights: (n,) unnormalised non-negative weights.
        cdf: (n,) inclusive prefix sum of ``weights``.
        seed: the run's 64-bit Philox key.
        frame: (1,) filter iteration.
        enabled: (1,) 0 -> identity.
        n: number of particles (launch dimension).
        ancestors: (n,) output parent indices.
    """
    j = wp.tid()
    if enabled[0] == 0:
        ancestors[j] = j
        return
    total = cdf[n - 1]
    u = word_to_unit64(random_words(seed, j, frame[0], STREAM_RESAMPLE)[0])
    ancestors[j] = positive_parent(weights, upper_bound(cdf, n, u * total), n)


@wp.kernel
def residual_split_kernel(
    weights: wp.array(dtype=wp.float64),
    cdf: wp.array(dtype=wp.float64),
    n: int,
    counts: wp.array(dtype=wp.int32),
    residuals: wp.array(dtype=wp.float64),
):
    """Split ``n w_i / T`` into deterministic copies ``counts_i = floor(.)`` and the residual ``n w_i / T - counts_i``.

    Args:
        weights: (n,) unnormalised non-negative weights.
        cdf: (n,) inclusive prefix sum of ``weights`` (only ``cdf[n - 1]`` is read).
        n: number of particles (launch dimension).
        counts: (n,) output deterministic copies.
        residuals: (n,) output residual weights in ``[0, 1)``.
    """
    i = wp.tid()
    x = wp.float64(n) * weights[i] / cdf[n - 1]
    c = wp.floor(x)
    if c > wp.float64(0.0):
        counts[i] = int(c)
        residuals[i] = x - c
    else:
        counts[i] = 0
        residuals[i] = wp.max(x, wp.float64(0.0))


@wp.kernel
def residual_scatter_kernel(
    counts: wp.array(dtype=wp.int32),
    positions: wp.array(dtype=wp.int32),
    enabled: wp.array(dtype=wp.int32),
    n: int,
    ancestors: wp.array(dtype=wp.int32),
):
    """Deterministic part of residual resampling: parent ``i`` fills ``counts_i`` slots ending at ``positions[i]``.

    Args:
        counts: (n,) deterministic copies per parent.
        positions: (n,) inclusive prefix sum of ``counts``.
        enabled: (1,) 0 -> identity.
        n: number of particles (launch dimension).
        ancestors: (n,) output parent indices (slots ``[0, sum(counts))``).
    """
    i = wp.tid()
    if enabled[0] == 0:
        ancestors[i] = i
        return
    end = wp.min(positions[i], n)
    start = positions[i] - counts[i]
    for s in range(start, end):
        ancestors[s] = i


@wp.kernel
def residual_draw_kernel(
    residuals: wp.array(dtype=wp.float64),
    residual_cdf: wp.array(dtype=wp.float64),
    positions: wp.array(dtype=wp.int32),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    enabled: wp.array(dtype=wp.int32),
    n: int,
    ancestors: wp.array(dtype=wp.int32),
):
    """Random part of residual resampling: ``R = n - sum(counts)`` multinomial draws from the residuals.

    Launched over ``n`` threads; thread ``j < R`` fills slot ``sum(counts) + j`` (threads ``j >= R`` return).

    Args:
        residuals: (n,) residual weights.
        residual_cdf: (n,) inclusive prefix sum of ``residuals``.
        positions: (n,) inclusive prefix sum of the deterministic counts.
        seed: the run's 64-bit Philox key.
        frame: (1,) filter iteration.
        enabled: (1,) 0 -> nothing (the scatter kernel wrote the identity).
        n: number of particles (launch dimension).
        ancestors: (n,) output parent indices (slots ``[sum(counts), n)``).
    """
    j = wp.tid()
    if enabled[0] == 0:
        return
    placed = wp.min(positions[n - 1], n)
    if j >= n - placed:
        return
    u = word_to_unit64(random_words(seed, j, frame[0], STREAM_RESIDUAL)[0])
    total = residual_cdf[n - 1]
    if total > wp.float64(0.0):
        ancestors[placed + j] = positive_parent(residuals, upper_bound(residual_cdf, n, u * total), n)
    elif placed > 0:
        # Rounding left slots but no residual mass: copy a random deterministic slot (already written).
        s = wp.clamp(int(u * wp.float64(placed)), 0, placed - 1)
        ancestors[placed + j] = ancestors[s]
    else:
        ancestors[j] = j  # invalid input (total weight 0): keep the particles
