"""Warm workers of ``wptrack batch`` (``--pool actors``, the default on Ray): Ray actors that keep their process and
take the batch's runs one at a time.

A Ray task per run (``--pool tasks``) starts a worker process per GPU run: Python, the imports, ``wp.init``, the
CUDA context and the kernel modules are paid again by every run, and runs of a second or two pay them as much as
they track. An actor pays them once: the pool starts one actor per worker slot, ``floor(GPUs / gpus_per_task)``
(``gpus_per_task`` 0.5: two per GPU) or, for CPU runs, ``floor(CPUs / cpus_per_task)``, never more than the runs;
each reserves its GPU share and ``cpus_per_task`` cores for its lifetime (``CUDA_VISIBLE_DEVICES`` is set by Ray,
so a run's ``device: auto`` is the actor's GPU), imports the trackers' modules and starts Warp and its device's
context before its first run, and then runs :func:`wptrack.batch.execute_run` for one queued run after another
(a run's kernel modules are loaded by its first run and stay loaded). A run dispatched to an actor writes what the
same run writes in a fresh process (``wptrack track`` and ``--address inline`` run the same code; the random
streams are counter-based, keyed by seed and frame).

Kept workers: with ``keep=True`` (``run_batch(keep_workers=True)``) the actors still alive at the end stay up, idle,
holding their resources, and the next batch of this process on the same Ray instance with the same worker shape
(GPUs and cores per worker, device, trackers) starts on them: its runs pay no worker start at all.
:func:`release_workers` (or the end of the process, or ``ray.shutdown()``) stops them.

Faults: a run whose actor died (the process killed, a node lost) or that raised is retried, up to ``retries``
times, on the next free actor; the actor it ran on is replaced by a new one (a run that raised may leave its CUDA
context unusable), so a retry normally runs elsewhere. The run folders stay atomic (``execute_run``: partial folder
renamed when complete) and completed runs are skipped as before (:func:`wptrack.batch.run_batch`).
"""

from __future__ import annotations

import gc
import logging
import math
import os
import socket
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import Any

log = logging.getLogger(__name__)


class NoWorkers(RuntimeError):
    """No batch worker could be started (each failed its warm-up)."""


class RunWorker:
    """The actor: a process that runs batch runs one after another (Ray's ``@ray.remote`` is applied by
    :func:`run_actor_pool`, so this class imports without Ray).

    Args:
        threads: video decoding threads (the cores the actor holds; :func:`wptrack.batch.worker.set_decode_threads`).
        device: the runs' device to start before the first run (``auto``: the actor's GPU, or ``cpu``); None: no
            Warp start (a batch of Python functions).
        modules: the modules the runs will import (the trackers' job modules), imported now.
        pin: bind this process to a free block of ``threads`` cores of its node first
            (:func:`wptrack.batch.affinity.pin_worker`; left unbound where none is free).
    """

    def __init__(self, threads: int, device: str | None, modules: Sequence[str] = (), pin: bool = False) -> None:
        from wptrack.batch.affinity import pin_worker
        from wptrack.batch.worker import prepare, set_decode_threads

        t0 = time.perf_counter()
        self._cores = pin_worker(threads) if pin else []
        set_decode_threads(threads)
        if device is not None:
            from wptrack.core.device import quiet_warp

            quiet_warp(True)
        self._warm = prepare(device, modules)
        self._warm["warm_up_s"] = time.perf_counter() - t0
        self._runs = 0
        _settle()

    def ready(self) -> dict[str, Any]:
        """Where this worker runs and what its warm-up took (``import_s``, ``warp_init_s``, ``context_s``)."""
        return {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "gpus": os.environ.get("CUDA_VISIBLE_DEVICES"),
            "cores": list(self._cores),
            **self._warm,
        }

    def run(self, fn: Callable[..., dict[str, Any]], *args: Any, **kwargs: Any) -> dict[str, Any]:
        """``fn(*args, **kwargs)`` (a batch run), then the run's objects collected (its device memory released)."""
        try:
            return fn(*args, **kwargs)
        finally:
            self._runs += 1
            if self._runs == 1:  # what the first run imported and cached stays for the worker's life
                _settle()
            else:
                gc.collect()


