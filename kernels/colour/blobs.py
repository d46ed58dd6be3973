"""Geometric detection for the S1 colour filter (issue 29): colour blobs per camera, 3D candidates by triangulating
blob pairs across camera pairs, scored by the window likelihood of all cameras.

Per frame, with fixed-size buffers (no allocation, no host round trip, no atomics):

1. :func:`subblock_counts_kernel`: target pixels in every 5 x 5 **sub-block** of every camera (the paper's window:
   the count is the window count m at the sub-block's centre pixel, one read of the window map in ``SCORE_MAP`` mode,
   four of the integral image in ``SCORE_INTEGRAL`` mode, 25 classified pixels in ``SCORE_DIRECT`` mode). The grid
   covers ``floor(W / 5) x floor(H / 5)`` sub-blocks (a remainder strip of < 5 pixels at the right and bottom is left
   out).
2. :func:`neighbourhood_sums_kernel` and :func:`blob_peaks_kernel`: a sub-block's **blob score** is the count of its
   3 x 3 sub-block neighbourhood (15 x 15 pixels; neighbours beyond the grid count 0); it is a **peak** when that
   score is at least ``min_pixels`` and its key - the score, ties broken by the 5 x 5 neighbourhood's count, so that
   inside a blob wider than 15 pixels the most central position wins - is at least the key of each of its 8
   neighbours and greater than those of its neighbours earlier in raster order (one peak per plateau). Its blob centre
   is the count-weighted mean of the neighbourhood's sub-block centres (pixels). Each block of the tiled launch owns
   ``PEAK_CHUNK`` sub-blocks of one camera and keeps its ``PEAK_KEEP`` best peaks (rounds of a block argmax), so the
   per-camera selection reads a short list.
3. :func:`blob_select_kernel`: the ``B`` best peaks of each camera (score descending, index ascending: a rank per
   entry, no sort), ``B`` blob slots per camera (score 0: empty).
4. :func:`candidates_kernel`: one thread per (camera pair, blob of the first camera, blob of the second): the
   midpoint of the two back-projected rays (``proposal.ray_pair_midpoint``) is kept when it lies in front of both
   cameras, inside the working volume and reprojects within ``gate_px`` pixels of both blob centres (epipolar
   consistency); its score is the mode-test log-likelihood there (``proposal.mode_log_likelihood``: eqs. 5-7 over
   all cameras, a camera that does not see the point adding log(1/5); a point that more cameras agree on scores
   higher: each agreeing camera adds up to log 25).
5. :func:`candidate_keep_kernel` and :func:`candidate_rank_kernel`: non-maximum suppression (a candidate is dropped
   when a better one lies within ``radius``) and the ``K`` best survivors, score descending, into the detection
   slots (score ``LOG_ZERO``: empty).

The tracker launches 1, 2 and the peaks, then steps 3-5 and the mode test (``proposal.jump_decision_kernel``) as one
block (:func:`detect_tail_kernel`); the separate kernels are the same functions, for tests.
"""

import warp as wp

from wptrack.kernels.colour.hsi import HALF_WINDOW, ColourTarget, window_count_integral
from wptrack.kernels.colour.proposal import (
    LOG_ZERO,
    camera_centre,
    jump_decision,
    mode_log_likelihood,
    pixel_ray_direction,
    ray_pair_midpoint,
)
from wptrack.kernels.colour.scoring import (
    SCORE_INTEGRAL,
    SCORE_MAP,
    window_count_direct,
)
from wptrack.kernels.core.camera import Camera, project
from wptrack.kernels.core.reduce import NEG_INF, NO_INDEX, block_argmax

wp.set_module_options({"enable_backward": False})

SUBBLOCK = wp.constant(5)
"""Side of a sub-block, pixels (the paper's 5 x 5 window)."""
PEAK_CHUNK = wp.constant(256)
"""Sub-blocks per block of :func:`blob_peaks_kernel`."""
PEAK_KEEP = wp.constant(4)
"""Peaks each block of :func:`blob_peaks_kernel` keeps."""


