"""Track tables (``tracks.csv``, ``groundtruth.csv``, ``best.csv``): one CSV cell format for every writer
(:func:`format_cell`: integers as integers, floats ``%.6f``, ``nan``/``inf`` spelled out), reading into columns
(:func:`read_tracks`), and the offline edits of a finished or resumed run (:func:`truncate_csv_after`,
:func:`drop_short_tracks`, :func:`smooth_tracks_file`).
"""

from __future__ import annotations

import csv
import logging
import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.errors import OutputError, WptrackError
from wptrack.io.atomic import atomic_file, atomic_write_text, copy_atomic

log = logging.getLogger(__name__)

TRACKS_FILE = "tracks.csv"


TRACKS_ALL_FILE = "tracks_all.csv"
"""Every track of a completed run whose tracks.csv left the short ones out (``RunWriter.close``)."""


#: The first columns of every tracks.csv.
BASE_COLUMNS = ("frame", "id", "x", "y", "z")


def truncate_csv_after(path: str | os.PathLike, frame: int) -> int:
    """Keep the header and the rows of ``frame`` and earlier (first column) of a CSV file, atomically.

    Used to resume a run from a checkpoint: rows written after the checkpoint's frame (and an incomplete last line
    of a killed run) are dropped. A missing file is left missing.

    Returns:
        The number of rows kept.
    """
    p = Path(path)
    if not p.exists():
        return 0
    lines = p.read_text(encoding="utf-8").splitlines(keepends=True)
    kept = lines[:1]
    for line in lines[1:]:
        if not line.endswith("\n"):
            break  # the incomplete last line of a killed run
        head = line.split(",", 1)[0].strip()
        try:
            if int(head) > frame:
                break
        except ValueError:
            break
        kept.append(line)
    atomic_write_text(p, "".join(kept))
    return len(kept) - 1


_FLOATS = (float, np.float64, np.float32)


def format_cell(value: Any) -> Any:
    """Format one CSV cell: ints as ints, floats with ``%.6f`` (``nan``/``inf`` spelled out), strings as-is."""
    if type(value) in _FLOATS:  # most cells (every row of every frame): the float branch below, without the tests
        v = float(value)
        if math.isfinite(v):
            return f"{v:.6f}"
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "1" if value else "0"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return f"{v:.6f}"
    text = str(value)
    if "\n" in text or "\r" in text:
        raise ValueError(f"tracks values must not contain line breaks: {text!r}")
    return text


def drop_short_tracks(path: Path, all_path: Path, min_frames: int) -> int:
    """Leave the tracks with fewer than ``min_frames`` rows out of the tracks CSV ``path`` (columns ``frame`` and
    ``id``), except those still reported in its last frame (the recording ended, not the track: a run of fewer
    frames keeps its tracks), keeping every row in ``all_path``; returns the number of tracks left out.

    Crash-safe: the full file is copied to ``all_path`` and the filtered one written next to ``path`` before it
    replaces ``path`` (at every moment ``path`` holds either every row or the filtered rows). Two streaming passes
    (the row counts and last frames per id, then the copy): memory grows with the number of tracks, not rows.
    """

    counts: dict[str, int] = {}
    last: dict[str, int] = {}
    end = None
    with open(path, encoding="utf-8", newline="") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None or "id" not in header or "frame" not in header:
            raise OutputError(f"{path}: no 'frame' and 'id' columns to count the tracks' rows by")
        col, fcol = header.index("id"), header.index("frame")
        for row in reader:
            k, f = row[col], int(row[fcol])
            counts[k] = counts.get(k, 0) + 1
            last[k] = max(last.get(k, f), f)
            end = f if end is None else max(end, f)
    keep = {k for k, c in counts.items() if c >= min_frames or last[k] == end}
    copy_atomic(path, all_path)
    with open(path, encoding="utf-8", newline="") as src, atomic_file(path) as dst:
        lines = iter(src)
        dst.write(next(lines).encode("utf-8"))
        for line in lines:
            if next(csv.reader([line]))[col] in keep:
                dst.write(line.encode("utf-8"))
    return len(counts) - len(keep)


