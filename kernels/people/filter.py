"""S2 people tracker (Lopez-Cifuentes et al.): particle dynamics and the motion observation model.

Map to the paper:
- :func:`constant_velocity`: eq. 5 with the frame interval dt made explicit, P_t = P_{t-1} + dt Pdot_{t-1} + n_P,
  Pdot_t = Pdot_{t-1} + n_V (velocity in metres per second; the paper's uniform frame rate makes its eq. 5 the
  case dt = 1 frame). n_t (6 x 1) has independent components, deviation ``sigma_pos`` on the position and
  ``sigma_vel`` on the velocity, per frame (the paper gives no covariance; the driver scales both with sqrt(dt)); the
  velocity noise has its own vertical deviation (ours: a person walks on the floor, but its points must keep mixing
  over the body's height).
  Noise: Philox streams ``(seed, particle, frame, STREAM_MOTION)`` for the position and ``STREAM_PEOPLE_VELOCITY``
  for the velocity.
- :func:`ray_jump` (ours, beyond the paper): a share of the particles moved along a camera's viewing ray each frame,
  so a filter can leave a multi-view ghost (docs/people.md).
- :func:`predict_kernel`: resampled gather + eq. 5 (+ :func:`ray_jump`) + the appearance update of eq. 6,
  C_t = alpha A_{t-1} + (1 - alpha) C_{t-1}, where A_{t-1} is the descriptor observed at P_{t-1}
  (``kernels.people.descriptor.descriptor_kernel``). A particle whose A_{t-1} was unseen (mass 0) keeps C_{t-1}.
- :func:`motion_log_likelihood`: eqs. 7-10, log p(M_t | x_t) = sum over cameras of
  log(1 - p_B) where the projection falls on a motion pixel, log(p_B) otherwise (eq. 9 as a sum of logs).
  A camera that does not see P (behind it, or the projection off the image) contributes ``log_outside``: pass
  log(p_B) to read "off the image" as "no motion observed" (eq. 10 literally: m(v) = 1 only for pixels of R), or 0
  for a neutral factor (the camera says nothing). The choice is the driver's.
- eq. 11, log p(z_t | x_t) = log p(M_t | x_t) + log p(A_t | x_t), inside :func:`step_kernel` and
  :func:`score_moments_kernel` (``tests/kernel_harness.py`` launches the single-factor kernels for the tests).
- :func:`step_kernel`: one frame fused (gather, eqs. 5-6, descriptor eqs. 19-22 at the new P_t, eq. 11, and the
  block partials of ``kernels.core.reduce``), so each particle's state is read once per frame.

State layout (struct-of-arrays, N particles): ``pos``, ``vel`` (N,) vec3; appearance C as a (N, 3 N_b) float32
array (H bins, S bins, V bins; each block sums to 1). At initialisation C_0 is the descriptor at P_0
(``descriptor_kernel`` into the model buffer). Several people: one particle set per person, each with its own
``seed`` word (e.g. ``wp.vec2ui(run_seed, person_id)``) so that their noise streams differ.
"""

import warp as wp

from wptrack.kernels.core.camera import Camera, pixel_index
from wptrack.kernels.core.random import (
    STREAM_INIT,
    STREAM_MOTION,
    STREAM_PEOPLE_JUMP,
    STREAM_PEOPLE_VELOCITY,
    normal4,
    uniform4,
)
from wptrack.kernels.core.reduce import finite_logw, moments_push, moments_store, moments_zero
from wptrack.kernels.people.coverage import PersonTerms, camera_centre, person_log_terms
from wptrack.kernels.people.descriptor import appearance_log_prob, descriptor_at

wp.set_module_options({"enable_backward": False})


