"""Resampling kernels: multinomial, stratified, systematic and residual ancestor selection.

Every kernel reads the unnormalised weights' inclusive float64 prefix sum ``cdf`` (computed by the driver with
``wp.utils.array_scan``) and takes the total ``T = cdf[n - 1]`` from that array, so nothing is read back to the
host. Random numbers come from the counter-based Philox generator with counter ``(index, frame[0], stream)``; the
frame number lives in a device array so that a captured graph can be replayed frame after frame. When
``enabled[0] == 0`` the kernels write the identity ``ancestors[j] = j`` (an ESS trigger without a host sync).

Conventions: ``n`` is the number of live particles (launch dimension), ``ancestors[j]`` is the parent of output
particle ``j``. A parent with zero weight is never selected, even when float rounding in the scan makes the CDF
non-monotone by an ulp (see :func:`positive_parent`).

The scatter kernels (systematic, residual) write short offspring ranges from the parent's thread and leave ranges
longer than ``long_range`` slots to :func:`long_ranges_fill_kernel`, which spreads them over its whole grid (one
parent owning most of the slots no longer serialises the pass).

Length: one module for the resampling family on purpose: the four float64-CDF schemes, the exact-integer systematic
pass from log-weights and the grouped one per row of weights share the long-range bookkeeping, the offspring-slot
search and the block scans defined here, and ``wptrack.core.resampling`` picks among them by name.
"""

import warp as wp

from wptrack.kernels.core.random import STREAM_RESAMPLE, STREAM_RESIDUAL, random_words, word_to_unit64

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


# --- long offspring ranges: written by the whole grid, not by one thread ---------------------------------------
#
# A parent whose offspring range [lo, hi) is longer than ``long_range`` slots writes only its first slot and records
# the rest, [lo + 1, hi), in a list; :func:`long_ranges_fill_kernel` then fills all recorded slots with every thread
# of a fixed grid. The ranges are the same integers as before, so the ancestors are bit-identical; only who writes
# them changes. The parents are split into ``groups`` contiguous groups (the blocks of the fused pass); group ``g``
# counts its long ranges and their total length in one packed int64 ``long_meta[g]`` (count << 32 | length; one
# atomic add per long range on the group's own counter, never per particle on one address) and writes its entries
# from ``long_base[g] = S_g // (long_range + 1) + g`` on, ``S_g`` being its first output slot. Long ranges are
# disjoint and longer than ``long_range``, so group g has at most ``(S_{g+1} - S_g) // (long_range + 1)`` of them and
# the groups' regions never overlap: the list needs ``n // (long_range + 1) + groups + 1`` entries in all.

MAX_GROUPS = wp.constant(2048)
"""Largest number of parent groups of the long-range list (the fill kernel scans their lengths as one tile)."""
LONG_SHIFT = wp.constant(wp.int64(32))
LONG_ONE = wp.constant(wp.int64(1 << 32))
LOW_MASK = wp.constant(wp.int64(0xFFFFFFFF))


@wp.func
def long_base_of(first_slot: int, long_range: int, group: int):
    """First list entry of a group whose offspring start at output slot ``first_slot``."""
    return first_slot // (long_range + 1) + group


@wp.func
def record_long_range(
    lo: int,
    hi: int,
    parent: int,
    group: int,
    base: int,
    ancestors: wp.array(dtype=wp.int32),
    long_meta: wp.array(dtype=wp.int64),
    long_lo: wp.array(dtype=wp.int32),
    long_off: wp.array(dtype=wp.int32),
):
    """A long offspring range ``[lo, hi)`` (more than ``long_range`` slots; the callers write shorter ones
    themselves): write ``parent`` to its first slot and append a list entry (first unwritten slot, offset in the
    group's concatenated long ranges) for :func:`long_ranges_fill_kernel`."""
    ancestors[lo] = parent
    old = wp.atomic_add(long_meta, group, LONG_ONE + wp.int64(hi - lo - 1))
    k = base + int(old >> LONG_SHIFT)
    long_lo[k] = lo + 1
    long_off[k] = int(old & LOW_MASK)


