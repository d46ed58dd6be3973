"""Everything a report reads from a run directory (and its rig, videos and ground truth), validated.

Missing optional inputs (ground truth, videos, particles, rig) are recorded as notes, never errors; a folder that
is not a wptrack run, or a run of an unknown tracker, is a :class:`~wptrack.core.errors.WptrackError`.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError, OutputError, WptrackError
from wptrack.io.run import PARTICLES_FILE, RUN_FILE
from wptrack.io.tables import TRACKS_FILE, read_tracks

log = logging.getLogger(__name__)

GROUNDTRUTH_FILE = "groundtruth.csv"
SWEEP_FILE = "errors.csv"


@dataclass(frozen=True)
class Trajectory:
    """One object's positions over time.

    Attributes:
        id: Object id.
        frames: (N,) int frame numbers, increasing.
        xyz: (N, 3) positions, metres (NaN where unknown).
    """

    id: int
    frames: np.ndarray
    xyz: np.ndarray

    def at(self, frames: np.ndarray) -> np.ndarray:
        """Positions at the given frames, (len(frames), 3); NaN where this trajectory has no such frame."""
        out = np.full((len(frames), 3), np.nan)
        idx = np.searchsorted(self.frames, frames)
        idx = np.clip(idx, 0, max(len(self.frames) - 1, 0))
        if len(self.frames):
            ok = self.frames[idx] == frames
            out[ok] = self.xyz[idx[ok]]
        return out


@dataclass(frozen=True)
class Particles:
    """The particle subsample saved by a run (``particles.npz``).

    Attributes:
        frames: (F,) frame numbers.
        positions: (F, K, 3) metres (NaN rows pad frames with fewer particles).
        weights: (F, K) weights (NaN padding).
    """

    frames: np.ndarray
    positions: np.ndarray
    weights: np.ndarray

    def index_of(self, frame: int) -> int:
        """Index of the stored frame nearest to ``frame``."""
        return int(np.argmin(np.abs(self.frames.astype(np.int64) - int(frame))))

    def cloud(self, frame: int) -> tuple[np.ndarray, np.ndarray]:
        """``(positions (K', 3), weights (K',))`` of the stored frame nearest to ``frame``, padding removed."""
        i = self.index_of(frame)
        pos, w = self.positions[i], self.weights[i]
        ok = np.all(np.isfinite(pos), axis=1) & np.isfinite(w)
        return pos[ok].astype(np.float64), w[ok].astype(np.float64)


@dataclass
class RunData:
    """A run directory, loaded.

    Attributes:
        run_dir: The run folder.
        run: run.json contents.
        tracker: Tracker name (the registry key).
        tracks: tracks.csv columns.
        estimates: Estimated trajectories by object id (the ``x, y, z`` columns).
        particles: The saved particle clouds, or None.
        rig: The rig (``wptrack.cameras.rig.Rig``), or None when its file is gone.
        groundtruth: Ground-truth trajectories by object id, or None.
        groundtruth_path: Where the ground truth was read.
        videos: One frame source spec per camera (paths that exist), or None when any is missing.
        notes: Human-readable notes about what is missing (shown in the page).
    """

    run_dir: Path
    run: dict[str, Any]
    tracker: str
    tracks: dict[str, np.ndarray]
    estimates: dict[int, Trajectory]
    particles: Particles | None = None
    rig: Any = None
    groundtruth: dict[int, Trajectory] | None = None
    groundtruth_path: Path | None = None
    videos: list[str] | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def config(self) -> dict[str, Any]:
        """The run's resolved configuration (``run.json`` "config")."""
        cfg = self.run.get("config")
        return cfg if isinstance(cfg, dict) else {}

    @property
    def frames(self) -> np.ndarray:
        """Sorted distinct frame numbers of tracks.csv."""
        return np.unique(self.tracks["frame"]).astype(np.int64)

    def matched_truth(self, obj: int) -> Trajectory | None:
        """The ground-truth trajectory to compare with estimate ``obj`` (same id, or the only one), or None."""
        if not self.groundtruth:
            return None
        if obj in self.groundtruth:
            return self.groundtruth[obj]
        if len(self.groundtruth) == 1 and len(self.estimates) == 1:
            return next(iter(self.groundtruth.values()))
        return None


