"""Detection-driven jumps for the S1 colour filter (issue 12, reworked in issue 29): beyond the paper's prior-only
proposal.

The paper (Barrera et al., 2005, conclusions) samples new particles only from the motion prior (eqs. 1-3), so it never
converges from a random initialisation and cannot re-acquire a lost object. Here the motion model may *jump* to a
detection: particle i is drawn from

    p_t(x | x_parent) = (1 - a_t) N(x; x_parent, sigma_m^2 I) + a_t D_t(x)

and weighted by the likelihood alone (eqs. 5-7; a bootstrap filter of this motion model: sensor resetting, Lenser and
Veloso, ICRA 2000; mixture Monte Carlo localisation, Thrun, Fox, Burgard and Dellaert, Artificial Intelligence 128,
2001). D_t is a mixture of gaussians of deviation sigma_d around the frame's K detection candidates
(``kernels.colour.blobs``: colour blobs triangulated across camera pairs), each weighted by exp(its log-likelihood -
the best one's), so jumps go to the candidates that the most cameras agree on.

The jump probability a_t comes from a **mode test** (:func:`jump_decision_kernel`, one thread per frame): the best
candidate's score (:func:`mode_log_likelihood`) is compared with the cloud's - the best score of the previous frame's
MMSE and MAP estimates and of the candidates next to them, on the current frame - and the excess over ``margin`` nats
accumulates (a CUSUM, Page 1954):

    S_t = max(0, S_{t-1} + (L_best - L_cloud) - margin);   jump when S_t > evidence, then S_t = 0

On a jump frame a_t = eps (``mixture``), else a_t = alpha (``reset_rate``, a small base rate, 0 by default). On the
first frame after a uniform initialisation the base distribution is the uniform one over the working volume and
a_t = eps. With no candidate a_t = 0 and the frame is the paper's. A stable track on the object is never out-scored by
a margin (the object's own candidate scores what the cloud scores), so it does not jump; a cloud on a wrong mode -
a point that fewer cameras agree on - is out-scored by about log 25 nats per disagreeing camera and moves to the
candidate within a frame or two. eps = alpha = 0 gives back the paper's filter.

Particles decide to jump with the fourth normal of their motion draw (``normal4``; the walk uses three): z_3 < the
frame's threshold Phi^-1(a_t) (set by the mode test from two host constants), so a frame without a jump costs one
comparison per particle more than the paper's.
"""

import functools

import warp as wp

from wptrack.kernels.colour.hsi import ColourTarget
from wptrack.kernels.colour.scoring import (
    LOG_WINDOW_AREA,
    camera_set_log_likelihood,
    colour_log_likelihood,
    window_count,
)
from wptrack.kernels.colour.walk import STREAM_MOTION
from wptrack.kernels.core.camera import CAMERA_SET_SIZE, Camera, CameraSet
from wptrack.kernels.core.random import normal4, uniform4
from wptrack.kernels.core.reduce import (
    EST_MAP,
    EST_MEAN,
    EST_STD,
    finite_logw,
    moments_push,
    moments_store,
    moments_zero,
)

wp.set_module_options({"enable_backward": False})

STREAM_PROPOSAL_MIX = wp.constant(13)  # per jumping particle: which detection component
STREAM_PROPOSAL_BOX = wp.constant(14)  # per particle on the first frame after a uniform initialisation: its position
LOG_ZERO = wp.constant(-1.0e30)  # log of a zero density (finite: sums stay finite in float32)
UNDISTORT_ITERATIONS = wp.constant(8)


@wp.func
def log_add(a: float, b: float):
    """log(exp(a) + exp(b)) without overflow; LOG_ZERO stands for log 0."""
    m = wp.max(a, b)
    if m <= LOG_ZERO:
        return LOG_ZERO
    return m + wp.log(wp.exp(a - m) + wp.exp(b - m))


@wp.func
def pixel_ray_direction(cam: Camera, u: float, v: float):
    """World direction (unit) of the ray through pixel coordinate (u, v): OpenCV distortion inverted by fixed-point
    iteration (as ``cv2.undistortPoints``), then rotated to the world frame (X_w = R^T (X_c - t))."""
    xd = (u - cam.c[0]) / cam.f[0]
    yd = (v - cam.c[1]) / cam.f[1]
    a = xd
    b = yd
    for _it in range(UNDISTORT_ITERATIONS):
        r2 = a * a + b * b
        radial = 1.0 + r2 * (cam.k[0] + r2 * (cam.k[1] + r2 * cam.k[2]))
        da = 2.0 * cam.p[0] * a * b + cam.p[1] * (r2 + 2.0 * a * a)
        db = cam.p[0] * (r2 + 2.0 * b * b) + 2.0 * cam.p[1] * a * b
        a = (xd - da) / radial
        b = (yd - db) / radial
    return wp.normalize(wp.transpose(cam.R) * wp.vec3(a, b, 1.0))


