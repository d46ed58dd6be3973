"""XOR matching penalty, complexity penalty and log-weights of the S3 template tracker (Juza et al., eqs. 4-6).

The matching penalty of particle i against the motion image q (H x W, values 0/1) is the number of pixels where q
and the virtual scene v_i differ (eq. 4). It is computed without an image per particle:
``m_i = |q| + |v_i| - 2 |q AND v_i|``, where ``|v_i|`` and ``|q AND v_i|`` are summed over the covered spans of
each row only (``|q AND span|`` from the row prefix sums of q in O(1)). The same pass records the particle's
spans in a per-row difference array of coverage counts (two atomic adds per span, spread over the image), from
which ``kernels.templates.uoh`` builds the Uncovered Object Histogram. The exclusion prior added to eq. 5's
complexity (objects of a particle on the same ground) is ``kernels.templates.exclusion``'s.
"""

import functools

import warp as wp

from wptrack.kernels.core.reduce import NEG_INF, block_argmax, finite_logw
from wptrack.kernels.templates.exclusion import pair_overlap
from wptrack.kernels.templates.partition import group_at
from wptrack.kernels.templates.raster import (
    MAX_PIECES,
    PIECES,
    hull_chain_span,
    vec_pieces,
    vec_slots,
    vec_slots_i,
)

wp.set_module_options({"enable_backward": False})


@wp.func
def row_segment(width: int, lane: int):
    """The columns ``[x0, x1)`` that lane ``lane`` of a row block owns: ``ceil(width / block_dim)`` contiguous
    pixels each (the whole row on the CPU backend, where a block has one thread); empty for lanes past the row."""
    seg = (width + wp.block_dim() - 1) // wp.block_dim()
    x0 = wp.min(lane * seg, width)
    return x0, wp.min(x0 + seg, width)


@wp.kernel
def mask_rows_kernel(q: wp.array2d(dtype=wp.uint8), qrow: wp.array2d(dtype=wp.int32)):
    """Row prefix sums of the motion mask: ``qrow[y, x] = sum(q[y, :x] != 0)``; qrow (H, W+1) pixels.

    Launch with ``wp.launch_tiled(dim=[H], block_dim=B)``: block ``y`` is row ``y``; each lane counts its
    segment of the row (``row_segment``), a block-wide exclusive scan of the counts gives every lane its start,
    then each lane writes its segment's prefix sums. Exact for any block size (one lane on the CPU backend).
    """
    y, lane = wp.tid()
    x0, x1 = row_segment(q.shape[1], lane)
    acc = int(0)
    if wp.block_dim() > 1:  # uniform over the block: every lane reaches the scan or none does
        for x in range(x0, x1):
            if q[y, x] != wp.uint8(0):
                acc += 1
        acc = wp.untile(wp.tile_scan_exclusive(wp.tile(acc)))
    if lane == 0:
        qrow[y, 0] = 0
    for x in range(x0, x1):
        if q[y, x] != wp.uint8(0):
            acc += 1
        qrow[y, x + 1] = acc


@wp.kernel
def mask_total_kernel(qrow: wp.array2d(dtype=wp.int32), total: wp.array(dtype=wp.int32)):
    """``total[0] = |q|`` (pixels) from the row prefix sums qrow (H, W+1).

    Launch with ``wp.launch_tiled(dim=[1], block_dim=B)``: the lanes stride over the rows' totals
    ``qrow[:, W]`` and one ``tile_sum`` combines them (no single-address atomics).
    """
    _b, lane = wp.tid()
    w = qrow.shape[1] - 1
    acc = int(0)
    for y in range(lane, qrow.shape[0], wp.block_dim()):
        acc += qrow[y, w]
    t = wp.tile_sum(wp.tile(acc))
    if lane == 0:
        total[0] = t[0]


