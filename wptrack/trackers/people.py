"""S2: multi-camera 3D people tracker (Lopez-Cifuentes et al., multi-camera 3D particle filters with motion and
colour). Several people are tracked directly in 3D from two or more calibrated cameras with overlapping views; each
person has its own particle filter whose particles are 3D points inside the person, weighted by the motion masks of
all cameras and a multi-view HSV colour descriptor; beyond the paper (ours, after the Probabilistic Occupancy Map of
Fleuret, Berclaz, Lengagne and Fua, PAMI 2008) each particle's weight also judges the whole person: the rectangle of
a person standing at its ground position must explain motion the other tracked people do not (``kernels/coverage.py``).

One frame::

    BGR frames + motion masks of every camera  -> device (one copy each)
    -> sigma_n from the previous frame (eq. 18); the masks' integral images
    -> per person (one CUDA graph each on GPUs): the gate (do this frame's masks show the person?) + gather +
       constant velocity (eq. 5, dt in seconds) + appearance update (eq. 6) + descriptor (eqs. 19-22; HSV of eqs.
       12-14 for the disc pixels) + motion x appearance likelihood (eqs. 7-11, 23-26) x the person terms (ours) +
       block moments (fused), estimate, systematic resampling (every frame, section 2.1)
    -> the tracked people's rectangles; the evidence map (ours): coverage of a person's rectangle at each ground
       cell by the motion nobody explains; the people's appearance histograms (re-identification)
    -> host: estimates; people added where the evidence is unexplained, removed when the masks stop showing them,
       re-identified when they come back (ours)

Units: metres (world frame, z up for the ground evidence map: the rig's ground is z = 0), pixels, seconds (the
frame interval dt from ``PeopleConfig.fps`` or the frames' timestamps).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from wptrack.device import block_partition, resolve_device
from wptrack.errors import ConfigError, FrameError
from wptrack.kernels import colour as kcolour
from wptrack.kernels import coverage as kcov
from wptrack.kernels import descriptor as kdesc
from wptrack.kernels import occupancy as kocc
from wptrack.kernels import people as kpeople
from wptrack.kernels import reduce as kreduce
from wptrack.pf import BLOCK, MAX_BLOCKS, ParticleFilter, _device_arrays
from wptrack.rig import Rig
from wptrack.warpcams import DeviceRig

from .people_area import working_area
from .people_model import PeopleConfig

log = logging.getLogger(__name__)

_GOLDEN = 0x9E3779B97F4A7C15
DEFAULT_FPS = 25.0
"""Frame rate assumed by a tracker built without ``PeopleConfig.fps`` and stepped without timestamps."""
DESCRIPTOR_BLOCK = 64
"""Lanes per particle of the GPU descriptor (they share the disc pixels)."""
STILL_SPEED = 0.3
"""A person walking slower than this (metres per second) when the masks lose it is taken to stand still."""
STILL_WINDOW = 1.0
"""Seconds over which a person's ground speed is measured."""
COVERAGE_ROWS = 120
"""The person rectangles are counted on masks reduced to about this many rows (``coverage_scale``)."""
GATE_SPACING = 0.125
"""Spacing of the points the gate tries around a person's last position, metres (``kernels.coverage.gate_kernel``)."""
MIN_APPEARANCE_PX = 100
"""Pixels of its own a body part needs in a frame to update a person's appearance (all cameras together)."""
WALK_SPEED = 1.5
"""Walking speed, metres per second: how far a lost person may have gone (re-identification)."""
MAX_SPEED = 2.0
"""A brisk walk, metres per second: how far evidence may move between frames and stay the same candidate."""
LEAVE_MARGIN = 0.5
"""A person farther than this from the ground that any camera sees (the rig's volume when it has one) has left,
metres."""
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
        support: how much of its rectangle (what the other people's rectangles leave of it) the masks cover near the
            person's last position (``kernels.coverage.gate_kernel``), a fraction; <= ``PersonConfig.gate``: not seen
            this frame.
        particles: (K, 3) subsample of the particles (before resampling), metres, or None.
        weights: (K,) their weights relative to the best particle, or None.
        occupancy: ``(origin (3,), grid (nx, ny, nz) float32)``: the occupancy pdf of this frame's particles (see
            :meth:`PeopleTracker.occupancy`), when the frame was stepped with ``occupancy=True``, else None. It is
            computed before the population update, so every person of the estimate has one, also a person removed
            after this frame.
        degenerate: every particle's log-weight was -inf/NaN this frame (floored to ``kernels.reduce.LOGW_FLOOR``):
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
    support: float = 0.0
    particles: np.ndarray | None = None
    weights: np.ndarray | None = None
    occupancy: tuple[np.ndarray, np.ndarray] | None = None
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


def coverage_scale(rig: Rig) -> int:
    """Block size of the reduced masks the person rectangles are counted on: about ``COVERAGE_ROWS`` rows for the
    smallest camera (1: full size for images of up to 180 rows; at most 15, so a block count fits a byte)."""
    rows = min(cam.height for cam in rig.cameras)
    return int(min(15, max(1, round(rows / COVERAGE_ROWS))))


