"""Addition of objects in the S3 template tracker (Juza et al., section 4.3, eqs. 10-12): the addition candidates
(a ground grid under the image, their templates projected once), the frame's UOH image and candidate gains (eq. 11)
and their argmax, the class-aware replacement of a chosen human by a vehicle and the further additions on disjoint
pixels (beyond the paper), and the choice of the slots the additions go to (eq. 12's o_new). The device driver that
runs these launches in its frame chain is :mod:`wptrack.trackers.templates.tracker`."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from wptrack.cameras.rig import Camera, GroundPlane
from wptrack.core.errors import RigError
from wptrack.core.filter import BLOCK, MAX_BLOCKS
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.templates import classify as kcls
from wptrack.kernels.templates import raster as kraster
from wptrack.kernels.templates import slots as kslots
from wptrack.kernels.templates import uoh as kuoh
from wptrack.trackers.templates.config import TemplateConfig
from wptrack.trackers.templates.launches import ROW_BLOCK, Hulls, launch_argmax

if TYPE_CHECKING:
    from wptrack.trackers.templates.tracker import TemplateTracker

CANDIDATE_BLOCK = 32
"""Threads per addition candidate in the candidate scoring kernel (they stride over the candidate's rows)."""


def ground_rays(camera: Camera, plane: GroundPlane, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Intersect the viewing rays of ``pixels`` (K, 2) with the ground plane (distortion included).

    Returns:
        ``(ground, distance)``: (K, 2) ground coordinates (metres) and (K,) distance from the camera centre along
        the ray (metres; ``inf`` where the ray misses the plane or hits it behind the camera).
    """
    rays = camera.pixel_rays(pixels)
    centre = camera.center
    denom = rays @ plane.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = ((plane.origin - centre) @ plane.normal) / denom
    ok = np.isfinite(lam) & (lam > 0) & (np.abs(denom) > 1e-9)
    dist = np.where(ok, lam, np.inf)
    points = centre + np.where(ok, lam, 0.0)[:, None] * rays
    return plane.to_ground(points), dist


class Candidates:
    """The fixed set of addition candidates (eq. 11): ground points under an image grid x class x orientation,
    at the prior's mean size, with their image spans precomputed on the device."""

    @staticmethod
    def _grid(
        camera: Camera,
        plane: GroundPlane,
        step: int,
        margin: int,
        max_range: float,
        width_frac: float = 0.0,
        body_width: float = 0.44,
    ) -> np.ndarray:
        """(K, 2) ground points (metres) under the pixel grid of pitch ``step`` over the image widened by ``margin``
        pixels left, right and below (the rays of pixels beyond the border: objects entering the view), within
        ``max_range`` of the camera.

        With ``width_frac`` > 0 the pitch of each row of the grid is ``width_frac`` x the image width of a person
        standing there (``body_width`` metres at the distance of the ground under the row's middle pixel), between 2
        pixels and ``step``: far people a few pixels wide get a candidate every pixel or two across them."""
        if width_frac <= 0.0:
            us = np.arange(step / 2.0 - margin, camera.width + margin, step)
            vs = np.arange(step / 2.0, camera.height + margin, step)
            grid = np.stack(np.meshgrid(us, vs), axis=-1).reshape(-1, 2)
        else:
            fx = float(np.asarray(camera.K)[0, 0])
            pts = []
            v = 0.0
            while v < camera.height + margin:
                _, dist = ground_rays(camera, plane, np.array([[0.5 * camera.width, v + 0.5]]))
                pitch = float(step)
                if np.isfinite(dist[0]) and dist[0] > 0:
                    pitch = float(np.clip(round(width_frac * body_width * fx / dist[0]), 2.0, step))
                row = v + 0.5 * pitch
                us = np.arange(pitch / 2.0 - margin, camera.width + margin, pitch)
                pts.append(np.stack([us, np.full_like(us, row)], axis=-1))
                v += pitch
            grid = np.concatenate(pts)
        ground, dist = ground_rays(camera, plane, grid)
        return ground[dist <= max_range]

    def __init__(
        self,
        camera: Camera,
        plane: GroundPlane,
        cam_struct,
        plane_struct,
        config: TemplateConfig,
        device,
        source: str = "<memory>",
    ):
        step = int(config.candidate_step_px)
        frac = float(config.candidate_step_width)
        body = 2.0 * float(config.human.dims_mean[1])
        ground = self._grid(camera, plane, step, 0, config.max_range, frac, body)
        if len(ground) == 0:
            where = "" if source == "<memory>" else f"{source}: "  # the rig file, as the rig's own errors say
            raise RigError(
                f"{where}camera '{camera.name}' does not see the ground plane (origin {plane.origin.tolist()}, normal "
                f"{plane.normal.tolist()}) within {config.max_range} m: no image pixel's ray meets it in front of "
                "the camera; check the rig's pose and its 'ground' entry"
            )
        grids = {0: ground}  # by margin beyond the border, pixels (the two classes' margins are often equal)
        for margin in {int(config.human_entry_px), int(config.vehicle_entry_px)} - {0}:
            grids[margin] = self._grid(camera, plane, step, margin, config.max_range, frac, body)
        ground_h, ground_v = grids[int(config.human_entry_px)], grids[int(config.vehicle_entry_px)]
        kinds, pos, heading, dims = [], [], [], []
        if "human" in config.classes:
            kinds.append(np.full(len(ground_h), int(kraster.KIND_HUMAN)))
            pos.append(ground_h)
            heading.append(np.zeros(len(ground_h)))
            dims.append(np.tile(config.human.dims_mean, (len(ground_h), 1)))
        if "vehicle" in config.classes:
            for k in range(config.vehicle.orientations):
                kinds.append(np.full(len(ground_v), int(kraster.KIND_VEHICLE)))
                pos.append(ground_v)
                heading.append(np.full(len(ground_v), math.pi * k / config.vehicle.orientations))
                dims.append(np.tile(config.vehicle.dims_mean, (len(ground_v), 1)))
        if "cyclist" in config.classes:  # beyond the paper: a rider and a bike, entering as people do
            for k in range(config.cyclist.orientations):
                kinds.append(np.full(len(ground_h), int(kraster.KIND_CYCLIST)))
                pos.append(ground_h)
                heading.append(np.full(len(ground_h), math.pi * k / config.cyclist.orientations))
                dims.append(np.tile(config.cyclist.dims_mean, (len(ground_h), 1)))
        self.kind_np = np.concatenate(kinds).astype(np.int32)
        self.pos_np = np.concatenate(pos).astype(np.float32)
        self.heading_np = np.concatenate(heading).astype(np.float32)
        dims_np = np.concatenate(dims).astype(np.float32)
        c = len(self.kind_np)
        self.count = c
        d = device
        kind2 = wp.array(self.kind_np.reshape(c, 1), dtype=wp.int32, device=d)
        pos2 = wp.array(self.pos_np.reshape(c, 1, 2), dtype=wp.vec2, device=d)
        head2 = wp.array(self.heading_np.reshape(c, 1), dtype=wp.float32, device=d)
        dims2 = wp.array(dims_np.reshape(c, 1, 3), dtype=wp.vec3, device=d)
        self.hulls = Hulls(c, 1, d)
        self.hulls.launch(cam_struct, plane_struct, kind2, pos2, head2, dims2, d)
        rows = self.hulls.rows.numpy()
        nverts = self.hulls.n.numpy()
        lengths = np.where(nverts > 0, rows[..., 1] - rows[..., 0] + 1, 0).sum(axis=1)
        offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int32)
        self.offsets = wp.array(offsets, dtype=wp.int32, device=d)
        self.spans = wp.zeros(max(int(lengths.sum()), 1), dtype=wp.vec2i, device=d)
        self.box = wp.zeros(c, dtype=wp.vec4i, device=d)
        self.pixels = wp.zeros(c, dtype=wp.int32, device=d)
        wp.launch(
            kuoh.candidate_spans_kernel,
            dim=c,
            inputs=[self.hulls.pts, self.hulls.n, self.hulls.rows, self.offsets, int(kraster.PIECES), camera.width],
            outputs=[self.spans, self.box, self.pixels],
            device=d,
        )
        self.kind = wp.array(self.kind_np, dtype=wp.int32, device=d)
        self.pos = wp.array(self.pos_np, dtype=wp.vec2, device=d)
        self.heading = wp.array(self.heading_np, dtype=wp.float32, device=d)
        # beyond the paper (TemplateConfig.add_cost): what each candidate's object costs a particle at its addition
        # (eq. 5 at age 0: a_r + b_r of its class, pixels at this image's size), 0 when off
        area_scale = camera.width * camera.height / config.reference_area if config.reference_area > 0 else 1.0
        priors = {int(kraster.KIND_HUMAN): config.human, int(kraster.KIND_VEHICLE): config.vehicle,
                  int(kraster.KIND_CYCLIST): config.cyclist}  # fmt: skip
        cost_np = np.zeros(c, dtype=np.float32)
        for kind, prior in priors.items():
            cost_np[self.kind_np == kind] = config.add_cost * (prior.cost_a + prior.cost_b) * area_scale
        self.cost = wp.array(cost_np, dtype=wp.float32, device=d)
        self.score = wp.zeros(c, dtype=wp.float32, device=d)
        self.area = wp.zeros(c, dtype=wp.int32, device=d)
        self.blocks = min((c + BLOCK - 1) // BLOCK, MAX_BLOCKS)
        self.chunk = (c + self.blocks - 1) // self.blocks
        self.part_max = wp.zeros(self.blocks, dtype=wp.float32, device=d)
        self.part_arg = wp.zeros(self.blocks, dtype=wp.int32, device=d)
        # one argmax per addition of the frame (TemplateConfig.additions): rows of est_k and entries of best_k;
        # round 0's are est and best (the paper's single addition, eq. 11)
        rounds = int(config.additions)
        self.est_k = wp.zeros((rounds, int(kreduce.EST_SIZE)), dtype=wp.float64, device=d)
        self.best_k = wp.zeros(rounds, dtype=wp.int32, device=d)
        self.est = self.est_k[0]
        self.best = self.best_k[0:1]
        self.round_est = [self.est_k[k] for k in range(rounds)]
        self.round_best = [self.best_k[k : k + 1] for k in range(rounds)]
        # class-aware addition (kernels.templates.classify): vehicle fits near a chosen human and their argmax
        self.fit = wp.zeros(c, dtype=wp.float32, device=d)
        self.fit_max = wp.zeros(self.blocks, dtype=wp.float32, device=d)
        self.fit_arg = wp.zeros(self.blocks, dtype=wp.int32, device=d)
        self.fit_est = wp.zeros(int(kreduce.EST_SIZE), dtype=wp.float64, device=d)
        self.fit_best = wp.zeros(1, dtype=wp.int32, device=d)
        self.bytes = int(lengths.sum()) * 8 + c * (int(kraster.PIECES) * (int(kraster.HULL_MAX) * 8 + 16) + 56)


def score_candidates(t: TemplateTracker) -> None:
    """The frame's UOH (eq. 10) and candidate gains (eq. 11), their argmax, the class-aware vehicle fit near the
    chosen human and, with ``TemplateConfig.additions`` > 1, the further rounds' argmaxes (device launches only)."""
    d = t.device
    c = t.candidates
    cfg = t.config
    wp.launch_tiled(
        kuoh.coverage_uoh_kernel,
        dim=[t.height],
        inputs=[t.q, t.n, float(cfg.add_beta)],
        outputs=[t.cov_diff, t.uoh, t.gain_rows, t.a_sat],
        block_dim=ROW_BLOCK,
        device=d,
    )
    cols = 1 if t.is_cuda else t.width + 1  # a block per column; one pass in memory order on the CPU
    wp.launch_tiled(
        kuoh.uoh_box_sums_kernel,
        dim=[(t.width + cols) // cols],
        inputs=[cols, t.a_sat],
        block_dim=ROW_BLOCK,
        device=d,
    )
    wp.launch_tiled(
        kuoh.candidate_score_kernel,
        dim=[c.count],
        inputs=[
            c.hulls.rows,
            c.hulls.n,
            c.offsets,
            c.spans,
            c.box,
            c.pixels,
            int(kraster.PIECES),
            t.gain_rows,
            t.a_sat,
            t.n,
            float(cfg.add_beta),
            float(cfg.add_min_gain),
            t.min_area,
            c.cost,
        ],
        outputs=[c.score, c.area],
        block_dim=CANDIDATE_BLOCK,
        device=d,
    )
    launch_argmax(c.score, c.count, c.blocks, c.chunk, c.part_max, c.part_arg, c.est, c.best, d)
    if t.min_fit < math.inf:
        # beyond the paper: a vehicle that fits the blob replaces a chosen human (kernels.templates.classify; the
        # replacement itself is made by uoh.choose_addition_kernel)
        wp.launch_tiled(
            kcls.vehicle_fit_kernel,
            dim=[c.count],
            inputs=[
                c.hulls.rows,
                c.hulls.n,
                c.offsets,
                c.spans,
                c.pixels,
                int(kraster.PIECES),
                c.kind,
                c.pos,
                c.heading,
                c.best,
                t.qrow,
                0.5 * float(cfg.vehicle.dims_mean[0]),
                t.min_area,
                wp.vec3(*cfg.vehicle.dims_mean),
                t.slot_est,
                t.slot_kind,
                float(cfg.min_existence),
            ],
            outputs=[c.fit],
            block_dim=CANDIDATE_BLOCK,
            device=d,
        )
        launch_argmax(c.fit, c.count, c.blocks, c.chunk, c.fit_max, c.fit_arg, c.fit_est, c.fit_best, d)
    # beyond the paper: more additions on other pixels (TemplateConfig.additions): the candidates sharing pixels
    # with the last round's choice are suppressed, and the next argmax picks among the rest
    for k in range(1, len(c.round_best)):
        min_fit = t.min_fit if k == 1 else math.inf  # round 0's choice after the class-aware replacement
        wp.launch(
            kuoh.suppress_candidates_kernel,
            dim=c.count,
            inputs=[c.round_best[k - 1], c.round_est[k - 1], int(kreduce.EST_MAXLOGW), c.fit_best, c.fit_est,
                    min_fit, c.box],
            outputs=[c.score],
            device=d,
        )  # fmt: skip
        launch_argmax(c.score, c.count, c.blocks, c.chunk, c.part_max, c.part_arg, c.round_est[k], c.round_best[k], d)


def choose_additions(t: TemplateTracker) -> None:
    """The slots of the frame's additions (eq. 12's o_new, ``kuoh.choose_addition_kernel``; the further additions of
    ``TemplateConfig.additions``), with ``slot_margin`` the free slots the additions may hold (device launches)."""
    d = t.device
    c = t.candidates
    slot_count = t.slot_count
    if t.config.slot_margin > 0:  # beyond the paper: open as many slots as the reported objects justify
        wp.launch(
            kuoh.slot_budget_kernel,
            dim=1,
            inputs=[t.slot_count, t.slot_est, int(kslots.SE_EXIST), float(t.config.min_existence),
                    int(t.config.slot_margin), float(t.config.slot_margin_frac)],
            outputs=[t.slot_open],
            device=d,
        )  # fmt: skip
        slot_count = t.slot_open
    wp.launch(
        kuoh.choose_addition_kernel,
        dim=1,
        inputs=[
            c.best,
            c.est,
            int(kreduce.EST_MAXLOGW),
            c.kind,
            slot_count,
            t.r,
            c.fit_best,
            c.fit_est,
            t.min_fit,
        ],
        outputs=[t.next_label, t.slot_label, t.slot_kind, t.add],
        device=d,
    )
    if len(c.round_best) > 1:  # beyond the paper: the frame's further additions (TemplateConfig.additions)
        wp.launch(
            kuoh.choose_more_additions_kernel,
            dim=1,
            inputs=[c.best_k, c.est_k, int(kreduce.EST_MAXLOGW), c.kind, slot_count, t.r],
            outputs=[t.next_label, t.slot_label, t.slot_kind, t.add],
            device=d,
        )
