"""Running the S2 people tracker on synchronised videos of two or more cameras, writing the run folder as it goes.

Outputs::

    out_dir/tracks.csv     frame,id,x,y,z,sx,sy,sz,map_x,map_y,map_z,ess,loglik,age,cloud_z,top,degenerate: x, y, z
                           the person's 3D centroid (BodyConfig), cloud_z the particles' mean height (the paper's
                           estimate), top the top of the person's silhouette column (metres; empty when not found),
                           degenerate 1 when every particle of the person had zero likelihood (log-weights -inf/NaN:
                           the predicted particles were kept with uniform weights, the prior)
    out_dir/hulls/         per (frame, person) the convex hull of the smallest particle set holding P_H of the
                           weight (section 4), streamed to one .npz per 500 frames (``wptrack.io.chunklog``; memory
                           bounded): rows (frame, id, start, count) into a (V, 3) vertex array, metres; read
                           them with ``wptrack.io.chunklog.read_chunks``
    out_dir/occupancy.npz  every ``occupancy_every`` frames, each person's occupancy pdf on a voxel grid (float16,
                           1 / m^3) with its origin and voxel edge (Figs. 6 and 8)
    out_dir/masks_camK.avi the motion masks used (only with ``save_masks``; 0/255 grey frames as 1-bit PNG images)
    out_dir/run.json       configuration, inputs, device, versions, timings, summary

When the run completes, ``tracks.csv``'s positions are smoothed over time (``PeopleConfig.smooth_seconds``).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.config import REQUIRED, check, param
from wptrack.core.errors import ConfigError
from wptrack.runs.loop import TrackerRun, run_tracker

log = logging.getLogger(__name__)

PEOPLE_COLUMNS = [
    "frame",
    "id",
    "x",
    "y",
    "z",
    "sx",
    "sy",
    "sz",
    "map_x",
    "map_y",
    "map_z",
    "ess",
    "loglik",
    "age",
    "cloud_z",
    "top",
    "degenerate",
]
HULLS_DIR = "hulls"
OCCUPANCY_FILE = "occupancy.npz"


def hull_points(points: np.ndarray, weights: np.ndarray, p_h: float) -> np.ndarray:
    """The vertices of the convex hull of the smallest set of particles holding at least ``p_h`` of the weight
    (section 4's bounding volume V_k), by scipy's Qhull (``scipy.spatial.ConvexHull``).

    Args:
        points: (K, 3) particles, metres. weights: (K,) non-negative weights (any scale). p_h: fraction in (0, 1).

    Returns:
        (V, 3) hull vertices, metres (fewer than 4 points or a flat set: the points themselves).
    """
    from scipy.spatial import ConvexHull, QhullError

    w = np.asarray(weights, dtype=np.float64)
    ok = np.isfinite(w) & np.all(np.isfinite(points), axis=1) & (w > 0)
    pts, w = np.asarray(points, dtype=np.float64)[ok], w[ok]
    if not len(pts):
        return np.zeros((0, 3))
    order = np.argsort(-w, kind="stable")
    cum = np.cumsum(w[order])
    k = int(np.searchsorted(cum, p_h * cum[-1])) + 1
    sel = pts[order[:k]]
    if len(sel) < 4:
        return sel
    try:
        return sel[ConvexHull(sel).vertices]
    except QhullError:  # all points on a plane or a line
        return sel


def recording_fps(given: float | None, frames: Any) -> float:
    """The frame rate of a run: ``given`` (``--fps``) if set, else the videos' own (the first camera's that knows
    one; ``wptrack.io.frames.SyncedFrames`` warns when they differ).

    Raises:
        ConfigError: no rate given and none known (image folders and arrays carry none).
    """
    if given is not None:
        return float(given)
    for source in frames.sources:
        if getattr(source, "fps", None):
            return float(source.fps)
    names = ", ".join(str(n) for n in frames.names)
    raise ConfigError(
        f"the frame rate of {names} is unknown (image folders carry none): give it with --fps (PeopleConfig.fps); "
        "the dynamics and the birth and removal times are in seconds"
    )


class _Thinned:
    """Keyframes kept in memory with a bounded count: past ``cap`` entries every other one is dropped."""

    def __init__(self, cap: int) -> None:
        self.cap = cap
        self.items: list[tuple[int, Any]] = []

    def add(self, frame: int, item: Any) -> None:
        self.items.append((frame, item))
        if len(self.items) > self.cap:
            self.items = self.items[::2]


class PeopleRun(TrackerRun):
    """The S2 people tracker as a run-loop job. Everything the user gave is validated here (rig, videos, masks,
    sizes, device, parameters), before the run loop touches the output folder.

    Args:
        rig_path: rig file (YAML/JSON) of two or more cameras; its working volume bounds where people are found.
        videos: one video / image folder / glob per camera, in rig order.
        config: ``PeopleConfig``.
        mask_config: ``wptrack.motion.masks.MaskConfig`` of the motion masks made from the videos.
        masks: given motion masks instead (one source per camera, rig order), or None.
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``.
        stop_at_shortest: track the common part of videos of unequal lengths.
        max_frames: stop after this many frames.
        occupancy_every: write the occupancy grids every this many frames (0: never).
        save_masks: also write the motion masks used (``masks_<camera>.avi``).
    """

    name = "people"
    columns = PEOPLE_COLUMNS

    def __init__(
        self,
        rig_path: str | Path,
        videos: Sequence,
        config: Any,
        mask_config: Any = None,
        masks: Sequence | None = None,
        device: str = "auto",
        stop_at_shortest: bool = False,
        max_frames: int | None = None,
        occupancy_every: int = 10,
        save_masks: bool = False,
    ) -> None:
        from wptrack.cameras.rig import Rig
        from wptrack.core.device import resolve_device
        from wptrack.io.frames import open_frames
        from wptrack.motion.masks import MaskConfig, open_masks
        from wptrack.trackers.people.tracker import PeopleTracker

        rig = Rig.load(rig_path)
        if len(rig) < 2:
            raise ConfigError(f"the people tracker needs two or more cameras; {rig_path} has {len(rig)}")
        if len(videos) != len(rig):
            raise ConfigError(
                f"{len(videos)} video(s) given for a rig of {len(rig)} camera(s) in {rig_path} ({', '.join(rig.names)})"
            )
        if masks is not None and len(masks) != len(rig):
            raise ConfigError(f"{len(masks)} mask source(s) given for a rig of {len(rig)} camera(s) in {rig_path}")
        if not isinstance(occupancy_every, int) or occupancy_every < 0:
            raise ConfigError(f"occupancy_every: expected frames >= 0, got {occupancy_every!r}")
        self._frames = open_frames(list(videos), stop_at_shortest=stop_at_shortest, max_frames=max_frames)
        rig = rig.at_sizes(self._frames.sizes, [str(n) for n in self._frames.names])  # a resized copy: K scaled
        config = replace(config, fps=recording_fps(config.fps, self._frames))
        mask_config = mask_config if mask_config is not None else MaskConfig()
        self._masks = [
            open_masks(masks=masks[i], config=mask_config, camera=cam, rig_source=rig.source)
            if masks is not None
            else open_masks(video=videos[i], config=mask_config, camera=cam, rig_source=rig.source)
            for i, cam in enumerate(rig.cameras)
        ]
        for m, name in zip(self._masks, rig.names, strict=True):
            if len(m) < len(self._frames):
                raise ConfigError(
                    f"motion masks of camera '{name}' ({m.name}): {len(m)} frames, fewer than the videos' "
                    f"{len(self._frames)}"
                )
        self.tracker = PeopleTracker(rig, config, device=resolve_device(device), keep_particles=config.particles)
        self.total = len(self._frames)
        self._occupancy_every = occupancy_every
        self._save_masks = save_masks
        self._names = rig.names
        self._fps = config.fps
        self.config = {
            "rig": str(Path(rig_path).resolve()),
            "videos": [str(v) for v in videos],
            "masks": [str(m) for m in masks] if masks is not None else None,
            "mask": asdict(mask_config),
            "tracker": asdict(config),
            "occupancy_every": occupancy_every,
        }
        self._hulls: Any = None  # ChunkLog, opened by start()
        self._occupancy = _Thinned(cap=300)
        self._ids: dict[int, int] = {}  # id -> frames tracked
        self._degenerate = 0  # (frame, person) estimates with all log-weights -inf/NaN
        self._out_dir: Path | None = None
        self._mask_writers: list[Any] = []
        self._frame_masks: list[np.ndarray] = []

    def info(self) -> dict[str, Any]:
        tr = self.tracker
        return {"device": tr.device, "seed": tr.config.seed, "cameras": self._names}

    source_stage = "gather"  # the run loop's prefetch thread only pairs the cameras' frames and masks

    def frames(self) -> Iterator[Any]:
        """The cameras' frames and each camera's masks, each made ahead in a thread of its own (issue 27: the cameras'
        masks were made one after another in one thread), bounded queues of 2."""
        from wptrack.io.prefetch import prefetch

        streams = [prefetch(self._frames, depth=2, name="decode")]
        streams += [prefetch(m, depth=2, name="masks") for m in self._masks]
        return zip(*streams, strict=False)  # the masks may run longer (checked: not shorter)

    def start(self, out_dir: Path, resume_after: int | None = None) -> None:
        from wptrack.io.chunklog import ChunkLog
        from wptrack.io.video import continue_video

        self._out_dir = out_dir
        self._hulls = ChunkLog(out_dir / HULLS_DIR, resume_after=resume_after)
        if resume_after is not None:
            self._load_npz_logs(out_dir, resume_after)
        if self._save_masks:  # a resumed run rewrites them: the frames up to the resume point, then the new ones
            keep = 0 if resume_after is None else resume_after + 1
            self._mask_writers = [
                continue_video(out_dir / f"masks_{n}.avi", keep, fps=self._fps, grey=True, codec="PNG", bilevel=True)
                for n in self._names
            ]

    def step(self, item: Any) -> Any:
        images, *masks = item
        self._frame_masks = masks
        every = self._occupancy_every
        return self.tracker.step(images, masks, occupancy=bool(every) and self.tracker.frames_done % every == 0)

    def record(self, est: Any, out: Any) -> None:
        p_h = self.tracker.config.occupancy.p_h
        rows = []
        for person in est.people:
            rows.append(
                [est.frame, person.id, *person.centroid, *person.std, *person.map, person.ess, person.loglik]
                + [person.age, person.mean[2], person.top if np.isfinite(person.top) else None]
                + [int(person.degenerate)]
            )
            self._ids[person.id] = self._ids.get(person.id, 0) + 1
            self._degenerate += int(person.degenerate)
            if person.particles is not None:
                self._hulls.add(est.frame, person.id, hull_points(person.particles, person.weights, p_h))
        out.add_rows(rows)
        grids = [(p.id, *p.occupancy) for p in est.people if p.occupancy is not None]  # computed with the frame
        if grids:
            self._occupancy.add(est.frame, grids)
        for writer, m in zip(self._mask_writers, self._frame_masks, strict=False):
            writer.write((np.asarray(m) != 0).astype(np.uint8) * np.uint8(255))  # 1-bit PNG images, encoded in threads
        if est.frame % 100 == 99:
            self.flush()

    # --- the npz logs (hulls streamed in chunks, occupancy rewritten atomically) ------------------------
    def flush(self) -> None:
        from wptrack.io.atomic import atomic_save_npz

        if self._out_dir is None:
            return
        self._hulls.flush()
        rows, origins, grids = [], [], []
        for frame, people in self._occupancy.items:
            for pid, origin, grid in people:
                rows.append((frame, pid))
                origins.append(origin)
                grids.append(grid.astype(np.float16))
        voxel = self.tracker.config.occupancy.voxel
        atomic_save_npz(
            self._out_dir / OCCUPANCY_FILE,
            index=np.asarray(rows, dtype=np.int64).reshape(-1, 2),
            origin=np.asarray(origins, dtype=np.float64).reshape(-1, 3),
            grid=np.stack(grids) if grids else np.zeros((0, 1, 1, 1), dtype=np.float16),
            voxel=np.float64(voxel),
        )

    def _load_npz_logs(self, out_dir: Path, after: int) -> None:
        op = out_dir / OCCUPANCY_FILE
        if op.exists():
            with np.load(op) as z:
                by_frame: dict[int, list] = {}
                for (frame, pid), origin, grid in zip(z["index"], z["origin"], z["grid"], strict=True):
                    if frame <= after:
                        by_frame.setdefault(int(frame), []).append((int(pid), origin, grid))
                for frame, people in by_frame.items():
                    self._occupancy.add(frame, people)

    def finish(self) -> None:
        self.flush()
        if self._hulls is not None:
            self._hulls.close()
        for writer in self._mask_writers:
            writer.close()

    def finish_tracks(self, path: Path) -> dict[str, Any]:
        """Smooth the completed run's ``tracks.csv`` over time (``PeopleConfig.smooth_seconds``,
        ``wptrack.core.smoothing``); the run.json record ``smooth_seconds, smooth_frames, smoothed_rows``."""
        from wptrack.io.tables import smooth_tracks_file

        cfg = self.tracker.config
        frames = int(round(cfg.smooth_seconds * float(self._fps)))
        rows = smooth_tracks_file(path, frames, ("x", "y", "z"))
        log.info("%s: %d rows smoothed over +-%d frames", path, rows, frames)
        return {"smooth_seconds": float(cfg.smooth_seconds), "smooth_frames": frames, "smoothed_rows": rows}

    def state_dict(self) -> dict[str, Any]:
        ids = sorted(self._ids)
        return {
            **self.tracker.state_dict(),
            "job.ids": np.asarray(ids, dtype=np.int64),
            "job.frames": np.asarray([self._ids[i] for i in ids], dtype=np.int64),
            "job.degenerate": np.int64(self._degenerate),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.tracker.load_state_dict({k: v for k, v in state.items() if not k.startswith("job.")})
        self._ids = {int(i): int(n) for i, n in zip(state["job.ids"], state["job.frames"], strict=True)}
        self._degenerate = int(state["job.degenerate"])

    def summary(self) -> dict[str, Any]:
        return {
            "frames": self.tracker.frames_done,
            "device": self.tracker.device,
            "people": len(self._ids),
            "frames_per_person": {str(k): v for k, v in sorted(self._ids.items())},
            "degenerate_estimates": self._degenerate,
            "births_refused": self.tracker.births_refused,
        }


def run_people_tracking(
    rig_path: str | Path,
    videos: Sequence,
    out_dir: str | Path,
    config: Any,
    mask_config: Any = None,
    masks: Sequence | None = None,
    device: str = "auto",
    stop_at_shortest: bool = False,
    max_frames: int | None = None,
    occupancy_every: int = 10,
    save_masks: bool = False,
    progress: bool = False,
    resume: bool = False,
    checkpoint_seconds: float = 60.0,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Track people in synchronised videos of two or more cameras and write the run folder (see the module
    docstring and :class:`PeopleRun`; ``resume``, ``checkpoint_seconds`` and ``overwrite``:
    :func:`wptrack.runs.run_tracker`).

    Returns:
        The run summary (also in run.json).
    """
    job = PeopleRun(
        rig_path, videos, config, mask_config, masks, device, stop_at_shortest, max_frames, occupancy_every, save_masks
    )
    return run_tracker(
        job, out_dir, progress=progress, resume=resume, checkpoint_seconds=checkpoint_seconds, overwrite=overwrite
    )


