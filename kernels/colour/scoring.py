"""S1 observation model (Barrera et al., eqs. 4-7) and the fused predict + project + score kernel.

For each camera: outside the image p = 1/25 (eq. 6); inside, m = number of target-coloured pixels in the
5x5 window around the projected pixel, p = max(m, 1)/25 (eq. 7). Cameras are independent: the weight is
the product over cameras (eq. 5), i.e. a sum of logs. Window pixels outside the image never match.

Two ways to count m, with identical results:
- ``SCORE_DIRECT``: classify the 25 window pixels of the BGR frame on the fly (the paper's choice; no
  whole-image colour filtering, best while 25 N < W H).
- ``SCORE_INTEGRAL``: 4 reads of the per-camera integral image of the target mask.
- ``SCORE_MAP``: 1 read of a per-pixel window-count map built from the integral image once per frame (best for
  large N: the per-particle reads, random accesses to L2, dominate the frame at 1e7+ particles).
"""

import functools

import warp as wp

from wptrack.kernels.colour.hsi import HALF_WINDOW, ColourTarget, pixel_matches, window_count_integral
from wptrack.kernels.colour.walk import gaussian_walk
from wptrack.kernels.core.camera import CAMERA_SET_SIZE, Camera, CameraSet, pixel_of, project
from wptrack.kernels.core.reduce import finite_logw, moments_push, moments_store, moments_zero

# fast_math (CUDA only): the particle kernel is compute-bound at 1e7+ particles (Philox, Box-Muller, one distorted
# projection and a log per camera); the approximate transcendentals and divisions (a few ulp; the CUDA tests against
# the NumPy references pass unchanged) took predict+score from 4.18 to 3.51 ms at 1e8 particles x 4 cameras (H200).
wp.set_module_options({"enable_backward": False, "fast_math": True})

SCORE_DIRECT = wp.constant(0)
SCORE_INTEGRAL = wp.constant(1)
SCORE_MAP = wp.constant(2)
LOG_WINDOW_AREA = wp.constant(3.2188758248682006)  # log(25)


@wp.func
def window_count_direct(cam: Camera, target: ColourTarget, bgr: wp.array(dtype=wp.uint8), px: int, py: int):
    """m: target pixels in the 5x5 window centred on pixel (px, py), classified from the BGR frame."""
    m = int(0)
    for dy in range(-HALF_WINDOW, HALF_WINDOW + 1):
        y = py + dy
        if y >= 0 and y < cam.height:
            for dx in range(-HALF_WINDOW, HALF_WINDOW + 1):
                x = px + dx
                if x >= 0 and x < cam.width:
                    m += pixel_matches(target, bgr, cam.pixel_offset + y * cam.width + x)
    return m


@wp.func
def window_count(
    cam: Camera,
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    x: wp.vec3,
):
    """m for world point ``x`` in one camera, or -1 when it projects outside the image."""
    uvz = project(cam, x)
    if uvz[2] <= 0.0:
        return -1
    px = pixel_of(uvz[0])
    py = pixel_of(uvz[1])
    if px < 0 or py < 0 or px >= cam.width or py >= cam.height:
        return -1
    if mode == SCORE_MAP:
        return int(window[cam.pixel_offset + py * cam.width + px])
    if mode == SCORE_INTEGRAL:
        return window_count_integral(cam, integral, px, py)
    return window_count_direct(cam, target, bgr, px, py)


@wp.func
def camera_log_likelihood(
    cam: Camera,
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    x: wp.vec3,
):
    """log p_c of one camera (eqs. 6-7): log(1/25) outside the image, log(max(m, 1)/25) inside."""
    m = window_count(cam, target, bgr, integral, window, mode, x)
    return wp.log(float(wp.max(m, 1))) - LOG_WINDOW_AREA


@wp.func
def colour_log_likelihood(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    x: wp.vec3,
):
    """log w = sum over cameras of log p_c (eqs. 5-7): log(1/25) outside, log(max(m, 1)/25) inside."""
    total = float(0.0)
    for c in range(cams.shape[0]):
        total += camera_log_likelihood(cams[c], target, bgr, integral, window, mode, x)
    return total


