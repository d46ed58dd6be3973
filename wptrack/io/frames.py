"""Synchronised multi-camera frame sources.

A :class:`FrameSource` yields one camera's frames as ``(H, W, 3)`` ``uint8`` BGR arrays, whatever it reads from:

* a video file (anything ``cv2.VideoCapture`` reads),
* a folder of images (``*.png``, ``*.jpg``, ``*.jpeg``, ``*.bmp``, ``*.tif``, ``*.tiff``, natural sort order),
* a glob pattern (a string containing ``*`` or ``?``) matching image files,
* a single image file (a one-frame sequence),
* a numpy array ``(F, H, W, 3)`` or ``(F, H, W)`` of ``uint8``.

:class:`SyncedFrames` iterates several sources in lock-step (one frame per camera per time step) and checks that
they agree on their frame counts. :class:`VideoWriter` / :func:`write_video` write videos with a lossless codec
when one is available, atomically (temporary name, renamed on close).

Every user mistake (missing file, unreadable video or image, inconsistent frame counts or sizes) raises a
one-line :class:`~wptrack.core.errors.FrameError` naming the path.
"""

from __future__ import annotations

import glob
import logging
import os
import re
from collections.abc import Iterable, Iterator, Sequence
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError, FrameError
from wptrack.io.decode import decode_threads, is_jpeg_video
from wptrack.io.jpeg import open_jpeg

log = logging.getLogger(__name__)

#: Image file extensions recognised in folders (lower case, compared case-insensitively).
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


_STOP_HINT = "(use --stop-at-shortest to track the common part)"


