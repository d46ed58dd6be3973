"""The clean-up of the offline model's foreground on the device (issue 27): the penumbra test, the hysteresis and the
morphological opening and closing of :func:`wptrack.motion.levels.resolve_levels` and
:func:`wptrack.motion.masks.clean_mask`, as Warp kernels (:mod:`wptrack.kernels.core.morphology`), so a mask made
on the GPU can stay there (no download of the levels, no host connected components, no upload for the tracker).

:class:`DeviceCleanup` gives the same mask as the host functions, pixel for pixel (tested on every device, the
structuring elements are OpenCV's ellipses). What it leaves to the host: ``min_area`` (a connected-components size
filter; off by default). On the CPU backend the host functions are faster (OpenCV's SIMD code against Warp launches
on one core), so the offline model keeps them there; on a GPU the kernels (a fixed chain of launches, no read-back:
the hysteresis is a union-find labelling, ``kernels.core.morphology``) replace 7-9 ms of host work a 1080p frame in
each mask thread alone on an H100 host (the penumbra test, the connected components, the opening and closing) with
one download of the mask (docs/notes.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from wptrack.core.errors import ConfigError


def ellipse_runs(diameter: int) -> np.ndarray:
    """The row runs ``(dy, dx0, dx1)`` of OpenCV's elliptical structuring element of ``diameter`` pixels (anchor at
    its centre), ``(rows, 3)`` int32."""
    import cv2

    se = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (int(diameter), int(diameter)))
    a = int(diameter) // 2
    runs = []
    for i, row in enumerate(se):
        on = np.flatnonzero(row)
        if on.size:
            if on[-1] - on[0] + 1 != on.size:  # an ellipse's rows are contiguous
                raise ValueError(f"structuring element row {i} of diameter {diameter} is not one run")
            runs.append((i - a, int(on[0]) - a, int(on[-1]) - a))
    return np.asarray(runs, dtype=np.int32).reshape(-1, 3)


class DeviceCleanup:
    """Resolve and clean the offline model's packed levels on ``device`` (see the module).

    Args:
        width, height: Image size, pixels.
        open_px, close_px: Diameters of the opening and the closing (0 or 1: off), as ``MaskConfig``.
        device: Warp device.
        penumbra_px: Penumbra candidates within this many pixels of a cast shadow's core are shadow
            (``wptrack.motion.levels.PENUMBRA_PX``).

    Raises:
        ConfigError: a diameter below 0.
    """

    def __init__(self, width: int, height: int, open_px: int, close_px: int, device: str, penumbra_px: int = 3):
        from wptrack.kernels.core import morphology as km  # noqa: F401  (the module, loaded on first launch)

        for name, value in (("open_px", open_px), ("close_px", close_px), ("penumbra_px", penumbra_px)):
            if int(value) < 0:
                raise ConfigError(f"DeviceCleanup.{name}: expected pixels >= 0, got {value!r}")
        self.shape = (int(height), int(width))
        self.device = device
        d = device
        self.levels = wp.zeros(self.shape, dtype=wp.uint8, device=d)
        self.core = wp.zeros(self.shape, dtype=wp.uint8, device=d)
        self.near = wp.zeros(self.shape, dtype=wp.uint8, device=d)
        self.mask = wp.zeros(self.shape, dtype=wp.uint8, device=d)
        self.work = wp.zeros(self.shape, dtype=wp.uint8, device=d)
        self.out = wp.zeros(self.shape, dtype=wp.uint8, device=d)
        pixels = self.shape[0] * self.shape[1]
        self.labels = wp.zeros(pixels, dtype=wp.int32, device=d)  # union-find trees of levels > 0 (row-major index)
        self.strong = wp.zeros(pixels, dtype=wp.uint8, device=d)  # 1 at the roots of components with a strong pixel
        self._no_prob = wp.zeros((1, 1), dtype=wp.float32, device=d)

        def runs(diameter: int) -> tuple[Any, int] | None:
            if int(diameter) <= 1:
                return None
            r = ellipse_runs(int(diameter))
            return wp.array(r, dtype=wp.vec3i, device=d), len(r)

        self._penumbra = runs(2 * int(penumbra_px) + 1)
        self._open = runs(open_px)
        self._close = runs(close_px)

    def _morph(self, src: Any, element: tuple[Any, int], erode: bool, dst: Any) -> None:
        from wptrack.kernels.core import morphology as km

        wp.launch(
            km.morph_kernel, dim=self.shape, inputs=[src, element[0], element[1], int(erode)], outputs=[dst],
            device=self.device,
        )  # fmt: skip

    def _hysteresis(self) -> None:
        """``mask`` = the components of ``levels > 0`` that hold a strong pixel (``kernels.core.morphology``)."""
        from wptrack.kernels.core import morphology as km

        d, shape = self.device, self.shape
        wp.launch(km.label_init_kernel, dim=shape, inputs=[self.levels], outputs=[self.labels], device=d)
        wp.launch(km.label_merge_kernel, dim=shape, inputs=[self.levels, self.labels], device=d)
        wp.launch(km.label_flatten_kernel, dim=shape, inputs=[self.levels, self.labels], device=d)
        self.strong.zero_()
        wp.launch(km.strong_roots_kernel, dim=shape, inputs=[self.levels, self.labels], outputs=[self.strong], device=d)
        wp.launch(
            km.hysteresis_kernel, dim=shape, inputs=[self.levels, self.labels, self.strong], outputs=[self.mask],
            device=d,
        )  # fmt: skip

    def __call__(self, packed: Any, prob: Any = None) -> Any:
        """The cleaned mask of one frame.

        Args:
            packed: ``(H, W)`` uint8 device array, the model's ``level + 4 shadow``.
            prob: ``(H, W)`` float32 device array set to 0 on the penumbrae (as ``resolve_levels``), or None.

        Returns:
            ``(H, W)`` uint8 device array with values 0/1, owned by this object (overwritten by the next call).
        """
        from wptrack.kernels.core import morphology as km

        d = self.device
        wp.launch(km.unpack_kernel, dim=self.shape, inputs=[packed], outputs=[self.levels, self.core], device=d)
        if self._penumbra is not None:
            self._morph(self.core, self._penumbra, False, self.near)
            has_prob = prob is not None
            wp.launch(
                km.penumbra_kernel, dim=self.shape,
                inputs=[packed, self.near], outputs=[self.levels, prob if has_prob else self._no_prob, int(has_prob)],
                device=d,
            )  # fmt: skip
        self._hysteresis()
        cur = self.mask
        if self._open is not None:  # erode then dilate
            self._morph(cur, self._open, True, self.work)
            self._morph(self.work, self._open, False, self.out)
            cur = self.out
        if self._close is not None:  # dilate then erode
            self._morph(cur, self._close, False, self.work)
            dst = self.mask if cur is self.out else self.out
            self._morph(self.work, self._close, True, dst)
            cur = dst
        return cur