@wp.func
def constant_velocity(
    pos: wp.vec3,
    vel: wp.vec3,
    dt: float,
    sigma_pos: float,
    sigma_vel: float,
    sigma_vel_z: float,
    seed: wp.vec2ui,
    index: int,
    frame: int,
):
    """Eq. 5: returns (P_t, Pdot_t) = (P + dt Pdot + n_P, Pdot + n_V); metres, metres per second, dt in seconds,
    ``sigma_pos`` (metres), ``sigma_vel`` (horizontal) and ``sigma_vel_z`` (vertical, metres per second) the
    deviations of this frame's noise."""
    zp = normal4(seed, index, frame, STREAM_MOTION)
    zv = normal4(seed, index, frame, STREAM_PEOPLE_VELOCITY)
    p = pos + dt * vel + sigma_pos * wp.vec3(zp[0], zp[1], zp[2])
    v = vel + wp.vec3(sigma_vel * zv[0], sigma_vel * zv[1], sigma_vel_z * zv[2])
    return p, v


@wp.func
def ray_jump(
    p: wp.vec3,
    cams: wp.array(dtype=Camera),
    share: float,
    span: float,
    others: wp.array(dtype=wp.vec2),
    alive: wp.array(dtype=wp.int32),
    own: int,
    clear: float,
    seed: wp.vec2ui,
    index: int,
    frame: int,
):
    """Ours, beyond the paper: with probability ``share`` move the particle at ``p`` along the ground direction of one
    camera's viewing ray through it (the camera drawn uniformly), by ``U(-span, span)`` metres, unless it would land
    within ``clear`` metres of another tracked person (``others[k]``, ``alive[k] != 0``, ``k != own``: a filter that
    jumped onto another body would follow it); otherwise return ``p``. One view fixes a person's position across its
    rays but not along them: a filter whose other view locked on someone else's silhouette (a multi-view ghost, 1-2 m
    off along the first camera's ray) is a local optimum its Gaussian walk does not leave, and these particles try the
    positions along the rays, where the weights (eq. 11 and the rectangle term) decide. Stream
    ``STREAM_PEOPLE_JUMP``; ``share`` per frame (0: no jump), ``span`` and ``clear`` metres."""
    if share <= 0.0 or span <= 0.0 or cams.shape[0] == 0:
        return p
    u = uniform4(seed, index, frame, STREAM_PEOPLE_JUMP)
    if u[0] >= share:
        return p
    c = wp.min(int(u[1] * float(cams.shape[0])), cams.shape[0] - 1)
    centre = camera_centre(cams[c])
    dx = p[0] - centre[0]
    dy = p[1] - centre[1]
    n = wp.sqrt(dx * dx + dy * dy)
    if n < 1.0e-6:
        return p
    s = span * (2.0 * u[2] - 1.0) / n
    q = wp.vec3(p[0] + s * dx, p[1] + s * dy, p[2])
    for k in range(others.shape[0]):  # never onto another tracked person: the filter would follow that body
        if k != own and alive[k] != 0:
            ex = q[0] - others[k][0]
            ey = q[1] - others[k][1]
            if ex * ex + ey * ey < clear * clear:
                return p
    return q


@wp.func
def appearance_update(
    model: wp.array2d(dtype=wp.float32),
    desc: wp.array2d(dtype=wp.float32),
    mass: wp.array(dtype=wp.float32),
    a: int,
    alpha: float,
    model_out: wp.array2d(dtype=wp.float32),
    i: int,
):
    """Eq. 6 for parent ``a`` into row ``i``: C_t = alpha A_{t-1} + (1 - alpha) C_{t-1} (C_{t-1} if A unseen)."""
    ncols = model.shape[1]
    if mass[a] > 0.0:
        for k in range(ncols):
            model_out[i, k] = alpha * desc[a, k] + (1.0 - alpha) * model[a, k]
    else:
        for k in range(ncols):
            model_out[i, k] = model[a, k]


