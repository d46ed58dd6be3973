"""Writing videos: :class:`VideoWriter` (lossless FFV1, MJPG/MP4 by suffix, or an AVI of PNG images encoded by several
threads for masks (:mod:`wptrack.io.avi`); written to a temporary file and renamed into place when closed; one grey
channel for masks), :class:`BackgroundWriter` (the encoding in a thread of its own, behind a bounded queue),
:func:`continue_video` (a resumed run goes on writing one file) and :func:`write_video`."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError, OutputError
from wptrack.io.atomic import FinishOnExit, commit, discard, temp_path
from wptrack.io.frames import _to_bgr

log = logging.getLogger(__name__)


#: Codecs tried, in order, per output video extension (the first one whose writer opens is used).
VIDEO_CODECS: dict[str, tuple[str, ...]] = {
    ".avi": ("FFV1", "MJPG"),
    ".mkv": ("FFV1", "MJPG", "mp4v"),
    ".mp4": ("mp4v", "avc1"),
    ".mov": ("mp4v", "MJPG"),
}

PNG_CODEC_NAMES = frozenset({"PNG", "MPNG"})
"""Values of :class:`VideoWriter`'s ``codec`` that select the AVI of PNG images (:class:`wptrack.io.avi.PngAviWriter`,
FOURCC ``MPNG``): lossless, encoded by several threads (a 1920x1080 mask: ~3 ms a thread instead of FFV1's 19 ms in
one)."""


class VideoWriter(FinishOnExit):
    """Write frames to a video file, atomically, with a lossless codec where possible.

    The codec is chosen by extension (:data:`VIDEO_CODECS`): ``.avi`` tries FFV1 (lossless) then MJPG;
    ``.mkv`` FFV1, MJPG, mp4v; ``.mp4`` mp4v then avc1; ``.mov`` mp4v then MJPG. ``codec="PNG"`` (``.avi`` only)
    writes PNG images instead, encoded by a pool of threads (:class:`wptrack.io.avi.PngAviWriter`, FOURCC ``MPNG``;
    lossless, read by OpenCV as any AVI): the masks' writer, where FFV1's one encoding thread was the bottleneck.
    Frames are written to a hidden temporary file in the same folder, renamed to ``path`` by :meth:`close`; leaving
    the ``with`` block by an exception (including Ctrl-C) deletes the temporary file, so no broken video is left
    behind. If no frame was written, no file is created.

    Args:
        path: Output video path.
        fps: Frames per second (> 0).
        size: ``(width, height)`` in pixels; ``None`` takes it from the first frame.
        grey: Write one grey channel (``(H, W)`` frames; a BGR frame is converted): for masks, a third of the
            encoding work of BGR with FFV1 (1440x1080 mask: 8 instead of 30 ms of CPU per frame on the CI machine);
            readers get the grey values in all three channels back.
        codec: ``None``: by extension (above); ``"PNG"`` (or ``"MPNG"``): an AVI of PNG images
            (:data:`PNG_CODEC_NAMES`).
        bilevel: With ``codec="PNG"`` and ``grey``: 1-bit PNG images, for masks whose values are 0 and 255 only (the
            caller's contract: a frame with other values makes the writer fail, see
            :class:`wptrack.io.avi.PngAviWriter`); read back as 0 and 255.

    Attributes:
        codec: The FOURCC in use (``None`` until the writer is opened; ``"MPNG"`` with ``codec="PNG"``).
        frames_written: Number of frames written so far.

    Raises:
        ConfigError: An unknown ``codec``, ``"PNG"`` for another extension than ``.avi``, or ``bilevel`` without
            ``codec="PNG"`` and ``grey``.
        OutputError: Unsupported extension, missing output folder, or no codec could be opened.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        fps: float = 25.0,
        size: tuple[int, int] | None = None,
        grey: bool = False,
        codec: str | None = None,
        bilevel: bool = False,
    ) -> None:
        self.path = Path(path)
        self.grey = bool(grey)
        ext = self.path.suffix.lower()
        if ext not in VIDEO_CODECS:
            raise OutputError(f"cannot write video {self.path}: unsupported extension (use {', '.join(VIDEO_CODECS)})")
        self.png = codec is not None and codec.upper() in PNG_CODEC_NAMES
        if codec is not None and not self.png:
            raise ConfigError(f"video codec must be None or 'PNG', got {codec!r}")
        if self.png and ext != ".avi":
            raise ConfigError(f"cannot write video {self.path} with PNG images: only to an .avi file")
        self.bilevel = bool(bilevel)
        if self.bilevel and not (self.png and self.grey):
            raise ConfigError(f"video {self.path}: bilevel frames need codec='PNG' and grey=True")
        if not fps or fps <= 0:
            raise ConfigError(f"video fps must be > 0, got {fps}")
        if not self.path.parent.is_dir():
            raise OutputError(f"cannot write video {self.path}: folder {self.path.parent} does not exist")
        self.fps = float(fps)
        self.size = tuple(int(v) for v in size) if size is not None else None
        self.codec: str | None = None
        self.frames_written = 0
        self._tmp = temp_path(self.path)
        self._writer: Any = None
        self._closed = False
        self._blank_pending = 0
        if self.size is not None:
            self._open()

    def _open(self) -> None:
        import cv2

        assert self.size is not None
        if self.png:
            from wptrack.io.avi import PNG_FOURCC, PngAviWriter

            self._writer = PngAviWriter(self._tmp, self.fps, self.size, bilevel=self.bilevel)
            self.codec = PNG_FOURCC
            log.debug("writing %s with PNG images (%dx%d @ %g fps)", self.path, *self.size, self.fps)
            return
        tried = []
        for fourcc in VIDEO_CODECS[self.path.suffix.lower()]:
            writer = cv2.VideoWriter(
                str(self._tmp), cv2.VideoWriter_fourcc(*fourcc), self.fps, self.size, not self.grey
            )
            if writer.isOpened():
                self._writer, self.codec = writer, fourcc
                log.debug("writing %s with codec %s (%dx%d @ %g fps)", self.path, fourcc, *self.size, self.fps)
                return
            writer.release()
            tried.append(fourcc)
        self._remove_tmp()
        raise OutputError(f"cannot write video {self.path}: no codec available (tried {', '.join(tried)})")

    def write(self, frame: np.ndarray) -> None:
        """Append one frame.

        Args:
            frame: ``(H, W, 3)`` uint8 BGR or ``(H, W)`` uint8 grayscale, of the writer's size.
        """
        if self._closed:
            raise RuntimeError(f"video writer for {self.path} is closed")
        frame = np.asarray(frame)
        if frame.dtype != np.uint8:
            raise ValueError(f"video frames must be uint8, got {frame.dtype}")
        frame = _to_grey(frame) if self.grey else _to_bgr(frame)
        h, w = frame.shape[:2]
        if self.size is None:
            self.size = (w, h)
            self._open()
        if (w, h) != self.size:
            raise ValueError(f"frame of {w}x{h} pixels written to video {self.path} of {self.size[0]}x{self.size[1]}")
        while self._blank_pending > 0:  # frames missing before a resume point (continue_video), once the size is known
            self._writer.write(np.zeros_like(frame))
            self.frames_written += 1
            self._blank_pending -= 1
        self._writer.write(np.ascontiguousarray(frame))
        self.frames_written += 1

    def flush(self) -> None:
        """Have every frame written so far encoded (the PNG writer's frames in flight; OpenCV's writers encode as
        they go). An error encoding a frame is raised here."""
        if self.png and self._writer is not None and not self._closed:
            self._writer.flush()

    def _release(self) -> None:
        """Finish the encoder's file (the PNG writer: encode the frames in flight, write the index; an error encoding
        a frame is raised here)."""
        if self._writer is None:
            return
        if self.png:
            self._writer.close()
        else:
            self._writer.release()

    def _remove_tmp(self) -> None:
        discard(self._tmp)

    def close(self) -> Path | None:
        """Finish the file and rename it into place (idempotent).

        Returns:
            The written path, or None when no frame was written (nothing is created then).
        """
        if self._closed:
            return self.path if self.path.exists() and self.frames_written else None
        self._closed = True
        try:
            self._release()
        except BaseException:
            self._remove_tmp()
            raise
        if self.frames_written == 0:
            self._remove_tmp()
            log.warning("no frames written to %s; no video created", self.path)
            return None
        commit(self._tmp, self.path)
        log.info("wrote %s (%d frames, %s)", self.path, self.frames_written, self.codec)
        return self.path

    def abort(self) -> None:
        """Stop writing and delete the temporary file (``path`` is left untouched)."""
        if self._closed:
            return
        self._closed = True
        if self._writer is not None:
            if self.png:
                self._writer.abort()
            else:
                self._writer.release()
        self._remove_tmp()