@wp.func
def pixel_window_count(
    cam: Camera,
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    px: int,
    py: int,
):
    """m: target pixels in the 5 x 5 window centred on pixel (px, py) (inside the image), in any scoring mode."""
    if mode == SCORE_MAP:
        return int(window[cam.pixel_offset + py * cam.width + px])
    if mode == SCORE_INTEGRAL:
        return window_count_integral(cam, integral, px, py)
    return window_count_direct(cam, target, bgr, px, py)


@wp.kernel
def subblock_counts_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    sb_offset: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
):
    """Target pixels per sub-block. Launch (M, max floor(H/5), max floor(W/5)); ``counts`` is flat over cameras,
    camera ``c``'s ``floor(H/5) x floor(W/5)`` grid (row-major) from ``sb_offset[c]``."""
    c, j, i = wp.tid()
    cam = cams[c]
    nx = cam.width // SUBBLOCK
    ny = cam.height // SUBBLOCK
    if i >= nx or j >= ny:
        return
    m = pixel_window_count(
        cam, target, bgr, integral, window, mode, i * SUBBLOCK + HALF_WINDOW, j * SUBBLOCK + HALF_WINDOW
    )
    counts[sb_offset[c] + j * nx + i] = m


@wp.func
def neighbourhood_sum(counts: wp.array(dtype=wp.int32), base: int, nx: int, ny: int, i: int, j: int, r: int):
    """Sum of the counts of the (2r+1) x (2r+1) sub-blocks around (i, j) that exist."""
    s = int(0)
    for y in range(wp.max(j - r, 0), wp.min(j + r + 1, ny)):
        for x in range(wp.max(i - r, 0), wp.min(i + r + 1, nx)):
            s += counts[base + y * nx + x]
    return s


KEY_SCALE = wp.constant(1024)
"""Blob key = 3 x 3 count * KEY_SCALE + 5 x 5 count (the 5 x 5 count, at most 625, breaks ties of the 3 x 3 one)."""


@wp.kernel
def neighbourhood_sums_kernel(
    cams: wp.array(dtype=Camera),
    sb_offset: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    keys: wp.array(dtype=wp.int32),
):
    """Blob key of every sub-block: ``KEY_SCALE`` x the count of its 3 x 3 sub-block neighbourhood (15 x 15 pixels,
    the blob score) + the count of its 5 x 5 neighbourhood (25 x 25 pixels), over the neighbours that exist. The second
    count ranks the positions inside a blob wider than 15 pixels, whose 3 x 3 counts are all full, by how central they
    are. Launch as :func:`subblock_counts_kernel`; ``keys`` flat like ``counts``."""
    c, j, i = wp.tid()
    cam = cams[c]
    nx = cam.width // SUBBLOCK
    ny = cam.height // SUBBLOCK
    if i >= nx or j >= ny:
        return
    base = sb_offset[c]
    s3 = neighbourhood_sum(counts, base, nx, ny, i, j, 1)
    s5 = neighbourhood_sum(counts, base, nx, ny, i, j, 2)
    keys[base + j * nx + i] = s3 * KEY_SCALE + s5


@wp.func
def peak_key(keys: wp.array(dtype=wp.int32), base: int, nx: int, ny: int, i: int, j: int, min_pixels: int):
    """The blob key of sub-block (i, j) when it is a peak (see the module docstring), else 0."""
    s = keys[base + j * nx + i]
    if s < min_pixels * KEY_SCALE or s <= 0:
        return 0
    for y in range(wp.max(j - 1, 0), wp.min(j + 2, ny)):
        for x in range(wp.max(i - 1, 0), wp.min(i + 2, nx)):
            if x != i or y != j:
                t = keys[base + y * nx + x]
                earlier = y < j or (y == j and x < i)
                if t > s or (earlier and t == s):
                    return 0
    return s


