"""Device launches of the S3 template tracker shared by its driver (:mod:`wptrack.trackers.templates.tracker`), the
benchmark and the tests: block sizes, the kernels' structs (ground plane, particle state, dynamics), the template
hulls of a set of scenes, the mask's row sums, the XOR scoring (eqs. 4-6) and the block argmax."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import warp as wp

from wptrack.cameras.rig import GroundPlane
from wptrack.core.device import CpuSplit
from wptrack.core.filter import BLOCK
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.templates import dynamics as kdyn
from wptrack.kernels.templates import partition as kpart
from wptrack.kernels.templates import raster as kraster
from wptrack.kernels.templates import xor as kxor
from wptrack.trackers.templates.config import TemplateConfig

SCORE_BLOCK = 64
"""Threads per particle in the XOR scoring kernel of the CPU backend (``kernels.templates.xor.xor_score_kernel``; they
stride over the particle's image rows; a CPU block has one thread)."""


def xor_band(particles: int, height: int, groups: int = 0) -> int:
    """Image rows per thread of the XOR sums on CUDA (``kernels.templates.xor.xor_band_kernel``: a thread per band and
    particle, and per group with ``groups`` > 0, the partitioned filter's R rows of group sums).

    Joint launch: 2 rows up to 3,000 particles, 8 below 30,000, 64 from there; grouped launch: 4, 16 and 64 (each of
    its threads walks one group's pieces only, so its bands are taller for the same work per thread). Measured on an
    H100 (bench scene, 1e3 / 1e4 / 1e5 particles x 5 and 10 objects, bands of 2 to 64 rows: BENCHMARKS.md, issue 13,
    round seven). Doubled while the launch would exceed 2^31 - 1 threads (``height`` image rows)."""
    small, mid = (4, 16) if groups > 0 else (2, 8)
    band = small if particles <= 3000 else mid if particles < 30_000 else 64
    while -(-height // band) * particles * max(groups, 1) > 2**31 - 1:
        band *= 2
    return band


SINGLE_MAX = 4096
"""Up to this many values an argmax runs in one block of :data:`SINGLE_MAX_BLOCK` threads (``kernels.core.reduce.
single_max_kernel``), beyond in blocks and a combining block (``block_max_kernel``, ``final_max_kernel``)."""
SINGLE_MAX_BLOCK = 1024
ROW_BLOCK = 128
"""Threads per image row in the row-scan kernels (mask prefix sums, coverage/UOH/gain rows): each owns a segment of
ceil(W / ROW_BLOCK) pixels."""


def _plane_struct(plane: GroundPlane) -> kraster.GroundPlane:
    s = kraster.GroundPlane()
    s.origin = wp.vec3(*plane.origin)
    s.e1 = wp.vec3(*plane.x_axis)
    s.e2 = wp.vec3(*plane.y_axis)
    s.normal = wp.vec3(*plane.normal)
    return s


def _new_state(n: int, r: int, device: str) -> kdyn.TemplateState:
    s = kdyn.TemplateState()
    s.kind = wp.zeros((n, r), dtype=wp.int32, device=device)
    s.label = wp.full((n, r), -1, dtype=wp.int32, device=device)
    s.pos = wp.zeros((n, r), dtype=wp.vec2, device=device)
    s.vel = wp.zeros((n, r), dtype=wp.vec2, device=device)
    s.heading = wp.zeros((n, r), dtype=wp.float32, device=device)
    s.dims = wp.zeros((n, r), dtype=wp.vec3, device=device)
    s.age = wp.zeros((n, r), dtype=wp.float32, device=device)
    s.logw = wp.zeros(n, dtype=wp.float32, device=device)
    return s


class Hulls:
    """Projected template pieces of a set of one- or multi-slot scenes (device arrays; see
    ``kernels.templates.raster``)."""

    def __init__(self, n: int, slots: int, device: str, particle_fastest: bool = False) -> None:
        """``pts`` (n, slots * PIECES, HULL_MAX), ``n``, ``rows`` and ``depth`` (n, slots * PIECES). With
        ``particle_fastest`` the arrays are views whose storage has the particle index fastest (the same indices,
        other strides): threads on neighbouring particles at the same piece and vertex then read neighbouring
        addresses (``kernels.templates.xor.xor_band_kernel`` on CUDA: the loads coalesce)."""
        q = slots * int(kraster.PIECES)
        h = int(kraster.HULL_MAX)
        self._views: dict[tuple[int, ...], list[list[wp.array]]] = {}  # per state buffer and split: views per range
        if particle_fastest:  # transposed views (each keeps its storage alive): checkpoints see the same names
            pts = wp.zeros((q, h, n), dtype=wp.vec2, device=device)
            cnt = wp.zeros((q, n), dtype=wp.int32, device=device)
            rows = wp.zeros((q, n), dtype=wp.vec2i, device=device)
            depth = wp.zeros((q, n), dtype=wp.float32, device=device)
            self.pts = pts.transpose((2, 0, 1))
            self.n = cnt.transpose((1, 0))
            self.rows = rows.transpose((1, 0))
            self.depth = depth.transpose((1, 0))
            return
        self.pts = wp.zeros((n, q, h), dtype=wp.vec2, device=device)
        self.n = wp.zeros((n, q), dtype=wp.int32, device=device)
        self.rows = wp.zeros((n, q), dtype=wp.vec2i, device=device)
        self.depth = wp.zeros((n, q), dtype=wp.float32, device=device)

    def launch(self, cam, plane, kind, pos, heading, dims, device: str, split: CpuSplit | None = None) -> None:
        """Project every piece of every particle; with ``split`` (CPU backend) the particles' ranges in threads of
        their own, on views of the arrays (the same values: a particle's hulls depend on its own state alone)."""
        if split is None or len(split) == 1:
            wp.launch(
                kraster.template_hulls_kernel,
                dim=(kind.shape[0], kind.shape[1] * int(kraster.PIECES)),
                inputs=[cam, plane, kind, pos, heading, dims],
                outputs=[self.pts, self.n, self.rows, self.depth],
                device=device,
            )
            return
        key = (kind.ptr, pos.ptr, heading.ptr, dims.ptr, *(b for r in split.ranges for b in r))
        views = self._views.get(key)
        if views is None:  # array views per range, made once per state buffer
            arrays = (kind, pos, heading, dims, self.pts, self.n, self.rows, self.depth)
            views = self._views[key] = [[a[lo:hi] for a in arrays] for lo, hi in split.ranges]

        def run(k: int, lo: int, hi: int) -> None:
            v = views[k]
            wp.launch(
                kraster.template_hulls_kernel,
                dim=(hi - lo, kind.shape[1] * int(kraster.PIECES)),
                inputs=[cam, plane, *v[:4]],
                outputs=v[4:],
                device=device,
            )

        split(run)


def _dynamics_struct(config: TemplateConfig) -> kdyn.Dynamics:
    h, v, c = config.human, config.vehicle, config.cyclist
    s = kdyn.Dynamics()
    s.dt = 1.0 / config.frame_rate
    s.sigma_pos = config.sigma_pos
    s.sigma_speed = wp.vec4(0.0, h.sigma_speed, v.sigma_speed, c.sigma_speed)
    s.sigma_turn = v.sigma_turn
    s.sigma_dims_human = wp.vec3(*h.sigma_dims)
    s.sigma_dims_vehicle = wp.vec3(*v.sigma_dims)
    s.sigma_dims_cyclist = wp.vec3(*c.sigma_dims)
    s.dims_mean_human = wp.vec3(*h.dims_mean)
    s.dims_mean_vehicle = wp.vec3(*v.dims_mean)
    s.dims_mean_cyclist = wp.vec3(*c.dims_mean)
    s.dims_sd_human = wp.vec3(*h.dims_sd)
    s.dims_sd_vehicle = wp.vec3(*v.dims_sd)
    s.dims_sd_cyclist = wp.vec3(*c.dims_sd)
    s.dims_min_human = wp.vec3(*h.dims_min)
    s.dims_max_human = wp.vec3(*h.dims_max)
    s.dims_min_vehicle = wp.vec3(*v.dims_min)
    s.dims_max_vehicle = wp.vec3(*v.dims_max)
    s.dims_min_cyclist = wp.vec3(*c.dims_min)
    s.dims_max_cyclist = wp.vec3(*c.dims_max)
    s.init_speed_sd = wp.vec4(0.0, h.init_speed_sd, v.init_speed_sd, c.init_speed_sd)
    s.init_heading_sd = v.init_heading_sd
    s.speed_max = wp.vec4(1.0, h.speed_max, v.speed_max, c.speed_max)
    s.speed_min = wp.vec4(0.0, 0.0, 0.0, c.speed_min)
    s.turn_max = v.turn_max
    s.t_add = config.t_add
    s.t_del = config.t_del
    s.occlusion_del = config.occlusion_del
    s.unseen_del = config.unseen_del
    s.dims_revert = config.dims_revert
    s.absorb = 1 if config.absorb else 0
    s.occlusion_noise = config.occlusion_noise
    return s


def launch_mask_rows(q: wp.array, qrow: wp.array, qtotal: wp.array, device: str, block_dim: int = ROW_BLOCK) -> None:
    """Row prefix sums ``qrow`` (H, W+1) and ``qtotal`` = |q| of the motion mask ``q`` (H, W): one block per row,
    then one block over the row totals (``kernels.templates.xor``)."""
    h = q.shape[0]
    wp.launch_tiled(kxor.mask_rows_kernel, dim=[h], inputs=[q], outputs=[qrow], block_dim=block_dim, device=device)
    wp.launch_tiled(
        kxor.mask_total_kernel, dim=[1], inputs=[qrow], outputs=[qtotal], block_dim=block_dim, device=device
    )


def empty_slot_acc(slots: int, device: str) -> wp.array:
    """The (R, 5) int32 box maxima of ``kernels.templates.partition.slot_box_kernel`` as it expects them: ``BOX_NONE``
    in the four box columns, 0 in the alive column (``group_slots_kernel`` leaves them so after reading)."""
    acc = np.zeros((slots, 5), np.int32)
    acc[:, :4] = int(kpart.BOX_NONE)
    return wp.array(acc, dtype=wp.int32, device=device)


def piece_cap(pieces: int) -> int:
    """The piece count ``kernels.templates.xor.xor_band_kernel`` is compiled for: the smallest power of two >=
    ``pieces`` (at least 2)."""
    c = 2
    while c < pieces:
        c *= 2
    return c


@functools.cache
def _no_groups(device: str) -> tuple[wp.array, wp.array, wp.array, wp.array]:
    """``(group_box, n_groups, slot_group, group_sums)`` of no groups on ``device`` (the joint filter; allocated
    once)."""
    return (
        wp.zeros(1, dtype=wp.vec4i, device=device),
        wp.zeros(1, dtype=wp.int32, device=device),
        wp.zeros(1, dtype=wp.int32, device=device),
        wp.zeros((1, 1), dtype=wp.vec2i, device=device),
    )


@functools.cache
def _all_slots(device: str, slots: int) -> wp.array:
    """``slot_hi`` of :func:`launch_xor_score` that scans every one of ``slots`` slots (allocated once; read only)."""
    return wp.full(1, slots, dtype=wp.int32, device=device)


def launch_xor_score(
    hulls: Any,
    kind: wp.array,
    age: wp.array,
    pos: wp.array,
    heading: wp.array,
    dims: wp.array,
    qrow: wp.array,
    qtotal: wp.array,
    cost_a: wp.vec4,
    cost_b: wp.vec4,
    scale: float,
    bg_weight: float,
    exclusion: float,
    sums: wp.array,
    logw: wp.array,
    penalty: wp.array,
    complexity: wp.array,
    cov_diff: wp.array,
    device: str,
    band: int = 0,
    groups: tuple[wp.array, wp.array, wp.array, wp.array] | None = None,
    finish: bool = True,
    slot_hi: wp.array | None = None,
) -> None:
    """Eqs. 4-6 for every particle (``kernels.templates.xor``) and the coverage counts: with ``band`` > 0 a thread per
    band of ``band`` rows and particle (``xor_band_kernel``, then ``xor_finish_kernel``; ``sums`` (N,) vec2i zeros, left
    zeroed), else a block per particle (``xor_score_kernel``). The same outputs bit for bit either way.

    ``groups`` = ``(group_box, n_groups, slot_group, group_sums)`` (``kernels.templates.partition``) also sums |v| and
    |q AND v| per independent group into ``group_sums`` (N, R) vec2i (zeros; ``xor.group_logw_kernel`` reads and clears
    them); the band kernel then runs a thread per (group, band, particle). ``finish`` False leaves the band path's
    ``sums`` unfinished for ``xor.group_logw_kernel`` (its ``finish`` 1: the same outputs, one launch less).
    ``slot_hi`` (1,) int32: the slots from ``slot_hi[0]`` on are empty in every particle
    (``partition.group_slots_kernel``), so their pieces are not scanned; ``None``: all R slots."""
    n = kind.shape[0]
    if slot_hi is None:
        slot_hi = _all_slots(str(device), kind.shape[1])
    cost = [kind, age, pos, heading, dims, qtotal, cost_a, cost_b, scale, bg_weight, exclusion]
    grouped = groups is not None
    group_box, n_groups, slot_group, group_sums = groups if grouped else _no_groups(str(device))
    if band > 0:
        h = qrow.shape[0]
        bands = (h + band - 1) // band
        wp.launch(
            kxor.xor_band_kernel(piece_cap(hulls.n.shape[1]), grouped),
            dim=(group_sums.shape[1] if grouped else 1, bands, n),
            inputs=[hulls.pts, hulls.n, hulls.rows, qrow, int(band), group_box, n_groups, slot_group, slot_hi],
            outputs=[sums, cov_diff, group_sums],
            device=device,
        )
        if finish:
            wp.launch(
                kxor.xor_finish_kernel, dim=n, inputs=[*cost, sums], outputs=[logw, penalty, complexity], device=device
            )
        return
    wp.launch_tiled(
        kxor.xor_score_kernel,
        dim=[n],
        inputs=[
            hulls.pts,
            hulls.n,
            hulls.rows,
            kind,
            age,
            pos,
            heading,
            dims,
            qrow,
            *cost[5:],
            group_box,
            n_groups,
            slot_hi,
        ],
        outputs=[logw, penalty, complexity, cov_diff, group_sums],
        block_dim=SCORE_BLOCK,
        device=device,
    )


def launch_argmax(values, n, blocks, chunk, part_max, part_arg, est, best, device: str) -> None:
    """Max and argmax of ``values[:n]`` into ``est`` (``kernels.core.reduce`` layout) and ``best`` (1,): one block up
    to :data:`SINGLE_MAX` values, else ``blocks`` blocks of ``chunk`` values and a combining block."""
    if n <= SINGLE_MAX:  # one block over all values: one launch instead of two, the same result
        wp.launch_tiled(
            kreduce.single_max_kernel,
            dim=[1],
            inputs=[values, n],
            outputs=[est, best],
            block_dim=SINGLE_MAX_BLOCK,
            device=device,
        )
        return
    wp.launch_tiled(
        kreduce.block_max_kernel,
        dim=[blocks],
        inputs=[values, n, chunk],
        outputs=[part_max, part_arg],
        block_dim=BLOCK,
        device=device,
    )
    wp.launch_tiled(
        kreduce.final_max_kernel,
        dim=[1],
        inputs=[part_max, part_arg, blocks],
        outputs=[est, best],
        block_dim=BLOCK,
        device=device,
    )
