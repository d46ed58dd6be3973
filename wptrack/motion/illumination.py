"""Local illumination changes for the offline background model (issue 26; ``MaskConfig.illum_*``): the light
field and the patch tests of :class:`wptrack.motion.background.OfflineBackground`, on the kernels of
:mod:`wptrack.kernels.core.illumination`.

A cloud's shadow drifting over the ground, a light switched on in part of the view, change the light of a region
smoothly and coherently: the texture, the gradient structure and the hue stay, scaled. Per frame
(:meth:`LightField.measure`, kernels :func:`~wptrack.kernels.core.illumination.luma_kernel` to
:func:`~wptrack.kernels.core.illumination.tile_smooth_kernel`):

- every pixel's ``(2 illum_patch + 1)^2`` patch of luminance (after the global gain) is compared with the
  background's: normalised cross-correlation, gradient correlation, both patches' texture (standard deviation in
  luminance noise scales) and the pixel's residual from the patch's linear fit;
- **local field** (``illum_tiles``): the image is cut into tiles (``illum_tiles`` along the shorter side, at least
  4 px); a tile's gain per channel is the median ratio frame / background of its pixels whose patch is textured
  and correlates (NCC >= ``illum_verify``) and that are no cast shadow by the learnt band (the votes: an object
  that entered does not keep the background's texture, a flat patch cannot tell, a cast shadow is the shadow
  test's); the tiles' gains are smoothed by a weighted median over ``illum_radius`` tiles (weights: the fraction
  that voted; a tile with a quarter of votes keeps its own gains within ``illum_keep`` of that median), and the
  frame is divided by the field interpolated bilinearly between the tile centres before every test. Objects on
  flat ground take the field of the textured ground around them, never their own;
- **veto** (``illum_veto``, ``illum_grad``): a pixel still foreground whose textured patch correlates with the
  background's (NCC >= ``illum_veto`` or gradient correlation >= ``illum_grad``), that follows its patch's linear
  fit within ``illum_resid`` noise scales (a thin leg on a textured patch does not) and whose colour is the
  background's scaled (brightness ratio in ``[illum_lo, illum_hi]``, chromaticity distortion <=
  ``illum_chroma``) is background (shadow code 3).

With ``illum_windows`` each window's samples are divided by their own field against the window's first median
before its statistics are taken (median, MAD, learnt shadow ratio, neighbourhood scale): a cloud that shaded a
pixel in a third of the samples no longer inflates its MAD (hiding the people there), nor do the unlit samples
of a light switched on mid-window teach the shadow band a ratio of 0.8.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wptrack.core.device import download

ILLUM_MIN_WEIGHT = 2.0
"""Smallest total weight (sum of the tiles' voting fractions) of a tile neighbourhood whose weighted median sets the
local illumination field; below it the field is 1 there
(:func:`wptrack.kernels.core.illumination.tile_smooth_kernel`)."""


ILLUM_WIDEN = 2
"""Times a tile neighbourhood without enough votes is widened (radius ``r`` -> ``2 r + 1``; with the default radius
2: 5, then 11 tiles) before the field is left at 1 there: a cloud over a wide flat road takes the field of the
textured ground (kerbs, markings, paving) around it."""


def tile_size(width: int, height: int, tiles: int) -> int:
    """Tile size of the local illumination field, pixels: ``ceil(min(width, height) / tiles)``, at least 4 (0 when
    ``tiles`` is 0: no field)."""
    if not tiles:
        return 0
    return max(4, -(-min(width, height) // int(tiles)))


PATCH_ROWS = 8
"""Samples whose shadow-vote texture statistics :meth:`LightField.sample_patches` computes before one download (at
1920x1080: 8 x 160k subsampled pixels x 24 bytes, 31 MB of device memory; 4 downloads for 25 samples instead of 25)."""


class LightField:
    """The local light field and patch statistics of one source's frames (device buffers allocated once).

    Args:
        config: A ``MaskConfig`` (the ``illum_*`` fields).
        width, height: The frames' size, pixels.
        params: The model's :class:`wptrack.kernels.core.background.ForegroundParams`: its illumination fields are
            set here; the model sets the per-frame bounds (spread cap, shadow bounds) the kernels read from it.
        device: Warp device alias.

    Attributes:
        active: Whether any patch work is done (a field or a veto); when False, :meth:`measure` is not needed.
        textured_votes: Whether the windows' shadow votes are texture-tested (``shadow_texture``, with a learnt
            band): :meth:`sample_patches` is used.
        tiles: Whether there is a field (``illum_tiles > 0``).
        local: ``(tiles_y tiles_x,)`` vec3 device array: the field's log gains per tile (B, G, R).
        patch: ``(H W,)`` patch statistics (:data:`wptrack.kernels.core.background.patch_vec`) of the last frame, at
            the pixels that read them only (the tiles' vote subsample, written by :meth:`measure`; the veto's
            candidates, written by the foreground kernel); other pixels hold older values.
        rows, luma: ``(H W,)`` the frame's patch row sums and luminance (the foreground kernel's veto computes its
            candidates' patch statistics from them).
    """

    def __init__(self, config: Any, width: int, height: int, params: Any, device: str) -> None:
        import warp as wp

        from wptrack.kernels.core import background as kbg
        from wptrack.kernels.core import illumination as kil

        c, p = config, params
        self.config, self.params, self.device = config, params, device
        self.width, self.height, self.pixels = int(width), int(height), int(width) * int(height)
        p.tile = tile_size(width, height, c.illum_tiles)
        p.width = width
        p.tiles_x = -(-width // p.tile) if p.tile else 1
        p.tiles_y = -(-height // p.tile) if p.tile else 1
        p.verify_ncc = float(c.illum_verify)
        p.veto_ncc = float(c.illum_veto)
        p.veto_grad = float(c.illum_grad)
        p.veto_texture = float(c.illum_texture)
        p.veto_resid = float(c.illum_resid)
        p.gain_gap = float(c.illum_gap)
        p.illum_chroma = float(c.illum_chroma)
        p.illum_lo = float(c.illum_lo)
        p.illum_hi = float(c.illum_hi)
        self.tiles = bool(p.tile)
        self.active = bool(p.tile or p.veto_ncc > 0 or p.veto_grad > 0)
        self.textured_votes = bool(
            getattr(c, "shadow_texture", 0.0) > 0 and getattr(c, "shadow_band", 0.0) > 0 and c.detect_shadows
        )
        n = self.pixels if self.active or self.textured_votes else 1
        n_tiles = p.tiles_x * p.tiles_y
        # per-pixel luminance and patch statistics, per-tile gains and the smoothed field
        self._luma = wp.zeros(n, dtype=wp.vec3, device=device)
        # the luminance gradients: read by the gradient veto only (off by default), a stand-in element otherwise
        self._grads = wp.zeros(n if p.veto_grad > 0 else 1, dtype=wp.vec4, device=device)
        self._rows9 = wp.zeros(n, dtype=kil.rows_vec, device=device)
        self.rows, self.luma = self._rows9, self._luma
        self.patch = wp.zeros(n, dtype=kbg.patch_vec, device=device)
        self._tiles = wp.zeros(n_tiles, dtype=wp.vec4, device=device)
        self.local = wp.zeros(n_tiles, dtype=wp.vec3, device=device)

    def measure(
        self, frame: Any, gain: Any, b0: Any, m0: Any, b1: Any, m1: Any, w: float, shadows: bool = True
    ) -> None:
        """Launch the patch statistics of ``frame`` (a flat device or CPU uint8 array, its global ``gain`` a
        ``wp.vec3``) against the background ``(b0, m0)``/``(b1, m1)`` (weight ``w`` of the second) into
        :attr:`rows` and :attr:`luma` and, with tiles, its local field into :attr:`local` (and the patch statistics
        of the tiles' votes into :attr:`patch`); with ``shadows``, pixels that pass the cast-shadow test (the
        params' bounds) do not vote for the field."""
        import warp as wp

        from wptrack.kernels.core import illumination as kil

        c, p, dev = self.config, self.params, self.device
        height = self.height
        self._patch_rows(frame, gain, b0, m0, b1, m1, w)
        r = int(c.illum_patch)
        if p.tile:
            n = p.tiles_x * p.tiles_y
            # the patch statistics where the tiles' votes read them; the veto's candidates get theirs in the
            # foreground kernel (from the same rows)
            wp.launch(kil.patch_samples_kernel, dim=n * int(kil.TILE_SAMPLES) ** 2,
                      inputs=[self._rows9, self._luma, p, height, r], outputs=[self.patch], device=dev)  # fmt: skip
            wp.launch(kil.tile_gain_kernel, dim=n, inputs=[frame, gain, b0, b1, w, self.patch, p, height,
                      int(shadows)], outputs=[self._tiles], device=dev)  # fmt: skip
            wp.launch(kil.tile_smooth_kernel, dim=n,
                      inputs=[self._tiles, p.tiles_x, p.tiles_y, int(c.illum_radius), ILLUM_WIDEN, ILLUM_MIN_WEIGHT,
                              float(c.illum_keep), float(c.illum_dead)],
                      outputs=[self.local], device=dev)  # fmt: skip

    def _patch_rows(self, frame: Any, gain: Any, b0: Any, m0: Any, b1: Any, m1: Any, w: float) -> None:
        """Launch the luminance, gradients and patch row sums of ``frame`` against the background into
        :attr:`luma` and :attr:`rows`."""
        import warp as wp

        from wptrack.kernels.core import illumination as kil

        p, dev, width, height = self.params, self.device, self.width, self.height
        wp.launch(kil.luma_kernel, dim=self.pixels, inputs=[frame, gain, b0, m0, b1, m1, w, p], outputs=[self._luma],
                  device=dev)  # fmt: skip
        gradients = int(p.veto_grad > 0)  # only the gradient veto reads the gradient correlation (off by default)
        if gradients:
            wp.launch(kil.luma_grad_kernel, dim=self.pixels, inputs=[self._luma, width, height],
                      outputs=[self._grads], device=dev)  # fmt: skip
        wp.launch(kil.patch_rows_kernel, dim=self.pixels,
                  inputs=[self._luma, self._grads, width, height, int(self.config.illum_patch), gradients],
                  outputs=[self._rows9], device=dev)  # fmt: skip

    def sample_patches(
        self, stack: Any, gains: np.ndarray, median: Any, mad: Any, pixels: Any, spread_cap: float
    ) -> np.ndarray:
        """The texture test of a window's shadow votes: for each sample ``k`` of ``stack`` (``(K, 3 H W)`` uint8 on
        the device, divided by ``gains[k]``), whether its patch at each pixel of ``pixels`` (``(P,)`` int32 device
        array of flat pixel indices) keeps the background's texture as a gain: the background patch is textured
        (``tex_b >= illum_texture``, ``tex_f >= illum_texture / 2``), the patches correlate (NCC ``>=
        shadow_texture``), the fit is a gain (``gap <= illum_gap``) and the pixel follows it (``resid <=
        illum_resid``); the statistics of :func:`~wptrack.kernels.core.background.patch_at` against ``(median,
        mad)`` with the window's own noise-scale cap ``spread_cap`` (8-bit units, 0: none).

        Returns:
            ``(K, P)`` bool.
        """
        import warp as wp

        from wptrack.kernels.core import illumination as kil

        c, p = self.config, self.params
        n, samples = pixels.shape[0], stack.shape[0]
        rows = min(samples, PATCH_ROWS)
        out = wp.zeros((rows, n), dtype=kil.patch_vec, device=self.device)  # one row per sample of a chunk
        keep = np.zeros((samples, n), dtype=bool)
        frame_cap = p.spread_cap
        p.spread_cap = float(spread_cap)
        try:
            for k0 in range(0, samples, rows):  # a chunk's samples launched back to back, downloaded at once
                for r, k in enumerate(range(k0, min(k0 + rows, samples))):
                    g = wp.vec3(*(float(v) for v in gains[k]))
                    self._patch_rows(stack[k], g, median, mad, median, mad, 0.0)
                    wp.launch(kil.patch_pixels_kernel, dim=n,
                              inputs=[self._rows9, self._luma, pixels, self.width, self.height, int(c.illum_patch)],
                              outputs=[out[r]], device=self.device)  # fmt: skip
                st = download(out).reshape(rows, n, 6)[: min(rows, samples - k0)]
                keep[k0 : k0 + len(st)] = (
                    (st[..., 2] >= c.illum_texture)
                    & (st[..., 3] >= 0.5 * c.illum_texture)
                    & (st[..., 0] >= c.shadow_texture)
                    & (st[..., 5] <= c.illum_gap)
                    & (st[..., 4] <= c.illum_resid)
                )
        finally:
            p.spread_cap = frame_cap
        return keep

    def compensate(self, stack: Any, gains: np.ndarray, median: Any, mad: Any, spread_cap: float) -> None:
        """Divide each sample of a window's ``stack`` (``(K, 3 H W)`` uint8 on the device, in place) by its global
        gain (``gains`` ``(K, 3)``) and its own local field against the window's first ``(median, mad)``, with the
        window's own noise-scale cap ``spread_cap`` (8-bit units, 0: none); the caller rebuilds the statistics with
        unit gains."""
        import warp as wp

        from wptrack.kernels.core import illumination as kil

        p = self.params
        frame_cap = p.spread_cap  # the per-frame cap; the window's own while it is built (no state from frames)
        p.spread_cap = float(spread_cap)
        try:
            for k in range(stack.shape[0]):
                g = wp.vec3(*(float(v) for v in gains[k]))
                self.measure(stack[k], g, median, mad, median, mad, 0.0, shadows=False)
                wp.launch(kil.compensate_kernel, dim=self.pixels, inputs=[stack, k, g, self.local, p],
                          device=self.device)  # fmt: skip
        finally:
            p.spread_cap = frame_cap
