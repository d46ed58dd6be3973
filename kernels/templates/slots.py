"""Per-object estimates of the S3 template tracker from the weighted particle set, without single-address
atomics (same block pattern as ``kernels.core.reduce``).

Every slot holds one persistent label across all particles (``uoh.choose_addition_kernel``), so the estimate of
object s is a weighted moment over the particles whose slot s is alive: existence probability
``sum_i w_i alive_is / sum_i w_i``, weighted means of ground position, speed, heading, dims and age. The weights
are the particles' (eq. 6) in the paper's joint filter, and the factor of the slot's group
(``kernels.templates.partition``, ``xor.group_logw_kernel``) in the partitioned filter: the marginal posterior of the
group's objects.
"""

import warp as wp

from wptrack.kernels.core.reduce import EST_MAXLOGW, NEG_INF, block_argmax, block_sum17, vec17d
from wptrack.kernels.core.resample import block_scan_int64
from wptrack.kernels.templates.dynamics import TemplateState
from wptrack.kernels.templates.raster import KIND_NONE, KIND_VEHICLE

wp.set_module_options({"enable_backward": False})

NS = wp.constant(17)
"""Per-block sums per slot: w, w^2, w a, a, w a x, w a y, w a x^2, w a y^2, w a speed, w a cos(dir), w a sin(dir),
w a dims (3), w a age (a = slot alive; w the slot's weight), then W, W^2 with the particle's joint weight W (eq. 6;
W = w in the joint filter)."""

# Columns of the per-slot estimate (float64, shape (R, NE)).
SE_EXIST = wp.constant(0)  # existence probability
SE_COUNT = wp.constant(1)  # particles holding the object
SE_X = wp.constant(2)  # weighted mean ground position x, y (metres)
SE_STD = wp.constant(4)  # weighted standard deviation of x, y (metres)
SE_SPEED = wp.constant(6)  # weighted mean speed (m/s)
SE_HEADING = wp.constant(7)  # direction of motion / orientation (radians, circular mean)
SE_DIMS = wp.constant(8)  # weighted mean dims (3, metres)
SE_AGE = wp.constant(11)  # weighted mean age (s)
SE_ESS = wp.constant(12)  # effective sample size of the joint weights (same in every row)
SE_LOGLIK = wp.constant(13)  # log of the mean joint weight (same in every row)
SE_GROUP_ESS = wp.constant(14)  # effective sample size of the slot's own weights (its group's; = SE_ESS when joint)
NE = wp.constant(16)


@wp.kernel
def block_slot_moments_kernel(
    state: TemplateState,
    n: int,
    chunk: int,
    est: wp.array(dtype=wp.float64),
    glogw: wp.array2d(dtype=wp.float32),
    part_gmax: wp.array2d(dtype=wp.float32),
    gblocks: int,
    slot_group: wp.array(dtype=wp.int32),
    group_first: wp.array(dtype=wp.int32),
    partition: int,
    scale: wp.float64,
    weights: wp.array2d(dtype=wp.float64),
    part: wp.array3d(dtype=wp.float64),
    part_q: wp.array2d(dtype=wp.int64),
):
    """Normalised weights and per-block sums of every slot; launch with ``wp.launch_tiled(dim=[blocks, R],
    block_dim=B)``; part (blocks, R, NS).

    Joint filter (``partition`` 0): the weights are ``W_i = exp(logw_i - max)`` (``est[EST_MAXLOGW]``), written to
    ``weights[0]`` by slot 0's blocks for the resampling. Partitioned filter: slot ``s`` of group ``g =
    slot_group[s]`` weighs particle ``i`` by its group factor ``exp(glogw[g, i] - max_g)`` (the maximum from the
    ``gblocks`` per-block maxima ``part_gmax[:, g]``), written to ``weights[g]`` by the blocks of the group's lowest
    slot (``group_first[g]``); a slot no particle holds (``g`` = -1) uses the joint weights and writes none. The
    blocks that write row ``g`` also write ``part_q[b, g]``, the block's sum of the integer weights ``floor(w_i
    scale)`` of ``kernels.core.resample.grouped_systematic_kernel`` (its per-block offsets; partitioned filter only).
    """
    b, s, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    mx = est[EST_MAXLOGW]
    g = int(-1)
    gm = wp.float64(0.0)
    row = int(-1)  # the weights row this slot's blocks write
    if partition == 0:
        if s == 0:
            row = 0
    else:
        g = slot_group[s]
        if g >= 0:  # uniform over the block: every lane reaches the reduction or none does
            best = float(NEG_INF)
            for j in range(lane, gblocks, wp.block_dim()):
                best = wp.max(best, part_gmax[j, g])
            m, _arg = block_argmax(best, 0)
            gm = wp.float64(m)
            if group_first[g] == s:
                row = g
    acc = vec17d()
    qsum = wp.int64(0)
    for i in range(start + lane, stop, wp.block_dim()):
        wj = wp.exp(wp.float64(state.logw[i]) - mx)
        w = wj
        if g >= 0:
            w = wp.exp(wp.float64(glogw[g, i]) - gm)
        if row >= 0:
            weights[row, i] = w
            qsum += wp.int64(wp.floor(w * scale))
        acc[0] += w
        acc[1] += w * w
        acc[15] += wj
        acc[16] += wj * wj
        k = state.kind[i, s]
        if k != KIND_NONE:
            p = state.pos[i, s]
            v = state.vel[i, s]
            d = state.dims[i, s]
            direction = state.heading[i, s]
            speed = wp.length(v)
            if k == KIND_VEHICLE:
                speed = wp.abs(v[0])
                if v[0] < 0.0:
                    direction = direction + wp.pi
            x = wp.float64(p[0])
            y = wp.float64(p[1])
            acc[2] += w
            acc[3] += wp.float64(1.0)
            acc[4] += w * x
            acc[5] += w * y
            acc[6] += w * x * x
            acc[7] += w * y * y
            acc[8] += w * wp.float64(speed)
            acc[9] += w * wp.float64(wp.cos(direction))
            acc[10] += w * wp.float64(wp.sin(direction))
            acc[11] += w * wp.float64(d[0])
            acc[12] += w * wp.float64(d[1])
            acc[13] += w * wp.float64(d[2])
            acc[14] += w * wp.float64(state.age[i, s])
    if g >= 0 and row >= 0:  # uniform over the block
        qt = block_scan_int64(qsum, lane, wp.block_dim())[1]
        if lane == 0:
            part_q[b, row] = qt
    t = block_sum17(acc)  # the block's sums, in lane 0
    if lane == 0:
        for f in range(NS):
            part[b, s, f] = t[f]


