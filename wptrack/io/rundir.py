"""Run folders: the lock a run holds while it writes into its folder (a second run refuses), and what a run owns
there (``--overwrite`` removes exactly that)."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from pathlib import Path

log = logging.getLogger(__name__)

LOCK_FILE = ".wptrack.lock"
"""Held in the run folder while a run writes into it (:func:`run_lock`): a second run into the folder refuses."""

RUN_OUTPUTS = (
    "run.json",
    "tracks.csv",
    "tracks_all.csv",
    "particles.npz",
    "checkpoint.npz",
    "best.csv",
    "virtual*.avi",
    "masks*.avi",
    "occupancy.npz",
    "hulls",
    "hulls.npz",
    "backgrounds",
    "report",
    "mot",
    "evaluation.json",
    ".*.tmp",
    ".*.tmp-*",
    "*.tmp",
)
"""What a run (and its report and evaluation) writes into its folder: ``--overwrite`` removes these names and
nothing else (other files a user keeps in the folder stay)."""


def clear_run_outputs(out_dir: Path) -> list[str]:
    """Remove the files and folders of a previous run in ``out_dir`` (the names of :data:`RUN_OUTPUTS`); returns
    the names removed."""
    import shutil

    removed = []
    for pattern in RUN_OUTPUTS:
        for path in sorted(out_dir.glob(pattern)):
            if path.name == LOCK_FILE:
                continue
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path)
            else:
                path.unlink(missing_ok=True)
            removed.append(path.name)
    return removed


def _pid_alive(pid: int) -> bool:
    import os

    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    except OSError:
        return False
    return True


@contextlib.contextmanager
def run_lock(out_dir: Path) -> Iterator[Path]:
    """Hold ``out_dir/.wptrack.lock`` (pid, host, start time; created with ``O_EXCL``) while the block runs.

    A lock held by a live process, or by a process of another host (which cannot be checked from here), is a
    :class:`~wptrack.core.errors.ConfigError` naming it. A lock left by a process of this host that is no longer alive
    (a run killed with SIGKILL, a crashed machine) is stale: it is taken over with a warning.

    Raises:
        ConfigError: another run holds the folder.
        OutputError: the lock file cannot be written.
    """
    import json
    import os
    import socket
    import uuid
    from datetime import datetime, timezone

    from wptrack.core.errors import ConfigError, OutputError

    path = out_dir / LOCK_FILE
    host = socket.gethostname()
    me = {
        "pid": os.getpid(),
        "host": host,
        "started": datetime.now(timezone.utc).astimezone().isoformat(timespec="seconds"),
    }
    for _attempt in range(3):
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            try:
                other = json.loads(path.read_text(encoding="utf-8") or "{}")
            except (OSError, ValueError):
                other = {}
            pid, other_host = other.get("pid"), other.get("host")
            if isinstance(pid, int) and other_host == host and not _pid_alive(pid):
                log.warning("%s: taking over the stale lock of process %d (no longer running)", out_dir, pid)
                stale = out_dir / f"{LOCK_FILE}.stale-{uuid.uuid4().hex[:8]}"
                with contextlib.suppress(FileNotFoundError):  # another run may have taken it over first
                    os.rename(path, stale)
                    stale.unlink()
                continue
            if not other:  # being written this instant, or unreadable: say so rather than guess
                raise ConfigError(
                    f"{out_dir} is in use by another wptrack run (lock {path}); wait for it to finish, or choose "
                    "another --out"
                ) from None
            raise ConfigError(
                f"{out_dir} is in use by another wptrack run (pid {pid} on {other_host}, started "
                f"{other.get('started', '?')}); wait for it to finish, or choose another --out (a lock left by a "
                f"dead run of another host: delete {path})"
            ) from None
        except OSError as e:
            raise OutputError(f"cannot write the lock file {path}: {e.strerror or e}") from None
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(json.dumps(me) + "\n")
        break
    else:
        raise ConfigError(f"{out_dir}: could not take the run lock {path}; try again")
    try:
        yield path
    finally:
        with contextlib.suppress(OSError):
            current = json.loads(path.read_text(encoding="utf-8") or "{}")
            if current.get("pid") == me["pid"] and current.get("host") == host:
                path.unlink()
