"""Batches of runs and parameter sweeps, one Ray task per run (``wptrack batch MANIFEST --out DIR``).

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

* ``local`` (default): a new local Ray instance (``ray.init(address="local")``), one task per run, each pinned to
  ``gpus_per_task`` GPUs (``CUDA_VISIBLE_DEVICES`` set by Ray, so ``--device auto`` is the task's GPU) or, with
  ``gpus_per_task = 0``, to the CPU (``--device auto`` becomes ``cpu``) with ``cpus_per_task`` cores.
* ``auto`` / ``HOST:PORT`` / ``ray://HOST:PORT``: an existing Ray cluster. ``DIR`` and the inputs must be on a
  filesystem shared by the nodes, at the same paths, and wptrack installed on every node.
* ``inline``: no Ray; the runs one after another in this process (the default when Ray is not installed), same
  outputs and the same retries.

Fault tolerance: a run writes into ``DIR/.<run-id>.partial-<unique>`` and is renamed to ``DIR/<run-id>`` when it
completed (an older ``DIR/<run-id>`` is replaced); a run that raised (other than a user-input error, which is
reported at once) or whose worker died is retried up to ``retries`` times (Ray's ``max_retries`` and
``retry_exceptions``), each attempt from a clean partial folder. ``DIR/<run-id>/batch.json`` records the manifest
entry's hash: re-running the manifest skips the runs completed with the same entry (after a crash, a node loss or
Ctrl-C only the missing runs run again); a changed entry runs again and replaces its folder.
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

from wptrack.batch.manifest import Manifest, RunSpec, _load_function, load_manifest, track_parts, validate
from wptrack.core.errors import ConfigError, WptrackError

log = logging.getLogger(__name__)

BATCH_FILE = "batch.json"
"""Written into a run folder when the run completed: manifest entry hash, attempts, wall time, host."""
SUMMARY_FILE = "summary.csv"
DEFAULT_RETRIES = 2


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


def _run_track(spec: RunSpec, out: Path, force_cpu: bool) -> dict[str, Any]:
    """Run a tracker through the library (what ``wptrack track`` calls), then its scoring and report."""
    from wptrack.core.device import quiet_warp
    from wptrack.io.run import RUN_FILE
    from wptrack.runs.spec import command, replace_part, run_command, score_run

    cmd = command(spec.tracker)
    parts = track_parts(spec, out)
    if force_cpu and parts["control"].device == "auto":
        parts = replace_part(parts, "control", device="cpu")
    quiet_warp(True)
    control = parts["control"]
    run_command(cmd, parts, progress=False)
    score_run(cmd, parts)  # evaluation.json in the run folder
    if control.report:
        from wptrack.report import build_report

        build_report(out)
    run = json.loads((out / RUN_FILE).read_text(encoding="utf-8"))
    if run.get("status") != "complete":
        raise RuntimeError(f"run {spec.id}: run.json status is {run.get('status')!r}")
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
    spec: RunSpec, out_root: str | os.PathLike, force_cpu: bool = False, threads: int | None = None
) -> dict[str, Any]:
    """Run one batch run into ``out_root/<id>`` (through a partial folder renamed when complete).

    This is the Ray task (and the in-process fallback's step). A user-input error (:class:`WptrackError`) is
    returned as a ``failed`` result, not raised, so it is not retried; any other exception is raised (the batch
    retries the run). ``threads``: OpenCV's thread pool (video decoding) is limited to this many threads, the
    cores Ray reserved for the task (Ray limits OpenMP the same way), so that parallel runs on one machine do not
    oversubscribe its cores; None leaves OpenCV's default.

    Returns:
        The run's result row: id, tracker, status, attempts, seconds, host, error, summary, timings.
    """
    from wptrack.io.atomic import atomic_write_json

    if threads is not None:
        import cv2

        cv2.setNumThreads(max(1, int(threads)))
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
    }
    t0 = time.perf_counter()
    try:
        run = _run_function(spec, partial) if spec.tracker == "function" else _run_track(spec, partial, force_cpu)
    except WptrackError as e:  # not retried: this invocation's count ends here
        shutil.rmtree(partial, ignore_errors=True)
        (root / f".{spec.id}.attempts").unlink(missing_ok=True)
        return {**result, "status": "failed", "error": str(e), "seconds": time.perf_counter() - t0}
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    result.update(
        status="complete",
        error="",
        seconds=time.perf_counter() - t0,
        summary=run.get("summary") or {},
        timings={k: v.get("total_s") for k, v in (run.get("timings") or {}).items() if isinstance(v, dict)},
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


SUMMARY_COLUMNS = ["id", "tracker", "status", "reused", "attempts", "seconds", "frames_per_s", "host", "gpus", "error"]


def write_summary(results: Sequence[dict[str, Any]], path: str | os.PathLike) -> Path:
    """``summary.csv``: one row per run: the fixed columns, the grid parameters (``param.NAME``), the run's
    summary metrics (flattened: ``error.mean_error_after``...) and per-stage totals (``time.STAGE_s``)."""
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
        rows.append(row)
    extra = sorted({k for row in rows for k in row} - set(SUMMARY_COLUMNS), key=lambda k: (k.split(".")[0], k))
    params = [k for k in extra if k.startswith("param.")]
    times = [k for k in extra if k.startswith("time.")]
    metrics = [k for k in extra if k not in params and k not in times]
    columns = SUMMARY_COLUMNS + params + metrics + times
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
    cpus_per_task: float = 1.0,
    retries: int | None = None,
    on_result: Callable[[dict[str, Any]], None] | None = None,
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
        cpus_per_task: CPU cores reserved per run (Ray's ``num_cpus``).
        retries: attempts after the first for a run that raised or whose worker died (default: the manifest's
            ``retries``, else 2).
        on_result: called with each run's result as it arrives (also for runs skipped as already complete).

    Returns:
        The results in manifest order: ``status`` ``complete`` or ``failed``, ``reused`` for skipped runs.

    Raises:
        ConfigError: a bad manifest or run (before anything runs), a Ray address that cannot be joined, Ray asked
            for but not installed, more GPUs per task than the cluster has.
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
    if not (cpus_per_task > 0):
        raise ConfigError(f"--cpus-per-task: expected a number > 0, got {cpus_per_task!r}")
    for spec in manifest.runs:
        validate(spec)
    use_ray = address != "inline"
    if use_ray and not ray_available():
        if address != "local":
            raise ConfigError(f"--address {address}: Ray is not installed (pip install 'wptrack[ray]')")
        log.warning("Ray is not installed: running the batch in this process, one run after another")
        use_ray = False
    created = not Path(out_dir).exists()
    out = ensure_writable_dir(out_dir)
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

    def record(res: dict[str, Any]) -> None:
        results[res["id"]] = res
        write_summary([results[i] for i in order if i in results], out / SUMMARY_FILE)
        if on_result:
            on_result(res)

    if pending and use_ray:
        try:
            _run_ray(pending, out, address, gpus_per_task, cpus_per_task, retries, record)
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
    cpus_per_task: float,
    retries: int,
    record: Callable[[dict[str, Any]], None],
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
        if cpus_per_task > float(resources.get("CPU", 0.0)):
            raise ConfigError(f"--cpus-per-task {cpus_per_task:g}: the Ray cluster has {resources.get('CPU', 0)} CPUs")
        # GPU tasks: a fresh worker per run (max_calls=1), as CUDA_VISIBLE_DEVICES is fixed when CUDA starts
        task = ray.remote(num_gpus=gpus_per_task, num_cpus=cpus_per_task, max_calls=1 if gpus_per_task > 0 else 0)(
            execute_run
        ).options(max_retries=retries, retry_exceptions=True)
        threads = max(1, int(cpus_per_task))
        refs = {task.remote(spec, str(out), gpus_per_task == 0, threads): spec for spec in pending}
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
