"""Run outputs, written as the run goes.

Every file is either appended to line by line (``tracks.csv``, flushed after each batch of rows) or replaced
atomically (``run.json``, ``particles.npz``: written to a temporary file in the same folder, fsync'ed, then
renamed over the old one), so an interrupted run (Ctrl-C, crash) leaves valid partial results and never a
half-written file.

Files of a run directory (see :class:`RunWriter`):

* ``run.json``: tracker, status (``running`` / ``complete`` / ``interrupted`` / ``failed``), config, versions,
  start/finish times, frames written and the last frame written (``last_frame``), per-stage timings, summary; the
  run loop adds ``stopped_early`` (where a truncated source ended, or None).
* ``tracks.csv``: one line per (frame, target): ``frame,id,x,y,z`` then tracker-specific columns. A tracker that
  confirms tracks offline (the template tracker's ``min_track_frames``) has the completed run's short tracks left
  out of it, with every row kept in ``tracks_all.csv`` (:func:`drop_short_tracks`: copy, then atomic replace).
* ``particles.npz``: subsampled particle clouds of some frames.

Memory stays bounded however long the run: rows go to disk as they come, the particle clouds kept for
``particles.npz`` are capped (:class:`RunWriter`'s ``particles_frames``: past the cap the kept frames are thinned
to every other one, see :class:`ParticleStore`), and the per-stage timings are running statistics
(:class:`StageTimer`: exact totals and means, the median of a bounded reservoir).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import logging
import math
import os
import platform
import random
import time
from collections.abc import Callable, Iterable, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.errors import OutputError
from wptrack.io.atomic import atomic_save_npz, atomic_write_json, copy_atomic, ensure_writable_dir, jsonable
from wptrack.io.tables import (
    BASE_COLUMNS,
    TRACKS_ALL_FILE,
    TRACKS_FILE,
    drop_short_tracks,
    format_cell,
    read_tracks,
    truncate_csv_after,
)

log = logging.getLogger(__name__)

RUN_FILE = "run.json"


PARTICLES_FILE = "particles.npz"


def versions() -> dict[str, str | None]:
    """Versions of wptrack, warp, numpy, cv2 (OpenCV) and Python; ``None`` for a package that is not installed."""
    from wptrack import __version__

    out: dict[str, str | None] = {"wptrack": __version__}
    for key, module in (("warp", "warp"), ("numpy", "numpy"), ("cv2", "cv2")):
        try:
            mod = __import__(module)
            out[key] = str(getattr(mod, "__version__", None) or getattr(getattr(mod, "config", None), "version", None))
        except Exception:  # a broken optional install must not stop a run
            out[key] = None
    out["python"] = platform.python_version()
    return out


def _now() -> str:
    """Local time, ISO 8601 with offset, to the second."""
    return datetime.now(timezone.utc).astimezone().isoformat(timespec="seconds")


class StageTimer:
    """Running statistics of one stage's durations, in bounded memory.

    ``total_s``, ``count`` and ``mean_ms`` are exact. ``median_ms`` is exact up to ``reservoir`` samples; past that it
    is the median of a uniform random sample of ``reservoir`` durations (Vitter's Algorithm R with a fixed seed, so
    a run's run.json is reproducible): with the default 4096 samples the reported median lies between the true
    49th and 51st percentiles with probability > 0.95 (the rank of a sample median has standard error
    ``0.5 / sqrt(4096)`` = 0.8 %).

    Args:
        reservoir: Samples kept (>= 1).
        seed: Seed of the replacement choices.
    """

    def __init__(self, reservoir: int = 4096, seed: int = 0) -> None:
        if reservoir < 1:
            raise ValueError(f"reservoir must be >= 1, got {reservoir}")
        self.total = 0.0
        self.count = 0
        self._samples = np.empty(int(reservoir), dtype=np.float64)
        self._rng = random.Random(seed)

    def add(self, seconds: float) -> None:
        """Add one duration (seconds)."""
        v = float(seconds)
        self.total += v
        size = self._samples.shape[0]
        if self.count < size:
            self._samples[self.count] = v
        else:
            j = self._rng.randrange(self.count + 1)  # Algorithm R: keep the new sample with probability size/(n+1)
            if j < size:
                self._samples[j] = v
        self.count += 1

    @property
    def exact(self) -> bool:
        """Whether :meth:`summary`'s median is exact (every sample kept)."""
        return self.count <= self._samples.shape[0]

    def summary(self) -> dict[str, float]:
        """``{"total_s", "count", "mean_ms", "median_ms"}`` (NaN mean and median without samples)."""
        kept = self._samples[: min(self.count, self._samples.shape[0])]
        return {
            "total_s": float(self.total),
            "count": int(self.count),
            "mean_ms": float(self.total / self.count * 1e3) if self.count else math.nan,
            "median_ms": float(np.median(kept) * 1e3) if self.count else math.nan,
        }


class ParticleStore:
    """The particle clouds kept for ``particles.npz``, at most ``cap`` frames of them.

    Frames are kept when their number is a multiple of the current stride, which starts at ``every``; when a new
    frame would make more than ``cap``, the stride doubles and the frames no longer on it are dropped. After frames
    ``0..F`` the store therefore holds exactly the frames ``f <= F`` with ``f % stride(F) == 0``, ``stride(F)`` the
    smallest ``every * 2^j`` leaving at most ``cap`` of them: evenly spaced over the whole run, a function of ``F``
    alone, so a resumed run ends with the same frames as an uninterrupted one. Memory: at most ``cap`` frames of
    ``particles_max`` particles (16 bytes each).

    Args:
        every: Initial stride (frames), >= 1.
        cap: Most frames kept, >= 1.
    """

    def __init__(self, every: int, cap: int) -> None:
        if every < 1 or cap < 1:
            raise ValueError(f"need every >= 1 and cap >= 1, got {every}, {cap}")
        self.every = int(every)
        self.cap = int(cap)
        self.stride = int(every)
        self.frames: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def wants(self, frame: int) -> bool:
        """Whether ``frame`` is on the current stride (worth preparing its particles)."""
        return int(frame) % self.stride == 0

    def add(self, frame: int, positions: np.ndarray, weights: np.ndarray) -> bool:
        """Keep a frame's ``(K, 3)`` positions and ``(K,)`` weights if it is on the stride; returns whether kept."""
        frame = int(frame)
        if frame % self.stride != 0:
            return False
        self.frames[frame] = (positions, weights)
        while len(self.frames) > self.cap:
            self.stride *= 2
            self.frames = {f: v for f, v in self.frames.items() if f % self.stride == 0}
        return frame in self.frames

    def __len__(self) -> int:
        return len(self.frames)


class RunWriter:
    """Write a run's outputs (``run.json``, ``tracks.csv``, ``particles.npz``) as the run goes.

    ``run.json`` is written at once with ``"status": "running"`` and rewritten (atomically) on :meth:`set_info`,
    every ``flush_seconds`` while rows/particles come in, and on :meth:`close`. ``tracks.csv`` lines are written
    and flushed at the end of every :meth:`add_rows` call (fsync'ed at most every ``flush_seconds`` and on
    close). ``particles.npz`` is rewritten atomically at most every ``flush_seconds`` and on close.

    Memory is bounded for runs of any length: the particles of at most ``particles_frames`` frames are kept
    (:class:`ParticleStore`: evenly spaced over the run, the spacing doubling as the run grows; ``particles.npz``
    records it as ``every``), timings are running statistics (:class:`StageTimer`), and frames are counted, not
    listed (rows must come in non-decreasing frame order, as the run loop writes them: ``frames`` counts the changes
    of frame number).

    Use it as a context manager: leaving the block normally closes with ``"complete"``, by KeyboardInterrupt
    (or SystemExit) with ``"interrupted"``, by another exception with ``"failed"`` (the error is recorded in
    ``run.json``); exceptions are always re-raised.

    Args:
        out_dir: Output folder (created if needed).
        tracker: Tracker name recorded in run.json.
        columns: tracks.csv header: ``frame, id, x, y, z`` then extra columns (e.g. ``sx, sy, sz``).
        config: Tracker/run configuration recorded in run.json (made JSON-safe).
        particles_every: Keep the particles of frames whose number is a multiple of this; 0 keeps none.
        particles_max: At most this many particles per frame (deterministic evenly-strided subsample).
        particles_frames: At most this many frames of particles kept (and written to particles.npz).
        flush_seconds: Minimum interval between periodic rewrites of run.json/particles.npz (and CSV fsyncs).
        resume_from: Continue the run already in ``out_dir`` after this frame: its tracks.csv rows and particle
            frames up to this frame are kept (later ones dropped) and appended to; run.json keeps its start time and
            records the resumption under ``resumed``.

    Raises:
        OutputError: The folder cannot be written.
        ValueError: ``columns`` does not start with ``frame, id, x, y, z`` or has duplicates; bad parameters.
    """

    def __init__(
        self,
        out_dir: str | os.PathLike,
        tracker: str,
        columns: Sequence[str],
        config: dict[str, Any],
        particles_every: int = 1,
        particles_max: int = 2000,
        flush_seconds: float = 2.0,
        resume_from: int | None = None,
        particles_frames: int = 500,
    ) -> None:
        columns = [str(c) for c in columns]
        if tuple(columns[: len(BASE_COLUMNS)]) != BASE_COLUMNS:
            raise ValueError(f"tracks columns must start with {','.join(BASE_COLUMNS)}, got {columns}")
        if len(set(columns)) != len(columns):
            raise ValueError(f"duplicate tracks columns: {columns}")
        bad = [c for c in columns if not c or any(ch in c for ch in ',"\n\r')]
        if bad:
            raise ValueError(f"invalid tracks column names: {bad}")
        if particles_every < 0 or particles_max < 1 or flush_seconds < 0 or particles_frames < 1:
            raise ValueError(
                f"need particles_every >= 0, particles_max >= 1, flush_seconds >= 0, particles_frames >= 1; got "
                f"{particles_every}, {particles_max}, {flush_seconds}, {particles_frames}"
            )
        self.out_dir = ensure_writable_dir(out_dir)
        self.tracks_path = self.out_dir / TRACKS_FILE
        self.run_path = self.out_dir / RUN_FILE
        self.particles_path = self.out_dir / PARTICLES_FILE
        self.columns = columns
        self.particles_every = int(particles_every)
        self.particles_max = int(particles_max)
        self.flush_seconds = float(flush_seconds)
        self.status = "running"
        self.rows_written = 0
        self._frames_count = 0
        self._last_row_frame: int | None = None
        self._last_frame: int | None = None
        self._particles = ParticleStore(max(1, self.particles_every), int(particles_frames))
        self._particles_dirty = False
        self._timings: dict[str, StageTimer] = {}
        self._t0 = time.monotonic()
        self._last_flush = self._t0
        self._closed = False
        self._run: dict[str, Any] = {
            "tracker": tracker,
            "status": "running",
            "started": _now(),
            "finished": None,
            "elapsed_s": None,
            "frames": 0,
            "last_frame": None,
            "rows": 0,
            "config": jsonable(config),
            "versions": versions(),
            "columns": list(columns),
            "files": {"tracks": TRACKS_FILE, "particles": None},
            "timings": {},
            "summary": None,
        }
        self._run["resumed"] = []
        self._reserved = set(self._run)
        if resume_from is not None:
            self._resume(int(resume_from))
        try:
            self._csv_file = open(
                self.tracks_path, "a" if resume_from is not None else "w", encoding="utf-8", newline=""
            )
        except OSError as e:
            raise OutputError(f"cannot write {self.tracks_path}: {e.strerror or e}") from None
        if resume_from is None:
            self._csv_file.write(",".join(columns) + "\n")
            (self.out_dir / TRACKS_ALL_FILE).unlink(missing_ok=True)  # an earlier run's: not this run's tracks
        self._csv_file.flush()
        self._write_run_json()
        log.info("writing run outputs to %s", self.out_dir)

    # ------------------------------------------------------------------ public API

    def set_info(self, **kw: Any) -> None:
        """Merge extra top-level fields into run.json (e.g. ``device="cuda:0", seed=1``) and rewrite it.

        Raises:
            ValueError: A key is one that RunWriter manages itself (status, config, timings, ...).
        """
        clash = sorted(set(kw) & self._reserved)
        if clash:
            raise ValueError(f"run.json fields {clash} are managed by RunWriter and cannot be set with set_info")
        self._run.update(jsonable(kw))
        if not self._closed:
            self._write_run_json()

    def add_rows(self, rows: Iterable[Sequence[Any]]) -> None:
        """Append rows to tracks.csv and flush them (whole lines, one write per call).

        Args:
            rows: Rows with one value per column, in ``columns`` order. Floats are written with ``%.6f``
                (metres: micrometre resolution), ints as ints, bools as 0/1, None as empty, strings as-is
                (CSV-quoted when needed).

        Raises:
            ValueError: A row has the wrong number of values (nothing of this call is written then).
        """
        self._check_open()
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        frames = []
        n = 0
        for row in rows:
            row = list(row)
            if len(row) != len(self.columns):
                raise ValueError(
                    f"tracks row has {len(row)} values, expected {len(self.columns)} ({self.columns}): {row}"
                )
            writer.writerow([format_cell(v) for v in row])
            frames.append(row[0])
            n += 1
        if n == 0:
            return
        self._csv_file.write(buf.getvalue())
        self._csv_file.flush()
        self.rows_written += n
        for f in frames:
            with contextlib.suppress(TypeError, ValueError):
                f = int(f)
                if f != self._last_row_frame:
                    self._frames_count += 1
                    self._last_row_frame = f
                self._last_frame = f if self._last_frame is None else max(self._last_frame, f)
        self._maybe_flush()

    def add_particles(self, frame: int, positions: np.ndarray, weights: np.ndarray | None = None) -> None:
        """Record a frame's particles (kept in memory; written to particles.npz periodically and on close).

        Only frames whose number is a multiple of ``particles_every`` are kept, at most ``particles_frames`` of them
        (see :class:`ParticleStore`). More than ``particles_max``
        particles are subsampled with an even deterministic stride (weights subsampled alike, not renormalised).

        Args:
            frame: Frame index.
            positions: ``(K, 3)`` particle positions in metres.
            weights: ``(K,)`` particle weights; ``None`` records uniform weights ``1/K``.

        Raises:
            ValueError: Wrong shapes.
        """
        self._check_open()
        if self.particles_every == 0 or not self._particles.wants(frame):
            return
        pos = np.asarray(positions)
        if pos.ndim != 2 or pos.shape[1] != 3:
            raise ValueError(f"particle positions must have shape (K, 3), got {pos.shape}")
        k = pos.shape[0]
        if weights is None:
            w = np.full(k, 1.0 / k if k else np.nan, dtype=np.float32)
        else:
            w = np.asarray(weights).reshape(-1)
            if w.shape[0] != k:
                raise ValueError(f"particle weights must have shape ({k},), got {np.shape(weights)}")
        if k > self.particles_max:
            idx = (np.arange(self.particles_max, dtype=np.int64) * k) // self.particles_max
            pos, w = pos[idx], w[idx]
        self._particles.add(int(frame), pos.astype(np.float32, copy=True), w.astype(np.float32, copy=True))
        self._particles_dirty = True
        self._maybe_flush()

    def frame_done(self, frame: int) -> None:
        """Mark ``frame`` as processed (also when it wrote no rows): run.json's ``last_frame``."""
        self._last_frame = int(frame) if self._last_frame is None else max(self._last_frame, int(frame))

    def add_timing(self, stage: str, seconds: float) -> None:
        """Add one duration sample (seconds) to a stage; run.json reports total, count, mean and median."""
        timer = self._timings.get(stage)
        if timer is None:
            timer = self._timings[stage] = StageTimer()
        timer.add(seconds)

    def timings(self) -> dict[str, dict[str, float]]:
        """Per-stage summary: ``{stage: {"total_s", "count", "mean_ms", "median_ms"}}`` (the median is exact up to
        4096 samples, then estimated from a bounded reservoir: :class:`StageTimer`)."""
        return {stage: timer.summary() for stage, timer in self._timings.items()}

    @property
    def frames_written(self) -> int:
        """Number of distinct frame numbers among the rows written (rows in non-decreasing frame order)."""
        return self._frames_count

    def flush(self) -> None:
        """fsync tracks.csv and rewrite particles.npz (if changed) and run.json now."""
        if self._closed:
            return
        self._csv_file.flush()
        os.fsync(self._csv_file.fileno())
        if self._particles_dirty:
            self._write_particles()
        self._write_run_json()
        self._last_flush = time.monotonic()

    def close(
        self,
        status: str = "complete",
        summary: dict[str, Any] | None = None,
        min_track_frames: int = 1,
        finish_tracks: Callable[[Path], dict[str, Any]] | None = None,
    ) -> None:
        """Finish the run: close tracks.csv, write the final particles.npz and run.json (idempotent).

        Args:
            status: ``"complete"``, ``"interrupted"``, ``"failed"`` (any string is recorded).
            summary: Tracker summary recorded in run.json (e.g. mean error, frames lost).
            min_track_frames: With ``"complete"`` and more than 1: every row goes to ``tracks_all.csv`` and
                ``tracks.csv`` keeps the tracks with at least this many rows or reported in the last frame
                (:func:`drop_short_tracks`; run.json records ``min_track_frames`` and ``short_tracks_dropped``, or
                ``short_tracks_error`` when the files could not be written: ``tracks.csv`` then has every row).
                Other runs keep every row in ``tracks.csv`` (a resumed run is filtered when it completes).
            finish_tracks: With ``"complete"``: called with the path of ``tracks.csv`` after the short tracks are
                left out (it rewrites the file atomically, e.g. ``wptrack.trackers.templates.backfill``); the dict it
                returns goes into run.json, or ``finish_tracks_error`` when it raised ``OSError`` or ``OutputError``
                (``tracks.csv`` then holds the rows it had before). ``tracks_all.csv`` gets every row before it (by the
                short-track filter, or as a copy).
        """
        if self._closed:
            return
        self._closed = True
        self.status = status
        try:
            self._csv_file.flush()
            os.fsync(self._csv_file.fileno())
        finally:
            self._csv_file.close()
        all_written = False
        if status == "complete" and min_track_frames > 1:
            self._run["min_track_frames"] = int(min_track_frames)
            try:
                dropped = drop_short_tracks(self.tracks_path, self.out_dir / TRACKS_ALL_FILE, min_track_frames)
                self._run["short_tracks_dropped"] = dropped
                all_written = True
            except (OSError, OutputError) as e:  # the run is complete: keep every row and say why
                log.warning("could not leave the short tracks out of %s: %s", self.tracks_path, e)
                self._run["short_tracks_error"] = str(e)
        if status == "complete" and finish_tracks is not None:
            try:
                if not all_written:  # the tracker's own rows stay in tracks_all.csv
                    copy_atomic(self.tracks_path, self.out_dir / TRACKS_ALL_FILE)
                self._run.update(finish_tracks(self.tracks_path))
            except (OSError, OutputError) as e:  # the run is complete: keep the rows as they are and say why
                log.warning("could not finish the tracks of %s: %s", self.tracks_path, e)
                self._run["finish_tracks_error"] = str(e)
        if len(self._particles):
            self._write_particles()
        self._run.update(status=status, finished=_now())
        if summary is not None:
            self._run["summary"] = jsonable(summary)
        self._write_run_json()
        log.info(
            "run %s: %d frames, %d rows written to %s", status, self.frames_written, self.rows_written, self.out_dir
        )

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(self, exc_type: Any, exc: BaseException | None, tb: Any) -> bool:
        if exc_type is None:
            self.close("complete")
            return False
        status = "failed" if isinstance(exc, Exception) else "interrupted"
        if status == "failed":
            self._run["error"] = f"{exc_type.__name__}: {exc}"
        try:
            self.close(status)
        except Exception:  # keep the original exception
            log.exception("could not finish the run outputs in %s", self.out_dir)
        return False

    # ------------------------------------------------------------------ internals

    def _resume(self, frame: int) -> None:
        """Take over the outputs of the interrupted run in ``out_dir`` up to ``frame`` (see ``resume_from``)."""
        try:
            previous = json.loads(self.run_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as e:
            raise OutputError(f"cannot resume: {self.run_path} is missing or unreadable ({e})") from None
        if previous.get("columns") != self.columns:
            raise OutputError(f"cannot resume: {self.tracks_path} has columns {previous.get('columns')}")
        self.rows_written = truncate_csv_after(self.tracks_path, frame)
        if self.rows_written:
            frames = read_tracks(self.tracks_path)["frame"]
            self._frames_count = len(np.unique(frames))
            self._last_row_frame = int(frames[-1])
        self._last_frame = frame
        self._run["started"] = previous.get("started", self._run["started"])
        self._run["resumed"] = [*previous.get("resumed", []), {"after_frame": frame, "at": _now()}]
        if self.particles_path.exists():
            with np.load(self.particles_path) as z:
                if "every" in z.files:  # the stride when it was written (>= the stride at ``frame``)
                    self._particles.stride = max(self._particles.stride, int(z["every"]))
                keep = z["frames"] <= frame
                for f, pos, w in zip(z["frames"][keep], z["positions"][keep], z["weights"][keep], strict=True):
                    ok = ~np.isnan(w)
                    self._particles.add(int(f), pos[ok], w[ok])
            self._particles_dirty = True

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"RunWriter for {self.out_dir} is closed")

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self.flush_seconds:
            self.flush()

    def _write_particles(self) -> None:
        kept = sorted(self._particles.frames.items())
        n = len(kept)
        k = max((p.shape[0] for _, (p, _) in kept), default=0)
        frames = np.array([f for f, _ in kept], dtype=np.int32)
        positions = np.full((n, k, 3), np.nan, dtype=np.float32)
        weights = np.full((n, k), np.nan, dtype=np.float32)
        for i, (_, (p, w)) in enumerate(kept):
            positions[i, : p.shape[0]] = p
            weights[i, : w.shape[0]] = w
        atomic_save_npz(
            self.particles_path,
            frames=frames,
            positions=positions,
            weights=weights,
            every=np.int64(self._particles.stride),
        )
        self._run["files"]["particles"] = PARTICLES_FILE
        self._particles_dirty = False

    def _write_run_json(self) -> None:
        self._run["elapsed_s"] = round(time.monotonic() - self._t0, 3)
        self._run["frames"] = self.frames_written
        self._run["last_frame"] = self._last_frame
        self._run["rows"] = self.rows_written
        self._run["timings"] = self.timings()
        atomic_write_json(self.run_path, self._run)