def _settle() -> None:
    """Collect the garbage, then freeze what is left (the modules, caches): later collections only scan what the
    next runs create. Without it, collecting after each run scanned ~150 000 objects (0.14-0.18 s on the CI box's
    CPU, against 0.0005 s frozen), as long as a short run's frame loop."""
    gc.collect()
    gc.freeze()


_KEPT: dict[str, Any] = {"key": None, "session": None, "actors": []}
"""The actors a batch kept for the next one (``keep=True``), with their shape and the Ray session they live in."""


def _session() -> tuple[str, str, str]:
    import ray

    ctx = ray.get_runtime_context()
    return str(ctx.gcs_address), str(ctx.get_node_id()), str(ctx.get_job_id())


def _take_kept(key: tuple) -> list[Any]:
    """The kept actors of shape ``key`` in this Ray session (taken out of the cache); kept actors of another shape
    are stopped (they would hold the resources the new ones need)."""
    import ray

    actors, _KEPT["actors"] = _KEPT["actors"], []
    if not actors or not ray.is_initialized() or _KEPT["session"] != _session():
        return []  # none, or of an earlier Ray instance (gone with it)
    if _KEPT["key"] == key:
        return actors
    for a in actors:
        _kill(a)
    return []


def release_workers() -> int:
    """Stop the workers a batch kept (``keep_workers=True``); returns how many there were."""
    import ray

    actors, _KEPT["actors"] = _KEPT["actors"], []
    if ray.is_initialized() and _KEPT["session"] == _session():
        for a in actors:
            _kill(a)
    return len(actors)


def _kill(actor: Any) -> None:
    import ray

    try:
        ray.kill(actor, no_restart=True)
    except Exception:  # noqa: BLE001 - already dead
        pass


def pool_size(resources: Mapping[str, float], gpus_per_task: float, cpus_per_task: float, runs: int) -> int:
    """The number of actors for ``runs`` runs on a cluster with ``resources`` (Ray's ``cluster_resources()``): one
    per ``gpus_per_task`` GPUs (GPU runs) and per ``cpus_per_task`` cores, at most one per run, at least one."""
    eps = 1e-9
    n = math.floor(float(resources.get("CPU", 0.0)) / cpus_per_task + eps)
    if gpus_per_task > 0:
        n = min(n, math.floor(float(resources.get("GPU", 0.0)) / gpus_per_task + eps))
    return max(1, min(n, runs))


def cpus_per_slot(nodes: Sequence[Mapping[str, Any]], gpus_per_task: float) -> float:
    """The cores each GPU worker can hold on every GPU node of a cluster (``ray.nodes()``): the smallest
    ``floor(cores / (GPUs / gpus_per_task))`` over the live nodes with a GPU, at least 1 (1 without GPU nodes)."""
    eps = 1e-9
    per = []
    for node in nodes:
        res = node.get("Resources") or {}
        gpus = float(res.get("GPU", 0.0))
        if node.get("Alive", True) and gpus >= gpus_per_task > 0:
            per.append(math.floor(float(res.get("CPU", 0.0)) / math.floor(gpus / gpus_per_task + eps) + eps))
    return float(max(1, min(per))) if per else 1.0


