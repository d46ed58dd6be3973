"""Detection-driven mixture proposal for the S1 colour filter (issue 12: beyond the paper's prior-only proposal).

The paper (Barrera et al., 2005, conclusions) samples new particles only from the motion prior (eqs. 1-3), so it
never converges from random initialisation and cannot re-acquire a lost object. Here particle i is drawn from

    q(x | x_parent) = (1 - eps) p(x | x_parent) + eps d(x)

(mixture Monte Carlo localisation: Thrun, Fox, Burgard and Dellaert, "Robust Monte Carlo localization for mobile
robots", Artificial Intelligence 128, 2001; sensor resetting: Lenser and Veloso, ICRA 2000) with the importance
weight of sequential importance sampling on the path space, evaluated per particle against its own parent:

    w = L(x) p(x | x_parent) / q(x | x_parent)

so the filter stays a valid particle filter for the motion model p. The motion model is the paper's gaussian walk
with a small "kidnap" (reset) probability alpha of jumping uniformly into the working volume V:

    p(x | x_parent) = (1 - alpha) N(x; x_parent, sigma_m^2 I) + alpha U_V(x)

(alpha = 1 on the first frame after a uniform initialisation: the prior is then U_V itself). Without the alpha term
a point proposed 1 m from every parent would have prior density ~0 and could never be kept: re-acquisition after a
loss needs a model that admits it. eps = 0 and alpha = 0 give back the paper's filter exactly.

d(x) is a gaussian mixture of K components of deviation sigma_d, built once per frame from the colour masks:
component k picks a camera a (and a second camera b != a), samples one target-coloured pixel in each uniformly by
rejection on the HSI colour table (no compaction, no per-frame allocation), back-projects both pixels to rays and
takes the midpoint of their closest points when the rays pass within ``max_gap``; when camera b shows no target
pixel (or the rig has one camera) the centre is drawn along ray a at a depth uniform in [depth_lo, depth_hi].
Components whose camera a shows no target pixel are invalid; with no valid component the frame has no detection
and eps = 0 is used.
"""

import warp as wp

from wptrack.kernels.colour.hsi import ColourTarget, pixel_matches
from wptrack.kernels.colour.scoring import colour_log_likelihood
from wptrack.kernels.colour.walk import STREAM_MOTION
from wptrack.kernels.core.camera import Camera
from wptrack.kernels.core.random import normal4, philox4x32, uniform4, word_to_unit
from wptrack.kernels.core.reduce import moments_push, moments_store, moments_zero

wp.set_module_options({"enable_backward": False})

STREAM_PROPOSAL_PIXELS = wp.constant(12)  # rejection sampling of target pixels, counter (component, frame, 12, try)
STREAM_PROPOSAL_MIX = wp.constant(13)  # per particle: mixture branch, component, reset draws
STREAM_PROPOSAL_BOX = wp.constant(14)  # per particle: uniform position in the working volume
LOG_ZERO = wp.constant(-1.0e30)  # log of a zero density (finite: sums stay finite in float32)
LOG_2PI_3_2 = wp.constant(2.756815599614018)  # 1.5 log(2 pi)
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


@wp.kernel
def ray_pair_kernel(
    cams: wp.array(dtype=Camera),
    cam_a: wp.array(dtype=wp.int32),
    cam_b: wp.array(dtype=wp.int32),
    uv_a: wp.array(dtype=wp.vec2),
    uv_b: wp.array(dtype=wp.vec2),
    out: wp.array(dtype=wp.vec4),
):
    """Triangulate pixel pairs (tests): ``out[i]`` = :func:`ray_pair_midpoint` of the rays through ``uv_a[i]`` in
    camera ``cam_a[i]`` and ``uv_b[i]`` in camera ``cam_b[i]``."""
    i = wp.tid()
    ca = cams[cam_a[i]]
    cb = cams[cam_b[i]]
    out[i] = ray_pair_midpoint(
        camera_centre(ca),
        pixel_ray_direction(ca, uv_a[i][0], uv_a[i][1]),
        camera_centre(cb),
        pixel_ray_direction(cb, uv_b[i][0], uv_b[i][1]),
    )