@wp.func
def map_log_likelihood(cam: Camera, window: wp.array(dtype=wp.uint8), x: wp.vec3):
    """:func:`camera_log_likelihood` in ``SCORE_MAP`` mode: the same value, without the other modes' code."""
    m = int(-1)
    uvz = project(cam, x)
    if uvz[2] > 0.0:
        px = pixel_of(uvz[0])
        py = pixel_of(uvz[1])
        if px >= 0 and py >= 0 and px < cam.width and py < cam.height:
            m = int(window[cam.pixel_offset + py * cam.width + px])
    return wp.log(float(wp.max(m, 1))) - LOG_WINDOW_AREA


@wp.kernel
def window_count_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    points: wp.array(dtype=wp.vec3),
    counts: wp.array2d(dtype=wp.int32),
):
    """Window counts ``counts[c, i]`` (M, N) of every point in every camera (-1: outside). For tests."""
    c, i = wp.tid()
    counts[c, i] = window_count(cams[c], target, bgr, integral, window, mode, points[i])


@wp.kernel
def colour_predict_score_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    particles: wp.array(dtype=wp.vec3),
    ancestors: wp.array(dtype=wp.int32),
    logw_prev: wp.array(dtype=wp.float32),
    resampled: wp.array(dtype=wp.int32),
    sigma: wp.array(dtype=wp.float32),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    n: int,
    chunk: int,
    particles_out: wp.array(dtype=wp.vec3),
    logw_out: wp.array(dtype=wp.float32),
    part_max: wp.array(dtype=wp.float32),
    part_arg: wp.array(dtype=wp.int32),
    part: wp.array2d(dtype=wp.float64),
):
    """One S1 iteration, fused: gather the resampled parent, gaussian walk (eqs. 1-3), project into every camera
    and score (eqs. 5-7), and accumulate the block's max log-weight, MAP index and weighted sums
    (``reduce.moments_push``), so the particles are read once per frame.

    Launch ``wp.launch_tiled(dim=[blocks], block_dim=B)``; block ``b`` owns particles ``[b chunk, (b+1) chunk)``.
    ``logw_out[i] = (resampled ? 0 : logw_prev[i]) + log-likelihood``: without resampling (ESS trigger not fired,
    ``ancestors`` is the identity) the weights accumulate. Outputs ``part_*`` as ``reduce.moments_store``.
    """
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    s = sigma[0]
    f = frame[0]
    keep = resampled[0] == 0
    best, arg, sw, sw2, sx, sxx = moments_zero()
    for i in range(start + lane, stop, wp.block_dim()):
        x = gaussian_walk(particles[ancestors[i]], s, seed, i, f)
        particles_out[i] = x
        lw = colour_log_likelihood(cams, target, bgr, integral, window, mode, x)
        if keep:
            lw += logw_prev[i]
        lw = finite_logw(lw)  # -inf/NaN -> the floor, as the estimate and the resampler read it
        logw_out[i] = lw
        best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
    moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)


@functools.cache
def camera_set_log_likelihood(count: int):
    """``sum_c map_log_likelihood(c, window, x)`` over the ``count`` cameras of a :class:`CameraSet` (eqs. 5-7), the
    cameras passed by value and the sum unrolled at compile time; one ``@wp.func`` per count, shared by the paper's
    large-N kernel and the mixture's."""

    @wp.func
    def camera_set_loglik(cams: CameraSet, window: wp.array(dtype=wp.uint8), x: wp.vec3):
        lw = map_log_likelihood(cams.c0, window, x)
        if wp.static(count > 1):
            lw += map_log_likelihood(cams.c1, window, x)
        if wp.static(count > 2):
            lw += map_log_likelihood(cams.c2, window, x)
        if wp.static(count > 3):
            lw += map_log_likelihood(cams.c3, window, x)
        if wp.static(count > 4):
            lw += map_log_likelihood(cams.c4, window, x)
        if wp.static(count > 5):
            lw += map_log_likelihood(cams.c5, window, x)
        if wp.static(count > 6):
            lw += map_log_likelihood(cams.c6, window, x)
        if wp.static(count > 7):
            lw += map_log_likelihood(cams.c7, window, x)
        return lw

    return camera_set_loglik