@wp.func
def camera_centre(cam: Camera):
    """Camera centre in the world frame, metres: -R^T t."""
    return -(wp.transpose(cam.R) * cam.t)


@wp.func
def ray_pair_midpoint(o1: wp.vec3, d1: wp.vec3, o2: wp.vec3, d2: wp.vec3):
    """Midpoint of the closest points of rays o1 + s d1 and o2 + t d2 (unit directions), and the gap between them.

    Returns ``vec4(x, y, z, gap)``, metres; gap = -1 when the rays are near parallel or a closest point lies
    behind its camera (s <= 0 or t <= 0).
    """
    w = o1 - o2
    b = wp.dot(d1, d2)
    d = wp.dot(d1, w)
    e = wp.dot(d2, w)
    den = 1.0 - b * b
    if den < 1.0e-6:
        return wp.vec4(0.0, 0.0, 0.0, -1.0)
    s = (b * e - d) / den
    t = (e - b * d) / den
    if s <= 0.0 or t <= 0.0:
        return wp.vec4(0.0, 0.0, 0.0, -1.0)
    p1 = o1 + s * d1
    p2 = o2 + t * d2
    mid = 0.5 * (p1 + p2)
    return wp.vec4(mid[0], mid[1], mid[2], wp.length(p1 - p2))


OUTSIDE_NATS = wp.constant(-1.6094379124341003)
"""log(1/5): what a camera that does not see a point adds to its mode-test score (:func:`mode_log_likelihood`)."""


@wp.func
def mode_log_likelihood(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    x: wp.vec3,
):
    """The score of a point in the mode test and the candidates' ranking: eqs. 5-7 except that a camera that does not
    see ``x`` (outside its image or behind it) adds ``OUTSIDE_NATS`` = log(1/5) instead of the paper's log(1/25).

    The paper's 1/25 outside the image makes a camera that cannot see a point vote against it as strongly as one
    that sees no target colour there, so a tracked ball that leaves one camera's view would lose the mode test to
    any spot where that camera sees a few look-alike pixels; half of that (in nats) still lets a point that more
    cameras agree on win. The particles' weights keep the paper's likelihood."""
    total = float(0.0)
    for c in range(cams.shape[0]):
        m = window_count(cams[c], target, bgr, integral, window, mode, x)
        if m < 0:
            total += OUTSIDE_NATS
        else:
            total += wp.log(float(wp.max(m, 1))) - LOG_WINDOW_AREA
    return total


MIX_THRESHOLD = wp.constant(0)
"""``mix[MIX_THRESHOLD]``: the frame's jump threshold on z_3 (Phi^-1 of the jump probability; -1e30: none)."""
MIX_EVIDENCE = wp.constant(1)
"""``mix[MIX_EVIDENCE]``: L_best - L_cloud this frame, nats (LOG_ZERO without a candidate)."""
MIX_JUMP = wp.constant(2)
"""``mix[MIX_JUMP]``: 1 when the frame jumps with probability eps (mode test fired or uniform frame), else 0."""
MIX_CUSUM = wp.constant(3)
"""``mix[MIX_CUSUM]``: the CUSUM S_t carried to the next frame, nats."""
MIX_SIZE = wp.constant(4)
NO_JUMP = wp.constant(-1.0e30)
"""A threshold no normal draw falls below (jump probability 0)."""


