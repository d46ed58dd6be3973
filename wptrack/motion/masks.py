"""Binary motion (foreground) masks, the observations ``q_t`` of the single-camera template tracker of Juza et al.

:class:`MotionMasks` yields one ``(H, W)`` ``uint8`` mask per frame with values ``{0, 1}`` (1 = moving / foreground),
made in one of three ways:

* **offline background model** (``method="offline"``, the default): the whole recording is available, so the
  background of each frame is the per-pixel temporal median of frames sampled before and after it, in sliding
  windows (:mod:`wptrack.motion.background`, Warp kernels in :mod:`wptrack.kernels.core.background`); foreground is the
  robust distance to it (per-pixel noise scale capped by the image-wide one, weak evidence kept where connected to
  strong: hysteresis, and a neighbourhood test for faint coherent changes); cast shadows (same chromaticity, darker by
  the recording's learnt shadow ratio) count as background; a per-frame foreground probability comes beside the mask
  (:meth:`MotionMasks.evidence`); then :func:`clean_mask`;
* **online background subtraction** of a camera's frames (``method="mog2"`` or ``"knn"``): OpenCV's
  ``cv2.createBackgroundSubtractorMOG2`` / ``cv2.createBackgroundSubtractorKNN``; shadow pixels (OpenCV's value
  127, when ``detect_shadows``) count as background; then :func:`clean_mask`: a morphological opening (removes
  isolated noise pixels), a closing (fills small holes), both with elliptical kernels, and optionally the removal
  of connected components smaller than ``min_area`` pixels;
* **given masks** (``method="given"``): a video, image folder, glob or array of masks made elsewhere (colour or
  grey); a pixel is foreground when any channel is ``> threshold``. Given masks are only thresholded, not
  cleaned (``open_px``, ``close_px`` and ``min_area`` apply to subtracted masks only).

Frames and masks are read through :mod:`wptrack.io.frames`, so every source it accepts works here. With a calibrated
:class:`~wptrack.cameras.rig.Camera`, the source's frame size is checked against the calibration before any frame is
processed.
"""

from __future__ import annotations

import dataclasses
import functools
import os
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from wptrack.cameras.rig import Camera
from wptrack.core.config import check, param
from wptrack.core.errors import ConfigError, FrameError
from wptrack.io.frames import FrameSource, open_source
from wptrack.io.prefetch import prefetch

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "SHADOW_VALUE",
    "MaskConfig",
    "MotionMasks",
    "clean_mask",
    "open_masks",
]

#: Mask methods: offline background model, OpenCV (online) background subtractors, or masks given as files/arrays.
METHODS = ("offline", "mog2", "knn", "given")

#: The method used for camera frames unless told otherwise.
DEFAULT_METHOD = "offline"

#: Value OpenCV's background subtractors write for shadow pixels (counted as background here).
SHADOW_VALUE = 127


