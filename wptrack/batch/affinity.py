"""Each batch worker on cores of its own (Linux): the worker slots of a node split its cores into disjoint blocks.

Ray reserves ``num_cpus`` per worker in its books but does not bind a process to cores: every worker's threads (a
run's video decoding threads above all, sized to the cores the worker holds) float over all of the node's cores.
A run alone then decodes on the whole host, and with G workers at once the runs crowd the same cores (and the
hyperthread siblings, caches and memory of one socket) while other cores sit idle: each run slows down
(BENCHMARKS.md, issue 32: one decode-bound run 1.2-1.4 s alone, 1.6-2.2 s beside three others on a 64-core host). A
worker bound to a block of ``cpus_per_task`` cores should run alone as it does beside the others: their decoding
cannot take its cores (nor it theirs).

The blocks: the cores this process may use, ordered by socket, then physical core, then hyperthread (Linux's
``/sys/devices/system/cpu/cpu*/topology``), cut into ``len(cores) // n`` consecutive blocks of ``n``: a block holds
whole physical cores (siblings together) of one socket where ``n`` allows. A worker claims the first block no live
worker of the node holds by an exclusive ``flock`` on a per-block lock file (node-local, in the temporary
directory); the kernel releases the lock when the worker's process ends, so a replaced worker's block is free for
its successor. Where no block is free (more workers than blocks, fractional cores) or the platform has no
``sched_setaffinity``, the worker is left unbound.

Off by default (``wptrack batch --pin-cores``): measured on a 2-GPU virtual machine (32 vCPUs, one socket, no
hyperthreads visible; BENCHMARKS.md, issue 32) it did not keep runs from slowing each other down (colour runs E 0.920
bound, 0.779 free, in that pair; template runs 0.823 bound, 0.965 free), nor on a 4-GPU one (64 vCPUs: colour 0.617
bound, 0.615 free; templates 0.869, 0.836): a VM's vCPUs hide the host's cores, and what the runs share there
(memory bandwidth, the host's siblings) no binding inside the VM separates.
"""

from __future__ import annotations

import hashlib
import logging
import os
import socket
import tempfile
from collections.abc import Sequence
from pathlib import Path

from wptrack.core.config import usable_cores

log = logging.getLogger(__name__)

_HELD: list[int] = []
"""File descriptors of this process's block locks (kept open for the process's life)."""


def _topology(cpu: int, root: Path) -> tuple[int, int]:
    """(socket, physical core) of ``cpu`` from sysfs; (0, cpu) where unreadable."""
    base = root / f"cpu{cpu}" / "topology"
    try:
        package = int((base / "physical_package_id").read_text().strip())
        core = int((base / "core_id").read_text().strip())
    except (OSError, ValueError):
        return 0, cpu
    return package, core


def ordered_cores(cores: Sequence[int], root: str | os.PathLike = "/sys/devices/system/cpu") -> list[int]:
    """``cores`` ordered by (socket, physical core, CPU id): hyperthread siblings next to each other, sockets apart.

    Args:
        cores: CPU ids.
        root: the sysfs CPU folder (tests give a fake one).
    """
    root = Path(root)
    return sorted(cores, key=lambda c: (*_topology(c, root), c))


def core_blocks(cores: Sequence[int], n: int, root: str | os.PathLike = "/sys/devices/system/cpu") -> list[list[int]]:
    """``len(cores) // n`` disjoint blocks of ``n`` cores in :func:`ordered_cores` order ([] when ``n`` < 1 or more
    than there are)."""
    if n < 1:
        return []
    order = ordered_cores(cores, root)
    return [order[k * n : (k + 1) * n] for k in range(len(order) // n)]


def lock_dir() -> Path:
    """The node-local folder of the block locks (per user; the host name keeps two nodes apart where the temporary
    directory is shared)."""
    return Path(tempfile.gettempdir()) / f"wptrack-cores-{os.getuid() if hasattr(os, 'getuid') else 0}"


def _set_affinity_all_threads(cpus: Sequence[int]) -> None:
    """Bind every thread of this process to ``cpus`` (``sched_setaffinity`` binds one thread; threads started later
    inherit their starter's)."""
    tids = [0]
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        pass
    for tid in tids:
        try:
            os.sched_setaffinity(tid, cpus)
        except OSError:  # a thread that ended meanwhile
            pass
    os.sched_setaffinity(0, cpus)


def pin_worker(n: int, root: str | os.PathLike = "/sys/devices/system/cpu", locks: Path | None = None) -> list[int]:
    """Claim a free block of ``n`` cores for this process (for its life) and bind its threads to it.

    Args:
        n: cores per worker (a batch's ``cpus_per_task``, rounded down).
        root: the sysfs CPU folder.
        locks: the lock folder (default :func:`lock_dir`).

    Returns:
        The block's CPU ids, or [] when the process stays unbound (no ``sched_setaffinity``, ``n`` below 1 or
        above the cores there are, every block held by a live worker, the lock folder not writable).
    """
    import fcntl

    if not hasattr(os, "sched_setaffinity") or _HELD:
        return []  # not on Linux, or pinned before
    cores = usable_cores()
    blocks = core_blocks(cores, int(n), root)
    if len(blocks) < 2:
        return []  # one block is the whole node: nothing to keep apart
    folder = Path(locks) if locks is not None else lock_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        log.debug("batch worker not bound to cores: %s", e)
        return []
    # the block layout's name: the same cores cut the same way share locks; other cuts (another n) do not
    layout = hashlib.sha1(f"{socket.gethostname()}:{n}:{cores}".encode()).hexdigest()[:12]
    for k, block in enumerate(blocks):
        path = folder / f"{layout}-{k}.lock"
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        except OSError as e:
            log.debug("batch worker not bound to cores: %s", e)
            return []
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        try:
            _set_affinity_all_threads(block)
        except OSError as e:
            os.close(fd)
            log.debug("batch worker not bound to cores: %s", e)
            return []
        _HELD.append(fd)
        return list(block)
    log.info("batch worker not bound to cores: all %d blocks of %d cores are held", len(blocks), n)
    return []
