"""Particle state and prediction of the S3 template tracker (Juza et al., sections 2.5, 3 and 4.2-4.3).

Each particle is a whole scene: R slots, each empty or holding one object (struct-of-arrays, shape (N, R)).
Prediction per slot: gather from the resampled parent, stochastic diffusion (deletion, eq. 13; addition of the
frame's chosen candidates, eq. 12; then noise) and deterministic drift (human eq. 8, vehicle eq. 9; a cyclist, beyond
the paper, moves as a vehicle with its own prior and limits).

Random numbers come from counter-based streams keyed by ``(particle * SLOT_KEY + slot % SLOT_KEY, frame, STREAM_*,
slot / SLOT_KEY)`` (the last in the Philox counter's fourth word): reproducible on every device and under CUDA graph
replay, and the streams of slots below 16 are those of R_max <= 16 before issue 26 (same runs bit for bit).
"""

import warp as wp

from wptrack.kernels.core.random import (
    STREAM_TEMPLATE_ADD,
    STREAM_TEMPLATE_EVENT,
    STREAM_TEMPLATE_INIT,
    STREAM_TEMPLATE_INIT2,
    STREAM_TEMPLATE_NOISE,
    STREAM_TEMPLATE_NOISE2,
    normal4_at,
    uniform4_at,
)
from wptrack.kernels.templates.exclusion import disc_in_box
from wptrack.kernels.templates.raster import KIND_CYCLIST, KIND_HUMAN, KIND_NONE, KIND_VEHICLE, PIECES

wp.set_module_options({"enable_backward": False})


SLOT_KEY = wp.constant(16)
"""Slots per particle in the index of the random streams (the former ``MAX_SLOTS``): slot ``s`` of particle ``j``
draws from index ``j SLOT_KEY + s % SLOT_KEY`` and counter word ``s / SLOT_KEY``."""


@wp.struct
class TemplateState:
    """Particle state (N particles x R slots); one of two ping-pong buffers.

    Per-slot fields, shape (N, R):
        kind: KIND_NONE (empty slot), KIND_HUMAN or KIND_VEHICLE.
        label: persistent object label (the same object keeps it through resampling).
        pos: ground position (x, y) on the plane, metres.
        vel: human: velocity (vx, vy) m/s; vehicle: (speed v m/s, angular velocity theta rad/s).
        heading: vehicle orientation alpha (radians); human: direction of motion (for output only).
        dims: human (height, body radius, head radius); vehicle (length, width, height); metres.
        age: tau of eq. 5, seconds the object has been in the particle.
    Per particle, shape (N,):
        logw: log-weight (0 after resampling; eq. 6 added by the scoring kernel).
    """

    kind: wp.array2d(dtype=wp.int32)
    label: wp.array2d(dtype=wp.int32)
    pos: wp.array2d(dtype=wp.vec2)
    vel: wp.array2d(dtype=wp.vec2)
    heading: wp.array2d(dtype=wp.float32)
    dims: wp.array2d(dtype=wp.vec3)
    age: wp.array2d(dtype=wp.float32)
    logw: wp.array(dtype=wp.float32)


@wp.struct
class Dynamics:
    """Motion model and diffusion parameters (per-kind vectors are indexed by KIND_*; index 0 unused).

    All deviations are per frame; units metres, seconds, radians.
    """

    dt: float  # frame period, s
    sigma_pos: float  # position diffusion (added to eqs. 8-9), m
    sigma_speed: wp.vec4  # sigma_v by kind: human velocity components / vehicle and cyclist speed, m/s
    sigma_turn: float  # sigma_theta: vehicle and cyclist angular velocity, rad/s
    sigma_dims_human: wp.vec3  # sigma_d of the human dims, m
    sigma_dims_vehicle: wp.vec3  # sigma_d of the vehicle dims, m
    sigma_dims_cyclist: wp.vec3  # sigma_d of the cyclist dims, m
    dims_mean_human: wp.vec3  # prior mean of an added human, m
    dims_mean_vehicle: wp.vec3
    dims_mean_cyclist: wp.vec3
    dims_sd_human: wp.vec3  # prior deviation of an added human's dims, m
    dims_sd_vehicle: wp.vec3
    dims_sd_cyclist: wp.vec3
    dims_min_human: wp.vec3  # dims are clamped to [min, max], m
    dims_max_human: wp.vec3
    dims_min_vehicle: wp.vec3
    dims_max_vehicle: wp.vec3
    dims_min_cyclist: wp.vec3
    dims_max_cyclist: wp.vec3
    init_speed_sd: wp.vec4  # initial velocity deviation of an added object by kind, m/s
    init_heading_sd: float  # initial heading deviation of an added vehicle or cyclist, rad
    speed_max: wp.vec4  # |velocity| (human) / |speed| (vehicle, cyclist) limit by kind, m/s
    speed_min: wp.vec4  # |speed| floor of the box kinds (the cyclist's; beyond the paper; 0: none), m/s
    turn_max: float  # |theta| limit, rad/s
    t_add: float  # T_add of eq. 12
    t_del: float  # T_del of eq. 13
    occlusion_del: float  # share of T_del an object's occlusion removes (beyond the paper; 0: eq. 13), in [0, 1]
    dims_revert: float  # per-frame pull of the dims towards the prior mean (beyond the paper; 0: eqs. 8-9)
    absorb: (
        int  # 1: an added vehicle removes the humans on its footprint (beyond the paper; kernels.templates.classify)
    )
    occlusion_noise: float  # share of the velocity/position noise its occlusion removes (0: eqs. 8-9), in [0, 1]
    unseen_del: float  # deletion probability of an object none of whose pieces is in the image (0: eq. 13)


