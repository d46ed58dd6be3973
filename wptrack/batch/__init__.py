"""Batches of runs and parameter sweeps on Ray workers that stay warm (``wptrack batch MANIFEST --out DIR``).

A manifest (YAML, :mod:`wptrack.batch.manifest`) lists runs, or grids of runs to expand. Each run is a ``wptrack
track color|templates|people`` run (its arguments are the command's options, without the dashes) or a Python
function. The batch builds the run's declared parts from its arguments (:mod:`wptrack.runs.spec`: the same configs
the command line derives its options from) and calls the same job function as ``wptrack track``, so a batch run
writes exactly what ``wptrack track`` writes, into ``DIR/<run-id>/``; ``DIR/summary.csv`` gets one row of metrics
and timings per run.

Manifest::

    tracker: color                # default tracker of the runs (color, templates, people, function)
    retries: 2                    # attempts after the first one (failed or killed task); default 2
    args:                         # default options of every run (those of `wptrack track color`)
      rig: scene/rig.yaml         # rig, video, masks, groundtruth: relative to the manifest's folder
      video: [scene/cam1.avi, scene/cam2.avi]
      hue: [300, 340]
      sat: [0.3, 1.0]
      init: [0.42, 0.45, 0.05]
    runs:
      - id: base                  # [A-Za-z0-9._+-], unique; default run000, run001...
      - id: "s{sigma}-seed{seed}" # a grid: one run per combination; {name} takes the grid's value
        grid: {sigma: [0.01, 0.03, 0.1], seed: [0, 1]}
        args: {particles: 500}
      - id: custom
        tracker: function
        function: my_experiment.py:run   # or package.module:function; called as fn(out_dir=..., **args)
        args: {n: 3}

The top-level ``tracker``, ``function``, ``args`` and ``grid`` are defaults of every run (a run's own override
them key by key); without ``runs`` the manifest is one run (or one grid) with the top-level ``id``. A run's
identity (what makes a re-run skip it) is its tracker, function and arguments: input files are named, not hashed.

Execution (``address``):

* ``local`` (default): a new local Ray instance (``ray.init(address="local")``). ``pool="actors"`` (default): one
  warm worker (a Ray actor, :mod:`wptrack.batch.actors`) per ``gpus_per_task`` GPUs (``CUDA_VISIBLE_DEVICES`` set
  by Ray, so ``--device auto`` is the worker's GPU) or, with ``gpus_per_task = 0``, per ``cpus_per_task`` cores on
  the CPU (``--device auto`` becomes ``cpu``), each started once and taking runs from a queue; ``pool="tasks"``: one
  Ray task per run (a fresh worker process per GPU run). Each worker holds ``cpus_per_task`` cores and sizes its
  runs' video decoding to them. Every run records its stage times (:mod:`wptrack.batch.worker`).
* ``auto`` / ``HOST:PORT`` / ``ray://HOST:PORT``: an existing Ray cluster. ``DIR`` and the inputs must be on a
  filesystem shared by the nodes, at the same paths, and wptrack installed on every node.
* ``inline``: no Ray; the runs one after another in this process (the default when Ray is not installed), same
  outputs and the same retries.

Fault tolerance: a run writes into ``DIR/.<run-id>.partial-<unique>`` and is renamed to ``DIR/<run-id>`` when it
completed (an older ``DIR/<run-id>`` is replaced); a run that raised (other than a user-input error, which is
reported at once) or whose worker died is retried up to ``retries`` times (on another warm worker; for tasks
Ray's ``max_retries`` and ``retry_exceptions``), each attempt from a clean partial folder.
``DIR/<run-id>/batch.json`` records the manifest entry's hash: re-running the manifest skips the runs completed
with the same entry (after a crash, a node loss or Ctrl-C only the missing runs run again); a changed entry runs
again and replaces its folder.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import os
import shutil
import socket
import time
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from wptrack.batch.address import check_ray_address
from wptrack.batch.manifest import Manifest, RunSpec, _load_function, load_manifest, track_parts, validate
from wptrack.core.errors import ConfigError, WptrackError

log = logging.getLogger(__name__)

BATCH_FILE = "batch.json"
"""Written into a run folder when the run completed: manifest entry hash, attempts, wall time, host."""
SUMMARY_FILE = "summary.csv"
DEFAULT_RETRIES = 2
POOLS = ("actors", "tasks")
"""How a batch runs on Ray: warm actors taking runs from a queue (default), or one Ray task per run."""


# ------------------------------------------------------------------------------------------------- one run
def _clear_partials(root: Path, run_id: str) -> None:
    for p in root.glob(f".{run_id}.partial-*"):
        shutil.rmtree(p, ignore_errors=True)
    for p in root.glob(f".{run_id}.old-*"):
        shutil.rmtree(p, ignore_errors=True)


def _publish(partial: Path, final: Path) -> None:
    """Rename the completed ``partial`` folder to ``final``, replacing an older ``final`` folder."""
    if final.exists():
        old = final.parent / f".{final.name}.old-{uuid.uuid4().hex[:8]}"
        os.rename(final, old)
        os.rename(partial, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.rename(partial, final)
    from wptrack.io.atomic import fsync_dir

    fsync_dir(final.parent)


def _bump_attempts(root: Path, run_id: str) -> int:
    counter = root / f".{run_id}.attempts"
    try:
        n = int(counter.read_text().strip() or 0)
    except (OSError, ValueError):
        n = 0
    from wptrack.io.atomic import atomic_write_text

    atomic_write_text(counter, f"{n + 1}\n")
    return n + 1


def _run_track(spec: RunSpec, out: Path, force_cpu: bool, stages: dict[str, Any]) -> dict[str, Any]:
    """Run a tracker through the library (what ``wptrack track`` calls), then its scoring and report; the stage
    times (:mod:`wptrack.batch.worker`) go into ``stages``."""
    from wptrack.batch.worker import prepare
    from wptrack.core.device import quiet_warp
    from wptrack.io.run import RUN_FILE
    from wptrack.runs.spec import command, replace_part, run_command, score_run

    t = time.perf_counter()
    cmd = command(spec.tracker)
    parts = track_parts(spec, out)  # the first run in a process imports the trackers' config modules here
    if force_cpu and parts["control"].device == "auto":
        parts = replace_part(parts, "control", device="cpu")
    t = time.perf_counter() - t
    stages.update(prepare(parts["control"].device, [cmd.job.split(":")[0]]))
    stages["import_s"] += t
    quiet_warp(True)
    control = parts["control"]
    t0 = time.perf_counter()
    run_command(cmd, parts, progress=False)
    t1 = time.perf_counter()
    score_run(cmd, parts)  # evaluation.json in the run folder
    if control.report:
        from wptrack.report import build_report

        build_report(out)
    stages["score_s"] = time.perf_counter() - t1
    run = json.loads((out / RUN_FILE).read_text(encoding="utf-8"))
    if run.get("status") != "complete":
        raise RuntimeError(f"run {spec.id}: run.json status is {run.get('status')!r}")
    phases = run.get("phases") or {}
    load, loop = float(phases.get("module_load_s") or 0.0), float(phases.get("frame_loop_s") or 0.0)
    wait = ((run.get("timings") or {}).get("decode_wait") or {}).get("total_s")
    stages.update(module_load_s=load, frame_loop_s=loop, setup_s=max(0.0, t1 - t0 - load - loop))
    stages.update(decode_wait_s=wait, loop_start=phases.get("loop_start"))
    return run


def _run_function(spec: RunSpec, out: Path) -> dict[str, Any]:
    from wptrack.io.atomic import atomic_write_json
    from wptrack.io.run import RUN_FILE

    out.mkdir(parents=True, exist_ok=True)
    summary = _load_function(spec.function)(out_dir=out, **spec.args)
    run = {"tracker": "function", "function": spec.function, "status": "complete", "config": spec.args}
    run["summary"] = summary if isinstance(summary, dict) else {}
    if not (out / RUN_FILE).exists():
        atomic_write_json(out / RUN_FILE, run)
    return run


def execute_run(
    spec: RunSpec,
    out_root: str | os.PathLike,
    force_cpu: bool = False,
    threads: int | None = None,
    submitted: float | None = None,
) -> dict[str, Any]:
    """Run one batch run into ``out_root/<id>`` (through a partial folder renamed when complete).

    This is the Ray task, the warm worker's step and the in-process batch's step. A user-input error
    (:class:`WptrackError`) is returned as a ``failed`` result, not raised, so it is not retried; any other exception
    is raised (the batch retries the run). ``threads``: the video decoding (OpenCV's thread pool and the FFmpeg
    decoders, :func:`wptrack.batch.worker.set_decode_threads`) is limited to this many threads, the cores Ray
    reserved for the worker (Ray limits OpenMP the same way), so that parallel runs on one machine do not
    oversubscribe its cores; None leaves the defaults. ``submitted``: when the batch submitted the run (seconds since
    the epoch), for the ``wait_s`` stage.

    Returns:
        The run's result row: id, tracker, status, attempts, seconds, host, error, summary, timings, stages
        (:mod:`wptrack.batch.worker`), started_at / ended_at (seconds since the epoch), worker_runs, worker_cores.
    """
    from wptrack.batch.worker import finish_stages, set_decode_threads, start_run
    from wptrack.io.atomic import atomic_write_json

    started = time.time()
    info = start_run()
    if threads is not None:
        set_decode_threads(threads)
    root = Path(out_root)
    root.mkdir(parents=True, exist_ok=True)
    final = root / spec.id
    _clear_partials(root, spec.id)
    attempts = _bump_attempts(root, spec.id)
    partial = root / f".{spec.id}.partial-{uuid.uuid4().hex[:8]}"
    result: dict[str, Any] = {
        "id": spec.id,
        "tracker": spec.tracker,
        "hash": spec.hash,
        "params": spec.params,
        "attempts": attempts,
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "gpus": os.environ.get("CUDA_VISIBLE_DEVICES"),
        "worker_runs": info["worker_runs"],
        "worker_cores": info["worker_cores"],
        "started_at": started,
    }
    stages: dict[str, Any] = {}
    if submitted is not None:
        stages["wait_s"] = max(0.0, started - submitted)
    t0 = time.perf_counter()
    try:
        if spec.tracker == "function":
            run = _run_function(spec, partial)
        else:
            run = _run_track(spec, partial, force_cpu, stages)
    except WptrackError as e:  # not retried: this invocation's count ends here
        shutil.rmtree(partial, ignore_errors=True)
        (root / f".{spec.id}.attempts").unlink(missing_ok=True)
        seconds = time.perf_counter() - t0
        return {**result, "status": "failed", "error": str(e), "seconds": seconds, "ended_at": time.time()}
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    seconds = time.perf_counter() - t0  # the rename below (and batch.json) are not in it
    result.update(
        status="complete",
        error="",
        seconds=seconds,
        ended_at=time.time(),
        summary=run.get("summary") or {},
        timings={k: v.get("total_s") for k, v in (run.get("timings") or {}).items() if isinstance(v, dict)},
        stages=finish_stages(stages, info, seconds, started),
    )
    atomic_write_json(partial / BATCH_FILE, result)
    _publish(partial, final)
    (root / f".{spec.id}.attempts").unlink(missing_ok=True)
    return result


def completed(spec: RunSpec, out_root: str | os.PathLike) -> dict[str, Any] | None:
    """The stored result of ``spec`` if ``out_root/<id>`` holds it completed with the same manifest entry."""
    try:
        res = json.loads((Path(out_root) / spec.id / BATCH_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if res.get("status") == "complete" and res.get("hash") == spec.hash:
        return res
    return None


# ------------------------------------------------------------------------------------------------- summary
def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        elif v is None or isinstance(v, (bool, int, float, str)):
            out[f"{prefix}{k}"] = v
    return out


SUMMARY_COLUMNS = [
    "id", "tracker", "status", "reused", "attempts", "seconds", "frames_per_s", "host", "gpus", "pid", "worker_runs",
    "worker_cores", "error",
]  # fmt: skip


def write_summary(results: Sequence[dict[str, Any]], path: str | os.PathLike) -> Path:
    """``summary.csv``: one row per run: the fixed columns, the grid parameters (``param.NAME``), the run's
    summary metrics (flattened: ``error.mean_error_after``...), per-stage totals of the frames (``time.STAGE_s``)
    and the run's stage times in its worker (``stage.NAME``, :mod:`wptrack.batch.worker`)."""
    from wptrack.batch.worker import STAGES
    from wptrack.io.atomic import atomic_write_text

    rows = []
    for r in results:
        summary = _flatten(r.get("summary") or {})
        frames = summary.get("frames")
        secs = r.get("seconds")
        row = {k: r.get(k, "") for k in SUMMARY_COLUMNS}
        row["reused"] = int(bool(r.get("reused")))
        row["seconds"] = f"{secs:.3f}" if isinstance(secs, (int, float)) else ""
        fps = frames / secs if isinstance(frames, int) and isinstance(secs, (int, float)) and secs > 0 else None
        row["frames_per_s"] = "" if fps is None else f"{fps:.3f}"
        row["error"] = str(r.get("error") or "").splitlines()[0] if r.get("error") else ""
        row.update({f"param.{k}": v for k, v in _flatten(r.get("params") or {}).items()})
        row.update(summary)
        row.update({f"time.{k}_s": v for k, v in (r.get("timings") or {}).items()})
        row.update({f"stage.{k}": v for k, v in (r.get("stages") or {}).items()})
        rows.append(row)
    extra = sorted({k for row in rows for k in row} - set(SUMMARY_COLUMNS), key=lambda k: (k.split(".")[0], k))
    params = [k for k in extra if k.startswith("param.")]
    times = [k for k in extra if k.startswith("time.")]
    stages = [f"stage.{k}" for k in STAGES if f"stage.{k}" in extra]
    metrics = [k for k in extra if k not in params and k not in times and not k.startswith("stage.")]
    columns = SUMMARY_COLUMNS + params + metrics + times + stages
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    for row in rows:
        w.writerow({k: ("" if row.get(k) is None else row.get(k, "")) for k in columns})
    atomic_write_text(path, buf.getvalue())
    return Path(path)


