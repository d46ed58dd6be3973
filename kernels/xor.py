"""XOR matching penalty, complexity penalty and log-weights of the S3 template tracker (Juza et al., eqs. 4-6).

The matching penalty of particle i against the motion image q (H x W, values 0/1) is the number of pixels where q
and the virtual scene v_i differ (eq. 4). It is computed without an image per particle:
``m_i = |q| + |v_i| - 2 |q AND v_i|``, where ``|v_i|`` and ``|q AND v_i|`` are summed over the covered spans of
each row only (``|q AND span|`` from the row prefix sums of q in O(1)). The same pass records the particle's
spans in a per-row difference array of coverage counts (two atomic adds per span, spread over the image), from
which ``kernels.uoh`` builds the Uncovered Object Histogram.
"""

import warp as wp

from .raster import KIND_HUMAN, PIECES, hull_chain_span, vec32i
from .reduce import finite_logw

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
def disc_in_box(c: wp.vec2, r: float, centre: wp.vec2, heading: float, half: wp.vec2):
    """Penetration of a ground disc (centre ``c``, radius ``r``, metres) into an oriented box (``centre``,
    ``heading`` radians, half length and half width ``half``, metres), as a fraction of the disc's diameter in
    [0, 1]: 0 when they do not overlap, 1 when the disc is pushed a whole diameter in."""
    d = c - centre
    ca = wp.cos(heading)
    sa = wp.sin(heading)
    lx = wp.abs(ca * d[0] + sa * d[1])
    ly = wp.abs(-sa * d[0] + ca * d[1])
    depth = wp.min(half[0] + r - lx, half[1] + r - ly)
    return wp.clamp(depth / (2.0 * r), 0.0, 1.0)


@wp.func
def footprint(k: int, dims: wp.vec3):
    """Radius of an object's ground disc (human: body radius; vehicle: half width, metres)."""
    if k == KIND_HUMAN:
        return dims[1]
    return 0.5 * dims[1]