def _to_grey(frame: np.ndarray) -> np.ndarray:
    if frame.ndim == 2:
        return frame
    if frame.ndim == 3 and frame.shape[2] == 1:
        return frame[..., 0]
    import cv2

    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)


class BackgroundWriter(FinishOnExit):
    """A video writer whose frames are prepared and encoded by a thread of its own, behind a bounded queue, so a
    run's frame loop does not wait for the encoder (FFV1 at 1440x1080: 57 ms of CPU per BGR frame on the CI
    machine, more than a frame of tracking).

    :meth:`write` hands a frame (and an optional ``prepare`` function run in the writer thread, e.g. colouring a
    label image) to the queue; when ``depth`` frames are waiting it blocks (time recorded as ``wait_<stage>`` in
    the run's timeline), so memory stays bounded at ``depth + 1`` frames whatever the encoder's speed.
    :meth:`flush` returns once every frame handed over is encoded (a checkpoint then describes the video as
    written), :meth:`close` flushes and closes the file (renamed into place: atomic, as :class:`VideoWriter`),
    :meth:`abort` drops what is queued and deletes the temporary file. An error of the writer thread is raised by
    the next :meth:`write`, :meth:`flush` or :meth:`close`.

    Args:
        writer: The :class:`VideoWriter` (or any object with ``write``, ``close``, ``abort``) it feeds; opened
            already (e.g. by :func:`continue_video`).
        depth: Frames queued at most.
        stage: The timeline stage of the encoding (:mod:`wptrack.io.timeline`), e.g. ``write_virtual``.
    """

    _END = object()

    def __init__(self, writer: Any, depth: int = 8, stage: str = "write_video") -> None:
        import queue
        import threading

        if depth < 1:
            raise ValueError(f"writer queue depth must be >= 1, got {depth}")
        self.writer = writer
        self.path = getattr(writer, "path", None)
        self.stage = stage
        self.depth = int(depth)
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._error: BaseException | None = None
        self._failed = False  # an encoding error happened: close() then deletes the file instead of keeping it
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=f"wptrack-{stage}", daemon=True)
        self._thread.start()

    @property
    def frames_written(self) -> int:
        return int(getattr(self.writer, "frames_written", 0))

    def _run(self) -> None:
        from wptrack.io import timeline

        with timeline.thread_cpu(self.stage):
            self._encode()

    def _encode(self) -> None:
        import time

        from wptrack.io import timeline

        while True:
            item = self._queue.get()
            try:
                if item is self._END:
                    return
                if self._failed or self._error is not None:
                    continue  # drain: after an error (raised in the caller) or an abort nothing more is written
                frame, prepare = item
                t0 = time.perf_counter()
                try:
                    self.writer.write(prepare(frame) if prepare is not None else frame)
                except BaseException as e:  # noqa: BLE001 - raised by the caller's next call
                    self._error = e
                    self._failed = True
                timeline.record(self.stage, time.perf_counter() - t0)
            finally:
                self._queue.task_done()

    def _raise(self) -> None:
        if self._error is not None:
            error, self._error = self._error, None
            raise error

    def write(self, frame: np.ndarray, prepare: Any = None) -> None:
        """Queue one frame (``prepare(frame)`` is what gets written, computed in the writer thread). The frame must
        not be changed by the caller afterwards (hand over a copy of a reused buffer)."""
        import queue
        import time

        from wptrack.io import timeline

        if self._closed:
            raise RuntimeError(f"video writer for {self.path} is closed")
        self._raise()
        try:
            self._queue.put_nowait((frame, prepare))
        except queue.Full:
            t0 = time.perf_counter()
            self._queue.put((frame, prepare))
            timeline.record(timeline.WAIT_PREFIX + self.stage, time.perf_counter() - t0)

    def flush(self) -> None:
        """Wait until every queued frame is encoded (the writer's own frames in flight too: its ``flush``, called
        here while the writer thread waits for the next frame)."""
        if not self._closed:
            self._queue.join()
        self._raise()
        flush = getattr(self.writer, "flush", None)
        if flush is not None and not self._closed and not self._failed:
            try:
                flush()
            except BaseException:
                self._failed = True  # close() deletes the file
                raise

    def _stop(self) -> None:
        self._closed = True
        self._queue.put(self._END)
        self._thread.join()

    def close(self) -> Path | None:
        """Encode what is queued and close the file (see :meth:`VideoWriter.close`; idempotent). After an encoding
        error the file is deleted instead (nothing half-written), and the error is raised unless the caller has had
        it already."""
        if not self._closed:
            self._stop()
        if self._failed:
            self.writer.abort()
            self._raise()
            log.warning("%s not written: its encoding failed", self.path)
            return None
        return self.writer.close()

    def abort(self) -> None:
        """Drop the queued frames and delete the temporary file."""
        if not self._closed:
            self._error = self._error or RuntimeError("aborted")  # the thread drops what is left
            self._stop()
        self._error = None
        self.writer.abort()