# ------------------------------------------------------------------------------------------------- the batch
def ray_available() -> bool:
    """Whether Ray is installed (``pip install wptrack[ray]``)."""
    import importlib.util

    return importlib.util.find_spec("ray") is not None


def _ray_init(address: str) -> bool:
    """Start or join Ray for ``address`` unless this process already joined one; True if we started it."""
    import ray

    if ray.is_initialized():
        return False
    kw: dict[str, Any] = {"log_to_driver": False}
    if address == "local":
        kw["include_dashboard"] = False
    try:
        ray.init(address=address, **kw)
    except ConnectionError as e:
        raise ConfigError(f"--address {address}: cannot connect to a Ray cluster ({e})") from None
    return True


def run_batch(
    manifest: Manifest | str | os.PathLike,
    out_dir: str | os.PathLike,
    address: str = "local",
    gpus_per_task: float | None = None,
    cpus_per_task: float | None = None,
    retries: int | None = None,
    on_result: Callable[[dict[str, Any]], None] | None = None,
    pool: str = "actors",
    on_start: Callable[[int, int], None] | None = None,
    keep_workers: bool = False,
    pin_cores: bool = False,
) -> list[dict[str, Any]]:
    """Run every run of ``manifest`` not already completed in ``out_dir``; write ``out_dir/summary.csv``.

    Args:
        manifest: a :class:`Manifest` or the path of a manifest file.
        out_dir: the batch folder (run folders ``out_dir/<id>`` and ``summary.csv``).
        address: ``local`` (new local Ray instance), ``auto`` (the running cluster), ``HOST:PORT`` or
            ``ray://HOST:PORT``, or ``inline`` (no Ray: one run after another in this process, also what
            ``local`` falls back to when Ray is not installed). A Ray instance this process already joined
            (``ray.init`` before) is used as it is.
        gpus_per_task: GPUs per run (fractions share a GPU); None: 1 if the Ray cluster has GPUs, else 0. With 0
            the runs' ``device: auto`` means the CPU.
        cpus_per_task: CPU cores reserved per worker (Ray's ``num_cpus``; its runs' video decoding threads); None:
            for GPU runs the cores per GPU worker of the cluster's GPU nodes (the smallest node's
            ``floor(cores / (GPUs / gpus_per_task))``, e.g. 4 on a node of 16 cores and 4 GPUs), else 1.
        retries: attempts after the first for a run that raised or whose worker died (default: the manifest's
            ``retries``, else 2).
        on_result: called with each run's result as it arrives (also for runs skipped as already complete).
        pool: on Ray, ``actors`` (warm workers, one per worker slot, that take the runs from a queue:
            :mod:`wptrack.batch.actors`) or ``tasks`` (one Ray task, in a fresh worker process, per GPU run).
        on_start: called once before the runs with (runs in the manifest, runs to run).
        keep_workers: ``pool="actors"`` on a Ray instance this process joined before: leave the warm workers up for
            the next batch (:func:`wptrack.batch.actors.release_workers` stops them).
        pin_cores: ``pool="actors"`` on Linux: bind each worker to a block of ``cpus_per_task`` cores of its own
            (:mod:`wptrack.batch.affinity`), so runs at once do not crowd the same cores; False (default): the
            workers' threads may run on every core of their node.

    Returns:
        The results in manifest order: ``status`` ``complete`` or ``failed``, ``reused`` for skipped runs.

    Raises:
        ConfigError: a bad manifest or run (before anything runs), a Ray address that cannot be joined, Ray asked
            for but not installed, more GPUs per task than the cluster has, an unknown ``pool``, batch workers
            that cannot start (the runs not done are in summary.csv as failed).
        OutputError: ``out_dir`` cannot be written.
    """
    from wptrack.io.atomic import ensure_writable_dir

    if not isinstance(manifest, Manifest):
        manifest = load_manifest(manifest)
    retries = retries if retries is not None else manifest.retries if manifest.retries is not None else DEFAULT_RETRIES
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise ConfigError(f"retries: expected an integer >= 0, got {retries!r}")
    if gpus_per_task is not None and not (gpus_per_task >= 0):
        raise ConfigError(f"--gpus-per-task: expected a number >= 0, got {gpus_per_task!r}")
    if cpus_per_task is not None and not (cpus_per_task > 0):
        raise ConfigError(f"--cpus-per-task: expected a number > 0, got {cpus_per_task!r}")
    if pool not in POOLS:
        raise ConfigError(f"--pool: expected one of {', '.join(POOLS)}, got {pool!r}")
    for spec in manifest.runs:
        validate(spec)
    use_ray = address != "inline"
    if use_ray and not ray_available():
        if address != "local":
            raise ConfigError(f"--address {address}: Ray is not installed (pip install 'wptrack[ray]')")
        log.warning("Ray is not installed: running the batch in this process, one run after another")
        use_ray = False
    if use_ray:
        check_ray_address(address)
    created = not Path(out_dir).exists()
    out = ensure_writable_dir(Path(out_dir).expanduser().absolute())  # workers elsewhere (other cwd, node)
    results: dict[str, dict[str, Any]] = {}
    pending = []
    for spec in manifest.runs:
        done = completed(spec, out)
        if done is not None:
            results[spec.id] = {**done, "reused": True}
            if on_result:
                on_result(results[spec.id])
        else:
            _clear_partials(out, spec.id)
            (out / f".{spec.id}.attempts").unlink(missing_ok=True)  # attempts count within this invocation
            pending.append(spec)
    order = [s.id for s in manifest.runs]
    if on_start:
        on_start(len(order), len(pending))

    def record(res: dict[str, Any]) -> None:
        results[res["id"]] = res
        write_summary([results[i] for i in order if i in results], out / SUMMARY_FILE)
        if on_result:
            on_result(res)

    if pending and use_ray:
        try:
            _run_ray(
                pending, out, address, gpus_per_task, cpus_per_task, retries, record, pool, keep_workers, pin_cores
            )
        except ConfigError:  # the cluster cannot run the tasks: leave nothing behind
            if created and not any(out.iterdir()):
                out.rmdir()
            raise
    else:
        for spec in pending:
            record(_run_inline(spec, out, retries, force_cpu=gpus_per_task == 0))
    final = [results[i] for i in order]
    write_summary(final, out / SUMMARY_FILE)
    return final


