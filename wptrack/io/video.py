"""Writing videos: :class:`VideoWriter` (lossless FFV1 for masks, MJPG/MP4 by suffix; written to a temporary file and
renamed into place when closed), :func:`continue_video` (a resumed run goes on writing one file) and
:func:`write_video`."""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError, OutputError
from wptrack.io.atomic import commit, discard, temp_path
from wptrack.io.frames import _to_bgr

log = logging.getLogger(__name__)


#: Codecs tried, in order, per output video extension (the first one whose writer opens is used).
VIDEO_CODECS: dict[str, tuple[str, ...]] = {
    ".avi": ("FFV1", "MJPG"),
    ".mkv": ("FFV1", "MJPG", "mp4v"),
    ".mp4": ("mp4v", "avc1"),
    ".mov": ("mp4v", "MJPG"),
}


class VideoWriter:
    """Write frames to a video file, atomically, with a lossless codec where possible.

    The codec is chosen by extension (:data:`VIDEO_CODECS`): ``.avi`` tries FFV1 (lossless) then MJPG;
    ``.mkv`` FFV1, MJPG, mp4v; ``.mp4`` mp4v then avc1; ``.mov`` mp4v then MJPG. Frames are written to a hidden
    temporary file in the same folder, renamed to ``path`` by :meth:`close`; leaving the ``with`` block by an
    exception (including Ctrl-C) deletes the temporary file, so no broken video is left behind. If no frame
    was written, no file is created.

    Args:
        path: Output video path.
        fps: Frames per second (> 0).
        size: ``(width, height)`` in pixels; ``None`` takes it from the first frame.

    Attributes:
        codec: The FOURCC in use (``None`` until the writer is opened).
        frames_written: Number of frames written so far.

    Raises:
        OutputError: Unsupported extension, missing output folder, or no codec could be opened.
    """

    def __init__(self, path: str | os.PathLike, fps: float = 25.0, size: tuple[int, int] | None = None) -> None:
        self.path = Path(path)
        ext = self.path.suffix.lower()
        if ext not in VIDEO_CODECS:
            raise OutputError(f"cannot write video {self.path}: unsupported extension (use {', '.join(VIDEO_CODECS)})")
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
        tried = []
        for fourcc in VIDEO_CODECS[self.path.suffix.lower()]:
            writer = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*fourcc), self.fps, self.size)
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
        frame = _to_bgr(frame)
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
        if self._writer is not None:
            self._writer.release()
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
            self._writer.release()
        self._remove_tmp()

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def continue_video(path: str | os.PathLike, keep: int, fps: float = 25.0) -> VideoWriter:
    """A :class:`VideoWriter` for ``path`` that starts with the first ``keep`` frames of the video already there, for
    a resumed run: it goes on writing one file, as an uninterrupted run does, and the old file is replaced only
    when the new one is closed (atomic, see :class:`VideoWriter`). The frames are decoded and encoded again
    (exact with the lossless FFV1 codec).

    When ``path`` holds fewer than ``keep`` frames (missing, or a run killed before it closed the video), the
    missing frames are written black (with a warning), so frame ``i`` of the video stays frame ``i`` of the run.

    Args:
        path: The video (``.avi``...).
        keep: Frames of the existing video to copy first (the frames before the resume point).
        fps: Frames per second.
    """
    writer = VideoWriter(path, fps=fps)
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