@wp.func
def low_word(v: wp.int64):
    """The length field (low 32 bits) of a packed ``long_meta`` entry."""
    return wp.int32(v & LOW_MASK)


@wp.func_native("""
#if defined(__CUDA_ARCH__)
    return __syncthreads_or(flag);
#else
    return flag;
#endif
""")
def block_any(flag: int) -> int:
    """Non-zero when ``flag`` is non-zero in any thread of the block (every thread must call it; one barrier)."""
    ...


@wp.kernel
def long_ranges_fill_kernel(
    long_meta: wp.array(dtype=wp.int64),
    long_base: wp.array(dtype=wp.int32),
    long_lo: wp.array(dtype=wp.int32),
    long_off: wp.array(dtype=wp.int32),
    groups: int,
    fill_blocks: int,
    ancestors: wp.array(dtype=wp.int32),
):
    """Fill the recorded long offspring ranges with every thread of a fixed grid (after the scatter kernel).

    Each block first checks the groups' long-range lengths for a non-zero one (one barrier) and returns at once when
    there is none (the usual case: the scan below took 12 us per launch on an H100 with nothing to fill); else it
    scans them (one tile of :data:`MAX_GROUPS`; entries past ``groups`` must be zero), and the threads walk the
    concatenated long slots with a grid stride (consecutive threads, consecutive slots); a thread finds the group of
    its flat index by binary search over the scan, the range within the group by binary search over the offsets,
    and searches again only when its index leaves the current range (the group search only when it leaves the
    group). The parent is read back from the range's first slot, written by the scatter kernel. Launch
    ``wp.launch_tiled(dim=[fill_blocks])``.

    Args:
        long_meta: (>= groups,) packed ``count << 32 | total length`` of each group's recorded ranges.
        long_base: (>= groups,) first list entry of each group.
        long_lo, long_off: list entries: first unwritten slot, offset within the group's concatenation.
        groups: number of parent groups of this call (at most :data:`MAX_GROUPS`).
        fill_blocks: launch dimension (the grid stride is ``fill_blocks x block_dim``).
        ancestors: (n,) int32 output parent indices (completed in place).
    """
    b, lane = wp.tid()
    found = int(0)
    for j in range(lane, groups, wp.block_dim()):
        if low_word(long_meta[j]) != 0:
            found = 1
    if block_any(found) == 0:  # the usual case: one barrier, not the scan of MAX_GROUPS entries below
        return
    ends = wp.tile_scan_inclusive(wp.tile_map(low_word, wp.tile_load(long_meta, shape=MAX_GROUPS)))
    total = ends[MAX_GROUPS - 1]
    if total == 0:
        return
    f = b * wp.block_dim() + lane
    stride = fill_blocks * wp.block_dim()
    # dynamic variables: the current group (flat indices [gstart, gend), list entries [base, base + cnt)) and range
    # (flat indices [start, end) -> slots from slot0); f only grows, so both searches only move forward
    gstart = int(0)  # noqa: UP018
    gend = int(0)  # noqa: UP018
    base = int(0)  # noqa: UP018
    cnt = int(0)  # noqa: UP018
    a = int(0)  # noqa: UP018
    start = int(0)  # noqa: UP018
    end = int(0)  # noqa: UP018
    slot0 = int(0)  # noqa: UP018
    parent = int(0)  # noqa: UP018
    while f < total:
        if f >= end:
            if f >= gend:
                lo = int(0)  # noqa: UP018 (first group g with ends[g] > f)
                hi = groups
                while lo < hi:
                    mid = (lo + hi) // 2
                    if ends[mid] > f:
                        hi = mid
                    else:
                        lo = mid + 1
                m = long_meta[lo]
                gend = int(ends[lo])
                gstart = gend - int(m & LOW_MASK)
                cnt = int(m >> LONG_SHIFT)
                base = int(long_base[lo])
                a = 0
            local = f - gstart
            z = cnt - 1  # last entry k >= a with long_off[base + k] <= local
            while a < z:
                mid = (a + z + 1) // 2
                if int(long_off[base + mid]) <= local:
                    a = mid
                else:
                    z = mid - 1
            start = gstart + int(long_off[base + a])
            end = gend
            if a + 1 < cnt:
                end = gstart + int(long_off[base + a + 1])
            slot0 = int(long_lo[base + a])
            parent = int(ancestors[slot0 - 1])
        ancestors[slot0 + f - start] = parent
        f += stride