@wp.func
def jump_decision(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    det_pos: wp.array(dtype=wp.vec3),
    det_score: wp.array(dtype=wp.float32),
    est: wp.array(dtype=wp.float64),
    frame: wp.array(dtype=wp.int32),
    uniform_frame: wp.array(dtype=wp.int32),
    thresholds: wp.vec2,
    margin: float,
    evidence: float,
    near: float,
    det_cum: wp.array(dtype=wp.float32),
    det_count: wp.array(dtype=wp.int32),
    mix: wp.array(dtype=wp.float32),
):
    """The mode test (:func:`jump_decision_kernel`; also called by ``blobs.detect_tail_kernel``)."""
    count = int(0)
    for k in range(det_score.shape[0]):
        if det_score[k] > LOG_ZERO:
            count += 1
    det_count[0] = count
    best = det_score[0]
    total = float(0.0)
    for k in range(det_score.shape[0]):
        if k < count:
            total += wp.exp(det_score[k] - best)
        det_cum[k] = total
    for k in range(det_score.shape[0]):
        if total > 0.0:
            det_cum[k] = det_cum[k] / total
    f = frame[0]
    s = mix[MIX_CUSUM]
    jump = int(0)
    e = float(LOG_ZERO)
    if count > 0:
        mean = wp.vec3(float(est[EST_MEAN]), float(est[EST_MEAN + 1]), float(est[EST_MEAN + 2]))
        best_particle = wp.vec3(float(est[EST_MAP]), float(est[EST_MAP + 1]), float(est[EST_MAP + 2]))
        cloud = wp.max(
            mode_log_likelihood(cams, target, bgr, integral, window, mode, mean),
            mode_log_likelihood(cams, target, bgr, integral, window, mode, best_particle),
        )
        # candidates on the cloud are the cloud's own mode: within near + 2 |spread| of the mean or the MAP
        spread = wp.vec3(float(est[EST_STD]), float(est[EST_STD + 1]), float(est[EST_STD + 2]))
        r = near + 2.0 * wp.length(spread)
        for k in range(count):
            p = det_pos[k]
            if wp.length(p - mean) <= r or wp.length(p - best_particle) <= r:
                cloud = wp.max(cloud, det_score[k])
        e = best - cloud
        s = wp.max(0.0, s + e - margin)
        if s > evidence:
            jump = 1
            s = 0.0
    else:
        s = 0.0
    if f == uniform_frame[0]:
        jump = 1
        s = 0.0
    thr = thresholds[1]
    if jump == 1:
        thr = thresholds[0]
    if count == 0:
        thr = NO_JUMP
        jump = 0
    mix[MIX_THRESHOLD] = thr
    mix[MIX_EVIDENCE] = e
    mix[MIX_JUMP] = float(jump)
    mix[MIX_CUSUM] = s


@wp.kernel
def jump_decision_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    det_pos: wp.array(dtype=wp.vec3),
    det_score: wp.array(dtype=wp.float32),
    est: wp.array(dtype=wp.float64),
    frame: wp.array(dtype=wp.int32),
    uniform_frame: wp.array(dtype=wp.int32),
    thresholds: wp.vec2,
    margin: float,
    evidence: float,
    near: float,
    det_cum: wp.array(dtype=wp.float32),
    det_count: wp.array(dtype=wp.int32),
    mix: wp.array(dtype=wp.float32),
):
    """The mode test (module docstring), one thread. Reads the detection slots (score descending, ``LOG_ZERO`` =
    empty) and the previous frame's estimate ``est`` (MMSE mean, spread and MAP, ``kernels.core.reduce.EST_*``; after
    ``init_point`` the mean and MAP hold the initial point). The cloud's score is the best of its mean's, its MAP's
    and those of the candidates within ``near`` + 2 |spread| metres of either (the cloud's own mode: near an image
    border a slightly biased estimate can fall just inside a camera that no longer sees the object, while the
    object's candidate, outside it, scores higher). Writes ``det_count[0]`` (valid slots), ``det_cum`` (normalised
    cumulative component weights, exp(score - best)) and ``mix`` (``MIX_*``). ``thresholds`` = (Phi^-1(eps),
    Phi^-1(alpha)) with ``NO_JUMP`` for a probability 0."""
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


@wp.kernel
def set_anchor_kernel(point: wp.vec3, est: wp.array(dtype=wp.float64)):
    """Put ``point`` into the estimate's MMSE and MAP slots (the cloud the first mode test compares, after
    ``init_point``). One thread."""
    for k in range(3):
        est[EST_MEAN + k] = wp.float64(point[k])
        est[EST_MAP + k] = wp.float64(point[k])


@wp.func
def pick_component(det_cum: wp.array(dtype=wp.float32), count: int, u: float):
    """Index of the component whose cumulative-weight interval holds ``u`` in (0, 1) (the last valid one for u at
    the top)."""
    for k in range(count):
        if u < det_cum[k]:
            return k
    return count - 1