@wp.kernel
def final_slot_moments_kernel(
    part: wp.array3d(dtype=wp.float64),
    blocks: int,
    n: int,
    est: wp.array(dtype=wp.float64),
    ess_threshold: wp.array(dtype=wp.float32),
    state: TemplateState,
    best: wp.array(dtype=wp.int32),
    penalty: wp.array(dtype=wp.int32),
    slot_est: wp.array2d(dtype=wp.float64),
    slot_count: wp.array(dtype=wp.float64),
    resample: wp.array(dtype=wp.int32),
    best_state: wp.array2d(dtype=wp.float32),
):
    """Combine the per-block sums (launch ``wp.launch_tiled(dim=[R], block_dim=B)``, one block per slot) into
    ``slot_est`` (R, NE) and ``slot_count`` (R,); slot 0 also decides resampling (joint ESS <= threshold x N). Block
    ``s`` also copies slot ``s`` of the best particle ``best[0]`` into ``best_state`` (R, 11; :func:`copy_slot`)."""
    s, lane = wp.tid()
    acc = vec17d()
    for j in range(lane, blocks, wp.block_dim()):
        for f in range(NS):
            acc[f] += part[j, s, f]
    tot = block_sum17(acc)  # valid in lane 0, the only reader
    if lane == 0:
        copy_slot(state, best[0], s, penalty, best_state)
        zero = wp.float64(0.0)
        sw = tot[0]
        wa = tot[2]
        slot_est[s, SE_EXIST] = wa / sw
        slot_est[s, SE_COUNT] = tot[3]
        slot_count[s] = tot[3]
        if wa > zero:
            mx = tot[4] / wa
            my = tot[5] / wa
            slot_est[s, SE_X] = mx
            slot_est[s, SE_X + 1] = my
            slot_est[s, SE_STD] = wp.sqrt(wp.max(tot[6] / wa - mx * mx, zero))
            slot_est[s, SE_STD + 1] = wp.sqrt(wp.max(tot[7] / wa - my * my, zero))
            slot_est[s, SE_SPEED] = tot[8] / wa
            slot_est[s, SE_HEADING] = wp.atan2(tot[10], tot[9])
            slot_est[s, SE_DIMS] = tot[11] / wa
            slot_est[s, SE_DIMS + 1] = tot[12] / wa
            slot_est[s, SE_DIMS + 2] = tot[13] / wa
            slot_est[s, SE_AGE] = tot[14] / wa
        else:
            for f in range(SE_X, SE_ESS):
                slot_est[s, f] = zero
        slot_est[s, SE_GROUP_ESS] = sw * sw / tot[1]
        ess = tot[15] * tot[15] / tot[16]
        slot_est[s, SE_ESS] = ess
        slot_est[s, SE_LOGLIK] = est[EST_MAXLOGW] + wp.log(tot[15] / wp.float64(n))
        if s == 0:
            flag = int(0)
            if ess <= wp.float64(ess_threshold[0]) * wp.float64(n) + wp.float64(1.0e-9):
                flag = 1
            resample[0] = flag


@wp.func
def copy_slot(
    state: TemplateState,
    i: int,
    s: int,
    penalty: wp.array(dtype=wp.int32),
    out: wp.array2d(dtype=wp.float32),
):
    """Copy slot ``s`` of particle ``i`` into ``out[s]`` (R, 11): kind, label, x, y, heading, vel (2), dims (3),
    penalty m (pixels, every row)."""
    out[s, 0] = float(state.kind[i, s])
    out[s, 1] = float(state.label[i, s])
    p = state.pos[i, s]
    v = state.vel[i, s]
    d = state.dims[i, s]
    out[s, 2] = p[0]
    out[s, 3] = p[1]
    out[s, 4] = state.heading[i, s]
    out[s, 5] = v[0]
    out[s, 6] = v[1]
    out[s, 7] = d[0]
    out[s, 8] = d[1]
    out[s, 9] = d[2]
    out[s, 10] = float(penalty[i])