def _is_int(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _is_real(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


@dataclass(frozen=True)
class MaskConfig:
    """How motion masks are made: the background model (``offline``: windowed temporal median of the whole recording,
    :mod:`wptrack.motion.background`; ``mog2``/``knn``: OpenCV's online models; ``given``: the source already holds
    masks), the shadow test and the clean-up.

    Raises:
        ConfigError: A field is out of range; the message names the field, the expected range and the value.
    """

    method: str = param(
        DEFAULT_METHOD,
        help="background model: offline (whole-recording median), mog2 or knn (online), given (the source holds masks)",
        choices=METHODS,
    )
    history: int = param(200, help="mog2/knn: frames of history the model is learnt over", units="frames", lo=1)
    var_threshold: float = param(
        16.0, help="mog2: squared Mahalanobis distance above which a pixel is foreground", lo=0.0, lo_open=True
    )
    dist2_threshold: float = param(
        400.0, help="knn: squared distance to the nearest samples above which a pixel is foreground",
        units="8-bit levels^2", lo=0.0, lo_open=True,
    )  # fmt: skip
    detect_shadows: bool = param(
        True, help="cast shadows count as background (off: shadows are foreground)", negative="keep-shadows"
    )
    learning_rate: float = param(
        -1.0, help="mog2/knn: learning rate per frame in [0, 1], or -1 for OpenCV's automatic rate", lo=-1.0, hi=1.0
    )
    open_px: int = param(3, help="diameter of the morphological opening (0 or 1: off)", units="px", lo=0)
    close_px: int = param(5, help="diameter of the morphological closing (0 or 1: off)", units="px", lo=0)
    min_area: int = param(0, help="drop 8-connected foreground blobs smaller than this (0: off)", units="px", lo=0)
    threshold: int = param(
        127, help="given masks: a pixel is foreground when any channel is above this", units="8-bit levels", lo=0,
        hi=254, flag="given-threshold",
    )  # fmt: skip
    window: int = param(
        300, help="offline: background window; windows overlap by half, each frame interpolates the two nearest",
        units="frames", lo=1,
    )  # fmt: skip
    samples: int = param(25, help="offline: frames sampled per window for its temporal median", lo=1, hi=64)
    fg_threshold: float = param(
        4.0, help="offline: foreground when the RMS colour distance to the background exceeds this",
        units="robust sigmas", lo=0.0, lo_open=True, flag="fg-threshold",
    )  # fmt: skip
    fg_low: float = param(
        3.0, help="offline: hysteresis low threshold: weaker pixels 8-connected to strong ones are foreground (0: off)",
        units="robust sigmas", lo=0.0,
    )  # fmt: skip
    spread_cap: float = param(
        1.5, help="offline: cap of the per-pixel noise scale, times the image-wide median (0: off; else >= 1)", lo=0.0
    )
    neighbourhood: int = param(
        1, help="offline: radius of the neighbourhood whose mean difference also marks weak foreground (0: off)",
        units="px", lo=0, hi=3,
    )  # fmt: skip
    noise_floor: float = param(
        3.0, help="offline: lower bound of the per-pixel noise deviation", units="8-bit levels", lo=0.0, lo_open=True
    )
    shadow_lo: float = param(
        0.4, help="offline: smallest brightness ratio of a cast shadow", lo=0.0, hi=1.0, lo_open=True, hi_open=True
    )
    shadow_hi: float = param(0.95, help="offline: largest brightness ratio of a cast shadow", lo=0.0, hi=1.0)
    shadow_chroma: float = param(0.1, help="offline: largest chromaticity distortion of a cast shadow", lo=0.0)
    shadow_band: float = param(
        0.08, help="offline: learn the recording's shadow brightness ratio r and take r +- this as shadow (0: the "
        "fixed bounds)", lo=0.0, hi=0.5,
    )  # fmt: skip
    shadow_texture: float = param(
        0.7, help="offline: the learnt shadow ratio counts only the votes that keep the ground's texture: a pixel "
        "whose background patch is textured (illum_texture) and whose sample patch correlates with it at least this "
        "much (NCC) and follows it as a gain (illum_gap, illum_resid); a cast shadow darkens the ground's texture, "
        "dark clothes replace it; with too few such votes (a flat floor), every vote (0: every vote)", lo=0.0,
        hi=1.0, hi_open=True,
    )  # fmt: skip
    shadow_peak: float = param(
        0.1, help="offline: learn the shadow ratio at the most significant peak of the votes' ratios (excess over "
        "their mean within +- this, in Poisson deviations), not the highest: one sky darkens one floor by one ratio, "
        "dark clothes make a broad hump (0: the highest peak)", lo=0.0, hi=0.3,
    )  # fmt: skip
    soft_scale: float = param(
        1.0, help="offline: scale of the foreground probability 1 / (1 + exp(-(z - T) / k))", units="robust sigmas",
        symbol="k", lo=0.0, lo_open=True,
    )  # fmt: skip
    illum_tiles: int = param(
        30, help="offline: local light field (cloud shadows, exposure, lights switched on in part of the view): tiles "
        "along the shorter image side, each tile's gain the median brightness ratio of its pixels whose patch keeps "
        "the background's texture; frames are divided by it before the tests (0: off)", lo=0, hi=1000,
    )  # fmt: skip
    illum_radius: int = param(
        2, help="offline: radius of the weighted median that smooths the tiles' gains", units="tiles", lo=0, hi=4
    )
    illum_keep: float = param(
        0.15, help="offline: a tile keeps its own gains where they differ from that median by at most this (0: the "
        "median everywhere)", units="log gain", lo=0.0, hi=1.0, flag="",
    )  # fmt: skip
    illum_dead: float = param(
        0.03, help="offline: a tile's field whose log gains all lie within this of 0 is 0 (no local change)",
        units="log gain", lo=0.0, hi=0.5, flag="",
    )  # fmt: skip
    illum_windows: bool = param(
        True, help="offline: with illum_tiles, also divide each background window's samples by their own local field "
        "before the window's median, noise scale and learnt shadow ratio", flag="",
    )  # fmt: skip
    illum_patch: int = param(
        3, help="offline: radius of the patches the texture tests compare", units="px", lo=1, hi=7, flag=""
    )
    illum_verify: float = param(
        0.7, help="offline: smallest normalised cross-correlation (NCC) of a pixel's patch with the background's for "
        "it to vote for its tile's gain", lo=0.0, hi=1.0, lo_open=True, hi_open=True, flag="",
    )  # fmt: skip
    illum_veto: float = param(
        0.7, help="offline: a foreground pixel whose textured patch correlates at least this much with the "
        "background's (NCC), follows the patch's fit and keeps the background's colour is a light change (0: off)",
        lo=0.0, hi=1.0, hi_open=True,
    )  # fmt: skip
    illum_grad: float = param(
        0.0, help="offline: as illum_veto with the gradient correlation of the patches (0: off)", lo=0.0, hi=1.0,
        hi_open=True,
    )  # fmt: skip
    illum_texture: float = param(
        2.0, help="offline: smallest deviation of a background patch for the texture tests (a flat patch cannot tell "
        "light from an object)", units="noise scales", lo=0.0, lo_open=True, flag="",
    )  # fmt: skip
    illum_resid: float = param(
        3.0, help="offline: largest residual of a vetoed pixel from its patch's linear fit", units="noise scales",
        lo=0.0, lo_open=True, flag="",
    )  # fmt: skip
    illum_chroma: float = param(
        0.12, help="offline: largest chromaticity distortion of a vetoed pixel", lo=0.0, flag=""
    )
    illum_gap: float = param(
        0.2, help="offline: largest |ln(slope / ratio of the means)| of a patch's linear fit for the texture tests "
        "(light multiplies radiance: its fit is a gain)", units="log gain", lo=0.0, lo_open=True, flag="",
    )  # fmt: skip
    illum_lo: float = param(
        0.3, help="offline: smallest brightness ratio of a vetoed pixel", lo=0.0, hi=1.0, lo_open=True, flag=""
    )
    illum_hi: float = param(3.0, help="offline: largest brightness ratio of a vetoed pixel", lo=1.0, flag="")
    mode_band: float = param(
        3.0, help="offline: each window's background is the densest cluster of a pixel's samples (within this of the "
        "sample with most such neighbours), not the median of all, so a pixel that people cover in most samples of a "
        "short clip keeps its background (0: the median; else 0.5 to 20)", units="noise scales", lo=0.0, hi=20.0,
    )  # fmt: skip
    mode_still: float = param(
        1.5, help="offline: with mode_band, a sample whose patch changed by more than this (or twice the window's "
        "median change, if more) from the samples mode_lag before and after it counts 1/8 in the densest cluster "
        "(people standing for most of a short clip still move; the ground does not; 0: every sample counts 1)",
        units="noise scales", lo=0.0,
    )  # fmt: skip
    mode_lag: float = param(
        0.2, help="offline: time between the samples mode_still compares, rounded to whole sample gaps (at least "
        "one): neighbouring samples unless they are much closer than this", units="s", lo=0.0, lo_open=True,
    )  # fmt: skip
    device: str = param("auto", help="offline: Warp device (auto, cpu, cuda or cuda:N)", flag="")

    def __post_init__(self) -> None:
        check(self, "MaskConfig.")

        def fail(field: str, expected: str) -> None:
            raise ConfigError(f"MaskConfig.{field}: expected {expected}, got {getattr(self, field)!r}")

        if self.learning_rate < 0 and self.learning_rate != -1:
            fail("learning_rate", "a rate in [0, 1] per frame or -1 (automatic)")
        if not (self.fg_low == 0 or self.fg_low <= self.fg_threshold):
            fail("fg_low", f"0 (off) or a value in (0, fg_threshold={self.fg_threshold}] (robust sigmas)")
        if self.neighbourhood and not self.fg_low:
            fail("neighbourhood", "0 unless fg_low is set (it adds weak foreground, kept by the hysteresis)")
        if not (self.spread_cap == 0 or self.spread_cap >= 1):
            fail("spread_cap", "0 (off) or a number >= 1 (times the image-wide median noise scale)")
        if not self.shadow_lo < self.shadow_hi:
            fail("shadow_hi", f"a ratio in (shadow_lo={self.shadow_lo}, 1]")
        if not (self.mode_band == 0 or self.mode_band >= 0.5):
            fail("mode_band", "0 (the median) or in [0.5, 20] (noise scales)")
        if not (self.device in ("auto", "cpu", "cuda") or self.device.startswith("cuda:")):
            fail("device", "'auto', 'cpu', 'cuda' or 'cuda:N'")


@functools.cache
def _kernel(diameter: int) -> np.ndarray:
    import cv2

    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (diameter, diameter))


def clean_mask(mask: np.ndarray, config: MaskConfig) -> np.ndarray:
    """Clean a binary mask: opening, then closing (elliptical kernels), then small-component removal.

    Pixels outside the image count as foreground for the erosions, so foreground touching the border is not
    eroded from outside (an all-ones mask stays all ones).

    Args:
        mask: ``(H, W)`` uint8 mask with values ``{0, 1}``.
        config: Uses ``open_px``, ``close_px`` and ``min_area``.

    Returns:
        ``(H, W)`` uint8 mask with values ``{0, 1}`` (a new array, or ``mask`` itself when nothing is enabled).
    """
    import cv2

    from wptrack.motion.levels import thread_work

    if config.open_px > 1 or config.close_px > 1:
        # OpenCV's opening and closing as their erosions and dilations into the thread's scratch images (the same
        # pixels, OpenCV's default border: outside counts as foreground for an erosion, background for a dilation),
        # so a frame allocates only the mask it returns (fresh pages cost a page fault each: levels.LevelsWork)
        work = thread_work(mask.shape)
        steps = []
        if config.open_px > 1:
            k = _kernel(config.open_px)
            steps += [(cv2.erode, k), (cv2.dilate, k)]
        if config.close_px > 1:
            k = _kernel(config.close_px)
            steps += [(cv2.dilate, k), (cv2.erode, k)]
        for i, (op, k) in enumerate(steps):
            last = i == len(steps) - 1
            mask = op(mask, k) if last else op(mask, k, dst=work.morph if i % 2 == 0 else work.morph2)
    if config.min_area > 1:
        count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        keep = stats[:, cv2.CC_STAT_AREA] >= config.min_area
        keep[0] = False  # label 0 is the background
        mask = keep.astype(np.uint8)[labels]
    return mask


def given_mask(image: np.ndarray, threshold: int) -> np.ndarray:
    """A given mask image's foreground: ``(H, W)`` uint8, 1 where any channel of ``image`` (``(H, W)`` or ``(H, W,
    C)`` uint8) is above ``threshold``: the channels' maximum thresholded by OpenCV, the same values as
    ``np.any(image > threshold, axis=2)`` at a tenth of its time (1440x1080: 1.5 instead of 17 ms)."""
    import cv2

    image = np.asarray(image)
    if image.ndim == 3:
        peak = image[..., 0]
        for c in range(1, image.shape[2]):
            peak = cv2.max(peak, image[..., c])
    else:
        peak = image
    return cv2.threshold(np.ascontiguousarray(peak), int(threshold), 1, cv2.THRESH_BINARY)[1]


DEVICE_CLEANUP_ENV = "WPTRACK_DEVICE_CLEANUP"
"""Environment variable: ``1`` resolves and cleans the offline masks on the device whatever it is, ``0`` on the host
(default: on a CUDA device, :func:`device_cleanup`)."""


def device_cleanup(device: Any) -> bool:
    """Whether the offline model's masks on ``device`` are resolved and cleaned there
    (:class:`wptrack.motion.cleanup.DeviceCleanup`): on a CUDA device unless :data:`DEVICE_CLEANUP_ENV` says ``0``;
    on the CPU only when it says ``1``.

    Raises:
        ConfigError: :data:`DEVICE_CLEANUP_ENV` set to something else than 0 or 1.
    """
    import warp as wp

    value = os.environ.get(DEVICE_CLEANUP_ENV, "").strip()
    if value not in ("", "0", "1"):
        raise ConfigError(f"{DEVICE_CLEANUP_ENV}: expected 0 or 1, got {value!r}")
    if value:
        return value == "1"
    return bool(wp.get_device(device).is_cuda)


class MotionMasks:
    """A sequence of binary motion masks, one per frame of a source.

    Args:
        source: An opened frame source: camera frames (``method`` ``"offline"``/``"mog2"``/``"knn"``) or masks
            (``"given"``).
        config: How masks are made (see :class:`MaskConfig`).
        camera: If given, the source's frame size must equal the camera's calibrated ``(width, height)``.
        rig_source: The rig file the camera came from, named in the size-mismatch message.
        prefetch_depth: Frames decoded ahead by a background thread (0: decode in the iterating thread).

    Raises:
        FrameError: The source's frame size differs from ``camera``'s calibration.
        ConfigError: ``prefetch_depth`` is negative.

    Iterating yields ``(H, W)`` uint8 masks with values ``{0, 1}``; :meth:`evidence` yields each mask with a
    per-pixel foreground probability. Every iteration starts from the first frame with a fresh background model
    (the offline model keeps its windows' backgrounds), so iterating twice gives the same masks. A frame whose size
    differs from the first frame's raises :class:`FrameError` naming the frame index.
    """

    def __init__(
        self,
        source: FrameSource,
        config: MaskConfig = MaskConfig(),
        camera: Camera | None = None,
        rig_source: str | None = None,
        prefetch_depth: int = 2,
    ) -> None:
        if not isinstance(config, MaskConfig):
            raise ConfigError(f"config must be a MaskConfig, got {type(config).__name__}")
        if not _is_int(prefetch_depth) or prefetch_depth < 0:
            raise ConfigError(f"prefetch_depth: must be an integer >= 0 (frames), got {prefetch_depth!r}")
        self.source = source
        self.config = config
        self.camera = camera
        self.prefetch_depth = int(prefetch_depth)
        from wptrack.motion.parallel import mask_workers

        self.workers = 1  # offline masks: threads making them (wptrack.motion.parallel.mask_workers)
        if config.method == "offline":
            from wptrack.core.device import resolve_device

            self.workers = mask_workers(resolve_device(config.device))
        self._model: Any = None
        if camera is not None and (source.width, source.height) != (camera.width, camera.height):
            where = f" in {rig_source}" if rig_source else ""
            raise FrameError(
                f"{source.name}: {self._kind} size {source.width}x{source.height} differs from camera "
                f"'{camera.name}' calibration {camera.width}x{camera.height}{where}"
            )

    @property
    def _kind(self) -> str:
        return "mask" if self.config.method == "given" else "frame"

    @property
    def name(self) -> str:
        """The source's label (path, or ``"array"``)."""
        return self.source.name

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` of the masks, pixels."""
        return (self.source.width, self.source.height)

    def __len__(self) -> int:
        """Number of masks (the source's frame count)."""
        return len(self.source)

    def _subtractor(self) -> Any:
        import cv2

        c = self.config
        if c.method == "mog2":
            return cv2.createBackgroundSubtractorMOG2(
                history=c.history, varThreshold=float(c.var_threshold), detectShadows=bool(c.detect_shadows)
            )
        return cv2.createBackgroundSubtractorKNN(
            history=c.history, dist2Threshold=float(c.dist2_threshold), detectShadows=bool(c.detect_shadows)
        )

    @property
    def model(self) -> Any:
        """The offline background model (:class:`wptrack.motion.background.OfflineBackground`), built on first use;
        ``None`` for the other methods."""
        if self.config.method != "offline":
            return None
        if self._model is None:
            from wptrack.core.device import device_guard, resolve_device
            from wptrack.motion.background import OfflineBackground

            device = resolve_device(self.config.device)
            with device_guard(device).shared():  # allocations: never inside a tracker's graph capture
                self._model = OfflineBackground(self.source, self.config, device)
            self.attach_cleanup(self._model)
        return self._model

    def attach_cleanup(self, model: Any) -> None:
        """On a CUDA device (issue 27) the model resolves and cleans its masks on the device
        (:class:`wptrack.motion.cleanup.DeviceCleanup`, the same masks) and downloads the mask instead of the levels;
        not with ``min_area`` (a host filter). ``WPTRACK_DEVICE_CLEANUP=1`` asks for it on the CPU device too (slower
        there), ``=0`` keeps the host's clean-up on a GPU. Call it outside the device guard's shared sections (it
        takes one for its allocations)."""
        if self.config.min_area <= 1 and device_cleanup(model.device):
            from wptrack.core.device import device_guard
            from wptrack.motion.cleanup import DeviceCleanup

            with device_guard(model.device).shared():  # allocations: never inside a tracker's graph capture
                model.cleanup = DeviceCleanup(*self.size, self.config.open_px, self.config.close_px, model.device)

    def background(self, window: int = 0) -> np.ndarray | None:
        """``(H, W, 3)`` uint8 BGR background of an offline window (for reports); ``None`` for other methods."""
        model = self.model
        return None if model is None else model.background(window)

    def __iter__(self) -> Iterator[np.ndarray]:
        evidence = self.evidence(probability=False)
        try:
            for mask, _ in evidence:
                yield mask
        finally:  # a consumer leaving early stops the mask threads now, not when the generator is collected
            evidence.close()

    def evidence(self, probability: bool = True) -> Iterator[tuple[np.ndarray, np.ndarray | None]]:
        """Yield ``(mask, prob)`` per frame.

        ``mask`` is the ``(H, W)`` uint8 mask of iteration; ``prob`` an ``(H, W)`` float32 foreground probability
        in ``[0, 1]``: for ``"offline"`` the model's soft evidence before the clean-up (see
        :mod:`wptrack.kernels.core.background`), for the other methods the mask itself (0 or 1); None when not
        asked for (``probability=False``, as iterating does) and not made anyway.
        """
        c = self.config
        width, height = self.size
        model = self.model
        frames = prefetch(self.source, depth=self.prefetch_depth) if self.prefetch_depth else self.source
        watched = frames
        if c.method != "given":  # camera frames: one warning if the camera moves (wptrack.motion.camera_motion)
            from wptrack.motion.camera_motion import CameraMotionWatch, watch_frames

            watched = watch_frames(frames, CameraMotionWatch(name=self.name))
        subtractor = None if c.method in ("given", "offline") else self._subtractor()
        builder = None
        if model is not None:
            from wptrack.core.device import device_guard

            model.want_prob = probability
            guard = device_guard(model.device)
        try:
            if model is not None and self.workers > 1:  # several models in threads, masks in frame order
                from wptrack.motion.parallel import parallel_evidence

                yield from parallel_evidence(self, watched, self.workers, lambda raw: clean_mask(raw, c), probability)
                return
            if model is not None:  # the windows after the first built by a worker, ahead of the frames
                from wptrack.motion.parallel import build_ahead

                builder = build_ahead(model, guard)
            for index, frame in enumerate(watched):
                if frame.shape[:2] != (height, width):
                    raise FrameError(
                        f"{self.name}: {self._kind} {index} is {frame.shape[1]}x{frame.shape[0]} pixels, but the "
                        f"sequence started with {width}x{height} (the frame size must not change)"
                    )
                if model is not None:
                    with guard.shared():  # a tracker's graph capture in another thread waits for this frame's work
                        raw, prob = model.evidence(index, frame)
                    yield (raw if model.cleanup is not None else clean_mask(raw, c)), prob
                    continue
                if subtractor is None:
                    mask = given_mask(frame, c.threshold)
                else:
                    foreground = subtractor.apply(frame, learningRate=float(c.learning_rate))
                    mask = clean_mask((foreground > SHADOW_VALUE).view(np.uint8), c)
                yield mask, mask.astype(np.float32) if probability else None
        finally:
            if isinstance(frames, prefetch):
                frames.close()
            if builder is not None:
                from wptrack.motion.parallel import stop_building_ahead

                stop_building_ahead(model, builder)
            if model is not None:
                model.close()

    def __repr__(self) -> str:
        return f"MotionMasks({self.name!r}, {self.config.method}, {len(self)} masks, {self.size[0]}x{self.size[1]})"


def open_masks(
    video: str | os.PathLike | np.ndarray | None = None,
    masks: str | os.PathLike | np.ndarray | None = None,
    config: MaskConfig = MaskConfig(),
    camera: Camera | None = None,
    *,
    rig_source: str | None = None,
    name: str | None = None,
) -> MotionMasks:
    """Open a camera's motion masks, from its frames (background subtraction) or from given masks.

    Args:
        video: Camera frames: a video file, image folder, glob or uint8 array ``(T, H, W[, 3])``
            (see :func:`wptrack.io.frames.open_source`); masks are made with ``config.method`` (``"offline"``, the
            default, ``"mog2"`` or ``"knn"``).
        masks: Given masks, in any of the same forms (colour or grey; foreground: any channel > ``threshold``).
            ``config.method`` is taken as ``"given"`` whatever it says.
        config: Mask settings.
        camera: If given, the frame/mask size is checked against its calibrated size before anything is read
            beyond the first frame.
        rig_source: The rig file ``camera`` came from, for the size-mismatch message.
        name: Label for messages (default: the path, or ``"array"``).

    Returns:
        The masks (iterable, with ``len`` and ``size``).

    Raises:
        ConfigError: Not exactly one of ``video`` / ``masks``, or ``method="given"`` with ``video``.
        FrameError: The source cannot be opened, or its size differs from ``camera``'s calibration.
    """
    if (video is None) == (masks is None):
        raise ConfigError("give exactly one of video (camera frames) or masks (given motion masks)")
    if video is not None and config.method == "given":
        raise ConfigError(
            "MaskConfig.method 'given' expects masks=..., not video=... (or use 'offline', 'mog2' or 'knn')"
        )
    if masks is not None and config.method != "given":
        config = dataclasses.replace(config, method="given")
    spec = video if video is not None else masks
    assert spec is not None
    source = open_source(spec, name=name)
    return MotionMasks(source, config=config, camera=camera, rig_source=rig_source)
