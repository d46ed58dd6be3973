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

This module is the driver (the device state and the frame chain); its parts live beside it: the launches shared with
the benchmark and the tests (:mod:`~wptrack.trackers.templates.launches`), the addition candidates, UOH and the
choice of new objects (:mod:`~wptrack.trackers.templates.additions`), the memory check made before allocation
(:mod:`~wptrack.trackers.templates.memory`) and the host side of a frame's estimate
(:mod:`~wptrack.trackers.templates.readout`). Their names are re-exported here.

Units: metres, seconds, radians on the ground plane (its own 2D frame, see ``wptrack.cameras.rig.GroundPlane``); pixels
in the image.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

import numpy as np
import warp as wp

from wptrack.cameras.rig import Rig
from wptrack.cameras.structs import camera_struct
from wptrack.core.device import CpuSplit, block_partition, cpu_split_threads
from wptrack.core.errors import ConfigError
from wptrack.core.filter import BLOCK, MAX_BLOCKS, FrameChain, _seed_words
from wptrack.core.resampling import Resampler, quantisation_bits
from wptrack.io.frames import camera_frame
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.core import resample as kres
from wptrack.kernels.templates import dynamics as kdyn
from wptrack.kernels.templates import occlusion as kocc
from wptrack.kernels.templates import partition as kpart
from wptrack.kernels.templates import raster as kraster
from wptrack.kernels.templates import slots as kslots
from wptrack.kernels.templates import xor as kxor
from wptrack.trackers.templates.additions import (  # noqa: F401  (Candidates, ground_rays: tests and reports)
    CANDIDATE_BLOCK,
    Candidates,
    choose_additions,
    ground_rays,
    score_candidates,
)
from wptrack.trackers.templates.config import (  # noqa: F401  (HumanPrior, VehiclePrior, CyclistPrior: the public API)
    CLASSES,
    CyclistPrior,
    HumanPrior,
    TemplateConfig,
    TemplateEstimate,
    TrackedObject,
    VehiclePrior,
)
from wptrack.trackers.templates.launches import (  # noqa: F401  (the launches' helpers: bench, tests)
    ROW_BLOCK,
    SCORE_BLOCK,
    SINGLE_MAX,
    SINGLE_MAX_BLOCK,
    Hulls,
    _dynamics_struct,
    _new_state,
    _no_groups,
    _plane_struct,
    empty_slot_acc,
    launch_argmax,
    launch_mask_rows,
    launch_xor_score,
    piece_cap,
    xor_band,
)
from wptrack.trackers.templates.memory import (  # noqa: F401  (byte counts: tests, bench)
    PARTICLE_BYTES,
    PARTITION_SLOT_BYTES,
    SLOT_STATE_BYTES,
    check_template_fits,
    particle_bytes,
)
from wptrack.trackers.templates.readout import (  # noqa: F401  (the in-image test: run, reports, MOT files)
    box_fraction_in_image,
    estimate_from_host,
    image_box_fraction,
    object_box_corners,
)

log = logging.getLogger(__name__)


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
        check_template_fits(n, r, config.resampling, self.partition, image_bytes, d)
        self.candidates = Candidates(self.camera, self.plane, self.cam, self.plane_struct, config, d, rig.source)
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
        self._q_view = self.q_host.numpy()  # its NumPy view, made once
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
        # one past the highest slot some particle holds (partition.group_slots_kernel each frame; R for the joint
        # filter): the XOR scoring scans the pieces below it only
        self.slot_hi = wp.full(1, r, dtype=wp.int32, device=d)
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
        self.slot_open = wp.zeros(r, dtype=wp.float64, device=d)  # slot_count with the closed free slots held
        self.slot_label = wp.full(r, -1, dtype=wp.int32, device=d)
        self.slot_kind = wp.zeros(r, dtype=wp.int32, device=d)
        self.next_label = wp.zeros(1, dtype=wp.int32, device=d)
        self.add = wp.full(2 * int(config.additions), -1, dtype=wp.int32, device=d)
        self.best_state = wp.zeros((r, 11), dtype=wp.float32, device=d)
        self.resampler = Resampler(config.resampling, n, d)
        # the pixel costs are given for an image of reference_area pixels and scale with this one's area
        self.area_scale = float(w * h) / float(config.reference_area) if config.reference_area > 0 else 1.0
        a = self.area_scale
        hp, vp, cp = config.human, config.vehicle, config.cyclist
        self.cost_a = wp.vec4(0.0, hp.cost_a * a, vp.cost_a * a, cp.cost_a * a)
        self.cost_b = wp.vec4(0.0, hp.cost_b * a, vp.cost_b * a, cp.cost_b * a)
        self.exclusion = float(config.exclusion) * a
        self.min_area = max(1, int(round(config.min_candidate_area * a)))
        self.score_scale = float(config.scale) / float(w * h)
        pinned = self.is_cuda
        self.host = {
            "slot_est": wp.zeros((r, int(kslots.NE)), dtype=wp.float64, device="cpu", pinned=pinned),
            "slot_label": wp.zeros(r, dtype=wp.int32, device="cpu", pinned=pinned),
            "slot_kind": wp.zeros(r, dtype=wp.int32, device="cpu", pinned=pinned),
            "best_state": wp.zeros((r, 11), dtype=wp.float32, device="cpu", pinned=pinned),
            "add": wp.zeros(2 * int(config.additions), dtype=wp.int32, device="cpu", pinned=pinned),
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
        host = self._q_view
        if m.dtype == np.uint8 and m.flags.c_contiguous:  # min(m, 1) = (m != 0) for uint8, one pass by OpenCV
            import cv2

            cv2.min(m, 1, dst=host)
        else:
            np.copyto(host, m != 0, casting="unsafe")
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
                         self.group_active, self.n_groups, self.slot_hi],
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
            self.score_scale, float(cfg.bg_weight), self.exclusion, self.xor_sums, s.logw, self.penalty,
            self.complexity, self.cov_diff, self.device, band=self.xor_band,
            groups=(self.group_box, self.n_groups, self.slot_group, self.group_sums) if self.partition else None,
            finish=finish_here, slot_hi=self.slot_hi,
        )  # fmt: skip
        if self.partition:  # each group's factor of eq. 6 (kernels.templates.xor.group_logw_kernel)
            wp.launch_tiled(
                kxor.group_logw_kernel,
                dim=[self.blocks],
                inputs=[s.kind, s.age, s.pos, s.heading, s.dims, self.qtotal, self.cost_a, self.cost_b,
                        self.score_scale, float(cfg.bg_weight), self.exclusion, self.slot_group, self.n_groups,
                        self.n, self.chunk, int(not finish_here), self.xor_sums],
                outputs=[self.group_sums, self.glogw, self.part_gmax, s.logw, self.penalty, self.complexity],
                block_dim=BLOCK,
                device=self.device,
            )  # fmt: skip

    def _uoh(self) -> None:
        score_candidates(self)

    def _estimate(self, cur: int) -> None:
        d = self.device
        s = self.state[cur]
        launch_argmax(
            s.logw, self.n, self.blocks, self.chunk, self.part_max, self.part_arg, self.est, self.best_index, d
        )
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
        choose_additions(self)  # eq. 12's o_new and the slots they go to
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

    def _estimate_from_host(self) -> TemplateEstimate:
        return estimate_from_host(self)

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
