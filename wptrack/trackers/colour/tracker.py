"""S1: colour-based 3D particle filter of Barrera, Canas and Matellan (2005; extended version with the
convergence experiments of section III.C).

One coloured object, M calibrated cameras; a particle is a 3D point; prediction is a gaussian walk with
deviation sigma_m (eqs. 1-3); the weight is the product over cameras of max(m, 1)/25 where m counts the
target-coloured pixels in the 5x5 window around the particle's projection, 1/25 outside the image
(eqs. 4-7). Log-weights throughout; resampling by name (``wptrack.core.resampling``).

Example::

    rig = Rig.load("rig.yaml")
    target = HSITarget(hue=(300, 20), sat=(0.25, 1.0))
    tracker = ColorTracker(rig, target, particles=200, sigma=0.03, init=(0.4, 0.1, 0.2), device="auto")
    for est in tracker.track(open_frames(["cam1.avi", "cam2.avi"])):
        print(est.frame, est.mean)
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np
import warp as wp

from wptrack.cameras.rig import Rig
from wptrack.cameras.structs import ColourMaps, DeviceRig
from wptrack.core.config import check, param
from wptrack.core.device import resolve_device
from wptrack.core.errors import ConfigError, FrameError
from wptrack.core.filter import BLOCK, Estimate, ParticleFilter
from wptrack.core.resampling import SCHEMES
from wptrack.io.frames import camera_frame
from wptrack.kernels.colour import blobs as kblobs
from wptrack.kernels.colour import hsi as kcolour
from wptrack.kernels.colour import proposal as kproposal
from wptrack.kernels.colour import scoring as kscoring

log = logging.getLogger(__name__)

SCORE_MODES = ("auto", "direct", "integral", "map")
PROPOSALS = ("prior", "mixture")
"""``prior``: the paper's filter (particles drawn from the gaussian walk only); ``mixture``: the walk plus jumps to
geometric detection candidates decided by a mode test (``wptrack.kernels.colour.proposal``; converges from anywhere,
re-acquires a lost object)."""


@dataclass(frozen=True)
class HSITarget:
    """Target colour in HSI (paper, section II.B): a pixel is the target's when its hue, saturation and intensity all
    lie in these ranges."""

    hue: tuple[float, float] = param(
        help="hue range (HMIN > HMAX wraps through 0, e.g. 330 20 for pink-red)", units="degrees", lo=0.0, hi=360.0,
        metavar=("HMIN", "HMAX"),
    )  # fmt: skip
    sat: tuple[float, float] = param((0.0, 1.0), help="saturation range", lo=0.0, hi=1.0, metavar=("SMIN", "SMAX"))
    intensity: tuple[float, float] = param(
        (20.0, 240.0), help="intensity range: darker or brighter pixels never match", units="8-bit levels", lo=0.0,
        hi=255.0, metavar=("IMIN", "IMAX"),
    )  # fmt: skip

    def __post_init__(self) -> None:
        check(self)
        for name in ("sat", "intensity"):
            lo, hi = getattr(self, name)
            if lo > hi:
                raise ConfigError(f"{name}: min {lo:g} must not exceed max {hi:g}")

    def hue_intervals(self) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
        """The hue range as intervals of cos(hue) on the two halves of the hue circle: B <= G (hue = acos c,
        0..180 degrees) and B > G (hue = 360 - acos c). At most two intervals per half."""
        lo, hi = self.hue
        ranges = [(lo, hi)] if lo <= hi else [(lo, 360.0), (0.0, hi)]
        lower, upper = [], []
        for a, b in ranges:
            if a <= 180.0:  # part in [0, 180]: c in [cos b', cos a]
                lower.append((math.cos(math.radians(min(b, 180.0))), math.cos(math.radians(a))))
            if b >= 180.0:  # part in [180, 360]: acos c in [360 - b, 360 - a]
                a2, b2 = max(a, 180.0), b
                upper.append((math.cos(math.radians(360.0 - a2)), math.cos(math.radians(360.0 - b2))))
        return lower, upper

    def to_struct(self, device: str = "cpu") -> kcolour.ColourTarget:
        """The target as a kernel struct on ``device``, with its colour table (2 MiB, built there once)."""
        s = kcolour.ColourTarget()
        s.h_min, s.h_max = self.hue
        s.s_min, s.s_max = self.sat
        s.i_min, s.i_max = self.intensity
        lower, upper = self.hue_intervals()
        empty = (2.0, -2.0)  # an interval no cosine falls in
        lower = (lower + [empty, empty])[:2]
        upper = (upper + [empty, empty])[:2]
        # widen by one float32 ulp-ish so that exact boundary hues (e.g. 0 and 360) stay inside
        eps = 1e-7
        s.lower = wp.vec4(lower[0][0] - eps, lower[0][1] + eps, lower[1][0] - eps, lower[1][1] + eps)
        s.upper = wp.vec4(upper[0][0] - eps, upper[0][1] + eps, upper[1][0] - eps, upper[1][1] + eps)
        s.table = wp.zeros(int(kcolour.TABLE_WORDS), dtype=wp.uint32, device=device)
        wp.launch(
            kcolour.colour_table_kernel, dim=int(kcolour.TABLE_WORDS), inputs=[s], outputs=[s.table], device=device
        )
        return s


@dataclass(frozen=True)
class ColorConfig:
    """Parameters of the S1 colour particle filter (Barrera et al.; the paper's symbols in the help)."""

    particles: int = param(200, help="number of particles", symbol="N", lo=1, hi=2**31 - 2)
    sigma: float = param(
        0.03, help="deviation of the gaussian walk per axis", units="m", symbol="sigma_m, eqs. 1-3", lo=0.0,
        lo_open=True,
    )  # fmt: skip
    init: tuple[float, float, float] | None = param(
        None, help="initial point: all particles start there and the first prediction spreads them (the paper's "
        "initialisation); none: uniform in init_box or the rig's working volume", units="m", metavar=("X", "Y", "Z"),
    )  # fmt: skip
    init_box: tuple[float, float, float, float, float, float] | None = param(
        None, help="box for the uniform initialisation (xmin ymin zmin xmax ymax zmax); default: the rig's working "
        "volume", units="m", flag="volume", metavar=("XMIN", "YMIN", "ZMIN", "XMAX", "YMAX", "ZMAX"),
    )  # fmt: skip
    resampling: str = param("systematic", help="resampling scheme", choices=SCHEMES)
    ess_threshold: float = param(
        1.0, help="resample when ESS <= this fraction of N (1: every frame, as in the paper)", lo=0.0, hi=1.0,
        lo_open=True,
    )  # fmt: skip
    score_mode: str = param(
        "auto", help="window counts: direct (25 reads per camera), integral (integral image, 4 reads), map (a "
        "per-pixel window map, 1 read) or auto (map when 25 N > the pixels, the paper's crossover); all identical",
        choices=SCORE_MODES,
    )  # fmt: skip
    seed: int = param(0, help="seed of the counter-based random streams (same seed and device: identical output)",
                      lo=0, hi=2**64 - 1)  # fmt: skip
    keep_particles: int = param(1000, help="particles per frame copied back for reports (0: none)", lo=0)
    proposal: str = param(
        "mixture", help="prior: the paper's filter (the gaussian walk only); mixture: the motion model may also jump "
        "to a detection candidate (colour blobs triangulated across camera pairs) when a mode test says the "
        "candidates beat the cloud (converges from anywhere, re-acquires a lost object)", choices=PROPOSALS,
    )  # fmt: skip
    mixture: float = param(
        0.5, help="fraction of particles that jump to the detection candidates on a frame where the mode test fires "
        "and on the first frame after a random initialisation (mixture only)", symbol="eps", lo=0.0, hi=1.0,
        hi_open=True,
    )  # fmt: skip
    reset_rate: float = param(
        0.0, help="fraction of particles that jump to the candidates on the other frames (mixture only; 0: a stable "
        "track never jumps)", symbol="alpha", lo=0.0, hi=1.0, hi_open=True,
    )  # fmt: skip
    detection_sigma: float = param(
        0.02, help="deviation of the particles a jump puts around a candidate (mixture only)", units="m",
        symbol="sigma_d", lo=0.0, lo_open=True,
    )  # fmt: skip
    detection_components: int = param(
        8, help="candidates kept per frame, the best after non-maximum suppression within 2 sigma_d (mixture only)",
        symbol="K", lo=1, hi=64,
    )  # fmt: skip
    blobs: int = param(
        8, help="colour blobs kept per camera and frame: the best local maxima of the target-pixel count over 15 x 15 "
        "pixel neighbourhoods (mixture only)", lo=1, hi=32,
    )  # fmt: skip
    min_blob_pixels: int = param(
        8, help="fewest target pixels in a blob's 15 x 15 neighbourhood (mixture only)", units="px", lo=1, hi=225
    )
    epipolar_px: float = param(
        8.0, help="largest reprojection error of a blob pair's triangulated point in either camera of the pair "
        "(mixture only)", units="px", lo=0.0, lo_open=True,
    )  # fmt: skip
    jump_margin: float = param(
        2.0, help="nats per frame by which the best candidate's log-likelihood must exceed the cloud's before "
        "evidence accumulates (mixture only)", units="nats", lo=0.0,
    )  # fmt: skip
    jump_evidence: float = param(
        0.0, help="accumulated excess beyond which the frame jumps (a CUSUM; 0: the first frame whose excess passes "
        "the margin jumps; mixture only)", units="nats", lo=0.0,
    )  # fmt: skip

    def __post_init__(self) -> None:
        box = self.init_box
        if box is not None and len(box) == 2 and all(np.ndim(c) == 1 and len(c) == 3 for c in box):
            object.__setattr__(self, "init_box", tuple(box[0]) + tuple(box[1]))  # ((min), (max)) corners
        check(self)
        if self.init_box is not None:
            lo, hi = self.init_box[:3], self.init_box[3:]
            if any(a > b for a, b in zip(lo, hi, strict=True)):
                raise ConfigError(f"init_box: min {list(lo)} must not exceed max {list(hi)}")

    @property
    def box(self) -> tuple[tuple[float, float, float], tuple[float, float, float]] | None:
        """``init_box`` as ``(min, max)`` corners, or None (``init_box`` also accepts the corners when built)."""
        if self.init_box is None:
            return None
        return tuple(self.init_box[:3]), tuple(self.init_box[3:])  # type: ignore[return-value]


class ColorTracker(ParticleFilter):
    """S1 colour particle filter on a rig of M cameras.

    Args:
        rig: calibrated cameras (``wptrack.cameras.rig.Rig``).
        target: the object's colour (:class:`HSITarget`).
        config: a :class:`ColorConfig`; keyword arguments override its fields (``particles=``, ``sigma=``,
            ``init=``, ``seed=`` ...). ``init="random"`` initialises uniformly in ``init_box`` or, if that is
            not given, in the rig's working volume (``rig.bounds()``).
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``.
        use_graph: capture the frame chain as a CUDA graph (default: on CUDA).

    Per-frame device buffers (besides ``ParticleFilter``'s state):
        bgr: (sum W*H*3,) uint8 frames of all cameras back to back (BGR, as OpenCV decodes them).
        maps: :class:`wptrack.cameras.structs.ColourMaps` (mask, integral images, window map) in integral/map mode.
    """

    kernel_modules = (
        *ParticleFilter.kernel_modules,
        "wptrack.kernels.colour.hsi",
        "wptrack.kernels.colour.scoring",
        "wptrack.kernels.colour.proposal",
        "wptrack.kernels.colour.blobs",
    )

    def __init__(
        self,
        rig: Rig,
        target: HSITarget,
        config: ColorConfig | None = None,
        device: str | None = "auto",
        use_graph: bool | None = None,
        **overrides,
    ) -> None:
        config = config or ColorConfig()
        init = overrides.pop("init", config.init)
        if isinstance(init, str):
            if init != "random":
                raise ConfigError(f"init: expected (x, y, z) metres or 'random', got {init!r}")
            box = overrides.pop("init_box", config.init_box) or tuple(tuple(v) for v in rig.bounds())
            overrides["init_box"] = box
            init = None
        elif init is not None:
            init = tuple(float(v) for v in init)
        try:
            config = ColorConfig(**{**asdict(config), **overrides, "init": init})
        except TypeError as e:
            raise ConfigError(f"ColorTracker: {e}") from None
        if not isinstance(target, HSITarget):
            raise ConfigError(f"target: expected an HSITarget, got {type(target).__name__}")
        device = resolve_device(device)
        super().__init__(
            config.particles,
            config.sigma,
            device,
            seed=config.seed,
            resampling=config.resampling,
            ess_threshold=config.ess_threshold,
            keep_particles=config.keep_particles,
            use_graph=use_graph,
        )
        self.config = config
        self.rig = rig
        self.target = target
        self.drig = DeviceRig(rig, self.device)
        total_pixels = self.drig.total_pixels
        mode = config.score_mode
        if mode == "auto":
            # Paper, section II.B: whole-image filtering costs W*H classifications per camera, the window
            # model 25 N; past the crossover a per-frame map wins: the window counts are computed once per pixel
            # (box sums of the mask) instead of per particle.
            mode = "map" if 25 * config.particles > total_pixels else "direct"
        self.score_mode = mode
        self._mode_id = {
            "direct": kscoring.SCORE_DIRECT,
            "integral": kscoring.SCORE_INTEGRAL,
            "map": kscoring.SCORE_MAP,
        }[mode]
        self._target = target.to_struct(self.device)
        d = self.device
        self.bgr = wp.zeros(3 * total_pixels, dtype=wp.uint8, device=d)
        self._staging = wp.zeros(3 * total_pixels, dtype=wp.uint8, device="cpu", pinned=self.is_cuda)
        self._staging_np = self._staging.numpy()
        self.maps = ColourMaps(self.drig, d, window=mode == "map") if mode in ("integral", "map") else None
        self._integral = self.maps.integral if self.maps else wp.zeros(1, dtype=wp.int32, device=d)
        self._window = self.maps.window if self.maps else wp.zeros(1, dtype=wp.uint8, device=d)
        if config.init is None and config.init_box is None:
            config = replace(config, init_box=tuple(tuple(float(c) for c in v) for v in rig.bounds()))
            self.config = config
        self.volume = config.box or tuple(tuple(float(c) for c in v) for v in rig.bounds())
        # detection candidates are kept inside a volume someone chose (the init box, the rig file's volume); the
        # fallback box around the camera centres would drop an object below or beside them
        chosen = config.init_box is not None or rig.volume is not None
        self.candidate_volume = self.volume if chosen else ((-1.0e30,) * 3, (1.0e30,) * 3)
        self.uniform_frame = wp.array([-1], dtype=wp.int32, device=d)
        if config.proposal != "prior":
            self._allocate_detection()
        if config.init is not None:
            self.init_point(config.init)
        else:
            self.init_box(*config.box)
        log.info(
            "colour tracker: %d particles, %d cameras, %s scoring, device %s",
            config.particles,
            self.drig.num_cameras,
            mode,
            self.device,
        )

    def _allocate_detection(self) -> None:
        """Fixed-size device buffers of the geometric detection and the mode test (``proposal='mixture'``):

        sb_offset: (M + 1,) int32 start of each camera's 5 x 5 sub-block grid in ``sb_counts``.
        sb_counts, sb_keys, peaks: (sum floor(W/5) floor(H/5),) int32 target pixels per sub-block, blob keys
            (``kernels.colour.blobs.neighbourhood_sums_kernel``); float32 peak keys.
        part_score, part_index, part_uv: (M, chunks, PEAK_KEEP) the best peaks of each chunk of sub-blocks.
        blob_score, blob_uv: (M, B) blobs per camera (pixel count of the 15 x 15 neighbourhood, 0 = empty; centre, px).
        pair_a, pair_b: (P,) int32 camera pairs (a < b), P = M (M - 1) / 2.
        cand_pos, cand_score, cand_keep: (P B^2,) triangulated candidates, their log-likelihood, the NMS flag.
        det_pos, det_score, det_cum: (K,) the kept candidates (score descending, LOG_ZERO = empty slot) and their
            normalised cumulative weights; det_count: (1,) int32 valid slots.
        mix: (MIX_SIZE,) float32 the frame's jump threshold, evidence, jump flag, CUSUM (``kernels.colour.proposal``).
        """
        from statistics import NormalDist

        cfg, d = self.config, self.device
        cams = self.rig.cameras
        m = len(cams)
        sizes = [(c.width // int(kblobs.SUBBLOCK)) * (c.height // int(kblobs.SUBBLOCK)) for c in cams]
        self._sb_max = (
            max(c.height // int(kblobs.SUBBLOCK) for c in cams),
            max(c.width // int(kblobs.SUBBLOCK) for c in cams),
        )
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int32)
        total = max(1, int(offsets[-1]))
        self._chunks = max(1, -(-max(sizes) // int(kblobs.PEAK_CHUNK)))
        keep = int(kblobs.PEAK_KEEP)
        self.sb_offset = wp.array(offsets, dtype=wp.int32, device=d)
        self.sb_counts = wp.zeros(total, dtype=wp.int32, device=d)
        self.sb_keys = wp.zeros(total, dtype=wp.int32, device=d)
        self.peaks = wp.zeros(total, dtype=wp.float32, device=d)
        self.part_score = wp.zeros((m, self._chunks, keep), dtype=wp.float32, device=d)
        self.part_index = wp.zeros((m, self._chunks, keep), dtype=wp.int32, device=d)
        self.part_uv = wp.zeros((m, self._chunks, keep), dtype=wp.vec2, device=d)
        b = cfg.blobs
        self.blob_score = wp.zeros((m, b), dtype=wp.float32, device=d)
        self.blob_uv = wp.zeros((m, b), dtype=wp.vec2, device=d)
        pairs = [(i, j) for i in range(m) for j in range(i + 1, m)]
        self._pairs = len(pairs)
        self.pair_a = wp.array([p[0] for p in pairs] or [0], dtype=wp.int32, device=d)
        self.pair_b = wp.array([p[1] for p in pairs] or [0], dtype=wp.int32, device=d)
        c = max(1, len(pairs) * b * b)
        self.cand_pos = wp.zeros(c, dtype=wp.vec3, device=d)
        self.cand_score = wp.full(c, float(kproposal.LOG_ZERO), dtype=wp.float32, device=d)
        self.cand_keep = wp.zeros(c, dtype=wp.int32, device=d)
        k = cfg.detection_components
        self.det_pos = wp.zeros(k, dtype=wp.vec3, device=d)
        self.det_score = wp.full(k, float(kproposal.LOG_ZERO), dtype=wp.float32, device=d)
        self.det_cum = wp.zeros(k, dtype=wp.float32, device=d)
        self.det_count = wp.zeros(1, dtype=wp.int32, device=d)
        self.mix = wp.zeros(int(kproposal.MIX_SIZE), dtype=wp.float32, device=d)
        pinned = self.is_cuda
        self.det_count_host = wp.zeros(1, dtype=wp.int32, device="cpu", pinned=pinned)
        self.mix_host = wp.zeros(int(kproposal.MIX_SIZE), dtype=wp.float32, device="cpu", pinned=pinned)

        def threshold(p: float) -> float:
            return NormalDist().inv_cdf(p) if p > 0.0 else float(kproposal.NO_JUMP)

        self._thresholds = wp.vec2(threshold(cfg.mixture), threshold(cfg.reset_rate))

    def state_arrays(self) -> dict[str, wp.array]:
        """:meth:`ParticleFilter.state_arrays` and the frame whose prior is the uniform initial box
        (``uniform_frame``); with the mixture proposal also the previous frame's estimate vector (the mode test
        compares the candidates with the cloud's MMSE and MAP estimates) and ``mix`` (its CUSUM carries over). The
        blobs and candidates are recomputed every frame."""
        arrays = {**super().state_arrays(), "uniform_frame": self.uniform_frame}
        if self.config.proposal != "prior":
            arrays.update(est=self.est, mix=self.mix)
        return arrays

    def init_box(self, lo, hi) -> None:
        """Particles uniform in the box [lo, hi] (metres); with the mixture proposal the next frame draws its
        non-jumping particles uniformly in the box and a fraction ``mixture`` from the detection candidates
        (``kernels.colour.proposal``)."""
        super().init_box(lo, hi)
        if hasattr(self, "uniform_frame"):
            self.uniform_frame.fill_(self.frames_done)

    def init_point(self, point) -> None:
        """Put every particle at ``point`` (3,) metres (the paper's initialisation); with the mixture proposal the
        first mode test compares the candidates with this point."""
        super().init_point(point)
        if hasattr(self, "uniform_frame"):
            self.uniform_frame.fill_(-1)
        if hasattr(self, "mix"):
            p = np.asarray(point, dtype=np.float64).reshape(-1)
            wp.launch(kproposal.set_anchor_kernel, dim=1, inputs=[wp.vec3(*p)], outputs=[self.est], device=self.device)
            self.mix.zero_()

    # --- observation --------------------------------------------------------------------------------
    def upload(self, images: Sequence[np.ndarray]) -> None:
        """Validate one BGR image per camera and copy them to the device (the frame's only host->device copy)."""
        cams = self.rig.cameras
        if len(images) != len(cams):
            raise FrameError(f"got {len(images)} images for a rig of {len(cams)} cameras")
        offs = self.drig.pixel_offsets
        for c, (img, cam) in enumerate(zip(images, cams, strict=True)):
            self._staging_np[3 * offs[c] : 3 * offs[c + 1]] = camera_frame(img, cam).reshape(-1)
        wp.copy(self.bgr, self._staging)

    def _launch_observation(self) -> None:
        if self.maps is not None:
            self.maps.launch(self._target, self.bgr)

    def _launch_detection(self) -> None:
        """Blobs, candidates and the mode test of the current frame (``proposal='mixture'``): four fixed launches
        (sub-block counts, blob keys, peaks per chunk, then the rest in one block: ``kernels.colour.blobs``)."""
        cfg, d, dr = self.config, self.device, self.drig
        m = dr.num_cameras
        obs = [dr.cams, self._target, self.bgr, self._integral, self._window, self._mode_id]
        wp.launch(
            kblobs.subblock_counts_kernel,
            dim=(m, *self._sb_max),
            inputs=[*obs, self.sb_offset],
            outputs=[self.sb_counts],
            device=d,
        )
        wp.launch(
            kblobs.neighbourhood_sums_kernel,
            dim=(m, *self._sb_max),
            inputs=[dr.cams, self.sb_offset, self.sb_counts],
            outputs=[self.sb_keys],
            device=d,
        )
        wp.launch_tiled(
            kblobs.blob_peaks_kernel,
            dim=[m, self._chunks],
            inputs=[dr.cams, self.sb_offset, self.sb_counts, self.sb_keys, cfg.min_blob_pixels],
            outputs=[self.peaks, self.part_score, self.part_index, self.part_uv],
            block_dim=BLOCK,
            device=d,
        )
        lo, hi = (wp.vec3(*v) for v in self.candidate_volume)
        wp.launch_tiled(
            kblobs.detect_tail_kernel,
            dim=[1],
            inputs=[*obs, self.part_score, self.part_index, self.part_uv, self.pair_a, self.pair_b, self._pairs]
            + [cfg.epipolar_px, lo, hi, 2.0 * cfg.detection_sigma, self.est, self.frame, self.uniform_frame]
            + [self._thresholds, cfg.jump_margin, cfg.jump_evidence, 3.0 * cfg.detection_sigma],
            outputs=[self.blob_score, self.blob_uv, self.cand_pos, self.cand_score, self.cand_keep, self.det_pos]
            + [self.det_score, self.det_cum, self.det_count, self.mix],
            block_dim=BLOCK,
            device=d,
        )

    def stages(self, src: int, dst: int):
        """The frame chain as named stages (for profiling); with the mixture proposal a ``detect`` stage (blobs,
        candidates, mode test) runs between ``observe`` and ``predict_score``."""
        stages = super().stages(src, dst)
        if self.config.proposal == "prior":
            return stages
        return [stages[0], ("detect", self._launch_detection), *stages[1:]]

    def _launch_predict_score(self, src: int, dst: int) -> None:
        observation = [self.drig.cams, self._target, self.bgr, self._integral, self._window, self._mode_id]
        cfg = self.config
        map_set = self.score_mode == "map" and self.drig.cam_set.count > 0
        if cfg.proposal == "prior":
            if map_set:  # the large-N kernel (cameras by value)
                kernel = kscoring.colour_predict_score_map_kernel(self.drig.cam_set.count)
                self._launch_fused(kernel, [self.drig.cam_set, self._window], src, dst)
                return
            self._launch_fused(kscoring.colour_predict_score_kernel, observation, src, dst)
            return
        lo, hi = (wp.vec3(*v) for v in self.volume)
        jumps = [self.det_pos, self.det_cum, self.det_count, self.mix, cfg.detection_sigma, self.uniform_frame, lo, hi]
        if map_set:
            kernel = kproposal.colour_jump_predict_score_map_kernel(self.drig.cam_set.count)
            self._launch_fused(kernel, [self.drig.cam_set, self._window, *jumps], src, dst)
            return
        self._launch_fused(kproposal.colour_jump_predict_score_kernel, observation + jumps, src, dst)

    def _readback(self) -> None:
        super()._readback()
        if self.config.proposal != "prior":
            wp.copy(self.det_count_host, self.det_count)
            wp.copy(self.mix_host, self.mix)

    def advance(self) -> Estimate:
        """One frame on the uploaded images; ``Estimate.detection`` is the number of detection candidates kept (0 = no
        candidate: the frame was the paper's) or -1 with ``proposal='prior'``; ``Estimate.jump`` whether the frame
        jumped (mode test fired, or first frame after a random initialisation)."""
        est = super().advance()
        if self.config.proposal != "prior":
            est.detection = int(self.det_count_host.numpy()[0])
            est.jump = bool(self.mix_host.numpy()[int(kproposal.MIX_JUMP)] > 0.5)
        return est

    # --- public API -----------------------------------------------------------------------------------
    def step(self, images: Sequence[np.ndarray]) -> Estimate:
        """Track one synchronised set of frames (one (H, W, 3) uint8 BGR image per camera, rig order)."""
        t0 = time.perf_counter()
        self.upload(images)
        t1 = time.perf_counter()
        est = self.advance()
        est.timings["upload"] = t1 - t0
        return est
