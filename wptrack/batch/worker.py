"""What a batch worker process pays before and around its runs, measured: the stage times of a batch run.

A batch run (:func:`wptrack.batch.execute_run`) runs in a process that may be fresh (a Ray task on a new worker,
the first run of a warm worker) or warm (a worker that ran others before). Its result and ``batch.json`` carry
``stages`` (seconds) so a batch's wall time can be attributed:

* ``wait_s``: from the driver's submission to the run's start (scheduling, a fresh worker's start and imports,
  the wait for a free worker),
* ``import_s``: importing NumPy, OpenCV, Warp and the tracker's modules, and building the run's configs from its
  arguments (about 0 in a warm process),
* ``warp_init_s``: ``wp.init()`` (the native library, the CUDA driver; 0 in a warm process),
* ``context_s``: the run's device context (CUDA primary context; 0 on the CPU and in a warm process),
* ``setup_s``: the job until its first frame minus the kernel load (inputs checked and opened, the tracker and its
  device memory built, the run folder) plus run.json's close,
* ``module_load_s``: the kernel modules loaded onto the device (compiled first when the cache misses them; about 0
  in a process that ran the same tracker before),
* ``frame_loop_s``: the frame loop; ``decode_wait_s`` the part of it the tracker waited for decoded frames,
* ``score_s``: scoring against the ground truth and the report,
* ``finish_s``: the rest (the partial folder's set-up, ``batch.json``, the rename),
* ``total_s``: the run's wall time in its worker; ``to_first_frame_s``: from its start to its frame loop's,
* ``cpu_s``: the process's CPU time (every thread: the tracker, the decoding threads) over the run; ``cpu_s /
  total_s`` is the cores the run kept busy.

With the process: ``worker_runs`` (runs this process ran before: 0 = a cold worker), ``worker_age_s`` and
``worker_cores`` (the cores it may run on: its CPU affinity, a block of its own on a pinned worker).
"""

from __future__ import annotations

import importlib
import os
import time
from collections.abc import Sequence
from typing import Any

_PROCESS = {"runs": 0}
"""Runs this process started (a warm worker's count)."""

STAGES = (
    "wait_s",
    "import_s",
    "warp_init_s",
    "context_s",
    "setup_s",
    "module_load_s",
    "frame_loop_s",
    "decode_wait_s",
    "score_s",
    "finish_s",
    "total_s",
    "to_first_frame_s",
    "cpu_s",
)
"""The stage names of a run's ``stages``, in summary.csv's column order (``stage.<name>``)."""


BASE_MODULES = ("numpy", "cv2", "warp", "wptrack.runs.loop", "wptrack.io.run", "wptrack.io.frames")
"""What every tracker run imports."""


def cpu_seconds() -> float:
    """CPU time of this process so far (user + system, every thread)."""
    t = os.times()
    return t.user + t.system


def process_age() -> float | None:
    """Seconds since this process started (Linux ``/proc``; None elsewhere)."""
    try:
        with open("/proc/self/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        start_ticks = int(fields[19])  # field 22 of stat(5): start time after boot, clock ticks
        with open("/proc/uptime", encoding="ascii") as f:
            uptime = float(f.read().split()[0])
        return max(0.0, uptime - start_ticks / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError):
        return None


def set_decode_threads(threads: int) -> None:
    """Give this process's video decoding ``threads`` threads (:data:`wptrack.io.decode.DECODE_THREADS_ENV`, read
    when a video is opened, and OpenCV's thread pool)."""
    import cv2

    from wptrack.io.decode import DECODE_THREADS_ENV

    n = max(1, int(threads))
    os.environ[DECODE_THREADS_ENV] = str(n)
    cv2.setNumThreads(n)


def prepare(device: str | None, modules: Sequence[str] = ()) -> dict[str, float]:
    """Import what a run needs, start Warp and the device's context, timing each (0 for what this process did
    before): ``import_s``, ``warp_init_s``, ``context_s``.

    Args:
        device: the run's device (``auto``, ``cpu``, ``cuda:N``); None: imports only.
        modules: further modules to import (the tracker's job module).
    """
    t0 = time.perf_counter()
    for name in (*BASE_MODULES, *modules):
        importlib.import_module(name)
    if modules:
        from wptrack.runs.spec import commands

        commands()  # every track command's parts: the trackers' config modules
    t1 = time.perf_counter()
    out = {"import_s": t1 - t0, "warp_init_s": 0.0, "context_s": 0.0}
    if device is None:
        return out
    import warp as wp

    from wptrack.core.device import init_warp, resolve_device

    init_warp()
    t2 = time.perf_counter()
    out["warp_init_s"] = t2 - t1
    try:
        alias = resolve_device(device)
    except Exception:  # noqa: BLE001 - a bad device is the job's error to report, with its message
        return out
    if alias != "cpu":
        wp.synchronize_device(alias)  # retains the device's primary context (created once per process)
        out["context_s"] = time.perf_counter() - t2
    return out


def start_run() -> dict[str, Any]:
    """Called as a run starts: the process's state (``worker_runs``, ``worker_age_s``, ``worker_cores``) and the CPU
    clock."""
    from wptrack.core.config import host_cores

    info = {
        "worker_runs": _PROCESS["runs"],
        "worker_age_s": process_age(),
        "worker_cores": host_cores(),
        "_cpu0": cpu_seconds(),
    }
    _PROCESS["runs"] += 1
    return info


def finish_stages(stages: dict[str, Any], info: dict[str, Any], total: float, started: float) -> dict[str, float]:
    """Complete ``stages`` of a run that took ``total`` seconds from ``started`` (epoch): ``total_s``, ``cpu_s``,
    ``finish_s`` (what the other stages leave), ``to_first_frame_s``; rounded to microseconds, in
    :data:`STAGES` order."""
    stages = dict(stages)
    loop_start = stages.pop("loop_start", None)
    stages["total_s"] = total
    stages["cpu_s"] = cpu_seconds() - info["_cpu0"]
    parts = ("import_s", "warp_init_s", "context_s", "setup_s", "module_load_s", "frame_loop_s", "score_s")
    known = sum(float(stages.get(k) or 0.0) for k in parts)
    stages["finish_s"] = max(0.0, total - known)
    if isinstance(loop_start, (int, float)):
        stages["to_first_frame_s"] = max(0.0, loop_start - started)
    return {k: round(float(stages[k]), 6) for k in STAGES if isinstance(stages.get(k), (int, float))}