def _failed(spec: RunSpec, error: BaseException | str, attempts: int | None = None) -> dict[str, Any]:
    text = str(error).strip().splitlines()
    return {
        "id": spec.id,
        "tracker": spec.tracker,
        "hash": spec.hash,
        "params": spec.params,
        "status": "failed",
        "attempts": attempts,
        "error": text[-1] if text else type(error).__name__,
    }


def _run_inline(spec: RunSpec, out: Path, retries: int, force_cpu: bool) -> dict[str, Any]:
    for attempt in range(retries + 1):
        try:
            return execute_run(spec, out, force_cpu=force_cpu)
        except Exception as e:  # noqa: BLE001 - any failure of a run is retried, then reported in summary.csv
            log.warning("run %s: attempt %d failed: %s", spec.id, attempt + 1, e)
            last = e
    (out / f".{spec.id}.attempts").unlink(missing_ok=True)
    return _failed(spec, last, retries + 1)


def _run_ray(
    pending: Sequence[RunSpec],
    out: Path,
    address: str,
    gpus_per_task: float | None,
    cpus_per_task: float | None,
    retries: int,
    record: Callable[[dict[str, Any]], None],
    pool: str = "actors",
    keep_workers: bool = False,
    pin_cores: bool = False,
) -> None:
    import ray

    started = _ray_init(address)
    try:
        resources = ray.cluster_resources()
        gpus = float(resources.get("GPU", 0.0))
        if gpus_per_task is None:
            gpus_per_task = 1.0 if gpus >= 1 else 0.0
        if gpus_per_task > gpus:
            raise ConfigError(
                f"--gpus-per-task {gpus_per_task:g}: the Ray cluster has {gpus:g} GPU(s); use --gpus-per-task 0 "
                "for CPU runs"
            )
        if cpus_per_task is None:
            from wptrack.batch.actors import cpus_per_slot

            cpus_per_task = cpus_per_slot(ray.nodes(), gpus_per_task) if gpus_per_task > 0 else 1.0
        if cpus_per_task > float(resources.get("CPU", 0.0)):
            raise ConfigError(f"--cpus-per-task {cpus_per_task:g}: the Ray cluster has {resources.get('CPU', 0)} CPUs")
        threads = max(1, int(cpus_per_task))
        if pool == "actors":
            keep = keep_workers and not started  # a Ray instance we started ends with the batch
            _run_pool(pending, out, resources, gpus_per_task, cpus_per_task, retries, record, keep, pin_cores)
            return
        # GPU tasks: a fresh worker per run (max_calls=1), as CUDA_VISIBLE_DEVICES is fixed when CUDA starts
        task = ray.remote(num_gpus=gpus_per_task, num_cpus=cpus_per_task, max_calls=1 if gpus_per_task > 0 else 0)(
            execute_run
        ).options(max_retries=retries, retry_exceptions=True)
        refs = {task.remote(spec, str(out), gpus_per_task == 0, threads, time.time()): spec for spec in pending}
        waiting = list(refs)
        while waiting:
            ready, waiting = ray.wait(waiting, num_returns=1)
            spec = refs[ready[0]]
            try:
                record(ray.get(ready[0]))
            except ray.exceptions.RayError as e:
                log.warning("run %s failed after %d retries: %s", spec.id, retries, e)
                record(_failed(spec, getattr(e, "cause", None) or e, retries + 1))
                (out / f".{spec.id}.attempts").unlink(missing_ok=True)
                _clear_partials(out, spec.id)
    finally:
        if started:
            ray.shutdown()