@wp.func
def particle_score(
    i: int,
    covered: int,
    both: int,
    kind: wp.array2d(dtype=wp.int32),
    age: wp.array2d(dtype=wp.float32),
    pos: wp.array2d(dtype=wp.vec2),
    heading: wp.array2d(dtype=wp.float32),
    dims: wp.array2d(dtype=wp.vec3),
    qtotal: int,
    cost_a: wp.vec4,
    cost_b: wp.vec4,
    scale: float,
    bg_weight: float,
    exclusion: float,
    logw_prior: float,
):
    """``(m_i, c_i, logw_i)`` of particle ``i`` from ``covered`` = |v_i| and ``both`` = |q AND v_i| (pixels): eq. 4,
    eq. 5 with the exclusion prior (see ``xor_score_kernel``) and eq. 6 in log space, in one fixed order of
    floating-point operations (both score paths call it, so they agree bit for bit)."""
    slots = kind.shape[1]
    m = qtotal + covered - 2 * both  # eq. 4 as |q| + |v| - 2 |q AND v|
    cost = float(0.0)
    for s in range(slots):
        kk = kind[i, s]
        if kk > 0:
            cost += cost_a[kk] + cost_b[kk] * wp.exp(-age[i, s])  # eq. 5
            if exclusion > 0.0:
                for t in range(s + 1, slots):
                    kt = kind[i, t]
                    if kt > 0:
                        o = pair_overlap(
                            kk, pos[i, s], heading[i, s], dims[i, s], kt, pos[i, t], heading[i, t], dims[i, t]
                        )
                        cost += exclusion * o
    # weighted eq. 4: uncovered foreground + lambda x template pixels on background (= m when lambda = 1)
    mw = float(qtotal - both) + bg_weight * float(covered - both)
    return m, cost, finite_logw(logw_prior - (mw + cost) * scale)  # eq. 6 in log space; -inf/NaN -> the floor


