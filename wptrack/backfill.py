"""Offline backfill: a confirmed track is extended backwards over the frames before it was first reported.

A filter reports an object some frames after it came into view: the addition step (eq. 11 of Juza et al.) needs
enough uncovered pixels, a new object must win the weight of enough particles (``min_existence``), and an object
that enters behind an occluder (a lamp post, a bush) or in clothes the masks half miss is added later still. Online
nothing better can be done; once the whole recording is tracked, the frames before a lasting track's first report
are known to have held that object, moving as it moved when it was first seen.

:func:`backfill_rows` extends every track with at least ``min_rows`` rows back by up to ``frames`` frames at the
constant velocity fitted (least squares) to its first ``fit_rows`` rows, and stops at the first frame where

* the run's first frame is passed,
* the object would be out of view (``in_view`` false: for the template tracker, less than ``min_in_image`` of its
  image box inside the image, the rule every reported object meets), or
* another track (or a backfilled row of one) stands nearer than the larger of ``guard`` and half the sum of the two
  objects' lengths (their footprints would overlap: the object was already tracked there under another id).

The added rows copy the track's first row (class, size, heading, spread) with the extrapolated position, the
fitted speed and ``existence`` 0 (no particle holds them). Extending tracks *forwards* was tried and not kept: an
object that stops being reported has mostly left, or its hypothesis died on a confusion that extrapolation would
prolong (docs/reproduction.md, round seven).

:func:`backfill_tracks_file` applies it to a completed run's ``tracks.csv``: every line of the file is kept as
written, the new ones are added in frame order, and the file is replaced atomically (write to a temporary file,
fsync, rename), so it holds either the old rows or the new ones at every moment.
"""

from __future__ import annotations

import csv
import os
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from .errors import OutputError

InView = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""``in_view(ground (n, 2) m, size (n, 3) m, heading (n,) rad) -> (n,) bool``."""

NEEDED = ("frame", "id", "x", "y", "z", "gx", "gy", "length", "width", "height", "orientation")
"""Columns :func:`backfill_rows` reads."""


def _velocity(frames: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """Least-squares slope (2,) of ``ground`` (n, 2) against ``frames`` (n,), metres per frame (0 for one row)."""
    t = frames - frames.mean()
    den = float(t @ t)
    if den == 0.0:
        return np.zeros(2)
    return (t @ (ground - ground.mean(axis=0))) / den


def backfill_rows(
    table: Mapping[str, np.ndarray],
    to_world: Callable[[np.ndarray], np.ndarray],
    in_view: InView,
    frames: int,
    min_rows: int,
    fit_rows: int = 8,
    guard: float = 1.0,
    fps: float = 1.0,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The rows that extend each lasting track back over the frames before its first row.

    Args:
        table: Tracks, one entry per column (at least :data:`NEEDED`), one row per (frame, track): ``frame`` and
            ``id`` integers, ``gx, gy`` ground-plane position, ``length, width, height`` metres, ``orientation``
            radians. Other columns are copied from each track's first row.
        to_world: (n, 2) ground-plane positions -> (n, 3) world points (``GroundPlane.to_world``).
        in_view: Whether an object at a ground position, of a size and heading, counts as in view (see
            :data:`InView`).
        frames: Largest number of frames a track is extended by (0: none).
        min_rows: Only tracks with at least this many rows are extended.
        fit_rows: The velocity is fitted to this many first rows of the track.
        guard: Smallest ground distance to another track's row in the same frame, metres (raised to half the sum
            of the two objects' lengths when larger).
        fps: Frame rate, for the ``speed`` column of the added rows (m/s).

    Returns:
        ``(rows, source)``: the added rows as columns (same keys and dtypes as ``table``, frame order within each
        track, tracks by id) and, per added row, the index in ``table`` of the first row of its track.
    """
    missing = [c for c in NEEDED if c not in table]
    if missing:
        raise OutputError(f"tracks: no {', '.join(missing)} column(s) to backfill from")
    frame = np.asarray(table["frame"], dtype=np.int64)
    ids = np.asarray(table["id"], dtype=np.int64)
    ground = np.stack([np.asarray(table["gx"], dtype=np.float64), np.asarray(table["gy"], dtype=np.float64)], 1)
    length = np.asarray(table["length"], dtype=np.float64)
    empty = {k: np.asarray(v)[:0] for k, v in table.items()}
    if frames <= 0 or len(frame) == 0:
        return empty, np.zeros(0, dtype=np.int64)
    start = int(frame.min())
    # rows per frame, for the guard: ground positions and lengths (the added rows join as they are accepted)
    by_frame: dict[int, list[tuple[float, float, float]]] = {}
    for f, g, ln in zip(frame.tolist(), ground.tolist(), length.tolist(), strict=True):
        by_frame.setdefault(f, []).append((g[0], g[1], ln))
    out_src: list[int] = []
    out_frame: list[int] = []
    out_ground: list[np.ndarray] = []
    out_speed: list[float] = []
    for tid in np.unique(ids):
        rows = np.flatnonzero(ids == tid)
        if len(rows) < min_rows:
            continue
        rows = rows[np.argsort(frame[rows], kind="stable")]
        first = int(rows[0])
        f0 = int(frame[first])
        fit = rows[:fit_rows]
        v = _velocity(frame[fit].astype(np.float64), ground[fit])  # m per frame
        k = np.arange(1, min(frames, f0 - start) + 1)
        if len(k) == 0:
            continue
        pos = ground[first][None, :] - k[:, None] * v[None, :]
        size = np.array([length[first], table["width"][first], table["height"][first]], dtype=np.float64)
        seen = np.asarray(
            in_view(pos, np.repeat(size[None], len(k), axis=0), np.full(len(k), float(table["orientation"][first]))),
            dtype=bool,
        )
        for j in range(len(k)):
            f = f0 - int(k[j])
            if not seen[j]:
                break
            others = by_frame.get(f, [])
            if any(
                np.hypot(ox - pos[j, 0], oy - pos[j, 1]) < max(guard, 0.5 * (ol + length[first]))
                for ox, oy, ol in others
            ):
                break
            others.append((float(pos[j, 0]), float(pos[j, 1]), float(length[first])))
            by_frame[f] = others
            out_src.append(first)
            out_frame.append(f)
            out_ground.append(pos[j])
            out_speed.append(float(np.hypot(*v)) * fps)
    if not out_src:
        return empty, np.zeros(0, dtype=np.int64)
    src = np.asarray(out_src, dtype=np.int64)
    g = np.asarray(out_ground)
    world = np.asarray(to_world(g), dtype=np.float64).reshape(-1, 3)
    added: dict[str, np.ndarray] = {k: np.asarray(v)[src] for k, v in table.items()}
    added["frame"] = np.asarray(out_frame, dtype=np.asarray(table["frame"]).dtype)
    added["gx"], added["gy"] = g[:, 0], g[:, 1]
    added["x"], added["y"], added["z"] = world[:, 0], world[:, 1], world[:, 2]
    if "speed" in table:
        added["speed"] = np.asarray(out_speed)
    if "existence" in table:
        added["existence"] = np.zeros(len(src))
    if "degenerate" in table:
        added["degenerate"] = np.zeros(len(src), dtype=np.asarray(table["degenerate"]).dtype)
    return added, src


