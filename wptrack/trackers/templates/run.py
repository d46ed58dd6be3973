"""Running the S3 template tracker on a video or on given motion masks, writing the run folder as it goes.

Outputs (all written incrementally or atomically, so an interrupted run leaves valid partial results)::

    out_dir/tracks.csv     frame,id,x,y,z,class,length,width,height,orientation,speed,existence,gx,gy,sx,sy,degenerate
                           (objects with existence >= min_existence and >= min_in_image of their image box
                           inside the image; once the run completes, tracks shorter than min_track_frames are left
                           out, the others backfilled (backfill_seconds; rows with existence 0) and stitched
                           (stitch_seconds: a track continuing another gets its id), the tracker's own rows
                           staying in tracks_all.csv; x,y,z the ground-contact point in the world
                           frame and gx,gy on the ground plane, metres; orientation radians; speed m/s; degenerate 1
                           when every particle's log-weight was -inf/NaN that frame: the predicted particles were
                           kept with uniform weights, the prior; run.json's summary counts such frames)
    out_dir/best.csv       the same columns for the objects of the best particle (its whole scene hypothesis)
    out_dir/virtual.avi    the best particle's virtual scene per frame (paper Fig. 5), one colour per object id
                           (by default only for frames up to VIRTUAL_AUTO_PIXELS; --virtual / --no-virtual decide)
    out_dir/masks.avi      the motion masks used (only with save_masks; 0/255 grey frames as 1-bit PNG images)
    out_dir/backgrounds/   offline masks: the background of each window used, for the report (BackgroundSaver)
    out_dir/run.json       configuration, inputs, device, versions, timings, summary
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.config import REQUIRED, check, param
from wptrack.core.errors import ConfigError
from wptrack.io.tables import CsvAppender
from wptrack.motion.flood import FloodGuard
from wptrack.runs.loop import TrackerRun, run_tracker
from wptrack.trackers.templates.config import CLASSES

log = logging.getLogger(__name__)

TEMPLATE_COLUMNS = [
    "frame",
    "id",
    "x",
    "y",
    "z",
    "class",
    "length",
    "width",
    "height",
    "orientation",
    "speed",
    "existence",
    "gx",
    "gy",
    "sx",
    "sy",
    "degenerate",
]


def object_row(frame: int, o, degenerate: bool = False) -> list[Any]:
    """One tracks.csv row of a ``TrackedObject`` (``degenerate``: the frame's flag, ``TemplateEstimate.degenerate``)."""
    length, width, height = o.size
    return [
        frame,
        o.id,
        *[float(v) for v in o.position],
        o.cls,
        length,
        width,
        height,
        float(math.remainder(o.heading, 2 * math.pi)),
        o.speed,
        o.existence,
        float(o.ground[0]),
        float(o.ground[1]),
        float(o.std[0]),
        float(o.std[1]),
        int(degenerate),
    ]


VIRTUAL_AUTO_PIXELS = 640 * 480
"""Largest frame (pixels) for which ``virtual.avi`` is written unless told (``virtual=None``): the FFV1 encoding of a
colour frame costs about 0.04 us per pixel of CPU (1440x1080: 57 ms on the CI machine, 12 ms at 640x480), more than
the whole frame of tracking on a GPU at large sizes; it runs in a writer thread, but one encoder thread cannot keep
up with 100 frames/s above about 0.25 Mpixels. ``--virtual`` writes it at any size."""


def virtual_default(width: int, height: int) -> bool:
    """Whether ``virtual.avi`` is written when neither ``--virtual`` nor ``--no-virtual`` is given."""
    return int(width) * int(height) <= VIRTUAL_AUTO_PIXELS


def label_colours(labels: np.ndarray) -> np.ndarray:
    """A distinct BGR colour (uint8) per object label (golden-angle hues, stable across frames)."""
    import cv2

    hue = (np.asarray(labels, dtype=np.int64) * 137.508) % 180.0
    hsv = np.stack([hue, np.full_like(hue, 200), np.full_like(hue, 255)], axis=-1).astype(np.uint8)
    return cv2.cvtColor(hsv.reshape(-1, 1, 3), cv2.COLOR_HSV2BGR).reshape(-1, 3)


def colour_virtual(virtual: np.ndarray, slot_labels: np.ndarray) -> np.ndarray:
    """Colour a virtual scene (H, W) uint8 of ``1 + slot`` values by the slots' labels -> (H, W, 3) BGR (OpenCV's
    table lookup: the same values as ``lut[virtual]``, a sixth of its time at 1440x1080)."""
    import cv2

    lut = np.zeros((256, 3), dtype=np.uint8)
    n = len(slot_labels)
    lut[1 : n + 1] = label_colours(np.maximum(slot_labels, 0))
    v = np.ascontiguousarray(virtual, dtype=np.uint8)
    return cv2.LUT(cv2.merge([v, v, v]), lut.reshape(1, 256, 3))


def _mask_image(mask: np.ndarray) -> np.ndarray:
    """A {0, 1} mask as the 0/255 grey frame of masks.avi."""
    return (np.asarray(mask) != 0).view(np.uint8) * np.uint8(255)


BACKGROUNDS_DIR = "backgrounds"
"""Folder of a run with offline masks: ``window_NNNN.png`` (the background of each window the run used) and
``index.json`` (``{"windows": [{"window", "centre", "file"}]}``, centres in frames)."""


class BackgroundSaver:
    """``OfflineBackground.on_build`` callback writing each window's background into ``folder`` (atomically, the
    index rewritten after every image, so an interrupted run leaves a readable folder).

    The images are encoded by a thread of its own (a 1080p PNG: ~0.1 s, which the window's build, the first mask
    included, no longer waits for); :meth:`flush` returns when every image handed over is written (a checkpoint),
    :meth:`close` also ends the thread. An error of the writing thread is raised by the next call, flush or close."""

    def __init__(self, folder: Path) -> None:
        import threading
        from concurrent.futures import ThreadPoolExecutor

        self.folder = Path(folder)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wptrack-backgrounds")
        self._pending: list[Any] = []
        self._closed = False
        self._lock = threading.Lock()
        self.windows: dict[int, dict[str, Any]] = {}
        index = self.folder / "index.json"
        if index.exists():  # a resumed run keeps the windows saved before
            import json

            try:
                self.windows = {int(w["window"]): w for w in json.loads(index.read_text())["windows"]}
            except (ValueError, KeyError, TypeError):
                self.windows = {}

    def __call__(self, window: int, centre: float, image: np.ndarray) -> None:
        self._check()
        with self._lock:
            if not self._closed:
                self._pending.append(self._pool.submit(self._save, window, centre, image))
                return
        self._save(window, centre, image)  # a window built ahead after the run's end: written here, as before

    def _check(self, wait: bool = False) -> None:
        """Raise the first error of the images written so far (with ``wait``, after every pending one is written)."""
        if wait:
            with self._lock:
                pending = list(self._pending)
            for f in pending:
                f.exception()
        with self._lock:  # the building threads hand images over while the run's thread flushes
            done = [f for f in self._pending if f.done()]
            self._pending = [f for f in self._pending if not f.done()]
        for f in done:
            if f.exception() is not None:
                raise f.exception()

    def flush(self) -> None:
        self._check(wait=True)

    def close(self) -> None:
        try:
            self.flush()
        finally:
            with self._lock:
                self._closed = True
            self._pool.shutdown(wait=True)

    def _save(self, window: int, centre: float, image: np.ndarray) -> None:
        from wptrack.io.atomic import atomic_imwrite, atomic_write_json

        self.folder.mkdir(parents=True, exist_ok=True)
        name = f"window_{window:04d}.png"
        atomic_imwrite(self.folder / name, image)
        self.windows[int(window)] = {"window": int(window), "centre": float(centre), "file": name}
        atomic_write_json(self.folder / "index.json", {"windows": [self.windows[k] for k in sorted(self.windows)]})


class TemplateRun(TrackerRun):
    """The template tracker as a run-loop job. Everything the user gave is validated here (rig, video or masks,
    sizes, parameters, device), before the run loop touches the output folder.

    Args:
        rig_path: rig file (YAML/JSON); its ``ground`` entry (default z = 0) is the ground plane.
        config: ``TemplateConfig``.
        video: the camera's video (motion masks by background subtraction, ``mask_config``), or None.
        masks: binary motion masks (video or image folder) instead of background subtraction; with ``video``
            as well, the masks are used and the video only sets the frame size check.
        mask_config: ``wptrack.motion.masks.MaskConfig`` (background subtraction parameters).
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``.
        max_frames: stop after this many frames.
        save_masks: also write the masks used to ``masks.avi``.
        virtual: write the best particle's virtual scenes to ``virtual.avi``; None: only for frames up to
            :data:`VIRTUAL_AUTO_PIXELS`. Both videos are encoded by writer threads
            (:class:`wptrack.io.video.BackgroundWriter`).
        flood_guard: hold the last normal mask on flooded frames (camera shake, :mod:`wptrack.motion.flood`); the
            flooded frames are counted in run.json (``flooded_frames``).

    Raises:
        WptrackError subclasses for bad input (rig, sizes, parameters, device).
    """

    name = "templates"
    columns = TEMPLATE_COLUMNS

    def __init__(
        self,
        rig_path: str | Path,
        config: Any,
        video: str | Path | None = None,
        masks: str | Path | None = None,
        mask_config: Any = None,
        device: str = "auto",
        max_frames: int | None = None,
        save_masks: bool = False,
        virtual: bool | None = None,
        flood_guard: bool = True,
    ) -> None:
        from dataclasses import asdict, replace

        from wptrack.cameras.rig import Rig
        from wptrack.core.device import resolve_device
        from wptrack.io.frames import open_source
        from wptrack.motion.masks import MaskConfig, open_masks
        from wptrack.trackers.templates.tracker import TemplateTracker

        if video is None and masks is None:
            raise ConfigError("give --video (background subtraction) or --masks (binary motion masks)")
        rig = Rig.load(rig_path)
        camera = rig[config.camera_key]
        mask_config = mask_config if mask_config is not None else MaskConfig()
        if video is not None:
            src = open_source(video)
            width, height = src.size
            camera = camera.for_size(width, height, str(video), rig.source)
        if masks is not None:
            mask_config = replace(mask_config, method="given")
            stream = open_masks(masks=masks, config=mask_config, camera=camera, rig_source=rig.source)
        else:
            stream = open_masks(video=video, config=mask_config, camera=camera, rig_source=rig.source)
        rig = rig.with_camera(camera)
        device = resolve_device(device)
        if virtual is None:
            virtual = virtual_default(camera.width, camera.height)
            if not virtual:
                log.info(
                    "virtual.avi not written for %dx%d frames (more than %d pixels; --virtual writes it)",
                    camera.width, camera.height, VIRTUAL_AUTO_PIXELS,
                )  # fmt: skip
        self.tracker = TemplateTracker(rig, config, device=device, keep_virtual=virtual)
        self._stream = stream
        self._fps = config.frame_rate
        self._virtual = bool(virtual)
        self.source_stage = "decode" if masks is not None else "masks"  # what the run loop's prefetch thread does
        self._save_masks = save_masks
        self.total = len(stream) if max_frames is None else min(len(stream), max_frames)
        self.config = {
            "rig": str(Path(rig_path).resolve()),
            "camera": camera.name,
            "frame_size": [camera.width, camera.height],
            "video": str(video) if video is not None else None,
            "masks": str(masks) if masks is not None else None,
            "mask": asdict(mask_config),
            "tracker": config.to_dict(),
        }
        self._flood = FloodGuard(name=str(masks if masks is not None else video)) if flood_guard else None
        self.min_track_frames = int(config.min_track_frames)  # the run loop filters tracks.csv when complete
        self._seen: dict[int, str] = {}
        self._penalty_sum = 0
        self._penalty_frames = 0
        self._degenerate = 0
        self._best_csv: CsvAppender | None = None
        self._vwriter: Any = None
        self._mwriter: Any = None
        self._saver: BackgroundSaver | None = None

    def info(self) -> dict[str, Any]:
        tr = self.tracker
        return {"device": tr.device, "seed": tr.config.seed, "candidates": tr.candidates.count}

    def frames(self) -> Any:
        return self._stream

    def start(self, out_dir: Path, resume_after: int | None = None) -> None:
        from wptrack.io.tables import truncate_csv_after
        from wptrack.io.video import BackgroundWriter, continue_video

        best = out_dir / "best.csv"
        if resume_after is not None:
            truncate_csv_after(best, resume_after)
        self._best_csv = CsvAppender(best, TEMPLATE_COLUMNS, append=resume_after is not None and best.exists())
        # a resumed run rewrites its videos: the frames up to the resume point copied, then the new ones (one file)
        keep = 0 if resume_after is None else resume_after + 1
        if self._virtual:
            self._vwriter = BackgroundWriter(
                continue_video(out_dir / "virtual.avi", keep, fps=self._fps), stage="write_virtual"
            )
        if self._save_masks:
            self._mwriter = BackgroundWriter(
                continue_video(out_dir / "masks.avi", keep, fps=self._fps, grey=True, codec="PNG", bilevel=True),
                stage="write_masks",
            )
        model = getattr(self._stream, "model", None)
        if model is not None:  # offline masks: keep each background window for the report's Fig. 5 panels
            self._saver = model.on_build = BackgroundSaver(out_dir / BACKGROUNDS_DIR)

    def step(self, item: Any) -> Any:
        self._mask = item
        return self.tracker.step(item if self._flood is None else self._flood.filter(item))

    def record(self, est: Any, out: Any) -> None:
        out.add_rows([object_row(est.frame, o, est.degenerate) for o in est.objects])
        self._best_csv.add([object_row(est.frame, o, est.degenerate) for o in est.best])
        for o in est.objects:
            self._seen.setdefault(o.id, o.cls)
        self._penalty_sum += int(est.penalty)  # running sums: memory bounded however long the run
        self._penalty_frames += 1
        self._degenerate += int(est.degenerate)
        if self._vwriter is not None and est.virtual is not None:  # est.virtual is the estimate's own copy
            labels = self.tracker.host["slot_label"].numpy().copy()
            self._vwriter.write(est.virtual, lambda v: colour_virtual(v, labels))
        if self._mwriter is not None:  # each frame's mask is a new array (the mask stream's)
            self._mwriter.write(self._mask, _mask_image)

    def flush(self) -> None:
        if self._best_csv is not None:
            self._best_csv.sync()
        for writer in (self._vwriter, self._mwriter, self._saver):
            if writer is not None:
                writer.flush()

    def state_dict(self) -> dict[str, Any]:
        ids = sorted(self._seen)
        return {
            **self.tracker.state_dict(),
            "job.seen_ids": np.asarray(ids, dtype=np.int64),
            "job.seen_classes": np.asarray([self._seen[i] for i in ids], dtype=str),
            "job.penalty_sum": np.int64(self._penalty_sum),
            "job.penalty_frames": np.int64(self._penalty_frames),
            "job.degenerate": np.int64(self._degenerate),
            **(self._flood.state() if self._flood is not None else {}),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        self._seen = {int(i): str(c) for i, c in zip(state["job.seen_ids"], state["job.seen_classes"], strict=True)}
        self._penalty_sum = int(state["job.penalty_sum"])
        self._penalty_frames = int(state["job.penalty_frames"])
        self._degenerate = int(state["job.degenerate"])
        if self._flood is not None:
            self._flood.load(state, self.tracker.frames_done)

    def finish(self) -> None:
        if self._best_csv is not None:
            self._best_csv.close()
        errors = []
        for writer in (self._vwriter, self._mwriter, self._saver):
            if writer is not None:
                try:
                    writer.close()
                except Exception as e:  # noqa: BLE001 - the other writer is still closed; the first error raised
                    errors.append(e)
        if errors:
            raise errors[0]

    def finish_tracks(self, path: Path) -> dict[str, Any]:
        """Complete the finished run's ``tracks.csv`` offline (``wptrack.trackers.templates.backfill``): backfill the
        lasting tracks (``TemplateConfig.backfill_seconds``), stitch the tracks that continue each other
        (``stitch_seconds``), then smooth every track's positions over time (``smooth_seconds``,
        ``wptrack.core.smoothing``).

        Returns the run.json record: ``backfill_seconds, backfill_frames, backfill_min_frames, backfilled_rows,
        stitch_seconds, stitch_frames, stitch_distance, stitched_tracks, smooth_seconds, smooth_frames,
        smoothed_rows``.
        """
        from wptrack.io.tables import smooth_tracks_file
        from wptrack.trackers.templates.backfill import backfill_tracks_file, stitch_tracks_file
        from wptrack.trackers.templates.tracker import box_fraction_in_image

        cfg = self.tracker.config
        camera, plane = self.tracker.camera, self.tracker.plane
        least = max(float(cfg.min_in_image), 1e-9)  # min_in_image 0: some part of the box in the image

        def in_view(ground: np.ndarray, size: np.ndarray, heading: np.ndarray) -> np.ndarray:
            return box_fraction_in_image(camera, plane, ground, size, heading) >= least

        # from the run's first frame (0, never reported: the filter adds objects after a frame's estimate)
        added = backfill_tracks_file(
            path, plane.to_world, in_view, cfg.backfill_frames, int(cfg.backfill_min_frames), fps=cfg.frame_rate,
            first_frame=0,
        )  # fmt: skip
        stitched = stitch_tracks_file(path, cfg.stitch_frames, float(cfg.stitch_distance))
        smoothed = smooth_tracks_file(path, cfg.smooth_frames, ("x", "y", "z", "gx", "gy"))
        log.info(
            "%s: %d rows backfilled, %d tracks stitched to their predecessors, %d rows smoothed over +-%d frames",
            path, added, stitched, smoothed, cfg.smooth_frames,
        )  # fmt: skip
        return {
            "backfill_seconds": float(cfg.backfill_seconds),
            "backfill_frames": cfg.backfill_frames,
            "backfill_min_frames": int(cfg.backfill_min_frames),
            "backfilled_rows": added,
            "stitch_seconds": float(cfg.stitch_seconds),
            "stitch_frames": cfg.stitch_frames,
            "stitch_distance": float(cfg.stitch_distance),
            "stitched_tracks": stitched,
            "smooth_seconds": float(cfg.smooth_seconds),
            "smooth_frames": cfg.smooth_frames,
            "smoothed_rows": smoothed,
        }

    def summary(self) -> dict[str, Any]:
        seen = self._seen
        return {
            "frames": self.tracker.frames_done,
            "device": self.tracker.device,
            "objects": len(seen),
            "classes": {c: sum(1 for v in seen.values() if v == c) for c in CLASSES},
            "mean_penalty": self._penalty_sum / self._penalty_frames if self._penalty_frames else None,
            "degenerate_frames": self._degenerate,
            "flooded_frames": len(self._flood.flooded) if self._flood is not None else None,
            "virtual": self._virtual,
        }


def run_template_tracking(
    rig_path: str | Path,
    out_dir: str | Path,
    config: Any,
    video: str | Path | None = None,
    masks: str | Path | None = None,
    mask_config: Any = None,
    device: str = "auto",
    max_frames: int | None = None,
    save_masks: bool = False,
    virtual: bool | None = None,
    progress: bool = False,
    resume: bool = False,
    checkpoint_seconds: float = 60.0,
    overwrite: bool = False,
    flood_guard: bool = True,
) -> dict[str, Any]:
    """Track objects with the template tracker and write the run folder (see the module docstring and
    :class:`TemplateRun` for the arguments).

    ``resume``, ``checkpoint_seconds`` and ``overwrite``: see :func:`wptrack.runs.run_tracker`.

    Returns:
        The run summary (also in run.json).
    """
    job = TemplateRun(rig_path, config, video, masks, mask_config, device, max_frames, save_masks, virtual, flood_guard)
    return run_tracker(
        job,
        out_dir,
        progress=progress,
        max_frames=max_frames,
        resume=resume,
        checkpoint_seconds=checkpoint_seconds,
        overwrite=overwrite,
    )


@dataclass(frozen=True)
class TemplateInputs:
    """The inputs of a template run (``wptrack track templates``); the rig camera is the config's ``camera``."""

    rig: str = param(REQUIRED, help="rig file (YAML/JSON) with the camera and an optional 'ground' plane")
    video: tuple[str, ...] | None = param(
        None, help="the camera's video or image folder (motion masks by background subtraction)"
    )
    masks: tuple[str, ...] | None = param(
        None, help="binary motion masks (video or image folder, nonzero = foreground) instead of --video"
    )
    save_masks: bool = param(False, help="write the masks used to masks.avi")
    virtual: bool | None = param(
        None, help="write virtual.avi (the best particle's virtual image per frame); unset: only for frames up to "
        "640x480 pixels (its encoding costs more than the tracking above that)",
    )  # fmt: skip

    def __post_init__(self) -> None:
        check(self)


def run_template_job(
    inputs: TemplateInputs, config: Any, masks: Any, control: Any, progress: bool = False
) -> dict[str, Any]:
    """``wptrack track templates``: the run of :func:`run_template_tracking` from its declared parts (inputs, the
    tracker's config, the motion masks' config, the run control); the CLI and ``wptrack batch`` call this. Without a
    ``fps`` in the config, the frame rate is the video's (or the masks video's).

    Raises:
        ConfigError: more than one video or masks source (one camera), or neither.
    """
    from wptrack.io.frames import open_source

    sources = {}
    for flag in ("video", "masks"):  # one camera: a second --video must not silently replace the first
        given = getattr(inputs, flag)
        if given is not None and len(given) > 1:
            raise ConfigError(
                f"--{flag}: the template tracker follows one camera, got {len(given)} ({', '.join(given)}); give one "
                f"--{flag} and pick its rig camera with --camera NAME"
            )
        sources[flag] = given[0] if given else None
    if config.fps is None:  # the frame rate of the video, or of the given masks when they are a video
        source = sources["video"] if sources["video"] is not None else sources["masks"]
        fps = open_source(source).fps if source is not None else None
        if fps:
            config = replace(config, fps=float(fps))
    return run_template_tracking(
        inputs.rig,
        control.out,
        config,
        video=sources["video"],
        masks=sources["masks"],
        mask_config=replace(masks, device=control.device),
        device=control.device,
        max_frames=control.max_frames,
        save_masks=inputs.save_masks,
        virtual=inputs.virtual,
        progress=progress,
        resume=control.resume,
        checkpoint_seconds=control.checkpoint_every,
        overwrite=control.overwrite,
    )
