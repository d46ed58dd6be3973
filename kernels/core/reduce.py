"""Reductions over the particle set without single-address atomics: max/argmax of log-weights and the weighted
moments (MMSE mean, spread, ESS, likelihood) in one pass with the online ("running max") rescaling.

Pattern (portable between CUDA and the CPU backend): ``wp.launch_tiled(dim=[blocks], block_dim=B)``; block
``b`` owns particles ``[b*chunk, (b+1)*chunk)`` and each of its threads strides through them by
``wp.block_dim()`` (B on CUDA, 1 on the CPU, where one thread then covers the whole chunk); the per-thread
partials are combined by the native block reductions below (:func:`block_argmax`, :func:`block_sum8`) and written
once per block. A second
launch with one block combines the per-block partials, so no address is ever hit by more than one writer.
"""

import warp as wp

from wptrack.kernels.core.camera import Camera  # noqa: F401  (keeps module dependency order explicit for readers)

wp.set_module_options({"enable_backward": False})

NO_INDEX = wp.constant(2147483647)
NEG_INF = wp.constant(-3.0e38)
LOGW_FLOOR = wp.constant(-1.0e30)
"""Lowest log-weight kept: -inf, NaN and anything below become this (see :func:`finite_logw`)."""

# Layout of the per-frame estimate vector (float64), shared with the host driver.
EST_MEAN = wp.constant(0)  # 0..2: weighted mean (MMSE), metres
EST_STD = wp.constant(3)  # 3..5: weighted standard deviation per axis, metres
EST_MAP = wp.constant(6)  # 6..8: best particle (MAP), metres
EST_ESS = wp.constant(9)  # effective sample size (sum w)^2 / sum w^2
EST_LOGLIK = wp.constant(10)  # log of the mean weight: log p(obs_t | obs_1..t-1) when resampled each frame
EST_MAXLOGW = wp.constant(11)  # max log-weight
EST_RESAMPLED = wp.constant(12)  # 1 if the particles are resampled after this frame
EST_DEGENERATE = wp.constant(13)  # 1 if every log-weight was -inf/NaN (<= LOGW_FLOOR): the weights were uniform
EST_SIZE = wp.constant(16)
N_SUMS = wp.constant(8)  # sum w, sum w^2, sum w x (3), sum w x^2 (3)


@wp.func
def finite_logw(v: float):
    """``v``, or :data:`LOGW_FLOOR` when ``v`` is -inf, NaN or below it (every particle out of view or of zero
    likelihood).

    A floored particle weighs ``exp(LOGW_FLOOR - M) = 0`` next to any particle with a real log-weight M, so the
    floor changes nothing while one particle is alive; when all are floored they weigh exp(0) = 1 each: the
    documented recovery "keep the prior" (the predicted cloud with uniform weights, flagged by
    ``EST_DEGENERATE``), with finite moments and no host round trip. Kernels apply it before storing a log-weight.
    """
    if v >= LOGW_FLOOR:  # false for NaN
        return v
    return float(LOGW_FLOOR)


# Block reductions in native CUDA. Warp's ``tile_sum``/``tile_max`` over ``wp.tile(x)`` cost two or three barriers
# and a serial pass of thread 0 each; the moments took ten of them per block (the max, the argmax and eight float64
# sums): about 20 microseconds per block on an H100, which made the block reduction, not the particles, most of the
# predict + score kernel at 1e6 particles (BENCHMARKS.md, issue 13, round six). These do the same arithmetic in one
# pass: warp shuffles, one barrier per stage. The sums add in exactly the order of ``tile_sum`` (a shuffle-down tree
# per warp, offsets 16 to 1, then thread 0 adds the warp totals in warp order), so the results are bit-identical to
# the tile reductions they replace. CUDA: every thread of the block calls them, the block size a multiple of 32. The
# CPU branches are the one-thread blocks of the CPU backend (``wp.block_dim()`` is 1 there).

vec8d = wp.types.vector(length=8, dtype=wp.float64)
"""Eight float64 sums reduced together (:func:`block_sum8`)."""