@wp.kernel
def predict_kernel(
    pos: wp.array(dtype=wp.vec3),
    vel: wp.array(dtype=wp.vec3),
    model: wp.array2d(dtype=wp.float32),
    desc: wp.array2d(dtype=wp.float32),
    mass: wp.array(dtype=wp.float32),
    ancestors: wp.array(dtype=wp.int32),
    sigma_pos: wp.array(dtype=wp.float32),
    sigma_vel: wp.array(dtype=wp.float32),
    dt: wp.array(dtype=wp.float32),
    alpha: wp.array(dtype=wp.float32),
    observe: wp.array(dtype=wp.int32),
    decay: wp.array(dtype=wp.float32),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    jump_cams: wp.array(dtype=Camera),
    jump_share: float,
    jump_span: float,
    others: wp.array(dtype=wp.vec2),
    alive: wp.array(dtype=wp.int32),
    own: int,
    jump_clear: float,
    pos_out: wp.array(dtype=wp.vec3),
    vel_out: wp.array(dtype=wp.vec3),
    model_out: wp.array2d(dtype=wp.float32),
):
    """One prediction per particle: gather the parent ``a = ancestors[i]``, eq. 5 on (pos, vel), then
    :func:`ray_jump` (ours), and eq. 6 on the appearance: ``model_out[i] = alpha desc[a] + (1 - alpha) model[a]``
    (``model[a]`` unchanged when ``mass[a] == 0``).

    Args:
        pos, vel: (N,) P_{t-1} (metres), Pdot_{t-1} (metres/second). model: (N, 3 N_b) C_{t-1}.
        desc, mass: (N, 3 N_b), (N,) A_{t-1} and its mass from ``descriptor.descriptor_kernel`` at P_{t-1}.
        ancestors: (N,) resampled parents (identity without resampling). sigma_pos: [0], sigma_vel: [0] horizontal,
            [1] vertical: this frame's noise deviations (metres, metres/second). dt: [0] the frame interval, seconds.
            alpha: [0] this frame's forgetting factor of eq. 6. observe: [0] 0 when this frame's masks do not show the
            person, [1] the same for the previous frame (``coverage.gate_kernel``): with [0] = 0 the parent's
            velocity is first multiplied by decay[0] (ours: a person nobody sees is more likely to stand than to walk
            on); with [1] = 0 the appearance model is kept (A_{t-1} was read where the person was not seen). All are
            device arrays so that CUDA graphs see updates.
        seed: 64-bit run seed. frame: [0] frame number (the noise counter).
        jump_cams: the cameras whose rays :func:`ray_jump` moves particles along (any size: only their centres are
            read). jump_share: the share of particles that jump (0: none). jump_span: metres. others, alive: (P,)
            every slot's ground position and whether it tracks somebody; own: this person's slot; jump_clear: metres.
        pos_out, vel_out, model_out: the predicted state (must not alias the inputs).
    """
    i = wp.tid()
    a = ancestors[i]
    va = vel[a]
    if observe[0] == 0:
        va = va * decay[0]
    p, v = constant_velocity(pos[a], va, dt[0], sigma_pos[0], sigma_vel[0], sigma_vel[1], seed, i, frame[0])
    p = ray_jump(p, jump_cams, jump_share, jump_span, others, alive, own, jump_clear, seed, i, frame[0])
    pos_out[i] = p
    vel_out[i] = v
    appearance_update(model, desc, mass, a, wp.where(observe[1] != 0, alpha[0], 0.0), model_out, i)  # eq. 6


@wp.func
def motion_log_likelihood(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    p_b: float,
    log_outside: float,
    drop_worst: int,
    x: wp.vec3,
):
    """log p(M_t | x_t) (eqs. 9-10): per camera log(1 - p_B) if the pixel nearest to the projection of ``x`` is a
    motion pixel (mask != 0), log(p_B) if not, ``log_outside`` if the camera does not see ``x``.

    ``drop_worst`` = 1 (ours, beyond the paper) leaves out the least supporting camera's term when there are three or
    more cameras: a point of a person hidden by furniture in one camera (its projection falls on the static
    occluder, no motion) keeps the support of the others, so the particles fill the whole person rather than only
    what every camera sees. 0 is eq. 9 as printed (the product over all cameras).

    ``mask``: flat uint8 motion masks of all cameras (``Camera.pixel_offset``), one byte per pixel."""
    lin = wp.log(1.0 - p_b)
    lout = wp.log(p_b)
    total = float(0.0)
    worst = float(0.0)
    for c in range(cams.shape[0]):
        pix = pixel_index(cams[c], x)
        term = log_outside
        if pix >= 0:
            term = lout
            if mask[pix] != wp.uint8(0):
                term = lin
        total += term
        if c == 0 or term < worst:
            worst = term
    if drop_worst != 0 and cams.shape[0] >= 3:
        total -= worst
    return total