def reduced_camera(cam, scale: int):
    """``cam`` for its image reduced by ``scale`` x ``scale`` blocks (``kernels.coverage.downsample_mask_kernel``):
    the block (u, v) covers the full pixels (scale u .. scale u + scale - 1, ...), whose centre is at full
    coordinate scale u + (scale - 1) / 2, so f' = f / scale and c' = (c - (scale - 1) / 2) / scale; the remainder
    columns and rows (width % scale, height % scale) are left out."""
    from wptrack.rig import Camera

    if scale == 1:
        return cam
    K = np.array(cam.K, dtype=np.float64)
    K[0, 0] /= scale
    K[1, 1] /= scale
    K[0, 2] = (K[0, 2] - 0.5 * (scale - 1)) / scale
    K[1, 2] = (K[1, 2] - 0.5 * (scale - 1)) / scale
    return Camera(
        name=cam.name, width=cam.width // scale, height=cam.height // scale, K=K, dist=cam.dist, R=cam.R, t=cam.t
    )


class PersonFilter(ParticleFilter):
    """One person's particle set (a slot of the tracker's pool): positions and log-weights from
    :class:`ParticleFilter`, plus, as (N, ...) ping-pong pairs: ``vel`` (metres/second), ``model`` (appearance C,
    (N, 3 N_b)), ``desc`` (descriptor A at the particle, (N, 3 N_b)), ``mass`` (its total weight); ``rgb`` (N,)
    the patch's mean colour (eq. 17)."""

    def __init__(self, tracker: PeopleTracker, slot: int) -> None:
        cfg = tracker.config
        super().__init__(
            cfg.particles,
            tracker.frame_dynamics[0],
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
        self.observe = wp.ones(2, dtype=wp.int32, device=d)  # [0] this frame's masks show the person, [1] the last
        self.support = wp.zeros(1, dtype=wp.float32, device=d)  # [0] the gate's best rectangle term, nats
        self.support_host = wp.zeros(1, dtype=wp.float32, device="cpu", pinned=tracker.is_cuda)
        oc = cfg.occupancy
        self.grid_dims = tuple(int(v) for v in np.maximum(np.round(np.asarray(oc.extent) / oc.voxel), 1))
        self.grid = wp.zeros(self.grid_dims, dtype=wp.float32, device=d)  # occupancy pdf around the person, 1/m^3
        self.grid_host = wp.zeros(self.grid_dims, dtype=wp.float32, device="cpu", pinned=tracker.is_cuda)
        self.log_norm = wp.zeros(1, dtype=wp.float64, device=d)
        self._occupancy_cmds: dict[int, tuple[wp.Launch, wp.Launch]] = {}  # recorded launches per parity

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

    def _launch_observation(self) -> None:
        """Whether this frame's masks show the person (``kernels.coverage.gate_kernel``, into :attr:`observe`)."""
        tr, pc = self.tracker, self.tracker.config.person
        wp.launch(
            kcov.gate_kernel,
            dim=1,
            inputs=[tr.sdrig.cams, tr.integral, tr.boxes, tr.slot_xy, self.slot, tr.terms]
            + [pc.gate_reach, WALK_SPEED, tr.dt, GATE_SPACING, pc.gate, pc.gate_left],
            outputs=[self.observe, self.support],
            device=self.device,
        )

    def _readback(self) -> None:
        super()._readback()
        wp.copy(self.support_host, self.support)

    def spawn(self, xy: np.ndarray, frame: int) -> None:
        """Start the filter on a new person standing at ``xy`` (ground, metres): particles uniform in the
        configured cylinder, with random horizontal velocities (``BirthConfig.init_speed``), each with the
        descriptor at its position as appearance model C_0."""
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
                b.init_speed,
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
        self.observe.fill_(1)
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
                    tr.sigma_vel,
                    tr.dt,
                    tr.alpha,
                    self.observe,
                    tr.decay,
                    tr.sigma_n,
                    dc.sigma_p,
                    self.seed,
                    self.frame,
                    tr.sdrig.cams,
                    tr.integral,
                    tr.slot_xy,
                    tr.slot_alive,
                    tr.boxes,
                    self.slot,
                    tr.terms,
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
                tr.sigma_vel,
                tr.dt,
                tr.alpha,
                self.observe,
                tr.decay,
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
                tr.sdrig.cams,
                tr.integral,
                tr.slot_xy,
                tr.slot_alive,
                tr.boxes,
                self.slot,
                tr.terms,
                self.observe,
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
            support=float(self.support_host.numpy()[0]),
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
        config: :class:`wptrack.trackers.people_model.PeopleConfig`.
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``.
        use_graph: capture each person's frame chain as a CUDA graph (default: on CUDA).
        keep_particles: particles per person and frame returned for reports and hulls (0: none).

    Time: the frame interval dt is ``1 / config.fps`` (``DEFAULT_FPS`` when None) unless :meth:`step` is given
    timestamps; the dynamics (``DynamicsConfig.per_frame``) and the birth and removal times follow it.

    Device buffers (P = pixels of all cameras):
        bgr, bgr_prev: (3 P,) uint8 this and the previous frame. mask: (P,) uint8 motion masks (nonzero = motion).
        sigma_n: (1,) float32 image noise (eq. 18, from every ``NOISE_STRIDE``-th pixel).
        integral, free_integral: the (H+1) x (W+1) integral images of the masks and of the motion the tracked people's
            rectangles leave (``free_mask``). boxes: (max_people, cameras) vec4 those rectangles.
        cover, free_cover: (cameras, nx * ny) float32 the evidence map: coverage of a person's rectangle at each cell
            by all motion / by the unexplained motion, -1 where the camera does not see it.
        hist: (max_people, cameras, 2, 17) float32 the people's appearance histograms (``kernels.coverage``).
        slot_xy, slot_alive: (max_people,) each pool slot's ground position and whether it tracks somebody.

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
        self.fps = float(config.fps) if config.fps is not None else DEFAULT_FPS
        self.frame_dt = 1.0 / self.fps  # seconds; :meth:`step` with timestamps changes it
        self.frame_dynamics = config.dynamics.per_frame(self.frame_dt)
        sp, sv, al = self.frame_dynamics
        self.dt = wp.array([self.frame_dt], dtype=wp.float32, device=d)  # [0] dt, seconds
        self.sigma_vel = wp.array(list(sv), dtype=wp.float32, device=d)  # velocity noise of one frame, m/s: xy, z
        self.alpha = wp.array([al], dtype=wp.float32, device=d)  # [0] eq. 6's factor of one frame
        self.decay = wp.array([self._decay(self.frame_dt)], dtype=wp.float32, device=d)  # [0] unseen velocity factor
        self._last_timestamp: float | None = None
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
        # ground evidence map over the working area (the rig's volume, else the ground two cameras see)
        b = config.birth
        self.area = working_area(rig, config.area)
        log.info("%s", self.area.describe())
        lo, hi = self.area.bounds
        self.grid_origin = np.array([lo[0], lo[1]], dtype=np.float64)
        self.nx = max(1, int(math.ceil((hi[0] - lo[0]) / b.cell - 1e-9)))
        self.ny = max(1, int(math.ceil((hi[1] - lo[1]) / b.cell - 1e-9)))
        self.area_map = self.area.resample(self.grid_origin, b.cell, self.nx, self.ny)  # (ny, nx) bool
        self.keep_area = self.area.followed.grown(LEAVE_MARGIN)  # a person beyond it has left
        self.volume = (np.array([lo[0], lo[1], 0.0]), np.array([hi[0], hi[1], self.area.z_top]))
        # the masks' integral images (all motion, and the motion the tracked people's rectangles leave), the person
        # rectangles' coverage on the evidence map's cells, and the person-level terms of the particles' weights
        ncam = len(rig)
        self.box_scale = s = coverage_scale(rig)  # the rectangles are counted on s x s blocks of the masks
        self.sdrig = DeviceRig(Rig(tuple(reduced_camera(c, s) for c in rig.cameras)), d)  # the rig at that size
        self.small_mask = wp.zeros(self.sdrig.total_pixels, dtype=wp.uint8, device=d)
        self.integral = wp.zeros(self.sdrig.total_integral, dtype=wp.int32, device=d)
        self.free_mask = wp.zeros(self.sdrig.total_pixels, dtype=wp.uint8, device=d)
        self.free_integral = wp.zeros(self.sdrig.total_integral, dtype=wp.int32, device=d)
        maxw, maxh = self.sdrig.max_width, self.sdrig.max_height
        seg = int(kcolour.SEGMENT)
        self._row_dims = (ncam, maxh, -(-maxw // seg))
        self._col_dims = (ncam, maxw + 1, -(-maxh // seg))
        self._row_seg = wp.zeros(self._row_dims, dtype=wp.int32, device=d)
        self._col_seg = wp.zeros(self._col_dims, dtype=wp.int32, device=d)
        self._pixel_dims = (ncam, maxh, maxw)  # of the reduced masks
        self._rows = max(c.height for c in rig.cameras)  # of the full images
        cells = self.nx * self.ny
        self.cover = wp.zeros((ncam, cells), dtype=wp.float32, device=d)  # coverage of all motion, -1: unseen
        self.free_cover = wp.zeros((ncam, cells), dtype=wp.float32, device=d)  # of the unexplained motion
        self._cover_host = wp.zeros((ncam, cells), dtype=wp.float32, device="cpu", pinned=pinned)
        cell_area = wp.zeros((ncam, cells), dtype=wp.float32, device=d)
        wp.launch(
            kcov.box_area_kernel,
            dim=(ncam, cells),
            inputs=[self.sdrig.cams, wp.vec2(*self.grid_origin), b.cell, self.nx]
            + [config.person.half_width, config.person.height, config.person.min_visible, float(s * s)],
            outputs=[cell_area],
            device=d,
        )
        self.cell_area = cell_area.numpy().reshape(ncam, self.ny, self.nx)  # pixels of each cell's rectangle
        self._free_cover_host = wp.zeros((ncam, cells), dtype=wp.float32, device="cpu", pinned=pinned)
        self.boxes = wp.zeros((b.max_people, ncam), dtype=wp.vec4, device=d)  # tracked people's rectangles per slot
        self.full_boxes = wp.zeros((b.max_people, ncam), dtype=wp.vec4, device=d)  # the same in the full images
        pc = config.person
        self.terms = kcov.PersonTerms()
        self.terms.half_width, self.terms.height, self.terms.min_visible = pc.half_width, pc.height, pc.min_visible
        self.terms.unit = float(s * s)
        self.terms.slope, self.terms.offset = pc.slope_offset
        self.terms.exclusion_radius, self.terms.exclusion_weight = pc.exclusion_radius, pc.exclusion_weight
        nb = int(kcov.HIST_BINS)
        self.hist = wp.zeros((b.max_people, ncam, int(kcov.HIST_PARTS), nb + 1), dtype=wp.float32, device=d)
        self._hist_host = wp.zeros(self.hist.shape, dtype=wp.float32, device="cpu", pinned=pinned)
        self.slot_xy = wp.zeros(b.max_people, dtype=wp.vec2, device=d)  # ground position per pool slot
        self.slot_alive = wp.zeros(b.max_people, dtype=wp.int32, device=d)  # 1 where the slot tracks somebody
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
        self.slot_miss = np.zeros(b.max_people, dtype=np.float64)  # seconds without support
        self.slot_close = np.zeros(b.max_people, dtype=np.float64)  # seconds closer than merge_distance to another
        self.slot_track = np.zeros((b.max_people, 3))  # ground x, y and time (seconds) of the walk's reference point
        self.slot_speed = np.zeros(b.max_people)  # ground speed over the last STILL_WINDOW seconds, m/s
        self.slot_still = np.zeros(b.max_people, dtype=bool)  # lost from sight while standing: held longer
        self.pending = np.zeros((0, 3), dtype=np.float64)  # x, y, seconds of unexplained evidence in a row
        nparts = int(kcov.HIST_PARTS)
        self.slot_app = np.zeros((b.max_people, nparts, nb))  # appearance per slot: normalised histograms
        self.slot_app_seen = np.zeros((b.max_people, nparts), dtype=bool)  # the part has been seen
        self.slot_new = np.zeros(b.max_people, dtype=bool)  # added last frame: may be somebody lost before
        self.lost: list[dict] = []  # people removed for lack of support: id, time, x, y, appearance (re-id)
        self.clock = 0.0  # seconds since the first frame (sum of the frame intervals)
        self.next_id = 0
        self.frames_done = 0
        log.info(
            "people tracker: %d particles per person, up to %d people, %d cameras, %g frames/s%s, evidence map %dx%d, "
            "device %s",
            config.particles,
            b.max_people,
            len(rig),
            self.fps,
            "" if config.fps is not None else " (assumed: no PeopleConfig.fps)",
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
            if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
                raise FrameError(
                    f"camera '{cam.name}': expected an (H, W, 3) uint8 BGR image, got {img.dtype} {img.shape}"
                )
            m = np.asarray(m)
            if m.ndim == 3:
                m = m.max(axis=2)
            if m.dtype != np.uint8 and m.dtype != np.bool_:
                m = m != 0
            for what, shape in (("frame", img.shape[:2]), ("mask", m.shape)):
                if tuple(shape) != (cam.height, cam.width):
                    raise FrameError(
                        f"camera '{cam.name}': {what} size {shape[1]}x{shape[0]} differs from the calibration "
                        f"{cam.width}x{cam.height}"
                    )
            bgr[3 * offs[c] : 3 * offs[c + 1]] = img.reshape(-1)
            np.not_equal(m.reshape(-1), 0, out=msk[offs[c] : offs[c + 1]].view(np.bool_))  # 0/1: counted
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
        wp.launch(
            kcov.downsample_mask_kernel,
            dim=self._pixel_dims,
            inputs=[self.drig.cams, self.mask, self.box_scale, self.sdrig.cams],
            outputs=[self.small_mask],
            device=d,
        )
        self._integral(self.small_mask, self.integral)

    def _integral(self, mask: wp.array, out: wp.array) -> None:
        """The (H+1) x (W+1) integral image of every camera's reduced ``mask`` (block counts) into ``out``
        (``kernels.colour``'s four segmented scans)."""
        cams, d = self.sdrig.cams, self.device
        wp.launch(
            kcolour.row_segment_sums_kernel, dim=self._row_dims, inputs=[cams, mask], outputs=[self._row_seg], device=d
        )
        wp.launch(
            kcolour.row_scan_kernel, dim=self._row_dims, inputs=[cams, mask, self._row_seg], outputs=[out], device=d
        )
        wp.launch(
            kcolour.col_segment_sums_kernel, dim=self._col_dims, inputs=[cams, out], outputs=[self._col_seg], device=d
        )
        wp.launch(kcolour.col_scan_kernel, dim=self._col_dims, inputs=[cams, self._col_seg], outputs=[out], device=d)

    def _coverage(self) -> None:
        """The tracked people's rectangles after this frame (``boxes``: what the others explain in the next frame's
        rectangle terms) and the person rectangles' coverage on the evidence map's cells (``kernels.coverage``): of
        all motion, and of the motion outside the tracked people's rectangles; copied to the host asynchronously."""
        pc, b, d = self.config.person, self.config.birth, self.device
        cams = self.sdrig.cams
        origin = wp.vec2(*self.grid_origin)
        dims = (len(self.rig), self.nx * self.ny)
        common = [origin, b.cell, self.nx, pc.half_width, pc.height, pc.min_visible, self.terms.unit]
        wp.launch(kcov.coverage_kernel, dim=dims, inputs=[cams, self.integral, *common], outputs=[self.cover], device=d)
        wp.launch(
            kcov.person_boxes_kernel,
            dim=(len(self.pool), len(self.rig)),
            inputs=[cams, self.slot_xy, self.slot_alive, pc.half_width, pc.height],
            outputs=[self.boxes],
            device=d,
        )
        wp.launch(
            kcov.explained_mask_kernel,
            dim=self._pixel_dims,
            inputs=[cams, self.small_mask, self.boxes, len(self.pool)],
            outputs=[self.free_mask],
            device=d,
        )
        self._integral(self.free_mask, self.free_integral)
        wp.launch(
            kcov.coverage_kernel,
            dim=dims,
            inputs=[cams, self.free_integral, *common],
            outputs=[self.free_cover],
            device=d,
        )
        wp.copy(self._cover_host, self.cover)
        wp.copy(self._free_cover_host, self.free_cover)
        self.hist.zero_()
        wp.launch(
            kcov.person_boxes_kernel,
            dim=(len(self.pool), len(self.rig)),
            inputs=[self.drig.cams, self.slot_xy, self.slot_alive, pc.half_width, pc.height],
            outputs=[self.full_boxes],
            device=d,
        )
        wp.launch(
            kcov.person_histogram_kernel,
            dim=(len(self.pool), len(self.rig), int(kcov.HIST_PARTS), self._rows),
            inputs=[self.drig.cams, self.bgr, self.mask, self.full_boxes],
            outputs=[self.hist],
            device=d,
        )
        wp.copy(self._hist_host, self.hist)

    def _evidence(self, n: int) -> None:
        """The silhouette column tops of the ``n`` people tracked after this frame (``people_xy[:n]``, filled on the
        device from their estimates), copied to the host asynchronously (the frame's one synchronisation follows)."""
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
        self,
        images: Sequence[np.ndarray],
        masks: Sequence[np.ndarray],
        occupancy: bool = False,
        timestamp: float | None = None,
    ) -> PeopleEstimate:
        """Track one synchronised set of frames: one (H, W, 3) uint8 BGR image and one (H, W) motion mask
        (nonzero = motion) per camera, in rig order. With ``occupancy``, every person of the returned estimate
        carries its occupancy grid (``PersonEstimate.occupancy``), computed before anybody is removed.

        Args:
            timestamp: the frames' time, seconds (any origin): dt is the time since the previous frame's timestamp
                (the first frame, and frames without one, keep the current dt).

        Raises:
            FrameError: bad images or masks (see :meth:`upload`), or a timestamp not after the previous one.
        """
        t0 = time.perf_counter()
        self._set_time(timestamp)
        self.upload(images, masks)
        t1 = time.perf_counter()
        self._observe()
        active = [k for k in range(len(self.pool)) if self.slot_id[k] >= 0]
        for j, k in enumerate(active):
            p = self.pool[k]
            src, dst = p.parity, 1 - p.parity
            p._run_chain(src, dst)
            p.parity = dst
            p.frames_done += 1
            for index, out in ((j, self.people_xy), (k, self.slot_xy)):
                wp.launch(
                    kpeople.person_xy_kernel,
                    dim=1,
                    inputs=[p.est, int(kreduce.EST_MEAN), index],
                    outputs=[out],
                    device=self.device,
                )
        self._coverage()
        self._evidence(len(active))
        wp.copy(self._sigma_host, self.sigma_n)
        wp.synchronize_device(self.device)  # the frame's one synchronisation: estimates, evidence, tops on the host
        t2 = time.perf_counter()
        people = []
        self.clock += self.frame_dt
        self._update_appearance(active)
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
        if occupancy and active:  # before the population update: the grids belong to this frame's estimates
            grids = self._occupancy_grids(active)
            for person, grid in zip(people, grids, strict=True):
                person.occupancy = grid
        est = PeopleEstimate(frame=self.frames_done, people=people, sigma_n=float(self._sigma_host.numpy()[0]))
        self._update_population(est, active, tops[: len(active)] > 0)
        self.frames_done += 1
        est.timings.update(upload=t1 - t0, filter=t2 - t1, population=time.perf_counter() - t2)
        return est

    def _set_time(self, timestamp: float | None) -> None:
        """Take dt from ``timestamp`` (seconds) and the previous one; update the device copies when it changes."""
        if timestamp is None:
            return
        t = float(timestamp)
        if not math.isfinite(t):
            raise FrameError(f"frame {self.frames_done}: timestamp {timestamp!r} is not a finite number of seconds")
        last, self._last_timestamp = self._last_timestamp, t
        if last is None:
            return
        if t <= last:
            raise FrameError(
                f"frame {self.frames_done}: timestamp {t:.6f} s is not after the previous one {last:.6f} s"
            )
        self.set_frame_interval(t - last)

    def set_frame_interval(self, dt: float) -> None:
        """Use the frame interval ``dt`` (seconds) from the next frame on: the dynamics' per-frame noise and eq. 6's
        factor (``DynamicsConfig.per_frame``) and the birth and removal clocks. A device fill per changed value, no
        host copy (CUDA graphs read the arrays)."""
        dt = float(dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ConfigError(f"frame interval: expected seconds > 0, got {dt!r}")
        if dt == self.frame_dt:
            return
        self.frame_dt = dt
        self.frame_dynamics = sp, sv, al = self.config.dynamics.per_frame(dt)
        self.dt.fill_(dt)
        self.sigma_vel[0:1].fill_(sv[0])
        self.sigma_vel[1:2].fill_(sv[1])
        self.alpha.fill_(al)
        self.decay.fill_(self._decay(dt))
        for p in self.pool:
            p.set_sigma(sp)

    def _decay(self, dt: float) -> float:
        """Factor of an unseen person's velocity over one frame interval ``dt``: exp(-dt / stop_seconds)."""
        return math.exp(-dt / self.config.person.stop_seconds)

    def _elapsed(self, seconds: float, limit: float) -> bool:
        """Whether ``seconds`` (a sum of frame intervals) has reached ``limit``, to half a frame: a time rounds to
        whole frames, and any limit is reached after one frame at a low frame rate."""
        return seconds >= limit - 0.5 * self.frame_dt

    # --- who is there (ours) ---------------------------------------------------------------------------------
    def _cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) of the evidence map's cell centres, metres, (ny, nx) each (computed once)."""
        if self._centres is None:
            c = self.config.birth.cell
            xs = self.grid_origin[0] + c * (np.arange(self.nx) + 0.5)
            ys = self.grid_origin[1] + c * (np.arange(self.ny) + 0.5)
            self._centres = tuple(np.meshgrid(xs, ys))
        return self._centres

    def _update_appearance(self, active: list[int]) -> None:
        """Fold this frame's appearance histograms (``kernels.coverage.person_histogram_kernel``, the cameras' counts
        added) into each tracked person's exponential average (``BirthConfig.appearance_seconds``); a part needs
        ``MIN_APPEARANCE_PX`` pixels of its own. A person added last frame is first compared with the people lost
        recently (:meth:`_reidentify`)."""
        b = self.config.birth
        counts = self._hist_host.numpy().sum(axis=1)  # (people, parts, bins + 1)
        rate = 1.0 - math.exp(-self.frame_dt / b.appearance_seconds)
        nh, ns = int(kcov.HIST_H), int(kcov.HIST_S)
        for k in active:
            for part in range(counts.shape[1]):
                c = counts[k, part]
                if c[-1] < MIN_APPEARANCE_PX:
                    continue
                h = c[:-1].copy()
                for lo, hi in ((0, nh), (nh, nh + ns), (nh + ns, len(h))):
                    total = h[lo:hi].sum()
                    h[lo:hi] = h[lo:hi] / total if total > 0 else 1.0 / (hi - lo)
                if self.slot_app_seen[k, part]:
                    self.slot_app[k, part] += rate * (h - self.slot_app[k, part])
                else:
                    self.slot_app[k, part] = h
                    self.slot_app_seen[k, part] = True
            if self.slot_new[k]:
                self.slot_new[k] = False
                self._reidentify(k)

    def _similarity(self, a: np.ndarray, seen_a: np.ndarray, b: np.ndarray, seen_b: np.ndarray) -> float:
        """Appearance similarity of two people: the mean Bhattacharyya coefficient of their hue, saturation and value
        histograms over the body parts both have seen (0 when none)."""
        nh, ns = int(kcov.HIST_H), int(kcov.HIST_S)
        values = [
            float(np.sum(np.sqrt(a[p, lo:hi] * b[p, lo:hi])))
            for p in range(a.shape[0])
            if seen_a[p] and seen_b[p]
            for lo, hi in ((0, nh), (nh, nh + ns), (nh + ns, a.shape[1]))
        ]
        return float(np.mean(values)) if values else 0.0

    def _reidentify(self, k: int) -> None:
        """Give the person just added in slot ``k`` the id of a person lost within ``reid_seconds`` and within reach
        (1 m + ``WALK_SPEED`` x the time since) whose appearance is the most similar, if at least
        ``reid_similarity``."""
        b = self.config.birth
        self.lost = [p for p in self.lost if self.clock - p["time"] <= b.reid_seconds]
        if not self.lost or not self.slot_app_seen[k].any():
            return
        xy = self.pool[k].est_host.numpy()[kreduce.EST_MEAN : kreduce.EST_MEAN + 2]
        best, score = None, b.reid_similarity
        for p in self.lost:
            if np.hypot(*(xy - p["xy"])) > 1.0 + WALK_SPEED * (self.clock - p["time"]):
                continue
            sim = self._similarity(self.slot_app[k], self.slot_app_seen[k], p["app"], p["seen"])
            if sim >= score:
                best, score = p, sim
        if best is None:
            return
        self.lost.remove(best)
        log.info("person %d is person %d again (appearance similarity %.2f)", self.slot_id[k], best["id"], score)
        self.slot_id[k] = best["id"]

    def _update_speed(self, k: int, xy: np.ndarray) -> None:
        """The ground speed of slot ``k`` over about the last ``STILL_WINDOW`` seconds (from its estimates)."""
        x0, y0, t0 = self.slot_track[k]
        span = self.clock - t0
        if span > 0:
            self.slot_speed[k] = float(np.hypot(xy[0] - x0, xy[1] - y0)) / span
        if span >= STILL_WINDOW or not np.all(np.isfinite(self.slot_track[k])):
            self.slot_track[k] = (xy[0], xy[1], self.clock)

    def _evidence_maps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """From this frame's coverage maps (host copies): ``(evidence, free_evidence, births)``, (ny, nx) each.
        ``evidence``: the sum over the cameras that see each cell's person rectangle of the rectangle term of
        :class:`~.people_model.PersonConfig` (``(slope f - offset) area``, nats: > 0 where a person explains the masks
        better than nobody); ``free_evidence`` the same for the motion the tracked people leave unexplained;
        ``births``: cells of the working area seen by ``min_cameras`` cameras where every camera that sees them
        finds more unexplained motion than an empty rectangle would have (its term > 0)."""
        slope, offset = self.config.person.slope_offset
        shape = (len(self.rig), self.ny, self.nx)
        cover = self._cover_host.numpy().reshape(shape)
        free = self._free_cover_host.numpy().reshape(shape)
        seen = cover >= 0
        evidence = np.where(seen, (slope * cover - offset) * self.cell_area, 0.0).sum(axis=0)
        terms = np.where(seen, (slope * free - offset) * self.cell_area, 0.0)
        free_evidence = terms.sum(axis=0)
        births = (seen.sum(axis=0) >= self.min_votes) & np.all(~seen | (terms > 0), axis=0) & self.area_map
        return evidence, free_evidence, births

    def _update_population(self, est: PeopleEstimate, active: list[int], column: np.ndarray) -> None:
        """Remove people without multi-view support, duplicates and people who left; add people where the
        evidence is unexplained for a while. Host code on the small evidence map.

        A person is supported while this frame's masks show it (``PersonEstimate.support`` above
        ``PersonConfig.gate``: the rectangle term of what the other people's rectangles leave, at its position or
        near it)."""
        b = self.config.birth
        dt = self.frame_dt
        _evidence, free_evidence, births = self._evidence_maps()
        gate = self.config.person.gate
        gx, gy = self._cell_centres()
        by_slot = {k: e for k, e in zip(active, est.people, strict=True)}
        for k, e in by_slot.items():
            self._update_speed(k, e.mean[:2])
            if e.support > gate:
                self.slot_miss[k] = 0.0
                self.slot_still[k] = False
            else:
                if self.slot_miss[k] == 0.0:  # lost from sight now: standing (the background model took it)?
                    self.slot_still[k] = self.slot_speed[k] < STILL_SPEED
                self.slot_miss[k] += dt
            limit = b.hold_seconds if self.slot_still[k] else b.remove_seconds
            outside = not self.keep_area.contains(e.mean[:2])
            if self._elapsed(self.slot_miss[k], limit) or outside or not np.all(np.isfinite(e.mean)):
                self._remove(k, est, remember=e.mean[:2] if np.all(np.isfinite(e.mean)) else None)
        # duplicates: two filters on one person
        alive = [k for k in active if self.slot_id[k] >= 0]
        for k in alive:
            close = any(
                np.hypot(*(by_slot[k].mean[:2] - by_slot[j].mean[:2])) < b.merge_distance
                for j in alive
                if j != k and self.slot_id[j] >= 0
            )
            self.slot_close[k] = self.slot_close[k] + dt if close else 0.0
        for k in sorted(alive, key=lambda s: self.slot_age[s]):  # the younger of a pair goes
            if self.slot_id[k] >= 0 and self._elapsed(self.slot_close[k], b.remove_seconds):
                self._remove(k, est)
                for j in alive:
                    self.slot_close[j] = 0.0
        # unexplained evidence -> candidates; at most one person added per frame, the strongest (see BirthConfig)
        free = births.copy()
        for k in range(len(self.pool)):  # people added or kept this frame explain their surroundings
            if self.slot_id[k] >= 0 and k in by_slot:
                e = by_slot[k]
                free &= (gx - e.mean[0]) ** 2 + (gy - e.mean[1]) ** 2 > b.exclusion**2
        candidates = self._blobs(free, free_evidence, gx, gy)
        pending, added = [], False
        reach = max(0.5, MAX_SPEED * dt)  # the same evidence one frame later: within a walk of one frame interval
        for cx, cy, _strength in sorted(candidates, key=lambda c: -c[2]):
            seen = dt
            if len(self.pending):
                dist = np.hypot(self.pending[:, 0] - cx, self.pending[:, 1] - cy)
                j = int(np.argmin(dist))
                if dist[j] < reach:
                    seen = self.pending[j, 2] + dt
            if self._elapsed(seen, b.add_seconds) and not added:
                self._add(np.array([cx, cy]), est)
                added = True
            else:
                pending.append((cx, cy, min(seen, b.add_seconds)))
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
            w = np.maximum(votes[sel].astype(np.float64), 1e-9)
            out.append((float(np.sum(gx[sel] * w) / w.sum()), float(np.sum(gy[sel] * w) / w.sum()), float(w.sum())))
        return out

    def _add(self, xy: np.ndarray, est: PeopleEstimate) -> None:
        free = np.nonzero(self.slot_id < 0)[0]
        if not free.size:
            log.warning("frame %d: no free slot for a new person at %s (max_people reached)", est.frame, xy.round(2))
            return
        k = int(free[0])
        self.pool[k].spawn(xy, self.frames_done)
        self.slot_xy[k : k + 1].fill_(wp.vec2(float(xy[0]), float(xy[1])))
        self.slot_app_seen[k] = False
        self.slot_new[k] = True
        self.slot_id[k] = self.next_id
        self.slot_alive.assign((self.slot_id >= 0).astype(np.int32))
        self.slot_age[k] = 0
        self.slot_miss[k] = 0
        self.slot_close[k] = 0
        self.slot_track[k] = (xy[0], xy[1], self.clock)
        self.slot_speed[k] = 0.0
        self.slot_still[k] = False
        est.added.append(self.next_id)
        log.info("frame %d: person %d added at (%.2f, %.2f)", est.frame, self.next_id, xy[0], xy[1])
        self.next_id += 1

    def _remove(self, k: int, est: PeopleEstimate, remember: np.ndarray | None = None) -> None:
        """Stop tracking slot ``k``; with ``remember`` (its last ground position) the person may be re-identified
        (:meth:`_reidentify`)."""
        est.removed.append(int(self.slot_id[k]))
        log.info("frame %d: person %d removed", est.frame, self.slot_id[k])
        if remember is not None and self.config.birth.reid_seconds > 0 and self.slot_app_seen[k].any():
            self.lost.append(
                dict(
                    id=int(self.slot_id[k]),
                    time=self.clock,
                    xy=np.array(remember, dtype=np.float64),
                    app=self.slot_app[k].copy(),
                    seen=self.slot_app_seen[k].copy(),
                )
            )
        self.slot_id[k] = -1
        self.slot_alive.assign((self.slot_id >= 0).astype(np.int32))

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
        slots = []
        for pid in ids:
            found = np.nonzero(self.slot_id == pid)[0]
            if not found.size:
                raise ConfigError(f"person {pid} is not tracked (tracked now: {self.tracked_ids})")
            slots.append(int(found[0]))
        return dict(zip(ids, self._occupancy_grids(slots), strict=True))

    def _occupancy_grids(self, slots: Sequence[int]) -> list[tuple[np.ndarray, np.ndarray]]:
        """The occupancy grids of the filters in pool ``slots`` around their last estimates (host copies): every
        grid is launched into its filter's buffer (allocated once), then one synchronisation and the copies."""
        oc = self.config.occupancy
        launched = []
        for k in slots:
            p = self.pool[k]
            centre = p.est_host.numpy()[kreduce.EST_MEAN : kreduce.EST_MEAN + 3]
            dims = np.asarray(p.grid_dims)
            origin = np.floor((centre - 0.5 * dims * oc.voxel) / oc.voxel) * oc.voxel  # on the voxel lattice
            p.launch_occupancy(origin)
            launched.append((origin, p))
        wp.synchronize_device(self.device)
        return [(origin, p.grid_host.numpy().copy()) for origin, p in launched]

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
    def state_dict(self) -> dict[str, np.ndarray]:
        """The whole state after the last frame (device arrays of the tracker and its pool, and the population
        bookkeeping), for :meth:`load_state_dict`."""
        state = {name: arr.numpy().copy() for name, arr in _device_arrays(self)}
        for name in (
            "slot_id",
            "slot_age",
            "slot_miss",
            "slot_close",
            "pending",
            "slot_track",
            "slot_speed",
            "slot_still",
            "slot_app",
            "slot_app_seen",
            "slot_new",
        ):
            state[f"__{name}__"] = getattr(self, name).copy()
        state["__next_id__"] = np.int64(self.next_id)
        state["__frames_done__"] = np.int64(self.frames_done)
        state["__clock__"] = np.float64(self.clock)
        state["__frame_dt__"] = np.float64(self.frame_dt)
        state["__last_timestamp__"] = np.float64(np.nan if self._last_timestamp is None else self._last_timestamp)
        nparts, nb = self.slot_app.shape[1:]
        state["__lost_id__"] = np.array([p["id"] for p in self.lost], dtype=np.int64)
        state["__lost_time__"] = np.array([p["time"] for p in self.lost], dtype=np.float64)
        state["__lost_xy__"] = np.array([p["xy"] for p in self.lost], dtype=np.float64).reshape(-1, 2)
        state["__lost_app__"] = np.array([p["app"] for p in self.lost], dtype=np.float64).reshape(-1, nparts, nb)
        state["__lost_seen__"] = np.array([p["seen"] for p in self.lost], dtype=bool).reshape(-1, nparts)
        state["__parity__"] = np.array([p.parity for p in self.pool], dtype=np.int64)
        state["__person_frames__"] = np.array([p.frames_done for p in self.pool], dtype=np.int64)
        return state

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restore a :meth:`state_dict` into a tracker built with the same rig and configuration."""
        arrays = dict(_device_arrays(self))
        missing = sorted(set(arrays) - set(state))
        if missing:
            raise ConfigError(f"checkpoint: arrays {missing[:5]} missing (a checkpoint of another configuration?)")
        for name, arr in arrays.items():
            arr.assign(np.asarray(state[name]))
        for name in (
            "slot_id",
            "slot_age",
            "slot_miss",
            "slot_close",
            "pending",
            "slot_track",
            "slot_speed",
            "slot_still",
            "slot_app",
            "slot_app_seen",
            "slot_new",
        ):
            setattr(self, name, np.array(state[f"__{name}__"]))
        self.next_id = int(state["__next_id__"])
        self.frames_done = int(state["__frames_done__"])
        self.clock = float(state["__clock__"])
        self.set_frame_interval(float(state["__frame_dt__"]))
        last = float(state["__last_timestamp__"])
        self._last_timestamp = None if math.isnan(last) else last
        self.lost = [
            dict(id=int(i), time=float(t), xy=np.array(xy), app=np.array(app), seen=np.array(seen))
            for i, t, xy, app, seen in zip(
                state["__lost_id__"],
                state["__lost_time__"],
                state["__lost_xy__"],
                state["__lost_app__"],
                state["__lost_seen__"],
                strict=True,
            )
        ]
        for p, parity, frames in zip(self.pool, state["__parity__"], state["__person_frames__"], strict=True):
            p.parity, p.frames_done = int(parity), int(frames)
        wp.synchronize_device(self.device)