@wp.kernel
def xor_score_kernel(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    kind: wp.array2d(dtype=wp.int32),
    age: wp.array2d(dtype=wp.float32),
    pos: wp.array2d(dtype=wp.vec2),
    heading: wp.array2d(dtype=wp.float32),
    dims: wp.array2d(dtype=wp.vec3),
    qrow: wp.array2d(dtype=wp.int32),
    qtotal: wp.array(dtype=wp.int32),
    cost_a: wp.vec4,
    cost_b: wp.vec4,
    scale: float,
    bg_weight: float,
    exclusion: float,
    group_box: wp.array(dtype=wp.vec4i),
    n_groups: wp.array(dtype=wp.int32),
    slot_hi: wp.array(dtype=wp.int32),
    logw: wp.array(dtype=wp.float32),
    penalty: wp.array(dtype=wp.int32),
    complexity: wp.array(dtype=wp.float32),
    cov_diff: wp.array2d(dtype=wp.int32),
    group_sums: wp.array2d(dtype=wp.vec2i),
):
    """Matching penalty (eq. 4), complexity penalty (eq. 5) and log-weight (eq. 6) of every particle.

    Launch with ``wp.launch_tiled(dim=[N], block_dim=B)``: block ``i`` is particle ``i`` and each of its threads
    takes a contiguous run of the rows its templates cover (``row_segment``; one thread per block on the CPU
    backend). Along its rows a thread walks the hull chains (``raster.hull_chain_span``) of the pieces drawn on the
    row (an active list of the pieces sorted by first row: a row costs the pieces it meets, not ``R_max``), keeps
    their spans sorted and merges them into the row's disjoint intervals (as ``raster.row_intervals``).

    Args:
        hull_pts, hull_n, hull_rows: the particles' piece hulls from ``raster.template_hulls_kernel``.
        kind: (N, R) KIND_* per slot. age: (N, R) seconds each object has been in the particle (tau of eq. 5).
        pos, heading, dims: (N, R) ground position (metres), heading (radians), dims (metres) per slot.
        qrow: (H, W+1) row prefix sums of the motion mask; qtotal: (1,) |q|.
        cost_a, cost_b: a_r and b_r of eq. 5 indexed by kind (pixels; index 0 unused).
        scale: s / (W H) of eq. 6 (1 / pixels).
        bg_weight: weight lambda of a template pixel on mask background in the weighted penalty
            ``m'_i = |q AND NOT v_i| + lambda |v_i AND NOT q|`` that enters the log-weight (1: eq. 4 exactly; < 1
            when the masks miss parts of objects more often than they show motion where there is none).
        exclusion: cost of two objects sharing the same ground, pixels: ``c_i`` gains ``exclusion x
            pair_overlap`` for every pair of objects (0: eq. 5 exactly). Solid objects cannot overlap on the
            ground; eq. 5's complexity penalty was introduced against objects placed at very similar positions, and
            this prior says so directly (it keeps two hypotheses off one person and humans off a car).
        group_box, n_groups: the boxes of the slots' independent groups (``kernels.templates.partition``); with
            ``n_groups[0]`` = 0 no group sums are kept (the joint filter).
        slot_hi: (1,) the slots from ``slot_hi[0]`` on are empty in every particle (``partition.group_slots_kernel``;
            R when unknown): only the pieces below it are scanned (the same sums: empty slots draw no piece).
        logw: (N,) log-weight, updated in place: ``logw_i += -(m'_i + c_i) s / (W H)`` (it holds the prior
            log-weight after prediction: 0 after resampling).
        penalty: (N,) m_i, pixels (exact). complexity: (N,) c_i, pixels.
        cov_diff: (H, W+1) per-row difference array of coverage counts; each covered span [u0, u1] adds 1 at
            u0 and -1 at u1 + 1 (zeroed again by ``uoh.coverage_uoh_kernel``).
        group_sums: (N, R) per group ``(|v_i|, |q AND v_i|)`` inside its box, pixels, added to (it must hold zeros;
            :func:`group_logw_kernel` clears it). Each merged interval lies in one group's box (the boxes are a
            column apart), found by :func:`kernels.templates.partition.group_at`; a lane adds its totals once per group.
    """
    i, lane = wp.tid()
    slots = kind.shape[1]
    pieces = wp.min(slots, slot_hi[0]) * PIECES  # the pieces of the slots some particle holds
    width = qrow.shape[1] - 1
    y0 = qrow.shape[0]  # empty row range unless a piece is visible
    y1 = int(-1)
    r0 = vec_pieces()  # each piece's rows (an empty range for pieces not drawn), read once
    r1 = vec_pieces()
    for q in range(pieces):
        r = hull_rows[i, q]
        if hull_n[i, q] > 0:
            r0[q] = r[0]
            r1[q] = r[1]
            y0 = wp.min(y0, r[0])
            y1 = wp.max(y1, r[1])
        else:
            r0[q] = 1
            r1[q] = 0
    covered = int(0)
    both = int(0)
    groups = n_groups[0]
    gcov = vec_slots_i()  # per group: this lane's |v| and |q AND v| (partitioned filter only)
    gboth = vec_slots_i()
    down = vec_pieces()  # the pieces' hull chain walks (raster.hull_chain_span) over this lane's rows
    up = vec_pieces()
    s0 = vec_pieces()  # the row's piece spans sorted by start (raster.row_intervals, written out: no vector copies)
    s1 = vec_pieces()
    # the drawn pieces in order of their first row, then a list of the pieces drawn on the current row (a row costs
    # the pieces it meets, not R_max; the merged intervals do not depend on the order the pieces are visited in)
    order = vec_pieces()
    drawn = int(0)
    for q in range(pieces):
        if r0[q] <= r1[q]:
            j = drawn
            while j > 0 and r0[order[j - 1]] > r0[q]:
                order[j] = order[j - 1]
                j -= 1
            order[j] = q
            drawn += 1
    active = vec_pieces()
    n_active = int(0)
    next_piece = int(0)
    ya, yb = row_segment(wp.max(y1 - y0 + 1, 0), lane)  # this lane's run of rows: the walks move forward row by row
    for y in range(y0 + ya, y0 + yb):
        yf = float(y)
        while next_piece < drawn and r0[order[next_piece]] <= y:
            if r1[order[next_piece]] >= y:
                active[n_active] = order[next_piece]
                n_active += 1
            next_piece += 1
        n = int(0)
        k = int(0)
        while k < n_active:
            q = active[k]
            if y > r1[q]:  # the piece ended above this row: drop it (the last one takes its place)
                n_active -= 1
                active[k] = active[n_active]
                continue
            k += 1
            u0, u1, dq, uq = hull_chain_span(hull_pts, i, q, hull_n[i, q], yf, width, down[q], up[q])
            down[q] = dq
            up[q] = uq
            if u0 <= u1:
                j = n
                while j > 0 and s0[j - 1] > u0:
                    s0[j] = s0[j - 1]
                    s1[j] = s1[j - 1]
                    j -= 1
                s0[j] = u0
                s1[j] = u1
                n += 1
        # merge the sorted spans into disjoint intervals [a, b] (separated by an uncovered pixel) and count them
        if n > 0:
            a = s0[0]
            b = s1[0]
            for k in range(1, n + 1):
                if k < n and s0[k] <= b + 1:
                    b = wp.max(b, s1[k])
                else:
                    cv = b - a + 1
                    bo = qrow[y, b + 1] - qrow[y, a]
                    covered += cv
                    both += bo
                    if groups > 0:
                        g = group_at(group_box, groups, a, y)
                        if g >= 0:  # always, by construction of the boxes
                            gcov[g] += cv
                            gboth[g] += bo
                    wp.atomic_add(cov_diff, y, a, 1)
                    wp.atomic_add(cov_diff, y, b + 1, -1)
                    if k < n:
                        a = s0[k]
                        b = s1[k]
    for g in range(groups):
        if gcov[g] > 0:
            wp.atomic_add(group_sums, i, g, wp.vec2i(gcov[g], gboth[g]))
    tc = wp.tile_sum(wp.tile(covered))
    tb = wp.tile_sum(wp.tile(both))
    if lane == 0:
        m, cost, lw = particle_score(
            i, tc[0], tb[0], kind, age, pos, heading, dims, qtotal[0], cost_a, cost_b, scale, bg_weight, exclusion,
            logw[i],
        )  # fmt: skip
        penalty[i] = m
        complexity[i] = cost
        logw[i] = lw


