"""A camera that moves (pans, tilts, drifts): say so once, instead of tracking moving background as objects.

Motion masks (offline median, MOG2, KNN) and the rig's calibration assume a fixed camera. A shake of a few pixels
floods a few masks and :class:`wptrack.motion.flood.FloodGuard` holds them; a camera that keeps moving changes every
mask gradually (a 4-pixel-per-frame pan of the s3 plaza: 4-12 % foreground in every frame, never a jump) and the
template tracker followed 8 ghosts without a word. :class:`CameraMotionWatch` measures, on every ``every``-th frame,
the global shift of the view since a reference frame (phase correlation of the green channel 160 pixels wide,
Hanning window; 0.45 ms a sample at 1920x1080 on the 2-core CI CPU) and logs one warning when the shift exceeds
``fraction`` of the image width, with a clear peak, in ``needed`` samples in a row. :class:`MotionMasks
<wptrack.motion.masks.MotionMasks>` watches every camera's frames it makes masks of.

The reference is the first frame, renewed only by a sample that clearly has not moved (the light of the day changes
the view), never by the previous sample: the shift between two nearby frames of a busy fixed street reads several
pixels (the crowd moves one way; TownCentre 4-10 px at 1920 wide), but it does not add up, while a moving camera's
does. Measured (fix4 report): no warning on the fixed PETS, TownCentre and terrace clips (400, 96 and 2 x 500
frames); pans and tilts of 0.5-2 px a frame made of them are told within 15-60 frames, except pans of the busy
TownCentre street, whose peaks the crowd keeps low (a limit of a global shift, not a bug).

A fast pan leaves the first frame's view within a few samples (20 px a frame at 320 wide: a third of the view between
two samples), after which the phase correlation against the first frame reads noise or an aliased shift. So each
sample is also compared with the previous sample: ``needed`` steps in a row, each a clear peak of at least
``fraction`` of the width and in the same direction as the one before it (cosine >= 0.5), are a moving camera, and the
warning gives their sum. A busy fixed street's steps (a few pixels, any direction) stay far below that.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from wptrack.core.errors import ConfigError

log = logging.getLogger(__name__)

__all__ = ["CameraMotionWatch", "watch_frames"]

SMALL_WIDTH = 160
"""Width of the grey images the shift is measured on, pixels."""


@dataclass
class CameraMotionWatch:
    """Global shift of a camera's view since its first frame, and one warning when the camera moves.

    Attributes:
        name: Source label for the warning.
        every: Measure every this many frames (>= 1).
        fraction: Shift, as a fraction of the image width, above which a sample counts as moved (0..1).
        needed: Moved samples in a row before the warning (>= 1).
        min_response: Smallest phase-correlation peak for a sample to count (a view changed by light, or covered by
            people, reads noise: low peaks).
        rekey_response: A sample whose peak is at least this and whose shift is at most ``rekey_shift`` pixels (of
            the small image) becomes the new reference: a fixed camera's reference follows the light of the day.
        rekey_shift: See ``rekey_response``, pixels of the 160-wide image.
        moved_at: Frame index of the warning (None: not warned).
        largest: The largest shift measured so far with a clear peak (``min_response``), full-resolution pixels.
    """

    name: str = "video"
    every: int = 5
    fraction: float = 0.03
    needed: int = 3
    min_response: float = 0.2
    rekey_response: float = 0.5
    rekey_shift: float = 0.5
    moved_at: int | None = None
    largest: float = 0.0
    _ref: np.ndarray | None = field(default=None, repr=False)
    _window: np.ndarray | None = field(default=None, repr=False)
    _scale: float = field(default=1.0, repr=False)
    _run: int = field(default=0, repr=False)
    _prev: np.ndarray | None = field(default=None, repr=False)
    _steps: list[tuple[float, float]] = field(default_factory=list, repr=False)

    def __post_init__(self) -> None:
        if int(self.every) != self.every or self.every < 1:
            raise ConfigError(f"CameraMotionWatch.every: expected an integer >= 1 (frames), got {self.every!r}")
        if not 0.0 < self.fraction < 1.0:
            raise ConfigError(
                f"CameraMotionWatch.fraction: expected a fraction of the width in (0, 1), got {self.fraction!r}"
            )
        if int(self.needed) != self.needed or self.needed < 1:
            raise ConfigError(f"CameraMotionWatch.needed: expected an integer >= 1 (samples), got {self.needed!r}")

    def _small(self, frame: np.ndarray) -> np.ndarray:
        import cv2

        h, w = frame.shape[:2]
        step = max(1, w // (2 * SMALL_WIDTH))  # every step-th pixel first (1080p: a 320-wide copy), then area-average
        grey = frame[::step, ::step] if frame.ndim == 2 else frame[::step, ::step, 1 if frame.shape[2] >= 3 else 0]
        grey = np.ascontiguousarray(grey)  # green: most of the luma
        h, w = grey.shape[:2]
        self._scale = frame.shape[1] / min(w, SMALL_WIDTH)
        if w > SMALL_WIDTH:
            grey = cv2.resize(grey, (SMALL_WIDTH, max(8, round(h * SMALL_WIDTH / w))), interpolation=cv2.INTER_AREA)
        return np.asarray(grey, dtype=np.float32)

    def shift(self, frame: np.ndarray) -> tuple[float, float]:
        """The shift of ``frame``'s view from the first frame's, full-resolution pixels, and the peak's response
        (the first call sets the reference and returns ``(0, 1)``). Also records the step from the previous call's
        view (:meth:`_step`)."""
        import cv2

        small = self._small(frame)
        if self._ref is None or self._ref.shape != small.shape:
            self._ref = self._prev = small
            self._window = cv2.createHanningWindow((small.shape[1], small.shape[0]), cv2.CV_32F)
            self._steps = []
            return 0.0, 1.0
        (dx, dy), response = cv2.phaseCorrelate(self._ref, small, self._window)
        if response >= self.rekey_response and np.hypot(dx, dy) <= self.rekey_shift:
            self._ref = small  # unmoved, clearly: the newer view is the better reference
        self._step(small, frame.shape[1])
        return float(np.hypot(dx, dy) * self._scale), float(response)

    def _step(self, small: np.ndarray, width: int) -> None:
        """The shift from the previous sample's view: appended to the current run of large steps in one direction
        (full-resolution pixels), or the run restarts."""
        import cv2

        (sx, sy), response = cv2.phaseCorrelate(self._prev, small, self._window)
        self._prev = small
        step = (float(sx * self._scale), float(sy * self._scale))
        large = response >= self.min_response and np.hypot(*step) > self.fraction * width
        if not large:
            self._steps = []
            return
        if self._steps:
            last = self._steps[-1]
            cos = (last[0] * step[0] + last[1] * step[1]) / (np.hypot(*last) * np.hypot(*step))
            if cos < 0.5:  # a shake back and forth, not a pan
                self._steps = []
        self._steps.append(step)

    def add(self, index: int, frame: np.ndarray) -> None:
        """Look at frame ``index`` (every ``every``-th is measured until the warning)."""
        if self.moved_at is not None or index % self.every:
            return
        moved, response = self.shift(frame)
        if response >= self.min_response:
            self.largest = max(self.largest, moved)
        width = frame.shape[1]
        if moved > self.fraction * width and response >= self.min_response:
            self._run += 1
        else:
            self._run = 0
        since = "since the first frame"
        if len(self._steps) >= self.needed:  # a fast pan: the sum of its steps (the reference may read it aliased)
            chain = float(np.hypot(sum(s[0] for s in self._steps), sum(s[1] for s in self._steps)))
            self.largest = max(self.largest, chain)
            if self._run < self.needed or chain > moved:
                moved, since = chain, f"in {len(self._steps) * self.every} frames"
        elif self._run < self.needed:
            return
        self.moved_at = index
        log.warning(
            "%s: the view has shifted by about %.0f px (%.0f %% of its width) %s, at frame %d: "
            "the camera seems to move; motion masks and the calibration assume a fixed camera, so the moving "
            "background shows as objects (stabilise the video, or track a fixed camera)",
            self.name,
            moved,
            100.0 * moved / width,
            since,
            index,
        )


def watch_frames(frames: Iterable[np.ndarray], watch: CameraMotionWatch) -> Iterator[np.ndarray]:
    """``frames`` unchanged, each shown to ``watch`` on the way."""
    for index, frame in enumerate(frames):
        watch.add(index, frame)
        yield frame