def continue_video(
    path: str | os.PathLike,
    keep: int,
    fps: float = 25.0,
    grey: bool = False,
    codec: str | None = None,
    bilevel: bool = False,
) -> VideoWriter:
    """A :class:`VideoWriter` for ``path`` that starts with the first ``keep`` frames of the video already there, for
    a resumed run: it goes on writing one file, as an uninterrupted run does, and the old file is replaced only
    when the new one is closed (atomic, see :class:`VideoWriter`). The frames are decoded and encoded again
    (exact with the lossless codecs: FFV1, PNG).

    When ``path`` holds fewer than ``keep`` frames (missing, or a run killed before it closed the video), the
    missing frames are written black (with a warning), so frame ``i`` of the video stays frame ``i`` of the run.

    Args:
        path: The video (``.avi``...).
        keep: Frames of the existing video to copy first (the frames before the resume point).
        fps: Frames per second.
        grey: One grey channel (:class:`VideoWriter`).
        codec: ``None`` (by extension) or ``"PNG"`` (:class:`VideoWriter`): the new file's codec, whatever the old
            one's.
        bilevel: 1-bit PNG images, for 0/255 masks (:class:`VideoWriter`); the old frames are taken as masks (grey
            values above 127 written 255, the others 0: exact for the 0/255 frames of a lossless masks video).
    """
    writer = VideoWriter(path, fps=fps, grey=grey, codec=codec, bilevel=bilevel)
    copied = 0
    target = Path(path)
    if keep > 0 and target.exists():
        import cv2

        cap = cv2.VideoCapture(str(target))
        try:
            while copied < keep:
                ok, frame = cap.read()
                if not ok:
                    break
                if bilevel:  # 0/255 whatever the old codec (an MJPG fallback's masks are not exactly 0/255)
                    frame = cv2.threshold(_to_grey(frame), 127, 255, cv2.THRESH_BINARY)[1]
                writer.write(frame)
                copied += 1
        finally:
            cap.release()
    if copied < keep:
        log.warning(
            "%s: %d of the %d frames before the resume point were found; the other %d are written black",
            target,
            copied,
            keep,
            keep - copied,
        )
        writer._blank_pending = keep - copied
    return writer


def write_video(path: str | os.PathLike, frames: Iterable[np.ndarray], fps: float = 25.0) -> Path | None:
    """Write frames to a video file (see :class:`VideoWriter` for codecs and atomicity).

    Args:
        path: Output path (``.avi``, ``.mkv``, ``.mp4`` or ``.mov``).
        frames: ``(H, W, 3)`` uint8 BGR (or ``(H, W)`` grayscale) frames, all the same size.
        fps: Frames per second.

    Returns:
        The written path, or None when ``frames`` was empty.
    """
    with VideoWriter(path, fps=fps) as writer:
        for frame in frames:
            writer.write(frame)
    return writer.path if writer.frames_written else None
