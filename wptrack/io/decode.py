"""One video decoded by several threads at once, frames in order (:func:`parallel_frames`), for
:class:`wptrack.io.frames.VideoSource` when :func:`decode_workers` says so; its timestamps checked against its rate
(:func:`rate_note`).

A video is cut into chunks of :data:`CHUNK` consecutive frames; worker ``k`` of ``W`` decodes chunks ``k, k + W,
k + 2W, ...`` with a ``cv2.VideoCapture`` of its own (a seek to each chunk's first frame, then sequential reads), and
the frames come out in order. Each worker holds at most :data:`CHUNK` decoded frames ahead (a bounded queue of its
own), so memory is at most ``W (CHUNK + 1)`` frames whatever the consumer's speed; a consumer that stops early
stops the workers. Only for codecs whose every frame is a keyframe (:data:`INTRA_CODECS`): their seeks land exactly
on the frame asked for, so the frames are those of one sequential read (tested); a seek whose reported position is
not the frame asked for (a truncated AVI without its index) is replaced by reading forward from the start; other
codecs are read by one thread.

When it pays: OpenCV's FFmpeg decoder already runs threads of its own inside one capture, and the calling thread
still does the colour conversion, so more captures help when decoding is the pipeline's slowest stage and cores
are free (a GPU host; measure with ``WPTRACK_DECODE_WORKERS=N wptrack bench --tracker pipeline``). On the 2-core CI
machine it costs more CPU than it saves (1440x1080 MJPG, 2 captures: 19 ms of CPU per frame instead of 11 ms), so
the default is one thread. Each capture opens as :meth:`wptrack.io.frames.VideoSource._open` does, so a
``WPTRACK_DECODE_THREADS`` budget (``wptrack batch`` workers) sets each capture's FFmpeg threads: with both, a video
uses up to workers x threads.
"""

from __future__ import annotations

import logging
import os
import queue
import threading
from collections.abc import Iterator
from typing import Any

import numpy as np

from wptrack.io.jpeg import PACKET_CODECS, JpegCapture, jpeg_enabled, jpeg_frames, jpeg_workers, open_raw
from wptrack.io.prefetch import put_until

log = logging.getLogger(__name__)

CHUNK = 8
"""Frames per chunk (each worker decodes this many consecutive frames between seeks)."""

INTRA_CODECS = frozenset({"MJPG", "FFV1", "MJPA", "AVRN", "LJPG", "HFYU", "FFVH", "PNG ", "MPNG", "RGBA", "DIB "})
"""FOURCCs (upper case; compare :func:`fourcc` upper-cased) of codecs whose seeks land exactly on the frame asked
for: every frame a keyframe, or (FFV1) frames coded without reference to other frames' pixels."""


RATE_TOLERANCE = 0.5
"""A frame interval departing from ``1 / fps`` by more than this fraction marks a variable-frame-rate video
(:func:`rate_note`); decoders' timestamps jitter by a millisecond or so."""


def rate_note(fps: float, index: int, interval_ms: float) -> dict[str, Any] | None:
    """``{"frame", "interval_ms", "expected_ms", "reason"}`` when frame ``index`` comes ``interval_ms`` after the one
    before it, more than :data:`RATE_TOLERANCE` away from ``1 / fps`` (a variable frame rate: the trackers take
    every frame as one time step of ``1 / fps``); None otherwise."""
    expected = 1000.0 / float(fps)
    if abs(interval_ms - expected) <= RATE_TOLERANCE * expected:
        return None
    reason = (
        f"variable frame rate: frame {index} comes {interval_ms:.0f} ms after frame {index - 1}, the video's rate "
        f"{fps:g} frames/s says {expected:.0f} ms; the trackers take every frame as one time step of 1/fps, so "
        "motion across such gaps is misjudged (re-encode at a constant rate, e.g. ffmpeg -fps_mode cfr)"
    )
    return {"frame": index, "interval_ms": round(interval_ms, 3), "expected_ms": round(expected, 3), "reason": reason}


DECODE_THREADS_ENV = "WPTRACK_DECODE_THREADS"
"""Environment variable: the threads a run's video decoding may use (unset: OpenCV's and FFmpeg's defaults, as
many as the machine has cores, per video). When set to N, OpenCV's thread pool gets N threads and the N are shared
out among the run's videos (each FFmpeg decoder ``max(1, N // videos)`` threads), so several runs on one machine
(a batch's workers) do not oversubscribe its cores. ``wptrack batch`` sets it in each worker to the cores the
worker holds. Decoded frames do not depend on it."""


def decode_threads() -> int | None:
    """The thread budget of :data:`DECODE_THREADS_ENV` (None: unset, empty or not a positive integer)."""
    text = os.environ.get(DECODE_THREADS_ENV, "").strip()
    try:
        n = int(text)
    except ValueError:
        return None
    return n if n > 0 else None


def thread_budget() -> int:
    """The threads a run's host work may keep busy: the cores this process may use (its CPU affinity), no more than
    a batch worker holds (:func:`decode_threads`, set by ``wptrack batch``)."""
    from wptrack.core.config import host_cores

    cores = host_cores()
    return min(cores, decode_threads() or cores)


def decode_workers() -> int:
    """Decoding threads per video: the environment variable ``WPTRACK_DECODE_WORKERS`` (default 1: one thread)."""
    from wptrack.core.config import env_count

    return env_count("WPTRACK_DECODE_WORKERS", 1)


def fourcc(cap: Any) -> str:
    """The codec FOURCC an opened ``cv2.VideoCapture`` reports (``""`` when none)."""
    import cv2

    code = int(cap.get(cv2.CAP_PROP_FOURCC))
    return "".join(chr((code >> (8 * k)) & 0xFF) for k in range(4)) if code > 0 else ""