@functools.cache
def colour_predict_score_map_kernel(count: int) -> wp.Kernel:
    """:func:`colour_predict_score_kernel` specialised for the large-N case, compiled once per camera count:
    ``SCORE_MAP``
    scoring and ``count`` (1 to ``CAMERA_SET_SIZE``) cameras passed by value in a
    :class:`~kernels.core.camera.CameraSet`. Same particles and log-weights, bit for bit (the same functions, the
    cameras summed in the same order). Launch and outputs as the general kernel.

    One of the two factories in ``kernels/`` (with ``xor.xor_band_kernel``): the camera count is a compile-time
    constant (``wp.static``), because a count read at run time (``if cams.count > k``) raised the kernel from 72 to
    91 registers and lost a third of the occupancy (3.57 vs 2.73 ms at 1e8 particles x 4 cameras, H200;
    BENCHMARKS.md, issue 13). Without the other scoring modes'
    code and the per-particle loads of the camera structs it runs where the general kernel takes 3.5 ms.
    """
    if not 1 <= count <= CAMERA_SET_SIZE:
        raise ValueError(f"camera count {count}: the camera-set kernel takes 1 to {CAMERA_SET_SIZE} cameras")

    set_loglik = camera_set_log_likelihood(count)

    @wp.kernel(enable_backward=False, module="unique", module_options={"fast_math": True})
    def colour_predict_score_map_kernel(
        cams: CameraSet,
        window: wp.array(dtype=wp.uint8),
        particles: wp.array(dtype=wp.vec3),
        ancestors: wp.array(dtype=wp.int32),
        logw_prev: wp.array(dtype=wp.float32),
        resampled: wp.array(dtype=wp.int32),
        sigma: wp.array(dtype=wp.float32),
        seed: wp.vec2ui,
        frame: wp.array(dtype=wp.int32),
        n: int,
        chunk: int,
        particles_out: wp.array(dtype=wp.vec3),
        logw_out: wp.array(dtype=wp.float32),
        part_max: wp.array(dtype=wp.float32),
        part_arg: wp.array(dtype=wp.int32),
        part: wp.array2d(dtype=wp.float64),
    ):
        b, lane = wp.tid()
        start = b * chunk
        stop = wp.min(start + chunk, n)
        s = sigma[0]
        f = frame[0]
        keep = resampled[0] == 0
        best, arg, sw, sw2, sx, sxx = moments_zero()
        for i in range(start + lane, stop, wp.block_dim()):
            x = gaussian_walk(particles[ancestors[i]], s, seed, i, f)  # eqs. 1-3
            particles_out[i] = x
            lw = set_loglik(cams, window, x)  # eqs. 5-7, camera by camera as colour_log_likelihood
            if keep:
                lw += logw_prev[i]
            lw = finite_logw(lw)
            logw_out[i] = lw
            best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
        moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)

    return colour_predict_score_map_kernel


@wp.kernel
def gaussian3d_predict_score_kernel(
    observation: wp.array(dtype=wp.vec3),
    sigma_obs: wp.array(dtype=wp.float32),
    particles: wp.array(dtype=wp.vec3),
    ancestors: wp.array(dtype=wp.int32),
    logw_prev: wp.array(dtype=wp.float32),
    resampled: wp.array(dtype=wp.int32),
    sigma: wp.array(dtype=wp.float32),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    n: int,
    chunk: int,
    particles_out: wp.array(dtype=wp.vec3),
    logw_out: wp.array(dtype=wp.float32),
    part_max: wp.array(dtype=wp.float32),
    part_arg: wp.array(dtype=wp.int32),
    part: wp.array2d(dtype=wp.float64),
):
    """Section III.C of the extended paper: gaussian walk, then a 3D gaussian observation model
    log p = -|x - obs|^2 / (2 sigma_obs^2) (constants dropped; they cancel in the normalisation). Launched and
    fused with the block partials like :func:`colour_predict_score_kernel`."""
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    s = sigma[0]
    f = frame[0]
    keep = resampled[0] == 0
    obs = observation[0]
    so = sigma_obs[0]
    best, arg, sw, sw2, sx, sxx = moments_zero()
    for i in range(start + lane, stop, wp.block_dim()):
        x = gaussian_walk(particles[ancestors[i]], s, seed, i, f)
        particles_out[i] = x
        d = x - obs
        lw = -wp.dot(d, d) / (2.0 * so * so)
        if keep:
            lw += logw_prev[i]
        lw = finite_logw(lw)  # -inf/NaN -> the floor, as the estimate and the resampler read it
        logw_out[i] = lw
        best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
    moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)