@wp.kernel
def systematic_kernel(
    weights: wp.array(dtype=wp.float64),
    cdf: wp.array(dtype=wp.float64),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    enabled: wp.array(dtype=wp.int32),
    n: int,
    long_range: int,
    chunk: int,
    ancestors: wp.array(dtype=wp.int32),
    long_meta: wp.array(dtype=wp.int64),
    long_base: wp.array(dtype=wp.int32),
    long_lo: wp.array(dtype=wp.int32),
    long_off: wp.array(dtype=wp.int32),
):
    """Systematic resampling as an O(n) scatter over parents (one uniform ``U`` per frame, counter index 0).

    Parent ``i`` writes its index to the output slots ``[floor(n C_{i-1}/T + U), floor(n C_i/T + U))``; the first
    parent starts at 0 and the last ends at ``n``, so every slot is written (exactly once for a monotone CDF).
    Ranges longer than ``long_range`` go to the long-range list of group ``i // chunk`` (``long_meta`` zeroed
    before the launch) and :func:`long_ranges_fill_kernel` completes them.

    Args:
        weights: (n,) unnormalised non-negative weights.
        cdf: (n,) inclusive prefix sum of ``weights``.
        seed: the run's 64-bit Philox key.
        frame: (1,) filter iteration.
        enabled: (1,) 0 -> identity.
        n: number of particles (launch dimension).
        long_range, chunk: the longest range written by its own thread; parents per group of the list.
        ancestors: (n,) output parent indices.
        long_meta, long_base, long_lo, long_off: the long-range list (see :func:`record_long_range`).
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
    g = i // chunk
    first = g * chunk
    base = int(0)  # noqa: UP018 (dynamic variable: the group's list base, needed by its first and long parents)
    if i == first or hi - lo > long_range:
        if first > 0:
            base = systematic_slot(cdf[first - 1], nf, total, u, n)
        base = long_base_of(base, long_range, g)
    if i == first:
        long_base[g] = base
    if hi <= lo:
        return
    k = positive_parent(weights, i, n)
    if hi - lo > long_range:
        record_long_range(lo, hi, k, g, base, ancestors, long_meta, long_lo, long_off)
    else:
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
    long_range: int,
    chunk: int,
    ancestors: wp.array(dtype=wp.int32),
    long_meta: wp.array(dtype=wp.int64),
    long_base: wp.array(dtype=wp.int32),
    long_lo: wp.array(dtype=wp.int32),
    long_off: wp.array(dtype=wp.int32),
):
    """Deterministic part of residual resampling: parent ``i`` fills ``counts_i`` slots ending at ``positions[i]``.

    Ranges longer than ``long_range`` go to the long-range list of group ``i // chunk`` (``long_meta`` zeroed before
    the launch); :func:`long_ranges_fill_kernel` completes them before :func:`residual_draw_kernel` runs.

    Args:
        counts: (n,) deterministic copies per parent.
        positions: (n,) inclusive prefix sum of ``counts``.
        enabled: (1,) 0 -> identity.
        n: number of particles (launch dimension).
        long_range, chunk: the longest range written by its own thread; parents per group of the list.
        ancestors: (n,) output parent indices (slots ``[0, sum(counts))``).
        long_meta, long_base, long_lo, long_off: the long-range list (see :func:`record_long_range`).
    """
    i = wp.tid()
    if enabled[0] == 0:
        ancestors[i] = i
        return
    end = wp.min(positions[i], n)
    start = positions[i] - counts[i]
    g = i // chunk
    first = g * chunk
    base = int(0)  # noqa: UP018 (dynamic variable: the group's list base, needed by its first and long parents)
    if i == first or end - start > long_range:
        if first > 0:
            base = wp.min(positions[first - 1], n)
        base = long_base_of(base, long_range, g)
    if i == first:
        long_base[g] = base
    if end - start > long_range:
        record_long_range(start, end, i, g, base, ancestors, long_meta, long_lo, long_off)
    else:
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


# --- systematic resampling straight from log-weights, with an exact integer CDF ---------------------------------
#
# The weights w_i = exp(logw_i - max) are quantised to integers q_i = floor(w_i 2^k) (k chosen by the driver so that
# sum q < 2^60) and the CDF is an exact int64 prefix sum: no rounding, no order dependence, and zero weights give
# empty offspring ranges by construction. The block-level sums and scans are int64 warp-shuffle scans
# (:func:`block_scan_int64`, native CUDA: Warp's tile scans take 32-bit types only).


BLOCK_SCAN_SNIPPET = """
#if defined(__CUDA_ARCH__)
    __shared__ long long warp_totals[32];
    const int w = lane >> 5;
    const int l = lane & 31;
    const int warps = (bd + 31) >> 5;
    long long x = v;
