"""Uncovered Object Histogram and object addition of the S3 template tracker (Juza et al., section 4, eqs. 10-12).

``UOH(w, h) = sum_i NOT v_i(w, h)`` where q(w, h) = 1, else 0 (eq. 10), is ``q * (N - coverage count)``: the
coverage counts come from the per-row difference array that ``xor.xor_score_kernel`` fills (no per-pixel
atomics). Object addition (eq. 11) picks, from a fixed candidate set (ground-grid position x type x orientation
at the prior's mean size), the object that lowers the UOH the most when added to every particle. Adding o to
all particles sets the UOH to 0 on o's pixels, so the UOH sum drops by ``sum_{p in o} UOH(p)``; we score

    gain(o) = (1 / N) sum_{p in o} (N - cov(p)) (q(p) - beta (1 - q(p)))

i.e. the UOH mass o covers minus beta times the background it would cover in particles that do not cover it
yet. ``beta = 0`` is eq. 11 exactly; ``beta = 1`` makes gain(o) the mean decrease of the XOR penalty (eq. 4)
over the particles, which stops a large template from winning by covering several people and the gaps between
them. The best candidate is proposed when gain(o) >= min_gain x area(o).
"""

from typing import Any

import warp as wp

from wptrack.kernels.templates.raster import hull_span
from wptrack.kernels.templates.xor import row_segment

wp.set_module_options({"enable_backward": False})

NEG_INF = wp.constant(-3.0e38)


@wp.func
def block_exclusive_scan_i64(v: wp.int64):
    """Exclusive prefix sum over the block's lanes of a non-negative int64 per lane, exactly.

    Warp's tile scans take 32-bit values only: the low 16 and the high bits are scanned as two int32 tiles and
    recombined. Exact while the block's total is below 2^47 and the block has at most 32768 lanes (the gain sums
    of ``coverage_uoh_kernel`` stay below W x 2^31 < 2^41). Every lane of the block must call it.
    """
    lo = wp.int32(v & wp.int64(65535))
    hi = wp.int32(v >> wp.int64(16))
    slo = wp.untile(wp.tile_scan_exclusive(wp.tile(lo)))
    shi = wp.untile(wp.tile_scan_exclusive(wp.tile(hi)))
    return (wp.int64(shi) << wp.int64(16)) + wp.int64(slo)