@wp.func
def clamp3(v: wp.vec3, lo: wp.vec3, hi: wp.vec3):
    return wp.vec3(wp.clamp(v[0], lo[0], hi[0]), wp.clamp(v[1], lo[1], hi[1]), wp.clamp(v[2], lo[2], hi[2]))


@wp.func
def box_prior(dyn: Dynamics, k: int):
    """``(mean, sd, min, max, sigma_d)`` of the dims of a box kind: the cyclist's for ``KIND_CYCLIST``, else the
    vehicle's (metres)."""
    if k == KIND_CYCLIST:
        return (dyn.dims_mean_cyclist, dyn.dims_sd_cyclist, dyn.dims_min_cyclist, dyn.dims_max_cyclist,
                dyn.sigma_dims_cyclist)  # fmt: skip
    return (
        dyn.dims_mean_vehicle,
        dyn.dims_sd_vehicle,
        dyn.dims_min_vehicle,
        dyn.dims_max_vehicle,
        dyn.sigma_dims_vehicle,
    )


@wp.func
def add_draw(seed: wp.vec2ui, j: int, f: int, r: int):
    """The U(0, 1) draw of particle ``j`` for the frame's addition ``r`` (eq. 12: added when below T_add): component
    ``r % 4`` of the particle's ``STREAM_TEMPLATE_ADD`` block with counter word ``r / 4`` (addition 0: the draw of the
    paper's single addition, as before)."""
    return uniform4_at(seed, j, f, STREAM_TEMPLATE_ADD, r / 4)[r % 4]