@wp.kernel
def detection_components_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    tries: int,
    max_gap: float,
    depth_lo: float,
    depth_hi: float,
    centres: wp.array(dtype=wp.vec3),
    valid: wp.array(dtype=wp.int32),
):
    """Centres of the detection mixture d(x), one thread per component k (K,): see the module docstring.

    ``valid[k]``: 1 = two-camera triangulation, 2 = point along one ray, 0 = no target pixel found in camera a
    (after ``tries`` uniform draws: rejection sampling, uniform over the target pixels when it succeeds).
    """
    k = wp.tid()
    f = frame[0]
    m = cams.shape[0]
    w0 = philox4x32(wp.uint32(k), wp.uint32(f), wp.uint32(STREAM_PROPOSAL_PIXELS), wp.uint32(0), seed[0], seed[1])
    a = int(w0[0] % wp.uint32(m))
    b = a
    if m > 1:
        b = (a + 1 + int(w0[1] % wp.uint32(m - 1))) % m
    ca = cams[a]
    cb = cams[b]
    na = ca.width * ca.height
    nb = cb.width * cb.height
    pa = int(-1)
    pb = int(-1)
    for t in range(tries):
        if pa < 0 or (pb < 0 and m > 1):
            w = philox4x32(
                wp.uint32(k), wp.uint32(f), wp.uint32(STREAM_PROPOSAL_PIXELS), wp.uint32(t + 1), seed[0], seed[1]
            )
            if pa < 0:
                q = int(w[0] % wp.uint32(na))
                if pixel_matches(target, bgr, ca.pixel_offset + q) != 0:
                    pa = q
            if pb < 0 and m > 1:
                q = int(w[1] % wp.uint32(nb))
                if pixel_matches(target, bgr, cb.pixel_offset + q) != 0:
                    pb = q
    valid[k] = 0
    centres[k] = wp.vec3(0.0, 0.0, 0.0)
    if pa < 0:
        return
    oa = camera_centre(ca)
    da = pixel_ray_direction(ca, float(pa % ca.width), float(pa // ca.width))
    if pb >= 0:
        ob = camera_centre(cb)
        db = pixel_ray_direction(cb, float(pb % cb.width), float(pb // cb.width))
        mid = ray_pair_midpoint(oa, da, ob, db)
        if mid[3] >= 0.0 and mid[3] <= max_gap:
            centres[k] = wp.vec3(mid[0], mid[1], mid[2])
            valid[k] = 1
            return
    # one camera sees the object (or the pair's rays miss each other): a point along ray a
    depth = depth_lo + (depth_hi - depth_lo) * word_to_unit(w0[2])
    centres[k] = oa + depth * da
    valid[k] = 2


@wp.kernel
def detection_count_kernel(valid: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32)):
    """``count[0]`` = number of valid components (one thread; K is small). 0 means 'no detection' this frame."""
    c = int(0)
    for k in range(valid.shape[0]):
        if valid[k] != 0:
            c += 1
    count[0] = c


@wp.func
def log_detection_density(
    centres: wp.array(dtype=wp.vec3), valid: wp.array(dtype=wp.int32), count: int, sigma_d: float, x: wp.vec3
):
    """log d(x) = log (1/K_valid) sum_k N(x; c_k, sigma_d^2 I) over the valid components (LOG_ZERO if none)."""
    if count == 0:
        return LOG_ZERO
    inv = 1.0 / (2.0 * sigma_d * sigma_d)
    # two passes (max, then sum of exp relative to it): K exp and one log per particle
    m = float(LOG_ZERO)
    for k in range(centres.shape[0]):
        if valid[k] != 0:
            r = x - centres[k]
            m = wp.max(m, -wp.dot(r, r) * inv)
    acc = float(0.0)
    for k in range(centres.shape[0]):
        if valid[k] != 0:
            r = x - centres[k]
            acc += wp.exp(-wp.dot(r, r) * inv - m)
    return m + wp.log(acc) - 3.0 * wp.log(sigma_d) - LOG_2PI_3_2 - wp.log(float(count))


@wp.func
def log_motion_density(x: wp.vec3, parent: wp.vec3, sigma: float, alpha: float, lo: wp.vec3, hi: wp.vec3):
    """log p(x | parent) = log((1 - alpha) N(x; parent, sigma^2 I) + alpha U_V(x)), V = box [lo, hi]."""
    lu = float(LOG_ZERO)
    inside = x[0] >= lo[0] and x[1] >= lo[1] and x[2] >= lo[2] and x[0] <= hi[0] and x[1] <= hi[1] and x[2] <= hi[2]
    if alpha > 0.0 and inside:
        vol = (hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2])
        lu = wp.log(alpha) - wp.log(vol)
    if alpha >= 1.0:
        return lu
    r = x - parent
    ln = -wp.dot(r, r) / (2.0 * sigma * sigma) - 3.0 * wp.log(sigma) - LOG_2PI_3_2
    return log_add(wp.log(1.0 - alpha) + ln, lu)


@wp.func
def pick_valid(valid: wp.array(dtype=wp.int32), count: int, u: float):
    """Index of the j-th valid component, j = floor(u count) (uniform over the valid components)."""
    j = wp.min(int(u * float(count)), count - 1)
    for k in range(valid.shape[0]):
        if valid[k] != 0:
            if j == 0:
                return k
            j -= 1
    return 0


@wp.func
def mixture_sample(
    parent: wp.vec3,
    z: wp.vec4,
    seed: wp.vec2ui,
    i: int,
    f: int,
    sigma: float,
    alpha: float,
    eps: float,
    lo: wp.vec3,
    hi: wp.vec3,
    centres: wp.array(dtype=wp.vec3),
    valid: wp.array(dtype=wp.int32),
    count: int,
    sigma_d: float,
):
    """Draw x ~ q(x | parent) and return ``vec4(x, log p(x | parent) - log q(x | parent))``.

    ``z``: the particle's 4 normal draws (the motion stream, reused by whichever branch is taken).
    """
    u = uniform4(seed, i, f, STREAM_PROPOSAL_MIX)
    e = eps
    if count == 0:
        e = 0.0
    x = wp.vec3()
    if u[0] < e:
        c = centres[pick_valid(valid, count, u[1])]
        x = c + sigma_d * wp.vec3(z[0], z[1], z[2])
    elif u[2] < alpha:
        b = uniform4(seed, i, f, STREAM_PROPOSAL_BOX)
        x = wp.vec3(lo[0] + (hi[0] - lo[0]) * b[0], lo[1] + (hi[1] - lo[1]) * b[1], lo[2] + (hi[2] - lo[2]) * b[2])
    else:
        x = parent + sigma * wp.vec3(z[0], z[1], z[2])
    lp = log_motion_density(x, parent, sigma, alpha, lo, hi)
    lq = lp
    if e > 0.0:
        lq = log_add(wp.log(1.0 - e) + lp, wp.log(e) + log_detection_density(centres, valid, count, sigma_d, x))
    return wp.vec4(x[0], x[1], x[2], lp - lq)


@wp.kernel
def mixture_sample_kernel(
    parents: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec4),
    seed: wp.vec2ui,
    frame: int,
    sigma: float,
    alpha: float,
    eps: float,
    lo: wp.vec3,
    hi: wp.vec3,
    centres: wp.array(dtype=wp.vec3),
    valid: wp.array(dtype=wp.int32),
    count: int,
    sigma_d: float,
    out: wp.array(dtype=wp.vec4),
):
    """:func:`mixture_sample` per point (tests): ``out[i] = (x, log p - log q)``."""
    i = wp.tid()
    out[i] = mixture_sample(
        parents[i], normals[i], seed, i, frame, sigma, alpha, eps, lo, hi, centres, valid, count, sigma_d
    )


@wp.kernel
def log_densities_kernel(
    points: wp.array(dtype=wp.vec3),
    parents: wp.array(dtype=wp.vec3),
    sigma: float,
    alpha: float,
    lo: wp.vec3,
    hi: wp.vec3,
    centres: wp.array(dtype=wp.vec3),
    valid: wp.array(dtype=wp.int32),
    count: int,
    sigma_d: float,
    out: wp.array2d(dtype=wp.float32),
):
    """Tests: ``out[i] = (log p(x_i | parent_i), log d(x_i))``, (N, 2)."""
    i = wp.tid()
    out[i, 0] = log_motion_density(points[i], parents[i], sigma, alpha, lo, hi)
    out[i, 1] = log_detection_density(centres, valid, count, sigma_d, points[i])


@wp.kernel
def colour_mixture_predict_score_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    centres: wp.array(dtype=wp.vec3),
    valid: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
    sigma_d: float,
    eps: float,
    alpha: float,
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
    """The S1 iteration with the mixture proposal, fused as ``scoring.colour_predict_score_kernel``:
    x ~ q(x | parent), log w = log L(x) (eqs. 5-7) + log p(x | parent) - log q(x | parent) (+ previous log-weight
    without resampling). ``alpha`` is replaced by 1 on frame ``uniform_frame[0]`` (first frame after a uniform
    initialisation)."""
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    s = sigma[0]
    f = frame[0]
    keep = resampled[0] == 0
    kv = count[0]
    al = alpha
    if f == uniform_frame[0]:
        al = 1.0
    best, arg, sw, sw2, sx, sxx = moments_zero()
    for i in range(start + lane, stop, wp.block_dim()):
        z = normal4(seed, i, f, STREAM_MOTION)
        r = mixture_sample(particles[ancestors[i]], z, seed, i, f, s, al, eps, lo, hi, centres, valid, kv, sigma_d)
        x = wp.vec3(r[0], r[1], r[2])
        particles_out[i] = x
        lw = colour_log_likelihood(cams, target, bgr, integral, window, mode, x) + r[3]
        if keep:
            lw += logw_prev[i]
        logw_out[i] = lw
        best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
    moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)
