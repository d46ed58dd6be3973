"""S3: 3D template tracker from one calibrated camera (Juza, Marik, Rojicek and Stluka, "3D Template-Based Single
Camera Multiple Object Tracking").

Several objects of two types (humans, vehicles) move on a ground plane seen by one camera. Each particle is a whole
scene: up to R_max objects (``max_objects``), each a 3D template (``kernels.templates.raster``). A frame is one chain of
device launches (CUDA graph on GPUs)::

    motion mask q -> row prefix sums, |q|
    -> template hulls (project every object of every particle, distortion included)
    -> XOR penalty m_i (eq. 4), complexity c_i (eq. 5), log-weight (eq. 6); coverage counts
    -> UOH (eq. 10), candidate gains and the best candidate (eq. 11)
    -> max log-weight, per-object weighted estimates (existence, position, class, dims, heading), best particle
    -> addition decision (slot + new label), resampling by cumulative weights (eq. 7, float64 CDF)
    -> prediction: deletion (eq. 13), addition (eq. 12), noise, drift (eqs. 8-9)

Every slot holds one persistent label in all particles, so an object's estimate is a weighted moment over the
particles that hold it, and labels survive resampling. Objects are reported when their existence probability (the
weight of the particles holding them) is at least ``min_existence`` and at least ``min_in_image`` of their image
bounding box is inside the image.

Units: metres, seconds, radians on the ground plane (its own 2D frame, see ``wptrack.cameras.rig.GroundPlane``); pixels
in the image.
"""

from __future__ import annotations

import functools
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import warp as wp

from wptrack.cameras.rig import Camera, GroundPlane, Rig
from wptrack.cameras.structs import camera_struct
from wptrack.core.device import CpuSplit, block_partition, cpu_split_threads
from wptrack.core.errors import ConfigError, RigError
from wptrack.core.filter import BLOCK, MAX_BLOCKS, FrameChain, _seed_words
from wptrack.core.memory import check_fits
from wptrack.core.resampling import Resampler, bytes_per_particle, quantisation_bits
from wptrack.io.frames import camera_frame
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.core import resample as kres
from wptrack.kernels.templates import classify as kcls
from wptrack.kernels.templates import dynamics as kdyn
from wptrack.kernels.templates import occlusion as kocc
from wptrack.kernels.templates import partition as kpart
from wptrack.kernels.templates import raster as kraster
from wptrack.kernels.templates import slots as kslots
from wptrack.kernels.templates import uoh as kuoh
from wptrack.kernels.templates import xor as kxor
from wptrack.trackers.templates.config import (  # noqa: F401  (HumanPrior, VehiclePrior: the tracker's public API)
    CLASSES,
    HumanPrior,
    TemplateConfig,
    TemplateEstimate,
    TrackedObject,
    VehiclePrior,
)

log = logging.getLogger(__name__)

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


SLOT_STATE_BYTES = (
    2 * (4 + 4 + 8 + 8 + 4 + 12 + 4) + int(kraster.PIECES) * (int(kraster.HULL_MAX) * 8 + 4 + 8 + 4) + 4  # + occlusion
)
"""Device bytes per object slot of a particle: two ping-pong state buffers and the piece hulls."""
PARTICLE_BYTES = 2 * 4 + 4 + 4 + 4 + 8 + 8
"""Device bytes per particle besides the slots: log-weights (2), penalty, complexity, ancestor, weight, XOR sums."""
PARTITION_SLOT_BYTES = 8 + 4 + 4 + 8 + 8
"""Device bytes per slot and particle of the partitioned filter (``TemplateConfig.partition``), besides the joint
filter's: a weight (float64), an ancestor, a log-factor and an exact CDF entry (int64) per group (a group per slot at
most), and the group sums (two int32)."""


def particle_bytes(max_objects: int, scheme: str, partition: bool = False) -> int:
    """Device memory per particle of the template tracker, bytes."""
    extra = max_objects * PARTITION_SLOT_BYTES if partition else 0
    return max_objects * SLOT_STATE_BYTES + PARTICLE_BYTES + extra + bytes_per_particle(scheme)  # float64 weights


_BOX_CORNERS = np.array([[sx, sy, sz] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5) for sz in (0.0, 1.0)])


def image_box_fraction(camera: Camera, plane: GroundPlane, objects: list[TrackedObject]) -> np.ndarray:
    """Fraction of each object's image bounding box that lies inside the image (``TemplateConfig.min_in_image``).

    The image bounding box is the box around the 8 projected corners of the object's 3D bounding box (``size``:
    length x width x height, metres, turned by its heading, standing on the ground plane), lens distortion included.
    An object with a corner behind the camera counts as outside (0).

    Args:
        camera: The tracker's ``wptrack.cameras.rig.Camera`` (its ``width`` x ``height`` pixels is the image).
        plane: The ``wptrack.cameras.rig.GroundPlane``.
        objects: ``TrackedObject`` s.

    Returns:
        (len(objects),) fractions in [0, 1].
    """
    if not objects:
        return np.zeros(0)
    return box_fraction_in_image(
        camera,
        plane,
        np.array([o.ground for o in objects], dtype=np.float64),
        np.array([o.size for o in objects], dtype=np.float64),
        np.array([o.heading for o in objects], dtype=np.float64),
    )