@wp.func
def jump_sample(
    parent: wp.vec3,
    z: wp.vec4,
    seed: wp.vec2ui,
    i: int,
    f: int,
    sigma: float,
    threshold: float,
    uniform: int,
    lo: wp.vec3,
    hi: wp.vec3,
    det_pos: wp.array(dtype=wp.vec3),
    det_cum: wp.array(dtype=wp.float32),
    count: int,
    sigma_d: float,
):
    """Draw x ~ p_t(x | parent) (module docstring): a jump to a detection component (z_3 < threshold; component by
    its weight, deviation ``sigma_d``), else the gaussian walk (``uniform`` = 1: a point uniform in [lo, hi]).
    ``z``: the particle's motion normals (``normal4``, stream ``STREAM_MOTION``); without a jump the walk is the paper's
    (``walk.gaussian_walk``) draw for draw."""
    if count > 0 and z[3] < threshold:
        u = uniform4(seed, i, f, STREAM_PROPOSAL_MIX)
        return det_pos[pick_component(det_cum, count, u[0])] + sigma_d * wp.vec3(z[0], z[1], z[2])
    if uniform != 0:
        b = uniform4(seed, i, f, STREAM_PROPOSAL_BOX)
        return wp.vec3(lo[0] + (hi[0] - lo[0]) * b[0], lo[1] + (hi[1] - lo[1]) * b[1], lo[2] + (hi[2] - lo[2]) * b[2])
    return parent + sigma * wp.vec3(z[0], z[1], z[2])


@wp.kernel
def colour_jump_predict_score_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    det_pos: wp.array(dtype=wp.vec3),
    det_cum: wp.array(dtype=wp.float32),
    det_count: wp.array(dtype=wp.int32),
    mix: wp.array(dtype=wp.float32),
    sigma_d: float,
    uniform_frame: wp.array(dtype=wp.int32),
    lo: wp.vec3,
    hi: wp.vec3,
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
    """The S1 iteration with detection jumps, fused as ``scoring.colour_predict_score_kernel``: x ~ p_t(x | parent)
    (:func:`jump_sample`), log w = log L(x) (eqs. 5-7) (+ the previous log-weight without resampling)."""
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    s = sigma[0]
    f = frame[0]
    keep = resampled[0] == 0
    kv = det_count[0]
    thr = mix[MIX_THRESHOLD]
    uni = int(0)
    if f == uniform_frame[0]:
        uni = 1
    best, arg, sw, sw2, sx, sxx = moments_zero()
    for i in range(start + lane, stop, wp.block_dim()):
        z = normal4(seed, i, f, STREAM_MOTION)
        x = jump_sample(particles[ancestors[i]], z, seed, i, f, s, thr, uni, lo, hi, det_pos, det_cum, kv, sigma_d)
        particles_out[i] = x
        lw = colour_log_likelihood(cams, target, bgr, integral, window, mode, x)
        if keep:
            lw += logw_prev[i]
        lw = finite_logw(lw)
        logw_out[i] = lw
        best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
    moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)


@functools.cache
def colour_jump_predict_score_map_kernel(count: int) -> wp.Kernel:
    """:func:`colour_jump_predict_score_kernel` specialised for the large-N case as
    ``scoring.colour_predict_score_map_kernel`` (``SCORE_MAP`` scoring, ``count`` cameras by value in a
    :class:`~kernels.core.camera.CameraSet`, compiled once per count; the same particles and log-weights as the general
    kernel in map mode). The third factory in ``kernels/``, for the same reason as that one: the mixture step must stay
    within 1.5x of the paper's step at 1e6 particles (issue 29)."""
    if not 1 <= count <= CAMERA_SET_SIZE:
        raise ValueError(f"camera count {count}: the camera-set kernel takes 1 to {CAMERA_SET_SIZE} cameras")

    set_loglik = camera_set_log_likelihood(count)

    @wp.kernel(enable_backward=False, module="unique", module_options={"fast_math": True})
    def colour_jump_predict_score_map_kernel(
        cams: CameraSet,
        window: wp.array(dtype=wp.uint8),
        det_pos: wp.array(dtype=wp.vec3),
        det_cum: wp.array(dtype=wp.float32),
        det_count: wp.array(dtype=wp.int32),
        mix: wp.array(dtype=wp.float32),
        sigma_d: float,
        uniform_frame: wp.array(dtype=wp.int32),
        lo: wp.vec3,
        hi: wp.vec3,
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
        kv = det_count[0]
        thr = mix[MIX_THRESHOLD]
        uni = int(0)
        if f == uniform_frame[0]:
            uni = 1
        best, arg, sw, sw2, sx, sxx = moments_zero()
        for i in range(start + lane, stop, wp.block_dim()):
            z = normal4(seed, i, f, STREAM_MOTION)
            x = jump_sample(particles[ancestors[i]], z, seed, i, f, s, thr, uni, lo, hi, det_pos, det_cum, kv, sigma_d)
            particles_out[i] = x
            lw = set_loglik(cams, window, x)  # eqs. 5-7, camera by camera as colour_log_likelihood
            if keep:
                lw += logw_prev[i]
            lw = finite_logw(lw)
            logw_out[i] = lw
            best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
        moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)

    return colour_jump_predict_score_map_kernel
