"""The binary mask of a frame from the offline model's packed levels, on the host: the penumbra test and the
hysteresis (:class:`wptrack.motion.background.OfflineBackground`; their device counterparts, the same masks:
:mod:`wptrack.motion.cleanup`)."""

from __future__ import annotations

import numpy as np


def hysteresis(levels: np.ndarray) -> np.ndarray:
    """Hysteresis of a mask of levels: weak pixels (1) count only when 8-connected to a strong one (2).

    Args:
        levels: ``(H, W)`` uint8 with values 0 (background), 1 (weak) and 2 (strong foreground).

    Returns:
        ``(H, W)`` uint8 mask with values ``{0, 1}``: the connected components of ``levels > 0`` that hold a
        strong pixel. (Computed as ``levels > 0`` less the weak pixels of the components without a strong pixel,
        which hold weak pixels only: sparse work on the few weak pixels instead of a lookup per image pixel.)
    """
    import cv2

    union = (levels > 0).view(np.uint8)
    count, labels = cv2.connectedComponents(union, connectivity=8)
    good = np.zeros(count, dtype=bool)
    good[labels[levels == 2]] = True
    weak = np.flatnonzero(levels == 1)
    weak_labels = labels.reshape(-1)[weak]
    union.reshape(-1)[weak[~good[weak_labels]]] = 0
    return union


PENUMBRA_PX = 3
"""Penumbra candidates within this many pixels of a cast shadow are shadow (:func:`resolve_levels`)."""


def _disc(diameter: int) -> np.ndarray:
    import cv2

    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (diameter, diameter))


def resolve_levels(packed: np.ndarray, prob: np.ndarray | None = None) -> np.ndarray:
    """The binary mask of a frame from the kernel's packed output ``level + 4 shadow``
    (:func:`wptrack.kernels.core.background.foreground_kernel`).

    Penumbra candidates (shadow 1) within :data:`PENUMBRA_PX` pixels of a cast shadow (shadow 2) are shadow
    (background, probability 0 in ``prob``, changed in place): the brighter rim of a soft shadow; the others keep
    their level (a shirt of the paving's colour attached to dark trousers taken for a shadow is not eaten whole);
    then :func:`hysteresis`.

    Args:
        packed: ``(H, W)`` uint8 kernel output.
        prob: ``(H, W)`` float32 probability to zero on the penumbrae, or ``None``.

    Returns:
        ``(H, W)`` uint8 mask with values ``{0, 1}``.
    """
    import cv2

    levels = packed & 3
    shadow = packed >> 2
    if (shadow == 1).any():
        near = cv2.dilate((shadow == 2).view(np.uint8), _disc(2 * PENUMBRA_PX + 1))
        penumbra = (near > 0) & (shadow == 1)
        levels[penumbra] = 0
        if prob is not None:
            prob[penumbra] = 0.0
    if (levels == 1).any():
        return hysteresis(levels)
    return (levels == 2).view(np.uint8)