def _natural_key(path: str) -> list[Any]:
    """Sort key that orders ``img2.png`` before ``img10.png``."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path)]


def _to_bgr(image: np.ndarray) -> np.ndarray:
    """Convert a grayscale ``(H, W)`` / ``(H, W, 1)`` or BGRA ``(H, W, 4)`` uint8 image to ``(H, W, 3)`` BGR."""
    if image.ndim == 3 and image.shape[2] == 3:
        return image
    import cv2

    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        return cv2.cvtColor(image.reshape(image.shape[:2]), cv2.COLOR_GRAY2BGR)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    raise ValueError(f"cannot convert an image of shape {image.shape} to BGR")


def _read_image(path: str) -> np.ndarray | None:
    """Read an image file as ``(H, W, 3)`` uint8 BGR (grayscale and 16-bit images converted); None if unreadable."""
    import cv2

    try:
        data = np.fromfile(path, dtype=np.uint8)  # works with non-ASCII paths, unlike cv2.imread
    except OSError:
        return None
    if data.size == 0:
        return None
    image = cv2.imdecode(data, cv2.IMREAD_COLOR)
    if image is None:
        return None
    return _to_bgr(image)


def camera_frame(image: np.ndarray, camera: Any, what: str = "frame", where: str = "") -> np.ndarray:
    """One image checked against a camera's calibrated size, as the trackers take it (every tracker's ``upload``).

    Args:
        image: ``what`` ``frame``: an (H, W, 3) uint8 BGR image; ``mask``: an (H, W) motion mask, or (H, W, 1|3)
            reduced by the maximum over its channels (nonzero = foreground).
        camera: The :class:`wptrack.cameras.camera.Camera` the image is from.
        what: ``frame`` or ``mask``.
        where: Appended to the message (e.g. `` in rig.yaml``).

    Returns:
        The image: the frame as it is; the mask as (H, W).

    Raises:
        FrameError: the wrong type or shape, or a size other than the camera's (``mask size 320x240 differs from
            camera 'cam0' calibration 640x480``).
    """
    img = np.asarray(image)
    if what == "mask":
        if img.ndim == 3 and img.shape[2] in (1, 3):
            img = img.max(axis=2)
        if img.ndim != 2:
            raise FrameError(f"camera '{camera.name}': expected a 2D (H, W) motion mask, got shape {img.shape}")
    elif img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise FrameError(f"camera '{camera.name}': expected an (H, W, 3) uint8 BGR image, got {img.dtype} {img.shape}")
    if img.shape[:2] != (camera.height, camera.width):
        raise FrameError(
            f"{what} size {img.shape[1]}x{img.shape[0]} differs from camera '{camera.name}' calibration "
            f"{camera.width}x{camera.height}{where}"
        )
    return img


class FrameSource:
    """One camera's frames.

    Attributes:
        name: Label used in messages: the path, or ``"array[i]"`` for an in-memory array.
        width: Frame width in pixels (known after opening: the first frame is probed).
        height: Frame height in pixels.
        fps: Frames per second when the source knows it (videos), else None.

    Iterating yields ``(H, W, 3)`` uint8 BGR frames; every iteration starts again from the first frame.

    ``stopped_early`` is None, or after an iteration that ended before the reported frame count (a truncated or
    corrupt video) ``{"camera": name, "frame": index of the first frame not read, "expected": reported count,
    "reason": ...}``.
    """

    name: str
    width: int
    height: int
    fps: float | None = None
    stopped_early: dict[str, Any] | None = None
    variable_rate: dict[str, Any] | None = None  # videos: where a pass found a variable frame rate
    stage = "decode"  # the timeline stage of a thread iterating it (wptrack.io.prefetch)

    def __len__(self) -> int:
        """Number of frames (as reported by the source; a video may turn out shorter when read)."""
        raise NotImplementedError

    def __iter__(self) -> Iterator[np.ndarray]:
        raise NotImplementedError

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return (self.width, self.height)

    def _check_size(self, frame: np.ndarray, index: int, where: str | None = None) -> None:
        h, w = frame.shape[:2]
        if (w, h) != (self.width, self.height):
            raise FrameError(
                f"frame {index} of {where or self.name} is {w}x{h} pixels, but the sequence started with "
                f"{self.width}x{self.height} (the frame size must not change)"
            )

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, {len(self)} frames, {self.width}x{self.height})"


class VideoSource(FrameSource):
    """Frames of a video file read with ``cv2.VideoCapture``.

    The frame count is ``CAP_PROP_FRAME_COUNT`` (counted by decoding the file when the container does not report
    it). When reading, at most that many frames are yielded; a video that ends earlier stops early with a
    warning in the log (:class:`SyncedFrames` turns that into an error when other cameras continue).
    A video whose timestamps depart from its rate (variable frame rate: the trackers take each frame as ``1 / fps``)
    is read all the same, with one warning per pass; ``variable_rate`` then says where
    (:func:`wptrack.io.decode.rate_note`).

    Args:
        path: Video file path (or any string ``cv2.VideoCapture`` opens, e.g. a URL).
        name: Label for messages; defaults to the path.

    Raises:
        FrameError: The file does not exist, cannot be opened, or its first frame cannot be decoded.
    """

    def __init__(self, path: str | os.PathLike, name: str | None = None) -> None:
        self.path = str(path)
        self.name = name or self.path
        is_uri = "://" in self.path or "%" in self.path
        if not is_uri and not os.path.exists(self.path):
            raise FrameError(f"video file not found: {self.path}")
        if not is_uri and os.path.isdir(self.path):
            raise FrameError(f"{self.path} is a folder, not a video file")
        self.jpeg = is_jpeg_video(self.path)
        cap = self._open()
        try:
            ok, frame = cap.read()
            if not ok or frame is None:
                raise FrameError(
                    f"cannot read the first frame of video {self.path} (corrupt file or unsupported codec)"
                )
            frame = _to_bgr(frame)
            self.height, self.width = frame.shape[:2]
            import cv2

            fps = cap.get(cv2.CAP_PROP_FPS)
            self.fps = float(fps) if fps and np.isfinite(fps) and fps > 0 else None
            count = cap.get(cv2.CAP_PROP_FRAME_COUNT)
            if count and np.isfinite(count) and count > 0:
                self._count = int(round(count))
            else:
                n = 1
                while cap.grab():
                    n += 1
                log.debug("%s does not report its frame count; counted %d frames", self.path, n)
                self._count = n
        finally:
            cap.release()
        log.debug(
            "opened video %s: %d frames, %dx%d, %s fps", self.path, self._count, self.width, self.height, self.fps
        )

    threads: int | None = None
    """FFmpeg decoder threads of this video (None: :func:`decode_threads`, else OpenCV's default); set by
    :class:`SyncedFrames` to its share of the budget."""

    jpeg: bool = False  #: a Motion-JPEG video read as JPEG packets (wptrack.io.jpeg: only retrieved frames decode)

    def _open(self) -> Any:
        import cv2

        if self.jpeg:
            return open_jpeg(self.path)
        threads = self.threads or decode_threads()
        if threads is None:
            cap = cv2.VideoCapture(self.path)
        else:
            cv2.setNumThreads(decode_threads() or threads)
            cap = cv2.VideoCapture(self.path, cv2.CAP_ANY, [cv2.CAP_PROP_N_THREADS, int(threads)])
        if not cap.isOpened():
            cap.release()
            raise FrameError(f"cannot open video {self.path} (not a video file, corrupt, or unsupported codec)")
        return cap

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[np.ndarray]:
        from wptrack.io.decode import frame_items, rate_note

        self.stopped_early = None
        self.variable_rate = None
        items = frame_items(self._open, self._count)  # one capture, or several (WPTRACK_DECODE_WORKERS)
        last_ms = None
        try:
            for i, ok, frame, ms in items:
                if not ok:
                    log.warning("video %s ended after %d frames, although it reports %d", self.path, i, self._count)
                    self.stopped_early = {
                        "camera": self.name,
                        "frame": i,
                        "expected": self._count,
                        "reason": f"video ended after {i} of its {self._count} reported frames (truncated or corrupt)",
                    }
                    return
                if self.fps and self.variable_rate is None and last_ms is not None and ms > last_ms:
                    self.variable_rate = rate_note(self.fps, i, ms - last_ms)  # timestamps against 1 / fps
                    if self.variable_rate is not None:
                        log.warning("%s: %s", self.name, self.variable_rate["reason"])
                last_ms = ms
                frame = _to_bgr(frame)
                self._check_size(frame, i)
                yield frame
        finally:
            items.close()


class VideoReader:
    """Exact random access to a video's frames, for readers that need frames out of order or far apart (the offline
    background model's samples, the report's frames).

    Over gaps of ``seek_gap`` frames or more it seeks (``CAP_PROP_POS_FRAMES``) and checks the position the decoder
    reports; when a seek lands elsewhere (inexact seeking for this codec), it reads sequentially from then on
    (re-opening the file to go backwards). Frames passed on the way can be collected for later reads.

    Args:
        source: The video.
        seek_gap: Smallest forward gap, in frames, over which to seek rather than decode through (a seek decodes
            from the previous keyframe, so short gaps are cheaper to read through).

    Attributes:
        passed: Frames decoded on the way to a read whose index was in its ``collect`` set (index -> BGR frame).
    """

    def __init__(self, source: VideoSource, seek_gap: int = 24) -> None:
        self.source = source
        self.seek_gap = max(1, int(seek_gap))
        self.cap: Any = None
        self.pos = 0
        self.exact_seek = True
        self.passed: dict[int, np.ndarray] = {}

    def _reopen(self) -> None:
        if self.cap is not None:
            self.cap.release()
        self.cap = self.source._open()
        self.pos = 0

    def read(self, index: int, collect: Iterable[int] = ()) -> np.ndarray | None:
        """Frame ``index`` as an (H, W, 3) uint8 BGR image, or None when the video ends before it."""
        import cv2

        if self.cap is None:
            self._reopen()
        if index < self.pos or (index - self.pos >= self.seek_gap and self.exact_seek):
            if self.exact_seek:
                self.cap.set(cv2.CAP_PROP_POS_FRAMES, float(index))
                if int(round(self.cap.get(cv2.CAP_PROP_POS_FRAMES))) == index:
                    self.pos = index
                else:
                    log.debug("seeking in %s is inexact; reading sequentially", self.source.path)
                    self.exact_seek = False
                    self._reopen()
            else:
                self._reopen()
        collect = set(collect)
        while self.pos < index:
            if not self.cap.grab():
                return None
            if self.pos in collect:
                ok, frame = self.cap.retrieve()
                if ok and frame is not None:
                    self.passed[self.pos] = _to_bgr(frame)
            self.pos += 1
        ok, frame = self.cap.read()
        if not ok or frame is None:
            return None
        self.pos += 1
        return _to_bgr(frame)

    def close(self) -> None:
        """Release the file."""
        if self.cap is not None:
            self.cap.release()
            self.cap = None
        self.passed = {}


class ImageSequenceSource(FrameSource):
    """Frames read from a list of image files (a folder, a glob pattern, or a single image).

    Grayscale, 16-bit and BGRA images are converted to 8-bit BGR.

    Args:
        files: Image paths, in frame order (at least one).
        name: Label for messages (the folder or pattern).

    Raises:
        FrameError: The first image cannot be read.
    """

    def __init__(self, files: Sequence[str], name: str) -> None:
        if not files:
            raise FrameError(f"no images in {name}")
        self.files = [str(f) for f in files]
        self.name = name
        first = _read_image(self.files[0])
        if first is None:
            raise FrameError(f"cannot read image {self.files[0]} (not an image, corrupt, or unsupported format)")
        self.height, self.width = first.shape[:2]

    def __len__(self) -> int:
        return len(self.files)

    def __iter__(self) -> Iterator[np.ndarray]:
        for i, path in enumerate(self.files):
            frame = _read_image(path)
            if frame is None:
                raise FrameError(f"cannot read image {path} (frame {i} of {self.name})")
            self._check_size(frame, i, where=f"{self.name} ({path})")
            yield frame


class ArraySource(FrameSource):
    """Frames held in memory.

    Args:
        frames: ``(F, H, W, 3)`` BGR or ``(F, H, W)`` / ``(F, H, W, 1)`` grayscale array of uint8, ``F >= 1``.
        name: Label for messages.

    Raises:
        FrameError: Wrong dtype, wrong number of dimensions, or no frames.

    Yielded BGR frames are views into the array (not copies); grayscale frames are converted per frame.
    """

    def __init__(self, frames: np.ndarray, name: str = "array") -> None:
        self.name = name
        arr = np.asarray(frames)
        if arr.dtype != np.uint8:
            raise FrameError(f"{name}: frames must be uint8, got {arr.dtype}")
        if not (arr.ndim == 3 or (arr.ndim == 4 and arr.shape[3] in (1, 3))):
            raise FrameError(f"{name}: frames must have shape (F, H, W, 3) or (F, H, W), got {tuple(arr.shape)}")
        if arr.shape[0] == 0 or arr.shape[1] == 0 or arr.shape[2] == 0:
            raise FrameError(f"{name}: empty frame array of shape {tuple(arr.shape)}")
        self.frames = arr
        self.height, self.width = int(arr.shape[1]), int(arr.shape[2])

    def __len__(self) -> int:
        return int(self.frames.shape[0])

    def __iter__(self) -> Iterator[np.ndarray]:
        for i in range(len(self)):
            yield _to_bgr(np.ascontiguousarray(self.frames[i]))


def _is_image_file(path: str) -> bool:
    return os.path.splitext(path)[1].lower() in IMAGE_EXTENSIONS


def open_source(spec: str | os.PathLike | np.ndarray, name: str | None = None) -> FrameSource:
    """Open one camera's frames.

    Args:
        spec: A video file path; a folder of images (``*.png``, ``*.jpg``, ``*.jpeg``, ``*.bmp``, ``*.tif``,
            ``*.tiff``, sorted in natural order, hidden files ignored); a glob pattern string containing ``*``
            or ``?`` (matching files in natural order); a single image file (one frame); or a uint8 array
            ``(F, H, W, 3)`` BGR / ``(F, H, W)`` grayscale.
        name: Label used in messages; defaults to the path, or ``"array"`` for arrays.

    Returns:
        The opened source (its first frame has been read, so ``width`` and ``height`` are known).

    Raises:
        FrameError: Missing file, unreadable video or image, empty folder, glob with no match, bad array.
    """
    if isinstance(spec, np.ndarray):
        return ArraySource(spec, name=name or "array")
    if not isinstance(spec, (str, os.PathLike)):
        raise FrameError(f"cannot use {type(spec).__name__} as a frame source (expected a path or a uint8 array)")
    path = os.fspath(spec)
    label = name or path
    if os.path.isdir(path):
        files = [
            os.path.join(path, f)
            for f in os.listdir(path)
            if not f.startswith(".") and _is_image_file(f) and os.path.isfile(os.path.join(path, f))
        ]
        if not files:
            exts = ", ".join("*" + e for e in IMAGE_EXTENSIONS)
            raise FrameError(f"image folder {path} contains no images ({exts})")
        return ImageSequenceSource(sorted(files, key=_natural_key), name=label)
    if not os.path.exists(path) and ("*" in path or "?" in path):
        files = [f for f in glob.glob(path) if os.path.isfile(f)]
        if not files:
            raise FrameError(f"no files match the pattern {path}")
        return ImageSequenceSource(sorted(files, key=_natural_key), name=label)
    if os.path.isfile(path) and _is_image_file(path):
        return ImageSequenceSource([path], name=label)
    return VideoSource(path, name=label)


class SyncedFrames:
    """Several cameras' frames in lock-step.

    Args:
        sources: One opened :class:`FrameSource` per camera (at least one); frame sizes may differ per camera.
        stop_at_shortest: Track only the frames all sources have instead of failing on differing frame counts
            (also stops quietly, with a log warning, when a video ends earlier than it reported).
        max_frames: Yield at most this many frames (``None``: all). Differing frame counts are accepted when
            every source has at least ``max_frames`` frames.

    Raises:
        FrameError: The sources report different frame counts (unless ``stop_at_shortest`` or ``max_frames``
            makes that irrelevant), or no source was given.
        ConfigError: ``max_frames`` is negative.

    Iterating yields, per frame index, a list with one ``(H_c, W_c, 3)`` uint8 BGR frame per camera. If a video
    turns out shorter than it reported while others continue, a :class:`FrameError` is raised at that point
    (frames before it have been yielded); with ``stop_at_shortest``, or when all sources end together,
    iteration just stops early. Either way ``stopped_early`` then says where: ``{"camera": the ended source(s),
    "frame": the first frame index not delivered, "expected": the frames expected, "reason": ...}`` (None after
    an iteration that delivered every frame).
    """

    stopped_early: dict[str, Any] | None = None
    stage = "decode"  # the timeline stage of a thread iterating it (wptrack.io.prefetch)

    def __init__(
        self, sources: list[FrameSource], stop_at_shortest: bool = False, max_frames: int | None = None
    ) -> None:
        if not sources:
            raise FrameError("no frame sources given (need one video, image folder or array per camera)")
        if max_frames is not None and max_frames < 0:
            raise ConfigError(f"max_frames must be >= 0, got {max_frames}")
        self.sources = list(sources)
        self.stop_at_shortest = stop_at_shortest
        self.max_frames = max_frames
        counts = [len(s) for s in self.sources]
        shortest = min(counts)
        if len(set(counts)) > 1 and not stop_at_shortest and (max_frames is None or max_frames > shortest):
            listing = ", ".join(f"{s.name} {n}" for s, n in zip(self.sources, counts, strict=True))
            raise FrameError(f"videos have different frame counts: {listing} {_STOP_HINT}")
        if len(set(counts)) > 1:
            log.info("frame counts differ (%s); using the first %d frames", counts, shortest)
        rates = [getattr(s, "fps", None) for s in self.sources]
        known = [r for r in rates if r]
        if known and max(known) > 1.01 * min(known):
            listing = ", ".join(f"{s.name} {r:g} fps" for s, r in zip(self.sources, rates, strict=True) if r)
            log.warning("frame rates differ (%s): frames are paired by index, check the videos are in sync", listing)
        self._len = shortest if max_frames is None else min(shortest, max_frames)
        budget = decode_threads()
        videos = [s for s in self.sources if isinstance(s, VideoSource)]
        if budget is not None and videos:  # the run's decode budget shared out among its videos
            for s in videos:
                s.threads = max(1, budget // len(videos))

    @property
    def sizes(self) -> list[tuple[int, int]]:
        """``(width, height)`` in pixels per camera."""
        return [(s.width, s.height) for s in self.sources]

    @property
    def names(self) -> list[str]:
        """Each camera's source label (path or ``array[i]``)."""
        return [s.name for s in self.sources]

    def __len__(self) -> int:
        """Number of frame steps that will be yielded (unless a video turns out shorter than it reported)."""
        return self._len

    def __iter__(self) -> Iterator[list[np.ndarray]]:
        self.stopped_early = None
        if self._len == 0:
            return
        iterators = [iter(s) for s in self.sources]
        try:
            for index in range(self._len):
                frames: list[np.ndarray] = []
                ended: list[int] = []
                for c, it in enumerate(iterators):
                    frame = next(it, None)
                    if frame is None:
                        ended.append(c)
                    else:
                        frames.append(frame)
                if not ended:
                    yield frames
                    continue
                names = ", ".join(self.sources[c].name for c in ended)
                reasons = [self.sources[c].stopped_early for c in ended]
                self.stopped_early = {
                    "camera": names,
                    "frame": index,
                    "expected": self._len,
                    "reason": "; ".join(r["reason"] for r in reasons if r) or "the source ended early",
                }
                if len(ended) == len(iterators) or self.stop_at_shortest:
                    log.warning("%s ended after %d frames (expected %d); stopping there", names, index, self._len)
                    return
                parts = [
                    f"{s.name} ended after {index} (reported {len(s)})" if c in ended else f"{s.name} {len(s)}"
                    for c, s in enumerate(self.sources)
                ]
                raise FrameError(f"videos have different frame counts: {', '.join(parts)} {_STOP_HINT}")
        finally:
            for it in iterators:
                close = getattr(it, "close", None)
                if close is not None:
                    close()

    def __repr__(self) -> str:
        return f"SyncedFrames({len(self.sources)} cameras, {len(self)} frames)"


def open_frames(
    specs: list[str | os.PathLike | np.ndarray], stop_at_shortest: bool = False, max_frames: int | None = None
) -> SyncedFrames:
    """Open one frame source per camera and synchronise them.

    Args:
        specs: One spec per camera, as accepted by :func:`open_source`; arrays are named ``array[i]``.
        stop_at_shortest: See :class:`SyncedFrames`.
        max_frames: See :class:`SyncedFrames`.

    Returns:
        The synchronised sources.

    Raises:
        FrameError: A source cannot be opened, or the sources are inconsistent.
    """
    sources = [
        open_source(spec, name=f"array[{i}]" if isinstance(spec, np.ndarray) else None) for i, spec in enumerate(specs)
    ]
    return SyncedFrames(sources, stop_at_shortest=stop_at_shortest, max_frames=max_frames)