@dataclass(frozen=True)
class PeopleInputs:
    """The inputs of a people run (``wptrack track people``)."""

    rig: str = param(REQUIRED, help="rig file (YAML/JSON) with two or more cameras")
    video: tuple[str, ...] = param(REQUIRED, help="video per camera, in rig order (repeat --video)")
    masks: tuple[str, ...] | None = param(None, help="given motion masks per camera, in rig order (repeat --masks)")
    occupancy_every: int = param(10, help="occupancy grids every this many frames (0: none)", units="frames", lo=0)
    save_masks: bool = param(False, help="write the masks used to masks_<camera>.avi")
    stop_at_shortest: bool = param(False, help="track the common part of videos of unequal lengths")

    def __post_init__(self) -> None:
        check(self)


def run_people_job(
    inputs: PeopleInputs, config: Any, masks: Any, control: Any, progress: bool = False
) -> dict[str, Any]:
    """``wptrack track people``: the run of :func:`run_people_tracking` from its declared parts (inputs, the
    tracker's config, the motion masks' config, the run control); the CLI and ``wptrack batch`` call this."""
    return run_people_tracking(
        inputs.rig,
        list(inputs.video),
        control.out,
        config,
        mask_config=replace(masks, device=control.device),
        masks=list(inputs.masks) if inputs.masks else None,
        device=control.device,
        stop_at_shortest=inputs.stop_at_shortest,
        max_frames=control.max_frames,
        occupancy_every=inputs.occupancy_every,
        save_masks=inputs.save_masks,
        progress=progress,
        resume=control.resume,
        checkpoint_seconds=control.checkpoint_every,
        overwrite=control.overwrite,
    )