def is_jpeg_video(path: str) -> bool:
    """``path`` is a Motion-JPEG video (or a video of PNG images, :data:`wptrack.io.jpeg.PNG_CODECS`: wptrack's masks)
    whose first packet ``cv2.imdecode`` reads, and :func:`jpeg_enabled`: read it as a :class:`JpegCapture` (else with
    FFmpeg's decoder, as any other video)."""
    import cv2

    if not jpeg_enabled():
        return False
    cap = open_raw(path)
    try:
        if not cap.isOpened() or fourcc(cap).upper() not in PACKET_CODECS or cap.get(cv2.CAP_PROP_FORMAT) != -1:
            return False
        ok, frame = JpegCapture(cap).read()
    except cv2.error:
        return False
    finally:
        cap.release()
    if not ok or frame is None:
        log.debug("%s: its packets do not decode alone; read with FFmpeg's decoder", path)
        return False
    return True


_END = object()


def parallel_frames(open_capture: Any, count: int, workers: int, stop: threading.Event | None = None) -> Iterator[Any]:
    """Yield ``(index, ok, frame, ms)`` for frames ``0 .. count - 1`` in order, decoded by ``workers`` threads (see the
    module); ``ok`` False at the first frame that cannot be read (the video ends early), after which nothing more
    comes. ``ms`` is the decoder's timestamp of the frame.

    Args:
        open_capture: Makes a new opened ``cv2.VideoCapture`` of the video.
        count: Frames to read.
        workers: Decoding threads (>= 2).
        stop: Set to stop the workers (closing the iterator also stops them).
    """
    import cv2

    chunks = (count + CHUNK - 1) // CHUNK
    queues = [queue.Queue(maxsize=CHUNK) for _ in range(workers)]
    halt = stop or threading.Event()

    def put(q: queue.Queue, item: Any) -> bool:
        return put_until(q, item, halt)

    def work(k: int) -> None:
        q = queues[k]
        try:
            cap = open_capture()
        except BaseException as e:  # noqa: BLE001 - raised by the consumer
            put(q, e)
            return
        try:
            pos, exact = 0, True
            for c in range(k, chunks, workers):
                first = c * CHUNK
                if pos != first and exact:
                    cap.set(cv2.CAP_PROP_POS_FRAMES, float(first))
                    pos = first
                    if int(round(cap.get(cv2.CAP_PROP_POS_FRAMES))) != first:  # inexact (an AVI without index):
                        exact = False  # from the start again, and read forward from now on
                        cap.release()
                        cap = open_capture()
                        pos = 0
                while pos < first and cap.grab():
                    pos += 1
                for i in range(first, min(first + CHUNK, count)):
                    ok, frame = cap.read()
                    pos += 1
                    if not put(q, (i, bool(ok and frame is not None), frame, cap.get(cv2.CAP_PROP_POS_MSEC))):
                        return
                    if not ok or frame is None:
                        put(q, _END)
                        return
            put(q, _END)
        except BaseException as e:  # noqa: BLE001 - raised by the consumer
            put(q, e)
        finally:
            cap.release()

    threads = [
        threading.Thread(target=work, args=(k,), name=f"wptrack-decode-{k}", daemon=True) for k in range(workers)
    ]
    for t in threads:
        t.start()
    try:
        for i in range(count):
            item = queues[(i // CHUNK) % workers].get()
            if isinstance(item, BaseException):
                raise item
            if item is _END:  # that worker's video ended before frame i
                yield i, False, None, 0.0
                return
            index, ok, frame, ms = item
            if index != i:  # cannot happen: each worker delivers its chunks in order
                raise RuntimeError(f"parallel decode delivered frame {index} for frame {i}")
            yield i, ok, frame, ms
            if not ok:
                return
    finally:
        halt.set()
        for t in threads:
            t.join(timeout=5.0)


def frame_items(open_capture: Any, count: int, workers: int | None = None) -> Iterator[Any]:
    """The items of :func:`parallel_frames` for a video's first ``count`` frames: a Motion-JPEG video's packets
    decoded by ``workers`` threads (default :func:`wptrack.io.jpeg.jpeg_workers`; :func:`wptrack.io.jpeg.jpeg_frames`);
    another video decoded by ``workers`` captures (default :func:`decode_workers`) when it is more than one, the video
    long enough and its codec intra-only, else by one capture in this thread (:func:`read_sequential`). The captures
    are released when the iteration ends or is closed."""
    cap = open_capture()
    if isinstance(cap, JpegCapture):  # Motion-JPEG packets: decoded by threads at once, read by this one
        if workers is None:  # within a batch worker's decoding budget
            workers = min(jpeg_workers(), decode_threads() or jpeg_workers())
        try:
            yield from jpeg_frames(cap, count, workers) if workers > 1 else read_sequential(cap, count)
        finally:
            cap.release()
        return
    workers = decode_workers() if workers is None else workers
    if workers > 1 and count >= 2 * CHUNK and fourcc(cap).upper() in INTRA_CODECS:  # OpenCV's FFV1 says "ffv1"
        cap.release()
        yield from parallel_frames(open_capture, count, workers)
        return
    try:
        yield from read_sequential(cap, count)
    finally:
        cap.release()


def read_sequential(cap: Any, count: int) -> Iterator[tuple[int, bool, np.ndarray | None, float]]:
    """The same items as :func:`parallel_frames` from one opened capture, in this thread."""
    import cv2

    for i in range(count):
        ok, frame = cap.read()
        ok = bool(ok and frame is not None)
        yield i, ok, frame, cap.get(cv2.CAP_PROP_POS_MSEC) if ok else 0.0
        if not ok:
            return