@wp.kernel
def step_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    p_b: float,
    log_outside: float,
    drop_worst: int,
    bgr: wp.array(dtype=wp.uint8),
    r_n: float,
    n_bins: int,
    r_min: float,
    r_max: float,
    step: int,
    pos: wp.array(dtype=wp.vec3),
    vel: wp.array(dtype=wp.vec3),
    model: wp.array2d(dtype=wp.float32),
    desc: wp.array2d(dtype=wp.float32),
    mass: wp.array(dtype=wp.float32),
    ancestors: wp.array(dtype=wp.int32),
    logw_prev: wp.array(dtype=wp.float32),
    resampled: wp.array(dtype=wp.int32),
    sigma_pos: wp.array(dtype=wp.float32),
    sigma_vel: wp.array(dtype=wp.float32),
    dt: wp.array(dtype=wp.float32),
    alpha: wp.array(dtype=wp.float32),
    observe: wp.array(dtype=wp.int32),
    decay: wp.array(dtype=wp.float32),
    sigma_n: wp.array(dtype=wp.float32),
    sigma_p: float,
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    box_cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    others: wp.array(dtype=wp.vec2),
    alive: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    terms: PersonTerms,
    n: int,
    chunk: int,
    jump_share: float,
    jump_span: float,
    jump_clear: float,
    pos_out: wp.array(dtype=wp.vec3),
    vel_out: wp.array(dtype=wp.vec3),
    model_out: wp.array2d(dtype=wp.float32),
    desc_out: wp.array2d(dtype=wp.float32),
    mass_out: wp.array(dtype=wp.float32),
    rgb_out: wp.array(dtype=wp.vec3),
    logw_out: wp.array(dtype=wp.float32),
    part_max: wp.array(dtype=wp.float32),
    part_arg: wp.array(dtype=wp.int32),
    part: wp.array2d(dtype=wp.float64),
):
    """One S2 frame for one target's particle set, fused: for particle i with parent a = ancestors[i]: eq. 5 on
    (pos, vel)[a], eq. 6 on (model, desc, mass)[a], the descriptor A_t = D(P_t) (eq. 22) into ``desc_out[i]``,
    log p(z_t | x_t) = motion + appearance (eq. 11) added to ``logw_prev[i]`` unless ``resampled[0]``, and the
    block's max / MAP / weighted sums (``reduce.moments_push``, outputs as ``reduce.moments_store``).

    Same arguments as :func:`predict_kernel` (its jumps along ``box_cams``' rays), :func:`motion_log_likelihood` and
    ``descriptor.descriptor_kernel``; every ``*_out`` is the other half of a ping-pong pair. Launch
    ``wp.launch_tiled(dim=[blocks], block_dim=B)``; block ``b`` owns particles ``[b chunk, (b+1) chunk)``. Same
    values as the separate kernels (tested).
    """
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    sp = sigma_pos[0]
    sv = sigma_vel[0]
    svz = sigma_vel[1]
    h = dt[0]
    al = wp.where(observe[1] != 0, alpha[0], 0.0)  # eq. 6, unless the person was not seen in the last frame
    seen = observe[0] != 0
    dv = decay[0]
    sn = sigma_n[0]
    f = frame[0]
    keep = resampled[0] == 0
    best, arg, sw, sw2, sx, sxx = moments_zero()
    for i in range(start + lane, stop, wp.block_dim()):
        a = ancestors[i]
        va = vel[a]
        if not seen:
            va = va * dv
        x, u = constant_velocity(pos[a], va, h, sp, sv, svz, seed, i, f)  # eq. 5
        x = ray_jump(x, box_cams, jump_share, jump_span, others, alive, own, jump_clear, seed, i, f)  # ours
        pos_out[i] = x
        vel_out[i] = u
        appearance_update(model, desc, mass, a, al, model_out, i)  # eq. 6
        m, rgb = descriptor_at(cams, bgr, x, r_n, n_bins, r_min, r_max, step, desc_out, i)  # eqs. 19-22
        mass_out[i] = m
        rgb_out[i] = rgb
        lw = float(0.0)
        if seen:
            lw = motion_log_likelihood(cams, mask, p_b, log_outside, drop_worst, x)  # eqs. 9-10
            lw += appearance_log_prob(model_out, i, desc_out, i, m, rgb, n_bins, sn, sigma_p)  # eqs. 23-26, eq. 11
            lw += person_log_terms(box_cams, integral, others, alive, boxes, own, terms, x)  # ours
        if keep:
            lw += logw_prev[i]
        lw = finite_logw(lw)  # -inf/NaN -> the floor, as the estimate and the resampler read it
        logw_out[i] = lw
        best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
    moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)