def smooth_tracks_file(path: Path, half_window: int, columns: Sequence[str]) -> int:
    """Smooth the ``columns`` of every track of the tracks CSV ``path`` over time, in place and atomically
    (:func:`wptrack.core.smoothing.smooth_track`: a weighted line over +- ``half_window`` frames at each row).

    Only those cells change (written ``%.6f``); every other cell and the rows' order are kept. Two streaming passes
    (the columns, then the copy): memory grows with the rows, 8 bytes a frame, id and smoothed cell (twice).

    Args:
        path: A tracks CSV with ``frame``, ``id`` and ``columns``, one row per track and frame.
        half_window: ``W``, frames (0: nothing changes).
        columns: The columns to smooth (e.g. ``x, y, z``), numbers.

    Returns:
        The number of rows whose cells were rewritten.

    Raises:
        OutputError: A column is missing or holds a value that is not a number, a track has two rows in one frame,
            or the file cannot be read or written (it is then left as it was).
    """
    from array import array

    from wptrack.core.smoothing import smooth_track

    path = Path(path)
    if half_window <= 0:
        return 0
    frames, tids, cells = array("q"), array("q"), array("d")  # the rows in file order, 8 bytes a value
    ids: dict[str, int] = {}
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader, None) or []
            missing = [c for c in ("frame", "id", *columns) if c not in header]
            if missing:
                raise OutputError(f"{path}: no {', '.join(missing)} column(s) to smooth the tracks by")
            fcol, icol = header.index("frame"), header.index("id")
            cols = [header.index(c) for c in columns]
            for row in reader:
                try:
                    frames.append(int(row[fcol]))
                    tids.append(ids.setdefault(row[icol], len(ids)))
                    cells.extend(float(row[c]) for c in cols)
                except (ValueError, IndexError):
                    raise OutputError(f"{path}: a frame, id or {', '.join(columns)} cell is not a number") from None
    except OSError as e:
        raise OutputError(f"cannot read {path}: {e.strerror or e}") from None
    if not frames:  # no rows: nothing to smooth
        return 0
    f = np.frombuffer(frames, dtype=np.int64)
    t = np.frombuffer(tids, dtype=np.int64)
    values = np.frombuffer(cells, dtype=np.float64).reshape(len(f), len(cols))
    smoothed = np.empty_like(values)
    order = np.lexsort((f, t))  # by track, then frame
    starts = np.flatnonzero(np.r_[True, np.diff(t[order]) != 0, True])
    names = {v: k for k, v in ids.items()}
    for a, b in zip(starts[:-1], starts[1:], strict=True):
        rows = order[a:b]
        if len(np.unique(f[rows])) != len(rows):
            raise OutputError(f"{path}: track {names[int(t[rows[0]])]} has two rows in one frame; cannot smooth it")
        smoothed[rows] = smooth_track(f[rows], values[rows], half_window)
    try:
        with open(path, encoding="utf-8", newline="") as src, atomic_file(path) as dst:
            lines = iter(src)
            dst.write(next(lines).encode("utf-8"))
            for k, line in enumerate(lines):
                row = next(csv.reader([line]))
                for c, v in zip(cols, smoothed[k], strict=True):
                    row[c] = format_cell(float(v))
                dst.write((",".join(row) + "\n").encode("utf-8"))
    except OSError as e:
        raise OutputError(f"cannot write {path}: {e.strerror or e}") from None
    return len(f)


def _column_array(name: str, values: list[str]) -> np.ndarray:
    """Numeric column -> int64 (all integers) or float64 (empty cells as NaN); otherwise a str array."""
    if not values:
        return np.zeros(0, dtype=np.int64 if name in ("frame", "id") else np.float64)
    try:
        return np.array([int(v) for v in values], dtype=np.int64)
    except ValueError:
        pass
    try:
        return np.array([float(v) if v.strip() else np.nan for v in values], dtype=np.float64)
    except ValueError:
        return np.array(values, dtype=str)


def read_tracks(path: str | os.PathLike, what: str = "tracks file") -> dict[str, np.ndarray]:
    """Read a tracks.csv / groundtruth.csv into columns.

    Blank lines and lines starting with ``#`` are skipped. A last line without a newline and with too few values
    (a run killed in the middle of a write) is dropped with a warning.

    Args:
        path: CSV file with a header line.
        what: What the file is, in the error messages (``tracks file``, ``ground truth file``).

    Returns:
        ``{column: (N,) array}`` in header order: int64 when every value is an integer, float64 when every
        value is a number (empty cells as NaN), otherwise a str array.

    Raises:
        WptrackError: The file is missing/unreadable, has no header, or a row has the wrong number of values.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise WptrackError(f"{what} not found: {p}") from None
    except (OSError, UnicodeDecodeError) as e:
        raise WptrackError(f"cannot read {what} {p}: {e}") from None
    lines = text.splitlines(keepends=True)
    records = [(i + 1, line) for i, line in enumerate(lines) if line.strip() and not line.lstrip().startswith("#")]
    if not records:
        raise WptrackError(f"{what} {p} is empty (expected a header line such as frame,id,x,y,z)")
    header = [h.strip() for h in next(csv.reader([records[0][1]]))]
    if len(set(header)) != len(header) or not all(header):
        raise WptrackError(f"{what} {p}: invalid header {header}")
    data: list[list[str]] = [[] for _ in header]
    body = records[1:]
    for j, (lineno, line) in enumerate(body):
        row = next(csv.reader([line]))
        if len(row) != len(header):
            if j == len(body) - 1 and not line.endswith("\n") and len(row) < len(header):
                log.warning("%s: dropping the incomplete last line %d", p, lineno)
                break
            raise WptrackError(f"{what} {p}, line {lineno}: {len(row)} values, expected {len(header)}")
        for col, value in zip(data, row, strict=True):
            col.append(value.strip())
    return {name: _column_array(name, col) for name, col in zip(header, data, strict=True)}


class CsvAppender:
    """A CSV table written row by row (cells by :func:`format_cell`) and flushed after each batch, so a partial file is
    always valid; :meth:`sync` makes it durable (fsync).

    Args:
        path: The file.
        columns: The header.
        append: Add to an existing file (a resumed run) instead of starting a new one.

    Raises:
        OutputError: the file cannot be opened.
    """

    def __init__(self, path: str | os.PathLike, columns: Sequence[str], append: bool = False) -> None:
        self.path = Path(path)
        try:
            self.fh = open(self.path, "a" if append else "w", encoding="utf-8", newline="")
        except OSError as e:
            raise OutputError(f"cannot write {self.path}: {e.strerror or e}") from None
        self._csv = csv.writer(self.fh, lineterminator="\n")
        if not append:
            self.fh.write(",".join(columns) + "\n")

    def add(self, rows: Iterable[Sequence[Any]]) -> None:
        """Append rows (one value per column) and flush."""
        for row in rows:
            self._csv.writerow([format_cell(v) for v in row])
        self.fh.flush()

    def sync(self) -> None:
        """Flush and fsync."""
        self.fh.flush()
        os.fsync(self.fh.fileno())

    def close(self) -> None:
        """Sync and close."""
        self.sync()
        self.fh.close()