def trajectories(columns: dict[str, np.ndarray], source: Path) -> dict[int, Trajectory]:
    """Split ``frame,id,x,y,z`` columns into per-id trajectories sorted by frame."""
    for name in ("frame", "id", "x", "y", "z"):
        if name not in columns:
            raise OutputError(f"{source}: missing column '{name}' (expected frame,id,x,y,z,...)")
    try:
        frames = np.asarray(columns["frame"], dtype=np.int64)
        ids = np.asarray(columns["id"], dtype=np.int64)
        xyz = np.column_stack([np.asarray(columns[c], dtype=np.float64) for c in ("x", "y", "z")])
    except (TypeError, ValueError):
        raise OutputError(f"{source}: frame, id, x, y, z must be numbers") from None
    out = {}
    for obj in np.unique(ids):
        sel = ids == obj
        order = np.argsort(frames[sel], kind="stable")
        out[int(obj)] = Trajectory(int(obj), frames[sel][order], xyz[sel][order])
    return out


def _resolve_file(spec: str, run_dir: Path, rig_dir: Path | None) -> str | None:
    """Find a video/image spec: as given, then relative to the run folder and to the rig folder (by name)."""
    if any(ch in spec for ch in "*?"):
        import glob

        return spec if glob.glob(spec) else None
    p = Path(spec)
    candidates = [p]
    if not p.is_absolute():
        candidates.append(run_dir / p)
    if rig_dir is not None:
        candidates.append(rig_dir / p.name)
    for c in candidates:
        if c.exists():
            return str(c)
    return None


