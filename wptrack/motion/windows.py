"""Background windows of the offline model (:mod:`wptrack.motion.background`): which frames each window samples
(:func:`plan_windows`), which two windows a frame interpolates between (:func:`bracket`), and the reader of the
samples (:class:`_Sampler`: seeks only across gaps of :data:`SEEK_GAP` frames or more, grabs forward otherwise,
keeping on its way the next window's samples; with :func:`sample_readers` > 1, an intra-coded video's window read by
several captures at once, in contiguous groups). The design is in :mod:`wptrack.motion.background` ("Windows",
"Drift", "Passes").
"""

from __future__ import annotations

import logging
import math
import threading
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wptrack.core.errors import FrameError
from wptrack.io.frames import ArraySource, FrameSource, ImageSequenceSource, VideoSource, _read_image, _to_bgr

log = logging.getLogger("wptrack.motion.background")  # the model's warnings (short recordings, unreadable samples)

#: Sample gap (frames) from which the sampler seeks instead of grabbing the frames in between. OpenCV's FFmpeg
#: reader seeks 16 frames before the target and decodes forward from there (more after a sparse keyframe), and
#: ``grab`` decodes as much as ``read`` (it only skips the colour conversion): a seek cost 17-27 decodes of a
#: 1920x1080 FFV1 video on the CI machine, so grabbing forward is cheaper up to about 20 frames.
SEEK_GAP = 24

SAMPLE_READERS_ENV = "WPTRACK_SAMPLE_READERS"
"""Environment variable: captures that read one window's samples of an intra-coded video at once (default:
:func:`sample_readers`)."""