def _cell(value) -> str:
    if isinstance(value, (np.floating, float)):
        return f"{float(value):.6f}"
    if isinstance(value, (np.integer, int)):
        return str(int(value))
    return str(value)


def backfill_tracks_file(
    path: Path,
    to_world: Callable[[np.ndarray], np.ndarray],
    in_view: InView,
    frames: int,
    min_rows: int,
    fit_rows: int = 8,
    guard: float = 1.0,
    fps: float = 1.0,
) -> int:
    """Extend the lasting tracks of a tracks CSV back in time (:func:`backfill_rows`), in place and atomically.

    Every existing line is kept as written; the added ones (floats as ``%.6f``, like ``wptrack.io.RunWriter``)
    follow the existing lines of their frame, so the file stays in frame order. Returns the number of rows added.

    Raises:
        OutputError: The file lacks a needed column, holds a value that is not a number where one is needed, or
            cannot be written (the old file is then left as it was).
    """
    path = Path(path)
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            lines = fh.read().splitlines(keepends=True)
    except OSError as e:
        raise OutputError(f"cannot read {path}: {e.strerror or e}") from None
    if not lines:
        raise OutputError(f"{path}: empty file, expected a header line")
    header = next(csv.reader([lines[0]]))
    body = lines[1:]
    if body and not body[-1].endswith("\n"):
        body[-1] += "\n"
    cells = list(csv.reader(body))
    missing = [c for c in NEEDED if c not in header]
    if missing:
        raise OutputError(f"{path}: no {', '.join(missing)} column(s) to backfill from")
    table: dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        col = [r[j] if j < len(r) else "" for r in cells]
        if name in ("frame", "id", "degenerate"):
            try:
                table[name] = np.array([int(v) for v in col], dtype=np.int64)
            except ValueError:
                raise OutputError(f"{path}: column {name!r} holds a value that is not an integer") from None
        elif name == "class":
            table[name] = np.array(col, dtype=object)
        else:
            try:
                table[name] = np.array([float(v) if v != "" else np.nan for v in col], dtype=np.float64)
            except ValueError:
                if name in NEEDED:
                    raise OutputError(f"{path}: column {name!r} holds a value that is not a number") from None
                table[name] = np.array(col, dtype=object)
    added, _ = backfill_rows(table, to_world, in_view, frames, min_rows, fit_rows=fit_rows, guard=guard, fps=fps)
    n = len(added["frame"]) if added else 0
    if n == 0:
        return 0
    new_lines = [",".join(_cell(added[c][i]) for c in header) + "\n" for i in range(n)]
    # merge by frame: every old line keeps its place among the old ones, new lines follow their frame's old lines
    keys = np.concatenate([table["frame"], added["frame"]])
    order = np.lexsort((np.arange(len(keys)), np.r_[np.zeros(len(body)), np.ones(n)], keys))
    everything = body + new_lines
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "w", encoding="utf-8", newline="") as dst:
            dst.write(lines[0])
            for i in order:
                dst.write(everything[i])
            dst.flush()
            os.fsync(dst.fileno())
        os.replace(tmp, path)
    except OSError as e:
        raise OutputError(f"cannot write {path}: {e.strerror or e}") from None
    finally:
        tmp.unlink(missing_ok=True)
    return n
