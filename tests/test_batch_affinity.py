"""Batch workers bound to blocks of cores of their own (wptrack.batch.affinity, issue 32)."""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
import threading
from pathlib import Path

import pytest

from wptrack.batch.affinity import core_blocks, ordered_cores, pin_worker
from wptrack.core.config import host_cores, usable_cores

linux = pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="CPU affinity is Linux-only")


def fake_sysfs(root, layout: dict[int, tuple[int, int]]) -> None:
    """cpuN/topology/{physical_package_id, core_id} for each N: (socket, core)."""
    for cpu, (package, core) in layout.items():
        top = root / f"cpu{cpu}" / "topology"
        top.mkdir(parents=True)
        (top / "physical_package_id").write_text(f"{package}\n")
        (top / "core_id").write_text(f"{core}\n")


def test_blocks_keep_siblings_together_and_sockets_apart(tmp_path):
    # Linux's usual numbering: cpu0-3 the first thread of cores 0-3 (cores 0-1 on socket 0, 2-3 on socket 1),
    # cpu4-7 their hyperthread siblings
    layout = {c: (0 if c % 4 < 2 else 1, c % 4) for c in range(8)}
    fake_sysfs(tmp_path, layout)
    assert ordered_cores(range(8), tmp_path) == [0, 4, 1, 5, 2, 6, 3, 7]
    assert core_blocks(range(8), 2, tmp_path) == [[0, 4], [1, 5], [2, 6], [3, 7]]
    assert core_blocks(range(8), 4, tmp_path) == [[0, 4, 1, 5], [2, 6, 3, 7]]  # one socket each
    assert core_blocks(range(8), 3, tmp_path) == [[0, 4, 1], [5, 2, 6]]  # the rest is left over
    assert core_blocks(range(8), 9, tmp_path) == [] and core_blocks(range(8), 0, tmp_path) == []
    # a restricted affinity (a cpuset) cuts only the cores it allows
    assert core_blocks([1, 5, 3, 7], 2, tmp_path) == [[1, 5], [3, 7]]


def test_unreadable_topology_orders_by_id(tmp_path):
    assert ordered_cores([3, 1, 2, 0], tmp_path / "missing") == [0, 1, 2, 3]


def _claim(n: int, locks: str, ready, release, out) -> None:
    """A worker: start a thread, pin, report (block, affinity of the process and of the earlier thread), hold."""
    hold = threading.Event()
    seen: list = []

    def early() -> None:  # a thread started before the pin (Ray's own threads in an actor)
        hold.wait()
        seen.append(sorted(os.sched_getaffinity(0)))

    t = threading.Thread(target=early)
    t.start()
    block = pin_worker(n, locks=Path(locks))
    hold.set()
    t.join()
    out.put((block, sorted(os.sched_getaffinity(0)), seen[0]))
    ready.set()
    release.wait(30)


@linux
@pytest.mark.skipif(len(usable_cores()) < 2, reason="needs two cores")
def test_workers_claim_disjoint_blocks_and_free_them_when_they_end(tmp_path):
    """Live workers of one core each get different cores (every thread bound, one started before the pin too); with
    every block held one more stays unbound; a killed worker's core is free for the next."""
    cores = usable_cores()
    ctx = mp.get_context("spawn")
    out = ctx.Queue()
    releases = []  # one per worker (a process killed while it waits on an Event shared with others blocks set())
    procs = []

    def spawn() -> tuple[list[int], list[int], list[int]]:
        """A worker claiming one core: (its block, its process's affinity, its early thread's affinity)."""
        ready, release = ctx.Event(), ctx.Event()
        releases.append(release)
        p = ctx.Process(target=_claim, args=(1, str(tmp_path), ready, release, out))
        p.start()
        procs.append(p)
        assert ready.wait(60)
        return out.get(timeout=10)

    try:
        blocks = []
        for _ in range(len(cores) + 1):  # blocks of one core: one worker more than there are
            block, process_affinity, thread_affinity = spawn()
            blocks.append(block)
            if block:
                assert process_affinity == thread_affinity == block
            else:
                assert process_affinity == cores  # unbound: as it was
        assert all(len(b) == 1 for b in blocks[:-1]) and blocks[-1] == []
        assert sorted(b[0] for b in blocks[:-1]) == sorted(cores)
        procs[0].kill()  # the first worker is killed: its core is free for a new one
        procs[0].join(10)
        releases[0] = None
        assert spawn()[0] == blocks[0]
    finally:
        for release in releases:
            if release is not None:
                release.set()
        for p in procs:
            p.join(10)
            if p.is_alive():
                p.kill()


@linux
def test_one_block_or_too_many_cores_leaves_the_worker_unbound(tmp_path):
    before = sorted(os.sched_getaffinity(0))
    assert pin_worker(len(before), locks=tmp_path) == []  # the whole node: nothing to keep apart
    assert pin_worker(len(before) + 1, locks=tmp_path) == []
    assert sorted(os.sched_getaffinity(0)) == before


@pytest.mark.skipif(sys.platform != "linux", reason="CPU affinity is Linux-only")
def test_host_cores_follow_the_affinity():
    """Thread pools are sized from the cores the process may use, not from the machine's."""
    assert host_cores() == len(os.sched_getaffinity(0))
