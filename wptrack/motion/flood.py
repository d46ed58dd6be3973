"""Flooded motion masks (camera shake, a sudden exposure jump): detect them and keep them from the tracker.

When a static camera shakes by a few pixels, every textured edge of the background becomes "motion": the mask's
foreground fraction jumps within one frame far above what moving objects produce (on the s3 plaza with the offline
masks: from about 4 % of the image to 11 % for a 4-pixel shake, 17 % for 8 pixels, 25 % for 16 pixels), and a
tracker that proposes objects where the mask is unexplained (Juza et al., eq. 11) adds objects on the shaken edges.
Objects entering the view change the fraction gradually, over many frames.

:class:`FloodGuard` flags a frame as flooded when its foreground fraction ``f`` is above ``fraction``, or when it
jumps above the median ``m`` of the last ``history`` unflooded frames by both ``f - m > jump`` and ``f > ratio * m``.
A run hands the tracker the last unflooded mask instead of a flooded one (the objects keep their predicted motion,
nothing is added for the flood, nothing is lost), counts the flooded frames in run.json and logs each flood once, the
first ``max_warnings`` floods of a video one by one (a camera shaken every other frame floods half of its frames: one
line each would bury the log), then one line saying that the rest are counted, not logged.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from wptrack.core.errors import ConfigError

log = logging.getLogger(__name__)

__all__ = ["FloodGuard"]


@dataclass
class FloodGuard:
    """Per-frame flood test of motion masks (see the module docstring).

    Attributes:
        fraction: Foreground fraction (0..1] above which a mask is always flooded.
        jump: Smallest rise of the fraction over the recent median that counts as a flood (0..1).
        ratio: Smallest factor over the recent median that counts as a flood (> 1).
        history: Number of recent unflooded frames whose median is the reference (>= 1).
        name: Source label for the log.
        max_warnings: Floods logged one by one; after them one line says that the rest are only counted (>= 0).
        flooded: Indices of the flooded frames seen so far.
    """

    fraction: float = 0.3
    jump: float = 0.05
    ratio: float = 2.0
    history: int = 15
    name: str = "masks"
    max_warnings: int = 5
    flooded: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not 0.0 < self.fraction <= 1.0:
            raise ConfigError(f"FloodGuard.fraction: expected a foreground fraction in (0, 1], got {self.fraction!r}")
        if not 0.0 < self.jump < 1.0:
            raise ConfigError(f"FloodGuard.jump: expected a fraction rise in (0, 1), got {self.jump!r}")
        if not self.ratio > 1.0:
            raise ConfigError(f"FloodGuard.ratio: expected a factor > 1, got {self.ratio!r}")
        if int(self.history) != self.history or self.history < 1:
            raise ConfigError(f"FloodGuard.history: expected an integer >= 1 (frames), got {self.history!r}")
        if int(self.max_warnings) != self.max_warnings or self.max_warnings < 0:
            raise ConfigError(f"FloodGuard.max_warnings: expected an integer >= 0, got {self.max_warnings!r}")
        self._floods = 0  # floods begun (runs of consecutive flooded frames), this process
        self._recent: deque[float] = deque(maxlen=int(self.history))
        self._good: np.ndarray | None = None
        self._frame = 0

    def is_flooded(self, f: float) -> bool:
        """Whether a mask with foreground fraction ``f`` is flooded, given the recent unflooded fractions."""
        if f > self.fraction:
            return True
        if not self._recent:
            return False
        m = float(np.median(self._recent))
        return f - m > self.jump and f > self.ratio * m

    def filter(self, mask: np.ndarray) -> np.ndarray:
        """The mask to track: ``mask`` itself, or for a flooded frame the last unflooded mask (zeros if none yet).

        Args:
            mask: ``(H, W)`` motion mask (nonzero = foreground).
        """
        f = float(_count_nonzero(mask)) / max(mask.size, 1)
        index = self._frame
        self._frame += 1
        if not self.is_flooded(f):
            self._recent.append(f)
            self._good = mask
            return mask
        if not self.flooded or self.flooded[-1] != index - 1:
            self._floods += 1
            ref = f"{np.median(self._recent):.1%}" if self._recent else "none yet"
            if self._floods <= self.max_warnings:
                log.warning(
                    "%s: frame %d: motion mask flooded (%.1f%% foreground, recent median %s: camera shake?); "
                    "tracking the last normal mask until it ends",
                    self.name,
                    index,
                    100.0 * f,
                    ref,
                )
            elif self._floods == self.max_warnings + 1:
                log.warning(
                    "%s: frame %d: motion mask flooded again (%d floods so far: a shaking camera?); further floods "
                    "are held the same way and counted (run.json flooded_frames), not logged",
                    self.name,
                    index,
                    self._floods,
                )
        self.flooded.append(index)
        return self._good if self._good is not None else np.zeros_like(mask)

    def state(self) -> dict[str, np.ndarray]:
        """Checkpoint arrays (for a resumed run)."""
        return {"job.flooded_frames": np.asarray(self.flooded, dtype=np.int64)}

    def load(self, state: dict[str, np.ndarray], frames_done: int) -> None:
        """Restore from :meth:`state` (the recent history restarts empty)."""
        self.flooded = [int(i) for i in state.get("job.flooded_frames", [])]
        self._frame = int(frames_done)


def _count_nonzero(mask: np.ndarray) -> int:
    """``np.count_nonzero`` of a mask; a 2D uint8 one by OpenCV (~20 times faster at 1920x1080: NumPy's count was 9 %
    of a 1080p run's main thread)."""
    if mask.ndim == 2 and mask.dtype == np.uint8 and mask.size:
        import cv2

        return int(cv2.countNonZero(mask))
    return int(np.count_nonzero(mask))