BLOCK_ARGMAX_SNIPPET = """
#if defined(__CUDA_ARCH__)
    __shared__ float warp_max[32];
    __shared__ int warp_arg[32];
    const int w = threadIdx.x >> 5;
    const int l = threadIdx.x & 31;
    const int warps = (blockDim.x + 31) >> 5;
    float m = best;
#pragma unroll
    for (int d = 16; d > 0; d >>= 1) {
        const float y = __shfl_xor_sync(0xffffffffu, m, d);
        m = y > m ? y : m;
    }
    if (l == 0) warp_max[w] = m;
    __syncthreads();
    float mv = warp_max[0];
    for (int k = 1; k < warps; ++k) mv = warp_max[k] > mv ? warp_max[k] : mv;
    int a = best == mv ? arg : no_index;
#pragma unroll
    for (int d = 16; d > 0; d >>= 1) {
        const int y = __shfl_xor_sync(0xffffffffu, a, d);
        a = y < a ? y : a;
    }
    if (l == 0) warp_arg[w] = a;
    __syncthreads();
    a = warp_arg[0];
    for (int k = 1; k < warps; ++k) a = warp_arg[k] < a ? warp_arg[k] : a;
    return wp::vec_t<2, wp::float64>(wp::float64(mv), wp::float64(a));
#else
    return wp::vec_t<2, wp::float64>(wp::float64(best), wp::float64(arg));
#endif
"""


@wp.func_native(BLOCK_ARGMAX_SNIPPET)
def block_argmax_native(best: float, arg: int, no_index: int) -> wp.vec2d:
    """``(block max of best, lowest arg among the threads holding it, no_index if none)`` to every thread, as float64
    (both exact). Use :func:`block_argmax`."""
    ...


@wp.func
def block_argmax(best: float, arg: int):
    """The block's maximum of the threads' ``best`` and the lowest ``arg`` attaining it (every thread of the block
    must call this; each gets both)."""
    r = block_argmax_native(best, arg, NO_INDEX)
    return wp.float32(r[0]), int(r[1])


BLOCK_SUM_SNIPPET = """
#if defined(__CUDA_ARCH__)
    __shared__ double warp_sums[32][LENGTH];
    const int w = threadIdx.x >> 5;
    const int l = threadIdx.x & 31;
    const int warps = (blockDim.x + 31) >> 5;
    wp::vec_t<LENGTH, wp::float64> s = v;
#pragma unroll
    for (int d = 16; d > 0; d >>= 1) {
#pragma unroll
        for (int k = 0; k < LENGTH; ++k) s.c[k] = s.c[k] + __shfl_down_sync(0xffffffffu, s.c[k], d);
    }
    if (l == 0) {
#pragma unroll
        for (int k = 0; k < LENGTH; ++k) warp_sums[w][k] = s.c[k];
    }
    __syncthreads();
    if (threadIdx.x == 0) {
        for (int j = 1; j < warps; ++j) {
#pragma unroll
            for (int k = 0; k < LENGTH; ++k) s.c[k] = s.c[k] + warp_sums[j][k];
        }
    }
    __syncthreads();
    return s;
#else
    return v;
#endif
"""
"""Native body of a block sum of a float64 vector of LENGTH components (see the comment above)."""


@wp.func_native(BLOCK_SUM_SNIPPET.replace("LENGTH", "8"))
def block_sum8(v: vec8d) -> vec8d:
    """The block's sum of ``v``, component by component, valid in thread 0 only (every thread must call it)."""
    ...


vec17d = wp.types.vector(length=17, dtype=wp.float64)
"""The seventeen per-slot sums of ``kernels.templates.slots`` (:func:`block_sum17`)."""


@wp.func_native(BLOCK_SUM_SNIPPET.replace("LENGTH", "17"))
def block_sum17(v: vec17d) -> vec17d:
    """:func:`block_sum8` for seventeen components."""
    ...


@wp.func
def partials_argmax(part_max: wp.array(dtype=wp.float32), part_arg: wp.array(dtype=wp.int32), blocks: int, lane: int):
    """Maximum of the per-block maxima and the lowest index attaining it, for a one-block combining launch."""
    best = float(NEG_INF)
    arg = int(NO_INDEX)
    for j in range(lane, blocks, wp.block_dim()):
        v = part_max[j]
        if v > best or (v == best and part_arg[j] < arg):
            best = v
            arg = part_arg[j]
    return block_argmax(best, arg)


@wp.func
def moments_zero():
    """Empty running partials for :func:`moments_push`: best, arg, sw, sw2, sx, sxx."""
    return float(NEG_INF), int(NO_INDEX), wp.float64(0.0), wp.float64(0.0), wp.vec3d(), wp.vec3d()