@wp.func
def blob_centre(counts: wp.array(dtype=wp.int32), base: int, nx: int, ny: int, i: int, j: int):
    """Count-weighted mean of the centres (pixels) of the 3 x 3 sub-blocks around (i, j)."""
    su = float(0.0)
    sv = float(0.0)
    sw = float(0.0)
    for dj in range(-1, 2):
        y = j + dj
        if y >= 0 and y < ny:
            for di in range(-1, 2):
                x = i + di
                if x >= 0 and x < nx:
                    w = float(counts[base + y * nx + x])
                    su += w * float(x * SUBBLOCK + HALF_WINDOW)
                    sv += w * float(y * SUBBLOCK + HALF_WINDOW)
                    sw += w
    if sw <= 0.0:
        return wp.vec2(float(i * SUBBLOCK + HALF_WINDOW), float(j * SUBBLOCK + HALF_WINDOW))
    return wp.vec2(su / sw, sv / sw)


@wp.kernel
def blob_peaks_kernel(
    cams: wp.array(dtype=Camera),
    sb_offset: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    keys: wp.array(dtype=wp.int32),
    min_pixels: int,
    peaks: wp.array(dtype=wp.float32),
    part_score: wp.array3d(dtype=wp.float32),
    part_index: wp.array3d(dtype=wp.int32),
    part_uv: wp.array3d(dtype=wp.vec2),
):
    """Peaks per chunk. Launch ``wp.launch_tiled(dim=[M, chunks], block_dim=B)`` with ``chunks`` = ceil(largest
    grid / PEAK_CHUNK); block (c, k) owns sub-blocks ``[k PEAK_CHUNK, (k+1) PEAK_CHUNK)`` of camera ``c``.

    Writes ``peaks`` (flat like ``counts``: the peak's key, 0 if not a peak; scratch) and, per block, its
    ``PEAK_KEEP`` best peaks (key descending, index ascending) into ``part_*[c, k, r]`` (M, chunks, PEAK_KEEP): key
    (0: none; exact in float32), sub-block index within the camera, blob centre (pixels).
    """
    c, k, lane = wp.tid()
    cam = cams[c]
    nx = cam.width // SUBBLOCK
    ny = cam.height // SUBBLOCK
    total = nx * ny
    base = sb_offset[c]
    start = k * PEAK_CHUNK
    if start >= total:
        for r in range(lane, PEAK_KEEP, wp.block_dim()):
            part_score[c, k, r] = 0.0
            part_index[c, k, r] = NO_INDEX
        return  # the whole block leaves together
    stop = wp.min(start + PEAK_CHUNK, total)
    for s in range(start + lane, stop, wp.block_dim()):
        peaks[base + s] = float(peak_key(keys, base, nx, ny, s % nx, s // nx, min_pixels))
    prev_score = float(3.0e38)
    prev_index = int(-1)
    for r in range(PEAK_KEEP):
        best = float(NEG_INF)
        arg = int(NO_INDEX)
        for s in range(start + lane, stop, wp.block_dim()):
            v = peaks[base + s]
            after = v < prev_score or (v == prev_score and s > prev_index)
            if v > 0.0 and after and (v > best or (v == best and s < arg)):
                best = v
                arg = s
        mv, a = block_argmax(best, arg)
        if lane == 0:
            if a != NO_INDEX and mv > 0.0:
                part_score[c, k, r] = mv
                part_index[c, k, r] = a
                part_uv[c, k, r] = blob_centre(counts, base, nx, ny, a % nx, a // nx)
            else:
                part_score[c, k, r] = 0.0
                part_index[c, k, r] = NO_INDEX
        prev_score = mv
        prev_index = a


@wp.func
def select_blob(
    c: int,
    k: int,
    r: int,
    part_score: wp.array3d(dtype=wp.float32),
    part_index: wp.array3d(dtype=wp.int32),
    part_uv: wp.array3d(dtype=wp.vec2),
    blobs: int,
    blob_score: wp.array2d(dtype=wp.float32),
    blob_uv: wp.array2d(dtype=wp.vec2),
):
    """Peak entry (c, k, r) to the blob slot of its rank (see :func:`blob_select_kernel`); entry (c, 0, 0) also
    empties the camera's slots from its number of peaks on."""
    v = part_score[c, k, r]
    if k == 0 and r == 0:
        # count this camera's peaks: slots from that count on are empty
        n = int(0)
        for kk in range(part_score.shape[1]):
            for rr in range(part_score.shape[2]):
                if part_score[c, kk, rr] > 0.0:
                    n += 1
        for q in range(n, blobs):
            blob_score[c, q] = 0.0
            blob_uv[c, q] = wp.vec2(0.0, 0.0)
    if v > 0.0:
        idx = part_index[c, k, r]
        rank = int(0)
        for kk in range(part_score.shape[1]):
            for rr in range(part_score.shape[2]):
                w = part_score[c, kk, rr]
                if w > v or (w == v and w > 0.0 and part_index[c, kk, rr] < idx):
                    rank += 1
        if rank < blobs:
            blob_score[c, rank] = float(int(v) // KEY_SCALE)
            blob_uv[c, rank] = part_uv[c, k, r]


@wp.func
def candidate(
    t: int,
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    blob_score: wp.array2d(dtype=wp.float32),
    blob_uv: wp.array2d(dtype=wp.vec2),
    pair_a: wp.array(dtype=wp.int32),
    pair_b: wp.array(dtype=wp.int32),
    gate_px: float,
    lo: wp.vec3,
    hi: wp.vec3,
    cand_pos: wp.array(dtype=wp.vec3),
    cand_score: wp.array(dtype=wp.float32),
):
    """Candidate t (see :func:`candidates_kernel`)."""
    nb = blob_score.shape[1]
    p = t // (nb * nb)
    i = (t // nb) % nb
    j = t % nb
    cand_score[t] = LOG_ZERO
    cand_pos[t] = wp.vec3(0.0, 0.0, 0.0)
    a = pair_a[p]
    b = pair_b[p]
    if blob_score[a, i] <= 0.0 or blob_score[b, j] <= 0.0:
        return
    ca = cams[a]
    cb = cams[b]
    ua = blob_uv[a, i]
    ub = blob_uv[b, j]
    mid = ray_pair_midpoint(
        camera_centre(ca),
        pixel_ray_direction(ca, ua[0], ua[1]),
        camera_centre(cb),
        pixel_ray_direction(cb, ub[0], ub[1]),
    )
    if mid[3] < 0.0:
        return
    x = wp.vec3(mid[0], mid[1], mid[2])
    if x[0] < lo[0] or x[1] < lo[1] or x[2] < lo[2] or x[0] > hi[0] or x[1] > hi[1] or x[2] > hi[2]:
        return
    pa = project(ca, x)
    pb = project(cb, x)
    if pa[2] <= 0.0 or pb[2] <= 0.0:
        return
    ea = wp.length(wp.vec2(pa[0], pa[1]) - ua)
    eb = wp.length(wp.vec2(pb[0], pb[1]) - ub)
    if ea > gate_px or eb > gate_px:
        return
    cand_pos[t] = x
    cand_score[t] = mode_log_likelihood(cams, target, bgr, integral, window, mode, x)


@wp.func
def ranks_before(s: float, t: int, u: float, q: int):
    """True when candidate (score u, index q) ranks before (score s, index t): higher score, ties by lower index."""
    return u > s or (u == s and q < t)


@wp.func
def keep_candidate(
    t: int,
    cand_pos: wp.array(dtype=wp.vec3),
    cand_score: wp.array(dtype=wp.float32),
    radius: float,
    keep: wp.array(dtype=wp.int32),
):
    """The suppression flag of candidate t (see :func:`candidate_keep_kernel`)."""
    s = cand_score[t]
    flag = int(0)
    if s > LOG_ZERO:
        flag = int(1)
        x = cand_pos[t]
        r2 = radius * radius
        for q in range(cand_score.shape[0]):
            u = cand_score[q]
            if u > LOG_ZERO and ranks_before(s, t, u, q):
                d = cand_pos[q] - x
                if wp.dot(d, d) < r2:
                    flag = int(0)
    keep[t] = flag


@wp.func
def rank_candidate(
    t: int,
    cand_pos: wp.array(dtype=wp.vec3),
    cand_score: wp.array(dtype=wp.float32),
    keep: wp.array(dtype=wp.int32),
    det_pos: wp.array(dtype=wp.vec3),
    det_score: wp.array(dtype=wp.float32),
):
    """Work item t of :func:`candidate_rank_kernel`."""
    kslots = det_pos.shape[0]
    n = cand_score.shape[0]
    if t < kslots:
        kept = int(0)
        for q in range(n):
            kept += keep[q]
        if t >= kept:
            det_score[t] = LOG_ZERO
            det_pos[t] = wp.vec3(0.0, 0.0, 0.0)
    if t < n:
        if keep[t] != 0:
            s = cand_score[t]
            rank = int(0)
            for q in range(n):
                if keep[q] != 0 and ranks_before(s, t, cand_score[q], q):
                    rank += 1
            if rank < kslots:
                det_pos[rank] = cand_pos[t]
                det_score[rank] = s


@wp.func_native("""
#if defined(__CUDA_ARCH__)
    __syncthreads();
#endif
""")
def block_sync():
    """Barrier of the block's threads, whose global-memory writes before it are then visible to all of them (CUDA; the
    CPU backend runs a block as one thread, which needs none). Every thread of the block must call it."""
    ...


@wp.kernel
def detect_tail_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    part_score: wp.array3d(dtype=wp.float32),
    part_index: wp.array3d(dtype=wp.int32),
    part_uv: wp.array3d(dtype=wp.vec2),
    pair_a: wp.array(dtype=wp.int32),
    pair_b: wp.array(dtype=wp.int32),
    pairs: int,
    gate_px: float,
    lo: wp.vec3,
    hi: wp.vec3,
    radius: float,
    est: wp.array(dtype=wp.float64),
    frame: wp.array(dtype=wp.int32),
    uniform_frame: wp.array(dtype=wp.int32),
    thresholds: wp.vec2,
    margin: float,
    evidence: float,
    near: float,
    blob_score: wp.array2d(dtype=wp.float32),
    blob_uv: wp.array2d(dtype=wp.vec2),
    cand_pos: wp.array(dtype=wp.vec3),
    cand_score: wp.array(dtype=wp.float32),
    keep: wp.array(dtype=wp.int32),
    det_pos: wp.array(dtype=wp.vec3),
    det_score: wp.array(dtype=wp.float32),
    det_cum: wp.array(dtype=wp.float32),
    det_count: wp.array(dtype=wp.int32),
    mix: wp.array(dtype=wp.float32),
):
    """:func:`blob_select_kernel`, :func:`candidates_kernel` (``pairs`` camera pairs: none with one camera),
    :func:`candidate_keep_kernel`, :func:`candidate_rank_kernel` and the mode test (``proposal.jump_decision_kernel``)
    in one block, the stages separated by block barriers: one launch instead of five (each a few microseconds of
    latency on a GPU, where a frame of 1e5 particles takes tens of microseconds). The same results as the five
    launches. Launch ``wp.launch_tiled(dim=[1], block_dim=B)``."""
    _b, lane = wp.tid()
    m = part_score.shape[0]
    per_camera = part_score.shape[1] * part_score.shape[2]
    for e in range(lane, m * per_camera, wp.block_dim()):
        c = e // per_camera
        q = e % per_camera
        k = q // part_score.shape[2]
        r = q % part_score.shape[2]
        select_blob(c, k, r, part_score, part_index, part_uv, blob_score.shape[1], blob_score, blob_uv)
    block_sync()
    n = int(0)
    if pairs > 0:
        n = cand_score.shape[0]
    for t in range(lane, n, wp.block_dim()):
        candidate(
            t,
            cams,
            target,
            bgr,
            integral,
            window,
            mode,
            blob_score,
            blob_uv,
            pair_a,
            pair_b,
            gate_px,
            lo,
            hi,
            cand_pos,
            cand_score,
        )
    block_sync()
    for t in range(lane, n, wp.block_dim()):
        keep_candidate(t, cand_pos, cand_score, radius, keep)
    block_sync()
    for t in range(lane, wp.max(n, det_pos.shape[0]), wp.block_dim()):
        if n > 0:
            rank_candidate(t, cand_pos, cand_score, keep, det_pos, det_score)
    block_sync()
    if lane == 0:
        jump_decision(
            cams,
            target,
            bgr,
            integral,
            window,
            mode,
            det_pos,
            det_score,
            est,
            frame,
            uniform_frame,
            thresholds,
            margin,
            evidence,
            near,
            det_cum,
            det_count,
            mix,
        )
