"""A template run read back for its report: objects per frame from tracks.csv / best.csv, ground truth, videos
(``TemplateRun``, :func:`template_run`)."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.errors import WptrackError
from wptrack.report import scene3d
from wptrack.report.calibration import _camera_for
from wptrack.report.data import GROUNDTRUTH_FILE, RunData, _resolve_file, trajectories
from wptrack.report.model import ReportContext
from wptrack.trackers.templates.geometry import DEFAULT_HEAD_RADIUS

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TemplateObject:
    """One object to draw (from tracks.csv / best.csv).

    Attributes:
        id: Object label.
        cls: ``"human"`` or ``"vehicle"``.
        ground: (2,) ground-contact point in ground-plane coordinates, metres.
        dims: Template dims: human (height, body radius, head radius), vehicle (length, width, height), metres.
        heading: Orientation in the ground plane, radians.
        existence: Existence probability (1 where unknown).
        speed: m/s (NaN where unknown).
    """

    id: int
    cls: str
    ground: np.ndarray
    dims: tuple[float, float, float]
    heading: float
    existence: float = 1.0
    speed: float = float("nan")


@dataclass
class TemplateRun:
    """What the template report reads from a run, resolved once per report (:func:`template_run`).

    Attributes:
        data: The loaded run.
        camera: The tracking camera at the run's frame size, or None without a rig.
        plane: The ground plane (z = 0 without a rig).
        video: The camera's video (resolved path), or None.
        masks: Motion masks: the run's ``masks.avi`` or the masks given as input, or None.
        virtual: The run's ``virtual.avi``, or None.
        tracks: tracks.csv columns.
        best: best.csv columns, or None.
        truth: Ground-truth columns (``frame,id,x,y,z[,class,...]``), or None.
        n_frames: Frames processed by the run.
        fps: Frame rate of the run, frames per second.
        head_radius: Head radius drawn for humans (tracks.csv does not store it), metres.
        notes: What is missing or unreadable (shown in the calibration section).
    """

    data: RunData
    camera: Any
    plane: Any
    video: str | None
    masks: str | None
    virtual: str | None
    tracks: dict[str, np.ndarray]
    best: dict[str, np.ndarray] | None
    truth: dict[str, np.ndarray] | None
    n_frames: int
    fps: float
    head_radius: float
    notes: list[str] = field(default_factory=list)

    @property
    def ids(self) -> list[int]:
        """Object ids of tracks.csv, sorted."""
        return sorted(int(i) for i in np.unique(self.tracks["id"]))

    def objects_at(self, frame: int, best: bool = False) -> list[TemplateObject]:
        """The objects of tracks.csv (or best.csv) at ``frame``."""
        table = self.best if best else self.tracks
        if table is None or "frame" not in table:
            return []
        return _objects(table, np.flatnonzero(table["frame"] == frame), self.plane, self.head_radius)

    def truth_at(self, frame: int) -> list[tuple[int, str, np.ndarray]]:
        """Ground truth at ``frame``: ``(id, class, ground point (2,))``."""
        t = self.truth
        if t is None:
            return []
        rows = np.flatnonzero(t["frame"] == frame)
        xyz = np.column_stack([t["x"][rows], t["y"][rows], t["z"][rows]]).astype(np.float64)
        g = self.plane.to_ground(xyz)
        cls = t["class"][rows] if "class" in t else np.full(len(rows), "")
        return [(int(t["id"][r]), str(c), g[k]) for k, (r, c) in enumerate(zip(rows, cls, strict=True))]

    def source_image(self) -> str | None:
        """The frames shown under overlays: the video, else the motion masks."""
        return self.video or self.masks


def _objects(table: dict[str, np.ndarray], rows: np.ndarray, plane: Any, head_r: float) -> list[TemplateObject]:
    out = []
    for r in rows:
        cls = str(table["class"][r]) if "class" in table else "human"
        if "gx" in table and "gy" in table:
            g = np.array([table["gx"][r], table["gy"][r]], dtype=np.float64)
        else:
            g = plane.to_ground(np.array([table["x"][r], table["y"][r], table["z"][r]], dtype=np.float64))
        length, width, height = (float(table[c][r]) for c in ("length", "width", "height"))
        dims = (height, 0.5 * length, head_r) if cls == "human" else (length, width, height)
        out.append(
            TemplateObject(
                id=int(table["id"][r]),
                cls=cls,
                ground=g,
                dims=dims,
                heading=float(table["orientation"][r]) if "orientation" in table else 0.0,
                existence=float(table["existence"][r]) if "existence" in table else 1.0,
                speed=float(table["speed"][r]) if "speed" in table else float("nan"),
            )
        )
    return out


_DROPPED_NOTES = ("no particles.npz", "run.json names no videos")


def template_run(ctx: ReportContext) -> TemplateRun:
    """Resolve the run's camera, ground plane, videos, best.csv and ground truth (cached in ``ctx.cache``).

    Notes of the generic loader that do not apply to template runs (no particles file, a single ``video``
    entry) are removed from ``ctx.data.notes``; when the loader found no ground truth, ``../scene/groundtruth.csv``
    beside the run folder is used (and recorded in ``ctx.data``).

    Args:
        ctx: The report context of a run (``ctx.data`` set).

    Returns:
        The resolved run; missing inputs are None and listed in its ``notes``.
    """
    if "templates" in ctx.cache:
        return ctx.cache["templates"]
    from wptrack.cameras.rig import GroundPlane
    from wptrack.io.tables import read_tracks

    data = ctx.data
    assert data is not None
    cfg = data.config
    data.notes[:] = [n for n in data.notes if not n.startswith(_DROPPED_NOTES)]
    notes: list[str] = []
    camera = None
    plane = GroundPlane()
    if data.rig is not None:
        plane = data.rig.ground_plane
        try:
            camera = data.rig[cfg.get("camera", 0)]
            size = cfg.get("frame_size")
            if isinstance(size, (list, tuple)) and len(size) == 2:
                camera = _camera_for(camera, int(size[0]), int(size[1]))
        except (WptrackError, ValueError, TypeError) as e:  # an unknown camera, a frame size of another aspect
            notes.append(f"camera not usable ({e}): projections are left out")
            camera = None
    rig_dir = Path(str(cfg["rig"])).parent if cfg.get("rig") else None

    def resolve(spec: Any) -> str | None:
        if not spec:
            return None
        found = _resolve_file(str(spec), data.run_dir, rig_dir)
        if found is None:
            notes.append(f"{spec} not found")
        return found

    video = resolve(cfg.get("video"))
    masks = str(data.run_dir / "masks.avi") if (data.run_dir / "masks.avi").is_file() else resolve(cfg.get("masks"))
    virtual = str(data.run_dir / "virtual.avi") if (data.run_dir / "virtual.avi").is_file() else None
    best = None
    if (data.run_dir / "best.csv").is_file():
        try:
            best = read_tracks(data.run_dir / "best.csv")
        except WptrackError as e:  # a damaged best.csv only removes a curve
            notes.append(f"cannot read best.csv ({e})")
    if data.groundtruth is None:
        fallback = data.run_dir.resolve().parent / "scene" / GROUNDTRUTH_FILE
        if fallback.is_file():
            try:
                data.groundtruth = trajectories(read_tracks(fallback), fallback)
                data.groundtruth_path = fallback
                data.notes[:] = [n for n in data.notes if not n.startswith(f"no {GROUNDTRUTH_FILE}")]
            except WptrackError as e:
                notes.append(f"cannot read ground truth {fallback} ({e})")
    truth = None
    if data.groundtruth_path is not None:
        try:
            truth = read_tracks(data.groundtruth_path)
        except WptrackError as e:
            notes.append(f"cannot read ground truth {data.groundtruth_path} ({e})")
    tcfg = cfg.get("tracker") if isinstance(cfg.get("tracker"), dict) else {}
    head_r = DEFAULT_HEAD_RADIUS
    try:
        head_r = float(((tcfg.get("human") or {}).get("dims_mean") or [0, 0, DEFAULT_HEAD_RADIUS])[2])
    except (TypeError, ValueError, IndexError):
        pass
    summary = data.run.get("summary") if isinstance(data.run.get("summary"), dict) else {}
    n_frames = int(data.frames.max()) + 1
    if isinstance(summary.get("frames"), int):
        n_frames = max(n_frames, int(summary["frames"]))
    fps = float(tcfg.get("fps") or 15.0)
    run = TemplateRun(data, camera, plane, video, masks, virtual, data.tracks, best, truth, n_frames, fps, head_r)
    run.notes = notes
    ctx.cache["templates"] = run
    return run


def _read(ctx: ReportContext, spec: str | None, frames: Sequence[int]) -> dict[int, np.ndarray]:
    """Frames of one video (cached per file in ``ctx.cache``)."""
    if spec is None:
        return {}
    key = ("frames", spec)
    have: dict[int, np.ndarray] = ctx.cache.setdefault(key, {})
    missing = [f for f in frames if f not in have]
    if missing:
        with ctx.timed("reading frames"):
            try:
                got = scene3d.read_frames([spec], missing)
            except (WptrackError, OSError) as e:  # an unreadable video leaves figures out
                log.warning("cannot read %s: %s", spec, e)
                got = {}
        have.update({f: imgs[0] for f, imgs in got.items()})
    return {f: have[f] for f in frames if f in have}


# --------------------------------------------------------------------------------------- overlays
