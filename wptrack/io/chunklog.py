"""Per-frame variable-length records streamed to a folder of ``.npz`` chunks, in bounded memory.

A run's per-frame geometry (e.g. the people tracker's hulls) would grow without bound in memory if kept for one
``.npz`` written at the end, and rewriting one growing file at every checkpoint costs time quadratic in the run's
length. :class:`ChunkLog` keeps only the current chunk (``chunk_frames`` frames) in memory: a chunk is written
atomically (temporary file, fsync, rename) when the run moves past it, the current one is rewritten atomically
on :meth:`ChunkLog.flush` (checkpoints) and :meth:`ChunkLog.close`, so an interrupted run leaves valid files.

Layout: ``folder/<first frame, 8 digits>.npz``, each with

* ``index``: ``(R, 4)`` int64 rows ``(frame, id, start, count)``,
* ``vertices``: ``(V, 3)`` float32; record r is ``vertices[start : start + count]``.

:func:`read_chunks` concatenates a folder back into one ``(index, vertices)`` pair (``start`` renumbered).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from wptrack.io.atomic import atomic_save_npz


def _chunk_files(folder: Path) -> list[tuple[int, Path]]:
    """``(first frame, path)`` of the chunk files in ``folder``, by first frame."""
    if not folder.is_dir():
        return []
    out = []
    for p in folder.iterdir():
        if p.suffix == ".npz" and p.stem.isdigit():
            out.append((int(p.stem), p))
    return sorted(out)


class ChunkLog:
    """Append ``(frame, id, (V, 3) array)`` records; at most one chunk of ``chunk_frames`` frames in memory.

    Records must come in non-decreasing frame order (the run loop's order).

    Args:
        folder: Output folder (created).
        chunk_frames: Frames per chunk file (>= 1).
        resume_after: Continue a log already in ``folder`` after this frame: chunks starting later are deleted and
            the records of later frames in the chunk holding it dropped.
    """

    def __init__(self, folder: str | os.PathLike, chunk_frames: int = 500, resume_after: int | None = None) -> None:
        if chunk_frames < 1:
            raise ValueError(f"chunk_frames must be >= 1, got {chunk_frames}")
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.chunk_frames = int(chunk_frames)
        self._chunk: int | None = None  # number of the chunk in memory
        self._records: list[tuple[int, int, np.ndarray]] = []
        self._dirty = False
        if resume_after is not None:
            self._resume(int(resume_after))

    def _path(self, chunk: int) -> Path:
        return self.folder / f"{chunk * self.chunk_frames:08d}.npz"

    def _resume(self, after: int) -> None:
        keep_chunk = after // self.chunk_frames
        for first, path in _chunk_files(self.folder):
            if first // self.chunk_frames > keep_chunk:
                path.unlink()
            elif first // self.chunk_frames == keep_chunk:
                with np.load(path) as z:
                    index, verts = z["index"], z["vertices"]
                self._chunk = keep_chunk
                self._records = [(int(f), int(i), verts[s : s + c].copy()) for f, i, s, c in index if int(f) <= after]
                self._dirty = True

    def add(self, frame: int, ident: int, vertices: np.ndarray) -> None:
        """Append one record: ``vertices`` ``(V, 3)`` (stored as float32)."""
        chunk = int(frame) // self.chunk_frames
        if self._chunk is not None and chunk != self._chunk:
            self._write()
            self._records = []
        self._chunk = chunk
        self._records.append((int(frame), int(ident), np.asarray(vertices, dtype=np.float32).reshape(-1, 3)))
        self._dirty = True

    def __len__(self) -> int:
        """Records held in memory (the current chunk's)."""
        return len(self._records)

    def _write(self) -> None:
        if self._chunk is None or not self._dirty:
            return
        index = np.zeros((len(self._records), 4), dtype=np.int64)
        start = 0
        for r, (frame, ident, verts) in enumerate(self._records):
            index[r] = (frame, ident, start, len(verts))
            start += len(verts)
        verts = np.concatenate([v for _, _, v in self._records]) if self._records else np.zeros((0, 3), np.float32)
        atomic_save_npz(self._path(self._chunk), index=index, vertices=verts.astype(np.float32))
        self._dirty = False

    def flush(self) -> None:
        """Write the current chunk (atomically)."""
        self._write()

    def close(self) -> None:
        """Write the current chunk and free it (idempotent)."""
        self._write()
        self._records = []


def read_chunks(folder: str | os.PathLike, frames: Iterable[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The records of a :class:`ChunkLog` folder: ``(index (R, 4) int64, vertices (V, 3) float32)``, ``start``
    renumbered into the concatenated vertices; empty arrays when the folder is missing or empty.

    Args:
        folder: The log's folder.
        frames: Only the records of these frames (memory then bounded by them, whatever the run's length).
    """
    wanted = None if frames is None else np.asarray(sorted({int(f) for f in frames}), dtype=np.int64)
    indices, verts = [], []
    offset = 0
    for _first, path in _chunk_files(Path(folder)):
        with np.load(path) as z:
            index, v = z["index"].astype(np.int64), z["vertices"]
        if wanted is not None:
            index = index[np.isin(index[:, 0], wanted)]
            parts = [v[s : s + c] for _f, _i, s, c in index]
            index[:, 2] = np.cumsum([0, *index[:-1, 3]]) if len(index) else index[:, 2]
            v = np.concatenate(parts) if parts else np.zeros((0, 3), np.float32)
        index[:, 2] += offset
        offset += len(v)
        indices.append(index)
        verts.append(v)
    if not indices:
        return np.zeros((0, 4), dtype=np.int64), np.zeros((0, 3), dtype=np.float32)
    return np.concatenate(indices), np.concatenate(verts).astype(np.float32)