@wp.kernel
def coverage_uoh_kernel(
    q: wp.array2d(dtype=wp.uint8),
    n: int,
    beta: float,
    cov_diff: wp.array2d(dtype=wp.int32),
    uoh: wp.array2d(dtype=wp.int32),
    gain_rows: wp.array2d(dtype=wp.float64),
    a_sat: wp.array2d(dtype=wp.int64),
):
    """Coverage counts, UOH (eq. 10) and row prefix sums of the addition gain; clears ``cov_diff``.

    Launch with ``wp.launch_tiled(dim=[H], block_dim=B)``: block ``y`` is row ``y``, each lane owns one segment
    of it (``xor.row_segment``; the whole row on the CPU backend). ``q`` (H, W) motion mask; ``n`` particles;
    ``cov_diff`` (H, W+1) difference array (read, then zeroed for the next frame); ``uoh`` (H, W) output, pixels
    x particles; ``gain_rows`` (H, W+1) with ``gain_rows[y, x] = A - beta B``, where ``A = sum_{x' < x} (N - cov) q``
    and ``B = sum_{x' < x} (N - cov) (1 - q)`` are exact int64 sums (one rounding for ``beta B`` and one for the
    difference: exact when beta has few binary digits, e.g. 0, 0.5, 1). ``a_sat`` (H+1, W+1) int64 gets the row
    prefix sums of the UOH, ``a_sat[y + 1, x] = A`` (row 0: zeros), which ``uoh_box_sums_kernel`` turns into a
    summed-area table.

    With several lanes, a first pass gives each lane the coverage count entering its segment (block scan of the
    segments' difference sums) and its segment's A and B, a second block scan their prefixes; the last pass
    writes the outputs.
    """
    y, lane = wp.tid()
    x0, x1 = row_segment(q.shape[1], lane)
    cov0 = int(0)
    a = wp.int64(0)
    b = wp.int64(0)
    if wp.block_dim() > 1:  # uniform over the block: every lane reaches the scans or none does
        d = int(0)
        for x in range(x0, x1):
            d += cov_diff[y, x]
        cov0 = wp.untile(wp.tile_scan_exclusive(wp.tile(d)))
        cov = cov0
        for x in range(x0, x1):
            cov += cov_diff[y, x]
            f = wp.int64(n - cov)
            if q[y, x] != wp.uint8(0):
                a += f
            else:
                b += f
        a = block_exclusive_scan_i64(a)
        b = block_exclusive_scan_i64(b)
    nb = wp.float64(beta)
    if lane == 0:
        gain_rows[y, 0] = wp.float64(0.0)
        cov_diff[y, q.shape[1]] = 0
        a_sat[y + 1, 0] = wp.int64(0)
        if y == 0:
            a_sat[0, 0] = wp.int64(0)
    cov = cov0
    for x in range(x0, x1):
        cov += cov_diff[y, x]
        cov_diff[y, x] = 0
        free = n - cov
        if q[y, x] != wp.uint8(0):
            uoh[y, x] = free
            a += wp.int64(free)
        else:
            uoh[y, x] = 0
            b += wp.int64(free)
        gain_rows[y, x + 1] = wp.float64(a) - nb * wp.float64(b)
        a_sat[y + 1, x + 1] = a
        if y == 0:
            a_sat[0, x + 1] = wp.int64(0)


@wp.func
def block_exclusive_scan_i64_wide(v: wp.int64):
    """``block_exclusive_scan_i64`` for totals up to 2^62: three 16/16/32-bit parts scanned as int32 tiles (every
    part's block sum stays below 2^31 for blocks of at most 32768 lanes). Every lane of the block must call it."""
    m = wp.int64(65535)
    p0 = wp.int32(v & m)
    p1 = wp.int32((v >> wp.int64(16)) & m)
    p2 = wp.int32(v >> wp.int64(32))
    s0 = wp.untile(wp.tile_scan_exclusive(wp.tile(p0)))
    s1 = wp.untile(wp.tile_scan_exclusive(wp.tile(p1)))
    s2 = wp.untile(wp.tile_scan_exclusive(wp.tile(p2)))
    return (wp.int64(s2) << wp.int64(32)) + (wp.int64(s1) << wp.int64(16)) + wp.int64(s0)


@wp.kernel
def uoh_box_sums_kernel(cols: int, a_sat: wp.array2d(dtype=wp.int64)):
    """Summed-area table of the UOH in place: ``a_sat[y, x] = sum_{y' < y, x' < x} UOH(x', y')`` from the row
    prefix sums that ``coverage_uoh_kernel`` wrote (pixels x particles, exact int64).

    Launch with ``wp.launch_tiled(dim=[ceil((W + 1) / cols)], block_dim=B)``: block ``b`` owns the columns ``[b
    cols, (b + 1) cols)``. With one lane (the CPU backend) it adds each row to the next, row after row (``cols = W
    + 1``: one pass over the table in memory order). With several lanes, for each of its columns the lanes own
    contiguous runs of the rows 1..H (``xor.row_segment``) and a block-wide exclusive scan of the runs' sums gives
    every lane the column sum above its run (``cols = 1`` on GPUs: one block per column). Used by
    ``candidate_score_kernel`` to bound a candidate's gain by the UOH mass of its bounding box.
    """
    blk, lane = wp.tid()
    c0 = blk * cols
    c1 = wp.min(c0 + cols, a_sat.shape[1])
    if wp.block_dim() == 1:
        for y in range(1, a_sat.shape[0]):
            for x in range(c0, c1):
                a_sat[y, x] = a_sat[y, x] + a_sat[y - 1, x]
    else:  # uniform over the block: every lane reaches the scans
        r0, r1 = row_segment(a_sat.shape[0] - 1, lane)
        for x in range(c0, c1):
            acc = wp.int64(0)
            for y in range(r0, r1):
                acc += a_sat[y + 1, x]
            acc = block_exclusive_scan_i64_wide(acc)
            for y in range(r0, r1):
                acc += a_sat[y + 1, x]
                a_sat[y + 1, x] = acc