@wp.func
def pair_overlap(ka: int, pa: wp.vec2, ha: float, da: wp.vec3, kb: int, pb: wp.vec2, hb: float, db: wp.vec3):
    """Ground-footprint overlap of two objects in [0, 1] (the exclusion prior of ``xor_score_kernel``).

    Humans are discs of their body radius, vehicles boxes of their length and width. Two humans: ``1 - d / (r_a +
    r_b)`` (d the distance of their centres). Human and vehicle: the disc's penetration into the box
    (``disc_in_box``). Two vehicles: the deepest penetration of three discs of half the width along b (its centre
    and both ends) into a's box.
    """
    if ka == KIND_HUMAN and kb == KIND_HUMAN:
        return wp.clamp(1.0 - wp.length(pa - pb) / (da[1] + db[1]), 0.0, 1.0)
    if ka == KIND_HUMAN:
        return disc_in_box(pa, da[1], pb, hb, wp.vec2(0.5 * db[0], 0.5 * db[1]))
    if kb == KIND_HUMAN:
        return disc_in_box(pb, db[1], pa, ha, wp.vec2(0.5 * da[0], 0.5 * da[1]))
    r = 0.5 * db[1]
    along = wp.max(0.5 * db[0] - r, 0.0) * wp.vec2(wp.cos(hb), wp.sin(hb))
    half = wp.vec2(0.5 * da[0], 0.5 * da[1])
    o = disc_in_box(pb, r, pa, ha, half)
    o = wp.max(o, disc_in_box(pb + along, r, pa, ha, half))
    return wp.max(o, disc_in_box(pb - along, r, pa, ha, half))


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
    cost_a: wp.vec3,
    cost_b: wp.vec3,
    scale: float,
    bg_weight: float,
    exclusion: float,
    logw: wp.array(dtype=wp.float32),
    penalty: wp.array(dtype=wp.int32),
    complexity: wp.array(dtype=wp.float32),
    cov_diff: wp.array2d(dtype=wp.int32),
):
    """Matching penalty (eq. 4), complexity penalty (eq. 5) and log-weight (eq. 6) of every particle.

    Launch with ``wp.launch_tiled(dim=[N], block_dim=B)``: block ``i`` is particle ``i`` and each of its threads
    takes a contiguous run of the rows its templates cover (``row_segment``; one thread per block on the CPU
    backend). Along its rows a thread walks each piece's hull chains (``raster.hull_chain_span``), keeps the pieces'
    spans sorted and merges them into the row's disjoint intervals (as ``raster.row_intervals``).

    Args:
        hull_pts, hull_n, hull_rows: the particles' piece hulls from ``raster.template_hulls_kernel``.
        kind: (N, R) KIND_* per slot. age: (N, R) seconds each object has been in the particle (tau of eq. 5).
        pos, heading, dims: (N, R) ground position (metres), heading (radians), dims (metres) per slot.
        qrow: (H, W+1) row prefix sums of the motion mask; qtotal: (1,) |q|.
        cost_a, cost_b: a_r and b_r of eq. 5 indexed by kind (pixels).
        scale: s / (W H) of eq. 6 (1 / pixels).
        bg_weight: weight lambda of a template pixel on mask background in the weighted penalty
            ``m'_i = |q AND NOT v_i| + lambda |v_i AND NOT q|`` that enters the log-weight (1: eq. 4 exactly; < 1
            when the masks miss parts of objects more often than they show motion where there is none).
        exclusion: cost of two objects sharing the same ground, pixels: ``c_i`` gains ``exclusion x
            pair_overlap`` for every pair of objects (0: eq. 5 exactly). Solid objects cannot overlap on the
            ground; eq. 5's complexity penalty was introduced against objects placed at very similar positions, and
            this prior says so directly (it keeps two hypotheses off one person and humans off a car).
        logw: (N,) log-weight, updated in place: ``logw_i += -(m'_i + c_i) s / (W H)`` (it holds the prior
            log-weight after prediction: 0 after resampling).
        penalty: (N,) m_i, pixels (exact). complexity: (N,) c_i, pixels.
        cov_diff: (H, W+1) per-row difference array of coverage counts; each covered span [u0, u1] adds 1 at
            u0 and -1 at u1 + 1 (zeroed again by ``uoh.coverage_uoh_kernel``).
    """
    i, lane = wp.tid()
    slots = kind.shape[1]
    pieces = slots * PIECES
    width = qrow.shape[1] - 1
    y0 = qrow.shape[0]  # empty row range unless a piece is visible
    y1 = int(-1)
    r0 = vec32i()  # each piece's rows (an empty range for pieces not drawn), read once
    r1 = vec32i()
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
    down = vec32i()  # the pieces' hull chain walks (raster.hull_chain_span) over this lane's rows
    up = vec32i()
    s0 = vec32i()  # the row's piece spans sorted by start (raster.row_intervals, written out: no vector copies)
    s1 = vec32i()
    ya, yb = row_segment(wp.max(y1 - y0 + 1, 0), lane)  # this lane's run of rows: the walks move forward row by row
    for y in range(y0 + ya, y0 + yb):
        yf = float(y)
        n = int(0)
        for q in range(pieces):
            if y >= r0[q] and y <= r1[q]:
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
                    covered += b - a + 1
                    both += qrow[y, b + 1] - qrow[y, a]
                    wp.atomic_add(cov_diff, y, a, 1)
                    wp.atomic_add(cov_diff, y, b + 1, -1)
                    if k < n:
                        a = s0[k]
                        b = s1[k]
    tc = wp.tile_sum(wp.tile(covered))
    tb = wp.tile_sum(wp.tile(both))
    if lane == 0:
        m = qtotal[0] + tc[0] - 2 * tb[0]  # eq. 4 as |q| + |v| - 2 |q AND v|
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
        mw = float(qtotal[0] - tb[0]) + bg_weight * float(tc[0] - tb[0])
        penalty[i] = m
        complexity[i] = cost
        logw[i] = finite_logw(logw[i] - (mw + cost) * scale)  # eq. 6 in log space; -inf/NaN -> the floor