def load_run(run_dir: str | Path, known: list[str] | None = None) -> RunData:
    """Load a run directory for a report.

    Args:
        run_dir: Folder written by ``wptrack track ...``.
        known: Tracker names that have a reporter (for the error message; None skips the check).

    Returns:
        The loaded run (notes list what is missing).

    Raises:
        OutputError: Not a run folder (no run.json / tracks.csv), unreadable or empty outputs.
        ConfigError: The run is from a tracker without a reporter.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise OutputError(f"run directory not found: {run_dir}")
    run_path = run_dir / RUN_FILE
    if not run_path.is_file():
        raise OutputError(
            f"{run_dir} has no {RUN_FILE}: not a wptrack run directory (run 'wptrack track ... --out {run_dir}' "
            f"first, or give a sweep folder with {SWEEP_FILE})"
        )
    try:
        run = json.loads(run_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise OutputError(f"cannot read {run_path}: {e}") from None
    if not isinstance(run, dict) or not isinstance(run.get("tracker"), str):
        raise OutputError(f"{run_path}: no 'tracker' field (not written by wptrack)")
    tracker = run["tracker"]
    if known is not None and tracker not in known:
        raise ConfigError(
            f"{run_path}: no report for tracker '{tracker}' (reports exist for: {', '.join(sorted(known))})"
        )
    tracks_path = run_dir / str((run.get("files") or {}).get("tracks") or TRACKS_FILE)
    if not tracks_path.is_file():
        raise OutputError(f"{run_dir} has no {tracks_path.name}: the run wrote no tracks")
    try:
        tracks = read_tracks(tracks_path)
    except WptrackError as e:
        raise OutputError(str(e)) from None
    if len(tracks.get("frame", ())) == 0:
        raise OutputError(f"{tracks_path} has no rows: nothing to report (run status: {run.get('status')})")
    data = RunData(run_dir, run, tracker, tracks, trajectories(tracks, tracks_path))
    if run.get("status") != "complete":
        data.notes.append(f"the run's status is '{run.get('status')}': the report shows the frames written so far")
    _load_particles(data)
    _load_rig(data)
    _load_groundtruth(data)
    _load_videos(data)
    return data


def _load_particles(data: RunData) -> None:
    listed = (data.run.get("files") or {}).get("particles")
    path = data.run_dir / str(listed or PARTICLES_FILE)
    if not path.is_file():
        if listed or data.tracker == "color":  # a run that saves none (people, templates) needs no note
            data.notes.append(f"no {PARTICLES_FILE}: particle clouds are left out")
        return
    try:
        with np.load(path) as z:
            frames = np.asarray(z["frames"], dtype=np.int64)
            positions = np.asarray(z["positions"], dtype=np.float64)
            weights = np.asarray(z["weights"], dtype=np.float64)
    except (OSError, KeyError, ValueError) as e:
        data.notes.append(f"cannot read {path.name} ({e}): particle clouds are left out")
        return
    if frames.size == 0 or positions.ndim != 3 or positions.shape[:2] != weights.shape:
        data.notes.append(f"{path.name} holds no particles: particle clouds are left out")
        return
    order = np.argsort(frames, kind="stable")
    data.particles = Particles(frames[order], positions[order], weights[order])


def _load_rig(data: RunData) -> None:
    from wptrack.cameras.rig import Rig

    rig_spec = data.config.get("rig")
    if not rig_spec:
        data.notes.append("run.json names no rig: camera frusta and overlays are left out")
        return
    path = Path(str(rig_spec))
    if not path.is_absolute() and not path.exists():
        path = data.run_dir / path
    try:
        data.rig = Rig.load(path)
    except WptrackError as e:
        data.notes.append(f"rig not available ({e}): camera frusta and overlays are left out")


def _load_groundtruth(data: RunData) -> None:
    candidates = [data.run_dir / GROUNDTRUTH_FILE]
    rig_spec = data.config.get("rig")
    if rig_spec:
        candidates.append(Path(str(rig_spec)).parent / GROUNDTRUTH_FILE)
    path = next((c for c in candidates if c.is_file()), None)
    if path is None:
        data.notes.append(f"no {GROUNDTRUTH_FILE} in the run folder or beside the rig: errors are left out")
        return
    try:
        data.groundtruth = trajectories(read_tracks(path), path)
        data.groundtruth_path = path
    except WptrackError as e:
        data.notes.append(f"cannot read ground truth {path} ({e}): errors are left out")


def _load_videos(data: RunData) -> None:
    specs = data.config.get("videos")
    if not specs:
        data.notes.append("run.json names no videos: overlays on the frames are left out")
        return
    rig_dir = Path(str(data.config["rig"])).parent if data.config.get("rig") else None
    found = [_resolve_file(str(s), data.run_dir, rig_dir) for s in specs]
    missing = [str(s) for s, f in zip(specs, found, strict=True) if f is None]
    if missing:
        data.notes.append(f"video(s) not found: {', '.join(missing)}: overlays on the frames are left out")
        return
    data.videos = [f for f in found if f is not None]


def find_sweep(path: str | Path) -> Path | None:
    """``errors.csv`` of a sigma sweep: the file itself or inside the folder; None if there is none."""
    p = Path(path)
    if p.is_file() and p.suffix.lower() == ".csv":
        return p
    if p.is_dir() and (p / SWEEP_FILE).is_file():
        return p / SWEEP_FILE
    return None


def load_sweep(path: str | Path) -> dict[str, Any]:
    """Read a sigma-sweep ``errors.csv`` (from ``wptrack convergence``) and its ``summary.json`` if present.

    Returns:
        ``{"path", "sigmas" (S,), "errors" (S, I) metres, "summary" (dict or None)}``.

    Raises:
        ConfigError: No errors.csv there, or it cannot be parsed.
    """
    from wptrack.trackers.colour.sweep import read_sweep

    csv_path = find_sweep(path)
    if csv_path is None:
        raise ConfigError(f"no sigma sweep at {path}: expected {SWEEP_FILE} from 'wptrack convergence --out DIR'")
    try:
        table = read_sweep(csv_path)
    except KeyError as e:  # another table (a groundtruth.csv): name the column, not just the key
        raise ConfigError(
            f"cannot read sigma sweep {csv_path}: missing column {e} (expected {SWEEP_FILE} from 'wptrack convergence "
            f"--out DIR')"
        ) from None
    except (OSError, ValueError) as e:
        raise ConfigError(f"cannot read sigma sweep {csv_path}: {e}") from None
    summary = None
    sj = csv_path.parent / "summary.json"
    if sj.is_file():
        try:
            summary = json.loads(sj.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            summary = None
    return {"path": csv_path, "sigmas": table["sigmas"], "errors": table["errors"], "summary": summary}