@wp.kernel
def candidate_spans_kernel(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    offsets: wp.array(dtype=wp.int32),
    pieces: int,
    width: int,
    spans: wp.array(dtype=wp.vec2i),
    box: wp.array(dtype=wp.vec4i),
    area: wp.array(dtype=wp.int32),
):
    """Spans, bounding box and area of every candidate's pieces, once when the model is built.

    Launch with ``dim=C`` (candidates as one-slot particles). Candidate c's pieces are written one after another
    from ``offsets[c]``: for each visible piece, one ``(u0, u1)`` per row of ``hull_rows`` (``u1 < u0``: empty).
    ``box[c] = (u_min, v_min, u_max, v_max)`` (pixels, inclusive) bounds the covered pixels (``u_max < u_min``:
    none); ``area[c]`` counts them, pixels covered by both pieces once (as ``candidate_score_kernel`` sums them:
    piece 0, then each later piece without its overlap with piece 0 on the same row).
    """
    c = wp.tid()
    o = offsets[c]
    bx = wp.vec4i(width, 2147483647, -1, -1)
    px = int(0)
    r0 = wp.vec2i(0, -1)
    o0 = o
    if hull_n[c, 0] > 0:
        r0 = hull_rows[c, 0]
    for q in range(pieces):
        m = hull_n[c, q]
        if m > 0:
            r = hull_rows[c, q]
            for y in range(r[0], r[1] + 1):
                u0, u1 = hull_span(hull_pts, c, q, m, float(y), width)
                spans[o] = wp.vec2i(u0, u1)
                o += 1
                if u0 <= u1:
                    bx = wp.vec4i(wp.min(bx[0], u0), wp.min(bx[1], y), wp.max(bx[2], u1), wp.max(bx[3], y))
                    px += u1 - u0 + 1
                    if q > 0 and y >= r0[0] and y <= r0[1]:
                        t = spans[o0 + y - r0[0]]
                        lo = wp.max(u0, t[0])
                        hi = wp.min(u1, t[1])
                        if lo <= hi:
                            px -= hi - lo + 1
    box[c] = bx
    area[c] = px


