"""``wptrack masks``: make a video's motion masks and write them (masks.avi, probability.avi, background.png,
masks.json), atomically."""

from __future__ import annotations

import dataclasses
import os
from typing import Any

import numpy as np

from wptrack.motion.masks import MaskConfig, open_masks

__all__ = ["write_masks"]


def _mask_frame(mask: np.ndarray) -> np.ndarray:
    return mask * np.uint8(255)


def pipeline_hash() -> str:
    """First 16 hex digits of a SHA-256 over the source of the mask pipeline (the modules of :mod:`wptrack.motion`
    and :mod:`wptrack.kernels.core`, and the video readers :mod:`wptrack.io.frames`, :mod:`~wptrack.io.decode` and
    :mod:`~wptrack.io.jpeg`, whose decoder sets the frames' pixels, by name): written to ``masks.json`` as ``code``,
    so that masks cached by an experiment are made again after the pipeline changed, not only its configuration."""
    import hashlib
    from importlib.util import find_spec
    from pathlib import Path

    files: list[Path] = []
    for package in ("wptrack.motion", "wptrack.kernels.core"):
        spec = find_spec(package)
        for root in spec.submodule_search_locations if spec is not None else ():
            files += sorted(Path(root).glob("*.py"))
    for module in ("wptrack.io.frames", "wptrack.io.decode", "wptrack.io.jpeg"):
        spec = find_spec(module)
        if spec is not None and spec.origin:
            files.append(Path(spec.origin))
    h = hashlib.sha256()
    for f in files:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _probability_frame(prob: np.ndarray) -> np.ndarray:
    return np.round(prob * 255.0).astype(np.uint8)


def write_masks(
    video: str | os.PathLike | np.ndarray,
    out_dir: str | os.PathLike,
    config: MaskConfig = MaskConfig(),
    probability: bool = False,
    max_frames: int | None = None,
) -> dict[str, Any]:
    """Make a video's motion masks and write them (``wptrack masks``).

    Outputs in ``out_dir``: ``masks.avi`` (masks as 0/255 grey frames: 1-bit PNG images, FOURCC ``MPNG``, lossless,
    :mod:`wptrack.io.avi`), ``probability.avi`` (with ``probability``: the foreground probability times 255, 8-bit
    grey PNG images), ``background.png`` (offline method: the first window's background) and ``masks.json``
    (inputs, config, frame count, codec, timing). Videos are prepared by writer threads
    (:class:`wptrack.io.video.BackgroundWriter`) whose PNG images are encoded by pools of threads (a 1920x1080
    mask: ~3 ms a thread, where OpenCV's FFV1 took 19 ms in one and bounded the command at ~52 frames/s), and written
    atomically: an error leaves no half-written video.

    Args:
        video: Camera frames (any :func:`wptrack.io.frames.open_source` spec).
        out_dir: Output folder (created).
        config: Mask settings (``method`` ``"given"`` is refused: there is nothing to make).
        probability: Also write ``probability.avi``.
        max_frames: Stop after this many frames (``None``: all).

    Returns:
        The summary written to ``masks.json``.

    Raises:
        ConfigError: ``method="given"``.
        FrameError: The video cannot be read.
        OutputError: ``out_dir`` or a file in it cannot be written.
    """
    import time

    from wptrack.io.atomic import atomic_write_bytes, atomic_write_json, ensure_writable_dir
    from wptrack.io.video import BackgroundWriter, VideoWriter

    masks = open_masks(video=video, config=config)
    out = ensure_writable_dir(out_dir)
    fps = masks.source.fps or 25.0
    first: list[np.ndarray] = []  # the first window's background, kept when the pass builds it (not built again)
    if masks.model is not None:
        report = masks.model.on_build

        def keep_first(window: int, centre: float, image: np.ndarray) -> None:
            if window == 0 and not first:
                first.append(image)
            if report is not None:
                report(window, centre, image)

        masks.model.on_build = keep_first
    t0 = time.perf_counter()
    frames = 0
    mask_video = VideoWriter(out / "masks.avi", fps=fps, size=masks.size, grey=True, codec="PNG", bilevel=True)
    with BackgroundWriter(mask_video) as mw:
        pw = None
        if probability:
            pw = BackgroundWriter(
                VideoWriter(out / "probability.avi", fps=fps, size=masks.size, grey=True, codec="PNG")
            )
        try:
            for mask, prob in masks.evidence(probability=probability):
                if max_frames is not None and frames >= max_frames:
                    break
                mw.write(mask, _mask_frame)
                if pw is not None:
                    pw.write(prob, _probability_frame)
                frames += 1
        except BaseException:
            if pw is not None:
                pw.abort()
            raise
        if pw is not None:
            pw.close()
    elapsed = time.perf_counter() - t0
    summary: dict[str, Any] = {
        "video": video if not isinstance(video, np.ndarray) else "array",
        "frames": frames,
        "size": list(masks.size),
        "fps": fps,
        "codec": mw.writer.codec,
        "seconds": elapsed,
        "config": dataclasses.asdict(config),
        "code": pipeline_hash(),
        "outputs": ["masks.avi"] + (["probability.avi"] if probability else []),
    }
    # a truncated or variable-rate video, under the keys a tracker's run.json uses
    for attr, key in (("stopped_early", "stopped_early"), ("variable_rate", "variable_frame_rate")):
        note = getattr(masks.source, attr, None)
        if note is not None:
            summary[key] = note
    background = first[0] if first else masks.background()
    if background is not None:
        import cv2

        ok, png = cv2.imencode(".png", background)
        if ok:
            atomic_write_bytes(out / "background.png", png.tobytes())
            summary["outputs"].append("background.png")
        # the frames each window's background was built from (a truncated video's planned samples past its end were
        # never read)
        end = frames if summary.get("stopped_early") else None
        summary["windows"] = [[int(f) for f in w.samples if end is None or f < end] for w in masks.model.windows]
    summary["outputs"].append("masks.json")
    atomic_write_json(out / "masks.json", summary)
    return summary
