"""Movie encoding: ``movie.mp4`` (MPEG-4 via OpenCV, for players and download) and, for the page, ``movie.webm``
(VP8/VP9 via OpenCV's FFmpeg, which browsers play) or, where no WebM encoder is available, an animated
``movie.gif`` (Pillow). No network-installed encoder is needed."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.errors import WptrackError
from wptrack.io.atomic import atomic_path, commit, discard, temp_path

log = logging.getLogger(__name__)

WEBM_CODECS = ("VP80", "VP90")
"""WebM codecs tried in order (VP8 encodes about three times faster than VP9 here)."""


@dataclass
class MovieFiles:
    """What :func:`encode_movie` wrote (paths in the output folder, or None).

    Attributes:
        mp4: MPEG-4 Part 2 file (plays in VLC/mpv/QuickTime; not in browsers).
        web: The file for the page: ``movie.webm`` or ``movie.gif``.
        frames: Frames encoded.
        notes: What could not be written.
    """

    mp4: Path | None = None
    web: Path | None = None
    frames: int = 0
    notes: list[str] = field(default_factory=list)


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Silence C-level stderr (FFmpeg prints codec-tag notices there) for the duration of the block."""
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        yield
        return
    sys.stderr.flush()
    saved = os.dup(fd)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), fd)
            try:
                yield
            finally:
                os.dup2(saved, fd)
    finally:
        os.close(saved)


class _WebmWriter:
    """A WebM writer (VP9, else VP8) on a temporary name, renamed on close."""

    def __init__(self, path: Path, fps: float, size: tuple[int, int]) -> None:
        import cv2

        self.path = path
        self.tmp = temp_path(path)
        self.writer: Any = None
        self.codec: str | None = None
        for codec in WEBM_CODECS:
            with _quiet_stderr():
                w = cv2.VideoWriter(str(self.tmp), cv2.VideoWriter_fourcc(*codec), fps, size)
            if w.isOpened():
                self.writer, self.codec = w, codec
                break
            w.release()
        if self.writer is None:
            discard(self.tmp)

    @property
    def ok(self) -> bool:
        return self.writer is not None

    def write(self, bgr: np.ndarray) -> None:
        self.writer.write(np.ascontiguousarray(bgr))

    def close(self, keep: bool) -> Path | None:
        if self.writer is None:
            return None
        with _quiet_stderr():
            self.writer.release()
        if keep and self.tmp.exists() and self.tmp.stat().st_size > 0:
            commit(self.tmp, self.path)
            return self.path
        discard(self.tmp)
        return None


def encode_movie(frames: Iterable[np.ndarray], out_dir: Path, fps: float, stem: str = "movie") -> MovieFiles:
    """Encode RGB frames to ``{stem}.mp4`` and ``{stem}.webm`` (or ``{stem}.gif``), streaming.

    Args:
        frames: (H, W, 3) uint8 RGB frames, all the same size (even sizes suit every encoder).
        out_dir: Output folder.
        fps: Frames per second.
        stem: File name stem.

    Returns:
        The files written and notes about those that could not be.
    """
    from wptrack.io.video import VideoWriter

    out = MovieFiles()
    mp4: VideoWriter | None = None
    webm: _WebmWriter | None = None
    gif_frames: list[Any] = []
    ok = False
    try:
        for rgb in frames:
            bgr = np.ascontiguousarray(rgb[..., 2::-1])
            if out.frames == 0:
                size = (bgr.shape[1], bgr.shape[0])
                try:
                    mp4 = VideoWriter(out_dir / f"{stem}.mp4", fps=fps, size=size)
                except WptrackError as e:
                    out.notes.append(f"no MP4 encoder ({e})")
                webm = _WebmWriter(out_dir / f"{stem}.webm", fps, size)
                if not webm.ok:
                    out.notes.append("no WebM encoder: the page shows an animated GIF")
            if mp4 is not None:
                mp4.write(bgr)
            if webm is not None and webm.ok:
                webm.write(bgr)
            else:
                gif_frames.append(_to_palette(rgb))
            out.frames += 1
        ok = True
    finally:
        if mp4 is not None:
            if ok:
                out.mp4 = mp4.close()
            else:
                mp4.abort()
        if webm is not None:
            out.web = webm.close(ok)
    if ok and gif_frames:
        out.web = _write_gif(gif_frames, out_dir / f"{stem}.gif", fps)
    return out


def _to_palette(rgb: np.ndarray) -> Any:
    from PIL import Image

    return Image.fromarray(np.ascontiguousarray(rgb[..., :3])).quantize(colors=128, method=Image.Quantize.MEDIANCUT)


def _write_gif(images: list[Any], path: Path, fps: float) -> Path:
    with atomic_path(path) as tmp:
        images[0].save(
            tmp, format="GIF", save_all=True, append_images=images[1:], duration=int(round(1000 / fps)), loop=0
        )
    return path


def add_movie_figures(sec: Any, files: MovieFiles, fps: float, total: int) -> None:
    """Attach an encoded movie to a report section: its notes, a note when frames were skipped, and the web
    video/animation (with the MP4 as an alternate) or the MP4 alone."""
    from wptrack.report.model import Figure

    sec.notes.extend(files.notes)
    if files.frames < total:
        sec.notes.append(f"{files.frames} of {total} frames shown (evenly spaced)")
    alternates = (files.mp4.name,) if files.mp4 is not None else ()
    if files.web is not None:
        kind = "video" if files.web.suffix == ".webm" else "image"
        sec.figures.append(Figure(files.web.name, f"{files.frames} frames at {fps:g} fps", kind, alternates))
    elif files.mp4 is not None:
        sec.figures.append(Figure(files.mp4.name, f"{files.frames} frames (MP4)", "video"))
