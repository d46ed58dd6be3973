"""Binary motion (foreground) masks, the observations ``q_t`` of the single-camera template tracker of Juza et al.

:class:`MotionMasks` yields one ``(H, W)`` ``uint8`` mask per frame with values ``{0, 1}`` (1 = moving / foreground),
made in one of three ways:

* **offline background model** (``method="offline"``, the default): the whole recording is available, so the
  background of each frame is the per-pixel temporal median of frames sampled before and after it, in sliding
  windows (:mod:`wptrack.background`, Warp kernels in :mod:`wptrack.kernels.background`); foreground is the robust
  distance to it (per-pixel noise scale capped by the image-wide one, weak evidence kept where connected to strong:
  hysteresis, and a neighbourhood test for faint coherent changes); cast shadows (same chromaticity, darker by the
  recording's learnt shadow ratio) count as background; a per-frame foreground probability comes beside the mask
  (:meth:`MotionMasks.evidence`); then :func:`clean_mask`;
* **online background subtraction** of a camera's frames (``method="mog2"`` or ``"knn"``): OpenCV's
  ``cv2.createBackgroundSubtractorMOG2`` / ``cv2.createBackgroundSubtractorKNN``; shadow pixels (OpenCV's value
  127, when ``detect_shadows``) count as background; then :func:`clean_mask`: a morphological opening (removes
  isolated noise pixels), a closing (fills small holes), both with elliptical kernels, and optionally the removal
  of connected components smaller than ``min_area`` pixels;
* **given masks** (``method="given"``): a video, image folder, glob or array of masks made elsewhere (colour or
  grey); a pixel is foreground when any channel is ``> threshold``. Given masks are only thresholded, not
  cleaned (``open_px``, ``close_px`` and ``min_area`` apply to subtracted masks only).

Frames and masks are read through :mod:`wptrack.frames`, so every source it accepts works here. With a calibrated
:class:`~wptrack.rig.Camera`, the source's frame size is checked against the calibration before any frame is
processed.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import ConfigError, FrameError
from .frames import FrameSource, open_source, prefetch
from .rig import Camera

__all__ = [
    "DEFAULT_METHOD",
    "METHODS",
    "SHADOW_VALUE",
    "MaskConfig",
    "MotionMasks",
    "clean_mask",
    "open_masks",
    "write_masks",
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
    """How motion masks are made.

    Attributes:
        method: ``"offline"`` (windowed temporal-median background of the whole recording, see
            :mod:`wptrack.background`), ``"mog2"`` (online Gaussian-mixture background model), ``"knn"`` (online
            K-nearest-neighbour background model) or ``"given"`` (the source already holds masks; see ``threshold``).
        history: Frames of history the background model is learnt over (>= 1).
        var_threshold: MOG2 only: squared Mahalanobis distance above which a pixel is foreground (> 0).
        dist2_threshold: KNN only: squared distance (in 8-bit intensity units squared) to the nearest samples
            above which a pixel is foreground (> 0).
        detect_shadows: Mark shadows (darker pixels of the same colour), which then count as background; ``False``
            makes shadows foreground. Offline: the test of ``shadow_lo``, ``shadow_hi`` and ``shadow_chroma``.
        learning_rate: Background-model learning rate in ``[0, 1]`` per frame, or ``-1`` for OpenCV's automatic
            rate (about ``1 / min(frames seen, history)``).
        open_px: Diameter in pixels of the elliptical kernel of the morphological opening (>= 0; 0 or 1 disables).
        close_px: Diameter in pixels of the elliptical kernel of the morphological closing (>= 0; 0 or 1 disables).
        min_area: Connected components (8-connected) with fewer pixels than this are removed (>= 0; 0 disables).
        threshold: Given masks only: a pixel is foreground when any channel is ``> threshold`` (0 to 254).
        window: Offline only: background window length in frames (>= 1); windows overlap by half, each frame
            uses the two nearest windows' backgrounds interpolated. A shorter recording uses one window.
        samples: Offline only: frames sampled per window for its temporal median (1 to 64).
        fg_threshold: Offline only: foreground when the RMS colour distance to the background exceeds this many
            robust standard deviations (> 0).
        fg_low: Offline only: hysteresis low threshold, robust standard deviations: a pixel with
            ``fg_low < z <= fg_threshold`` (not a shadow) is foreground when 8-connected to one above ``fg_threshold``
            (0 disables; else in ``(0, fg_threshold]``).
        neighbourhood: Offline only: radius in pixels of the neighbourhood whose mean difference to the background
            also marks weak foreground (:func:`wptrack.kernels.background.neighbourhood_kernel`: a faint but
            coherent change, as a dark car's roof on the road; 0 disables; 0 to 3). Needs ``fg_low``.
        spread_cap: Offline only: the per-pixel noise scale is capped at this many times the image-wide median
            scale of the window (0 disables; else >= 1), so an object standing still in many of a window's samples
            does not inflate its own pixels' noise scale and vanish.
        noise_floor: Offline only: lower bound of the per-pixel noise standard deviation, 8-bit units (> 0).
        shadow_lo: Offline only: smallest brightness ratio (pixel / background along the background colour) of a
            cast shadow, in ``(0, shadow_hi)``.
        shadow_hi: Offline only: largest brightness ratio of a cast shadow, in ``(shadow_lo, 1]``.
        shadow_band: Offline only: learn the shadows' brightness ratio ``r`` from the recording (the peak of the
            ratios of candidate shadow pixels of each window's samples, see :func:`wptrack.background.shadow_ratio`)
            and take ``r - shadow_band <= a <= r + shadow_band`` as cast shadow (``shadow_lo`` then no longer
            applies: nothing darker than the scene's own shadows is a shadow), and
            ``r + shadow_band < a <= shadow_hi`` as shadow only within 3 px of it (the penumbra); 0 disables (then,
            and where nothing is learnt: ``shadow_lo <= a <= shadow_hi``); else in ``(0, 0.5]``.
        shadow_chroma: Offline only: largest chromaticity distortion ``|I - a B| / |B|`` of a cast shadow (>= 0).
        soft_scale: Offline only: scale ``k`` of the foreground probability ``1 / (1 + exp(-(z - T) / k))``, robust
            standard deviations (> 0).
        illum_tiles: Offline only: local illumination field (cloud shadows, lights switched on in part of the view):
            the image is cut into tiles, this many along its shorter side (0 disables), each tile's gain per
            channel is the median brightness ratio of its pixels whose patch keeps the background's texture
            (``illum_verify``), smoothed over ``illum_radius`` tiles and interpolated, and frames are divided by it
            before the tests (:mod:`wptrack.background`).
        illum_radius: Offline only: radius in tiles of the weighted median that smooths the tiles' gains (0 to 4).
        illum_keep: Offline only: a tile keeps its own gains where they differ from that median by at most this
            much (log gain, mean over the channels; 0: the median everywhere; 0 to 1).
        illum_dead: Offline only: a tile's field whose log gains all lie within this of 0 is 0 (no local change;
            0 to 0.5).
        illum_windows: Offline only: with ``illum_tiles``, also divide each background window's samples by their
            own local field before the window's median, noise scale and learnt shadow ratio.
        illum_patch: Offline only: radius in pixels of the patches the texture tests compare (1 to 7).
        illum_verify: Offline only: smallest normalised cross-correlation (NCC) of a pixel's patch with the
            background's for it to vote for its tile's gain (in ``(0, 1)``).
        illum_veto: Offline only: a foreground pixel whose textured patch correlates at least this much with the
            background's (NCC), whose own value follows the patch's fit and whose colour is the background's scaled
            is a local illumination change, not foreground (0 disables; else in ``(0, 1)``).
        illum_grad: Offline only: as ``illum_veto`` with the gradient correlation of the patches (0 disables).
        illum_texture: Offline only: smallest standard deviation of a background patch, in noise scales, for the
            texture tests (a flat patch cannot tell light from an object; > 0).
        illum_resid: Offline only: largest residual of a pixel from its patch's linear fit, luminance noise
            scales, for the veto (> 0).
        illum_chroma: Offline only: largest chromaticity distortion of a vetoed pixel (>= 0).
        illum_gap: Offline only: largest ``|ln(slope / ratio of the means)|`` of a patch's linear fit for the
            texture tests: light multiplies radiance, so the fit of a light change is a gain (> 0).
        illum_lo: Offline only: smallest brightness ratio of a vetoed pixel (in ``(0, 1]``).
        illum_hi: Offline only: largest brightness ratio of a vetoed pixel (>= 1).
        mode_band: Offline only: each window's background is the densest cluster of a pixel's samples (those within
            this many noise scales of the sample with most such neighbours, every channel; their median) instead
            of the median of all its samples, so a pixel that moving objects cover in most samples of a short
            recording keeps its background (:func:`wptrack.kernels.background.mode_kernel`; 0: the median).
        device: Offline only: Warp device, ``"auto"``, ``"cpu"``, ``"cuda"`` or ``"cuda:N"``.

    Raises:
        ConfigError: A field is out of range; the message names the field and the expected range.
    """

    method: str = DEFAULT_METHOD
    history: int = 200
    var_threshold: float = 16.0
    dist2_threshold: float = 400.0
    detect_shadows: bool = True
    learning_rate: float = -1.0
    open_px: int = 3
    close_px: int = 5
    min_area: int = 0
    threshold: int = 127
    window: int = 300
    samples: int = 25
    fg_threshold: float = 4.0
    fg_low: float = 3.0
    spread_cap: float = 1.5
    neighbourhood: int = 1
    noise_floor: float = 3.0
    shadow_lo: float = 0.4
    shadow_hi: float = 0.95
    shadow_chroma: float = 0.1
    shadow_band: float = 0.08
    soft_scale: float = 1.0
    illum_tiles: int = 30
    illum_radius: int = 2
    illum_keep: float = 0.15
    illum_dead: float = 0.03
    illum_windows: bool = True
    illum_patch: int = 3
    illum_verify: float = 0.7
    illum_veto: float = 0.7
    illum_grad: float = 0.0
    illum_texture: float = 2.0
    illum_resid: float = 3.0
    illum_chroma: float = 0.12
    illum_gap: float = 0.2
    illum_lo: float = 0.3
    illum_hi: float = 3.0
    mode_band: float = 3.0
    device: str = "auto"

    def __post_init__(self) -> None:
        def fail(field: str, expected: str) -> None:
            raise ConfigError(f"MaskConfig.{field}: must be {expected}, got {getattr(self, field)!r}")

        if not isinstance(self.method, str) or self.method not in METHODS:
            fail("method", "one of " + ", ".join(repr(m) for m in METHODS))
        if not _is_int(self.history) or self.history < 1:
            fail("history", "an integer >= 1 (frames)")
        for field in ("var_threshold", "dist2_threshold"):
            value = getattr(self, field)
            if not _is_real(value) or not math.isfinite(value) or value <= 0:
                fail(field, "a finite number > 0")
        if not isinstance(self.detect_shadows, (bool, np.bool_)):
            fail("detect_shadows", "True or False")
        lr = self.learning_rate
        if not _is_real(lr) or not (lr == -1 or 0 <= lr <= 1):
            fail("learning_rate", "in [0, 1] (per frame) or -1 (automatic)")
        for field in ("open_px", "close_px"):
            if not _is_int(getattr(self, field)) or getattr(self, field) < 0:
                fail(field, "an integer >= 0 (kernel diameter in pixels; 0 disables)")
        if not _is_int(self.min_area) or self.min_area < 0:
            fail("min_area", "an integer >= 0 (pixels; 0 disables)")
        if not _is_int(self.threshold) or not 0 <= self.threshold <= 254:
            fail("threshold", "an integer in [0, 254] (foreground: pixel > threshold)")
        if not _is_int(self.window) or self.window < 1:
            fail("window", "an integer >= 1 (frames)")
        if not _is_int(self.samples) or not 1 <= self.samples <= 64:
            fail("samples", "an integer in [1, 64] (frames per window)")
        for field, expected in (
            ("fg_threshold", "a finite number > 0 (robust standard deviations)"),
            ("noise_floor", "a finite number > 0 (8-bit units)"),
            ("soft_scale", "a finite number > 0 (robust standard deviations)"),
        ):
            value = getattr(self, field)
            if not _is_real(value) or not math.isfinite(value) or value <= 0:
                fail(field, expected)
        if not _is_real(self.fg_low) or not (self.fg_low == 0 or 0 < self.fg_low <= self.fg_threshold):
            fail("fg_low", f"0 (off) or in (0, fg_threshold={self.fg_threshold}] (robust standard deviations)")
        if not _is_int(self.neighbourhood) or not 0 <= self.neighbourhood <= 3:
            fail("neighbourhood", "an integer in [0, 3] (pixels; 0 disables)")
        if self.neighbourhood and not self.fg_low:
            fail("neighbourhood", "0 unless fg_low is set (it adds weak foreground, kept by the hysteresis)")
        if not _is_real(self.spread_cap) or not (self.spread_cap == 0 or 1 <= self.spread_cap < math.inf):
            fail("spread_cap", "0 (off) or a finite number >= 1 (times the image-wide median noise scale)")
        for field in ("shadow_lo", "shadow_hi", "shadow_chroma"):
            if not _is_real(getattr(self, field)) or not math.isfinite(getattr(self, field)):
                fail(field, "a finite number")
        if not 0 < self.shadow_lo < 1:
            fail("shadow_lo", "in (0, 1) (brightness ratio)")
        if not self.shadow_lo < self.shadow_hi <= 1:
            fail("shadow_hi", f"in (shadow_lo={self.shadow_lo}, 1] (brightness ratio)")
        if not _is_real(self.shadow_band) or not 0 <= self.shadow_band <= 0.5:
            fail("shadow_band", "in [0, 0.5] (brightness ratio; 0: fixed bounds)")
        if self.shadow_chroma < 0:
            fail("shadow_chroma", ">= 0 (chromaticity distortion)")
        if not _is_int(self.illum_tiles) or not 0 <= self.illum_tiles <= 1000:
            fail("illum_tiles", "an integer in [0, 1000] (tiles along the shorter image side; 0 disables)")
        if not _is_int(self.illum_radius) or not 0 <= self.illum_radius <= 4:
            fail("illum_radius", "an integer in [0, 4] (tiles)")
        if not _is_real(self.illum_keep) or not 0 <= self.illum_keep <= 1:
            fail("illum_keep", "in [0, 1] (log gain)")
        if not _is_real(self.illum_dead) or not 0 <= self.illum_dead <= 0.5:
            fail("illum_dead", "in [0, 0.5] (log gain)")
        if not isinstance(self.illum_windows, (bool, np.bool_)):
            fail("illum_windows", "True or False")
        if not _is_int(self.illum_patch) or not 1 <= self.illum_patch <= 7:
            fail("illum_patch", "an integer in [1, 7] (pixels)")
        for field in ("illum_verify", "illum_veto", "illum_grad", "illum_texture", "illum_resid", "illum_chroma",
                      "illum_lo", "illum_hi"):  # fmt: skip
            if not _is_real(getattr(self, field)) or not math.isfinite(getattr(self, field)):
                fail(field, "a finite number")
        if not 0 < self.illum_verify < 1:
            fail("illum_verify", "in (0, 1) (normalised cross-correlation)")
        for field in ("illum_veto", "illum_grad"):
            if not 0 <= getattr(self, field) < 1:
                fail(field, "0 (off) or in (0, 1) (correlation)")
        for field in ("illum_texture", "illum_resid"):
            if getattr(self, field) <= 0:
                fail(field, "> 0 (noise scales)")
        if not _is_real(self.illum_gap) or not 0 < self.illum_gap < math.inf:
            fail("illum_gap", "a finite number > 0 (log gain)")
        if self.illum_chroma < 0:
            fail("illum_chroma", ">= 0 (chromaticity distortion)")
        if not 0 < self.illum_lo <= 1:
            fail("illum_lo", "in (0, 1] (brightness ratio)")
        if not self.illum_hi >= 1:
            fail("illum_hi", ">= 1 (brightness ratio)")
        if not _is_real(self.mode_band) or not (self.mode_band == 0 or 0.5 <= self.mode_band <= 20):
            fail("mode_band", "0 (the median) or in [0.5, 20] (noise scales)")
        if not isinstance(self.device, str) or not (
            self.device in ("auto", "cpu", "cuda") or self.device.startswith("cuda:")
        ):
            fail("device", "'auto', 'cpu', 'cuda' or 'cuda:N'")


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

    if config.open_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, _kernel(config.open_px))
    if config.close_px > 1:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _kernel(config.close_px))
    if config.min_area > 1:
        count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        keep = stats[:, cv2.CC_STAT_AREA] >= config.min_area
        keep[0] = False  # label 0 is the background
        mask = keep.astype(np.uint8)[labels]
    return mask


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
        """The offline background model (:class:`wptrack.background.OfflineBackground`), built on first use;
        ``None`` for the other methods."""
        if self.config.method != "offline":
            return None
        if self._model is None:
            from .background import OfflineBackground
            from .device import resolve_device

            self._model = OfflineBackground(self.source, self.config, resolve_device(self.config.device))
        return self._model

    def background(self, window: int = 0) -> np.ndarray | None:
        """``(H, W, 3)`` uint8 BGR background of an offline window (for reports); ``None`` for other methods."""
        model = self.model
        return None if model is None else model.background(window)

    def __iter__(self) -> Iterator[np.ndarray]:
        for mask, _ in self.evidence():
            yield mask

    def evidence(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Yield ``(mask, prob)`` per frame.

        ``mask`` is the ``(H, W)`` uint8 mask of iteration; ``prob`` an ``(H, W)`` float32 foreground probability
        in ``[0, 1]``: for ``"offline"`` the model's soft evidence before the clean-up (see
        :mod:`wptrack.kernels.background`), for the other methods the mask itself (0 or 1).
        """
        c = self.config
        width, height = self.size
        model = self.model
        frames = prefetch(self.source, depth=self.prefetch_depth) if self.prefetch_depth else self.source
        subtractor = None if c.method in ("given", "offline") else self._subtractor()
        try:
            for index, frame in enumerate(frames):
                if frame.shape[:2] != (height, width):
                    raise FrameError(
                        f"{self.name}: {self._kind} {index} is {frame.shape[1]}x{frame.shape[0]} pixels, but the "
                        f"sequence started with {width}x{height} (the frame size must not change)"
                    )
                if model is not None:
                    raw, prob = model.evidence(index, frame)
                    yield clean_mask(raw, c), prob
                    continue
                if subtractor is None:
                    image = frame if frame.ndim == 3 else frame[..., None]
                    mask = np.any(image > c.threshold, axis=2).view(np.uint8)
                else:
                    foreground = subtractor.apply(frame, learningRate=float(c.learning_rate))
                    mask = clean_mask((foreground > SHADOW_VALUE).view(np.uint8), c)
                yield mask, mask.astype(np.float32)
        finally:
            if isinstance(frames, prefetch):
                frames.close()
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
            (see :func:`wptrack.frames.open_source`); masks are made with ``config.method`` (``"offline"``, the
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


def write_masks(
    video: str | os.PathLike | np.ndarray,
    out_dir: str | os.PathLike,
    config: MaskConfig = MaskConfig(),
    probability: bool = False,
    max_frames: int | None = None,
) -> dict[str, Any]:
    """Make a video's motion masks and write them (``wptrack masks``).

    Outputs in ``out_dir``: ``masks.avi`` (masks as 0/255 grey frames, lossless FFV1 where OpenCV has it),
    ``probability.avi`` (with ``probability``: the foreground probability times 255), ``background.png`` (offline
    method: the first window's background) and ``masks.json`` (inputs, config, frame count, codec, timing). Videos
    are written atomically: an error leaves no half-written video.

    Args:
        video: Camera frames (any :func:`wptrack.frames.open_source` spec).
        out_dir: Output folder (created).
        config: Mask settings (``method`` ``"given"`` is refused: there is nothing to make).
        probability: Also write ``probability.avi``.
        max_frames: Stop after this many frames (``None``: all).

    Returns:
        The summary written to ``masks.json``.

    Raises:
        ConfigError: ``method="given"``.
        FrameError: The video cannot be read.
        OutputError: ``out_dir`` or a file in it cannot be written.
    """
    import time

    from .frames import VideoWriter
    from .io import atomic_write_bytes, atomic_write_json, ensure_writable_dir

    masks = open_masks(video=video, config=config)
    out = ensure_writable_dir(out_dir)
    fps = masks.source.fps or 25.0
    t0 = time.perf_counter()
    frames = 0
    with VideoWriter(out / "masks.avi", fps=fps, size=masks.size) as mw:
        pw = VideoWriter(out / "probability.avi", fps=fps, size=masks.size) if probability else None
        try:
            for mask, prob in masks.evidence():
                if max_frames is not None and frames >= max_frames:
                    break
                mw.write(mask * np.uint8(255))
                if pw is not None:
                    pw.write(np.round(prob * 255.0).astype(np.uint8))
                frames += 1
        except BaseException:
            if pw is not None:
                pw.abort()
            raise
        if pw is not None:
            pw.close()
    elapsed = time.perf_counter() - t0
    summary: dict[str, Any] = {
        "video": video if not isinstance(video, np.ndarray) else "array",
        "frames": frames,
        "size": list(masks.size),
        "fps": fps,
        "codec": mw.codec,
        "seconds": elapsed,
        "config": dataclasses.asdict(config),
        "outputs": ["masks.avi"] + (["probability.avi"] if probability else []),
    }
    background = masks.background()
    if background is not None:
        import cv2

        ok, png = cv2.imencode(".png", background)
        if ok:
            atomic_write_bytes(out / "background.png", png.tobytes())
            summary["outputs"].append("background.png")
        summary["windows"] = [list(w.samples) for w in masks.model.windows]
    summary["outputs"].append("masks.json")
    atomic_write_json(out / "masks.json", summary)
    return summary
