"""Files that are never half-written: every output that is not appended to line by line is written to a temporary file
in the same folder, fsync'ed, and renamed over the old one (then the folder is fsync'ed), so an interrupted run
(Ctrl-C, crash, a full disk) leaves either the old file or the new one. :func:`atomic_file` is the one way to do it;
the other functions write bytes, text, JSON, ``.npz`` and images through it, and :func:`atomic_path` gives a
temporary path for writers that open the file themselves (OpenCV's video and FileStorage writers).
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import json
import logging
import math
import os
import tempfile
import uuid
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from wptrack.core.errors import OutputError

log = logging.getLogger(__name__)

_Finishing = TypeVar("_Finishing", bound="FinishOnExit")


class FinishOnExit:
    """The ``with`` block of a writer that finishes a file: leaving it normally calls ``close()`` (the file complete,
    in place), leaving it by an exception (Ctrl-C included) calls ``abort()`` (nothing half-written is left)."""

    def close(self) -> Any:
        raise NotImplementedError

    def abort(self) -> None:
        raise NotImplementedError

    def __enter__(self: _Finishing) -> _Finishing:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def fsync_dir(directory: Path) -> None:
    """Make a rename durable (best effort: not every platform lets a folder be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def default_file_mode() -> int:
    """The mode a plain ``open(path, "w")`` would give a new file: ``0o666`` less the process umask.

    ``tempfile.mkstemp`` creates its files ``0o600``; an atomic write renames such a file into place, so it sets
    this mode first, or a report would be unreadable by a web server or a colleague.
    """
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike) -> Any:
    """Yield a binary file object on a temporary file next to ``path``; on success fsync and rename it to ``path``.

    On any exception (including KeyboardInterrupt) the temporary file is removed and ``path`` is untouched.
    """
    target = Path(path)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            os.fchmod(f.fileno(), default_file_mode())  # mkstemp's 0600 -> the umask's usual mode
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    fsync_dir(target.parent)


def temp_path(path: str | os.PathLike) -> Path:
    """A new temporary path beside ``path`` with the same suffix (writers that pick the format by suffix, such as
    OpenCV's, write the same format), hidden (``.name.tmp-XXXXXXXX.suffix``). Not created."""
    target = Path(path)
    return target.with_name(f".{target.stem}.tmp-{uuid.uuid4().hex[:8]}{target.suffix}")


def commit(tmp: str | os.PathLike, path: str | os.PathLike) -> None:
    """Finish an atomic write made through :func:`temp_path`: fsync ``tmp``, give it the usual file mode, rename it
    over ``path`` and fsync the folder."""
    tmp, target = Path(tmp), Path(path)
    with open(tmp, "rb+") as f:
        os.fchmod(f.fileno(), default_file_mode())
        os.fsync(f.fileno())
    os.replace(tmp, target)
    fsync_dir(target.parent)


def discard(tmp: str | os.PathLike) -> None:
    """Remove an unfinished temporary file (no error when it is gone)."""
    with contextlib.suppress(FileNotFoundError):
        Path(tmp).unlink()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Any:
    """Yield a temporary path beside ``path`` (:func:`temp_path`) for a writer that opens the file itself; on success
    :func:`commit` it to ``path``, on any exception remove it (``path`` untouched)."""
    tmp = temp_path(path)
    try:
        yield tmp
        commit(tmp, path)
    except BaseException:
        discard(tmp)
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Replace ``path`` with ``data`` atomically (temporary file in the same folder, fsync, ``os.replace``)."""
    with atomic_file(path) as f:
        f.write(data)


def atomic_imwrite(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an image (format from the suffix, e.g. ``.png``; BGR as OpenCV) atomically: a crash never leaves a
    half-written picture that a browser would show broken.

    Raises:
        OutputError: OpenCV cannot encode the image in that format.
    """
    import cv2

    ok, buf = cv2.imencode(Path(path).suffix or ".png", image)
    if not ok:
        raise OutputError(f"{path}: cannot encode the image as {Path(path).suffix or '.png'}")
    atomic_write_bytes(path, buf.tobytes())


def atomic_write_text(path: str | os.PathLike, text: str, encoding: str = "utf-8") -> None:
    """Replace ``path`` with ``text`` atomically (no newline translation)."""
    atomic_write_bytes(path, text.encode(encoding))


def jsonable(obj: Any) -> Any:
    """Convert ``obj`` into plain JSON types: numpy scalars/arrays, paths, dataclasses, enums, sets, tuples.

    Non-finite floats become ``None`` so that the output is strict JSON.
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if isinstance(obj, enum.Enum):
        return jsonable(obj.value)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return jsonable(dataclasses.asdict(obj))
    return str(obj)


def atomic_write_json(path: str | os.PathLike, obj: Any, indent: int | None = 2) -> None:
    """Write ``obj`` as strict JSON (NaN/inf as null; numpy, paths and dataclasses converted), atomically."""
    text = json.dumps(jsonable(obj), indent=indent, allow_nan=False) + "\n"
    atomic_write_text(path, text)


def atomic_save_npz(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    """Save arrays to an uncompressed ``.npz`` file atomically (``path`` is used as given; no suffix added)."""
    with atomic_file(path) as f:
        np.savez(f, **arrays)


def ensure_writable_dir(path: str | os.PathLike) -> Path:
    """Create an output folder (with parents) and check that files can be written into it.

    Args:
        path: Folder path.

    Returns:
        The folder as a :class:`~pathlib.Path`.

    Raises:
        OutputError: ``output directory 'x' is not writable: <reason>`` when the path is a file, lies under a file,
            cannot be created, or a test file cannot be written in it.
    """
    p = Path(path)

    def fail(reason: str) -> OutputError:
        return OutputError(f"output directory '{p}' is not writable: {reason}")

    if p.exists() and not p.is_dir():
        raise fail("it exists and is a file")
    for parent in p.parents:
        if parent.exists():
            if not parent.is_dir():
                raise fail(f"'{parent}' is a file, not a folder")
            break
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise fail(e.strerror or str(e)) from None
    try:
        fd, tmp = tempfile.mkstemp(dir=p, prefix=".wptrack-write-test-")
        os.close(fd)
        os.unlink(tmp)
    except OSError as e:
        raise fail(e.strerror or str(e)) from None
    return p


def ensure_writable_file(path: str | os.PathLike) -> Path:
    """Before a command's work: create an output file's folder (with parents) and check that the file can be written
    there, so that a bad ``--out FILE`` is said first, not as a traceback after the work.

    Args:
        path: File path.

    Returns:
        The path as a :class:`~pathlib.Path`.

    Raises:
        OutputError: ``output file 'x' is not writable: <reason>`` when the path is a folder, or
            ``output directory 'y' is not writable: <reason>`` when its folder cannot be created or written
            (:func:`ensure_writable_dir`).
    """
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"output file '{p}' is not writable: it is a folder")
    ensure_writable_dir(p.parent)
    return p


def copy_atomic(src: str | os.PathLike, dst: str | os.PathLike) -> None:
    """Copy ``src`` to ``dst`` atomically (``dst`` is never half-written)."""
    import shutil

    with open(src, "rb") as fin, atomic_file(dst) as fout:
        shutil.copyfileobj(fin, fout)
