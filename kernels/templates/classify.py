"""Class-aware object addition of the S3 template tracker (beyond Juza et al., section 4.2).

Eq. 11 proposes the candidate that removes the most Uncovered Object Histogram. Where a vehicle is only partly
explained (entering the image, turning, passing behind a person, or a vehicle hypothesis lagging behind its car),
the uncovered part of the car is human-sized and a human candidate wins; once humans cover the car, its UOH is low
and no vehicle candidate is proposed again. The class-aware addition asks, whenever eq. 11 picks a human, whether a
vehicle fits the motion image there: among the vehicle candidates whose ground point lies within ``radius`` of the
human's, the one whose silhouette is the largest fraction of foreground,

    fit(c) = |q AND c| / |c|      (pixels / pixels, coverage by the particles ignored)

replaces the human when fit(c) >= ``min_fit``. A person's blob fills a vehicle template only in part (the template
is wider and longer than a person), a car's blob fills it, so the fit is a size/shape test of the blob. The
prediction (``dynamics.template_predict_kernel``, ``absorb``) then removes, in the particles that receive the
vehicle, the humans standing on its footprint: the replacement of several humans covering a car by one vehicle is
proposed as one move, and the weights (eq. 6) decide between the particles that took it and those that did not.
"""

import warp as wp

from wptrack.kernels.templates.raster import KIND_HUMAN, KIND_VEHICLE
from wptrack.kernels.templates.slots import SE_DIMS, SE_EXIST, SE_HEADING, SE_X
from wptrack.kernels.templates.uoh import candidate_sum
from wptrack.kernels.templates.xor import pair_overlap

wp.set_module_options({"enable_backward": False})

NEG_INF = wp.constant(-3.0e38)


@wp.kernel
def vehicle_fit_kernel(
    hull_rows: wp.array2d(dtype=wp.vec2i),
    hull_n: wp.array2d(dtype=wp.int32),
    offsets: wp.array(dtype=wp.int32),
    spans: wp.array(dtype=wp.vec2i),
    cand_pixels: wp.array(dtype=wp.int32),
    pieces: int,
    cand_kind: wp.array(dtype=wp.int32),
    cand_pos: wp.array(dtype=wp.vec2),
    cand_heading: wp.array(dtype=wp.float32),
    best: wp.array(dtype=wp.int32),
    qrow: wp.array2d(dtype=wp.int32),
    radius: float,
    min_area: int,
    dims: wp.vec3,
    slot_est: wp.array2d(dtype=wp.float64),
    slot_kind: wp.array(dtype=wp.int32),
    min_existence: float,
    fit: wp.array(dtype=wp.float32),
):
    """Foreground fraction of the vehicle candidates near the chosen human candidate (module docstring).

    Launch with ``wp.launch_tiled(dim=[C], block_dim=B)``: block ``c`` is candidate ``c``; its lanes stride over
    the rows of its pieces (``uoh.candidate_sum``; one lane on the CPU backend) and ``tile_sum`` combines them.

    Args:
        hull_rows, hull_n, offsets, spans, pieces: the candidates' rows, piece counts and spans.
        cand_pixels: (C,) pixels of each candidate's silhouette (``uoh.candidate_spans_kernel``).
        cand_kind, cand_pos, cand_heading: (C,) kind, ground position (metres) and heading (radians) of each
            candidate.
        best: (1,) the candidate eq. 11 chose (``reduce.final_max_kernel``; < 0: none).
        qrow: (H, W+1) row prefix sums of the motion mask (``xor.mask_rows_kernel``).
        radius: vehicle candidates farther than this from the chosen candidate's ground point are skipped, metres.
        min_area: candidates with fewer pixels are skipped.
        dims: (length, width, height) of the vehicle candidates, metres (the prior's mean).
        slot_est, slot_kind, min_existence: the last estimate per slot (``slots.final_slot_moments_kernel``, (R,
            NE)) and kind (R,): candidates whose footprint meets a reported vehicle's (existence >= min_existence,
            ``xor.pair_overlap`` > 0) are skipped, so a tracked car does not get a second vehicle.
        fit: (C,) ``|q AND c| / |c|`` for a vehicle candidate within ``radius`` of a chosen human, else -3e38.
    """
    c, lane = wp.tid()
    b = best[0]
    eligible = False
    if b >= 0 and b < cand_kind.shape[0]:
        if cand_kind[b] == KIND_HUMAN and cand_kind[c] == KIND_VEHICLE:
            eligible = wp.length(cand_pos[c] - cand_pos[b]) <= radius
    if eligible:
        for e in range(slot_kind.shape[0]):
            if slot_kind[e] == KIND_VEHICLE and slot_est[e, SE_EXIST] >= wp.float64(min_existence):
                sp = wp.vec2(float(slot_est[e, SE_X]), float(slot_est[e, SE_X + 1]))
                sd = wp.vec3(
                    float(slot_est[e, SE_DIMS]), float(slot_est[e, SE_DIMS + 1]), float(slot_est[e, SE_DIMS + 2])
                )
                sh = float(slot_est[e, SE_HEADING])
                if pair_overlap(KIND_VEHICLE, cand_pos[c], cand_heading[c], dims, KIND_VEHICLE, sp, sh, sd) > 0.0:
                    eligible = False
    fg = int(0)
    if eligible:  # uniform over the block: every lane reaches the tile sum below either way
        fg = candidate_sum(hull_rows, hull_n, offsets, spans, pieces, c, lane, qrow, int(0))
    ft = wp.tile_sum(wp.tile(fg))
    if lane == 0:
        px = cand_pixels[c]
        if eligible and px >= min_area and px > 0:
            fit[c] = float(ft[0]) / float(px)
        else:
            fit[c] = NEG_INF
