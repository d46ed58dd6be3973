"""S2: multi-camera 3D people tracker (Lopez-Cifuentes et al., multi-camera 3D particle filters with motion and
colour). Several people are tracked directly in 3D from two or more calibrated cameras with overlapping views; each
person has its own particle filter whose particles are 3D points inside the person, weighted by the motion masks of
all cameras and a multi-view HSV colour descriptor.

One frame::

    BGR frames + motion masks of every camera  -> device (one copy each)
    -> sigma_n from the previous frame (eq. 18)
    -> per person (one CUDA graph each on GPUs): gather + constant velocity (eq. 5) + appearance update (eq. 6)
       + descriptor (eqs. 19-22; HSV of eqs. 12-14 for the disc pixels) + motion x appearance likelihood
       (eqs. 7-11, 23-26) + block moments (fused), estimate, systematic resampling (every frame, section 2.1)
    -> ground evidence map (ours): cameras whose masks agree on a column over each ground cell
    -> host: estimates; people added where the evidence is unexplained, removed where it is gone (ours)

Units: metres (world frame, z up for the ground evidence map: the rig's ground is z = 0), pixels, frames.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from wptrack.cameras.rig import Rig
from wptrack.cameras.structs import DeviceRig
from wptrack.core.device import block_partition, resolve_device
from wptrack.core.errors import ConfigError, FrameError
from wptrack.core.filter import BLOCK, MAX_BLOCKS, ParticleFilter, arrays_state, check_state, load_arrays
from wptrack.io.frames import camera_frame
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.people import descriptor as kdesc
from wptrack.kernels.people import filter as kpeople
from wptrack.kernels.people import occupancy as kocc
from wptrack.trackers.people.config import PeopleConfig

log = logging.getLogger(__name__)

_GOLDEN = 0x9E3779B97F4A7C15
DESCRIPTOR_BLOCK = 64
"""Lanes per particle of the GPU descriptor (they share the disc pixels)."""
NOISE_STRIDE = 4
"""Pixels between the samples of the image-noise estimate (eq. 18)."""


def person_seed(seed: int, slot: int) -> int:
    """The 64-bit seed of pool slot ``slot``: the run seed mixed with the slot (splitmix64), so that the people's
    random streams differ and the same run seed gives the same streams."""
    z = (int(seed) + _GOLDEN * (slot + 1)) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & 0xFFFFFFFFFFFFFFFF
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & 0xFFFFFFFFFFFFFFFF
    return z ^ (z >> 31)


@dataclass
class PersonEstimate:
    """One tracked person in one frame.

    Attributes:
        id: persistent id (never reused in a run).
        centroid: (3,) the person's 3D centroid, metres: the particles' mean, its height from the standing-person
            model unless ``BodyConfig.centroid == "particles"`` (see :class:`~.people_model.BodyConfig`).
        top: top of the person's silhouette column, metres (NaN when not found).
        mean: (3,) weighted mean of the particles (the paper's estimate), metres.
        std: (3,) weighted standard deviation per axis, metres.
        map: (3,) best particle, metres.
        ess: effective sample size of the frame's weights.
        loglik: log of the mean weight (eq. 11 averaged over the particles).
        age: frames since the person was added.
        particles: (K, 3) subsample of the particles (before resampling), metres, or None.
        weights: (K,) their weights relative to the best particle, or None.
        degenerate: every particle's log-weight was -inf/NaN this frame (floored to ``kernels.core.reduce.LOGW_FLOOR``):
            the person's predicted particles were kept with uniform weights (the prior), the estimate is finite.
    """

    id: int
    centroid: np.ndarray
    top: float
    mean: np.ndarray
    std: np.ndarray
    map: np.ndarray
    ess: float
    loglik: float
    age: int
    particles: np.ndarray | None = None
    weights: np.ndarray | None = None
    degenerate: bool = False


@dataclass
class PeopleEstimate:
    """The tracker's output for one frame.

    Attributes:
        frame: 0-based frame number.
        people: the tracked people (added this frame: from the next frame on).
        sigma_n: image noise sigma_n of eq. 18 (V units, [0, 1]).
        added, removed: ids added / removed after this frame.
        timings: seconds per stage.
    """

    frame: int
    people: list[PersonEstimate]
    sigma_n: float
    added: list[int] = field(default_factory=list)
    removed: list[int] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)


def _all_pixel_rays(cam) -> np.ndarray:
    """(H W, 3) world directions of the viewing rays of every pixel of ``cam`` (row-major), distortion removed."""
    u, v = np.meshgrid(np.arange(cam.width, dtype=np.float64), np.arange(cam.height, dtype=np.float64))
    return cam.pixel_rays(np.column_stack([u.ravel(), v.ravel()]))


class PersonFilter(ParticleFilter):
    """One person's particle set (a slot of the tracker's pool): positions and log-weights from
    :class:`ParticleFilter`, plus, as (N, ...) ping-pong pairs: ``vel`` (metres/frame), ``model`` (appearance C,
    (N, 3 N_b)), ``desc`` (descriptor A at the particle, (N, 3 N_b)), ``mass`` (its total weight); ``rgb`` (N,)
    the patch's mean colour (eq. 17)."""

    def __init__(self, tracker: PeopleTracker, slot: int) -> None:
        cfg = tracker.config
        super().__init__(
            cfg.particles,
            cfg.dynamics.sigma_pos,
            tracker.device,
            seed=person_seed(cfg.seed, slot),
            resampling="systematic",
            ess_threshold=1.0,  # section 2.1: resample every frame
            keep_particles=tracker.keep_particles,
            use_graph=tracker.use_graph,
        )
        n, cols, d = self.n, 3 * cfg.descriptor.n_bins, self.device
        self.tracker = tracker
        self.slot = slot
        self.vel = [wp.zeros(n, dtype=wp.vec3, device=d) for _ in range(2)]
        self.model = [wp.zeros((n, cols), dtype=wp.float32, device=d) for _ in range(2)]
        self.desc = [wp.zeros((n, cols), dtype=wp.float32, device=d) for _ in range(2)]
        self.mass = [wp.zeros(n, dtype=wp.float32, device=d) for _ in range(2)]
        self.rgb = wp.zeros(n, dtype=wp.vec3, device=d)
        self.sigma_vel = wp.array([cfg.dynamics.sigma_vel], dtype=wp.float32, device=d)
        oc = cfg.occupancy
        self.grid_dims = tuple(int(v) for v in np.maximum(np.round(np.asarray(oc.extent) / oc.voxel), 1))
        self.grid = wp.zeros(self.grid_dims, dtype=wp.float32, device=d)  # occupancy pdf around the person, 1/m^3
        self.grid_host = wp.zeros(self.grid_dims, dtype=wp.float32, device="cpu", pinned=tracker.is_cuda)
        self.log_norm = wp.zeros(1, dtype=wp.float64, device=d)
        self._occupancy_cmds: dict[int, tuple[wp.Launch, wp.Launch]] = {}  # recorded launches per parity

    def state_arrays(self) -> dict[str, wp.array]:
        """:meth:`ParticleFilter.state_arrays` and the person's other particle fields, both buffers of each (velocity,
        appearance model C, descriptor A, mass), the patch colours and the velocity noise. The occupancy grid is
        recomputed when asked for."""
        arrays = super().state_arrays()
        for name in ("vel", "model", "desc", "mass"):
            for k, arr in enumerate(getattr(self, name)):
                arrays[f"{name}.{k}"] = arr
        arrays.update(rgb=self.rgb, sigma_vel=self.sigma_vel)
        return arrays

    def launch_occupancy(self, origin: np.ndarray) -> None:
        """Launch the occupancy grid of the current particles with its corner at ``origin`` (metres) into
        :attr:`grid` and its asynchronous copy into :attr:`grid_host` (recorded launches: a few microseconds of
        host time each instead of a full ``wp.launch``)."""
        cur = self.parity
        if cur not in self._occupancy_cmds:
            oc, d = self.tracker.config.occupancy, self.device
            norm = wp.launch(
                kocc.log_norm_kernel,
                dim=1,
                inputs=[self.est, int(kreduce.EST_LOGLIK), self.n],
                outputs=[self.log_norm],
                device=d,
                record_cmd=True,
            )
            grid = wp.launch(
                kocc.occupancy_kernel,
                dim=self.grid_dims,
                inputs=[self.x[cur], self.logw[cur], self.log_norm, oc.sigma, oc.cutoff, wp.vec3(0.0), oc.voxel],
                outputs=[self.grid],
                device=d,
                record_cmd=True,
            )
            self._occupancy_cmds[cur] = (norm, grid)
        norm, grid = self._occupancy_cmds[cur]
        grid.set_param_by_name("origin", wp.vec3(*(float(v) for v in origin)))
        norm.launch()
        grid.launch()
        wp.copy(self.grid_host, self.grid)  # asynchronous on CUDA (pinned)

    def spawn(self, xy: np.ndarray, frame: int) -> None:
        """Start the filter on a new person standing at ``xy`` (ground, metres): particles uniform in the
        configured cylinder, at rest, each with the descriptor at its position as appearance model C_0."""
        tr, b = self.tracker, self.tracker.config.birth
        cur, d = self.parity, self.device
        wp.launch(
            kpeople.init_cylinder_kernel,
            dim=self.n,
            inputs=[
                wp.vec3(float(xy[0]), float(xy[1]), 0.0),
                b.init_radius,
                b.init_z[0],
                b.init_z[1],
                self.seed,
                frame,
            ],
            outputs=[self.x[cur], self.vel[cur]],
            device=d,
        )
        dc = tr.config.descriptor
        wp.launch(
            kdesc.descriptor_kernel,
            dim=self.n,
            inputs=[
                tr.drig.cams,
                tr.bgr,
                self.x[cur],
                dc.r_n,
                dc.n_bins,
                dc.r_min,
                dc.r_max,
                dc.step,
            ],
            outputs=[self.desc[cur], self.mass[cur], self.rgb],
            device=d,
        )
        wp.copy(self.model[cur], self.desc[cur])  # C_0 = A_0
        self._reset_weights()

    def _launch_predict_score(self, src: int, dst: int) -> None:
        """One frame's particle work. CPU: the fused ``step_kernel`` (one pass per particle). CUDA: the same in three
        launches (predict, descriptor with one block per particle, score + block moments): the descriptor's ~300 disc
        pixels per particle are shared by a block's lanes instead of looping in one thread (a few thousand threads
        leave a GPU idle)."""
        tr, cfg = self.tracker, self.tracker.config
        dc, mo = cfg.descriptor, cfg.motion
        d = self.device
        if not self.is_cuda:
            wp.launch_tiled(
                kpeople.step_kernel,
                dim=[self.blocks],
                inputs=[
                    tr.drig.cams,
                    tr.mask,
                    mo.p_b,
                    mo.log_outside,
                    int(mo.drop_worst),
                    tr.bgr,
                    dc.r_n,
                    dc.n_bins,
                    dc.r_min,
                    dc.r_max,
                    dc.step,
                    self.x[src],
                    self.vel[src],
                    self.model[src],
                    self.desc[src],
                    self.mass[src],
                    self.ancestors,
                    self.logw[src],
                    self.resampled,
                    self.sigma,
                    self.sigma_vel,
                    cfg.dynamics.alpha,
                    tr.sigma_n,
                    dc.sigma_p,
                    self.seed,
                    self.frame,
                    self.n,
                    self.chunk,
                ],
                outputs=[
                    self.x[dst],
                    self.vel[dst],
                    self.model[dst],
                    self.desc[dst],
                    self.mass[dst],
                    self.rgb,
                    self.logw[dst],
                    self.part_max,
                    self.part_arg,
                    self.part,
                ],
                block_dim=BLOCK,
                device=d,
            )
            return
        wp.launch(
            kpeople.predict_kernel,
            dim=self.n,
            inputs=[
                self.x[src],
                self.vel[src],
                self.model[src],
                self.desc[src],
                self.mass[src],
                self.ancestors,
                self.sigma,
                self.sigma_vel,
                cfg.dynamics.alpha,
                self.seed,
                self.frame,
            ],
            outputs=[self.x[dst], self.vel[dst], self.model[dst]],
            device=d,
        )
        wp.launch_tiled(
            kdesc.descriptor_block_kernel,
            dim=[self.n],
            inputs=[tr.drig.cams, tr.bgr, self.x[dst], dc.r_n, dc.n_bins, dc.r_min, dc.r_max, dc.step],
            outputs=[self.desc[dst], self.mass[dst], self.rgb],
            block_dim=DESCRIPTOR_BLOCK,
            device=d,
        )
        wp.launch_tiled(
            kpeople.score_moments_kernel,
            dim=[self.blocks],
            inputs=[
                tr.drig.cams,
                tr.mask,
                mo.p_b,
                mo.log_outside,
                int(mo.drop_worst),
                self.x[dst],
                self.model[dst],
                self.desc[dst],
                self.mass[dst],
                self.rgb,
                dc.n_bins,
                self.logw[src],
                self.resampled,
                tr.sigma_n,
                dc.sigma_p,
                self.n,
                self.chunk,
            ],
            outputs=[self.logw[dst], self.part_max, self.part_arg, self.part],
            block_dim=BLOCK,
            device=d,
        )

    def estimate_from_host(self, person_id: int, age: int) -> PersonEstimate:
        """The estimate of the last frame from the host copies (after the device synchronised)."""
        e = self.est_host.numpy()
        mean = e[kreduce.EST_MEAN : kreduce.EST_MEAN + 3].copy()
        est = PersonEstimate(
            id=person_id,
            centroid=mean.copy(),
            top=float("nan"),
            mean=mean,
            std=e[kreduce.EST_STD : kreduce.EST_STD + 3].copy(),
            map=e[kreduce.EST_MAP : kreduce.EST_MAP + 3].copy(),
            ess=float(e[kreduce.EST_ESS]),
            loglik=float(e[kreduce.EST_LOGLIK]),
            age=age,
            degenerate=bool(e[kreduce.EST_DEGENERATE]),
        )
        if self.keep:
            est.particles = self.sub_x_host.numpy().copy()
            est.weights = self.sub_w_host.numpy().copy()
        return est