def _run_pool(
    pending: Sequence[RunSpec],
    out: Path,
    resources: dict[str, float],
    gpus_per_task: float,
    cpus_per_task: float,
    retries: int,
    record: Callable[[dict[str, Any]], None],
    keep: bool = False,
    pin_cores: bool = False,
) -> None:
    """The runs on warm actors (:mod:`wptrack.batch.actors`), one per worker slot of the cluster."""
    from wptrack.batch.actors import NoWorkers, pool_size, run_actor_pool
    from wptrack.runs.spec import command

    trackers = sorted({s.tracker for s in pending if s.tracker != "function"})
    modules = [command(t).job.split(":")[0] for t in trackers]
    device = None if not trackers else "cpu" if gpus_per_task == 0 else "auto"
    threads = max(1, int(cpus_per_task))

    def failed(spec: RunSpec, error: BaseException | str, attempts: int) -> dict[str, Any]:
        (out / f".{spec.id}.attempts").unlink(missing_ok=True)
        _clear_partials(out, spec.id)
        return _failed(spec, error, attempts)

    workers = pool_size(resources, gpus_per_task, cpus_per_task, len(pending))
    try:
        run_actor_pool(
            pending,
            execute_run,
            lambda spec: (spec, str(out), gpus_per_task == 0, threads),
            workers,
            gpus_per_task,
            cpus_per_task,
            retries,
            record,
            failed,
            device,
            modules,
            keep=keep,
            pin=pin_cores,
        )
    except NoWorkers as e:
        raise ConfigError(f"{e}; see the Ray logs") from None