#pragma unroll
    for (int d = 1; d < 32; d <<= 1) {
        const long long y = __shfl_up_sync(0xffffffffu, x, d);
        if (l >= d) x += y;
    }
    if (l == 31) warp_totals[w] = x;
    __syncthreads();
    if (w == 0) {
        long long t = l < warps ? warp_totals[l] : 0;
#pragma unroll
        for (int d = 1; d < 32; d <<= 1) {
            const long long y = __shfl_up_sync(0xffffffffu, t, d);
            if (l >= d) t += y;
        }
        if (l < warps) warp_totals[l] = t;
    }
    __syncthreads();
    if (w > 0) x += warp_totals[w - 1];
    const long long total = warp_totals[warps - 1];
    __syncthreads();
    return wp::vec_t<2, wp::int64>(x, total);
#else
    return wp::vec_t<2, wp::int64>(v, v);
#endif
"""


@wp.func_native(BLOCK_SCAN_SNIPPET)
def block_scan_int64(v: wp.int64, lane: int, bd: int) -> wp.vec2l:
    """``(inclusive prefix sum of v over the block's lanes 0..lane, the block's total)``, exact in int64.

    One warp-shuffle scan per warp and one over the warp totals, 3 barriers. It replaced three scans of 20-bit limbs
    with Warp's 32-bit tile scans (about 20 barriers per round, counted in Warp 1.19's ``tile_scan.h``) in the
    systematic pass (BENCHMARKS.md, issue 13).
    CUDA: every lane of the block calls it, ``bd`` (the block size) a multiple of 32, at most 1024. The CPU branch is
    the one-lane block of the CPU backend: the kernels that call it are launched with ``block_dim=1`` there.
    """
    ...


@wp.func
def quantise(w: float, scale: wp.float64):
    """q = floor(w * scale) as int64 for a float32 weight w in [0, 1]."""
    return wp.int64(wp.floor(wp.float64(w) * scale))


@wp.func
def quantised_weight(logw: float, max_logw: float, scale: wp.float64):
    """q_i = floor(exp(logw_i - max) scale): both systematic passes evaluate it from the log-weight (the same float32
    operations, hence the same integer) instead of the second pass reading a stored weight."""
    return quantise(wp.exp(logw - max_logw), scale)


@wp.kernel
def quantised_totals_kernel(
    logw: wp.array(dtype=wp.float32),
    est: wp.array(dtype=wp.float64),
    max_slot: int,
    scale: wp.float64,
    n: int,
    chunk: int,
    totals: wp.array(dtype=wp.int64),
):
    """Pass 1 of systematic resampling from log-weights: ``totals[b]`` = sum of q_i = floor(exp(logw_i - max) scale)
    over block b's particles ``[b chunk, (b+1) chunk)``. ``est[max_slot]`` holds the max log-weight. Launch
    ``wp.launch_tiled(dim=[blocks])``.
    """
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    mx = wp.float32(est[max_slot])
    acc = wp.int64(0)
    for i in range(start + lane, stop, wp.block_dim()):
        acc += quantised_weight(logw[i], mx, scale)
    t = block_scan_int64(acc, lane, wp.block_dim())[1]
    if lane == 0:
        totals[b] = t


@wp.func
def systematic_slot_exact(c: wp.int64, ratio: wp.float64, u: wp.float64, n: int):
    """Output slot boundary ``floor(c n / T + U)`` of the exact cumulative weight ``c``, clamped to [0, n].

    ``ratio`` = n / T. Every rounding step is monotone in ``c``, and both neighbours of a boundary evaluate it from
    the same integer, so the offspring ranges tile [0, n) without gaps or overlaps."""
    x = wp.floor(wp.float64(c) * ratio + u)
    s = int(0)  # noqa: UP018 (dynamic variable)
    if x >= wp.float64(n):
        s = n
    elif x > wp.float64(0.0):
        s = int(x)
    return s


@wp.kernel
def systematic_logw_kernel(
    logw: wp.array(dtype=wp.float32),
    est: wp.array(dtype=wp.float64),
    max_slot: int,
    scale: wp.float64,
    totals: wp.array(dtype=wp.int64),
    blocks: int,
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    enabled: wp.array(dtype=wp.int32),
    n: int,
    chunk: int,
    per_lane: int,
    long_range: int,
    ancestors: wp.array(dtype=wp.int32),
    long_meta: wp.array(dtype=wp.int64),
    long_base: wp.array(dtype=wp.int32),
    long_lo: wp.array(dtype=wp.int32),
    long_off: wp.array(dtype=wp.int32),
):
    """Pass 2 of systematic resampling from log-weights: exact scan and O(N) scatter, fused.

    Block ``b`` owns particles ``[b chunk, (b+1) chunk)``. Its offset (the sum of the earlier blocks' ``totals``)
    and the grand total T are summed exactly by the block itself; it then walks its particles in rounds of
    ``block_dim x per_lane`` particles (``per_lane`` contiguous ones per lane), scans the rounds' q_i exactly (int64
    warp shuffles) and writes parent ``i`` to the slots ``[slot(C_{i-1}), slot(C_i))`` with
    ``slot(c) = floor(n c / T + U)`` and one uniform U per frame (Philox counter ``(0, frame, STREAM_RESAMPLE)``,
    as :func:`systematic_kernel`). When ``enabled[0] == 0`` it writes the identity. A range longer than
    ``long_range`` slots goes to block b's long-range list (the block zeroes its ``long_meta[b]`` first) and
    :func:`long_ranges_fill_kernel`, launched next, completes it. Launch
    ``wp.launch_tiled(dim=[blocks], block_dim=B)``.

    Args:
        logw, est, max_slot: the float32 log-weights and the max log-weight ``est[max_slot]``, as in
            :func:`quantised_totals_kernel`.
        scale: 2^k of the quantisation (the same value as in :func:`quantised_totals_kernel`).
        totals: (blocks,) int64 per-block sums of q from :func:`quantised_totals_kernel`.
        blocks, chunk: the block partition of the particles.
        per_lane: contiguous particles per lane and scan round (any value >= 1 is exact).
        seed, frame, enabled: as :func:`systematic_kernel`.
        n: number of particles.
        long_range: the longest offspring range a lane writes itself.
        ancestors: (n,) int32 output parent indices.
        long_meta, long_base, long_lo, long_off: the long-range list (:func:`record_long_range`), a group per block.
    """
    b, lane = wp.tid()
    bd = wp.block_dim()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    if lane == 0:
        long_meta[b] = wp.int64(0)  # before the block-wide sums below (with several warps: a __syncthreads)
    if enabled[0] == 0:
        for i in range(start + lane, stop, bd):
            ancestors[i] = i
        return
    below = wp.int64(0)
    every = wp.int64(0)
    for j in range(lane, blocks, bd):
        t = totals[j]
        every += t
        if j < b:
            below += t
    offset = block_scan_int64(below, lane, bd)[1]
    total = block_scan_int64(every, lane, bd)[1]
    u = word_to_unit64(random_words(seed, 0, frame[0], STREAM_RESAMPLE)[0])
    ratio = wp.float64(n) / wp.float64(total)
    mx = wp.float32(est[max_slot])
    list_base = long_base_of(systematic_slot_exact(offset, ratio, u, n), long_range, b)
    if lane == 0:
        long_base[b] = list_base
    carry = offset
    for base in range(start, stop, bd * per_lane):
        first = base + lane * per_lane
        own = wp.int64(0)
        for k in range(per_lane):
            if first + k < stop:
                own += quantised_weight(logw[first + k], mx, scale)
        scan = block_scan_int64(own, lane, bd)
        c = carry + scan[0] - own  # exact cumulative weight before this lane's first particle
        lo = systematic_slot_exact(c, ratio, u, n)
        for k in range(per_lane):
            i = first + k
            if i < stop:
                c += quantised_weight(logw[i], mx, scale)
                hi = systematic_slot_exact(c, ratio, u, n)
                if i == n - 1:
                    hi = n
                if hi - lo > long_range:
                    record_long_range(lo, hi, i, b, list_base, ancestors, long_meta, long_lo, long_off)
                else:
                    for s in range(lo, hi):
                        ancestors[s] = i
                lo = hi
        carry += scan[1]  # the round's total


@wp.kernel
def weights_from_log_kernel(
    logw: wp.array(dtype=wp.float32),
    est: wp.array(dtype=wp.float64),
    max_slot: int,
    weights: wp.array(dtype=wp.float64),
):
    """``weights[i] = exp(logw[i] - est[max_slot])`` in float64 (the input of the search-based schemes)."""
    i = wp.tid()
    weights[i] = wp.exp(wp.float64(logw[i]) - est[max_slot])


@wp.kernel
def quantised_weights_kernel(
    logw: wp.array(dtype=wp.float32),
    est: wp.array(dtype=wp.float64),
    max_slot: int,
    scale: wp.float64,
    q: wp.array(dtype=wp.int64),
):
    """The integer weights q_i = floor(exp(logw_i - max) scale) of the systematic passes (tests and diagnostics)."""
    i = wp.tid()
    q[i] = quantised_weight(logw[i], wp.float32(est[max_slot]), scale)


# --- one systematic resampling per row of weights, in one launch (the template tracker's independent groups) ----


@wp.func
def slot_at(cdf: wp.array2d(dtype=wp.int64), g: int, ratio: wp.float64, u: wp.float64, n: int, i: int):
    """``slot(C_i)`` of row ``g`` (:func:`systematic_slot_exact`), ``n`` for the last parent (as the scatter)."""
    s = n
    if i < n - 1:
        s = systematic_slot_exact(cdf[g, i], ratio, u, n)
    return s


@wp.func
def first_above(cdf: wp.array2d(dtype=wp.int64), g: int, ratio: wp.float64, u: wp.float64, n: int, j: int, lo: int,
                hi: int):  # fmt: skip
    """The smallest parent ``i`` in ``[lo, hi]`` with ``slot(C_i) > j`` (``hi`` is one, or the last parent): the
    parent of output slot ``j`` when ``lo`` is at or below it."""
    while lo < hi:
        mid = (lo + hi) // 2
        if slot_at(cdf, g, ratio, u, n, mid) > j:
            hi = mid
        else:
            lo = mid + 1
    return lo


@wp.kernel
def grouped_systematic_kernel(
    weights: wp.array2d(dtype=wp.float64),
    active: wp.array(dtype=wp.int32),
    part_q: wp.array2d(dtype=wp.int64),
    blocks: int,
    chunk: int,
    scale: wp.float64,
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    n: int,
    cdf: wp.array2d(dtype=wp.int64),
    ancestors: wp.array2d(dtype=wp.int32),
):
    """Systematic resampling of every row ``g`` of ``weights`` on its own, on the exact integer CDF of
    :func:`systematic_logw_kernel`: ``q_i = floor(w_i scale)``, ``C_i = q_0 + ... + q_i``, and output slot ``j`` takes
    the parent ``min{i : slot(C_i) > j}`` with ``slot(c) = floor(n c / T + U_g)`` (clamped to [0, n], ``slot(C_{n-1})
    = n``): parent ``i`` fills ``[slot(C_{i-1}), slot(C_i))``, as in the scatter of :func:`systematic_logw_kernel`. One
    uniform per row and frame (Philox counter ``(g, frame, STREAM_RESAMPLE)``: independent draws for the rows; row 0
    draws the joint filter's U). Rows with ``active[g] == 0`` get the identity.

    Launch ``wp.launch_tiled(dim=[G, blocks], block_dim=B)``: block ``(g, b)`` owns the parents ``[b chunk, (b+1)
    chunk)`` of row ``g`` and, because ``slot`` is monotone, the contiguous output slots ``[slot(C_{start-1}),
    slot(C_{stop-1}))`` they fill. Its offset ``C_{start-1}`` and the row total ``T`` come from the per-block sums
    ``part_q`` (``kernels.templates.slots.block_slot_moments_kernel`` writes them beside the weights); the block writes
    its parents' CDF (int64 warp-shuffle scans), then each lane takes a contiguous run of the block's output slots: a
    binary search inside the block's parents for the first one, then a galloping search forward from parent to parent.
    No lane writes a long offspring range alone, so weights concentrated on one parent cost no more than spread ones,
    and every row's work spreads over ``blocks`` blocks. CPU backend: one lane per block.

    Args:
        weights: (G, n) float64 non-negative weights, at most 1 (``exp(logw - max)``), with a positive maximum.
        active: (G,) 1 for the rows to resample.
        part_q: (blocks, G) int64 sums of ``q_i`` over each block's parents (rows of inactive groups unread).
        blocks, chunk: blocks per row and parents per block (``blocks chunk >= n``).
        scale: 2^k with ``n 2^k <= 2^60`` (``wptrack.core.resampling.quantisation_bits``).
        seed, frame: the run's key and the filter iteration.
        n: particles per row.
        cdf: (G, n) int64 scratch: the rows' exact CDFs.
        ancestors: (G, n) int32 output parents.
    """
    g, b, lane = wp.tid()
    bd = wp.block_dim()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    if stop <= start:  # uniform over the block: no parents, no output slots
        return
    if active[g] == 0:
        for i in range(start + lane, stop, bd):
            ancestors[g, i] = i
        return
    before = wp.int64(0)
    every = wp.int64(0)
    for k in range(lane, blocks, bd):
        v = part_q[k, g]
        every += v
        if k < b:
            before += v
    total = block_scan_int64(every, lane, bd)[1]
    carry = block_scan_int64(before, lane, bd)[1]  # C_{start-1}
    u = word_to_unit64(random_words(seed, g, frame[0], STREAM_RESAMPLE)[0])
    ratio = wp.float64(n) / wp.float64(total)
    j0 = systematic_slot_exact(carry, ratio, u, n)  # slot(C_{start-1}); 0 for the first block (U < 1)
    for base in range(start, stop, bd):  # the block's parents' CDF, a round of bd parents at a time
        i = base + lane
        own = wp.int64(0)
        if i < stop:
            own = wp.int64(wp.floor(weights[g, i] * scale))
        scan = block_scan_int64(own, lane, bd)
        if i < stop:
            cdf[g, i] = carry + scan[0]
        carry += scan[1]
    block_scan_int64(wp.int64(0), lane, bd)  # a block barrier: every lane's CDF entries are written
    last = stop - 1
    j1 = slot_at(cdf, g, ratio, u, n, last)
    # each lane a contiguous run of the block's output slots: a binary search for the first one's parent, then gallop
    per = (j1 - j0 + bd - 1) // bd
    k0 = wp.min(j0 + lane * per, j1)
    k1 = wp.min(k0 + per, j1)
    if k0 < k1:
        i = first_above(cdf, g, ratio, u, n, k0, start, last)
        for j in range(k0, k1):
            if slot_at(cdf, g, ratio, u, n, i) <= j:
                lo = i + 1
                step = int(1)
                hi = wp.min(i + 1, last)
                while hi < last and slot_at(cdf, g, ratio, u, n, hi) <= j:
                    lo = hi + 1
                    step = step * 2
                    hi = wp.min(i + step, last)
                i = first_above(cdf, g, ratio, u, n, j, lo, hi)
            ancestors[g, j] = i
