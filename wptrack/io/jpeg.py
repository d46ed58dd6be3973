"""Motion-JPEG videos read as JPEG packets: a frame is decoded only when it is asked for, and several at once.

A Motion-JPEG video (FOURCC ``MJPG``, ``JPEG``: PETS 2009's recordings, many surveillance cameras, the pipeline
bench's videos) is a sequence of independent JPEG images. OpenCV's FFmpeg reader in raw mode
(``CAP_PROP_FORMAT = -1``) hands out each frame's packet without decoding it; ``cv2.imdecode`` (libjpeg-turbo)
decodes the packets that are wanted, and releases the GIL while it does. So:

* skipping a frame costs a packet read (~0.02 ms at 1920x1080) instead of a decode (~3 ms): the offline background
  model's sampler (:mod:`wptrack.motion.windows`), which passes ~12 frames for each one it keeps, and the report's
  random access read only the frames they use;
* the frames of a run can be decoded by several threads at once, in order (:func:`jpeg_frames`), where one thread
  of FFmpeg's JPEG decoder was the pipeline's slowest stage on a GPU host (issue 27).

libjpeg-turbo and FFmpeg's JPEG decoder do not give bit-identical images (a different inverse DCT, chroma upsampling
and colour conversion: on the PETS clip a mean absolute difference of ~1 level, larger at sharp colour edges;
libjpeg-turbo's images are as close to the encoded ones or closer, ``tests/test_jpeg.py``). Every reader of
a video in wptrack opens it through :meth:`wptrack.io.frames.VideoSource._open`, so one run sees one decoder
throughout (the background model's samples and the frames it is compared with). ``WPTRACK_JPEG_DECODE=0`` keeps
FFmpeg's decoder (and its per-frame decoding of skipped frames).

The masks wptrack writes (``masks.avi``: an AVI of PNG images, :mod:`wptrack.io.avi`) are read the same way: their
packets are PNG images, which ``cv2.imdecode`` decodes exactly (lossless) and several threads decode at once.

A video whose first packet ``cv2.imdecode`` cannot read (e.g. an AVI1 stream without Huffman tables) is read by
FFmpeg as any other video.
"""

from __future__ import annotations

import logging
import os
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from wptrack.core.errors import FrameError

log = logging.getLogger(__name__)

JPEG_CODECS = frozenset({"MJPG", "JPEG"})
"""FOURCCs (upper case) of videos whose packets are baseline JPEG images that ``cv2.imdecode`` reads."""

PNG_CODECS = frozenset({"MPNG", "PNG ", "PNG1"})
"""FOURCCs (upper case) of videos whose packets are PNG images (wptrack's own masks: :mod:`wptrack.io.avi`)."""

PACKET_CODECS = JPEG_CODECS | PNG_CODECS
"""FOURCCs of the videos read as packets decoded by ``cv2.imdecode`` (:class:`JpegCapture`)."""

_PNG_SIGNATURE = b"\x89PNG"

JPEG_DECODE_ENV = "WPTRACK_JPEG_DECODE"
"""Environment variable: ``0`` reads Motion-JPEG videos with FFmpeg's decoder like any other (default: JPEG
packets, :mod:`wptrack.io.jpeg`)."""

JPEG_WORKERS_ENV = "WPTRACK_JPEG_WORKERS"
"""Environment variable: threads decoding a Motion-JPEG video's frames at once (default :func:`jpeg_workers`)."""


def jpeg_enabled() -> bool:
    """Motion-JPEG videos are read as JPEG packets (:data:`JPEG_DECODE_ENV` is not ``0``)."""
    return os.environ.get(JPEG_DECODE_ENV, "").strip() not in ("0", "false", "no", "off")


