"""Lossless frames (motion masks) as an AVI of PNG images, encoded by several threads: :class:`PngAviWriter`.

OpenCV's FFV1 encoder runs in one thread (a 1920x1080 mask: 19 ms on a GPU host, which bounded ``wptrack masks``
at ~52 frames/s). A PNG image of a mask (``cv2.imencode``, compression level 1; a 1-bit image for 0/255 masks) costs
~3 ms, is lossless, a few KB, and ``cv2.imencode`` releases the GIL, so several threads encode frames at once. The
frames go, in order, into an AVI file written here (RIFF, one video stream, FOURCC ``MPNG``, every frame a keyframe,
an ``idx1`` index), which OpenCV's FFmpeg reader decodes exactly (frame count, rate and ``CAP_PROP_POS_FRAMES`` seeks
included, ``tests/test_avi.py``).

Layout (as FFmpeg's ``libavformat/avienc.c`` writes it)::

    RIFF 'AVI '
        LIST 'hdrl'
            'avih'                      main header (frames of the first RIFF, size, largest frame)
            LIST 'strl'
                'strh'                  stream header ('vids', 'MPNG', rate / scale, frames in all, largest frame)
                'strf'                  BITMAPINFOHEADER (biCompression 'MPNG')
                'indx' (else 'JUNK')    OpenDML super index: one entry per RIFF, pointing at its 'ix00'
            LIST 'odml' (else 'JUNK')   'dmlh': frames in all
        LIST 'movi'
            '00dc' ...                  one PNG image per chunk
            'ix00'                      OpenDML standard index of this RIFF (only when there are several)
        'idx1'                          AVI 1.0 index of the first RIFF's frames
    RIFF 'AVIX'                         (OpenDML, AVI 2.0: a file larger than ``segment_bytes``)
        LIST 'movi'
            '00dc' ...
            'ix00'
    ...

A RIFF's sizes are 32-bit, so an AVI 1.0 file ends at 4 GiB (and many readers stop at 1 or 2 GiB); past
``segment_bytes`` (1 GiB by default, as FFmpeg) the file goes on in ``AVIX`` RIFFs, each indexed by an ``ix00``
chunk that the super index in the header points at (the OpenDML extension). A file of one RIFF is plain AVI 1.0: the
super index and the ``odml`` list stay ``JUNK`` chunks.

The writer streams: chunks go to the file as their frames are encoded, only the index entries are kept (8 bytes a
frame), and :meth:`PngAviWriter.close` goes back to fill in the header's counts and sizes.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import struct
import sys
from array import array
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor
from fractions import Fraction
from pathlib import Path
from typing import BinaryIO

import numpy as np

from wptrack.core.errors import ConfigError, OutputError
from wptrack.io.atomic import FinishOnExit

log = logging.getLogger(__name__)

PNG_FOURCC = "MPNG"
"""The FOURCC of the video stream (FFmpeg reads it as PNG)."""

PNG_WORKERS_ENV = "WPTRACK_PNG_WORKERS"
"""Environment variable: threads encoding one video's PNG frames at once (default :func:`png_workers`)."""

PNG_COMPRESSION = 1
"""zlib level of the PNG frames (1: fastest; a 1920x1080 mask is a few KB whatever the level)."""

SEGMENT_BYTES = 1 << 30
"""Default size (bytes) past which the file goes on in a new RIFF (OpenDML), as FFmpeg's AVI muxer."""

MAX_SEGMENT_BYTES = 1 << 31
"""Largest ``segment_bytes`` allowed: a RIFF's size is 32-bit (and some readers take it as signed)."""

SUPER_INDEX_ENTRIES = 256
"""RIFFs a file may have (entries reserved in the OpenDML super index): 256 GiB with the default segment size."""

_FLAGS = 0x10 | 0x100 | 0x800  # AVIF_HASINDEX | AVIF_ISINTERLEAVED | AVIF_TRUSTCKTYPE, as FFmpeg
_KEYFRAME = 0x10  # AVIIF_KEYFRAME
_CHUNK_ID = b"00dc"
_INDX_BYTES = 24 + 16 * SUPER_INDEX_ENTRIES  # 'indx' chunk body
_DMLH_BYTES = 248  # 'dmlh' chunk body (FFmpeg's size: dwTotalFrames and reserved space)
_IX_HEADER = 24  # 'ix00' chunk body before its entries