def box_fraction_in_image(
    camera: Camera, plane: GroundPlane, ground: np.ndarray, size: np.ndarray, heading: np.ndarray
) -> np.ndarray:
    """:func:`image_box_fraction` of objects given as arrays.

    Args:
        camera: The camera (its ``width`` x ``height`` pixels is the image).
        plane: The ground plane.
        ground: (n, 2) ground-plane positions of the objects' footprint centres, metres.
        size: (n, 3) length, width, height, metres.
        heading: (n,) headings on the ground plane, radians.

    Returns:
        (n,) fractions in [0, 1].
    """
    ground = np.asarray(ground, dtype=np.float64).reshape(-1, 2)
    if len(ground) == 0:
        return np.zeros(0)
    ok, area, inside = camera.image_box_cover(object_box_corners(plane, ground, size, heading))
    return np.where(ok, inside / area, 0.0)


def object_box_corners(plane: GroundPlane, ground: np.ndarray, size: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """The 8 world corners of each object's 3D box (the box whose image is the object's image box).

    Args:
        plane: The ground plane.
        ground: (n, 2) ground-plane positions of the footprint centres, metres.
        size: (n, 3) length, width, height, metres.
        heading: (n,) headings on the ground plane, radians.

    Returns:
        (n, 8, 3) world points, metres.
    """
    ground = np.asarray(ground, dtype=np.float64).reshape(-1, 2)
    size = np.asarray(size, dtype=np.float64).reshape(-1, 3)
    heading = np.asarray(heading, dtype=np.float64).reshape(-1)
    c = np.cos(heading)[:, None]
    s = np.sin(heading)[:, None]
    local = _BOX_CORNERS[None] * size[:, None, :]  # (n, 8, 3)
    gx = ground[:, :1] + c * local[..., 0] - s * local[..., 1]
    gy = ground[:, 1:] + s * local[..., 0] + c * local[..., 1]
    return plane.to_world(np.stack([gx, gy], axis=-1), local[..., 2])


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


class Candidates:
    """The fixed set of addition candidates (eq. 11): ground points under an image grid x class x orientation,
    at the prior's mean size, with their image spans precomputed on the device."""

    @staticmethod
    def _grid(camera: Camera, plane: GroundPlane, step: int, margin: int, max_range: float) -> np.ndarray:
        """(K, 2) ground points (metres) under the pixel grid of pitch ``step`` over the image widened by ``margin``
        pixels left, right and below (the rays of pixels beyond the border: objects entering the view), within
        ``max_range`` of the camera."""
        us = np.arange(step / 2.0 - margin, camera.width + margin, step)
        vs = np.arange(step / 2.0, camera.height + margin, step)
        grid = np.stack(np.meshgrid(us, vs), axis=-1).reshape(-1, 2)
        ground, dist = ground_rays(camera, plane, grid)
        return ground[dist <= max_range]

    def __init__(self, camera: Camera, plane: GroundPlane, cam_struct, plane_struct, config: TemplateConfig, device):
        step = int(config.candidate_step_px)
        ground = self._grid(camera, plane, step, 0, config.max_range)
        if len(ground) == 0:
            raise RigError(
                f"camera '{camera.name}' does not see the ground plane (origin {plane.origin.tolist()}, normal "
                f"{plane.normal.tolist()}) within {config.max_range} m: no image pixel's ray meets it in front of "
                "the camera; check the rig's pose and its 'ground' entry"
            )
        grids = {0: ground}  # by margin beyond the border, pixels (the two classes' margins are often equal)
        for margin in {int(config.human_entry_px), int(config.vehicle_entry_px)} - {0}:
            grids[margin] = self._grid(camera, plane, step, margin, config.max_range)
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
        self.score = wp.zeros(c, dtype=wp.float32, device=d)
        self.area = wp.zeros(c, dtype=wp.int32, device=d)
        self.blocks = min((c + BLOCK - 1) // BLOCK, MAX_BLOCKS)
        self.chunk = (c + self.blocks - 1) // self.blocks
        self.part_max = wp.zeros(self.blocks, dtype=wp.float32, device=d)
        self.part_arg = wp.zeros(self.blocks, dtype=wp.int32, device=d)
        self.est = wp.zeros(int(kreduce.EST_SIZE), dtype=wp.float64, device=d)
        self.best = wp.zeros(1, dtype=wp.int32, device=d)
        # class-aware addition (kernels.templates.classify): vehicle fits near a chosen human and their argmax
        self.fit = wp.zeros(c, dtype=wp.float32, device=d)
        self.fit_max = wp.zeros(self.blocks, dtype=wp.float32, device=d)
        self.fit_arg = wp.zeros(self.blocks, dtype=wp.int32, device=d)
        self.fit_est = wp.zeros(int(kreduce.EST_SIZE), dtype=wp.float64, device=d)
        self.fit_best = wp.zeros(1, dtype=wp.int32, device=d)
        self.bytes = int(lengths.sum()) * 8 + c * (int(kraster.PIECES) * (int(kraster.HULL_MAX) * 8 + 16) + 56)


def _dynamics_struct(config: TemplateConfig) -> kdyn.Dynamics:
    h, v = config.human, config.vehicle
    s = kdyn.Dynamics()
    s.dt = 1.0 / config.frame_rate
    s.sigma_pos = config.sigma_pos
    s.sigma_speed = wp.vec3(0.0, h.sigma_speed, v.sigma_speed)
    s.sigma_turn = v.sigma_turn
    s.sigma_dims_human = wp.vec3(*h.sigma_dims)
    s.sigma_dims_vehicle = wp.vec3(*v.sigma_dims)
    s.dims_mean_human = wp.vec3(*h.dims_mean)
    s.dims_mean_vehicle = wp.vec3(*v.dims_mean)
    s.dims_sd_human = wp.vec3(*h.dims_sd)
    s.dims_sd_vehicle = wp.vec3(*v.dims_sd)
    s.dims_min_human = wp.vec3(*h.dims_min)
    s.dims_max_human = wp.vec3(*h.dims_max)
    s.dims_min_vehicle = wp.vec3(*v.dims_min)
    s.dims_max_vehicle = wp.vec3(*v.dims_max)
    s.init_speed_sd = wp.vec3(0.0, h.init_speed_sd, v.init_speed_sd)
    s.init_heading_sd = v.init_heading_sd
    s.speed_max = wp.vec3(1.0, h.speed_max, v.speed_max)
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


def launch_xor_score(
    hulls: Any,
    kind: wp.array,
    age: wp.array,
    pos: wp.array,
    heading: wp.array,
    dims: wp.array,
    qrow: wp.array,
    qtotal: wp.array,
    cost_a: wp.vec3,
    cost_b: wp.vec3,
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
) -> None:
    """Eqs. 4-6 for every particle (``kernels.templates.xor``) and the coverage counts: with ``band`` > 0 a thread per
    band of ``band`` rows and particle (``xor_band_kernel``, then ``xor_finish_kernel``; ``sums`` (N,) vec2i zeros, left
    zeroed), else a block per particle (``xor_score_kernel``). The same outputs bit for bit either way.

    ``groups`` = ``(group_box, n_groups, slot_group, group_sums)`` (``kernels.templates.partition``) also sums |v| and
    |q AND v| per independent group into ``group_sums`` (N, R) vec2i (zeros; ``xor.group_logw_kernel`` reads and clears
    them); the band kernel then runs a thread per (group, band, particle). ``finish`` False leaves the band path's
    ``sums`` unfinished for ``xor.group_logw_kernel`` (its ``finish`` 1: the same outputs, one launch less)."""
    n = kind.shape[0]
    cost = [kind, age, pos, heading, dims, qtotal, cost_a, cost_b, scale, bg_weight, exclusion]
    grouped = groups is not None
    group_box, n_groups, slot_group, group_sums = groups if grouped else _no_groups(str(device))
    if band > 0:
        h = qrow.shape[0]
        bands = (h + band - 1) // band
        wp.launch(
            kxor.xor_band_kernel(piece_cap(hulls.n.shape[1]), grouped),
            dim=(group_sums.shape[1] if grouped else 1, bands, n),
            inputs=[hulls.pts, hulls.n, hulls.rows, qrow, int(band), group_box, n_groups, slot_group],
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
        inputs=[hulls.pts, hulls.n, hulls.rows, kind, age, pos, heading, dims, qrow, *cost[5:], group_box, n_groups],
        outputs=[logw, penalty, complexity, cov_diff, group_sums],
        block_dim=SCORE_BLOCK,
        device=device,
    )


class TemplateTracker(FrameChain):
    """The S3 template tracker on one device.

    Args:
        rig: calibrated rig; ``config.camera`` picks the camera, ``rig.ground_plane`` the ground.
        config: tracker configuration.
        device: Warp device (``"cpu"``, ``"cuda:0"``).
        keep_virtual: read back the best particle's virtual scene every frame (reports, Fig. 5).
        keep_uoh: read back the UOH image every frame (reports, Fig. 4).
        use_graph: capture the frame chain as CUDA graphs (default: on CUDA).

    Raises:
        ConfigError: invalid configuration, or more particles than fit in the device's memory.
        RigError: unknown camera, or a camera that does not see the ground plane.

    Device state (N particles, R = max_objects slots): two ``kernels.templates.dynamics.TemplateState`` buffers (see
    there for fields, shapes and units), piece hulls (N, 2R, 16) vec2 pixels, penalties m (N,) int32 pixels, complexity
    c (N,) float32 pixels, weights (N,) float64, ancestors (N,) int32; per slot (R,): label, kind, particle count.
    """

    def __init__(
        self,
        rig: Rig,
        config: TemplateConfig | None = None,
        device: str = "cpu",
        keep_virtual: bool = False,
        keep_uoh: bool = False,
        use_graph: bool | None = None,
    ) -> None:
        self.config = config = config if config is not None else TemplateConfig()
        if not isinstance(rig, Rig):
            raise ConfigError(f"rig: expected a wptrack.cameras.rig.Rig, got {type(rig).__name__}")
        self.rig = rig
        self.camera = rig[config.camera_key]
        self.plane = rig.ground_plane
        super().__init__(device, use_graph)
        d = self.device
        self.n = n = int(config.particles)
        self.r = r = int(config.max_objects)
        self.width, self.height = self.camera.width, self.camera.height
        self.seed = _seed_words(config.seed)
        self.cam = camera_struct(self.camera)
        self.plane_struct = _plane_struct(self.plane)
        self.dyn = _dynamics_struct(config)
        self.keep_virtual = bool(keep_virtual)
        self.keep_uoh = bool(keep_uoh)
        h, w = self.height, self.width
        image_bytes = h * (w + 1) * (4 + 4 + 8) + (h + 1) * (w + 1) * 8 + h * w * (1 + 4 + 1)
        self.partition = bool(config.partition)
        check_fits(
            n, particle_bytes(r, config.resampling, self.partition), image_bytes, d, what="template tracker particles"
        )
        self.candidates = Candidates(self.camera, self.plane, self.cam, self.plane_struct, config, d)
        log.info(
            "template tracker: %d particles x %d slots, %d addition candidates, camera %s %dx%d on %s",
            n,
            r,
            self.candidates.count,
            self.camera.name,
            w,
            h,
            d,
        )
        self.state = [_new_state(n, r, d), _new_state(n, r, d)]
        self.hulls = Hulls(n, r, d, particle_fastest=self.is_cuda)
        # CPU backend: the hull projection (a third of the frame at 1000 particles) in threads over particle ranges
        self.split = None if self.is_cuda else CpuSplit(n, cpu_split_threads(n))
        self.occlusion = wp.zeros((n, r), dtype=wp.float32, device=d)
        self.use_occlusion = config.occlusion_del > 0.0 or config.occlusion_noise > 0.0
        self.q = wp.zeros((h, w), dtype=wp.uint8, device=d)
        self.q_host = wp.zeros((h, w), dtype=wp.uint8, device="cpu", pinned=self.is_cuda)
        self.qrow = wp.zeros((h, w + 1), dtype=wp.int32, device=d)
        self.qtotal = wp.zeros(1, dtype=wp.int32, device=d)
        self.cov_diff = wp.zeros((h, w + 1), dtype=wp.int32, device=d)
        self.uoh = wp.zeros((h, w), dtype=wp.int32, device=d)
        self.gain_rows = wp.zeros((h, w + 1), dtype=wp.float64, device=d)
        self.a_sat = wp.zeros((h + 1, w + 1), dtype=wp.int64, device=d)  # UOH summed-area table (candidate bounds)
        self.virtual = wp.zeros((h, w), dtype=wp.uint8, device=d)
        self.penalty = wp.zeros(n, dtype=wp.int32, device=d)
        self.xor_sums = wp.zeros(n, dtype=wp.vec2i, device=d)  # per-particle (|v|, |q AND v|) of xor_band_kernel
        # CUDA: a thread per band of rows and particle (the packed coordinates need images below 32768 pixels);
        # the CPU backend (one lane per block) walks each particle's rows in xor_score_kernel
        self.xor_band = xor_band(n, h, r if self.partition else 0) if self.is_cuda and max(w, h) < 32768 else 0
        self.complexity = wp.zeros(n, dtype=wp.float32, device=d)
        # one weight and ancestor row per group of slots: one in the paper's joint filter, R in the partitioned one
        rows = r if self.partition else 1
        self.weights = wp.zeros((rows, n), dtype=wp.float64, device=d)
        self.ancestors = wp.array(np.tile(np.arange(n, dtype=np.int32), (rows, 1)), device=d)
        self.resampled = wp.ones(1, dtype=wp.int32, device=d)
        self.frame = wp.zeros(1, dtype=wp.int32, device=d)
        self.ess_threshold = wp.array([config.ess_threshold], dtype=wp.float32, device=d)
        sms = wp.get_device(d).sm_count if self.is_cuda else 0
        self.blocks, self.chunk = block_partition(n, not self.is_cuda, BLOCK, MAX_BLOCKS, sms)
        self.part_max = wp.zeros(self.blocks, dtype=wp.float32, device=d)
        self.part_arg = wp.zeros(self.blocks, dtype=wp.int32, device=d)
        self.part = wp.zeros((self.blocks, r, int(kslots.NS)), dtype=wp.float64, device=d)
        self.est = wp.zeros(int(kreduce.EST_SIZE), dtype=wp.float64, device=d)
        self.best_index = wp.zeros(1, dtype=wp.int32, device=d)
        # independent groups of slots (kernels.templates.partition); the joint filter keeps every slot in group 0
        self.slot_group = wp.zeros(r, dtype=wp.int32, device=d)
        self.slot_box = wp.zeros(r, dtype=wp.vec4i, device=d)
        self.slot_alive = wp.zeros(r, dtype=wp.int32, device=d)
        self.group_box = wp.zeros(r, dtype=wp.vec4i, device=d)
        self.group_first = wp.full(r, -1, dtype=wp.int32, device=d)
        self.group_active = wp.zeros(r, dtype=wp.int32, device=d)
        self.n_groups = wp.zeros(1, dtype=wp.int32, device=d)
        gn, gr, gb = (n, r, self.blocks) if self.partition else (1, 1, 1)  # unused 1 x 1 stand-ins when joint
        self.slot_acc = empty_slot_acc(
            r, d
        )  # the slots' box maxima (kernels.templates.partition), reset by group_slots_kernel
        self.group_sums = wp.zeros((gn, gr), dtype=wp.vec2i, device=d)
        self.glogw = wp.zeros((gr, gn), dtype=wp.float32, device=d)
        self.part_gmax = wp.zeros((gb, gr), dtype=wp.float32, device=d)
        # row views for the resampler (array headers only) and a resampling stream per group
        self._weight_rows = [self.weights[g] for g in range(rows)]
        self._ancestor_rows = [self.ancestors[g] for g in range(rows)]
        self._active_rows = [self.group_active[g : g + 1] for g in range(r)]
        # the class-aware addition's threshold (kernels.templates.classify; inf: off)
        on = config.vehicle_fit > 0.0 and "vehicle" in config.classes and "human" in config.classes
        self.min_fit = float(config.vehicle_fit) if on else math.inf
        self.group_scale = float(2 ** quantisation_bits(n))  # the exact integer CDF of grouped_systematic_kernel
        self.group_cdf = wp.zeros((gr, gn), dtype=wp.int64, device=d)
        self.part_q = wp.zeros((gb, gr), dtype=wp.int64, device=d)  # per-block sums of the groups' integer weights
        self._group_seeds = [
            wp.vec2ui(int(self.seed[0]) ^ ((0x9E3779B9 * g) & 0xFFFFFFFF), int(self.seed[1])) for g in range(rows)
        ]
        self.slot_est = wp.zeros((r, int(kslots.NE)), dtype=wp.float64, device=d)
        self.slot_count = wp.zeros(r, dtype=wp.float64, device=d)
        self.slot_label = wp.full(r, -1, dtype=wp.int32, device=d)
        self.slot_kind = wp.zeros(r, dtype=wp.int32, device=d)
        self.next_label = wp.zeros(1, dtype=wp.int32, device=d)
        self.add = wp.full(2, -1, dtype=wp.int32, device=d)
        self.best_state = wp.zeros((r, 11), dtype=wp.float32, device=d)
        self.resampler = Resampler(config.resampling, n, d)
        self.cost_a = wp.vec3(0.0, config.human.cost_a, config.vehicle.cost_a)
        self.cost_b = wp.vec3(0.0, config.human.cost_b, config.vehicle.cost_b)
        self.score_scale = float(config.scale) / float(w * h)
        pinned = self.is_cuda
        self.host = {
            "slot_est": wp.zeros((r, int(kslots.NE)), dtype=wp.float64, device="cpu", pinned=pinned),
            "slot_label": wp.zeros(r, dtype=wp.int32, device="cpu", pinned=pinned),
            "slot_kind": wp.zeros(r, dtype=wp.int32, device="cpu", pinned=pinned),
            "best_state": wp.zeros((r, 11), dtype=wp.float32, device="cpu", pinned=pinned),
            "add": wp.zeros(2, dtype=wp.int32, device="cpu", pinned=pinned),
            "qtotal": wp.zeros(1, dtype=wp.int32, device="cpu", pinned=pinned),
            "est": wp.zeros(int(kreduce.EST_SIZE), dtype=wp.float64, device="cpu", pinned=pinned),
            "n_groups": wp.zeros(1, dtype=wp.int32, device="cpu", pinned=pinned),
        }
        if self.keep_virtual:
            self.host["virtual"] = wp.zeros((h, w), dtype=wp.uint8, device="cpu", pinned=pinned)
        if self.keep_uoh:
            self.host["uoh"] = wp.zeros((h, w), dtype=wp.int32, device="cpu", pinned=pinned)

    def state_arrays(self) -> dict[str, wp.array]:
        """The template filter's state: both particle buffers (``kernels.templates.dynamics.TemplateState``: kind,
        label, pos, vel, heading, dims, age (N, R); logw (N,)), the frame counter, the per-slot labels, kinds and
        estimates (the addition and the vehicle fit read the previous frame's), the next label and the slots' box
        accumulator (reset by every frame's grouping). The ancestors, weights, resample flag and slot counts are
        rewritten before they are read in every configuration tests/test_state.py runs; they are kept (N x groups
        values) so that a checkpoint does not depend on that order. Hulls, scores, the UOH, the groups and the
        candidates' scores are recomputed every frame; the candidates' geometry is built from the configuration."""
        arrays: dict[str, wp.array] = {}
        for k, state in enumerate(self.state):
            for name in ("kind", "label", "pos", "vel", "heading", "dims", "age", "logw"):
                arrays[f"state.{k}.{name}"] = getattr(state, name)
        arrays.update(
            ancestors=self.ancestors,
            weights=self.weights,
            resampled=self.resampled,
            frame=self.frame,
            ess_threshold=self.ess_threshold,
            slot_est=self.slot_est,
            slot_count=self.slot_count,
            slot_label=self.slot_label,
            slot_kind=self.slot_kind,
            next_label=self.next_label,
            slot_acc=self.slot_acc,
        )
        return arrays

    # --- memory --------------------------------------------------------------------------------------------
    @property
    def bytes_per_particle(self) -> int:
        """Device bytes per particle (state, hulls, weights, resampler)."""
        return particle_bytes(self.r, self.config.resampling)

    # --- observation ---------------------------------------------------------------------------------------
    def upload(self, mask: np.ndarray) -> None:
        """Copy one motion mask (H, W) (nonzero = foreground) to the device.

        Raises:
            FrameError: the mask's size differs from the camera's calibrated size, or it is not 2D.
        """
        m = camera_frame(mask, self.camera, "mask", f" in {self.rig.source}")
        np.copyto(self.q_host.numpy(), m != 0, casting="unsafe")
        wp.copy(self.q, self.q_host)

    # --- the chain -----------------------------------------------------------------------------------------
    def _observe(self) -> None:
        launch_mask_rows(self.q, self.qrow, self.qtotal, self.device)

    def _raster(self, cur: int) -> None:
        s = self.state[cur]
        self.hulls.launch(self.cam, self.plane_struct, s.kind, s.pos, s.heading, s.dims, self.device, self.split)
        if (
            self.partition
        ):  # beyond the paper: the slots' boxes and their independent groups (kernels.templates.partition)
            wp.launch_tiled(
                kpart.slot_box_kernel,
                dim=[self.blocks, self.r],
                inputs=[self.hulls.pts, self.hulls.n, self.hulls.rows, s.kind, self.n, self.chunk, self.width,
                        self.height],
                outputs=[self.slot_acc],
                block_dim=BLOCK,
                device=self.device,
            )  # fmt: skip
            wp.launch(
                kpart.group_slots_kernel,
                dim=1,
                inputs=[self.slot_acc, 1],
                outputs=[self.slot_box, self.slot_alive, self.slot_group, self.group_box, self.group_first,
                         self.group_active, self.n_groups],
                device=self.device,
            )  # fmt: skip
        if (
            self.use_occlusion
        ):  # beyond the paper: per-object occlusion for the prediction (kernels.templates.occlusion)
            wp.launch(
                kocc.occlusion_kernel,
                dim=(self.n, self.r),
                inputs=[self.hulls.pts, self.hulls.n, self.hulls.depth, self.width, self.height],
                outputs=[self.occlusion],
                device=self.device,
            )

    def _score(self, cur: int) -> None:
        s = self.state[cur]
        cfg = self.config
        # partitioned on CUDA: the band kernel's joint sums are finished by group_logw_kernel (one launch less)
        finish_here = not (self.partition and self.xor_band > 0)
        launch_xor_score(
            self.hulls, s.kind, s.age, s.pos, s.heading, s.dims, self.qrow, self.qtotal, self.cost_a, self.cost_b,
            self.score_scale, float(cfg.bg_weight), float(cfg.exclusion), self.xor_sums, s.logw, self.penalty,
            self.complexity, self.cov_diff, self.device, band=self.xor_band,
            groups=(self.group_box, self.n_groups, self.slot_group, self.group_sums) if self.partition else None,
            finish=finish_here,
        )  # fmt: skip
        if self.partition:  # each group's factor of eq. 6 (kernels.templates.xor.group_logw_kernel)
            wp.launch_tiled(
                kxor.group_logw_kernel,
                dim=[self.blocks],
                inputs=[s.kind, s.age, s.pos, s.heading, s.dims, self.qtotal, self.cost_a, self.cost_b,
                        self.score_scale, float(cfg.bg_weight), float(cfg.exclusion), self.slot_group, self.n_groups,
                        self.n, self.chunk, int(not finish_here), self.xor_sums],
                outputs=[self.group_sums, self.glogw, self.part_gmax, s.logw, self.penalty, self.complexity],
                block_dim=BLOCK,
                device=self.device,
            )  # fmt: skip

    def _uoh(self) -> None:
        d = self.device
        c = self.candidates
        cfg = self.config
        wp.launch_tiled(
            kuoh.coverage_uoh_kernel,
            dim=[self.height],
            inputs=[self.q, self.n, float(cfg.add_beta)],
            outputs=[self.cov_diff, self.uoh, self.gain_rows, self.a_sat],
            block_dim=ROW_BLOCK,
            device=d,
        )
        cols = 1 if self.is_cuda else self.width + 1  # a block per column; one pass in memory order on the CPU
        wp.launch_tiled(
            kuoh.uoh_box_sums_kernel,
            dim=[(self.width + cols) // cols],
            inputs=[cols, self.a_sat],
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
                self.gain_rows,
                self.a_sat,
                self.n,
                float(cfg.add_beta),
                float(cfg.add_min_gain),
                int(cfg.min_candidate_area),
            ],
            outputs=[c.score, c.area],
            block_dim=CANDIDATE_BLOCK,
            device=d,
        )
        self._argmax(c.score, c.count, c.blocks, c.chunk, c.part_max, c.part_arg, c.est, c.best)
        if self.min_fit < math.inf:
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
                    self.qrow,
                    0.5 * float(cfg.vehicle.dims_mean[0]),
                    int(cfg.min_candidate_area),
                    wp.vec3(*cfg.vehicle.dims_mean),
                    self.slot_est,
                    self.slot_kind,
                    float(cfg.min_existence),
                ],
                outputs=[c.fit],
                block_dim=CANDIDATE_BLOCK,
                device=d,
            )
            self._argmax(c.fit, c.count, c.blocks, c.chunk, c.fit_max, c.fit_arg, c.fit_est, c.fit_best)

    def _argmax(self, values, n, blocks, chunk, part_max, part_arg, est, best) -> None:
        if n <= SINGLE_MAX:  # one block over all values: one launch instead of two, the same result
            wp.launch_tiled(
                kreduce.single_max_kernel,
                dim=[1],
                inputs=[values, n],
                outputs=[est, best],
                block_dim=SINGLE_MAX_BLOCK,
                device=self.device,
            )
            return
        wp.launch_tiled(
            kreduce.block_max_kernel,
            dim=[blocks],
            inputs=[values, n, chunk],
            outputs=[part_max, part_arg],
            block_dim=BLOCK,
            device=self.device,
        )
        wp.launch_tiled(
            kreduce.final_max_kernel,
            dim=[1],
            inputs=[part_max, part_arg, blocks],
            outputs=[est, best],
            block_dim=BLOCK,
            device=self.device,
        )

    def _estimate(self, cur: int) -> None:
        d = self.device
        s = self.state[cur]
        self._argmax(s.logw, self.n, self.blocks, self.chunk, self.part_max, self.part_arg, self.est, self.best_index)
        wp.launch_tiled(
            kslots.block_slot_moments_kernel,
            dim=[self.blocks, self.r],
            inputs=[
                s,
                self.n,
                self.chunk,
                self.est,
                self.glogw,
                self.part_gmax,
                self.blocks,
                self.slot_group,
                self.group_first,
                int(self.partition),
                self.group_scale,
            ],
            outputs=[self.weights, self.part, self.part_q],
            block_dim=BLOCK,
            device=d,
        )
        wp.launch_tiled(
            kslots.final_slot_moments_kernel,
            dim=[self.r],
            inputs=[self.part, self.blocks, self.n, self.est, self.ess_threshold, s, self.best_index, self.penalty],
            outputs=[self.slot_est, self.slot_count, self.resampled, self.best_state],
            block_dim=BLOCK,
            device=d,
        )
        if self.keep_virtual:
            wp.launch(
                kraster.render_labels_kernel,
                dim=self.height,
                inputs=[
                    self.hulls.pts,
                    self.hulls.n,
                    self.hulls.rows,
                    self.hulls.depth,
                    self.r * int(kraster.PIECES),
                    self.best_index,
                ],
                outputs=[self.virtual],
                device=d,
            )

    def _predict(self, cur: int, nxt: int) -> None:
        d = self.device
        c = self.candidates
        wp.launch(
            kuoh.choose_addition_kernel,
            dim=1,
            inputs=[
                c.best,
                c.est,
                int(kreduce.EST_MAXLOGW),
                c.kind,
                self.slot_count,
                self.r,
                c.fit_best,
                c.fit_est,
                self.min_fit,
            ],
            outputs=[self.next_label, self.slot_label, self.slot_kind, self.add],
            device=d,
        )
        if self.partition and self.config.resampling == "systematic":
            # each group of slots on its own factor (kernels.templates.partition), one launch; unused rows: the identity
            wp.launch_tiled(
                kres.grouped_systematic_kernel,
                dim=[self.r, self.blocks],
                inputs=[self.weights, self.group_active, self.part_q, self.blocks, self.chunk, self.group_scale,
                        self.seed, self.frame, self.n, self.group_cdf],
                outputs=[self.ancestors],
                block_dim=BLOCK,
                device=d,
            )  # fmt: skip
        elif self.partition:  # the other schemes: one resampler call per group
            for g in range(self.r):
                self.resampler(
                    self._weight_rows[g], self._group_seeds[g], self.frame, self._ancestor_rows[g],
                    enabled=self._active_rows[g],
                )  # fmt: skip
        else:
            self.resampler(self._weight_rows[0], self.seed, self.frame, self._ancestor_rows[0], enabled=self.resampled)
        wp.launch(
            kdyn.template_predict_kernel,
            dim=(self.n, self.r),
            inputs=[
                self.dyn,
                self.seed,
                self.frame,
                self.ancestors,
                self.slot_group,
                self.resampled,
                self.add,
                self.slot_label,
                c.kind,
                c.pos,
                c.heading,
                self.occlusion,
                self.hulls.n,
                self.state[cur],
            ],
            outputs=[self.state[nxt]],
            device=d,
        )
        wp.launch(kreduce.increment_kernel, dim=1, inputs=[self.frame], device=d)

    def _readback(self) -> None:
        h = self.host
        wp.copy(h["slot_est"], self.slot_est)
        wp.copy(h["slot_label"], self.slot_label)
        wp.copy(h["slot_kind"], self.slot_kind)
        wp.copy(h["best_state"], self.best_state)
        wp.copy(h["add"], self.add)
        wp.copy(h["qtotal"], self.qtotal)
        wp.copy(h["est"], self.est)
        wp.copy(h["n_groups"], self.n_groups)
        if self.keep_virtual:
            wp.copy(h["virtual"], self.virtual)
        if self.keep_uoh:
            wp.copy(h["uoh"], self.uoh)

    def stages(self, src: int, dst: int) -> list[tuple[str, Callable[[], None]]]:
        """The frame chain as named stages: observe, raster, score, uoh, estimate, resample_predict, readback.

        ``src`` is the buffer holding the predicted particles of this frame; ``dst`` receives the prediction for
        the next frame."""
        return [
            ("observe", self._observe),
            ("raster", lambda: self._raster(src)),
            ("score", lambda: self._score(src)),
            ("uoh", self._uoh),
            ("estimate", lambda: self._estimate(src)),
            ("resample_predict", lambda: self._predict(src, dst)),
            ("readback", self._readback),
        ]

    # --- frames --------------------------------------------------------------------------------------------
    def step(self, mask: np.ndarray) -> TemplateEstimate:
        """Track one frame: upload its motion mask (H, W) and run the chain."""
        t0 = time.perf_counter()
        self.upload(mask)
        est = self.advance()
        est.timings["step"] = time.perf_counter() - t0
        return est

    def advance(self) -> TemplateEstimate:
        """Run one frame on the uploaded mask and return the estimate of that frame."""
        t0 = time.perf_counter()
        src, dst = self.parity, 1 - self.parity
        self._run_chain(src, dst)
        wp.synchronize_device(self.device)
        self.parity = dst
        est = self._estimate_from_host()
        est.timings["filter"] = time.perf_counter() - t0
        self.frames_done += 1
        return est

    def _object(self, label: int, kind: int, ground: np.ndarray, dims: np.ndarray, heading: float, speed: float):
        return TrackedObject(
            id=int(label),
            cls=CLASSES[kind - 1],
            position=self.plane.to_world(ground),
            ground=np.array(ground, dtype=np.float64),  # copies: the host buffers are reused every frame
            dims=np.array(dims, dtype=np.float64),
            heading=float(heading),
            speed=float(speed),
        )

    def _estimate_from_host(self) -> TemplateEstimate:
        h = self.host
        se = h["slot_est"].numpy()
        labels = h["slot_label"].numpy()
        kinds = h["slot_kind"].numpy()
        objects = []
        for s in range(self.r):
            exist = float(se[s, kslots.SE_EXIST])
            if exist >= self.config.min_existence and se[s, kslots.SE_COUNT] > 0 and kinds[s] > 0:
                o = self._object(
                    labels[s],
                    int(kinds[s]),
                    se[s, kslots.SE_X : kslots.SE_X + 2],
                    se[s, kslots.SE_DIMS : kslots.SE_DIMS + 3],
                    se[s, kslots.SE_HEADING],
                    se[s, kslots.SE_SPEED],
                )
                o.existence = exist
                o.std = se[s, kslots.SE_STD : kslots.SE_STD + 2].copy()
                o.age = float(se[s, kslots.SE_AGE])
                objects.append(o)
        for o, f in zip(objects, image_box_fraction(self.camera, self.plane, objects), strict=True):
            o.in_image = float(f)
        objects = [o for o in objects if o.in_image >= self.config.min_in_image]
        objects.sort(key=lambda o: o.id)
        bs = h["best_state"].numpy()
        best = []
        for s in range(self.r):
            k = int(bs[s, 0])
            if k > 0:
                v = bs[s, 5:7]
                speed = float(np.hypot(*v)) if k == 1 else abs(float(v[0]))
                heading = float(bs[s, 4]) + (math.pi if k == 2 and v[0] < 0 else 0.0)
                best.append(self._object(int(bs[s, 1]), k, bs[s, 2:4], bs[s, 7:10], heading, speed))
        add = h["add"].numpy()
        added = None
        if add[0] >= 0:
            added = (int(labels[add[0]]), CLASSES[int(kinds[add[0]]) - 1])
        est = TemplateEstimate(
            frame=self.frames_done,
            objects=objects,
            best=best,
            penalty=int(bs[0, 10]),
            foreground=int(h["qtotal"].numpy()[0]),
            ess=float(se[0, kslots.SE_ESS]),
            loglik=float(se[0, kslots.SE_LOGLIK]),
            added=added,
            # every log-weight -inf/NaN (floored in the score kernel): uniform weights, the predicted particles kept
            degenerate=bool(h["est"].numpy()[kreduce.EST_MAXLOGW] <= float(kreduce.LOGW_FLOOR)),
            groups=int(h["n_groups"].numpy()[0]) if self.partition else 1,
        )
        if self.keep_virtual:
            est.virtual = h["virtual"].numpy().copy()
        if self.keep_uoh:
            est.uoh = h["uoh"].numpy().copy()
        return est

    # --- diagnostics ---------------------------------------------------------------------------------------
    def render_virtual(self, particles: np.ndarray | None = None) -> np.ndarray:
        """Binary virtual scenes v_i (K, H, W) uint8 of the current particles (as scored by the next frame; for
        tests and reports; allocates, not for the frame loop)."""
        idx = np.arange(self.n, dtype=np.int32) if particles is None else np.asarray(particles, dtype=np.int32)
        self._raster(self.parity)
        out = wp.zeros((len(idx), self.height, self.width), dtype=wp.uint8, device=self.device)
        wp.launch(
            kraster.render_virtual_kernel,
            dim=(len(idx), self.height),
            inputs=[
                self.hulls.pts,
                self.hulls.n,
                self.hulls.rows,
                self.r * int(kraster.PIECES),
                wp.array(idx, dtype=wp.int32, device=self.device),
            ],
            outputs=[out],
            device=self.device,
        )
        return out.numpy()

    def particles(self) -> dict[str, np.ndarray]:
        """The current (predicted) particle state as host arrays: kind, label, pos, vel, heading, dims, age (N, R,
        ...), logw (N,). Copies: on the CPU ``wp.array.numpy()`` is a view of the tracker's memory, which the next
        frame overwrites."""
        s = self.state[self.parity]
        return {
            name: getattr(s, name).numpy().copy() for name in ("kind", "label", "pos", "vel", "heading", "dims", "age")
        } | {"logw": s.logw.numpy().copy()}

    def set_particles(self, **arrays: np.ndarray) -> None:
        """Overwrite fields of the current particle state (tests, warm starts): kind, label, pos, vel, heading,
        dims, age with shape (N, R, ...), logw (N,)."""
        s = self.state[self.parity]
        for name, value in arrays.items():
            target = getattr(s, name)
            target.assign(np.asarray(value).astype(target.numpy().dtype).reshape(target.numpy().shape))
        self.ancestors.assign(np.tile(np.arange(self.n, dtype=np.int32), (self.ancestors.shape[0], 1)))
        # one label and kind per slot, as the addition kernel keeps them
        kind, label = s.kind.numpy(), s.label.numpy()
        slot_label = np.full(self.r, -1, dtype=np.int32)
        slot_kind = np.zeros(self.r, dtype=np.int32)
        for slot in range(self.r):
            alive = np.flatnonzero(kind[:, slot] > 0)
            if len(alive):
                slot_label[slot] = label[alive[0], slot]
                slot_kind[slot] = kind[alive[0], slot]
        self.slot_label.assign(slot_label)
        self.slot_kind.assign(slot_kind)
        self.next_label.fill_(int(max(label.max(initial=-1), slot_label.max(initial=-1)) + 1))