def sample_readers() -> int:
    """Captures reading one window's samples: :data:`SAMPLE_READERS_ENV` when set, else one per 4 host cores, at
    most 4 (one on the 2-core CI machine: the sampler reads alone, as before). The first window is read before the
    first mask (300 frames grabbed at 1080p, ~2.5 s on an H100 host: a third of a 600-frame run), and every later one
    by a thread beside the frames' own decoding; on a host with cores to spare, several captures read a window's
    samples in contiguous groups at once."""
    from wptrack.core.config import env_count, host_cores

    return env_count(SAMPLE_READERS_ENV, max(1, min(4, host_cores() // 4)))


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

    def __init__(self, source: FrameSource, readers: int | None = None) -> None:
        self.source = source
        self.cap: Any = None
        self.pos = 0  # index of the frame the next read() returns
        self.kept: dict[int, np.ndarray] = {}  # frames passed by an earlier read that a later one samples
        self.notes: list[tuple[Any, ...]] | None = None  # a list: warnings kept here (for another thread to log)
        self.stop = threading.Event()  # set (by another thread): a video read stops at its next frame
        self.readers = sample_readers() if readers is None else max(1, int(readers))
        self._intra: bool | None = None  # the video's codec is intra-only (exact seeks); None: not known yet
        self._pool: ThreadPoolExecutor | None = None  # the other captures' threads (readers > 1)

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
        if self.cap is None:
            self.cap = self.source._open()  # type: ignore[attr-defined]
            self.pos = 0
        kept, self.kept = self.kept, {}
        todo = [i for i in indices if i not in kept]
        groups = self._groups(todo)
        if len(groups) > 1:
            frames, failed = self._read_groups(groups, ahead)
        else:
            frames, failed = {}, None
            self.cap, self.pos, failed = _read_forward(self.cap, self.pos, todo, ahead, frames, self.kept, self.stop,
                                                       self.source.name)  # fmt: skip
        out = []
        for i in indices:
            if failed is not None and i >= failed:
                self._warn("%s: cannot read frame %d for the background; skipped", self.source.name, failed)
                break  # the video ends earlier than it reported
            frame = kept[i] if i in kept else frames[i]
            if i in ahead:
                self.kept[i] = frame
            if frame.ndim == 3 and frame.shape[2] == 3 and frame.shape[:2] == (self.source.height, self.source.width):
                out.append(frame)
        return out

    def _groups(self, todo: list[int]) -> list[list[int]]:
        """``todo`` (increasing frame indices to decode) cut into contiguous groups, one per capture: several only
        with :attr:`readers` > 1, an intra-coded video (its seeks land exactly on the frame asked for, so a group read
        from a seek gives the frames of one forward read) and a span worth it (each group at least ``2 SEEK_GAP``
        frames: a seek costs about 16 decodes)."""
        import cv2

        from wptrack.io.decode import INTRA_CODECS, fourcc

        if self.readers < 2 or len(todo) < 2:
            return [todo]
        if self._intra is None:
            self._intra = fourcc(self.cap).upper() in INTRA_CODECS
        span = todo[-1] - todo[0] + 1
        n = min(self.readers, len(todo), span // (2 * SEEK_GAP))
        if not self._intra or n < 2 or int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT)) <= 0:
            return [todo]
        cuts = [round(k * len(todo) / n) for k in range(n + 1)]
        return [todo[cuts[k] : cuts[k + 1]] for k in range(n)]

    def _read_groups(self, groups: list[list[int]], ahead: set[int]) -> tuple[dict[int, np.ndarray], int | None]:
        """Read ``groups`` at once: the first with the sampler's capture (from where it stands), each other with a
        capture of its own sought to its first frame; the last group's capture becomes the sampler's (the next
        window's samples follow it). Returns the frames by index and the first index that could not be read (None:
        all were)."""
        import cv2

        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=self.readers - 1, thread_name_prefix="wptrack-samples")
        name = self.source.name

        def group(g: list[int]) -> tuple[Any, int, dict[int, np.ndarray], dict[int, np.ndarray], int | None]:
            frames: dict[int, np.ndarray] = {}
            passed: dict[int, np.ndarray] = {}
            cap = self.source._open()  # type: ignore[attr-defined]
            try:
                cap.set(cv2.CAP_PROP_POS_FRAMES, float(g[0]))
                if int(round(cap.get(cv2.CAP_PROP_POS_FRAMES))) != g[0]:  # not exact after all: from the start
                    cap.release()
                    cap = self.source._open()  # type: ignore[attr-defined]
                    pos = 0
                else:
                    pos = g[0]
                cap, pos, failed = _read_forward(cap, pos, g, ahead, frames, passed, self.stop, name)
            except BaseException:
                cap.release()
                raise
            return cap, pos, frames, passed, failed

        futures = [self._pool.submit(group, g) for g in groups[1:]]
        frames: dict[int, np.ndarray] = {}
        error: BaseException | None = None
        try:
            self.cap, self.pos, failed = _read_forward(self.cap, self.pos, groups[0], ahead, frames, self.kept,
                                                       self.stop, name)  # fmt: skip
        except BaseException as e:  # noqa: BLE001 - raised below, after the other groups' captures are released
            error, failed = e, None
        results = []
        for f in futures:
            try:
                results.append(f.result())
            except BaseException as e:  # noqa: BLE001 - the first error is raised below
                error = error or e
        if error is not None:
            for r in results:
                r[0].release()
            raise error
        for _, _, got, passed, g_failed in results:
            frames.update(got)
            self.kept.update(passed)
            if failed is None:
                failed = g_failed
        # the last group's capture reads on (the next window's samples come after it); the others are released
        for cap, *_ in results[:-1]:
            cap.release()
        self.cap.release()
        self.cap, self.pos = results[-1][0], results[-1][1]
        return frames, failed

    def close(self) -> None:
        self.kept = {}
        if self.cap is not None:
            self.cap.release()
            self.cap = None
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


def _read_forward(
    cap: Any,
    pos: int,
    todo: list[int],
    ahead: set[int],
    frames: dict[int, np.ndarray],
    passed: dict[int, np.ndarray],
    stop: threading.Event,
    name: str,
) -> tuple[Any, int, int | None]:
    """Read the frames ``todo`` (increasing indices) with ``cap``, which stands at frame ``pos``: seek only across
    gaps of :data:`SEEK_GAP` frames or more (or back), grab the frames in between, keeping in ``passed`` those of
    ``ahead``; the frames read go to ``frames``. Returns ``(cap, pos, failed)``: where the capture now stands and the
    first index that could not be read (None: all were; nothing after it is read). ``stop`` set ends the read
    (:class:`_Stopped`)."""
    import cv2

    for i in todo:
        if stop.is_set():
            raise _Stopped(f"{name}: background read stopped")
        if i < pos or i - pos >= SEEK_GAP:
            cap.set(cv2.CAP_PROP_POS_FRAMES, float(i))
            pos = i
        ok = True
        while ok and pos < i:
            if stop.is_set():
                raise _Stopped(f"{name}: background read stopped")
            ok = cap.grab()
            if ok and pos in ahead:
                ok, frame = cap.retrieve()
                if ok and frame is not None:
                    passed[pos] = frame
            pos += 1
        ok, frame = cap.read() if ok else (False, None)
        if not ok or frame is None:
            return cap, pos, i
        pos += 1
        frames[i] = frame
    return cap, pos, None


@dataclass
class _WindowRead:
    """A window's samples as read from the source and prepared on the host (NumPy only, no device work): what
    :meth:`wptrack.motion.background.OfflineBackground._read` returns, in the prefetch worker or in the calling thread.

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


class WindowShare:
    """The built windows of one source, shared by the :class:`~wptrack.motion.background.OfflineBackground` models
    that make its masks in threads (:func:`wptrack.motion.parallel.parallel_evidence`): each window is built once, by
    the first model that needs it, and the others wait for it and use the same device arrays and statistics (read
    only after the build). Without it every model built every window (``W`` times the decoding of the samples and the
    window kernels).

    The windows' reader (the sampler and its prefetch worker) is the share's too: every frame needs the window before
    the one it builds, so the windows are built one after another in time order, whichever model builds them, and
    the sampler reads the same frames in the same order as for one model alone (the same masks, also from a video
    whose seeks are not exact). Windows before the earliest one a model still needs are dropped.

    Args:
        source: The frames the models read (the sampler's).

    Attributes:
        windows: The windows' plan (:func:`plan_windows`), made by the first model (which logs its warnings once).
        built: ``{window: (median, mad)}`` device arrays of the built windows.
        bg_sub, bg_gain, scale, nb_scale, ratio: The windows' host statistics (see ``OfflineBackground``).
    """

    def __init__(self, source: FrameSource) -> None:
        self.lock = threading.Lock()
        self.sampler = _Sampler(source)
        self.windows: list[Window] | None = None  # the plan (plan_windows), made once: its warnings said once
        self.plan: tuple[int, int, int] | None = None  # its (frames, window, samples)
        self.read_lock = threading.Lock()  # the sampler serves one read at a time
        self.executor: ThreadPoolExecutor | None = None  # the prefetch worker (one thread), made on first use
        self.pending: tuple[int, Future] | None = None  # (window, its read) submitted to the worker
        self.build_executor: ThreadPoolExecutor | None = None  # with a builder (``ahead``): its build worker
        self.built: dict[int, tuple[Any, Any]] = {}
        self.bg_sub: dict[int, np.ndarray] = {}
        self.bg_gain: dict[int, np.ndarray] = {}
        self.scale: dict[int, float] = {}
        self.nb_scale: dict[int, float] = {}
        self.ratio: dict[int, float | None] = {}
        self.building: dict[int, threading.Event] = {}  # windows being built, set when done (or failed)
        self.failed: dict[int, BaseException] = {}  # a failed build's error, raised by the models that waited
        self.notes: dict[int, list[tuple]] = {}  # an ahead build's warnings, logged by the model that takes it first
        self.positions: dict[int, int] = {}  # id(model) -> the first window its current frame needs
        self.ahead: Any = None
        """A model that builds the windows in the prefetch worker, ahead of the frames that need them (None: the first
        model that needs a window builds it, and the others wait meanwhile); set by
        :func:`wptrack.motion.parallel.build_ahead` with ``guard``)."""
        self.guard: Any = None  # the device's DeviceGuard: the builder's device work is shared work

    def drop_before(self, model: Any, i: int) -> None:
        """``model``'s frames now need windows ``>= i``: drop the windows no model needs any more."""
        with self.lock:
            self.positions[id(model)] = i
            keep = min(self.positions.values())
            for old in [k for k in self.built if k < keep]:
                for stats in (self.built, self.bg_sub, self.bg_gain):
                    stats.pop(old, None)
