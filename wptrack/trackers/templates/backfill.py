"""Offline completion of a finished run's tracks: backfill (a confirmed track is extended backwards over the frames
before it was first reported) and stitching (a track that ends and one that starts where it was heading get one id).

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
prolong (docs/notes.md, round seven).

:func:`backfill_tracks_file` applies it to a completed run's ``tracks.csv``: every line of the file is kept as
written, the new ones are added in frame order, and the file is replaced atomically (write to a temporary file,
fsync, rename), so it holds either the old rows or the new ones at every moment.

:func:`stitch_tracks_file` gives one id to a track A that ends (before the run's last frame) and a track B of the
same class that starts at most ``gap`` frames later within ``distance`` metres of where A was heading (A's last
position moved on at the velocity fitted to its last ``fit_rows`` rows): the filter lost the object (deleted by
eq. 13, or its hypothesis absorbed by a neighbour's) and added it again under a new label, an identity switch. Pairs
are taken greedily, nearest first, each track with at most one successor and one predecessor; chains take the id of
their first track. Only the ``id`` cells change (in place and atomically, as above).
"""

from __future__ import annotations

import contextlib
import csv
import math
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import numpy as np

from wptrack.core.errors import OutputError
from wptrack.io.atomic import atomic_file

InView = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
"""``in_view(ground (n, 2) m, size (n, 3) m, heading (n,) rad) -> (n,) bool``."""

NEEDED = ("frame", "id", "x", "y", "z", "gx", "gy", "length", "width", "height", "orientation")
"""Columns the backfill needs (it reads ``frame, id, gx, gy, length, width, height, orientation`` and writes ``x, y,
z`` too)."""