@wp.func
def candidate_sum(
    hull_rows: wp.array2d(dtype=wp.vec2i),
    hull_n: wp.array2d(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    spans: wp.array(dtype=wp.vec2i),
    pieces: int,
    c: int,
    lane: int,
    prefix: wp.array2d(dtype=Any),
    zero: Any,
):
    """This lane's part of the sum of an image over candidate ``c``'s silhouette, from the image's row prefix sums
    ``prefix`` (H, W+1): piece 0's spans, then each later piece's spans minus their overlap with piece 0 on the same
    row (pixels covered by both count once). The lanes of a block stride over the rows; ``zero`` gives the sum's type.
    """
    o = offsets[c]
    acc = zero
    r0 = wp.vec2i(0, -1)
    o0 = o
    if hull_n[c, 0] > 0:
        r0 = hull_rows[c, 0]
    for q in range(pieces):
        if hull_n[c, q] > 0:
            r = hull_rows[c, q]
            for y in range(r[0] + lane, r[1] + 1, wp.block_dim()):
                s = spans[o + y - r[0]]
                u0 = s[0]
                u1 = s[1]
                if u0 <= u1:
                    acc += prefix[y, u1 + 1] - prefix[y, u0]
                    if q > 0 and y >= r0[0] and y <= r0[1]:
                        t = spans[o0 + y - r0[0]]
                        a = wp.max(u0, t[0])
                        b = wp.min(u1, t[1])
                        if a <= b:
                            acc -= prefix[y, b + 1] - prefix[y, a]
            o += r[1] - r[0] + 1
    return acc


@wp.kernel
def candidate_score_kernel(
    hull_rows: wp.array2d(dtype=wp.vec2i),
    hull_n: wp.array2d(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    spans: wp.array(dtype=wp.vec2i),
    box: wp.array(dtype=wp.vec4i),
    cand_area: wp.array(dtype=wp.int32),
    pieces: int,
    gain_rows: wp.array2d(dtype=wp.float64),
    a_sat: wp.array2d(dtype=wp.int64),
    n: int,
    beta: float,
    min_gain: float,
    min_area: int,
    cost: wp.array(dtype=wp.float32),
    score: wp.array(dtype=wp.float32),
    area: wp.array(dtype=wp.int32),
):
    """Addition gain of every candidate (eq. 11, see the module docstring), less its cost.

    Launch with ``wp.launch_tiled(dim=[C], block_dim=B)``: block ``c`` is candidate ``c`` and its lanes stride
    over the rows of its pieces (one lane on the CPU backend); ``tile_sum`` combines the lanes' sums.

    Pixels covered by both pieces of a candidate count once (the head overlaps the body, the cabin the lower
    body): a row's second span contributes only its part outside the first. ``score[c]`` is the gain in pixels
    (a mean over particles) or -3e38 when the candidate is not eligible (gain < min_gain x area or area <
    min_area pixels); ``area[c]`` its pixel count (``cand_area``, from ``candidate_spans_kernel`` with ``box``).
    The row sums are exact whenever ``gain_rows`` holds exactly representable values (integers or halves: beta =
    0, 0.5, 1), so the lane order does not change the score.

    Most candidates are settled without their rows: the gain times N is at most A, the UOH mass they cover
    (``beta >= 0`` and coverage <= N make the background term non-positive), and A is at most the UOH mass of
    their bounding box, four reads of the summed-area table ``a_sat`` (``uoh_box_sums_kernel``). A candidate whose
    bound lies more than 1e-3 pixels below min_gain x area (or below its cost) is not eligible whatever its rows
    hold (the float64 row sums err by far less), and gets -3e38 as before.
    """
    c, lane = wp.tid()
    pa = cand_area[c]
    need = wp.float64(min_gain) * wp.float64(pa)
    if cost[c] > 0.0:
        need = wp.max(need, wp.float64(cost[c]))
    settled = pa < min_area
    if not settled and beta >= 0.0:
        bx = box[c]
        bound = wp.float64(0.0)
        if bx[0] <= bx[2]:
            mass = a_sat[bx[3] + 1, bx[2] + 1] - a_sat[bx[1], bx[2] + 1] - a_sat[bx[3] + 1, bx[0]] + a_sat[bx[1], bx[0]]
            bound = wp.float64(mass) / wp.float64(n)
        settled = bound < need - wp.float64(1.0e-3)
    if settled:  # uniform over the block: every lane returns here or none does
        if lane == 0:
            area[c] = pa
            score[c] = NEG_INF
        return
    g = candidate_sum(hull_rows, hull_n, offsets, spans, pieces, c, lane, gain_rows, wp.float64(0.0))
    gt = wp.tile_sum(wp.tile(g))
    if lane == 0:
        gain = gt[0] / wp.float64(n)
        area[c] = pa
        if gain >= need:
            score[c] = wp.float32(gain - wp.float64(cost[c]))
        else:
            score[c] = NEG_INF


@wp.kernel
def slot_budget_kernel(
    slot_count: wp.array(dtype=wp.float64),
    slot_est: wp.array2d(dtype=wp.float64),
    exist_col: int,
    min_existence: float,
    margin: int,
    margin_frac: float,
    slot_open: wp.array(dtype=wp.float64),
):
    """Beyond the paper (``TemplateConfig.slot_margin``): the slots that additions may open this frame. With ``n`` the
    objects reported (existence ``slot_est[s, exist_col]`` >= ``min_existence``) and ``u`` the slots held by some
    particle (``slot_count`` > 0), at most ``n + max(margin, ceil(margin_frac n)) - u`` free slots may be opened:
    ``slot_open`` is ``slot_count`` with the other free slots (the highest) set to 1 (held), so the choice kernels
    (:func:`choose_addition_kernel`, :func:`choose_more_additions_kernel`) pass over them. ``margin`` <= 0: every
    free slot stays open (``slot_open`` = ``slot_count``). Launch ``dim=1``."""
    r = slot_count.shape[0]
    reported = int(0)
    used = int(0)
    for s in range(r):
        if slot_count[s] > wp.float64(0.0):
            used += 1
            if slot_est[s, exist_col] >= wp.float64(min_existence):
                reported += 1
    budget = r
    if margin > 0:
        extra = wp.max(margin, int(wp.ceil(margin_frac * float(reported))))
        budget = reported + extra - used
    for s in range(r):
        slot_open[s] = slot_count[s]
        if slot_count[s] == wp.float64(0.0):
            if budget > 0:
                budget -= 1
            else:
                slot_open[s] = wp.float64(1.0)


@wp.func
def chosen_candidate(
    best: wp.array(dtype=wp.int32),
    best_score: wp.array(dtype=wp.float64),
    best_slot: int,
    n_cand: int,
    fit_best: wp.array(dtype=wp.int32),
    fit_est: wp.array(dtype=wp.float64),
    min_fit: float,
):
    """The candidate an argmax chose (``best[0]``, score ``best_score[best_slot]``), after the class-aware
    replacement by the best-fitting vehicle ``fit_best[0]`` when its fit ``fit_est[best_slot]`` is at least
    ``min_fit`` (``inf``: none); -1 when nothing is eligible (every score -3e38) or the index is invalid."""
    c = best[0]
    f = fit_est[best_slot]
    if f > wp.float64(-1.0e37) and f >= wp.float64(min_fit) and fit_best[0] >= 0:
        c = fit_best[0]
    if best_score[best_slot] < wp.float64(-1.0e37) or c < 0 or c >= n_cand:
        return int(-1)
    return c


@wp.kernel
def suppress_candidates_kernel(
    best: wp.array(dtype=wp.int32),
    best_score: wp.array(dtype=wp.float64),
    best_slot: int,
    fit_best: wp.array(dtype=wp.int32),
    fit_est: wp.array(dtype=wp.float64),
    min_fit: float,
    box: wp.array(dtype=wp.vec4i),
    score: wp.array(dtype=wp.float32),
):
    """Beyond the paper (several additions per frame, ``TemplateConfig.additions``): after an argmax chose a
    candidate (:func:`chosen_candidate`), every candidate whose image box ``box`` (``candidate_spans_kernel``)
    shares a pixel with the chosen one's gets ``score`` -3e38, the chosen one too. The next argmax then picks the best
    candidate on other pixels: its gain (eq. 11, computed without the chosen object) is what it gains with the
    chosen one added, as no pixel is shared. Nothing changes when nothing was chosen. Launch ``dim=C``."""
    j = wp.tid()
    c = chosen_candidate(best, best_score, best_slot, score.shape[0], fit_best, fit_est, min_fit)
    if c < 0:
        return
    a = box[c]
    b = box[j]
    if j == c or (a[0] <= b[2] and b[0] <= a[2] and a[1] <= b[3] and b[1] <= a[3]):
        score[j] = NEG_INF


@wp.kernel
def choose_more_additions_kernel(
    best: wp.array(dtype=wp.int32),
    best_score: wp.array2d(dtype=wp.float64),
    best_slot: int,
    cand_kind: wp.array(dtype=wp.int32),
    slot_count: wp.array(dtype=wp.float64),
    slots: int,
    next_label: wp.array(dtype=wp.int32),
    slot_label: wp.array(dtype=wp.int32),
    slot_kind: wp.array(dtype=wp.int32),
    add: wp.array(dtype=wp.int32),
):
    """Additions 1 .. K-1 of the frame (launch ``dim=1``, after :func:`choose_addition_kernel` wrote addition 0 into
    ``add[0:2]``; beyond the paper, ``TemplateConfig.additions``): round ``k``'s argmax ``best[k]`` with score
    ``best_score[k, best_slot]`` (candidates sharing pixels with an earlier round's were suppressed,
    :func:`suppress_candidates_kernel`) gets the lowest slot that is empty in every particle and not given this
    frame, a new label and its kind: ``add[2k: 2k + 2] = (slot, candidate)``, or ``(-1, -1)`` when nothing is
    eligible or no slot is free. ``best`` (K,), ``best_score`` (K, EST_SIZE), ``add`` (2K,)."""
    rounds = add.shape[0] / 2
    for k in range(1, rounds):
        add[2 * k] = -1
        add[2 * k + 1] = -1
        c = best[k]
        if best_score[k, best_slot] < wp.float64(-1.0e37) or c < 0 or c >= cand_kind.shape[0]:
            continue
        for s in range(slots):
            taken = slot_count[s] != wp.float64(0.0)
            for e in range(k):
                if add[2 * e] == s:
                    taken = True
            if not taken:
                label = next_label[0]
                next_label[0] = label + 1
                slot_label[s] = label
                slot_kind[s] = cand_kind[c]
                add[2 * k] = s
                add[2 * k + 1] = c
                break


@wp.kernel
def choose_addition_kernel(
    best: wp.array(dtype=wp.int32),
    best_score: wp.array(dtype=wp.float64),
    best_slot: int,
    cand_kind: wp.array(dtype=wp.int32),
    slot_count: wp.array(dtype=wp.float64),
    slots: int,
    fit_best: wp.array(dtype=wp.int32),
    fit_est: wp.array(dtype=wp.float64),
    min_fit: float,
    next_label: wp.array(dtype=wp.int32),
    slot_label: wp.array(dtype=wp.int32),
    slot_kind: wp.array(dtype=wp.int32),
    add: wp.array(dtype=wp.int32),
):
    """Decide this frame's addition (launch ``dim=1``).

    Every slot holds one label across all particles. When the best candidate is eligible and some slot is empty
    in every particle (``slot_count[s] == 0``), the lowest such slot gets a new persistent label
    (``next_label``, then incremented) and the candidate's kind; ``add = (slot, candidate)``; otherwise
    ``add[0] = -1``. ``best_score[best_slot]`` is the candidate argmax's score (``reduce.final_max_kernel``).

    Beyond the paper (class-aware addition, ``kernels.templates.classify``): first the chosen candidate ``best[0]`` (a
    human) is replaced by the best-fitting vehicle candidate ``fit_best[0]`` when its fit ``fit_est[best_slot]`` (the
    argmax over ``classify.vehicle_fit_kernel``'s output) is at least ``min_fit`` (``inf``: never; ``best`` is updated).
    """
    add[0] = -1
    add[1] = -1
    f = fit_est[best_slot]
    if f > wp.float64(-1.0e37) and f >= wp.float64(min_fit) and fit_best[0] >= 0:
        best[0] = fit_best[0]
    c = best[0]
    if best_score[best_slot] < wp.float64(-1.0e37) or c < 0 or c >= cand_kind.shape[0]:
        return
    for s in range(slots):
        if slot_count[s] == wp.float64(0.0):
            label = next_label[0]
            next_label[0] = label + 1
            slot_label[s] = label
            slot_kind[s] = cand_kind[c]
            add[0] = s
            add[1] = c
            return
