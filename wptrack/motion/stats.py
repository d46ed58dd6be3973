"""Host statistics of the offline model's windows (:mod:`wptrack.motion.background`), NumPy on pixel subsamples:
global gains per channel of frames and samples (:func:`channel_gains`, :func:`sample_gains_channels`), the
image-wide noise scale (:func:`spread_scale`) and the neighbourhood test's (:func:`neighbourhood_scale`), and the
recording's learnt cast-shadow brightness ratio (:func:`shadow_ratio`). The design is in
:mod:`wptrack.motion.background` ("Gains", "Spread cap", the shadow band of
:meth:`wptrack.motion.background.OfflineBackground.shadow_bounds`).
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

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

    def one(c: int) -> np.ndarray | None:  # a channel's ratios and their medians
        b = background[c]
        ok = np.flatnonzero(b >= MIN_GAIN_LEVEL)
        return median_last(values[:, c, ok] / b[ok]) if ok.size >= 16 else None

    threads = None if values.size >= PARALLEL_MIN else 1  # a window's samples in threads; a frame's gain in this one
    for c, gains in enumerate(thread_map(one, [0, 1, 2], threads)):
        if gains is not None:
            out[:, c] = gains
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


PARALLEL_MIN = 1 << 20
"""Elements of an array from which :func:`median_last` splits its rows among :func:`host_threads` threads (a 1080p
window's gains and subsample medians: 12 million; a frame's gain: 0.1 million, in the calling thread)."""


def host_threads() -> int:
    """Threads for a window build's host statistics: the cores this process may use, at most 8, no more than a
    batch worker holds (``WPTRACK_DECODE_THREADS``). The results do not depend on it."""
    from wptrack.io.decode import thread_budget

    return max(1, min(8, thread_budget()))


def thread_map(fn: Callable, items: list, threads: int | None = None) -> list:
    """``[fn(item) for item in items]``, computed by up to ``threads`` (default :func:`host_threads`) threads at
    once (NumPy and OpenCV release the GIL in their loops), in the calling thread when that is one."""
    threads = min(len(items), host_threads() if threads is None else threads)
    if threads < 2:
        return [fn(item) for item in items]
    with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="wptrack-stats") as pool:
        return list(pool.map(fn, items))


def median_last(x: np.ndarray) -> np.ndarray:
    """``np.median(x, axis=-1)`` of an array without NaNs, the same numbers and dtype (the mean of the middle value,
    or of the two middle values, as ``np.median`` takes it), faster: rows sorted (float rows of at most 64 values:
    NumPy's vectorised sort beats selection there) or partitioned at the middle only (``np.median`` also
    partitions at the last value, for its NaN check, and costs several times more). From :data:`PARALLEL_MIN`
    elements the rows are split among threads (:func:`thread_map`; each row's median is its own: the same numbers)."""
    threads = host_threads() if x.size >= PARALLEL_MIN and x.ndim > 1 else 1
    if threads > 1:
        rows = x.reshape(-1, x.shape[-1])
        cuts = np.linspace(0, rows.shape[0], min(threads, rows.shape[0]) + 1).round().astype(int)
        parts = thread_map(_median_rows, [rows[a:b] for a, b in zip(cuts[:-1], cuts[1:], strict=True)], threads)
        return np.concatenate(parts).reshape(x.shape[:-1])
    return _median_rows(x)


def _median_rows(x: np.ndarray) -> np.ndarray:
    """:func:`median_last` in the calling thread."""
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


def motion_radius(width: int, height: int) -> int:
    """Radius (pixels) of the patch over which a window sample's change is averaged
    (:meth:`wptrack.motion.background.OfflineBackground._sample_motion`): 1/240 of the image's longer side, at least
    1 (2 at 480x360, 8 at 1920x1080), a few centimetres of a person at the usual distances."""
    return max(1, round(max(width, height) / 240))


#: Pixels between two of a window's image-wide noise statistics reads (:func:`spread_scale`'s MADs, the median sample
#: change of ``OfflineBackground._mode``).
SCALE_STEP = 7


def spread_scale(mad: np.ndarray, step: int = SCALE_STEP) -> float:
    """Image-wide median of the per-pixel noise scales ``1.4826 sqrt(sum_c MAD_c^2 / 3)`` (8-bit units), over every
    ``step``-th pixel of a flat ``(3 P,)`` MAD array."""
    m = mad.reshape(-1, 3)[::step].astype(np.float64)
    return float(np.median(1.4826 * np.sqrt((m * m).mean(axis=1))))


def neighbourhood_picks(count: int, max_samples: int = 5) -> list[int]:
    """The samples of a window of ``count`` that :func:`neighbourhood_scale` reads: ``max_samples`` evenly chosen."""
    return [int(k) for k in np.unique(np.linspace(0, count - 1, min(max_samples, count)).round().astype(int))]


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
    :func:`wptrack.kernels.core.background.neighbourhood_kernel` multiplies its ``z_n`` by ``c``, so a coherent change
    must beat the recording's real neighbourhood noise.

    Args:
        samples: ``(K, H, W, 3)`` uint8 a window's samples (an array or a sequence of K ``(H, W, 3)`` frames; only
            those of :func:`neighbourhood_picks` are read, the others may be None). gains: ``(K, 3)`` their global
            gains.
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
    pick = neighbourhood_picks(len(samples), max_samples)

    def one(k: int) -> tuple[np.ndarray, np.ndarray]:  # a sample's normalised differences, alone and averaged
        d = samples[k].astype(np.float32)
        d /= gains[k].astype(np.float32)
        d -= b
        d /= s
        single = np.abs(d[radius:-radius:3, radius:-radius:3]).ravel()
        return single, np.abs(cv2.blur(d, (2 * radius + 1, 2 * radius + 1))[radius:-radius:3, radius:-radius:3]).ravel()

    parts = thread_map(one, list(pick))  # in threads, in order: the same numbers
    s1 = float(median_last(np.concatenate([p[0] for p in parts])))
    sn = float(median_last(np.concatenate([p[1] for p in parts])))
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
    keep: np.ndarray | None = None,
    sharp: float = 0.0,
) -> float | None:
    """The brightness ratio of the cast shadows of a recording, learnt from a window's samples.

    Every sampled pixel that is foreground (``z > threshold``) and passes the chromaticity part of the shadow test
    (``cd <= chroma_max``) votes for its brightness ratio ``a`` (see :mod:`wptrack.kernels.core.background`); the cast
    shadows of one sun all darken the ground by about the same ratio and make the highest peak of the histogram
    of ``a`` inside :data:`SHADOW_SEARCH` (dark objects spread over many ratios, or lie below it). The peak must
    be a local maximum of the smoothed histogram, not the search range's end (the tail of a peak outside it).

    Args:
        samples: ``(K, P, 3)`` uint8 sampled values of P subsampled pixels. gains: ``(K, 3)`` the samples' global
            gains. background: ``(P, 3)`` the window's background at those pixels. mad: ``(P, 3)`` its MAD.
        threshold, noise_floor, chroma_max: As in :class:`wptrack.kernels.core.background.ForegroundParams`.
        bin_width: Histogram bin width (ratio).
        min_count: Fewer votes than this inside the search range: ``None`` (nothing learnt).
        keep: ``(K, P)`` bool, or None: only the sampled pixels marked here vote (the texture test of
            :meth:`wptrack.motion.illumination.LightField.sample_patches`: cast shadows keep the ground's texture,
            dark clothes of the shadow's colour replace it and would otherwise teach the band their own ratio);
            when fewer than ``min_count`` of them lie inside the search range (a flat floor: nothing to test), every
            vote counts.
        sharp: 0: the highest peak. Else the most significant: the peak whose excess over the mean ``m`` of the
            histogram within ``+- sharp`` of it (votes outside the search range included: a top-hat) is the most
            Poisson standard deviations, ``(s - m) / sqrt(max(m, 1))``, among the peaks with at least 3 (none: the
            highest peak). The shadows of one sky darken one floor by one ratio and make a narrow peak; dark clothes
            a broad hump, which may be higher (the EPFL terrace: clothes at 0.33-0.47 outnumber the shadows at
            0.81-0.89 in 31 of its 32 windows; the excess alone, ``s - m``, still chose the clothes in 5).

    Returns:
        The ratio at the peak, or ``None``.
    """
    b = background.astype(np.float64)
    s = np.maximum(noise_floor, 1.4826 * np.sqrt((mad.astype(np.float64) ** 2).mean(axis=1)))
    bb = (b * b).sum(axis=1)
    if len(gains) != len(samples):
        raise ValueError(f"{len(samples)} samples but {len(gains)} gains")

    def one(k: int) -> tuple[np.ndarray, np.ndarray | None]:  # sample k's votes: all, and those kept
        x = samples[k].astype(np.float64) / gains[k][None, :]
        z = np.sqrt(((x - b) ** 2).mean(axis=1)) / s
        fg = np.flatnonzero((z > threshold) & (bb >= 1.0))  # the ratios of the foreground pixels only
        x, bf, bbf = x[fg], b[fg], bb[fg]
        ib = (x * bf).sum(axis=1)
        a = ib / np.maximum(bbf, 1.0)
        cd = np.sqrt(np.maximum((x * x).sum(axis=1) - a * ib, 0.0) / np.maximum(bbf, 1.0))
        return a[cd <= chroma_max], None if keep is None else a[(cd <= chroma_max) & keep[k][fg]]

    parts = thread_map(one, list(range(len(samples))))  # samples in threads, votes in order: the same numbers
    votes = [p[0] for p in parts]
    lo, hi = SHADOW_SEARCH
    edges = np.arange(lo, hi + bin_width / 2, bin_width)
    counts = chosen = None
    if keep is not None:
        chosen = np.concatenate([p[1] for p in parts])
        counts, _ = np.histogram(chosen, bins=edges)
    if counts is None or counts.sum() < min_count:  # too little texture to test: every vote
        chosen = np.concatenate(votes)
        counts, _ = np.histogram(chosen, bins=edges)
    if counts.sum() < min_count:
        return None
    smooth = np.convolve(counts.astype(np.float64), [0.25, 0.5, 0.25], mode="same")
    peaks = [i for i in range(1, len(smooth) - 1) if smooth[i] >= smooth[i - 1] and smooth[i] > smooth[i + 1]]
    if not peaks:
        return None
    best = max(peaks, key=lambda i: smooth[i])
    if sharp > 0:
        wide = max(1, int(round(sharp / bin_width)))
        outer = np.arange(lo - wide * bin_width, hi + (wide + 0.5) * bin_width, bin_width)
        around, _ = np.histogram(chosen, bins=outer)
        mean = np.convolve(around.astype(np.float64), np.ones(2 * wide + 1) / (2 * wide + 1), mode="same")
        mean = mean[wide : wide + len(smooth)]
        standing = [i for i in peaks if smooth[i] - mean[i] >= 3.0 * np.sqrt(max(mean[i], 1.0))]
        if standing:
            best = max(standing, key=lambda i: (smooth[i] - mean[i]) / np.sqrt(max(mean[i], 1.0)))
    return float(edges[best] + bin_width / 2)