def jpeg_workers() -> int:
    """Threads decoding one Motion-JPEG video's frames: :data:`JPEG_WORKERS_ENV` when set, else one per 4 host
    cores, at most 4 (one on a 2-core machine: the frames are decoded in the reading thread, as before)."""
    from wptrack.core.config import env_count, host_cores

    return env_count(JPEG_WORKERS_ENV, max(1, min(4, host_cores() // 4)))


def decode_packet(packet: np.ndarray | None) -> np.ndarray | None:
    """One JPEG or PNG packet (a uint8 array of its bytes) as an (H, W, 3) uint8 BGR image; None when it is not one.

    A PNG packet (a mask of :mod:`wptrack.io.avi`: 1-bit or 8-bit grey) is decoded as it is stored and its grey
    channel repeated (half the time of ``IMREAD_COLOR``'s conversion inside the decoder, the same pixels)."""
    import cv2

    if packet is None or packet.size == 0:
        return None
    data = packet.reshape(-1)
    if bytes(data[:4]) != _PNG_SIGNATURE:
        return cv2.imdecode(data, cv2.IMREAD_COLOR)
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if image is None or image.dtype != np.uint8:  # 16-bit PNG: let OpenCV convert it as a colour image
        return None if image is None else cv2.imdecode(data, cv2.IMREAD_COLOR)
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    return image


class JpegCapture:
    """A ``cv2.VideoCapture`` of a Motion-JPEG video in raw mode that decodes the packets it returns.

    It answers the calls wptrack's readers make of a capture: :meth:`grab` moves on one frame without decoding it,
    :meth:`retrieve` decodes the frame grabbed last, :meth:`read` does both; :meth:`get` and :meth:`set`
    (``CAP_PROP_POS_FRAMES``: seeks, exact here, every frame a keyframe) go to the capture.

    Args:
        cap: An opened ``cv2.VideoCapture`` in raw mode (``CAP_PROP_FORMAT`` -1).
    """

    def __init__(self, cap: Any) -> None:
        self.cap = cap

    def isOpened(self) -> bool:  # noqa: N802 - cv2.VideoCapture's name
        return bool(self.cap.isOpened())

    def grab(self) -> bool:
        return bool(self.cap.grab())

    def packet(self) -> np.ndarray | None:
        """The packet of the frame grabbed last (a copy), or None."""
        ok, packet = self.cap.retrieve()
        return np.array(packet, copy=True).reshape(-1) if ok and packet is not None else None

    def retrieve(self) -> tuple[bool, np.ndarray | None]:
        frame = decode_packet(self.packet())
        return frame is not None, frame

    def read(self) -> tuple[bool, np.ndarray | None]:
        if not self.grab():
            return False, None
        return self.retrieve()

    def get(self, prop: int) -> float:
        return float(self.cap.get(prop))

    def set(self, prop: int, value: float) -> bool:
        return bool(self.cap.set(prop, value))

    def release(self) -> None:
        self.cap.release()


def open_raw(path: str) -> Any:
    """``path`` opened by OpenCV's FFmpeg reader in raw mode (packets, not frames)."""
    import cv2

    return cv2.VideoCapture(path, cv2.CAP_FFMPEG, [cv2.CAP_PROP_FORMAT, -1])


def open_jpeg(path: str) -> JpegCapture:
    """``path`` (a Motion-JPEG video) opened as a :class:`JpegCapture`.

    Raises:
        FrameError: It cannot be opened.
    """
    raw = open_raw(path)
    if not raw.isOpened():
        raw.release()
        raise FrameError(f"cannot open video {path} (not a video file, corrupt, or unsupported codec)")
    return JpegCapture(raw)


def jpeg_frames(cap: JpegCapture, count: int, workers: int) -> Iterator[tuple[int, bool, np.ndarray | None, float]]:
    """The items of :func:`wptrack.io.decode.read_sequential` (``(index, ok, frame, ms)`` for frames ``0 .. count -
    1`` in order, ``ok`` False at the first frame that cannot be read, nothing after it) from a :class:`JpegCapture`
    whose packets ``workers`` threads decode at once (:func:`wptrack.io.decode.frame_items` reads a video in the
    calling thread when one is to decode it). This thread reads the packets (cheap) and keeps at most
    ``2 workers`` frames in flight, so memory stays bounded whatever the consumer's speed."""
    import cv2

    workers = max(1, int(workers))
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="wptrack-jpeg")
    pending: deque[tuple[int, Future | None, float]] = deque()
    try:
        i = 0
        while i < count or pending:
            while i < count and len(pending) < 2 * workers:
                packet = cap.packet() if cap.grab() else None
                ms = cap.get(cv2.CAP_PROP_POS_MSEC) if packet is not None else 0.0
                pending.append((i, None if packet is None else pool.submit(decode_packet, packet), ms))
                i += 1
                if packet is None:
                    i = count  # the video ends here: nothing after it is read
            index, future, ms = pending.popleft()
            frame = None if future is None else future.result()
            ok = frame is not None
            yield index, ok, frame, ms if ok else 0.0
            if not ok:
                return
    finally:
        for _, future, _ in pending:
            if future is not None:
                future.cancel()
        pool.shutdown(wait=True)
