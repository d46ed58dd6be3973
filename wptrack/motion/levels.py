"""The binary mask of a frame from the offline model's packed levels, on the host: the penumbra test and the
hysteresis (:class:`wptrack.motion.background.OfflineBackground`; their device counterparts, the same masks:
:mod:`wptrack.motion.cleanup`)."""

from __future__ import annotations

import functools
import threading

import numpy as np


class LevelsWork:
    """Scratch buffers of :func:`resolve_levels` and :func:`hysteresis` for one frame size, so that a frame's
    resolution allocates nothing but the mask it returns (and the few labels it gathers).

    A 1080p frame's temporaries (levels, shadow flags, the dilated umbra, the int32 components image: ~17 MB) were
    allocated afresh every frame, and fresh pages cost a page fault each: on this project's 2-core CPU
    ``resolve_levels`` took 9.9 ms a 1080p frame, 3.8 ms with freed memory kept for reuse, 5.6 ms with these buffers
    (the clean-up's 5.0 -> 1.2 ms; docs/notes.md). ~22 MB at 1080p, held by each thread that resolves masks
    (:func:`thread_work`) for its lifetime; not thread-safe.

    Args:
        shape: ``(H, W)`` of the frames, pixels.
    """

    def __init__(self, shape: tuple[int, int]) -> None:
        self.shape = (int(shape[0]), int(shape[1]))
        self.levels = np.empty(self.shape, np.uint8)  # level of each pixel (0, 1 weak, 2 strong)
        self.shadow = np.empty(self.shape, np.uint8)  # its shadow code (0, 1 penumbra candidate, 2 umbra)
        self.near = np.empty(self.shape, np.uint8)  # umbrae dilated by the penumbra's width
        self.flag = np.empty(self.shape, bool)  # comparisons
        self.flag2 = np.empty(self.shape, bool)
        self.labels = np.empty(self.shape, np.int32)  # connected components of levels > 0
        self.morph = np.empty(self.shape, np.uint8)  # the clean-up's intermediate images (masks.clean_mask)
        self.morph2 = np.empty(self.shape, np.uint8)

    def fits(self, shape: tuple[int, ...]) -> bool:
        """Whether these buffers serve frames of ``shape``."""
        return tuple(shape) == self.shape


_local = threading.local()


def thread_work(shape: tuple[int, ...]) -> LevelsWork:
    """The calling thread's :class:`LevelsWork` for frames of ``shape`` (made on its first use, one per frame size:
    a thread serving cameras of several sizes keeps one for each; released with the thread): the mask threads of a
    run each have their own."""
    works = getattr(_local, "works", None)
    if works is None:
        works = _local.works = {}
    key = (int(shape[0]), int(shape[1]))
    work = works.get(key)
    if work is None:
        work = works[key] = LevelsWork(key)
    return work


def hysteresis(levels: np.ndarray, work: LevelsWork | None = None) -> np.ndarray:
    """Hysteresis of a mask of levels: weak pixels (1) count only when 8-connected to a strong one (2).

    Args:
        levels: ``(H, W)`` uint8 with values 0 (background), 1 (weak) and 2 (strong foreground).
        work: Scratch buffers of this frame size (:class:`LevelsWork`; ``None``: the calling thread's,
            :func:`thread_work`).

    Returns:
        ``(H, W)`` uint8 mask with values ``{0, 1}`` (a new array): the connected components of ``levels > 0`` that
        hold a strong pixel. (Computed as ``levels > 0`` less the weak pixels of the components without a strong
        pixel, which hold weak pixels only: sparse work on the few weak pixels instead of a lookup per image pixel.)
    """
    import cv2

    if work is None or not work.fits(levels.shape):
        work = thread_work(levels.shape)
    union = np.greater(levels, 0).view(np.uint8)
    count, labels = cv2.connectedComponents(union, work.labels, connectivity=8)
    good = np.zeros(count, dtype=bool)
    good[labels[np.equal(levels, 2, out=work.flag)]] = True
    weak = np.flatnonzero(np.equal(levels, 1, out=work.flag))
    weak_labels = labels.reshape(-1)[weak]
    union.reshape(-1)[weak[~good[weak_labels]]] = 0
    return union


PENUMBRA_PX = 3
"""Penumbra candidates within this many pixels of a cast shadow are shadow (:func:`resolve_levels`)."""


@functools.cache
def _disc(diameter: int) -> np.ndarray:
    import cv2

    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (diameter, diameter))


def resolve_levels(packed: np.ndarray, prob: np.ndarray | None = None, work: LevelsWork | None = None) -> np.ndarray:
    """The binary mask of a frame from the kernel's packed output ``level + 4 shadow``
    (:func:`wptrack.kernels.core.background.foreground_kernel`).

    Penumbra candidates (shadow 1) within :data:`PENUMBRA_PX` pixels of a cast shadow (shadow 2) are shadow
    (background, probability 0 in ``prob``, changed in place): the brighter rim of a soft shadow; the others keep
    their level (a shirt of the paving's colour attached to dark trousers taken for a shadow is not eaten whole);
    then :func:`hysteresis`.

    Args:
        packed: ``(H, W)`` uint8 kernel output (not changed).
        prob: ``(H, W)`` float32 probability to zero on the penumbrae, or ``None``.
        work: Scratch buffers of this frame size (:class:`LevelsWork`; ``None``: the calling thread's,
            :func:`thread_work`).

    Returns:
        ``(H, W)`` uint8 mask with values ``{0, 1}`` (a new array).
    """
    import cv2

    if work is None or not work.fits(packed.shape):
        work = thread_work(packed.shape)
    levels = np.bitwise_and(packed, 3, out=work.levels)
    shadow = np.right_shift(packed, 2, out=work.shadow)
    candidates = np.equal(shadow, 1, out=work.flag)
    if candidates.any():
        umbra = np.equal(shadow, 2, out=work.flag2).view(np.uint8)
        near = cv2.dilate(umbra, _disc(2 * PENUMBRA_PX + 1), dst=work.near)
        penumbra = np.logical_and(candidates, near, out=work.flag2)
        levels[penumbra] = 0
        if prob is not None:
            prob[penumbra] = 0.0
    if np.equal(levels, 1, out=work.flag).any():
        return hysteresis(levels, work)
    return np.equal(levels, 2).view(np.uint8)
