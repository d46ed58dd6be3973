"""Reductions over the particle set without single-address atomics: max/argmax of log-weights, then
normalised weights and weighted moments (MMSE mean, spread, ESS, likelihood).

Pattern (portable between CUDA and the CPU backend): ``wp.launch_tiled(dim=[blocks], block_dim=B)``; block
``b`` owns particles ``[b*chunk, (b+1)*chunk)`` and each of its threads strides through them by
``wp.block_dim()`` (B on CUDA, 1 on the CPU, where one thread then covers the whole chunk); the per-thread
partials are combined with ``wp.tile`` + ``wp.tile_sum``/``tile_max`` and written once per block. A second
launch with one block combines the per-block partials, so no address is ever hit by more than one writer.
"""

import warp as wp

from .camera import Camera  # noqa: F401  (keeps module dependency order explicit for readers)

wp.set_module_options({"enable_backward": False})

NO_INDEX = wp.constant(2147483647)
NEG_INF = wp.constant(-3.0e38)

# Layout of the per-frame estimate vector (float64), shared with the host driver.
EST_MEAN = wp.constant(0)  # 0..2: weighted mean (MMSE), metres
EST_STD = wp.constant(3)  # 3..5: weighted standard deviation per axis, metres
EST_MAP = wp.constant(6)  # 6..8: best particle (MAP), metres
EST_ESS = wp.constant(9)  # effective sample size (sum w)^2 / sum w^2
EST_LOGLIK = wp.constant(10)  # log of the mean weight: log p(obs_t | obs_1..t-1) when resampled each frame
EST_MAXLOGW = wp.constant(11)  # max log-weight
EST_RESAMPLED = wp.constant(12)  # 1 if the particles are resampled after this frame
EST_SIZE = wp.constant(16)
N_SUMS = wp.constant(8)  # sum w, sum w^2, sum w x (3), sum w x^2 (3)


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
    stop = wp.min(start + chunk, n)
    best = float(NEG_INF)
    arg = int(NO_INDEX)
    for i in range(start + lane, stop, wp.block_dim()):
        v = logw[i]
        if v > best:
            best = v
            arg = i
    m = wp.tile_max(wp.tile(best))
    mv = m[0]
    cand = int(NO_INDEX)
    if best == mv:
        cand = arg
    a = wp.tile_min(wp.tile(cand))
    if lane == 0:
        part_max[b] = mv
        part_arg[b] = a[0]


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
    best = float(NEG_INF)
    arg = int(NO_INDEX)
    for j in range(lane, blocks, wp.block_dim()):
        v = part_max[j]
        if v > best or (v == best and part_arg[j] < arg):
            best = v
            arg = part_arg[j]
    m = wp.tile_max(wp.tile(best))
    mv = m[0]
    cand = int(NO_INDEX)
    if best == mv:
        cand = arg
    a = wp.tile_min(wp.tile(cand))
    if lane == 0:
        est[EST_MAXLOGW] = wp.float64(mv)
        best_index[0] = a[0]


@wp.kernel
def block_moments_kernel(
    logw: wp.array(dtype=wp.float32),
    particles: wp.array(dtype=wp.vec3),
    n: int,
    chunk: int,
    est: wp.array(dtype=wp.float64),
    weights: wp.array(dtype=wp.float64),
    part: wp.array2d(dtype=wp.float64),
):
    """w_i = exp(logw_i - max) (written to ``weights`` for resampling) and per-block sums of w, w^2, w x,
    w x^2 into ``part`` (blocks, N_SUMS)."""
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    mx = est[EST_MAXLOGW]
    sw = wp.float64(0.0)
    sw2 = wp.float64(0.0)
    sx = wp.vec3d()
    sxx = wp.vec3d()
    for i in range(start + lane, stop, wp.block_dim()):
        w = wp.exp(wp.float64(logw[i]) - mx)
        weights[i] = w
        x = wp.vec3d(particles[i])
        sw += w
        sw2 += w * w
        sx += w * x
        sxx += w * wp.cw_mul(x, x)
    t0 = wp.tile_sum(wp.tile(sw))
    t1 = wp.tile_sum(wp.tile(sw2))
    for k in range(3):
        tk = wp.tile_sum(wp.tile(sx[k]))
        tkk = wp.tile_sum(wp.tile(sxx[k]))
        if lane == 0:
            part[b, 2 + k] = tk[0]
            part[b, 5 + k] = tkk[0]
    if lane == 0:
        part[b, 0] = t0[0]
        part[b, 1] = t1[0]


@wp.kernel
def final_moments_kernel(
    part: wp.array2d(dtype=wp.float64),
    blocks: int,
    n: int,
    particles: wp.array(dtype=wp.vec3),
    best_index: wp.array(dtype=wp.int32),
    ess_threshold: wp.array(dtype=wp.float32),
    est: wp.array(dtype=wp.float64),
    resample: wp.array(dtype=wp.int32),
):
    """Combine the per-block sums (launch one block) into the estimate vector (layout ``EST_*``) and the
    resampling decision: resample when ESS <= threshold * N (threshold 1 = every frame, CONDENSATION)."""
    _b, lane = wp.tid()
    sw = wp.float64(0.0)
    sw2 = wp.float64(0.0)
    sx = wp.vec3d()
    sxx = wp.vec3d()
    for j in range(lane, blocks, wp.block_dim()):
        sw += part[j, 0]
        sw2 += part[j, 1]
        sx += wp.vec3d(part[j, 2], part[j, 3], part[j, 4])
        sxx += wp.vec3d(part[j, 5], part[j, 6], part[j, 7])
    t0 = wp.tile_sum(wp.tile(sw))
    t1 = wp.tile_sum(wp.tile(sw2))
    mean = wp.vec3d()
    ex2 = wp.vec3d()
    for k in range(3):
        tk = wp.tile_sum(wp.tile(sx[k]))
        tkk = wp.tile_sum(wp.tile(sxx[k]))
        mean[k] = tk[0]
        ex2[k] = tkk[0]
    if lane == 0:
        w = t0[0]
        mean = mean / w
        ex2 = ex2 / w
        best = particles[best_index[0]]
        for k in range(3):
            est[EST_MEAN + k] = mean[k]
            est[EST_STD + k] = wp.sqrt(wp.max(ex2[k] - mean[k] * mean[k], wp.float64(0.0)))
            est[EST_MAP + k] = wp.float64(best[k])
        ess = w * w / t1[0]
        est[EST_ESS] = ess
        est[EST_LOGLIK] = est[EST_MAXLOGW] + wp.log(w / wp.float64(n))
        flag = int(0)
        if ess <= wp.float64(ess_threshold[0]) * wp.float64(n) + wp.float64(1.0e-9):
            flag = 1
        est[EST_RESAMPLED] = wp.float64(flag)
        resample[0] = flag


@wp.kernel
def subsample_kernel(
    particles: wp.array(dtype=wp.vec3),
    weights: wp.array(dtype=wp.float64),
    stride: int,
    out_particles: wp.array(dtype=wp.vec3),
    out_weights: wp.array(dtype=wp.float32),
):
    """Every ``stride``-th particle and its weight relative to the best (for reports; not for tracking)."""
    k = wp.tid()
    out_particles[k] = particles[k * stride]
    out_weights[k] = wp.float32(weights[k * stride])


@wp.kernel
def increment_kernel(counter: wp.array(dtype=wp.int32)):
    """counter[0] += 1 (the frame number that seeds the random streams; kept on device for graph replay)."""
    counter[0] = counter[0] + 1