# --- the XOR sums with a thread per (band of rows, particle) (CUDA) ---------------------------------------------
#
# In ``xor_score_kernel`` the lanes of a warp hold different rows of one particle, so they meet different pieces and
# hull edges and diverge (Nsight Compute, H100, 1e4 particles x 5 objects: 9.6 of 32 threads active per warp
# instruction, BENCHMARKS.md). ``xor_band_kernel`` puts neighbouring particles in a warp's lanes, all on the same
# band of image rows: resampling gives a parent's children neighbouring indices, so the lanes meet the same pieces
# at the same rows. A row's spans are sorted and merged exactly as in ``xor_score_kernel``; the particle's sums
# over its bands are added up in ``sums`` and ``xor_finish_kernel`` applies eqs. 4-6.


PACK = wp.constant(65536)
"""Packing base of two pixel coordinates in one int32 (``a * PACK + b``; images below 32768 pixels a side)."""
LOW = wp.constant(65535)


@functools.cache
def xor_band_kernel(cap: int, grouped: bool = False) -> wp.Kernel:
    """The band kernel for particles of at most ``cap`` pieces (a power of two, 2 to ``MAX_PIECES``), compiled once
    per ``cap`` and ``grouped``.

    Launch with ``dim=(1, ceil(H / band), N)``: thread ``(0, b, i)`` takes rows ``[b band, (b + 1) band)`` of
    particle ``i`` (neighbouring threads: neighbouring particles on the same rows) and adds its rows' |v_i| and |q AND
    v_i| to ``sums[i]`` (one atomic add per band that covers anything) and the merged intervals' coverage adds to
    ``cov_diff``, as ``xor_score_kernel`` does for the particle's rows.

    ``grouped`` (the partitioned filter, ``kernels.templates.partition``): launch with ``dim=(G, ceil(H / band), N)``
    for up to G groups; thread ``(g, b, i)`` takes the pieces of group ``g``'s slots only, on the rows of band ``b``
    inside the group's box (threads of unused groups and bands outside the box return at once), and adds its sums to
    ``sums[i]`` and ``group_sums[i, g]``. The groups' boxes are at least a column apart, so no merged interval mixes two
    groups: the per-group merging gives the same intervals, hence the same ``sums`` and ``cov_diff``, as the ungrouped
    launch (integer sums: bit for bit), with no per-thread table of groups.

    The per-piece arrays hold two coordinates per int32 (rows, walk positions, spans) in vectors of ``cap``
    entries: a thread's run-time indexed arrays live in local memory, and with 32 lanes per warp on 32 particles
    their footprint decides how much of it stays in L1 (3 x 64 bytes per thread at 5 objects, against 6 x 128
    bytes with the row kernel's separate per-piece arrays). Spans are sorted by (start, end) instead of (start,
    piece): the merged intervals, and so every output, are the same.

    Kernel args:
        hull_pts, hull_n, hull_rows: the particles' piece hulls from ``raster.template_hulls_kernel``
            (``hull_n.shape[1] <= cap``).
        qrow: (H, W+1) row prefix sums of the motion mask (H, W < 32768).
        band: rows per band.
        group_box, n_groups, slot_group: the groups' boxes, their count and each slot's group
            (``kernels.templates.partition``); read only when ``grouped``.
        slot_hi: (1,) only the pieces of the slots below ``slot_hi[0]`` are scanned (see ``xor_score_kernel``).
        sums: (N,) (|v_i|, |q AND v_i|), pixels; must hold zeros (``xor_finish_kernel`` clears it).
        cov_diff: (H, W+1) per-row difference array of coverage counts, as in ``xor_score_kernel``.
        group_sums: (N, R) with ``grouped``: the same sums per group (one atomic add per band and group that covers
            anything); must hold zeros. Not touched otherwise.
    """
    if cap not in (2, 4, 8, 16, 32, 64, 128):
        raise ValueError(f"xor_band_kernel: cap {cap} must be a power of two from 2 to {MAX_PIECES}")
    veci = wp.types.vector(length=cap, dtype=wp.int32)

    @wp.func
    def band_sums(
        hull_pts: wp.array3d(dtype=wp.vec2),
        hull_n: wp.array2d(dtype=wp.int32),
        hull_rows: wp.array2d(dtype=wp.vec2i),
        qrow: wp.array2d(dtype=wp.int32),
        i: int,
        ya: int,
        yb: int,
        slot_group: wp.array(dtype=wp.int32),
        g: int,
        pieces: int,
        cov_diff: wp.array2d(dtype=wp.int32),
    ):
        """(|v_i|, |q AND v_i|) over rows [ya, yb] of the first ``pieces`` pieces of particle ``i`` (of group ``g``'s
        slots only when ``g`` >= 0), with the merged intervals' coverage adds to ``cov_diff``."""
        width = qrow.shape[1] - 1
        rows = veci()  # each piece's rows within the band, first * PACK + last (PACK: first 1 > last 0, none)
        any_rows = int(0)
        for q in range(pieces):
            rows[q] = PACK
            if hull_n[i, q] > 0 and (g < 0 or slot_group[q // PIECES] == g):
                r = hull_rows[i, q]
                lo = wp.max(r[0], ya)
                hi = wp.min(r[1], yb)
                if lo <= hi:
                    rows[q] = lo * PACK + hi
                    any_rows = 1
        covered = int(0)
        both = int(0)
        if any_rows == 0:
            return covered, both
        walk = veci()  # the pieces' hull chain walks (raster.hull_chain_span): down * PACK + up
        span = veci()  # the row's piece spans sorted: u0 * PACK + u1
        for y in range(ya, yb + 1):
            yf = float(y)
            n = int(0)
            for q in range(pieces):
                rq = rows[q]
                if y >= rq / PACK and y <= (rq & LOW):
                    w = walk[q]
                    u0, u1, dq, uq = hull_chain_span(hull_pts, i, q, hull_n[i, q], yf, width, w / PACK, w & LOW)
                    walk[q] = dq * PACK + uq
                    if u0 <= u1:
                        key = u0 * PACK + u1
                        j = n
                        while j > 0 and span[j - 1] > key:
                            span[j] = span[j - 1]
                            j -= 1
                        span[j] = key
                        n += 1
            if n > 0:  # merge into disjoint intervals [a, e] separated by an uncovered pixel, as xor_score_kernel
                a = span[0] / PACK
                e = span[0] & LOW
                for k in range(1, n + 1):
                    if k < n and span[k] / PACK <= e + 1:
                        e = wp.max(e, span[k] & LOW)
                    else:
                        covered += e - a + 1
                        both += qrow[y, e + 1] - qrow[y, a]
                        wp.atomic_add(cov_diff, y, a, 1)
                        wp.atomic_add(cov_diff, y, e + 1, -1)
                        if k < n:
                            a = span[k] / PACK
                            e = span[k] & LOW
        return covered, both

    @wp.kernel(enable_backward=False, module="unique")
    def xor_band_kernel(
        hull_pts: wp.array3d(dtype=wp.vec2),
        hull_n: wp.array2d(dtype=wp.int32),
        hull_rows: wp.array2d(dtype=wp.vec2i),
        qrow: wp.array2d(dtype=wp.int32),
        band: int,
        group_box: wp.array(dtype=wp.vec4i),
        n_groups: wp.array(dtype=wp.int32),
        slot_group: wp.array(dtype=wp.int32),
        slot_hi: wp.array(dtype=wp.int32),
        sums: wp.array(dtype=wp.vec2i),
        cov_diff: wp.array2d(dtype=wp.int32),
        group_sums: wp.array2d(dtype=wp.vec2i),
    ):
        g, b, i = wp.tid()
        ya = b * band
        yb = wp.min(ya + band, qrow.shape[0]) - 1
        only = int(-1)  # every piece of the particle, or (grouped) those of group g's slots
        if wp.static(grouped):
            if g >= n_groups[0]:
                return
            box = group_box[g]
            ya = wp.max(ya, box[1])
            yb = wp.min(yb, box[3])
            if ya > yb:
                return
            only = g
        pieces = wp.min(hull_n.shape[1], slot_hi[0] * PIECES)  # the pieces of the slots some particle holds
        covered, both = band_sums(hull_pts, hull_n, hull_rows, qrow, i, ya, yb, slot_group, only, pieces, cov_diff)
        if covered > 0:
            wp.atomic_add(sums, i, wp.vec2i(covered, both))
            if wp.static(grouped):
                wp.atomic_add(group_sums, i, g, wp.vec2i(covered, both))

    return xor_band_kernel


@wp.func
def finish_particle(
    i: int,
    kind: wp.array2d(dtype=wp.int32),
    age: wp.array2d(dtype=wp.float32),
    pos: wp.array2d(dtype=wp.vec2),
    heading: wp.array2d(dtype=wp.float32),
    dims: wp.array2d(dtype=wp.vec3),
    qtotal: wp.array(dtype=wp.int32),
    cost_a: wp.vec4,
    cost_b: wp.vec4,
    scale: float,
    bg_weight: float,
    exclusion: float,
    sums: wp.array(dtype=wp.vec2i),
    logw: wp.array(dtype=wp.float32),
    penalty: wp.array(dtype=wp.int32),
    complexity: wp.array(dtype=wp.float32),
):
    """Particle ``i``'s penalty, complexity and log-weight (:func:`particle_score`) from the band kernel's ``sums[i]``,
    which it clears; ``logw[i]`` is updated in place."""
    t = sums[i]
    sums[i] = wp.vec2i(0, 0)
    m, cost, lw = particle_score(
        i, t[0], t[1], kind, age, pos, heading, dims, qtotal[0], cost_a, cost_b, scale, bg_weight, exclusion, logw[i]
    )
    penalty[i] = m
    complexity[i] = cost
    logw[i] = lw


@wp.kernel
def xor_finish_kernel(
    kind: wp.array2d(dtype=wp.int32),
    age: wp.array2d(dtype=wp.float32),
    pos: wp.array2d(dtype=wp.vec2),
    heading: wp.array2d(dtype=wp.float32),
    dims: wp.array2d(dtype=wp.vec3),
    qtotal: wp.array(dtype=wp.int32),
    cost_a: wp.vec4,
    cost_b: wp.vec4,
    scale: float,
    bg_weight: float,
    exclusion: float,
    sums: wp.array(dtype=wp.vec2i),
    logw: wp.array(dtype=wp.float32),
    penalty: wp.array(dtype=wp.int32),
    complexity: wp.array(dtype=wp.float32),
):
    """Matching penalty (eq. 4), complexity penalty (eq. 5) and log-weight (eq. 6) of every particle from the sums
    of ``xor_band_kernel``, which it clears. Launch with ``dim=N``; arguments and outputs as in
    ``xor_score_kernel`` (``logw`` updated in place)."""
    i = wp.tid()
    finish_particle(
        i, kind, age, pos, heading, dims, qtotal, cost_a, cost_b, scale, bg_weight, exclusion, sums, logw, penalty,
        complexity,
    )  # fmt: skip


@wp.kernel
def group_logw_kernel(
    kind: wp.array2d(dtype=wp.int32),
    age: wp.array2d(dtype=wp.float32),
    pos: wp.array2d(dtype=wp.vec2),
    heading: wp.array2d(dtype=wp.float32),
    dims: wp.array2d(dtype=wp.vec3),
    qtotal: wp.array(dtype=wp.int32),
    cost_a: wp.vec4,
    cost_b: wp.vec4,
    scale: float,
    bg_weight: float,
    exclusion: float,
    slot_group: wp.array(dtype=wp.int32),
    n_groups: wp.array(dtype=wp.int32),
    n: int,
    chunk: int,
    finish: int,
    sums: wp.array(dtype=wp.vec2i),
    group_sums: wp.array2d(dtype=wp.vec2i),
    glogw: wp.array2d(dtype=wp.float32),
    part_gmax: wp.array2d(dtype=wp.float32),
    logw: wp.array(dtype=wp.float32),
    penalty: wp.array(dtype=wp.int32),
    complexity: wp.array(dtype=wp.float32),
):
    """The factor of eq. 6 of every independent group of every particle (``kernels.templates.partition``; beyond the
    paper), from the group sums of ``xor_score_kernel`` / ``xor_band_kernel``, which it clears, and the per-block
    maxima.

    Group ``g``'s log-factor is ``-(m'_{i,g} + c_{i,g}) s / (W H)`` without the particle-independent count of
    foreground pixels in its box: ``m'_{i,g} - |q in box_g| = -|q AND v_i| + lambda (|v_i| - |q AND v_i|)`` over the
    box, and ``c_{i,g}`` holds eq. 5 for the group's objects and the exclusion prior of its pairs (pairs of different
    groups have disjoint image boxes, hence no ground overlap). Summed over the groups it is the particle's
    log-weight of eq. 6 up to a constant; each group is resampled on its own factor. Launch
    ``wp.launch_tiled(dim=[blocks], block_dim=B)``; block ``b`` owns particles ``[b chunk, (b+1) chunk)``.

    With ``finish`` 1 it also does the work of :func:`xor_finish_kernel` after ``xor_band_kernel`` (one launch less
    per frame): the joint penalty, complexity and log-weight from ``sums``, which it clears, bit for bit as there.

    Args:
        kind, age, pos, heading, dims, qtotal, cost_a, cost_b, scale, bg_weight, exclusion: as ``xor_score_kernel``.
        slot_group: (R,) group of each slot; n_groups: (1,) number of groups (``kernels.templates.partition``).
        n, chunk: particles and particles per block.
        finish: 1 to finish the joint scores from ``sums`` (the band kernel's), 0 when they are final already.
        sums: (N,) joint (|v_i|, |q AND v_i|) of ``xor_band_kernel`` (read and zeroed with ``finish`` 1).
        group_sums: (N, R) per group (|v_i|, |q AND v_i|) in its box, pixels; zeroed here.
        glogw: (R, N) output log-factor of group g (rows ``g >= n_groups`` untouched).
        part_gmax: (blocks, R) output per-block maximum of each group's log-factor (``NEG_INF`` for unused groups).
        logw, penalty, complexity: (N,) the joint scores as ``xor_finish_kernel`` writes them (``finish`` 1 only;
            ``logw`` updated in place).
    """
    b, lane = wp.tid()
    slots = kind.shape[1]
    groups = n_groups[0]
    start = b * chunk
    stop = wp.min(start + chunk, n)
    gmax = vec_slots()
    for g in range(slots):
        gmax[g] = NEG_INF
    for i in range(start + lane, stop, wp.block_dim()):
        if finish != 0:
            finish_particle(
                i, kind, age, pos, heading, dims, qtotal, cost_a, cost_b, scale, bg_weight, exclusion, sums, logw,
                penalty, complexity,
            )  # fmt: skip
        cost = vec_slots()
        for s in range(slots):
            kk = kind[i, s]
            g = slot_group[s]
            if kk > 0 and g >= 0:
                cost[g] += cost_a[kk] + cost_b[kk] * wp.exp(-age[i, s])  # eq. 5
                if exclusion > 0.0:
                    for t in range(s + 1, slots):
                        kt = kind[i, t]
                        if kt > 0 and slot_group[t] == g:
                            o = pair_overlap(
                                kk, pos[i, s], heading[i, s], dims[i, s], kt, pos[i, t], heading[i, t], dims[i, t]
                            )
                            cost[g] += exclusion * o
        for g in range(groups):
            gs = group_sums[i, g]
            group_sums[i, g] = wp.vec2i(0, 0)
            mw = -float(gs[1]) + bg_weight * float(gs[0] - gs[1])
            lw = finite_logw(-(mw + cost[g]) * scale)  # eq. 6 in log space, the group's factor
            glogw[g, i] = lw
            gmax[g] = wp.max(gmax[g], lw)
    for g in range(slots):  # every lane reaches every block reduction
        m, _arg = block_argmax(gmax[g], 0)
        if lane == 0:
            part_gmax[b, g] = m