def png_workers() -> int:
    """Threads encoding one video's PNG frames: :data:`PNG_WORKERS_ENV` when set, else one per 2 host cores, at
    most 4 (one on a 2-core machine: it encodes while the calling thread goes on)."""
    from wptrack.core.config import env_count, host_cores

    return env_count(PNG_WORKERS_ENV, max(1, min(4, host_cores() // 2)))


def encode_png(frame: np.ndarray, bilevel: bool, compression: int = PNG_COMPRESSION) -> bytes:
    """One frame as a PNG image (run in the writer's threads: OpenCV releases the GIL).

    Args:
        frame: ``(H, W)`` uint8 grey or ``(H, W, 3)`` uint8 BGR.
        bilevel: A 1-bit image; ``frame`` must be grey with values 0 and 255 only (checked: ``ValueError``), which
            come back as 0 and 255.
        compression: zlib level (0-9).

    Raises:
        ValueError: A bilevel frame that is not grey or has other values, or OpenCV could not encode it.
    """
    import cv2

    params = [cv2.IMWRITE_PNG_COMPRESSION, int(compression)]
    if bilevel:
        if frame.ndim != 2:
            raise ValueError(f"a bilevel PNG frame must be grey (H, W), got shape {frame.shape}")
        if cv2.countNonZero(cv2.inRange(frame, 1, 254)):  # ~0.5 ms at 1920x1080, GIL released
            raise ValueError("a bilevel PNG frame must hold only the values 0 and 255")
        params += [cv2.IMWRITE_PNG_BILEVEL, 1]
    ok, buf = cv2.imencode(".png", frame, params)
    if not ok:
        raise ValueError(f"OpenCV could not encode a {frame.shape} frame as PNG")
    return buf.tobytes()


def _rate(fps: float) -> tuple[int, int]:
    """``(rate, scale)`` of the stream header: ``fps`` as a fraction ``rate / scale`` of 32-bit integers."""
    limit = 1001000
    while True:
        q = Fraction(fps).limit_denominator(limit)
        if q.numerator <= 0xFFFFFFFF or limit == 1:
            break
        limit //= 10
    if q <= 0 or q.numerator > 0xFFFFFFFF:
        raise ConfigError(f"video fps {fps} cannot be written to an AVI header")
    return q.numerator, q.denominator


def _u32(values: array) -> bytes:
    """An ``array('I')`` as little-endian 32-bit words."""
    if sys.byteorder == "little":
        return values.tobytes()
    swapped = array("I", values)
    swapped.byteswap()
    return swapped.tobytes()


class PngAviWriter(FinishOnExit):
    """Write frames to an AVI file as PNG images (FOURCC ``MPNG``), encoded by a thread pool, in order.

    :meth:`write` copies the frame and hands it to a pool of ``workers`` threads; at most ``in_flight`` frames are
    waiting or being encoded (when that many are, it waits for the oldest), and the encoded frames are written to the
    file in the order they were given, by the thread that calls :meth:`write` / :meth:`close`. So memory stays
    bounded and only the index (8 bytes a frame) grows with the video. An error encoding a frame (e.g. a bilevel frame
    with a value other than 0 and 255) is raised by the next :meth:`write`, :meth:`flush` or :meth:`close`; the file
    is then deleted. :meth:`flush` writes the frames in flight; :meth:`close` encodes what is left and finishes the
    file; :meth:`abort` drops it and deletes the file.

    The file is written at ``path`` itself (for an atomic write, give a temporary path and rename it after
    :meth:`close`: :class:`wptrack.io.video.VideoWriter` does).

    Args:
        path: Output file (created or replaced).
        fps: Frames per second (> 0); written as a fraction ``rate / scale`` (e.g. 29.97 as 2997/100).
        size: ``(width, height)`` of every frame.
        bilevel: 1-bit PNG images: every frame must be grey ``(H, W)`` with values 0 and 255 only (the caller's
            contract, checked per frame by the encoder), e.g. motion masks; they are read back as 0 and 255.
            Otherwise 8-bit grey ``(H, W)`` or BGR ``(H, W, 3)`` images, read back exactly.
        workers: Encoding threads (``None``: :func:`png_workers`).
        in_flight: Frames waiting or being encoded at most (``None``: twice ``workers``).
        segment_bytes: Size (bytes) of a RIFF past which the file goes on in a new one (OpenDML; default 1 GiB,
            at most 2 GiB); a RIFF holds at least one frame.
        compression: zlib level of the PNG images (0-9).

    Attributes:
        frames: Frames written to the file so far (encoded and in place).
        segments: RIFFs in the file (1 for a plain AVI 1.0 file).

    Raises:
        ConfigError: A bad fps, size or option.
        OutputError: ``path`` cannot be written.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        fps: float,
        size: tuple[int, int],
        *,
        bilevel: bool = False,
        workers: int | None = None,
        in_flight: int | None = None,
        segment_bytes: int = SEGMENT_BYTES,
        compression: int = PNG_COMPRESSION,
    ) -> None:
        self.path = Path(path)
        if not math.isfinite(float(fps)) or float(fps) <= 0:
            raise ConfigError(f"video fps must be > 0, got {fps}")
        self.fps = float(fps)
        self._rate, self._scale = _rate(self.fps)
        width, height = (int(v) for v in size)
        if width <= 0 or height <= 0:
            raise ConfigError(f"video size must be positive, got {width}x{height}")
        self.size = (width, height)
        if not 1 <= int(segment_bytes) <= MAX_SEGMENT_BYTES:
            raise ConfigError(f"segment_bytes must be in [1, {MAX_SEGMENT_BYTES}], got {segment_bytes}")
        if not 0 <= int(compression) <= 9:
            raise ConfigError(f"PNG compression must be in [0, 9], got {compression}")
        self.bilevel = bool(bilevel)
        self.compression = int(compression)
        self.segment_bytes = int(segment_bytes)
        self.workers = max(1, int(workers)) if workers is not None else png_workers()
        self.in_flight = max(1, int(in_flight)) if in_flight is not None else 2 * self.workers
        self.frames = 0
        self.segments = 1
        self._encode = encode_png  # looked up here, so a test can replace the module's function
        self._pending: deque[Future] = deque()
        self._error: BaseException | None = None
        self._closed = False
        self._finished = False  # closed with the file complete
        self._max_chunk = 0
        self._first_frames = 0  # frames of the first RIFF (known once it ends)
        self._super: list[tuple[int, int, int]] = []  # (offset of 'ix00', its size, its frames) per finished RIFF
        self._ix = array("I")  # (data offset from the movi list, size) per frame of the current RIFF
        try:
            self._file: BinaryIO = open(self.path, "wb", buffering=1 << 20)  # closed by close() or abort()
        except OSError as e:
            raise OutputError(f"cannot write video {self.path}: {e.strerror or e}") from e
        self._pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="wptrack-png")
        try:
            header = b"RIFF" + bytes(4) + b"AVI " + self._hdrl()
            self._file.write(header)
            self._pos = len(header)
            self._riff_start = 0
            self._begin_movi()
        except OSError as e:
            self._drop()
            raise OutputError(f"cannot write video {self.path}: {e.strerror or e}") from e

    # ------------------------------------------------------------------------------------------------ header

    def _hdrl(self) -> bytes:
        """The ``LIST hdrl`` (same length whatever the counts: rewritten in place by :meth:`close`)."""
        w, h = self.size
        odml = len(self._super) > 1
        total = self.frames
        first = self._first_frames if odml else total
        largest = self._max_chunk
        per_second = min(0xFFFFFFFF, math.ceil(largest * self.fps))
        us_per_frame = min(0xFFFFFFFF, round(1e6 / self.fps))
        avih = struct.pack("<14I", us_per_frame, per_second, 0, _FLAGS, first, 0, 1, largest, w, h, 0, 0, 0, 0)
        strh = struct.pack(
            "<4s4sIHHIIIIIIIIhhhh",
            b"vids",
            PNG_FOURCC.encode(),
            0,  # flags
            0,  # priority
            0,  # language
            0,  # initial frames
            self._scale,
            self._rate,
            0,  # start
            total,  # length (frames)
            largest,  # suggested buffer size
            0xFFFFFFFF,  # quality: default
            0,  # sample size: variable
            0,
            0,
            min(w, 0x7FFF),
            min(h, 0x7FFF),
        )
        fourcc = struct.unpack("<I", PNG_FOURCC.encode())[0]
        strf = struct.pack("<IiiHHIIiiII", 40, w, h, 1, 24, fourcc, min(0xFFFFFFFF, w * h * 3), 0, 0, 0, 0)
        entries = b"".join(struct.pack("<QII", *entry) for entry in self._super) if odml else b""
        indx = struct.pack("<HBBI4s3I", 4, 0, 0, len(entries) // 16, _CHUNK_ID, 0, 0, 0) + entries
        indx += bytes(_INDX_BYTES - len(indx))
        dmlh = struct.pack("<I", total if odml else 0) + bytes(_DMLH_BYTES - 4)
        strl = (
            _chunk(b"strh", strh) + _chunk(b"strf", strf) + _chunk(b"indx" if odml else b"JUNK", indx)
        )  # the super index stays JUNK in a plain AVI 1.0 file, as FFmpeg's
        odml_list = b"odml" + _chunk(b"dmlh", dmlh)
        body = b"hdrl" + _chunk(b"avih", avih) + _chunk(b"LIST", b"strl" + strl)
        body += _chunk(b"LIST" if odml else b"JUNK", odml_list)
        return _chunk(b"LIST", body)

    # ------------------------------------------------------------------------------------------------ file

    def _put(self, data: bytes) -> None:
        self._file.write(data)
        self._pos += len(data)

    def _patch(self, offset: int, data: bytes) -> None:
        self._file.seek(offset)
        self._file.write(data)
        self._file.seek(self._pos)

    def _begin_movi(self) -> None:
        self._movi = self._pos + 8  # the 'movi' FOURCC: the index offsets' origin
        self._ix = array("I")
        self._put(b"LIST" + bytes(4) + b"movi")

    def _end_segment(self, index: bool) -> None:
        """End the current RIFF: its ``ix00`` (``index``), the movi list, ``idx1`` (the first RIFF), sizes."""
        n = len(self._ix) // 2
        if index:
            at = self._pos
            body = struct.pack("<HBBI4sQI", 2, 0, 1, n, _CHUNK_ID, self._movi, 0) + _u32(self._ix)
            self._put(b"ix00" + struct.pack("<I", len(body)) + body)
            self._super.append((at, self._pos - at, n))
        self._patch(self._movi - 4, struct.pack("<I", self._pos - self._movi))
        if self._riff_start == 0:
            self._first_frames = n
            entries = np.empty((n, 4), dtype="<u4")
            entries[:, 0] = struct.unpack("<I", _CHUNK_ID)[0]
            entries[:, 1] = _KEYFRAME
            ix = np.frombuffer(self._ix, dtype=np.uint32).reshape(n, 2)
            entries[:, 2] = ix[:, 0] - 8  # idx1: the chunk's header, from the 'movi' FOURCC
            entries[:, 3] = ix[:, 1]
            self._put(b"idx1" + struct.pack("<I", 16 * n) + entries.tobytes())
        self._patch(self._riff_start + 4, struct.pack("<I", self._pos - self._riff_start - 8))

    def _emit(self, data: bytes) -> None:
        """Append one encoded frame (a new RIFF first when this one would pass ``segment_bytes``)."""
        size = len(data)
        chunk = 8 + size + (size & 1)
        if chunk > MAX_SEGMENT_BYTES:
            raise OutputError(f"cannot write video {self.path}: a frame of {size} bytes is too large for AVI")
        n = len(self._ix) // 2 + 1
        after = self._pos + chunk - self._riff_start + 8 + _IX_HEADER + 8 * n
        if self._riff_start == 0:
            after += 8 + 16 * n  # idx1
        if n > 1 and after > self.segment_bytes:
            if len(self._super) + 1 >= SUPER_INDEX_ENTRIES:
                raise OutputError(
                    f"cannot write video {self.path}: more than {SUPER_INDEX_ENTRIES} RIFFs of {self.segment_bytes} "
                    "bytes (the OpenDML super index is full)"
                )
            self._end_segment(index=True)
            self._riff_start = self._pos
            self._put(b"RIFF" + bytes(4) + b"AVIX")
            self._begin_movi()
            self.segments += 1
        self._ix.extend((self._pos + 8 - self._movi, size))
        self._put(_CHUNK_ID + struct.pack("<I", size) + data + (b"\0" if size & 1 else b""))
        self._max_chunk = max(self._max_chunk, size)
        self.frames += 1

    def _finish(self) -> None:
        self._end_segment(index=bool(self._super))  # several RIFFs: the last one's ix00 too
        self._patch(12, self._hdrl())
        self._file.close()

    # ------------------------------------------------------------------------------------------------ frames

    def _fail(self, error: BaseException) -> None:
        """An encoding or writing error: drop everything (the file is deleted) and keep the error to raise."""
        self._error = error
        self._drop()

    def _write_oldest(self) -> None:
        future = self._pending.popleft()
        try:
            data = future.result()
            self._emit(data)
        except OSError as e:
            error = OutputError(f"cannot write video {self.path}: {e.strerror or e}")
            self._fail(error)
            raise error from e
        except BaseException as e:
            self._fail(e)
            raise

    def _check(self) -> None:
        if self._error is not None:
            raise OutputError(f"video {self.path} was not written: {self._error}") from self._error
        if self._closed:
            raise RuntimeError(f"video writer for {self.path} is closed")
        for future in self._pending:  # an encoding error of any frame in flight: raised now
            if future.done() and future.exception() is not None:
                error = future.exception()
                assert error is not None
                self._fail(error)
                raise error

    def write(self, frame: np.ndarray) -> None:
        """Append one frame (copied: the caller may reuse its buffer).

        Args:
            frame: ``(H, W)`` uint8 grey or ``(H, W, 3)`` uint8 BGR (``(H, W)`` with 0 and 255 only when bilevel),
                of the writer's size.

        Raises:
            ValueError: A frame of the wrong type, shape or size.
            OutputError: The file cannot be written (an error encoding an earlier frame is raised as it was).
        """
        self._check()
        frame = np.asarray(frame)
        if frame.ndim == 3 and frame.shape[2] == 1:
            frame = frame[..., 0]
        if frame.dtype != np.uint8 or frame.ndim not in (2, 3) or (frame.ndim == 3 and frame.shape[2] != 3):
            raise ValueError(f"PNG video frames must be (H, W) or (H, W, 3) uint8, got {frame.shape} {frame.dtype}")
        if self.bilevel and frame.ndim != 2:
            raise ValueError(f"bilevel PNG video {self.path}: frames must be grey (H, W), got shape {frame.shape}")
        h, w = frame.shape[:2]
        if (w, h) != self.size:
            raise ValueError(f"frame of {w}x{h} pixels written to video {self.path} of {self.size[0]}x{self.size[1]}")
        frame = np.array(frame, copy=True, order="C")
        while len(self._pending) >= self.in_flight:
            self._write_oldest()
        self._pending.append(self._pool.submit(self._encode, frame, self.bilevel, self.compression))
        while self._pending and self._pending[0].done():  # what is ready goes to the file without waiting
            self._write_oldest()

    def flush(self) -> None:
        """Wait for the frames in flight and write them to the file (an encoding error is raised here)."""
        self._check()
        while self._pending:
            self._write_oldest()
        try:
            self._file.flush()
        except OSError as e:
            error = OutputError(f"cannot write video {self.path}: {e.strerror or e}")
            self._fail(error)
            raise error from e

    @property
    def pending(self) -> int:
        """Frames handed to :meth:`write` and not yet in the file (waiting or being encoded)."""
        return len(self._pending)

    def close(self) -> Path:
        """Encode the frames in flight, finish the file (index, header) and return its path (idempotent).

        Raises:
            OutputError: The file cannot be written, or an earlier frame failed (the file is deleted then); an error
                encoding a frame is raised as it was.
        """
        if self._finished:
            return self.path
        self._check()
        while self._pending:
            self._write_oldest()
        try:
            self._finish()
        except OSError as e:
            error = OutputError(f"cannot write video {self.path}: {e.strerror or e}")
            self._fail(error)
            raise error from e
        self._closed = self._finished = True
        self._pool.shutdown(wait=True)
        log.debug(
            "wrote %s: %d PNG frames in %d RIFF(s), largest %d bytes",
            self.path,
            self.frames,
            self.segments,
            self._max_chunk,
        )
        return self.path

    def _drop(self) -> None:
        self._closed = True
        for future in self._pending:
            future.cancel()
        self._pending.clear()
        self._pool.shutdown(wait=True, cancel_futures=True)
        with contextlib.suppress(OSError):
            self._file.close()
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()

    def abort(self) -> None:
        """Drop the frames in flight and delete the file (idempotent; after :meth:`close` the finished file is
        kept)."""
        if not self._closed:
            self._drop()


def _chunk(fourcc: bytes, body: bytes) -> bytes:
    """A RIFF chunk: FOURCC, 32-bit size, body, a pad byte when the size is odd."""
    return fourcc + struct.pack("<I", len(body)) + body + (b"\0" if len(body) & 1 else b"")