@wp.func
def strided_argmax(values: wp.array(dtype=wp.float32), start: int, stop: int, lane: int):
    """The block's maximum of ``values[start:stop]`` and the lowest index attaining it (``NO_INDEX`` when empty or
    all ``NEG_INF``); every lane of the block calls it."""
    best = float(NEG_INF)
    arg = int(NO_INDEX)
    for i in range(start + lane, stop, wp.block_dim()):
        v = values[i]
        if v > best:
            best = v
            arg = i
    return block_argmax(best, arg)


@wp.kernel
def block_max_kernel(
    logw: wp.array(dtype=wp.float32),
    n: int,
    chunk: int,
    part_max: wp.array(dtype=wp.float32),
    part_arg: wp.array(dtype=wp.int32),
):
    """Per-block max log-weight and the lowest index attaining it."""
    b, lane = wp.tid()
    start = b * chunk
    mv, a = strided_argmax(logw, start, wp.min(start + chunk, n), lane)
    if lane == 0:
        part_max[b] = mv
        part_arg[b] = a


@wp.kernel
def single_max_kernel(
    logw: wp.array(dtype=wp.float32),
    n: int,
    est: wp.array(dtype=wp.float64),
    best_index: wp.array(dtype=wp.int32),
):
    """:func:`block_max_kernel` and :func:`final_max_kernel` in one block, for small ``n`` (one launch instead of
    two): launch ``wp.launch_tiled(dim=[1], block_dim=B)``; writes ``est[EST_MAXLOGW]`` and ``best_index[0]`` (the
    lowest index attaining the maximum, as the two-pass reduction)."""
    _b, lane = wp.tid()
    mv, a = strided_argmax(logw, 0, n, lane)
    if lane == 0:
        est[EST_MAXLOGW] = wp.float64(mv)
        best_index[0] = a


@wp.kernel
def final_max_kernel(
    part_max: wp.array(dtype=wp.float32),
    part_arg: wp.array(dtype=wp.int32),
    blocks: int,
    est: wp.array(dtype=wp.float64),
    best_index: wp.array(dtype=wp.int32),
):
    """Combine the per-block maxima (launch one block): writes ``est[EST_MAXLOGW]`` and ``best_index[0]``."""
    _b, lane = wp.tid()
    mv, a = partials_argmax(part_max, part_arg, blocks, lane)
    if lane == 0:
        est[EST_MAXLOGW] = wp.float64(mv)
        best_index[0] = a


@wp.func
def moments_push(
    best: float,
    arg: int,
    sw: wp.float64,
    sw2: wp.float64,
    sx: wp.vec3d,
    sxx: wp.vec3d,
    v: float,
    i: int,
    x: wp.vec3,
):
    """Add particle ``i`` (log-weight ``v``, position ``x``) to one thread's running partials.

    The partials are kept relative to the thread's running maximum ``best`` (the "online softmax" update):
    ``sw = sum exp(logw - best)``, ``sw2 = sum exp(2 (logw - best))``, ``sx = sum w x``, ``sxx = sum w x^2``. A new
    maximum rescales them by ``exp(best_old - v)``, so one pass over the particles yields the maximum, the MAP index
    and the weighted moments together (no second read of the log-weights). ``v`` goes through
    :func:`finite_logw` (-inf/NaN count as the floor). Returns the updated partials.
    """
    v = finite_logw(v)
    if v > best:
        r = wp.float64(0.0)
        if best > NEG_INF:
            r = wp.exp(wp.float64(best) - wp.float64(v))
        sw = sw * r
        sw2 = sw2 * r * r
        sx = sx * r
        sxx = sxx * r
        best = v
        arg = i
    w = wp.float64(wp.exp(v - best))  # float32 exp (the log-weights are float32), float64 sums
    xd = wp.vec3d(x)
    return best, arg, sw + w, sw2 + w * w, sx + w * xd, sxx + w * wp.cw_mul(xd, xd)


@wp.func
def moments_store(
    b: int,
    lane: int,
    best: float,
    arg: int,
    sw: wp.float64,
    sw2: wp.float64,
    sx: wp.vec3d,
    sxx: wp.vec3d,
    part_max: wp.array(dtype=wp.float32),
    part_arg: wp.array(dtype=wp.int32),
    part: wp.array2d(dtype=wp.float64),
):
    """Combine the threads' running partials of block ``b`` (every thread of the block must call this) and write
    them once: ``part_max[b]`` (block max log-weight), ``part_arg[b]`` (lowest index attaining it) and
    ``part[b, :]`` = sums of w, w^2, w x (3), w x^2 (3) with w relative to the block max."""
    mv, a = block_argmax(best, arg)
    r = wp.float64(0.0)
    if best > NEG_INF:
        r = wp.exp(wp.float64(best) - wp.float64(mv))
    t = block_sum8(vec8d(sw * r, sw2 * r * r, sx[0] * r, sx[1] * r, sx[2] * r, sxx[0] * r, sxx[1] * r, sxx[2] * r))
    if lane == 0:
        part_max[b] = mv
        part_arg[b] = a
        for k in range(8):
            part[b, k] = t[k]


