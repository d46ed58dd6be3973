"""S2: multi-camera 3D people tracker (Lopez-Cifuentes et al., multi-camera 3D particle filters with motion and
colour). Several people are tracked directly in 3D from two or more calibrated cameras with overlapping views; each
person has its own particle filter whose particles are 3D points inside the person, weighted by the motion masks of
all cameras and a multi-view HSV colour descriptor; beyond the paper (ours, after the Probabilistic Occupancy Map of
Fleuret, Berclaz, Lengagne and Fua, PAMI 2008) each particle's weight also judges the whole person: the rectangle of
a person standing at its ground position must explain motion the other tracked people do not
(``kernels/people/coverage.py``).

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

Length: the frame's device side in one class (buffers allocated once, the recorded launches and CUDA graphs of the
observation, the rectangles and the evidence map, the one readback per frame, checkpoints); the population logic
is in ``population.py``, one person's filter in ``person.py``.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable, Iterator, Sequence

import numpy as np
import warp as wp

from wptrack.cameras.rig import Camera, Rig
from wptrack.cameras.structs import DeviceRig
from wptrack.core.device import block_partition, device_guard, resolve_device
from wptrack.core.errors import ConfigError, FrameError
from wptrack.core.filter import BLOCK, MAX_BLOCKS, arrays_state, check_state, load_arrays, no_gc
from wptrack.io.frames import camera_frame
from wptrack.kernels.colour import hsi as kcolour
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.people import coverage as kcov
from wptrack.kernels.people import descriptor as kdesc
from wptrack.kernels.people import filter as kpeople
from wptrack.trackers.people.area import working_area
from wptrack.trackers.people.config import PeopleConfig
from wptrack.trackers.people.person import PeopleEstimate, PersonEstimate, PersonFilter, person_seed
from wptrack.trackers.people.population import Population

__all__ = ["PeopleEstimate", "PeopleTracker", "PersonEstimate", "PersonFilter", "coverage_scale", "person_seed"]

log = logging.getLogger(__name__)

DEFAULT_FPS = 25.0
"""Frame rate assumed by a tracker built without ``PeopleConfig.fps`` and stepped without timestamps."""
COVERAGE_ROWS = 120
"""The person rectangles are counted on masks reduced to about this many rows (``coverage_scale``)."""
LEAVE_MARGIN = 0.5
"""A person farther than this from the ground that any camera sees (the rig's volume when it has one) has left,
metres."""
NOISE_STRIDE = 4
"""Pixels between the samples of the image-noise estimate (eq. 18)."""


def coverage_scale(rig: Rig) -> int:
    """Block size of the reduced masks the person rectangles are counted on: about ``COVERAGE_ROWS`` rows for the
    smallest camera (1: full size for images of up to 180 rows; at most 15, so a block count fits a byte)."""
    rows = min(cam.height for cam in rig.cameras)
    return int(min(15, max(1, round(rows / COVERAGE_ROWS))))


def reduced_camera(cam, scale: int):
    """``cam`` for its image reduced by ``scale`` x ``scale`` blocks
    (``kernels.people.coverage.downsample_mask_kernel``): the block (u, v) covers the full pixels (scale u .. scale u
    + scale - 1, ...), whose centre is at full coordinate scale u + (scale - 1) / 2, so f' = f / scale and c' = (c -
    (scale - 1) / 2) / scale; the remainder columns and rows (width % scale, height % scale) are left out."""
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


class PeopleTracker(Population):
    """S2 people tracker on a rig of two or more cameras.

    Args:
        rig: calibrated cameras with overlapping views (ground plane z = 0; ``rig.volume`` bounds the evidence map).
        config: :class:`wptrack.trackers.people.config.PeopleConfig`.
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``.
        use_graph: capture each person's frame chain and the tracker's fixed per-frame work as CUDA graphs (default:
            on CUDA).
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
        hist: (max_people, cameras, 2, 17) float32 the people's appearance histograms (``kernels.people.coverage``).
        slot_xy, slot_alive: (max_people,) each pool slot's ground position and whether it tracks somebody.
        sigma_n, cover, free_cover, hist and top (max_people, axes: the column tops) are views of one float32 buffer
        copied to its pinned host twin once per frame.

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
        # eq. 18 over every NOISE_STRIDE-th pixel (a mean square estimated from ~1e5 values is as good as from all)
        self.noise_values = 3 * len(range(0, npx, NOISE_STRIDE))
        self.noise_blocks, self.noise_chunk = block_partition(self.noise_values, not self.is_cuda, BLOCK, MAX_BLOCKS)
        self.noise_part = wp.zeros(self.noise_blocks, dtype=wp.float64, device=d)
        pinned = self.is_cuda
        self._bgr_host = wp.zeros(3 * npx, dtype=wp.uint8, device="cpu", pinned=pinned)
        self._mask_host = wp.zeros(npx, dtype=wp.uint8, device="cpu", pinned=pinned)
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
        # BirthConfig.explained "neutral" only: 1 outside every rectangle, its integral image (empty otherwise)
        neutral = self.config.birth.explained == "neutral"
        self.left_mask = wp.zeros(self.sdrig.total_pixels if neutral else 0, dtype=wp.uint8, device=d)
        self.left_integral = wp.zeros(self.sdrig.total_integral if neutral else 0, dtype=wp.int32, device=d)
        maxw, maxh = self.sdrig.max_width, self.sdrig.max_height
        seg = int(kcolour.SEGMENT)
        self._row_dims = (ncam, maxh, -(-maxw // seg))
        self._col_dims = (ncam, maxw + 1, -(-maxh // seg))
        self._row_seg = wp.zeros(self._row_dims, dtype=wp.int32, device=d)
        self._col_seg = wp.zeros(self._col_dims, dtype=wp.int32, device=d)
        self._pixel_dims = (ncam, maxh, maxw)  # of the reduced masks
        self._rows = max(c.height for c in rig.cameras)  # of the full images
        cells = self.nx * self.ny
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
        self.boxes = wp.zeros((b.max_people, ncam), dtype=wp.vec4, device=d)  # tracked people's rectangles per slot
        self.full_boxes = wp.zeros((b.max_people, ncam), dtype=wp.vec4, device=d)  # the same in the full images
        pc = config.person
        self.terms = kcov.PersonTerms()
        self.terms.half_width, self.terms.height, self.terms.min_visible = pc.half_width, pc.height, pc.min_visible
        self.terms.unit = float(s * s)
        self.terms.slope, self.terms.offset = pc.slope_offset
        self.terms.exclusion_radius, self.terms.exclusion_weight = pc.exclusion_radius, pc.exclusion_weight
        self.terms.balance = int(pc.balance_cameras)
        nb = int(kcov.HIST_BINS)
        self.slot_xy = wp.zeros(b.max_people, dtype=wp.vec2, device=d)  # ground position per pool slot
        self.slot_alive = wp.zeros(b.max_people, dtype=wp.int32, device=d)  # 1 where the slot tracks somebody
        body = config.body
        self.column_z_lo = 0.05
        self.column_nz = int((float(self.volume[1][2]) - self.column_z_lo) / body.step) + 1
        axes = kpeople.COLUMN_AXES
        self.column_seen = wp.zeros((b.max_people, axes, self.column_nz), dtype=wp.uint8, device=d)
        # what the host reads of a frame, in one float32 buffer (one copy per frame into its pinned twin): sigma_n,
        # the coverage of all motion (-1: unseen) and of the unexplained motion, the appearance histograms, the tops
        shapes = {
            "sigma_n": (1,),
            "cover": (ncam, cells),
            "free_cover": (ncam, cells),
            "free_left": (ncam, cells) if neutral else (0,),  # read (and written) with "neutral" births only
            "hist": (b.max_people, ncam, int(kcov.HIST_PARTS), nb + 1),
            "top": (b.max_people, axes),
        }
        self._readback = wp.zeros(sum(math.prod(v) for v in shapes.values()), dtype=wp.float32, device=d)
        self._readback_host = wp.zeros(self._readback.shape, dtype=wp.float32, device="cpu", pinned=pinned)
        start = 0
        for name, shape in shapes.items():
            end = start + math.prod(shape)
            setattr(self, name, self._readback[start:end].reshape(shape))
            setattr(self, f"_{name}_host", self._readback_host[start:end].reshape(shape))
            start = end
        self.min_votes = min(b.min_cameras, len(rig))
        self._commands: dict[str, list[Callable[[], None]]] = {}  # the frame's fixed device work (:meth:`_replay`)
        self._graphs: dict[str, object] = {}  # their CUDA graphs (use_graph)
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
        self.births_refused = 0  # people not added because every slot of the pool was taken (max_people)
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
            img, m = camera_frame(img, cam), camera_frame(m, cam, "mask")
            if m.dtype != np.uint8 and m.dtype != np.bool_:
                m = m != 0
            bgr[3 * offs[c] : 3 * offs[c + 1]] = img.reshape(-1)
            np.not_equal(m.reshape(-1), 0, out=msk[offs[c] : offs[c + 1]].view(np.bool_))  # 0/1: counted
        wp.copy(self.bgr, self._bgr_host)
        wp.copy(self.mask, self._mask_host)

    def _replay(self, name: str, build: Callable[[], list[Callable[[], None]]]) -> None:
        """Run the fixed command list ``name`` of the frame: built by ``build`` on its first run (launches recorded
        with ``record_cmd=True``: their arguments are packed once, a replay costs a few microseconds of host time
        instead of a full ``wp.launch``; the buffers and parameters are the tracker's, fixed), replayed after; with
        ``use_graph`` the second run captures the list as a CUDA graph (like each person's chain) and later runs
        launch it (one launch instead of the list's)."""
        cmds = self._commands.get(name)
        if cmds is None:
            cmds = self._commands[name] = build()
        elif self.use_graph:
            graph = self._graphs.get(name)
            if graph is None:
                with device_guard(self.device).exclusive(), no_gc():  # no other thread's device work in the graph
                    with wp.ScopedCapture(device=self.device) as capture:
                        for cmd in cmds:
                            cmd()
                graph = self._graphs[name] = capture.graph
            wp.capture_launch(graph)
            return
        for cmd in cmds:
            cmd()

    def _record(self, kernel, dim, inputs: list, outputs: list, block_dim: int | None = None) -> Callable[[], None]:
        """A recorded launch of ``kernel`` on the tracker's device (tiled with ``block_dim``), to replay."""
        args = dict(dim=dim, inputs=inputs, outputs=outputs, device=self.device, record_cmd=True)
        if block_dim is None:
            return wp.launch(kernel, **args).launch
        return wp.launch_tiled(kernel, block_dim=block_dim, **args).launch

    def _observe(self) -> None:
        """sigma_n of eq. 18 from the previous and this frame, and the reduced masks' integral image."""
        if self.frames_done == 0:
            wp.copy(self.bgr_prev, self.bgr)  # no previous frame: sigma_n = 0 (the floor of eqs. 15-17)
        self._replay("observe", self._observe_commands)

    def _observe_commands(self) -> list[Callable[[], None]]:
        nb, nv = self.noise_blocks, self.noise_values
        return [
            self._record(
                kdesc.noise_partials_kernel,
                [nb],
                [self.bgr_prev, self.bgr, nv, NOISE_STRIDE, self.noise_chunk],
                [self.noise_part],
                BLOCK,
            ),
            self._record(kdesc.noise_sigma_kernel, [1], [self.noise_part, nb, nv], [self.sigma_n], BLOCK),
            lambda: wp.copy(self.bgr_prev, self.bgr),
            self._record(
                kcov.downsample_mask_kernel,
                self._pixel_dims,
                [self.drig.cams, self.mask, self.box_scale, self.sdrig.cams],
                [self.small_mask],
            ),
            *self._integral(self.small_mask, self.integral),
        ]

    def _integral(self, mask: wp.array, out: wp.array) -> list[Callable[[], None]]:
        """The (H+1) x (W+1) integral image of every camera's reduced ``mask`` (block counts) into ``out``
        (``kernels.colour.hsi``'s four segmented scans), as recorded launches."""
        cams = self.sdrig.cams
        return [
            self._record(kcolour.row_segment_sums_kernel, self._row_dims, [cams, mask], [self._row_seg]),
            self._record(kcolour.row_scan_kernel, self._row_dims, [cams, mask, self._row_seg], [out]),
            self._record(kcolour.col_segment_sums_kernel, self._col_dims, [cams, out], [self._col_seg]),
            self._record(kcolour.col_scan_kernel, self._col_dims, [cams, self._col_seg], [out]),
        ]

    def _coverage(self) -> None:
        """The tracked people's rectangles after this frame (``boxes``: what the others explain in the next frame's
        rectangle terms) and the person rectangles' coverage on the evidence map's cells (``kernels.people.coverage``):
        of all motion, and of the motion outside the tracked people's rectangles; the appearance histograms (all read
        back by :meth:`step`'s one copy)."""
        self._replay("coverage", self._coverage_commands)

    def _coverage_commands(self) -> list[Callable[[], None]]:
        pc, b = self.config.person, self.config.birth
        cams, full = self.sdrig.cams, self.drig.cams
        dims = (len(self.rig), self.nx * self.ny)
        common = [wp.vec2(*self.grid_origin), b.cell, self.nx, pc.half_width, pc.height, pc.min_visible]
        common.append(self.terms.unit)
        boxes_dims = (len(self.pool), len(self.rig))
        people = [self.slot_xy, self.slot_alive, pc.half_width, pc.height]
        return [
            self._record(kcov.coverage_kernel, dims, [cams, self.integral, *common], [self.cover]),
            self._record(kcov.person_boxes_kernel, boxes_dims, [cams, *people], [self.boxes]),
            self._record(
                kcov.explained_mask_kernel,
                self._pixel_dims,
                [cams, self.small_mask, self.boxes, len(self.pool)],
                [self.free_mask],
            ),
            *self._integral(self.free_mask, self.free_integral),
            *self._free_coverage_commands(dims, common),
            self.hist.zero_,
            self._record(kcov.person_boxes_kernel, boxes_dims, [full, *people], [self.full_boxes]),
            self._record(
                kcov.person_histogram_kernel,
                (*boxes_dims, int(kcov.HIST_PARTS), self._rows),
                [full, self.bgr, self.mask, self.full_boxes],
                [self.hist],
            ),
        ]

    def _free_coverage_commands(self, dims: tuple[int, int], common: list) -> list[Callable[[], None]]:
        """The evidence map of the unexplained motion (``free_cover``) as recorded launches: its coverage of the whole
        rectangle (``BirthConfig.explained == "empty"``), or, ``neutral``, of the part the tracked people's
        rectangles leave, with that part's fraction in ``free_left`` (``kernels.people.coverage.left_coverage_kernel``;
        ``free_left`` is not written otherwise)."""
        cams = self.sdrig.cams
        if self.config.birth.explained == "empty":
            return [self._record(kcov.coverage_kernel, dims, [cams, self.free_integral, *common], [self.free_cover])]
        return [
            self._record(kcov.left_mask_kernel, self._pixel_dims, [cams, self.boxes, len(self.pool)], [self.left_mask]),
            *self._integral(self.left_mask, self.left_integral),
            self._record(
                kcov.left_coverage_kernel,
                dims,
                [cams, self.free_integral, self.left_integral, *common],
                [self.free_cover, self.free_left],
            ),
        ]

    def _evidence(self, n: int) -> None:
        """The silhouette column tops of every pool slot (``slot_xy``, filled on the device from the estimates of the
        ``n`` people tracked this frame; a free slot's columns are empty and its row is not read), read back by
        :meth:`step`'s one copy."""
        if n:
            self._replay("columns", self._column_commands)

    def _column_commands(self) -> list[Callable[[], None]]:
        body, slots, axes = self.config.body, len(self.pool), kpeople.COLUMN_AXES
        gap, votes = int(round(body.max_gap / body.step)), min(body.min_cameras, len(self.rig))
        return [
            self._record(
                kpeople.column_seen_kernel,
                (slots, axes, self.column_nz),
                [self.drig.cams, self.mask, self.slot_xy, self.slot_alive, self.column_z_lo, body.step, body.search],
                [self.column_seen],
            ),
            self._record(
                kpeople.column_top_kernel,
                (slots, axes),
                [self.column_seen, self.column_z_lo, body.step, self.column_nz, votes, gap],
                [self.top],
            ),
        ]

    # --- the frame --------------------------------------------------------------------------------------
    def step(
        self,
        images: Sequence[np.ndarray] | tuple[Sequence[np.ndarray], Sequence[np.ndarray]],
        masks: Sequence[np.ndarray] | None = None,
        occupancy: bool = False,
        timestamp: float | None = None,
    ) -> PeopleEstimate:
        """Track one synchronised set of frames: one (H, W, 3) uint8 BGR image and one (H, W) motion mask
        (nonzero = motion) per camera, in rig order; ``step(images, masks)`` or ``step((images, masks))`` (the
        observation of the tracker contract, :class:`wptrack.core.filter.Tracker`). With ``occupancy``, every person
        of the returned estimate carries its occupancy grid (``PersonEstimate.occupancy``), computed before anybody
        is removed.

        Args:
            timestamp: the frames' time, seconds (any origin): dt is the time since the previous frame's timestamp
                (the first frame, and frames without one, keep the current dt).

        Raises:
            FrameError: bad images or masks (see :meth:`upload`), or a timestamp not after the previous one.
        """
        if masks is None:
            images, masks = images
        t0 = time.perf_counter()
        self._set_time(timestamp)
        self.upload(images, masks)
        t1 = time.perf_counter()
        self._observe()
        active = [k for k in range(len(self.pool)) if self.slot_id[k] >= 0]
        for k in active:
            self.pool[k].launch_frame()  # its chain ends with its ground position in slot_xy[k]
        self._coverage()
        self._evidence(len(active))
        wp.copy(self._readback_host, self._readback)  # sigma_n, coverage, histograms, tops: one copy
        wp.synchronize_device(self.device)  # the frame's one synchronisation: estimates, evidence, tops on the host
        t2 = time.perf_counter()
        people = []
        self.clock += self.frame_dt
        self._update_appearance(active)
        tops = self._top_host.numpy().max(axis=1)  # the highest of each slot's axes
        body = self.config.body
        for k in active:
            self.slot_age[k] += 1
            person = self.pool[k].estimate_from_host(int(self.slot_id[k]), int(self.slot_age[k]))
            if tops[k] > 0:
                person.top = float(tops[k])
                if body.centroid == "standing":
                    person.centroid[2] = body.ratio * person.top  # standing-person model (BodyConfig)
            people.append(person)
        if occupancy and active:  # before the population update: the grids belong to this frame's estimates
            grids = self._occupancy_grids(active)
            for person, grid in zip(people, grids, strict=True):
                person.occupancy = grid
        est = PeopleEstimate(frame=self.frames_done, people=people, sigma_n=float(self._sigma_n_host.numpy()[0]))
        self._update_population(est, active, tops[active] > 0)
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

    # --- checkpoints -----------------------------------------------------------------------------------------
    def state_arrays(self) -> dict[str, wp.array]:
        """The device arrays that carry the tracker to the next frame: the previous frame (the noise estimate of eq. 18
        differences consecutive frames), the frame interval's parameters (dt, velocity noise, eq. 6's factor, the
        unseen velocity's decay), each slot's ground position, whether it tracks somebody and its rectangles (the next
        frame's gate and person terms read them), and every slot's person filter (``person<k>.<name>``, see
        :meth:`PersonFilter.state_arrays`), free slots included (a checkpoint has the same names whoever is tracked)."""
        arrays = {
            "bgr_prev": self.bgr_prev,
            "dt": self.dt,
            "sigma_vel": self.sigma_vel,
            "alpha": self.alpha,
            "decay": self.decay,
            "slot_xy": self.slot_xy,
            "slot_alive": self.slot_alive,
            "boxes": self.boxes,
        }
        for k, p in enumerate(self.pool):
            arrays.update({f"person{k}.{name}": arr for name, arr in p.state_arrays().items()})
        return arrays

    def host_state(self) -> dict[str, np.ndarray]:
        """The population bookkeeping (:meth:`Population.population_state`), the frame count, the frame interval and
        the last timestamp, and each slot's parity and frame count."""
        state = self.population_state()
        state["__frames_done__"] = np.int64(self.frames_done)
        state["__frame_dt__"] = np.float64(self.frame_dt)
        state["__last_timestamp__"] = np.float64(np.nan if self._last_timestamp is None else self._last_timestamp)
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
        self.load_population_state(state)
        self.frames_done = int(state["__frames_done__"])
        self.set_frame_interval(float(state["__frame_dt__"]))
        last = float(state["__last_timestamp__"])
        self._last_timestamp = None if math.isnan(last) else last
        for p, parity, frames in zip(self.pool, state["__parity__"], state["__person_frames__"], strict=True):
            p.parity, p.frames_done = int(parity), int(frames)
        wp.synchronize_device(self.device)