def _velocity(frames: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """Least-squares slope (2,) of ``ground`` (n, 2) against ``frames`` (n,), metres per frame (0 for one row)."""
    t = frames - frames.mean()
    den = float(t @ t)
    if den == 0.0:
        return np.zeros(2)
    return (t @ (ground - ground.mean(axis=0))) / den


class _Track:
    """What the backfill needs of one track: its row count and its first rows (frame, ground, size, heading)."""

    __slots__ = ("count", "frames", "ground", "size", "heading", "first")

    def __init__(self) -> None:
        self.count = 0
        self.frames: list[int] = []
        self.ground: list[tuple[float, float]] = []
        self.size: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.heading = 0.0
        self.first: object = None  # the first row, as the caller keeps it (an index, a list of cells)

    def add(self, frame: int, ground: tuple[float, float], fit_rows: int) -> None:
        """Count a row (rows in frame order); the first ``fit_rows`` are kept for the velocity fit."""
        self.count += 1
        if len(self.frames) < max(fit_rows, 1):
            self.frames.append(frame)
            self.ground.append(ground)


def _windows(tracks: dict[int, _Track], start: int, frames: int, min_rows: int) -> dict[int, tuple[int, int]]:
    """Frames ``[lo, f0)`` each lasting track may be extended over, by id (ids in ascending order)."""
    out = {}
    for tid in sorted(tracks):
        t = tracks[tid]
        f0 = t.frames[0]
        lo = max(start, f0 - frames)
        if t.count >= min_rows and lo < f0:
            out[tid] = (lo, f0)
    return out


def _plan(
    tracks: dict[int, _Track],
    windows: dict[int, tuple[int, int]],
    occupied: dict[int, list[tuple[float, float, float]]],
    in_view: InView,
    guard: float,
) -> list[tuple[int, int, float, float, float]]:
    """The added rows ``(id, frame, gx, gy, speed m/frame)``, tracks by id, frames backwards from each start.

    ``occupied`` (frame -> ``(gx, gy, length)`` of every row there) gets the accepted rows too, so a later track
    keeps off an earlier one's backfilled rows.
    """
    added = []
    for tid, (lo, f0) in windows.items():
        t = tracks[tid]
        v = _velocity(np.asarray(t.frames, dtype=np.float64), np.asarray(t.ground, dtype=np.float64))
        k = np.arange(1, f0 - lo + 1)
        pos = np.asarray(t.ground[0])[None, :] - k[:, None] * v[None, :]
        seen = np.asarray(
            in_view(pos, np.repeat(np.asarray(t.size, dtype=np.float64)[None], len(k), 0), np.full(len(k), t.heading)),
            dtype=bool,
        )
        ln = float(t.size[0])
        speed = float(np.hypot(v[0], v[1]))
        for j in range(len(k)):
            f = f0 - int(k[j])
            gx, gy = float(pos[j, 0]), float(pos[j, 1])
            others = occupied.setdefault(f, [])
            if not seen[j] or any(math.hypot(ox - gx, oy - gy) < max(guard, 0.5 * (ol + ln)) for ox, oy, ol in others):
                break
            others.append((gx, gy, ln))
            added.append((tid, f, gx, gy, speed))
    return added


def backfill_rows(
    table: Mapping[str, np.ndarray],
    to_world: Callable[[np.ndarray], np.ndarray],
    in_view: InView,
    frames: int,
    min_rows: int,
    fit_rows: int = 8,
    guard: float = 1.0,
    fps: float = 1.0,
    first_frame: int | None = None,
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
        first_frame: The run's first frame: no row is added before it (default: the table's first frame). A run's
            first frame never has a row (the filter starts without objects and adds them after a frame's
            estimate), so a completed run passes its own first frame, 0.

    Returns:
        ``(rows, source)``: the added rows as columns (same keys as ``table``; tracks by id, frames backwards from
        each track's start) and, per added row, the index in ``table`` of the first row of its track.
    """
    missing = [c for c in NEEDED if c not in table]
    if missing:
        raise OutputError(f"tracks: no {', '.join(missing)} column(s) to backfill from")
    frame = np.asarray(table["frame"], dtype=np.int64)
    empty = {k: np.asarray(v)[:0] for k, v in table.items()}
    if frames <= 0 or len(frame) == 0:
        return empty, np.zeros(0, dtype=np.int64)
    ids = np.asarray(table["id"], dtype=np.int64)
    gx, gy = (np.asarray(table[c], dtype=np.float64) for c in ("gx", "gy"))
    length, width, height = (np.asarray(table[c], dtype=np.float64) for c in ("length", "width", "height"))
    heading = np.asarray(table["orientation"], dtype=np.float64)
    tracks: dict[int, _Track] = {}
    occupied: dict[int, list[tuple[float, float, float]]] = {}
    for i in np.argsort(frame, kind="stable").tolist():
        g = (float(gx[i]), float(gy[i]))
        size = (float(length[i]), float(width[i]), float(height[i]))
        t = tracks.setdefault(int(ids[i]), _Track())
        if t.count == 0:
            t.first, t.size, t.heading = i, size, float(heading[i])
        t.add(int(frame[i]), g, fit_rows)
        occupied.setdefault(int(frame[i]), []).append((g[0], g[1], size[0]))
    start = int(frame.min()) if first_frame is None else min(int(first_frame), int(frame.min()))
    plan = _plan(tracks, _windows(tracks, start, frames, min_rows), occupied, in_view, guard)
    if not plan:
        return empty, np.zeros(0, dtype=np.int64)
    src = np.array([tracks[tid].first for tid, *_ in plan], dtype=np.int64)
    g = np.array([(p[2], p[3]) for p in plan], dtype=np.float64)
    world = np.asarray(to_world(g), dtype=np.float64).reshape(-1, 3)
    added: dict[str, np.ndarray] = {k: np.asarray(v)[src] for k, v in table.items()}
    added["frame"] = np.array([p[1] for p in plan], dtype=np.asarray(table["frame"]).dtype)
    added["gx"], added["gy"] = g[:, 0], g[:, 1]
    added["x"], added["y"], added["z"] = world[:, 0], world[:, 1], world[:, 2]
    if "speed" in table:
        added["speed"] = np.array([p[4] * fps for p in plan])
    if "existence" in table:
        added["existence"] = np.zeros(len(plan))
    if "degenerate" in table:
        added["degenerate"] = np.zeros(len(plan), dtype=np.asarray(table["degenerate"]).dtype)
    return added, src


def _header(path: Path) -> tuple[str, list[str]]:
    """The header line of a CSV file and its cells."""
    with open(path, encoding="utf-8", newline="") as fh:
        line = fh.readline()
    if not line.strip():
        raise OutputError(f"{path}: empty file, expected a header line")
    return (line if line.endswith("\n") else line + "\n"), next(csv.reader([line]))


def _body(path: Path) -> Iterator[tuple[str, list[str]]]:
    """The (line, cells) of a CSV file after its header, lines newline-terminated (the file is opened on the first
    item and closed when the iterator ends or is closed)."""
    with open(path, encoding="utf-8", newline="") as fh:
        fh.readline()
        for line in fh:
            if not line.endswith("\n"):
                line += "\n"
            yield line, next(csv.reader([line]))


class _Table:
    """A tracks CSV read in streaming passes: its header, column indices and checked cell parsing."""

    def __init__(self, path: Path, needed: tuple[str, ...], purpose: str) -> None:
        self.path = path
        self.header_line, header = _header(path)
        missing = [c for c in needed if c not in header]
        if missing:
            raise OutputError(f"{path}: no {', '.join(missing)} column(s) to {purpose}")
        self.col = {c: header.index(c) for c in header}

    def number(self, cells: list[str], name: str, cast: type = float):
        """The cell of column ``name`` as ``cast`` (float or int); an error names the file and the column."""
        try:
            return cast(cells[self.col[name]])
        except (ValueError, IndexError):
            what = "an integer" if cast is int else "a number"
            raise OutputError(f"{self.path}: column {name!r} holds a value that is not {what}") from None

    def rows(self, check_order: bool = False) -> Iterator[tuple[int, str, list[str]]]:
        """``(frame, line, cells)`` of every row (``check_order``: an error when the frames go back)."""
        last = None
        with contextlib.closing(_body(self.path)) as rows:
            for line, cells in rows:
                f = self.number(cells, "frame", int)
                if check_order and last is not None and f < last:
                    raise OutputError(f"{self.path}: rows are not in frame order (frame {f} after {last})")
                last = f
                yield f, line, cells

    def rewrite(self, lines: Iterator[str]) -> None:
        """Replace the file by the header and ``lines`` atomically (temporary file, fsync, rename)."""
        try:
            with atomic_file(self.path) as dst:
                dst.write(self.header_line.encode("utf-8"))
                for line in lines:
                    dst.write(line.encode("utf-8"))
        except OSError as e:
            raise OutputError(f"cannot write {self.path}: {e.strerror or e}") from None


def backfill_tracks_file(
    path: Path,
    to_world: Callable[[np.ndarray], np.ndarray],
    in_view: InView,
    frames: int,
    min_rows: int,
    fit_rows: int = 8,
    guard: float = 1.0,
    fps: float = 1.0,
    first_frame: int | None = None,
) -> int:
    """Extend the lasting tracks of a tracks CSV back in time (as :func:`backfill_rows`), in place and atomically.

    Every existing line is kept as written; an added line copies the cells of its track's first line, with the
    new ``frame, x, y, z, gx, gy``, ``speed`` (m/s), ``existence`` 0 and ``degenerate`` 0 (floats as ``%.6f``), and
    follows the existing lines of its frame. Three streaming passes (the tracks' counts and first rows; the rows
    in the frames a track may be extended over; the copy), so memory grows with the tracks and the backfilled
    frames, not with the length of the run. ``first_frame``: the run's first frame (as :func:`backfill_rows`;
    default: the file's first frame). Returns the number of rows added.

    Raises:
        OutputError: The file lacks a needed column, holds a value that is not a number where one is needed, is
            not in frame order, or cannot be read or written (the old file is then left as it was).
    """
    path = Path(path)
    if frames <= 0:
        return 0
    try:
        table = _Table(path, NEEDED, "backfill from")
        number, col = table.number, table.col
        tracks: dict[int, _Track] = {}
        start = None
        for f, _, cells in table.rows(check_order=True):  # pass 1: counts and first rows per track
            start = f if start is None else start
            t = tracks.setdefault(number(cells, "id", int), _Track())
            if t.count == 0:
                t.first, t.heading = cells, number(cells, "orientation")
                t.size = (number(cells, "length"), number(cells, "width"), number(cells, "height"))
            t.add(f, (number(cells, "gx"), number(cells, "gy")), fit_rows)
        if start is None:
            return 0
        if first_frame is not None:
            start = min(start, int(first_frame))
        windows = _windows(tracks, start, frames, min_rows)
        if not windows:
            return 0
        wanted = set()
        for lo, hi in windows.values():
            wanted.update(range(lo, hi))
        occupied: dict[int, list[tuple[float, float, float]]] = {}
        for f, _, cells in table.rows():  # pass 2: the rows of the frames the tracks may be extended over
            if f in wanted:
                occupied.setdefault(f, []).append((number(cells, "gx"), number(cells, "gy"), number(cells, "length")))
        plan = _plan(tracks, windows, occupied, in_view, guard)
    except OSError as e:
        raise OutputError(f"cannot read {path}: {e.strerror or e}") from None
    if not plan:
        return 0
    world = np.asarray(to_world(np.array([(p[2], p[3]) for p in plan])), dtype=np.float64).reshape(-1, 3)
    new: list[tuple[int, str]] = []
    for (tid, f, gx, gy, speed), w in zip(plan, world, strict=True):
        cells = list(tracks[tid].first)
        values = {"frame": f, "x": w[0], "y": w[1], "z": w[2], "gx": gx, "gy": gy, "speed": speed * fps}
        values |= {"existence": 0.0, "degenerate": 0}
        for name, value in values.items():
            if name in col:
                cells[col[name]] = str(value) if isinstance(value, int) else f"{float(value):.6f}"
        new.append((f, ",".join(cells) + "\n"))
    new.sort(key=lambda r: r[0])  # stable: tracks by id within a frame

    def merged() -> Iterator[str]:  # pass 3: each added line after the existing lines of its frame
        j = 0
        for f, line, _ in table.rows():
            while j < len(new) and new[j][0] < f:
                yield new[j][1]
                j += 1
            yield line
        for _, line in new[j:]:
            yield line

    table.rewrite(merged())
    return len(new)


def stitch_tracks_file(path: Path, gap: int, distance: float, fit_rows: int = 8) -> int:
    """Give one id to the tracks that continue each other (see the module docstring), in place and atomically.

    Args:
        path: A tracks CSV in frame order with at least ``frame, id, gx, gy`` (and ``class`` when present: only
            tracks of one class are stitched).
        gap: Largest number of frames from a track's last row to its successor's first (0: off).
        distance: Largest ground distance between the successor's first position and the predicted one, metres.
        fit_rows: The end velocity is fitted to this many last rows of a track.

    Returns:
        The number of tracks that got their predecessor's id.

    Raises:
        OutputError: The file lacks a needed column, holds a value that is not a number where one is needed, is
            not in frame order, or cannot be read or written (the old file is then left as it was).
    """
    import collections

    path = Path(path)
    if gap <= 0:
        return 0
    try:
        table = _Table(path, ("frame", "id", "gx", "gy"), "stitch tracks by")
        kind = table.col.get("class")
        first: dict[int, tuple[int, float, float, str]] = {}
        tail: dict[int, collections.deque] = {}
        last = None
        for f, _, cells in table.rows(check_order=True):
            last = f
            tid = table.number(cells, "id", int)
            g = (table.number(cells, "gx"), table.number(cells, "gy"))
            if tid not in first:
                first[tid] = (f, g[0], g[1], cells[kind] if kind is not None and kind < len(cells) else "")
                tail[tid] = collections.deque(maxlen=max(fit_rows, 1))
            tail[tid].append((f, g[0], g[1]))
    except OSError as e:
        raise OutputError(f"cannot read {path}: {e.strerror or e}") from None
    starts: dict[int, list[int]] = {}
    for b, (f0, *_) in first.items():
        starts.setdefault(f0, []).append(b)
    pairs = []
    for a, rows_a in tail.items():
        end = np.asarray(rows_a, dtype=np.float64)
        f1 = int(end[-1, 0])
        if f1 == last:
            continue
        v = _velocity(end[:, 0], end[:, 1:])
        for f0 in range(f1 + 1, f1 + gap + 1):  # the tracks starting in the gap only
            for b in starts.get(f0, ()):
                _, bx, by, cls = first[b]
                if cls != first[a][3]:
                    continue
                d = math.hypot(end[-1, 1] + v[0] * (f0 - f1) - bx, end[-1, 2] + v[1] * (f0 - f1) - by)
                if d < distance:
                    pairs.append((d, a, b))
    pairs.sort()
    succ: dict[int, int] = {}
    pred: dict[int, int] = {}
    for _, a, b in pairs:
        if a not in succ and b not in pred:
            succ[a], pred[b] = b, a
    if not pred:
        return 0
    root = {}
    for b in pred:
        r = b
        while r in pred:
            r = pred[r]
        root[b] = r
    c = table.col["id"]

    def relabelled() -> Iterator[str]:
        for _, line, cells in table.rows():
            tid = int(cells[c])
            if tid in root:
                cells[c] = str(root[tid])
                line = ",".join(cells) + "\n"
            yield line

    table.rewrite(relabelled())
    return len(root)