@wp.kernel
def init_cylinder_kernel(
    centre: wp.vec3,
    radius: float,
    z_lo: float,
    z_hi: float,
    speed: float,
    seed: wp.vec2ui,
    frame: int,
    pos: wp.array(dtype=wp.vec3),
    vel: wp.array(dtype=wp.vec3),
):
    """A new person's particles: uniform in the vertical cylinder of ``radius`` around ``centre`` (x, y) between
    heights ``z_lo`` and ``z_hi`` (metres), keyed by (seed, particle, frame, STREAM_MOTION); horizontal velocities
    normal with deviation ``speed`` per axis (metres per second; ours: a newcomer's walking direction is unknown, the
    weights pick it from the first frames), keyed by (seed, particle, frame, STREAM_INIT); no vertical velocity."""
    i = wp.tid()
    u = uniform4(seed, i, frame, STREAM_MOTION)
    r = radius * wp.sqrt(u[0])
    a = 6.283185307179586 * u[1]
    pos[i] = wp.vec3(centre[0] + r * wp.cos(a), centre[1] + r * wp.sin(a), z_lo + (z_hi - z_lo) * u[2])
    z = normal4(seed, i, frame, STREAM_INIT)
    vel[i] = wp.vec3(speed * z[0], speed * z[1], 0.0)


COLUMN_AXES = 9
"""Vertical axes tried per person by :func:`column_seen_kernel`: the estimate and the 8 around it."""


