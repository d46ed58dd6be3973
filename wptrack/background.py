"""Offline background model of a whole recording (``MaskConfig.method == "offline"``), on Warp kernels.

Offline processing may look at the whole recording before making any mask, so the background of frame ``t`` is
estimated from frames before *and after* it: an object standing still at the start is in the background only for
as long as it stands still, and leaves no ghost once it moves (an online model such as MOG2 has learnt it into
the background by then, and marks the uncovered road as foreground for a while). The condition: a pixel's
background is what it shows in most of its window's samples, so an object is left out of it when it stands on
that pixel for less than about half of the window (choose ``window`` longer than twice the longest stand that
must stay foreground).

Design (kernels and formulas: :mod:`wptrack.kernels.background`):

* **Windows.** The recording of ``T`` frames is covered by windows of ``L = window`` frames whose starts are spaced
  evenly, about ``L / 2`` apart (half overlap), the first starting at frame 0 and the last ending at frame ``T``.
  Window ``i`` samples ``K = min(samples, L)`` frames evenly inside itself and its background is the per-pixel
  temporal median of those ``K`` frames, with the per-channel MAD as its noise estimate. Its centre is the mean
  of its sample indices. A recording shorter than ``L`` gets one window over all of it (a log warning says so);
  with fewer than 3 frames the median cannot reject anything that stands still (another warning).
* **Drift.** Frame ``t`` uses the background and MAD interpolated linearly between the two windows whose centres
  bracket it (before the first centre / after the last: that window alone), so slow illumination changes are
  followed with a lag of at most a window, without steps at window boundaries.
* **Passes.** Windows are built lazily while the frames are streamed (the mask pass): a second reader fetches the
  ``K`` sampled frames of the next window when frame ``t`` first needs it, so only two windows' backgrounds are
  held. It seeks only across gaps of :data:`SEEK_GAP` frames or more (an OpenCV seek decodes about 16 frames
  before its target) and grabs the frames in between otherwise, keeping on its way the samples of the following
  window (which overlaps this one by half), so it reads forward and decodes each frame about once: with the
  defaults (a sample every 12 frames) a video costs at most one extra decoding pass (0.6 of the decoding time of
  a 600-frame 640x480 FFV1 video on the CI machine, where seeking to every sample cost 2.9); an image sequence,
  or samples more than :data:`SEEK_GAP` apart, about ``K / (L / 2)`` extra decoded frames per frame. The exact
  frame a seek lands on does not matter: the median is robust to a sample being a frame off. That reading runs
  ahead in one worker thread: when the mask pass builds window ``i``, the worker starts reading (and preparing
  with NumPy) window ``i + 1``'s samples, so the extra decoding overlaps the per-frame work on another core
  (:class:`OfflineBackground`; the same reads in the same order, so the same masks).
* **Gains.** Each window's samples and each frame get a global gain per channel (illumination changes), the median
  of their ratios to the background over a pixel subsample: every 13th pixel for the windows, thinned to at most
  :data:`GAIN_PIXELS` for a frame (the same pixels up to 425,984 pixels per frame, e.g. 640x480; at 1920x1080
  every 65th pixel).
* **Spread cap.** Each window also records the image-wide median of its per-pixel noise scales (on a pixel
  subsample); with ``MaskConfig.spread_cap`` the per-pixel scale is capped at that many times it, so an object
  standing in a large minority of a window's samples does not hide itself by inflating its pixels' MAD.
* **Local illumination** (issue 26; ``MaskConfig.illum_*``). A cloud's shadow drifting over the ground, a light
  switched on in part of the view, change the light of a region smoothly and coherently: the texture, the gradient
  structure and the hue stay, scaled. Per frame (:meth:`OfflineBackground._illumination`, kernels
  :func:`~wptrack.kernels.background.luma_kernel` to :func:`~wptrack.kernels.background.tile_smooth_kernel`):

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
* **Densest samples** (``MaskConfig.mode_band``; short recordings with people in most frames): the background of a
  window is, per pixel, the median of its densest cluster of samples (those within ``mode_band`` noise scales of
  the sample with the most such neighbours) instead of the median of all: moving people differ from sample to
  sample, the background does not, so a pixel covered in most samples keeps its background
  (:func:`~wptrack.kernels.background.mode_kernel`).
* **Hysteresis.** With ``MaskConfig.fg_low``, the kernel marks weak foreground (``fg_low < z <= fg_threshold``)
  beside the strong; :func:`hysteresis` keeps the weak pixels 8-connected to a strong one (OpenCV connected
  components on the host, where the mask goes anyway).
* **Host work per frame** (the kernels are cheap; what costs is on the host): the frame's gain (bounded by
  :data:`GAIN_PIXELS`), the hysteresis (one labelling of the foreground, then work on the weak pixels only) and
  one copy of the probability for the caller. On CUDA the frame goes up and the mask and probability come down
  through pinned buffers allocated once (one wait per frame, for the results).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import wait as wait_futures
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import FrameError
from .frames import ArraySource, FrameSource, ImageSequenceSource, VideoSource, _read_image, _to_bgr

log = logging.getLogger(__name__)

#: Sample gap (frames) from which the sampler seeks instead of grabbing the frames in between. OpenCV's FFmpeg
#: reader seeks 16 frames before the target and decodes forward from there (more after a sparse keyframe), and
#: ``grab`` decodes as much as ``read`` (it only skips the colour conversion): a seek cost 17-27 decodes of a
#: 1920x1080 FFV1 video on the CI machine, so grabbing forward is cheaper up to about 20 frames.
SEEK_GAP = 24


@dataclass(frozen=True)
class Window:
    """One background window: its sampled frame indices and their mean (the window's centre, frames)."""

    samples: tuple[int, ...]

    @property
    def centre(self) -> float:
        return float(np.mean(self.samples))


def plan_windows(frames: int, window: int, samples: int, name: str = "recording") -> list[Window]:
    """Background windows covering ``frames`` frames (see the module docstring).

    Args:
        frames: Number of frames ``T`` (>= 1).
        window: Window length ``L`` in frames (>= 1).
        samples: Sampled frames per window (>= 1).
        name: Source label for the warnings.

    Returns:
        The windows in time order (centres strictly increasing).
    """
    if frames < 1:
        raise FrameError(f"{name}: no frames to build a background from")
    if frames < window:
        log.warning(
            "%s: %d frames, shorter than the background window of %d frames; using one window over all of them",
            name,
            frames,
            window,
        )
        window = frames
    if frames < 3:
        log.warning("%s: background from %d frame(s); whatever stands in them is background", name, frames)
    k = min(samples, window)
    count = 1 if frames == window else math.ceil((frames - window) / max(window // 2, 1)) + 1
    starts = np.round(np.linspace(0, frames - window, count)).astype(int)
    out = []
    for s in starts:
        idx = s + np.floor((np.arange(k) + 0.5) * window / k).astype(int)
        out.append(Window(tuple(int(i) for i in np.unique(np.clip(idx, s, s + window - 1)))))
    return out


def bracket(centres: list[float], t: int) -> tuple[int, int, float]:
    """``(i, j, w)``: frame ``t`` uses ``(1 - w) * window_i + w * window_j`` (linear in the centres, clamped)."""
    if t <= centres[0] or len(centres) == 1:
        return 0, 0, 0.0
    if t >= centres[-1]:
        n = len(centres) - 1
        return n, n, 0.0
    j = int(np.searchsorted(centres, t, side="right"))
    i = j - 1
    return i, j, float((t - centres[i]) / (centres[j] - centres[i]))


class _Stopped(Exception):
    """A sampler's read stopped by :meth:`OfflineBackground.close` (its result is dropped)."""


class _Sampler:
    """Reads given frame indices of a source (increasing within a call), for the window backgrounds.

    A video is read forward: the frames between samples closer than :data:`SEEK_GAP` are grabbed, not sought, and
    those of them that the next window samples (``ahead``) are kept, so that window, which overlaps this one by
    half, does not seek back and decode them again (each frame is decoded about once by the sampler instead of
    twice).

    One thread at a time uses it (:class:`OfflineBackground`'s caller or its prefetch worker); with ``notes`` a
    list, its warnings are kept there for the caller to log, and ``stop`` set by another thread ends a video read
    at its next frame (:class:`_Stopped`).
    """

    def __init__(self, source: FrameSource) -> None:
        self.source = source
        self.cap: Any = None
        self.pos = 0  # index of the frame the next read() returns
        self.kept: dict[int, np.ndarray] = {}  # frames passed by an earlier read that a later one samples
        self.notes: list[tuple[Any, ...]] | None = None  # a list: warnings kept here (for another thread to log)
        self.stop = threading.Event()  # set (by another thread): a video read stops at its next frame

    def _warn(self, message: str, *args: Any) -> None:
        if self.notes is None:
            log.warning(message, *args)
        else:
            self.notes.append((message, *args))

    def read(self, indices: tuple[int, ...], ahead: tuple[int, ...] = ()) -> list[np.ndarray]:
        """The frames at ``indices`` (fewer when some cannot be read); a video keeps those of ``ahead`` (the next
        read's indices) that it passes on the way."""
        s = self.source
        if isinstance(s, ArraySource):
            return [_to_bgr(np.ascontiguousarray(s.frames[i])) for i in indices]
        if isinstance(s, ImageSequenceSource):
            out = [_read_image(s.files[i]) for i in indices]
            return [f for f in out if f is not None and f.shape[:2] == (s.height, s.width)]
        if isinstance(s, VideoSource):
            return self._read_video(indices, set(ahead))
        return [f for i, f in enumerate(s) if i in set(indices)]  # any other source: one decoding pass

    def _read_video(self, indices: tuple[int, ...], ahead: set[int]) -> list[np.ndarray]:
        import cv2

        if self.cap is None:
            self.cap = self.source._open()  # type: ignore[attr-defined]
            self.pos = 0
        kept, self.kept = self.kept, {}
        out = []
        for i in indices:
            if self.stop.is_set():
                raise _Stopped(f"{self.source.name}: background read stopped")
            frame = kept.get(i)
            if frame is None:
                if i < self.pos or i - self.pos >= SEEK_GAP:
                    self.cap.set(cv2.CAP_PROP_POS_FRAMES, float(i))
                    self.pos = i
                ok = True
                while ok and self.pos < i:
                    if self.stop.is_set():
                        raise _Stopped(f"{self.source.name}: background read stopped")
                    ok = self.cap.grab()
                    if ok and self.pos in ahead:
                        ok, passed = self.cap.retrieve()
                        if ok and passed is not None:
                            self.kept[self.pos] = passed
                    self.pos += 1
                ok, frame = self.cap.read() if ok else (False, None)
                if not ok or frame is None:
                    self._warn("%s: cannot read frame %d for the background; skipped", self.source.name, i)
                    break  # the video ends earlier than it reported
                self.pos += 1
            if i in ahead:
                self.kept[i] = frame
            if frame.ndim == 3 and frame.shape[2] == 3 and frame.shape[:2] == (self.source.height, self.source.width):
                out.append(frame)
        return out

    def close(self) -> None:
        self.kept = {}
        if self.cap is not None:
            self.cap.release()
            self.cap = None


GAIN_PIXELS = 32768
"""Most pixels of the subsample a frame's global gain is estimated on (:class:`OfflineBackground`: every 13th
pixel, thinned further above this), so its cost per frame is bounded at any frame size (at 1920x1080: 32k pixels
instead of 160k, 1.9 instead of about 8 ms on the CI machine). Frames up to 425,984 pixels are unchanged. Measured
effect at 1920x1080 (s3-mixed, light-change + sun + noise, frames 55-114 upscaled, window 30, 15 samples): 65 % of
the masks identical, 13.5 pixels per frame differ on average (of about 60k foreground), mean IoU with the uncapped
masks 0.9995 (min 0.982), mean IoU with the perfect masks 0.71858 -> 0.71856. The differences come where the
median of the ratios sits between two quantisation steps of 8-bit values (a gain of 0.988 or 1.0): the uncapped
estimate jumps between them from one frame to the next as well."""

MIN_GAIN_LEVEL = 16.0
"""Background values below this (8-bit) are left out of gain estimates (dark pixels carry no ratio)."""


def frame_gain(values: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Global gain per channel of a frame relative to a background: the median over pixels of their ratio.

    Args:
        values: ``(P, 3)`` a pixel subsample of the frame (8-bit). background: ``(P, 3)`` the same pixels of the
            background (float, 8-bit units).

    Returns:
        ``(3,)`` gains (1 where no pixel is bright enough). The median ignores a minority of changed pixels
        (the people); a light dimming by 20 % gives 0.8.
    """
    return channel_gains(np.ascontiguousarray(values.T)[None], np.ascontiguousarray(background.T))[0]


def channel_gains(values: np.ndarray, background: np.ndarray) -> np.ndarray:
    """:func:`frame_gain` of ``K`` frames at once, on channel-major arrays (the same numbers).

    Args:
        values: ``(K, 3, P)`` uint8 channel values of K frames at P subsampled pixels.
        background: ``(3, P)`` float64 the background at those pixels (8-bit units).

    Returns:
        ``(K, 3)`` float64 gains, each the median over the pixels whose background is at least
        :data:`MIN_GAIN_LEVEL` of their ratio to the background (1 where fewer than 16 such pixels), clipped to
        ``[0.05, 20]``.
    """
    out = np.ones((values.shape[0], 3))
    for c in range(3):
        b = background[c]
        ok = np.flatnonzero(b >= MIN_GAIN_LEVEL)
        if ok.size >= 16:
            out[:, c] = median_last(values[:, c, ok] / b[ok])
    return np.clip(out, 0.05, 20.0)


def sample_gains(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gains of a window's samples relative to their median, and that (compensated) median, on a pixel subsample.

    Args:
        samples: ``(K, P, 3)`` uint8 channel values of K samples at P subsampled pixels.

    Returns:
        ``(gains (K, 3) float32, background (P, 3) float64)``: each sample's gain against the per-pixel median of the
        samples (normalised so that their median gain is 1), and the median of the compensated samples.
    """
    gains, background = sample_gains_channels(np.ascontiguousarray(samples.transpose(0, 2, 1)))
    return gains, np.ascontiguousarray(background.T)


def median_last(x: np.ndarray) -> np.ndarray:
    """``np.median(x, axis=-1)`` of an array without NaNs, the same numbers and dtype (the mean of the middle value,
    or of the two middle values, as ``np.median`` takes it), faster: rows sorted (float rows of at most 64 values:
    NumPy's vectorised sort beats selection there) or partitioned at the middle only (``np.median`` also
    partitions at the last value, for its NaN check, and costs several times more)."""
    n = x.shape[-1]
    h = n // 2
    lo = h if n % 2 else h - 1
    if np.issubdtype(x.dtype, np.floating) and n <= 64:
        part = np.sort(x, axis=-1)
    else:
        part = np.partition(x, [lo, h] if lo < h else h, axis=-1)
    return np.mean(part[..., lo : h + 1], axis=-1)


def sample_gains_channels(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sample_gains` on channel-major samples ``(K, 3, P)`` uint8; the background comes back ``(3, P)``.

    The medians over the samples are taken along a contiguous last axis (a ``(3, P, K)`` copy): the same values as
    ``np.median`` along a strided first axis, several times faster.
    """
    along = np.moveaxis(samples, 0, -1).copy()  # (3, P, K)
    ref = median_last(along)  # float64: the same as the median of the samples taken as float64
    gains = channel_gains(samples, ref)
    gains /= np.median(gains, axis=0, keepdims=True)
    return gains.astype(np.float32), median_last(along / gains.T[:, None, :])


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
    (:func:`wptrack.kernels.background.foreground_kernel`).

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


def spread_scale(mad: np.ndarray, step: int = 7) -> float:
    """Image-wide median of the per-pixel noise scales ``1.4826 sqrt(sum_c MAD_c^2 / 3)`` (8-bit units), over every
    ``step``-th pixel of a flat ``(3 P,)`` MAD array."""
    m = mad.reshape(-1, 3)[::step].astype(np.float64)
    return float(np.median(1.4826 * np.sqrt((m * m).mean(axis=1))))


def neighbourhood_scale(
    samples: np.ndarray,
    gains: np.ndarray,
    median: np.ndarray,
    mad: np.ndarray,
    radius: int,
    noise_floor: float,
    max_samples: int = 5,
) -> float:
    """How much averaging over a ``(2 radius + 1)^2`` neighbourhood reduces the noise of a recording, relative to
    independent pixels: ``c = sigma_1 / (sqrt(N) sigma_N)`` with ``sigma_1`` the robust spread (MAD) of the
    normalised differences ``(I - B) / s`` of a window's samples and ``sigma_N`` that of their neighbourhood means
    (N pixels). Independent noise (a rendered scene's sensor noise) gives 1; spatially correlated noise
    (compression blocks, demosaicing, denoising) less, down to ``1 / sqrt(N)`` when neighbours move together.
    :func:`wptrack.kernels.background.neighbourhood_kernel` multiplies its ``z_n`` by ``c``, so a coherent change
    must beat the recording's real neighbourhood noise.

    Args:
        samples: ``(K, H, W, 3)`` uint8 a window's samples (an array or a sequence of K ``(H, W, 3)`` frames).
            gains: ``(K, 3)`` their global gains.
        median: ``(H, W, 3)`` uint8 the window's background. mad: ``(H, W, 3)`` uint8 its MAD.
        radius: Neighbourhood radius, pixels.
        noise_floor: Smallest noise scale, 8-bit units.
        max_samples: Samples used (evenly chosen), to bound the cost.

    Returns:
        ``c`` in ``[1 / sqrt(N), 1]``.
    """
    import cv2

    n = (2 * radius + 1) ** 2
    s = np.maximum(noise_floor, 1.4826 * np.sqrt((mad.astype(np.float32) ** 2).mean(axis=2)))[..., None]
    b = median.astype(np.float32)
    pick = np.unique(np.linspace(0, len(samples) - 1, min(max_samples, len(samples))).round().astype(int))
    single, mean = [], []
    for k in pick:
        d = samples[k].astype(np.float32)
        d /= gains[k].astype(np.float32)
        d -= b
        d /= s
        single.append(np.abs(d[radius:-radius:3, radius:-radius:3]).ravel())
        mean.append(np.abs(cv2.blur(d, (2 * radius + 1, 2 * radius + 1))[radius:-radius:3, radius:-radius:3]).ravel())
    s1 = float(median_last(np.concatenate(single)))
    sn = float(median_last(np.concatenate(mean)))
    if sn <= 0:
        return 1.0
    return float(np.clip(s1 / (np.sqrt(n) * sn), 1.0 / np.sqrt(n), 1.0))


SHADOW_SEARCH = (0.3, 0.95)
"""Brightness ratios searched for the learnt shadow ratio (:func:`shadow_ratio`). Below 0.3 lie mostly dark
objects (a dark car's sides on a grey road: 0.2), not outdoor cast shadows (the sky light alone is rarely under a
third of sky + sun on a horizontal surface)."""


def shadow_ratio(
    samples: np.ndarray,
    gains: np.ndarray,
    background: np.ndarray,
    mad: np.ndarray,
    threshold: float,
    noise_floor: float,
    chroma_max: float,
    bin_width: float = 0.02,
    min_count: int = 200,
) -> float | None:
    """The brightness ratio of the cast shadows of a recording, learnt from a window's samples.

    Every sampled pixel that is foreground (``z > threshold``) and passes the chromaticity part of the shadow test
    (``cd <= chroma_max``) votes for its brightness ratio ``a`` (see :mod:`wptrack.kernels.background`); the cast
    shadows of one sun all darken the ground by about the same ratio and make the highest peak of the histogram
    of ``a`` inside :data:`SHADOW_SEARCH` (dark objects spread over many ratios, or lie below it). The peak must
    be a local maximum of the smoothed histogram, not the search range's end (the tail of a peak outside it).

    Args:
        samples: ``(K, P, 3)`` uint8 sampled values of P subsampled pixels. gains: ``(K, 3)`` the samples' global
            gains. background: ``(P, 3)`` the window's background at those pixels. mad: ``(P, 3)`` its MAD.
        threshold, noise_floor, chroma_max: As in :class:`wptrack.kernels.background.ForegroundParams`.
        bin_width: Histogram bin width (ratio).
        min_count: Fewer votes than this inside the search range: ``None`` (nothing learnt).

    Returns:
        The ratio at the peak, or ``None``.
    """
    b = background.astype(np.float64)
    s = np.maximum(noise_floor, 1.4826 * np.sqrt((mad.astype(np.float64) ** 2).mean(axis=1)))
    bb = (b * b).sum(axis=1)
    votes = []
    for xk, g in zip(samples, gains, strict=True):
        x = xk.astype(np.float64) / g[None, :]
        z = np.sqrt(((x - b) ** 2).mean(axis=1)) / s
        fg = np.flatnonzero((z > threshold) & (bb >= 1.0))  # the ratios of the foreground pixels only
        x, bf, bbf = x[fg], b[fg], bb[fg]
        ib = (x * bf).sum(axis=1)
        a = ib / np.maximum(bbf, 1.0)
        cd = np.sqrt(np.maximum((x * x).sum(axis=1) - a * ib, 0.0) / np.maximum(bbf, 1.0))
        votes.append(a[cd <= chroma_max])
    a = np.concatenate(votes)
    lo, hi = SHADOW_SEARCH
    edges = np.arange(lo, hi + bin_width / 2, bin_width)
    counts, _ = np.histogram(a, bins=edges)
    if counts.sum() < min_count:
        return None
    smooth = np.convolve(counts.astype(np.float64), [0.25, 0.5, 0.25], mode="same")
    peaks = [i for i in range(1, len(smooth) - 1) if smooth[i] >= smooth[i - 1] and smooth[i] > smooth[i + 1]]
    if not peaks:
        return None
    best = max(peaks, key=lambda i: smooth[i])
    return float(edges[best] + bin_width / 2)


ILLUM_MIN_WEIGHT = 2.0
"""Smallest total weight (sum of the tiles' voting fractions) of a tile neighbourhood whose weighted median sets the
local illumination field; below it the field is 1 there (:func:`wptrack.kernels.background.tile_smooth_kernel`)."""


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


@dataclass
class _WindowRead:
    """A window's samples as read from the source and prepared on the host (NumPy only, no device work): what
    :meth:`OfflineBackground._read` returns, in the prefetch worker or in the calling thread.

    Attributes:
        frames: The K readable samples, ``(H, W, 3)`` uint8 C-contiguous each.
        sub: ``(K, 3, P')`` uint8 their channel values at the pixel subsample (None when no frame).
        gains: ``(K, 3)`` float32 their gains (:func:`sample_gains_channels`).
        bg_sub: ``(3, P')`` float64 the compensated median at the subsample.
        bg_gain: ``(3, P'')`` float64 it at the frame gain's pixels.
        notes: The sampler's warnings, ``(message, *args)``, logged by the thread that takes the read.
        error: The exception the read raised, re-raised by the thread that takes it.
    """

    frames: list[np.ndarray]
    sub: np.ndarray | None = None
    gains: np.ndarray | None = None
    bg_sub: np.ndarray | None = None
    bg_gain: np.ndarray | None = None
    notes: list[tuple[Any, ...]] = field(default_factory=list)
    error: Exception | None = None


class OfflineBackground:
    """Windowed median/MAD background of one source and the per-frame foreground evidence.

    Args:
        source: The camera's frames.
        config: A ``MaskConfig`` (fields ``window``, ``samples``, ``fg_threshold``, ``fg_low``, ``spread_cap``,
            ``soft_scale``, ``noise_floor``, ``detect_shadows``, ``shadow_lo``, ``shadow_hi``, ``shadow_chroma``).
        device: Warp device alias.

    Attributes:
        windows: The background windows (:func:`plan_windows`).
        centres: Their centres, frames.

    Use :meth:`evidence` frame by frame in time order (a restart at frame 0 is allowed); windows are built when
    first needed and dropped when no later frame needs them.

    Prefetch: when :meth:`evidence` builds window ``i``, one worker thread (created on first use, joined by
    :meth:`close`) starts reading window ``i + 1``'s samples (decoding: OpenCV releases the GIL) and preparing
    them with NumPy (subsample, gains, medians), while the frames before it are processed; building ``i + 1``
    then takes that read. The worker touches only the sampler and NumPy: every Warp launch, allocation and copy
    stays in the calling thread (trackers capture CUDA graphs there). The sampler is used by one thread at a time
    and reads the same frames in the same order as without the worker, so the masks are the same; its warnings
    are logged, and its errors raised, by the calling thread when it takes the read. A request for another window
    first waits for (or cancels) the pending read and drops it. :meth:`background` and :meth:`spread` do not
    prefetch.
    """

    def __init__(self, source: FrameSource, config: Any, device: str) -> None:
        import warp as wp

        from .kernels import background as kbg

        self.source = source
        self.config = config
        self.device = device
        self.windows = plan_windows(len(source), config.window, config.samples, source.name)
        self.centres = [w.centre for w in self.windows]
        self.pixels = source.width * source.height
        n3 = 3 * self.pixels
        on_cpu = wp.get_device(device).is_cpu
        # CUDA: the frame goes up and the results come down through pinned host buffers (allocated once, copied
        # asynchronously, one wait per frame); CPU: the kernel reads the caller's frame and writes arrays that
        # NumPy views share
        self._frame = None if on_cpu else wp.zeros(n3, dtype=wp.uint8, device=device)
        self._stage_in = None if on_cpu else wp.empty(n3, dtype=wp.uint8, device="cpu", pinned=True)
        self._stage_mask = None if on_cpu else wp.empty(self.pixels, dtype=wp.uint8, device="cpu", pinned=True)
        self._stage_prob = None if on_cpu else wp.empty(self.pixels, dtype=wp.float32, device="cpu", pinned=True)
        staged = (self._stage_in, self._stage_mask, self._stage_prob)
        self._stage_views = None if on_cpu else [a.numpy() for a in staged]  # NumPy views of the pinned buffers
        self._mask = wp.zeros(self.pixels, dtype=wp.uint8, device=device)
        self._prob = wp.zeros(self.pixels, dtype=wp.float32, device=device)
        self._shadow = wp.zeros(self.pixels, dtype=wp.uint8, device=device)
        self._diff = wp.zeros(self.pixels, dtype=wp.vec3, device=device)
        self._packed = wp.zeros(self.pixels, dtype=wp.uint8, device=device) if config.neighbourhood else None
        self._rows = wp.zeros(self.pixels, dtype=wp.vec4, device=device) if config.neighbourhood else None
        self._built: dict[int, tuple[Any, Any]] = {}
        self._scale: dict[int, float] = {}  # image-wide median noise scale of each built window
        self._nb_scale: dict[int, float] = {}  # neighbourhood_scale of each built window
        self._ratio: dict[int, float | None] = {}  # learnt shadow ratio of each built window (None: not learnt)
        # channel values of a pixel subsample (every 13th pixel) for the windows' gains (illumination changes) and
        # shadow ratios: flat indices pixel-major (3 P',) and channel-major (3, P')
        pixels = np.arange(0, self.pixels, 13)
        self._sub = (3 * pixels[:, None] + np.arange(3)[None, :]).reshape(-1)
        self._sub_channels = np.ascontiguousarray(self._sub.reshape(-1, 3).T)
        # a frame's gain: every m-th pixel of that subsample, at most GAIN_PIXELS pixels
        self._gain_step = max(1, math.ceil(len(pixels) / GAIN_PIXELS))
        self._gain_index = np.ascontiguousarray(self._sub_channels[:, :: self._gain_step])
        self._bg_sub: dict[int, np.ndarray] = {}  # each window's (3, P') compensated median at the subsample
        self._bg_gain: dict[int, np.ndarray] = {}  # ... at the frame gain's pixels
        self.last_gain = np.ones(3)  # the global gain of the last frame given to evidence() (B, G, R)
        self._stacks: dict[int, Any] = {}
        self._sampler = _Sampler(source)
        self._executor: ThreadPoolExecutor | None = None  # the prefetch worker (one thread), made on first use
        self._pending: tuple[int, Future] | None = None  # (window, its read) submitted to the worker
        self._prefetch = True  # False: every window read in the calling thread (tests compare the two)
        self.on_build: Callable[[int, float, np.ndarray], None] | None = None
        """Called as ``on_build(window, centre, background)`` when a window is built (in the thread that asked
        for it), with its ``(H, W, 3)`` uint8 BGR background: e.g. a run saving the backgrounds for its report."""
        p = kbg.ForegroundParams()
        p.threshold = float(config.fg_threshold)
        p.low_threshold = float(config.fg_low) if config.fg_low > 0 else float(config.fg_threshold)
        p.spread_cap = 0.0
        p.soft_scale = float(config.soft_scale)
        p.noise_floor = float(config.noise_floor)
        p.shadow = int(bool(config.detect_shadows))
        p.shadow_lo = float(config.shadow_lo)
        p.shadow_hi = float(config.shadow_hi)
        p.shadow_edge_hi = float(config.shadow_hi)
        p.chroma_max = float(config.shadow_chroma)
        c = config
        height, width = source.height, source.width
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
        self.params = p
        # local illumination: per-pixel luminance and patch statistics, per-tile gains and the smoothed field
        self._patches = bool(p.tile or p.veto_ncc > 0 or p.veto_grad > 0)
        n_tiles = p.tiles_x * p.tiles_y
        self._luma = wp.zeros(self.pixels if self._patches else 1, dtype=wp.vec3, device=device)
        self._rows9 = wp.zeros(self.pixels if self._patches else 1, dtype=kbg.rows_vec, device=device)
        self._patch = wp.zeros(self.pixels if self._patches else 1, dtype=kbg.patch_vec, device=device)
        self._tiles = wp.zeros(n_tiles, dtype=wp.vec4, device=device)
        self._local = wp.zeros(n_tiles, dtype=wp.vec3, device=device)

    def _read(self, i: int) -> _WindowRead:
        """Read window ``i``'s samples and prepare them on the host (any thread; no Warp call: see the class)."""
        ahead = self.windows[i + 1].samples if i + 1 < len(self.windows) else ()
        notes: list[tuple[Any, ...]] = []
        self._sampler.notes = notes
        try:
            frames = [np.ascontiguousarray(f) for f in self._sampler.read(self.windows[i].samples, ahead)]
            if not frames:
                return _WindowRead(frames, notes=notes)
            sub = np.empty((len(frames), *self._sub_channels.shape), dtype=np.uint8)
            for r, f in enumerate(frames):
                sub[r] = f.reshape(-1)[self._sub_channels]
            gains, bg_sub = sample_gains_channels(sub)
            bg_gain = np.ascontiguousarray(bg_sub[:, :: self._gain_step])
            return _WindowRead(frames, sub, gains, bg_sub, bg_gain, notes)
        except Exception as e:  # noqa: BLE001 - raised by the thread that takes the read, after its warnings
            return _WindowRead([], notes=notes, error=e)
        finally:
            self._sampler.notes = None

    def _take(self, i: int) -> _WindowRead:
        """Window ``i``'s read: the worker's when it was prefetched, else read now (a pending read of another
        window is cancelled, or waited for and dropped, first: the sampler serves one thread at a time)."""
        pending, self._pending = self._pending, None
        if pending is not None and pending[0] == i:
            got = pending[1].result()
        else:
            if pending is not None and not pending[1].cancel():
                wait_futures([pending[1]])
            got = self._read(i)
        for note in got.notes:
            log.warning(*note)
        if got.error is not None:
            raise got.error
        return got

    def _submit(self, i: int) -> None:
        """Start reading window ``i``'s samples in the worker (unless built, pending or past the last)."""
        if not self._prefetch or i >= len(self.windows) or i in self._built or self._pending is not None:
            return
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wptrack-background")
        self._pending = (i, self._executor.submit(self._read, i))

    def _window(self, i: int, prefetch: bool = False) -> tuple[Any, Any]:
        """``(median, mad)`` device arrays of window ``i`` (built on first use; with ``prefetch``, building it
        starts the worker's read of window ``i + 1``)."""
        import warp as wp

        from .kernels import background as kbg

        if i in self._built:
            return self._built[i]
        got = self._take(i)
        frames = got.frames
        if not frames:
            if self._built:
                log.warning("%s: no frame of background window %d could be read; reusing another", self.source.name, i)
                m = max(self._built)
                for stats in (self._bg_sub, self._bg_gain, self._scale, self._nb_scale, self._ratio):
                    if m in stats:
                        stats[i] = stats[m]
                return self._built[m]
            raise FrameError(f"{self.source.name}: no frame of background window {i} could be read")
        if prefetch:
            self._submit(i + 1)  # the worker reads on while this window is built and its frames processed
        k = len(frames)
        n3 = 3 * self.pixels
        stack = self._stacks.get(k)
        if stack is None:
            stack = self._stacks[k] = wp.zeros((k, n3), dtype=wp.uint8, device=self.device)
        for r, f in enumerate(frames):
            flat = f.reshape(-1)
            wp.copy(stack, wp.array(flat, dtype=wp.uint8, device="cpu", copy=False), dest_offset=r * n3, count=n3)
        sub, gains = got.sub, got.gains
        self._bg_sub[i], self._bg_gain[i] = got.bg_sub, got.bg_gain
        median = wp.zeros(3 * self.pixels, dtype=wp.uint8, device=self.device)
        mad = wp.zeros(3 * self.pixels, dtype=wp.uint8, device=self.device)
        g = wp.array(gains, dtype=wp.vec3, device=self.device)
        wp.launch(
            kbg.median_mad_kernel, dim=3 * self.pixels, inputs=[stack, g], outputs=[median, mad], device=self.device
        )
        c = self.config
        if self.params.tile and c.illum_windows:
            # each sample under its own light: divide it by its global gain and local field against this first
            # median, then the statistics again (unit gains) on what now differs only by what moved
            self._compensate_window(stack, gains, median, mad)
            ones = wp.array(np.ones((k, 3), dtype=np.float32), dtype=wp.vec3, device=self.device)
            wp.launch(kbg.median_mad_kernel, dim=3 * self.pixels, inputs=[stack, ones], outputs=[median, mad],
                      device=self.device)  # fmt: skip
            if c.mode_band > 0:
                self._mode(stack, ones, mad, median)
            host = stack.numpy()
            frames = [host[r].reshape(self.source.height, self.source.width, 3) for r in range(k)]
            sub = np.ascontiguousarray(host[:, self._sub_channels.reshape(-1)].reshape(k, *self._sub_channels.shape))
            gains = np.ones((k, 3), dtype=np.float32)
            bg_sub = median_last(np.moveaxis(sub, 0, -1).astype(np.float64))
            self._bg_sub[i], self._bg_gain[i] = bg_sub, np.ascontiguousarray(bg_sub[:, :: self._gain_step])
        elif c.mode_band > 0:
            self._mode(stack, g, mad, median)
        self._built[i] = (median, mad)
        if c.spread_cap > 0 or c.shadow_band > 0 or c.neighbourhood > 0:
            mad_host = mad.numpy()
            self._scale[i] = spread_scale(mad_host)
            if c.neighbourhood > 0:
                shape = (self.source.height, self.source.width, 3)
                self._nb_scale[i] = neighbourhood_scale(
                    [f.reshape(shape) for f in frames], gains, median.numpy().reshape(shape), mad_host.reshape(shape),
                    c.neighbourhood, c.noise_floor,
                )  # fmt: skip
                log.info(
                    "%s: background window %d: neighbourhood noise scale %.2f", self.source.name, i, self._nb_scale[i]
                )
            if self.config.shadow_band > 0 and self.config.detect_shadows:
                c = self.config
                ratio = shadow_ratio(
                    sub.transpose(0, 2, 1), gains, self._bg_sub[i].T, mad_host[self._sub].reshape(-1, 3),
                    c.fg_threshold, c.noise_floor, c.shadow_chroma,
                )  # fmt: skip
                self._ratio[i] = ratio
                log.info("%s: background window %d: learnt shadow ratio %s", self.source.name, i, ratio)
        log.debug("%s: background window %d from %d frames", self.source.name, i, k)
        if self.on_build is not None:
            image = median.numpy().reshape(self.source.height, self.source.width, 3).copy()
            self.on_build(i, float(self.centres[i]), image)
        return median, mad

    def _illumination(
        self, frame: Any, gain: Any, b0: Any, m0: Any, b1: Any, m1: Any, w: float, shadows: bool = True
    ) -> None:
        """Launch the patch statistics of ``frame`` (a flat device or CPU uint8 array) against the background
        ``(b0, m0)``/``(b1, m1)`` (weight ``w`` of the second) into ``self._patch`` and, with tiles, its local field
        into ``self._local`` (:mod:`wptrack.kernels.background`); with ``shadows``, pixels that pass the cast-shadow
        test (``self.params``' bounds) do not vote for the field."""
        import warp as wp

        from .kernels import background as kbg

        c, p, dev = self.config, self.params, self.device
        width, height = self.source.width, self.source.height
        wp.launch(kbg.luma_kernel, dim=self.pixels, inputs=[frame, gain, b0, m0, b1, m1, w, p], outputs=[self._luma],
                  device=dev)  # fmt: skip
        r = int(c.illum_patch)
        wp.launch(kbg.patch_rows_kernel, dim=self.pixels, inputs=[self._luma, width, height, r],
                  outputs=[self._rows9], device=dev)  # fmt: skip
        wp.launch(kbg.patch_kernel, dim=self.pixels, inputs=[self._rows9, self._luma, width, height, r],
                  outputs=[self._patch], device=dev)  # fmt: skip
        if p.tile:
            n = p.tiles_x * p.tiles_y
            wp.launch(kbg.tile_gain_kernel, dim=n, inputs=[frame, gain, b0, b1, w, self._patch, p, height,
                      int(shadows)], outputs=[self._tiles], device=dev)  # fmt: skip
            wp.launch(kbg.tile_smooth_kernel, dim=n,
                      inputs=[self._tiles, p.tiles_x, p.tiles_y, int(c.illum_radius), ILLUM_WIDEN, ILLUM_MIN_WEIGHT,
                              float(c.illum_keep), float(c.illum_dead)],
                      outputs=[self._local], device=dev)  # fmt: skip

    def _compensate_window(self, stack: Any, gains: np.ndarray, median: Any, mad: Any) -> None:
        """Divide each sample of a window's ``stack`` (on the device, in place) by its global gain and its own local
        illumination field against the window's first ``(median, mad)``; the caller rebuilds the statistics with
        unit gains."""
        import warp as wp

        from .kernels import background as kbg

        p, c = self.params, self.config
        frame_cap = p.spread_cap  # the per-frame cap; the window's own while it is built (no state from frames)
        p.spread_cap = float(c.spread_cap * spread_scale(mad.numpy())) if c.spread_cap > 0 else 0.0
        try:
            for k in range(stack.shape[0]):
                g = wp.vec3(*(float(v) for v in gains[k]))
                self._illumination(stack[k], g, median, mad, median, mad, 0.0, shadows=False)
                wp.launch(kbg.compensate_kernel, dim=self.pixels, inputs=[stack, k, g, self._local, p],
                          device=self.device)  # fmt: skip
        finally:
            p.spread_cap = frame_cap

    def _mode(self, stack: Any, gains: Any, mad: Any, median: Any) -> None:
        """Rebuild a window's ``median`` and ``mad`` (device arrays, in place) as the densest cluster of each pixel's
        samples (:func:`wptrack.kernels.background.mode_kernel`), the band ``mode_band`` times the image-wide noise
        scale of the window's first ``mad`` (at least the noise floor)."""
        import warp as wp

        from .kernels import background as kbg

        c = self.config
        band = float(c.mode_band * max(c.noise_floor, spread_scale(mad.numpy())))
        wp.launch(kbg.mode_kernel, dim=self.pixels, inputs=[stack, gains, band], outputs=[median, mad],
                  device=self.device)  # fmt: skip

    def shadow_bounds(self, i: int, j: int, w: float) -> tuple[float, float]:
        """Brightness-ratio bounds of the cast-shadow (umbra) test between windows ``i`` and ``j`` (weight ``w`` of
        ``j``): the learnt ratio ``r`` (interpolated; a window that learnt none uses the other's) gives
        ``[max(r - band, 0.05), min(r + band, shadow_hi)]``: one sky and one sun darken every cast shadow of the
        scene by about ``r``, so nothing darker than ``r - band`` is one of them, whatever ``shadow_lo`` says (deep
        sun shadows below it are removed; under an overcast sky, ``r`` near 0.9 as on the PETS clip, dark neutral
        clothes at 0.6-0.7, which the fixed bounds took for shadow, stay foreground). Ratios above the band, up to
        ``shadow_hi``, are penumbra candidates (shadow only where attached to an umbra, :func:`resolve_levels`).
        No learnt ratio: the configured ``[shadow_lo, shadow_hi]``.

        Until 2026-11-24 the learnt ratio could lower ``shadow_lo`` but not raise it, because raising it on the
        PETS clip made the darker shadows at the people's feet foreground and the joint template filter then lost
        MOTA (0.24 -> 0.05); with the partitioned filter (``TemplateConfig.partition``) the fuller legs are worth
        more than the feet's shadow costs (docs/reproduction.md, round five)."""
        c = self.config
        ri, rj = self._ratio.get(i), self._ratio.get(j)
        if ri is None and rj is None:
            return float(c.shadow_lo), float(c.shadow_hi)
        r = (1.0 - w) * (ri if ri is not None else rj) + w * (rj if rj is not None else ri)
        lo = max(r - c.shadow_band, 0.05)
        return float(lo), float(max(min(r + c.shadow_band, c.shadow_hi), lo))

    def background(self, i: int = 0) -> np.ndarray:
        """``(H, W, 3)`` uint8 BGR background of window ``i`` (builds it if needed)."""
        median, _ = self._window(i)
        return median.numpy().reshape(self.source.height, self.source.width, 3).copy()

    def spread(self, i: int = 0) -> np.ndarray:
        """``(H, W, 3)`` uint8 per-channel MAD of window ``i`` (8-bit units)."""
        _, mad = self._window(i)
        return mad.numpy().reshape(self.source.height, self.source.width, 3).copy()

    def evidence(self, t: int, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Foreground of frame ``t``.

        Args:
            t: Frame index.
            frame: ``(H, W, 3)`` uint8 BGR.

        Returns:
            ``(mask, prob)``: ``(H, W)`` uint8 mask (1 = foreground, shadows excluded, after the hysteresis, not
            cleaned) and ``(H, W)`` float32 foreground probability.
        """
        import warp as wp

        from .kernels import background as kbg

        i, j, w = bracket(self.centres, t)
        for old in [k for k in self._built if k < i]:
            del self._built[old]
            self._bg_sub.pop(old, None)
            self._bg_gain.pop(old, None)
        b0, m0 = self._window(i, prefetch=True)
        b1, m1 = self._window(j, prefetch=True)
        flat = np.ascontiguousarray(frame, dtype=np.uint8).reshape(-1)
        if flat.size != 3 * self.pixels:  # the kernel reads 3 H W values where the frame is
            raise FrameError(
                f"{self.source.name}: frame {t} has shape {np.shape(frame)}, expected "
                f"({self.source.height}, {self.source.width}, 3) uint8"
            )
        if self._stage_in is None:
            frame_in = wp.array(flat, dtype=wp.uint8, device="cpu", copy=False)
        else:  # the upload runs while the host computes the gain
            self._stage_views[0][:] = flat
            wp.copy(self._frame, self._stage_in)
            frame_in = self._frame
        bg = self._bg_gain[i] if w == 0.0 else (1.0 - w) * self._bg_gain[i] + w * self._bg_gain[j]
        gain = channel_gains(flat[self._gain_index][None], bg)[0]
        self.last_gain = gain
        if self.config.spread_cap > 0:
            self.params.spread_cap = float(self.config.spread_cap * ((1.0 - w) * self._scale[i] + w * self._scale[j]))
        if self.config.shadow_band > 0:
            self.params.shadow_lo, self.params.shadow_hi = self.shadow_bounds(i, j, w)
        if self._patches:
            self._illumination(frame_in, wp.vec3(*gain), b0, m0, b1, m1, w)
        wp.launch(
            kbg.foreground_kernel,
            dim=self.pixels,
            inputs=[frame_in, b0, m0, b1, m1, w, wp.vec3(*gain), self.params, self._local, self._patch],
            outputs=[self._mask, self._prob, self._shadow, self._diff],
            device=self.device,
        )
        packed = self._mask
        if self._packed is not None:
            r = int(self.config.neighbourhood)
            width, height = self.source.width, self.source.height
            run = int(kbg.RUN)
            wp.launch(
                kbg.neighbourhood_rows_kernel,
                dim=height * ((width + run - 1) // run),
                inputs=[self._mask, self._diff, width, height, r],
                outputs=[self._rows],
                device=self.device,
            )
            scale = float((1.0 - w) * self._nb_scale[i] + w * self._nb_scale[j])
            wp.launch(
                kbg.neighbourhood_kernel,
                dim=width * ((height + run - 1) // run),
                inputs=[self._mask, self._rows, width, height, r, self.params.low_threshold, scale],
                outputs=[self._packed],
                device=self.device,
            )
            packed = self._packed
        shape = (self.source.height, self.source.width)
        if self._stage_mask is None:
            levels, prob = packed.numpy(), self._prob.numpy()
        else:
            wp.copy(self._stage_mask, packed)
            wp.copy(self._stage_prob, self._prob)
            wp.synchronize_stream(wp.get_stream(self.device))
            levels, prob = self._stage_views[1], self._stage_views[2]
        prob = prob.reshape(shape).copy()  # the caller's own (the buffers are overwritten by the next frame)
        return resolve_levels(levels.reshape(shape), prob), prob

    def close(self) -> None:
        """Stop and join the prefetch worker (a read in progress stops at its next frame and is dropped) and
        release the sampler's video reader. The model stays usable: a later call reads again (a new worker)."""
        pending, self._pending = self._pending, None
        if pending is not None:
            pending[1].cancel()
        if self._executor is not None:
            self._sampler.stop.set()
            try:
                self._executor.shutdown(wait=True, cancel_futures=True)
            finally:
                self._executor = None
                self._sampler.stop.clear()
        self._sampler.close()