@wp.kernel
def final_moments_kernel(
    part_max: wp.array(dtype=wp.float32),
    part_arg: wp.array(dtype=wp.int32),
    part: wp.array2d(dtype=wp.float64),
    blocks: int,
    n: int,
    particles: wp.array(dtype=wp.vec3),
    ess_threshold: wp.array(dtype=wp.float32),
    est: wp.array(dtype=wp.float64),
    best_index: wp.array(dtype=wp.int32),
    resample: wp.array(dtype=wp.int32),
):
    """Combine the per-block partials (launch one block) into the estimate vector (layout ``EST_*``), the MAP index
    and the resampling decision: resample when ESS <= threshold * N (threshold 1 = every frame, CONDENSATION).

    Block sums are rescaled from their block maximum to the global one M: ``sum w = sum_b exp(M_b - M) S_b``.
    """
    _b, lane = wp.tid()
    mv, a = partials_argmax(part_max, part_arg, blocks, lane)
    sw = wp.float64(0.0)
    sw2 = wp.float64(0.0)
    sx = wp.vec3d()
    sxx = wp.vec3d()
    for j in range(lane, blocks, wp.block_dim()):
        pm = part_max[j]
        if pm > NEG_INF:
            r = wp.exp(wp.float64(pm) - wp.float64(mv))
            sw += r * part[j, 0]
            sw2 += r * r * part[j, 1]
            sx += r * wp.vec3d(part[j, 2], part[j, 3], part[j, 4])
            sxx += r * wp.vec3d(part[j, 5], part[j, 6], part[j, 7])
    t = block_sum8(vec8d(sw, sw2, sx[0], sx[1], sx[2], sxx[0], sxx[1], sxx[2]))
    if lane == 0:
        w = t[0]
        mean = wp.vec3d(t[2], t[3], t[4]) / w
        ex2 = wp.vec3d(t[5], t[6], t[7]) / w
        bi = a
        best_index[0] = bi
        bx = particles[bi]
        est[EST_MAXLOGW] = wp.float64(mv)
        for k in range(3):
            est[EST_MEAN + k] = mean[k]
            est[EST_STD + k] = wp.sqrt(wp.max(ex2[k] - mean[k] * mean[k], wp.float64(0.0)))
            est[EST_MAP + k] = wp.float64(bx[k])
        ess = w * w / t[1]
        est[EST_ESS] = ess
        est[EST_LOGLIK] = wp.float64(mv) + wp.log(w / wp.float64(n))
        flag = int(0)
        if ess <= wp.float64(ess_threshold[0]) * wp.float64(n) + wp.float64(1.0e-9):
            flag = 1
        est[EST_RESAMPLED] = wp.float64(flag)
        resample[0] = flag
        degenerate = wp.float64(0.0)
        if mv <= LOGW_FLOOR:
            degenerate = wp.float64(1.0)
        est[EST_DEGENERATE] = degenerate


@wp.kernel
def subsample_kernel(
    particles: wp.array(dtype=wp.vec3),
    logw: wp.array(dtype=wp.float32),
    est: wp.array(dtype=wp.float64),
    stride: int,
    out_particles: wp.array(dtype=wp.vec3),
    out_weights: wp.array(dtype=wp.float32),
):
    """Every ``stride``-th particle and its weight relative to the best, ``exp(logw - max)`` (for reports; not for
    tracking). ``est[EST_MAXLOGW]`` holds the frame's max log-weight."""
    k = wp.tid()
    out_particles[k] = particles[k * stride]
    out_weights[k] = wp.float32(wp.exp(wp.float64(logw[k * stride]) - est[EST_MAXLOGW]))


@wp.kernel
def increment_kernel(counter: wp.array(dtype=wp.int32)):
    """counter[0] += 1 (the frame number that seeds the random streams; kept on device for graph replay)."""
    counter[0] = counter[0] + 1
