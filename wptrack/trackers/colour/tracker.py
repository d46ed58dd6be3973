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
from wptrack.core.filter import Estimate, ParticleFilter
from wptrack.core.resampling import SCHEMES
from wptrack.io.frames import camera_frame
from wptrack.kernels.colour import hsi as kcolour
from wptrack.kernels.colour import proposal as kproposal
from wptrack.kernels.colour import scoring as kscoring

log = logging.getLogger(__name__)

SCORE_MODES = ("auto", "direct", "integral", "map")
PROPOSALS = ("prior", "mixture")
"""``prior``: the paper's filter (particles drawn from the gaussian walk only); ``mixture``: the detection-driven
mixture proposal of ``wptrack.kernels.colour.proposal`` (converges from anywhere, re-acquires a lost object)."""


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
        "mixture", help="prior: the paper's filter (the gaussian walk only); mixture: (1 - mixture) x the motion prior "
        "+ mixture x a detection proposal from the colour masks, importance-weighted (converges from anywhere, "
        "re-acquires a lost object)", choices=PROPOSALS,
    )  # fmt: skip
    mixture: float = param(
        0.25, help="fraction of particles drawn from the detection proposal (mixture only)", symbol="eps", lo=0.0,
        hi=1.0, hi_open=True,
    )  # fmt: skip
    reset_rate: float = param(
        0.05, help="probability per frame that the object jumps uniformly into the working volume: the motion model's "
        "kidnap term, which makes re-acquisition possible (mixture only)", symbol="alpha", lo=0.0, hi=1.0,
        hi_open=True,
    )  # fmt: skip
    detection_sigma: float = param(
        0.04, help="deviation of each detection component (mixture only)", units="m", symbol="sigma_d", lo=0.0,
        lo_open=True,
    )  # fmt: skip
    detection_components: int = param(
        32, help="gaussian components of the detection proposal (mixture only)", symbol="K", lo=1, hi=4096
    )
    detection_tries: int = param(
        1024, help="rejection-sampling draws per component and camera to find a target pixel (mixture only)", lo=1,
        hi=1 << 20,
    )  # fmt: skip
    max_gap: float = param(
        0.1, help="largest distance between two back-projected rays accepted as a triangulation", units="m", lo=0.0,
        lo_open=True,
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

    kernel_modules = (*ParticleFilter.kernel_modules, "wptrack.kernels.colour.hsi", "wptrack.kernels.colour.scoring")

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
        k = config.detection_components
        self.det_centres = wp.zeros(k, dtype=wp.vec3, device=d)
        self.det_valid = wp.zeros(k, dtype=wp.int32, device=d)
        self.det_count = wp.zeros(1, dtype=wp.int32, device=d)
        self.det_count_host = wp.zeros(1, dtype=wp.int32, device="cpu", pinned=self.is_cuda)
        self.uniform_frame = wp.array([-1], dtype=wp.int32, device=d)
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

    def state_arrays(self) -> dict[str, wp.array]:
        """:meth:`ParticleFilter.state_arrays` and the frame whose prior is the uniform initial box
        (``uniform_frame``); the detection components are recomputed every frame."""
        return {**super().state_arrays(), "uniform_frame": self.uniform_frame}

    def init_box(self, lo, hi) -> None:
        """Particles uniform in the box [lo, hi] (metres); with the mixture proposal the next frame's prior is this
        uniform distribution (alpha = 1 for that frame, ``kernels.colour.proposal``)."""
        super().init_box(lo, hi)
        if hasattr(self, "uniform_frame"):
            self.uniform_frame.fill_(self.frames_done)

    def init_point(self, point) -> None:
        """Put every particle at ``point`` (3,) metres (the paper's initialisation)."""
        super().init_point(point)
        if hasattr(self, "uniform_frame"):
            self.uniform_frame.fill_(-1)

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

    def _launch_predict_score(self, src: int, dst: int) -> None:
        observation = [self.drig.cams, self._target, self.bgr, self._integral, self._window, self._mode_id]
        cfg = self.config
        if cfg.proposal == "prior":
            if self.score_mode == "map" and self.drig.cam_set.count > 0:  # the large-N kernel (cameras by value)
                kernel = kscoring.colour_predict_score_map_kernel(self.drig.cam_set.count)
                self._launch_fused(kernel, [self.drig.cam_set, self._window], src, dst)
                return
            self._launch_fused(kscoring.colour_predict_score_kernel, observation, src, dst)
            return
        d = self.device
        k = cfg.detection_components
        lo, hi = (np.asarray(v, dtype=np.float64) for v in self.volume)
        depth_hi = float(np.linalg.norm(hi - lo))
        wp.launch(
            kproposal.detection_components_kernel,
            dim=k,
            inputs=[self.drig.cams, self._target, self.bgr, self.seed, self.frame, cfg.detection_tries]
            + [cfg.max_gap, 0.1, depth_hi],
            outputs=[self.det_centres, self.det_valid],
            device=d,
        )
        wp.launch(kproposal.detection_count_kernel, dim=1, inputs=[self.det_valid], outputs=[self.det_count], device=d)
        observation += [self.det_centres, self.det_valid, self.det_count, cfg.detection_sigma, cfg.mixture]
        observation += [cfg.reset_rate, self.uniform_frame, wp.vec3(*lo), wp.vec3(*hi)]
        self._launch_fused(kproposal.colour_mixture_predict_score_kernel, observation, src, dst)

    def _readback(self) -> None:
        super()._readback()
        if self.config.proposal != "prior":
            wp.copy(self.det_count_host, self.det_count)

    def advance(self) -> Estimate:
        """One frame on the uploaded images; ``Estimate.detection`` is the number of valid detection components
        (0 = no target pixel in any camera; the proposal fell back to the prior) or -1 with ``proposal='prior'``."""
        est = super().advance()
        est.detection = int(self.det_count_host.numpy()[0]) if self.config.proposal != "prior" else -1
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