class PeopleTracker:
    """S2 people tracker on a rig of two or more cameras.

    Args:
        rig: calibrated cameras with overlapping views (ground plane z = 0; ``rig.volume`` bounds the evidence map).
        config: :class:`wptrack.trackers.people.config.PeopleConfig`.
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``.
        use_graph: capture each person's frame chain as a CUDA graph (default: on CUDA).
        keep_particles: particles per person and frame returned for reports and hulls (0: none).

    Device buffers (P = pixels of all cameras):
        bgr, bgr_prev: (3 P,) uint8 this and the previous frame. mask: (P,) uint8 motion masks (nonzero = motion).
        sigma_n: (1,) float32 image noise (eq. 18, from every ``NOISE_STRIDE``-th pixel).
        rays: (P,) vec3 world direction of every pixel's viewing ray.
        votes, free_votes: (nx * ny,) int32 ground evidence map: cameras voting for each cell, with all motion /
            with the motion not explained by a tracked person.

    Raises:
        ConfigError: fewer than two cameras, a bad configuration or a pool that does not fit the device.
    """

    def __init__(
        self,
        rig: Rig,
        config: PeopleConfig | None = None,
        device: str | None = "auto",
        use_graph: bool | None = None,
        keep_particles: int = 200,
    ) -> None:
        config = config if config is not None else PeopleConfig()
        if not isinstance(config, PeopleConfig):
            raise ConfigError(f"config: expected a PeopleConfig, got {type(config).__name__}")
        if len(rig) < 2:
            raise ConfigError(
                f"the people tracker needs two or more calibrated cameras with overlapping views; "
                f"{rig.source} has {len(rig)}"
            )
        if keep_particles < 0:
            raise ConfigError(f"keep_particles: expected >= 0, got {keep_particles}")
        self.config = config
        self.rig = rig
        dev = wp.get_device(resolve_device(device))
        self.device = d = str(dev)
        self.is_cuda = dev.is_cuda
        self.use_graph = self.is_cuda if use_graph is None else (bool(use_graph) and self.is_cuda)
        self.keep_particles = min(int(keep_particles), config.particles)
        self.drig = DeviceRig(rig, d)
        npx = self.drig.total_pixels
        self.bgr = wp.zeros(3 * npx, dtype=wp.uint8, device=d)
        self.bgr_prev = wp.zeros(3 * npx, dtype=wp.uint8, device=d)
        self.mask = wp.zeros(npx, dtype=wp.uint8, device=d)
        self.sigma_n = wp.zeros(1, dtype=wp.float32, device=d)
        # eq. 18 over every NOISE_STRIDE-th pixel (a mean square estimated from ~1e5 values is as good as from all)
        self.noise_values = 3 * len(range(0, npx, NOISE_STRIDE))
        self.noise_blocks, self.noise_chunk = block_partition(self.noise_values, not self.is_cuda, BLOCK, MAX_BLOCKS)
        self.noise_part = wp.zeros(self.noise_blocks, dtype=wp.float64, device=d)
        pinned = self.is_cuda
        self._bgr_host = wp.zeros(3 * npx, dtype=wp.uint8, device="cpu", pinned=pinned)
        self._mask_host = wp.zeros(npx, dtype=wp.uint8, device="cpu", pinned=pinned)
        self._sigma_host = wp.zeros(1, dtype=wp.float32, device="cpu", pinned=pinned)
        # ground evidence map over the rig's working volume
        b = config.birth
        lo, hi = rig.bounds()
        self.grid_origin = np.array([lo[0], lo[1]], dtype=np.float64)
        self.nx = max(1, int(math.ceil((hi[0] - lo[0]) / b.cell)))
        self.ny = max(1, int(math.ceil((hi[1] - lo[1]) / b.cell)))
        self.volume = (np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64))
        self.heights = wp.array(np.asarray(b.heights, dtype=np.float32), dtype=wp.float32, device=d)
        self.votes = wp.zeros(self.nx * self.ny, dtype=wp.int32, device=d)
        self.free_votes = wp.zeros(self.nx * self.ny, dtype=wp.int32, device=d)
        self._votes_host = wp.zeros(self.nx * self.ny, dtype=wp.int32, device="cpu", pinned=pinned)
        self._free_host = wp.zeros(self.nx * self.ny, dtype=wp.int32, device="cpu", pinned=pinned)
        rays = np.concatenate([_all_pixel_rays(cam) for cam in rig.cameras]).astype(np.float32)
        self.rays = wp.array(rays, dtype=wp.vec3, device=d)  # (P,) world direction of every pixel's viewing ray
        self.people_xy = wp.zeros(b.max_people, dtype=wp.vec2, device=d)  # the tracked people's ground positions
        body = config.body
        self.column_z_lo = 0.05
        self.column_nz = int((float(self.volume[1][2]) - self.column_z_lo) / body.step) + 1
        axes = kpeople.COLUMN_AXES
        self.column_seen = wp.zeros((b.max_people, axes, self.column_nz), dtype=wp.uint8, device=d)
        self.top = wp.zeros((b.max_people, axes), dtype=wp.float32, device=d)  # per person and axis
        self._top_host = wp.zeros((b.max_people, axes), dtype=wp.float32, device="cpu", pinned=pinned)
        self.min_votes = min(b.min_cameras, len(rig))
        self._centres: tuple[np.ndarray, np.ndarray] | None = None
        # the pool of person filters, allocated once
        self.pool = [PersonFilter(self, k) for k in range(b.max_people)]
        self.slot_id = np.full(b.max_people, -1, dtype=np.int64)  # person id per slot, -1 = free
        self.slot_age = np.zeros(b.max_people, dtype=np.int64)
        self.slot_miss = np.zeros(b.max_people, dtype=np.int64)
        self.slot_close = np.zeros(b.max_people, dtype=np.int64)
        self.pending = np.zeros((0, 3), dtype=np.float64)  # x, y, consecutive frames of unexplained evidence
        self.next_id = 0
        self.frames_done = 0
        log.info(
            "people tracker: %d particles per person, up to %d people, %d cameras, evidence map %dx%d, device %s",
            config.particles,
            b.max_people,
            len(rig),
            self.nx,
            self.ny,
            self.device,
        )

    # --- observation ---------------------------------------------------------------------------------
    def upload(self, images: Sequence[np.ndarray], masks: Sequence[np.ndarray]) -> None:
        """Validate one BGR image and one motion mask per camera and copy them to the device.

        Raises:
            FrameError: wrong count, type or size (the message names the camera).
        """
        cams = self.rig.cameras
        if len(images) != len(cams) or len(masks) != len(cams):
            raise FrameError(f"got {len(images)} images and {len(masks)} masks for a rig of {len(cams)} cameras")
        offs = self.drig.pixel_offsets
        bgr, msk = self._bgr_host.numpy(), self._mask_host.numpy()
        for c, (img, m, cam) in enumerate(zip(images, masks, cams, strict=True)):
            img, m = camera_frame(img, cam), camera_frame(m, cam, "mask")
            if m.dtype != np.uint8 and m.dtype != np.bool_:
                m = m != 0
            bgr[3 * offs[c] : 3 * offs[c + 1]] = img.reshape(-1)
            msk[offs[c] : offs[c + 1]] = m.reshape(-1)  # the kernels read nonzero as motion
        wp.copy(self.bgr, self._bgr_host)
        wp.copy(self.mask, self._mask_host)

    def _observe(self) -> None:
        d = self.device
        if self.frames_done == 0:
            wp.copy(self.bgr_prev, self.bgr)  # no previous frame: sigma_n = 0 (the floor of eqs. 15-17)
        wp.launch_tiled(
            kdesc.noise_partials_kernel,
            dim=[self.noise_blocks],
            inputs=[self.bgr_prev, self.bgr, self.noise_values, NOISE_STRIDE, self.noise_chunk],
            outputs=[self.noise_part],
            block_dim=BLOCK,
            device=d,
        )
        wp.launch_tiled(
            kdesc.noise_sigma_kernel,
            dim=[1],
            inputs=[self.noise_part, self.noise_blocks, self.noise_values],
            outputs=[self.sigma_n],
            block_dim=BLOCK,
            device=d,
        )
        wp.copy(self.bgr_prev, self.bgr)

    def _evidence(self, n: int) -> None:
        """The ground evidence map and the column tops, with the motion of the ``n`` people tracked after this
        frame's prediction explained (``people_xy[:n]``, filled on the device from their estimates); the results are
        copied to the host asynchronously (the frame's one synchronisation follows)."""
        b = self.config.birth
        wp.launch(
            kpeople.ground_votes_kernel,
            dim=self.nx * self.ny,
            inputs=[
                self.drig.cams,
                self.mask,
                self.rays,
                self.heights,
                self.people_xy,
                n,
                b.person_radius,
                b.person_height,
                wp.vec2(*self.grid_origin),
                b.cell,
                self.nx,
                b.min_fraction,
            ],
            outputs=[self.votes, self.free_votes],
            device=self.device,
        )
        wp.copy(self._votes_host, self.votes)
        wp.copy(self._free_host, self.free_votes)
        if n:
            body = self.config.body
            axes = kpeople.COLUMN_AXES
            wp.launch(
                kpeople.column_seen_kernel,
                dim=(n, axes, self.column_nz),
                inputs=[self.drig.cams, self.mask, self.people_xy, self.column_z_lo, body.step, body.search],
                outputs=[self.column_seen],
                device=self.device,
            )
            wp.launch(
                kpeople.column_top_kernel,
                dim=(n, axes),
                inputs=[
                    self.column_seen,
                    self.column_z_lo,
                    body.step,
                    self.column_nz,
                    min(body.min_cameras, len(self.rig)),
                    int(round(body.max_gap / body.step)),
                ],
                outputs=[self.top],
                device=self.device,
            )
            wp.copy(self._top_host, self.top)

    # --- the frame --------------------------------------------------------------------------------------
    def step(
        self, images: Sequence[np.ndarray] | tuple[Sequence[np.ndarray], Sequence[np.ndarray]], masks=None
    ) -> PeopleEstimate:
        """Track one synchronised set of frames: one (H, W, 3) uint8 BGR image and one (H, W) motion mask
        (nonzero = motion) per camera, in rig order; ``step(images, masks)`` or ``step((images, masks))`` (the
        observation of the tracker contract, :class:`wptrack.core.filter.Tracker`)."""
        if masks is None:
            images, masks = images
        t0 = time.perf_counter()
        self.upload(images, masks)
        t1 = time.perf_counter()
        self._observe()
        active = [k for k in range(len(self.pool)) if self.slot_id[k] >= 0]
        for j, k in enumerate(active):
            p = self.pool[k]
            p.launch_frame()
            wp.launch(
                kpeople.person_xy_kernel,
                dim=1,
                inputs=[p.est, int(kreduce.EST_MEAN), j],
                outputs=[self.people_xy],
                device=self.device,
            )
        self._evidence(len(active))
        wp.copy(self._sigma_host, self.sigma_n)
        wp.synchronize_device(self.device)  # the frame's one synchronisation: estimates, evidence, tops on the host
        t2 = time.perf_counter()
        people = []
        tops = self._top_host.numpy().max(axis=1)  # the highest of each person's axes
        body = self.config.body
        for j, k in enumerate(active):
            self.slot_age[k] += 1
            person = self.pool[k].estimate_from_host(int(self.slot_id[k]), int(self.slot_age[k]))
            if tops[j] > 0:
                person.top = float(tops[j])
                if body.centroid == "standing":
                    person.centroid[2] = body.ratio * person.top  # standing-person model (BodyConfig)
            people.append(person)
        est = PeopleEstimate(frame=self.frames_done, people=people, sigma_n=float(self._sigma_host.numpy()[0]))
        self._update_population(est, active, tops[: len(active)] > 0)
        self.frames_done += 1
        est.timings.update(upload=t1 - t0, filter=t2 - t1, population=time.perf_counter() - t2)
        return est

    def track(
        self,
        observations: Iterable[tuple[Sequence[np.ndarray], Sequence[np.ndarray]]],
        max_frames: int | None = None,
    ) -> Iterator[PeopleEstimate]:
        """Iterate over ``(images, masks)`` per frame (e.g. ``zip(open_frames(videos), motion_masks)``), yielding one
        estimate each, for at most ``max_frames`` frames."""
        for k, obs in enumerate(observations):
            if max_frames is not None and k >= max_frames:
                return
            yield self.step(obs)

    # --- who is there (ours) ---------------------------------------------------------------------------------
    def _cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of the evidence map's cell centres, metres, (ny, nx) each (computed once)."""
        if self._centres is None:
            c = self.config.birth.cell
            xs = self.grid_origin[0] + c * (np.arange(self.nx) + 0.5)
            ys = self.grid_origin[1] + c * (np.arange(self.ny) + 0.5)
            self._centres = tuple(np.meshgrid(xs, ys))
        return self._centres

    def _update_population(self, est: PeopleEstimate, active: list[int], column: np.ndarray) -> None:
        """Remove people without multi-view support, duplicates and people who left; add people where the
        evidence is unexplained for several frames. Host code on the small evidence map.

        A person is supported while motion seen by several cameras is found either on its silhouette column
        (``column[j]``: the column-top search found a point, which stays true when furniture hides everything
        but the head and shoulders) or in a cell of the evidence map within ``support_radius``."""
        b = self.config.birth
        votes = self._votes_host.numpy().reshape(self.ny, self.nx)
        free_votes = self._free_host.numpy().reshape(self.ny, self.nx)
        support = votes >= self.min_votes
        gx, gy = self._cell_centres()
        lo, hi = self.volume
        margin = 0.5
        by_slot = {k: e for k, e in zip(active, est.people, strict=True)}
        for j, (k, e) in enumerate(by_slot.items()):
            x, y = e.mean[0], e.mean[1]
            near = (gx - x) ** 2 + (gy - y) ** 2 <= b.support_radius**2
            self.slot_miss[k] = 0 if column[j] or np.any(support & near) else self.slot_miss[k] + 1
            outside = np.any(e.mean[:2] < lo[:2] - margin) or np.any(e.mean[:2] > hi[:2] + margin)
            if self.slot_miss[k] >= b.frames_to_remove or outside or not np.all(np.isfinite(e.mean)):
                self._remove(k, est)
        # duplicates: two filters on one person
        alive = [k for k in active if self.slot_id[k] >= 0]
        for k in alive:
            close = any(
                np.hypot(*(by_slot[k].mean[:2] - by_slot[j].mean[:2])) < b.merge_distance
                for j in alive
                if j != k and self.slot_id[j] >= 0
            )
            self.slot_close[k] = self.slot_close[k] + 1 if close else 0
        for k in sorted(alive, key=lambda s: -self.slot_id[s]):  # the younger of a pair goes
            if self.slot_id[k] >= 0 and self.slot_close[k] >= b.frames_to_remove:
                self._remove(k, est)
                for j in alive:
                    self.slot_close[j] = 0
        # unexplained evidence -> candidates; at most one person added per frame, the strongest (see BirthConfig)
        free = free_votes >= self.min_votes
        for k in range(len(self.pool)):  # people added or kept this frame explain their surroundings
            if self.slot_id[k] >= 0 and k in by_slot:
                e = by_slot[k]
                free &= (gx - e.mean[0]) ** 2 + (gy - e.mean[1]) ** 2 > b.exclusion**2
        candidates = self._blobs(free, free_votes, gx, gy)
        pending, added = [], False
        for cx, cy, _strength in sorted(candidates, key=lambda c: -c[2]):
            count = 1.0
            if len(self.pending):
                dist = np.hypot(self.pending[:, 0] - cx, self.pending[:, 1] - cy)
                j = int(np.argmin(dist))
                if dist[j] < 0.5:
                    count = self.pending[j, 2] + 1
            if count >= b.frames_to_add and not added:
                self._add(np.array([cx, cy]), est)
                added = True
            else:
                pending.append((cx, cy, min(count, b.frames_to_add)))
        self.pending = np.asarray(pending, dtype=np.float64).reshape(-1, 3)

    def _blobs(
        self, free: np.ndarray, votes: np.ndarray, gx: np.ndarray, gy: np.ndarray
    ) -> list[tuple[float, float, float]]:
        """Vote-weighted centroids and total votes of the connected regions of ``free`` cells with at least
        ``min_area`` cells."""
        if not free.any():
            return []
        import cv2

        count, labels, stats, _ = cv2.connectedComponentsWithStats(free.astype(np.uint8), connectivity=8)
        out = []
        for lab in range(1, count):
            if stats[lab, cv2.CC_STAT_AREA] < self.config.birth.min_area:
                continue
            sel = labels == lab
            w = votes[sel].astype(np.float64)
            out.append((float(np.sum(gx[sel] * w) / w.sum()), float(np.sum(gy[sel] * w) / w.sum()), float(w.sum())))
        return out

    def _add(self, xy: np.ndarray, est: PeopleEstimate) -> None:
        free = np.nonzero(self.slot_id < 0)[0]
        if not free.size:
            log.warning("frame %d: no free slot for a new person at %s (max_people reached)", est.frame, xy.round(2))
            return
        k = int(free[0])
        self.pool[k].spawn(xy, self.frames_done)
        self.slot_id[k] = self.next_id
        self.slot_age[k] = 0
        self.slot_miss[k] = 0
        self.slot_close[k] = 0
        est.added.append(self.next_id)
        log.info("frame %d: person %d added at (%.2f, %.2f)", est.frame, self.next_id, xy[0], xy[1])
        self.next_id += 1

    def _remove(self, k: int, est: PeopleEstimate) -> None:
        est.removed.append(int(self.slot_id[k]))
        log.info("frame %d: person %d removed", est.frame, self.slot_id[k])
        self.slot_id[k] = -1

    # --- outputs beyond the estimate ------------------------------------------------------------------------
    def occupancy(self, person_id: int) -> tuple[np.ndarray, np.ndarray]:
        """The occupancy pdf (3D Gaussian kernel over the particles, Figs. 6 and 8) of a tracked person on a voxel
        grid of ``config.occupancy.extent`` around its estimate, after the last frame.

        Returns:
            ``(origin (3,), grid (nx, ny, nz) float32)``: the corner of voxel (0, 0, 0), metres, and the density
            per cubic metre (voxel edge ``config.occupancy.voxel``).

        Raises:
            ConfigError: ``person_id`` is not tracked.
        """
        return self.occupancies([person_id])[person_id]

    def occupancies(self, person_ids: Sequence[int] | None = None) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """:meth:`occupancy` of several people (default: everybody tracked): every grid is launched into the
        person's buffer (allocated once), then one synchronisation and the copies back."""
        ids = self.tracked_ids if person_ids is None else [int(i) for i in person_ids]
        oc = self.config.occupancy
        launched = {}
        for pid in ids:
            slots = np.nonzero(self.slot_id == pid)[0]
            if not slots.size:
                raise ConfigError(f"person {pid} is not tracked")
            p = self.pool[int(slots[0])]
            centre = p.est_host.numpy()[kreduce.EST_MEAN : kreduce.EST_MEAN + 3]
            dims = np.asarray(p.grid_dims)
            origin = np.floor((centre - 0.5 * dims * oc.voxel) / oc.voxel) * oc.voxel  # on the voxel lattice
            p.launch_occupancy(origin)
            launched[pid] = (origin, p)
        wp.synchronize_device(self.device)
        return {pid: (origin, p.grid_host.numpy().copy()) for pid, (origin, p) in launched.items()}

    def add_person(self, xy: Sequence[float]) -> int:
        """Start tracking a person standing at ``xy`` (ground x, y, metres) now, as if added by the evidence (e.g.
        known initial positions). Returns its id.

        Raises:
            ConfigError: every slot of the pool is taken (``BirthConfig.max_people``).
        """
        if not np.any(self.slot_id < 0):
            raise ConfigError(f"max_people ({len(self.pool)}) people are tracked already")
        est = PeopleEstimate(frame=self.frames_done, people=[], sigma_n=0.0)
        self._add(np.asarray(xy, dtype=np.float64)[:2], est)
        return est.added[0]

    @property
    def tracked_ids(self) -> list[int]:
        """Ids of the people tracked now."""
        return [int(i) for i in self.slot_id if i >= 0]

    # --- checkpoints -----------------------------------------------------------------------------------------
    _HOST_ARRAYS = ("slot_id", "slot_age", "slot_miss", "slot_close", "pending")
    """The population bookkeeping kept on the host (per slot: person id, age, missed and close frames; pending
    births)."""

    def state_arrays(self) -> dict[str, wp.array]:
        """The device arrays that carry the tracker to the next frame: the previous frame (the noise estimate of eq. 18
        differences consecutive frames) and every slot's person filter (``person<k>.<name>``, see
        :meth:`PersonFilter.state_arrays`), free slots included (a checkpoint has the same names whoever is tracked)."""
        arrays = {"bgr_prev": self.bgr_prev}
        for k, p in enumerate(self.pool):
            arrays.update({f"person{k}.{name}": arr for name, arr in p.state_arrays().items()})
        return arrays

    def host_state(self) -> dict[str, np.ndarray]:
        """The population bookkeeping, the next id, the frame count and each slot's parity and frame count."""
        state = {f"__{name}__": getattr(self, name).copy() for name in self._HOST_ARRAYS}
        state["__next_id__"] = np.int64(self.next_id)
        state["__frames_done__"] = np.int64(self.frames_done)
        state["__parity__"] = np.array([p.parity for p in self.pool], dtype=np.int64)
        state["__person_frames__"] = np.array([p.frames_done for p in self.pool], dtype=np.int64)
        return state

    def state_dict(self) -> dict[str, np.ndarray]:
        """The whole state after the last frame (:meth:`state_arrays` and :meth:`host_state`), for
        :meth:`load_state_dict`. Syncs with the device: not for the frame loop."""
        return {**arrays_state(self.state_arrays()), **self.host_state()}

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restore a :meth:`state_dict` into a tracker built with the same rig and configuration.

        Raises:
            ConfigError: the state does not match this tracker (names missing or unexpected, other shapes or types).
        """
        arrays = self.state_arrays()
        check_state(arrays, state, tuple(self.host_state()))
        load_arrays(arrays, state)
        for name in self._HOST_ARRAYS:
            setattr(self, name, np.array(state[f"__{name}__"]))
        self.next_id = int(state["__next_id__"])
        self.frames_done = int(state["__frames_done__"])
        for p, parity, frames in zip(self.pool, state["__parity__"], state["__person_frames__"], strict=True):
            p.parity, p.frames_done = int(parity), int(frames)
        wp.synchronize_device(self.device)