@wp.kernel
def template_predict_kernel(
    dyn: Dynamics,
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    ancestors: wp.array2d(dtype=wp.int32),
    slot_group: wp.array(dtype=wp.int32),
    resampled: wp.array(dtype=wp.int32),
    add: wp.array(dtype=wp.int32),
    slot_label: wp.array(dtype=wp.int32),
    cand_kind: wp.array(dtype=wp.int32),
    cand_pos: wp.array(dtype=wp.vec2),
    cand_heading: wp.array(dtype=wp.float32),
    occlusion: wp.array2d(dtype=wp.float32),
    hull_n: wp.array2d(dtype=wp.int32),
    src: TemplateState,
    dst: TemplateState,
):
    """One prediction step (section 2.5); launch with ``dim=(N, R)``.

    Args:
        dyn: motion model parameters.
        seed: the run's 64-bit seed; frame: (1,) filter iteration (keys the random streams).
        ancestors: (G, N) parents per group of slots (identity when not resampled): slot ``s`` of particle ``j``
            is gathered from particle ``ancestors[max(slot_group[s], 0), j]``. The paper's joint filter has one
            row and ``slot_group`` zeros; the partitioned filter (``kernels.templates.partition``) a row per independent
            group. A slot of group -1 is empty in every particle (any parent will do: row 0).
        slot_group: (R,) group of each slot. resampled: (1,) 1 when the weights restart from 0.
        add: (2K,) this frame's K additions ``(slot, candidate)`` or ``slot = -1`` (``uoh.choose_addition_kernel``,
            ``uoh.choose_more_additions_kernel``; K = 1: eq. 12); each is added to a particle with its own draw
            (:func:`add_draw`). With ``dyn.absorb``, a vehicle added to a particle removes the particle's humans
            whose ground disc meets the candidate's footprint (a box of the prior's mean length and width; beyond
            the paper).
        slot_label: (R,) label of each slot. cand_kind, cand_pos, cand_heading: (C,) candidate objects.
        occlusion: (N, R) fraction of each object hidden by nearer objects of its particle, read at the parent
            (``occlusion.occlusion_kernel``; zeros: the paper's prediction). Beyond the paper: an object hidden a
            fraction ``o`` is deleted with probability ``T_del (1 - occlusion_del o)`` and diffused with
            ``(1 - occlusion_noise o)`` times the velocity, turn and position deviations: a hidden object gets no
            evidence (eq. 6), so it keeps its motion and is not removed for free while it is hidden.
        hull_n: (N, R * PIECES) the parents' piece hulls' vertex counts (``raster.template_hulls_kernel`` on the
            state just scored; 0: the piece misses the image). Beyond the paper: an object none of whose pieces is
            in the image (it has left the view) is deleted with probability ``dyn.unseen_del``; under eq. 13 alone
            it stayed, invisible and unverifiable, for 1 / T_del frames on average.
        src: state read at the parents. dst: predicted state written for particle j.
    """
    j, s = wp.tid()
    a = ancestors[wp.max(slot_group[s], 0), j]
    f = frame[0]
    idx = j * SLOT_KEY + s % SLOT_KEY
    word = s / SLOT_KEY
    if s == 0:
        if resampled[0] != 0:
            dst.logw[j] = 0.0
        else:
            dst.logw[j] = src.logw[a]
    k = src.kind[a, s]
    rounds = add.shape[0] / 2  # the frame's additions (beyond the paper: TemplateConfig.additions; eq. 12: one)
    mine = int(-1)  # the addition that targets this slot
    for r in range(rounds):
        if add[2 * r] == s:
            mine = r
    if k == KIND_NONE and mine < 0:
        # a slot empty at the parent and not added to stays empty (most of R_max): the else branch below, without
        # the draws it does not use
        dst.kind[j, s] = KIND_NONE
        dst.label[j, s] = -1
        dst.pos[j, s] = wp.vec2(0.0, 0.0)
        dst.vel[j, s] = wp.vec2(0.0, 0.0)
        dst.heading[j, s] = 0.0
        dst.dims[j, s] = src.dims[a, s]
        dst.age[j, s] = 0.0
        return
    label = src.label[a, s]
    p = src.pos[a, s]
    v = src.vel[a, s]
    alpha = src.heading[a, s]
    d = src.dims[a, s]
    age = src.age[a, s]
    occ = occlusion[a, s]
    # stochastic diffusion: deletion (eq. 13, T_del lowered for hidden objects), then addition (eq. 12)
    u = uniform4_at(seed, idx, f, STREAM_TEMPLATE_EVENT, word)
    if k != KIND_NONE and u[0] < dyn.t_del * (1.0 - dyn.occlusion_del * occ):
        k = KIND_NONE
    if k != KIND_NONE and dyn.unseen_del > 0.0:
        seen = False
        for piece in range(PIECES):
            if hull_n[a, s * PIECES + piece] > 0:
                seen = True
        if not seen and u[1] < dyn.unseen_del:
            k = KIND_NONE
    if k == KIND_HUMAN and dyn.absorb != 0:
        # beyond the paper (kernels.templates.classify): a vehicle added to this particle (the same draw as the
        # addition below, keyed by the particle) replaces the humans standing on its footprint, in one move
        for r in range(rounds):
            if add[2 * r] >= 0 and k == KIND_HUMAN:
                cv = add[2 * r + 1]
                add_parent = ancestors[wp.max(slot_group[add[2 * r]], 0), j]  # the parent of the receiving slot
                if cand_kind[cv] == KIND_VEHICLE and src.kind[add_parent, add[2 * r]] == KIND_NONE:
                    if add_draw(seed, j, f, r) < dyn.t_add:
                        half = 0.5 * wp.vec2(dyn.dims_mean_vehicle[0], dyn.dims_mean_vehicle[1])
                        if disc_in_box(p, d[1], cand_pos[cv], cand_heading[cv], half) > 0.0:
                            k = KIND_NONE
    if k == KIND_NONE and mine >= 0:
        if add_draw(seed, j, f, mine) < dyn.t_add:
            c = add[2 * mine + 1]
            k = cand_kind[c]
            label = slot_label[s]
            p = cand_pos[c]
            alpha = cand_heading[c]
            age = 0.0
            z = normal4_at(seed, idx, f, STREAM_TEMPLATE_INIT, word)
            if k == KIND_HUMAN:
                d = dyn.dims_mean_human + wp.cw_mul(dyn.dims_sd_human, wp.vec3(z[0], z[1], z[2]))
                d = clamp3(d, dyn.dims_min_human, dyn.dims_max_human)
                z2 = normal4_at(seed, idx, f, STREAM_TEMPLATE_INIT2, word)
                v = dyn.init_speed_sd[KIND_HUMAN] * wp.vec2(z2[0], z2[1])
                alpha = 0.0
            else:  # a vehicle or a cyclist (beyond the paper: a box kind of its own prior)
                mean, sd, lo, hi, _sig = box_prior(dyn, k)
                d = clamp3(mean + wp.cw_mul(sd, wp.vec3(z[0], z[1], z[2])), lo, hi)
                z2 = normal4_at(seed, idx, f, STREAM_TEMPLATE_INIT2, word)
                v = wp.vec2(dyn.init_speed_sd[k] * z2[0], 0.0)
                alpha = alpha + dyn.init_heading_sd * z[3]
    if k != KIND_NONE:
        n1 = normal4_at(seed, idx, f, STREAM_TEMPLATE_NOISE, word)
        n2 = normal4_at(seed, idx, f, STREAM_TEMPLATE_NOISE2, word)
        # beyond the paper: a hidden object keeps its motion (no evidence to correct a diffused velocity); an object
        # added this frame is not hidden in its parent (its slot was empty there: occ = 0)
        ns = 1.0 - dyn.occlusion_noise * occ
        sig_pos = dyn.sigma_pos * ns
        if k == KIND_HUMAN:
            # eq. 8: d_t = d + N(0, sd^2); v_t = v + N(0, sv^2); l_t = l + v_t dt (+ the pull to the prior mean)
            d = clamp3(
                d
                + dyn.dims_revert * (dyn.dims_mean_human - d)
                + wp.cw_mul(dyn.sigma_dims_human, wp.vec3(n1[0], n1[1], n1[2])),
                dyn.dims_min_human,
                dyn.dims_max_human,
            )
            v = v + ns * dyn.sigma_speed[KIND_HUMAN] * wp.vec2(n1[3], n2[0])
            sp = wp.length(v)
            vmax = dyn.speed_max[KIND_HUMAN]
            if sp > vmax:
                v = v * (vmax / sp)
            p = p + v * dyn.dt + sig_pos * wp.vec2(n2[1], n2[2])
            if sp > 0.2:
                alpha = wp.atan2(v[1], v[0])
        else:
            # eq. 9 (vehicles; cyclists too, with their own prior and limits): theta_t = theta + N;
            #        alpha_t = alpha + theta_{t-1} dt; v_t = v + N; l_t = l + v_{t-1} dt (cos alpha_t, sin alpha_t)
            mean, _sd, lo, hi, sig = box_prior(dyn, k)
            d = clamp3(d + dyn.dims_revert * (mean - d) + wp.cw_mul(sig, wp.vec3(n1[0], n1[1], n1[2])), lo, hi)
            speed = v[0]
            turn = v[1]
            alpha = alpha + turn * dyn.dt
            p = p + speed * dyn.dt * wp.vec2(wp.cos(alpha), wp.sin(alpha)) + sig_pos * wp.vec2(n2[1], n2[2])
            vmax = dyn.speed_max[k]
            speed = wp.clamp(speed + ns * dyn.sigma_speed[k] * n1[3], -vmax, vmax)
            vmin = dyn.speed_min[k]  # beyond the paper: a cyclist is never slower than this (0: no floor)
            if wp.abs(speed) < vmin:
                speed = wp.where(speed < 0.0, -vmin, vmin)
            v = wp.vec2(speed, wp.clamp(turn + ns * dyn.sigma_turn * n2[0], -dyn.turn_max, dyn.turn_max))
        age = age + dyn.dt
    else:
        label = -1
        p = wp.vec2(0.0, 0.0)
        v = wp.vec2(0.0, 0.0)
        alpha = 0.0
        age = 0.0
    dst.kind[j, s] = k
    dst.label[j, s] = label
    dst.pos[j, s] = p
    dst.vel[j, s] = v
    dst.heading[j, s] = alpha
    dst.dims[j, s] = d
    dst.age[j, s] = age