def run_actor_pool(
    pending: Sequence[Any],
    execute: Callable[..., dict[str, Any]],
    args: Callable[[Any], tuple],
    workers: int,
    gpus_per_task: float,
    cpus_per_task: float,
    retries: int,
    record: Callable[[dict[str, Any]], None],
    failed: Callable[[Any, BaseException | str, int], dict[str, Any]],
    device: str | None,
    modules: Sequence[str] = (),
    on_worker: Callable[[dict[str, Any]], None] | None = None,
    keep: bool = False,
    pin: bool = False,
) -> None:
    """Run ``pending`` (objects with an ``id``) on ``workers`` warm actors.

    Args:
        pending: the runs, dispatched in this order.
        execute: the function an actor calls per run (:func:`wptrack.batch.execute_run`), as
            ``execute(*args(run), submitted=<epoch seconds>)``.
        args: a run's positional arguments for ``execute``.
        workers: actors to start (:func:`pool_size`).
        gpus_per_task, cpus_per_task: each actor's Ray resources.
        retries: attempts after the first of a run whose actor died or that raised.
        record: called with each run's result (completed, or failed after its retries).
        failed: builds a failed result ``failed(run, error, attempts)``.
        device, modules: each actor's warm-up (:class:`RunWorker`).
        on_worker: called with each actor's :meth:`RunWorker.ready` once it is ready.
        keep: leave the live actors up for the next batch of this process (see the module docstring); a kept pool
            of this shape is used first.
        pin: bind each actor to a block of ``int(cpus_per_task)`` cores of its own (:mod:`wptrack.batch.affinity`).

    Raises:
        NoWorkers: no actor could be started (they failed their warm-up, 3 times per worker in all); the runs
            not done are recorded as failed first.
    """
    import ray

    remote = ray.remote(num_gpus=gpus_per_task, num_cpus=cpus_per_task, max_restarts=0, max_task_retries=0)(RunWorker)
    threads = max(1, int(cpus_per_task))
    queue = deque(pending)
    tries: dict[str, int] = {}
    starting: dict[Any, Any] = {}  # ready() ref -> actor
    idle: list[Any] = []
    running: dict[Any, tuple[Any, Any]] = {}  # run() ref -> (actor, run)
    actors: list[Any] = []
    start_failures = 0
    last_start_error: BaseException | None = None

    def start() -> None:
        actor = remote.remote(threads, device, tuple(modules), pin)
        actors.append(actor)
        starting[actor.ready.remote()] = actor

    retire = _kill
    key = (float(gpus_per_task), float(cpus_per_task), device, tuple(sorted(modules)), bool(pin))
    for actor in _take_kept(key):  # ready() again: a kept worker may have died since
        actors.append(actor)
        starting[actor.ready.remote()] = actor
    try:
        while queue or running:
            live = len(idle) + len(starting) + len(running)
            if start_failures < 3 * workers:  # else: go on with the workers there are
                for _ in range(min(workers, len(queue) + len(running)) - live):
                    start()
            while idle and queue:
                actor, run = idle.pop(), queue.popleft()
                running[actor.run.remote(execute, *args(run), submitted=time.time())] = (actor, run)
            if not running and not starting:  # queued runs and no worker left to take them
                break
            (ref,), _ = ray.wait([*running, *starting], num_returns=1)
            if ref in starting:
                actor = starting.pop(ref)
                try:
                    info = ray.get(ref)
                except ray.exceptions.RayError as e:
                    start_failures += 1
                    last_start_error = e
                    log.warning("a batch worker failed to start: %s", e)
                    retire(actor)
                    continue
                idle.append(actor)
                if on_worker:
                    on_worker(info)
                continue
            actor, run = running.pop(ref)
            try:
                result = ray.get(ref)
                if queue:  # the next run first, then the bookkeeping (summary.csv)
                    nxt = queue.popleft()
                    running[actor.run.remote(execute, *args(nxt), submitted=time.time())] = (actor, nxt)
                else:
                    idle.append(actor)
            except ray.exceptions.RayError as e:
                n = tries[run.id] = tries.get(run.id, 0) + 1
                died = isinstance(e, ray.exceptions.RayActorError)
                why = "its worker died" if died else "it raised"
                retire(actor)  # replaced at the top of the loop (if runs are left)
                if n <= retries:
                    log.warning("run %s: attempt %d failed (%s): %s; retrying", run.id, n, why, e)
                    queue.appendleft(run)
                else:
                    log.warning("run %s failed after %d attempts (%s): %s", run.id, n, why, e)
                    record(failed(run, getattr(e, "cause", None) or e, n))
                continue
            record(result)
        if queue:
            why = f"no batch worker could start ({last_start_error})"
            for run in queue:
                record(failed(run, why, tries.get(run.id, 0)))
            raise NoWorkers(why)
    finally:
        kept = idle if keep else []
        for actor in actors:
            if not any(actor is k for k in kept):
                retire(actor)
        if kept:
            _KEPT.update(key=key, session=_session(), actors=list(kept))