@wp.kernel
def column_seen_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    people: wp.array(dtype=wp.vec2),
    alive: wp.array(dtype=wp.int32),
    z_lo: float,
    dz: float,
    search: float,
    seen: wp.array3d(dtype=wp.uint8),
):
    """How many cameras see motion at each point of each person's silhouette columns (ours, for the
    standing-person centroid; :func:`column_top_kernel` walks the result).

    ``seen[i, a, k]`` = the number of cameras whose motion mask is set at the projection of the point at height
    ``z_lo + k * dz`` metres on axis ``a`` of person ``i``: axis 0..8 is the person's estimated ground position
    ``people[i]`` moved by ``search`` metres times ``(a // 3 - 1, a % 3 - 1)`` (the head is narrow and a walking
    person's estimate lags a little). Points behind a camera or outside its image count for nothing. A row with
    ``alive[i] == 0`` (a free slot of the tracker's pool) is zero, nothing projected. Launch dim ``(n,
    COLUMN_AXES, nz)``: one thread per point, so the mask reads of a column run in parallel."""
    i, a, k = wp.tid()
    if alive[i] == 0:
        seen[i, a, k] = wp.uint8(0)
        return
    axis = people[i] + search * wp.vec2(float(a // 3 - 1), float(a % 3 - 1))
    x = wp.vec3(axis[0], axis[1], z_lo + dz * float(k))
    n = int(0)
    for c in range(cams.shape[0]):
        pix = pixel_index(cams[c], x)
        if pix >= 0:
            if mask[pix] != wp.uint8(0):  # nested: Warp may evaluate both operands of `and`
                n += 1
    seen[i, a, k] = wp.uint8(n)


@wp.kernel
def column_top_kernel(
    seen: wp.array3d(dtype=wp.uint8),
    z_lo: float,
    dz: float,
    nz: int,
    min_cameras: int,
    max_gap: int,
    top: wp.array2d(dtype=wp.float32),
):
    """The top of each silhouette column of :func:`column_seen_kernel` (ours): walking up from ``z_lo``, the highest
    point seen moving by at least ``min_cameras`` cameras, in one run from the first such point with gaps of at
    most ``max_gap`` steps (holes in a mask; a hand raised apart from the body does not count). ``top[i, a]`` =
    that height of axis ``a`` of person ``i``, metres, or -1 when no point qualifies; a person's top is the highest
    over its axes (taken by the caller). Launch dim ``(n, COLUMN_AXES)``."""
    i, a = wp.tid()
    best = float(-1.0)
    started = int(0)
    gap = int(0)
    for k in range(nz):
        if int(seen[i, a, k]) >= min_cameras:
            best = z_lo + dz * float(k)
            started = 1
            gap = 0
        elif started == 1:
            gap += 1
            if gap > max_gap:
                break
    top[i, a] = best


@wp.kernel
def score_moments_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    p_b: float,
    log_outside: float,
    drop_worst: int,
    pos: wp.array(dtype=wp.vec3),
    model: wp.array2d(dtype=wp.float32),
    desc: wp.array2d(dtype=wp.float32),
    mass: wp.array(dtype=wp.float32),
    rgb: wp.array(dtype=wp.vec3),
    n_bins: int,
    logw_prev: wp.array(dtype=wp.float32),
    resampled: wp.array(dtype=wp.int32),
    sigma_n: wp.array(dtype=wp.float32),
    sigma_p: float,
    box_cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    others: wp.array(dtype=wp.vec2),
    alive: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    terms: PersonTerms,
    observe: wp.array(dtype=wp.int32),
    n: int,
    chunk: int,
    logw_out: wp.array(dtype=wp.float32),
    part_max: wp.array(dtype=wp.float32),
    part_arg: wp.array(dtype=wp.int32),
    part: wp.array2d(dtype=wp.float64),
):
    """The second half of :func:`step_kernel` for the GPU chain predict -> descriptor (one block per particle) ->
    this: log p(z_t | x_t) = motion + appearance (eq. 11) of the predicted particles ``pos`` with their appearance
    ``model`` and descriptor ``desc``/``mass``/``rgb``, added to ``logw_prev`` unless ``resampled[0]``, and the block
    partials (``reduce.moments_push``/``moments_store``). Launch like :func:`step_kernel`."""
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    sn = sigma_n[0]
    keep = resampled[0] == 0
    seen = observe[0] != 0
    best, arg, sw, sw2, sx, sxx = moments_zero()
    for i in range(start + lane, stop, wp.block_dim()):
        x = pos[i]
        lw = float(0.0)
        if seen:
            lw = motion_log_likelihood(cams, mask, p_b, log_outside, drop_worst, x)  # eqs. 9-10
            lw += appearance_log_prob(model, i, desc, i, mass[i], rgb[i], n_bins, sn, sigma_p)  # eqs. 23-26, eq. 11
            lw += person_log_terms(box_cams, integral, others, alive, boxes, own, terms, x)  # ours
        if keep:
            lw += logw_prev[i]
        lw = finite_logw(lw)  # -inf/NaN -> the floor, as the estimate and the resampler read it
        logw_out[i] = lw
        best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, lw, i, x)
    moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)


@wp.kernel
def person_xy_kernel(est: wp.array(dtype=wp.float64), mean_slot: int, j: int, people: wp.array(dtype=wp.vec2)):
    """``people[j]`` = the (x, y) of a filter's estimate vector (``est[mean_slot]``, ``est[mean_slot + 1]``, e.g.
    ``kernels.core.reduce.EST_MEAN``): the tracked people's ground positions for ``kernels.people.coverage`` and
    :func:`column_top_kernel` without a round trip through the host. Launch dim 1."""
    people[j] = wp.vec2(wp.float32(est[mean_slot]), wp.float32(est[mean_slot + 1]))
