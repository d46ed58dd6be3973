"""Parallel efficiency of ``wptrack batch`` on Ray: K identical-size runs with one worker, then with G GPUs (or CPU
cores), on warm actors or one task per run, and where the time goes (the runs' stage times).

Definition. ``K`` runs of one tracker (seeds 0..K-1, the same video, so every run does the same work) are run by
``run_batch`` on a fresh local Ray instance that offers one worker slot (one GPU, or one CPU core; ``T1``), then on
one offering ``G`` GPUs with ``slots`` workers per GPU (``gpus_per_task = 1 / slots``), or ``G`` CPU cores
(``TG``). Both batches reserve the same ``cpus_per_task`` cores per worker (default: the machine's cores over
``G x slots``), so their runs decode with the same threads. ``T1``, ``TG``: wall time of ``run_batch``, Ray's own
start outside. With ``--pool tasks`` every run's worker start, imports and Warp start are inside (each task pays
them). With ``--pool actors`` (warm workers) the pool is started before the timed batch, by a batch of tiny runs
(2 frames, two per worker) that also loads the kernels in every worker, and kept for the timed batch
(``keep_workers``): T is then the steady state of warm workers, and the pool's start (``pool start``: from that
batch's start until every worker began its first run, paid once per ``wptrack batch`` command or per Python
session) is reported beside it, with
``E cold = (S1 + T1) / (G (SG + TG))``, the efficiency had the pool started inside (``--cold`` measures that
directly). The parallel efficiency is

    E = T1 / (G * TG)          (1.0: linear scaling; K a multiple of G x slots keeps the last wave full)

and it splits exactly into two factors, both reported: ``E = (r1 / rG) x (bG / b1)``, where ``r`` is the mean wall
time of one run inside its worker (``r1`` alone, ``rG`` with the others at once: "runs slow each other down") and
``b`` the busy fraction of the worker slots, ``sum(run seconds) / (slots x T)`` (what the batch spends outside the
runs: a task's worker start, dispatch, the pool's start, the last wave's tail). The mean stage times of the runs
(:mod:`wptrack.batch.worker`: wait, import, Warp start, device context, set-up, kernel load, frame loop, decode
wait, CPU cores used) say which part of a run grew.

Cases: ``color`` is the S1 colour tracker on the synthetic lab scene (2 cameras 320x240, FFV1 as ``wptrack synth``
writes it) at ``particles``; ``templates`` the S3 template tracker on a real-size video: the ``s3-people`` plaza
rendered at 640x480 and scaled to 1440x1080 (the camera's calibration is scaled with it by the tracker), MPEG-4
(``.mp4``), motion masks by the default background model, no ``virtual.avi``. A long run (more frames than
rendered) plays the rendered frames forward and back (ping-pong), so the motion stays continuous. The videos are
written once per work folder.

Long runs make a one-worker baseline of K runs expensive: ``--t1-runs K1`` measures T1 on K1 runs and extrapolates
it to K exactly as a one-slot batch behaves (``T1(K) = overhead + K x cycle``, with the overhead and the per-run cycle
taken from the K1 runs' start and end times); such rows say ``T1 from K1``.

Before timing, one run compiles the kernels into Warp's kernel cache (shared by the workers). The G-worker batch
must give the same ``tracks.csv`` per run as the 1-worker batch (``equivalent``).

Run (GPU): ``python -m wptrack.bench.batch --gpus 2 --runs 8 16 32 64 --tracker color --length short --pool actors
tasks --out batch_gpu.json`` (see BENCHMARKS.md for the commands per machine); CPU workers: ``--cpus N``.
``wptrack bench --tracker batch --device cuda|cpu [--runs K..] [--particles N] [--frames F]`` runs the colour case on
warm actors over every GPU (or CPU core).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import shutil
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

HEADER = (
    f"{'suite':6s} {'tracker':9s} {'pool':6s} {'len':5s} {'N':>8s} {'K':>4s} {'G':>2s} {'sl':>2s} {'frames':>6s} "
    f"{'T1 s':>8s} {'TG s':>8s} {'speed-up':>8s} {'E':>6s} {'r1/rG':>6s} {'bG/b1':>6s} {'eq':>3s}"
)

STAGE_KEYS = ("wait_s", "start_s", "setup_s", "module_load_s", "frame_loop_s", "decode_wait_s", "finish_s", "cores")
"""The stage means shown per batch: ``start_s`` is import + Warp start + device context; ``cores`` is CPU seconds
over wall seconds of a run."""


def format_row(r: dict) -> str:
    eq = {True: "yes", False: "NO"}.get(r.get("equivalent"), "-")
    t1 = f"{r['t1_s']:8.2f}" + ("*" if r.get("t1_from") else " ")
    line = (
        f"{'batch':6s} {r['tracker']:9s} {r['pool']:6s} {r['length']:5s} {r['particles']:>8.0e} {r['runs']:>4d} "
        f"{r['workers']:>2d} {r['slots']:>2d} {r['frames']:>6d} {t1}{r['tg_s']:8.2f} {r['speedup']:8.3f} "
        f"{r['parallel_efficiency']:6.3f} {r['run_ratio']:6.3f} {r['busy_ratio']:6.3f} {eq:>3s}"
    )
    one = (
        f"\n       one run {r['run_s_1']:.2f} s alone, {r['run_s_g']:.2f} s with {r['workers'] * r['slots']} workers; "
        f"busy {r['busy_1']:.3f} / {r['busy_g']:.3f}; {r['cpus_per_task']:g} cores per worker "
        f"({'bound to their own' if r.get('pin_cores') else 'free'}: may use {r.get('worker_cores_1')} / "
        f"{r.get('worker_cores_g')}); pool start "
        f"{r['pool_start_1']:.2f} / {r['pool_start_g']:.2f} s, E with it {r['parallel_efficiency_cold']:.3f}"
    )
    if r.get("t1_from"):
        one += f"; T1 from {r['t1_from']} runs"
    stages = "".join(
        f"\n       {label:>5s}: " + " ".join(f"{k}={r[key].get(k, float('nan')):.3f}" for k in STAGE_KEYS)
        for label, key in (("alone", "stages_1"), ("at G", "stages_g"))
    )
    return line + one + stages


@dataclass(frozen=True)
class BatchCase:
    particles: int
    runs: int


# ------------------------------------------------------------------------------------------------- the videos
def pingpong(n: int, total: int) -> Iterator[int]:
    """Frame indices 0, 1, ..., n-1, n-2, ..., 1, 0, 1, ... (``total`` of them): ``n`` rendered frames played
    forward and back, a continuous motion as long as wanted."""
    period = max(1, 2 * n - 2)
    for i in range(total):
        k = i % period
        yield k if k < n else period - k


def _read_all(path: Path) -> list[np.ndarray]:
    from wptrack.io.frames import open_source

    return list(open_source(str(path)))


def colour_scene(work: Path, frames: int, render_max: int = 400) -> tuple[Path, dict]:
    """The s1-lab scene with ``frames`` frames in ``work`` (rendered once per work folder and frame count; more
    than ``render_max`` frames: ``render_max`` rendered, played forward and back)."""
    from wptrack.io.video import write_video
    from wptrack.synth import render_scene

    out = work / f"lab-{frames}"
    if (out / "scene.json").exists():
        return out, json.loads((out / "scene.json").read_text())
    rendered = work / f"lab-render-{min(frames, render_max)}"
    if not (rendered / "scene.json").exists():
        render_scene("s1-lab", rendered, frames=min(frames, render_max), seed=0)
    if frames <= render_max:
        return rendered, json.loads((rendered / "scene.json").read_text())
    tmp = work / f".lab-{frames}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    hints = json.loads((rendered / "scene.json").read_text())
    shutil.copy(rendered / "rig.yaml", tmp / "rig.yaml")
    for video in hints["videos"]:
        src = _read_all(rendered / video)
        write_video(tmp / video, (src[i] for i in pingpong(len(src), frames)), fps=float(hints.get("fps", 25.0)))
    (tmp / "scene.json").write_text(json.dumps({**hints, "frames": frames}))
    os.replace(tmp, out)
    return out, hints


def template_scene(work: Path, frames: int, size: tuple[int, int] = (1440, 1080), render_max: int = 200) -> Path:
    """The s3-people plaza as a real-size video: ``min(frames, render_max)`` frames rendered at 640x480, scaled to
    ``size`` (same aspect ratio) and played forward and back to ``frames`` frames, MPEG-4; with the scene's rig."""
    import cv2

    from wptrack.io.video import write_video
    from wptrack.synth import render_scene

    out = work / f"plaza-{size[0]}x{size[1]}-{frames}"
    if (out / "video.mp4").exists():
        return out
    rendered = work / f"plaza-render-{min(frames, render_max)}"
    if not (rendered / "scene.json").exists():
        render_scene("s3-people", rendered, frames=min(frames, render_max), seed=0)
    src = _read_all(rendered / "cam0.avi")  # 640x480: scaled frame by frame (the scaled clip would be GBs)
    out.mkdir(parents=True, exist_ok=True)
    shutil.copy(rendered / "rig.yaml", out / "rig.yaml")
    scaled = (cv2.resize(src[i], size, interpolation=cv2.INTER_LINEAR) for i in pingpong(len(src), frames))
    write_video(out / "video.mp4", scaled, fps=15.0)
    return out


def _manifest(
    work: Path, tracker: str, particles: int, runs: int, frames: int, device: str, max_frames: int | None = None
) -> Path:
    """K runs (seeds 0..K-1) on the case's video of ``frames`` frames, each tracking ``max_frames`` of them (default
    all)."""
    import yaml

    if tracker == "color":
        scene, hints = colour_scene(work, frames)
        t = hints["target"]
        args = {
            "rig": str(scene / "rig.yaml"),
            "video": [str(scene / v) for v in hints["videos"]],
            "hue": list(t["hue"]),
            "sat": list(t["sat"]),
            "intensity": list(t["intensity"]),
            "init": list(hints["init"]),
            "sigma": float(hints.get("sigma", 0.03)),
            "keep_particles": 100,
        }
    elif tracker == "templates":
        scene = template_scene(work, frames)
        args = {"rig": str(scene / "rig.yaml"), "video": str(scene / "video.mp4"), "virtual": False}
    else:
        raise ValueError(f"batch bench: unknown tracker {tracker!r} (color, templates)")
    doc = {
        "tracker": tracker,
        "retries": 0,
        "args": {**args, "particles": int(particles), "max_frames": int(max_frames or frames), "device": device},
        "runs": [{"id": "seed{seed}", "grid": {"seed": list(range(runs))}}],
    }
    path = work / f"batch-{tracker}-{particles}-{runs}-{frames}-{max_frames or frames}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


# ------------------------------------------------------------------------------------------------- one batch
def _stage_means(results: list[dict]) -> dict[str, float]:
    out: dict[str, float] = {}
    stages = [r.get("stages") or {} for r in results]
    for k in ("wait_s", "setup_s", "module_load_s", "frame_loop_s", "decode_wait_s", "finish_s", "total_s"):
        vals = [s[k] for s in stages if isinstance(s.get(k), (int, float))]
        if vals:
            out[k] = float(np.mean(vals))
    start = [sum(s.get(k) or 0.0 for k in ("import_s", "warp_init_s", "context_s")) for s in stages]
    out["start_s"] = float(np.mean(start)) if start else float("nan")
    cores = [s["cpu_s"] / s["total_s"] for s in stages if s.get("total_s") and "cpu_s" in s]
    out["cores"] = float(np.mean(cores)) if cores else float("nan")
    return out


def _timed_batch(
    manifest: Path,
    out: Path,
    gpus: int,
    slots: int,
    cpus_per_task: float,
    pool: str,
    gpu: bool,
    warm: Path | None,
    pin: bool = False,
) -> dict[str, Any]:
    """One batch on a fresh local Ray instance offering ``gpus`` GPUs x ``slots`` workers (GPU) or ``gpus`` cores
    (CPU); its wall time, mean run seconds, busy fraction, stage means and the runs' start/end times. With ``warm``
    (a manifest of tiny runs; actors only) the pool is started by a batch of those first (kept for the timed batch;
    its wall time is ``pool_start_s``), so the timed batch measures warm workers."""
    import ray

    from wptrack.batch import run_batch
    from wptrack.batch.actors import release_workers

    if ray.is_initialized():
        ray.shutdown()
    workers = gpus * slots if gpu else gpus
    cpus = max(1, int(np.ceil(cpus_per_task * workers)))
    kw = {"num_gpus": gpus, "num_cpus": cpus} if gpu else {"num_cpus": cpus, "num_gpus": 0}
    ray.init(address="local", include_dashboard=False, log_to_driver=False, **kw)
    shape = {"gpus_per_task": 1.0 / slots if gpu else 0, "cpus_per_task": cpus_per_task, "pool": pool, "pin_cores": pin}
    keep = warm is not None and pool == "actors"
    try:
        pool_start = 0.0
        if keep:  # the pool's start: until every worker began its first (warm-up) run
            t0 = time.time()
            warmed = run_batch(warm, out.parent / f".{out.name}-warm", keep_workers=True, **shape)
            first: dict[int, float] = {}
            for r in warmed:
                first[r["pid"]] = min(first.get(r["pid"], r["started_at"]), r["started_at"])
            pool_start = max(first.values()) - t0
        t0 = time.time()
        res = run_batch(manifest, out, keep_workers=keep, **shape)
        t_end = time.time()
        release_workers()
    finally:
        ray.shutdown()
    bad = [r["id"] for r in res if r["status"] != "complete"]
    if bad:
        raise RuntimeError(f"batch bench: runs failed: {bad} ({next(r for r in res if r['id'] in bad).get('error')})")
    seconds = t_end - t0
    busy = sum(r["seconds"] for r in res) / (workers * seconds)
    starts = sorted(r["started_at"] for r in res)
    ends = sorted(r["ended_at"] for r in res)
    return {
        "seconds": seconds,
        "pool_start_s": pool_start,
        "run_s": float(np.mean([r["seconds"] for r in res])),
        "busy": busy,
        "stages": _stage_means(res),
        "overhead_s": (starts[0] - t0) + (t_end - ends[-1]),
        "cycle_s": (ends[-1] - starts[0]) / len(res),
        "used": sorted({f"{r.get('gpus') or '-'}:{(r.get('summary') or {}).get('device')}" for r in res}),
        "workers_seen": len({(r.get("host"), r.get("pid")) for r in res}),
        "worker_cores": sorted({r.get("worker_cores") for r in res if r.get("worker_cores") is not None}),
    }


def parallel_efficiency(
    runs: int = 8,
    workers: int = 2,
    particles: int = 10_000,
    frames: int = 50,
    gpu: bool = False,
    work_dir: str | Path | None = None,
    pool: str = "actors",
    tracker: str = "color",
    slots: int = 1,
    cpus_per_task: float | None = None,
    t1_runs: int | None = None,
    length: str = "-",
    warm: bool = True,
    baselines: dict | None = None,
    pin: bool = False,
) -> dict[str, Any]:
    """Measure E = T1 / (G TG) (see the module docstring) and return the numbers as a dict.

    Args:
        runs: K.
        workers: G (GPUs, or CPU cores with ``gpu=False``).
        particles, frames: each run's size.
        gpu: GPU workers (``device: auto`` in a GPU worker is its GPU) or CPU ones (``device: cpu``).
        work_dir: where the videos and batches go (default: a temporary folder).
        pool: ``actors`` or ``tasks`` (:func:`wptrack.batch.run_batch`).
        tracker: ``color`` or ``templates``.
        slots: workers per GPU in the G batch (``gpus_per_task = 1 / slots``; GPU only).
        cpus_per_task: cores per worker in both batches (default: the machine's cores over ``G x slots``, at least 1).
        t1_runs: measure T1 on this many runs and extrapolate it to K (None: on K runs).
        length: a label of the run length (``short``, ``long``).
        warm: actors: start the pool before timing (its start is reported as ``pool_start``, and ``E_cold`` adds it
            to T1 and TG); False: the pool starts inside the timed batch.
        baselines: a dict kept between calls: a T1 measured on ``t1_runs`` runs is measured once per case shape and
            reused for every K.
        pin: actors: each worker bound to a block of ``cpus_per_task`` cores of its own in both batches
            (``run_batch(pin_cores=...)``).
    """
    import ray

    from wptrack.batch import execute_run
    from wptrack.batch.manifest import load_manifest
    from wptrack.core.config import host_cores
    from wptrack.core.device import quiet_warp

    quiet_warp(True)
    slots = max(1, int(slots)) if gpu else 1
    if cpus_per_task is None:
        cpus_per_task = float(max(1, host_cores() // (workers * slots))) if gpu else 1.0
    tmp = tempfile.TemporaryDirectory(prefix="wptrack-batch-bench-") if work_dir is None else None
    work = Path(tmp.name if tmp else work_dir)
    try:
        device = "auto" if gpu else "cpu"  # auto in a GPU worker: the worker's GPU (CUDA_VISIBLE_DEVICES)
        manifest = _manifest(work, tracker, particles, runs, frames, device)
        k1 = runs if not t1_runs or t1_runs >= runs else int(t1_runs)
        manifest_1 = manifest if k1 == runs else _manifest(work, tracker, particles, k1, frames, device)
        tiny = _manifest(work, tracker, particles, 2 * workers * slots, frames, device, max_frames=2)
        warm_manifest = tiny if warm and pool == "actors" else None
        batches = work / f"batches-{tracker}-{pool}-{particles}-{runs}-{frames}-{slots}"
        shutil.rmtree(batches, ignore_errors=True)  # every run runs (none reused from an earlier measurement)
        execute_run(load_manifest(tiny).runs[0], batches / "compile")  # compile the kernels into the cache
        key = (tracker, pool, particles, frames, k1, cpus_per_task, warm_manifest is not None, pin)
        if k1 < runs and baselines is not None and key in baselines:
            one, w1 = baselines[key]
        else:
            w1 = batches / "w1"
            one = _timed_batch(manifest_1, w1, 1, 1, cpus_per_task, pool, gpu, warm_manifest, pin)
            if k1 < runs and baselines is not None:
                baselines[key] = (one, w1)
        t1 = one["seconds"] if k1 == runs else one["overhead_s"] + runs * one["cycle_s"]
        many = _timed_batch(
            manifest, batches / f"w{workers}", workers, slots, cpus_per_task, pool, gpu, warm_manifest, pin
        )
        tg = many["seconds"]
        s1, sg = one["pool_start_s"], many["pool_start_s"]
        ids = [s.id for s in load_manifest(manifest_1).runs]
        equivalent = all(
            (w1 / i / "tracks.csv").read_bytes() == (batches / f"w{workers}" / i / "tracks.csv").read_bytes()
            for i in ids
        )
        from wptrack.io.run import versions

        return {
            "suite": "batch",
            "kind": "gpu" if gpu else "cpu",
            "tracker": tracker,
            "pool": pool,
            "length": length,
            "particles": int(particles),
            "runs": int(runs),
            "workers": int(workers),
            "slots": int(slots),
            "cpus_per_task": float(cpus_per_task),
            "pin_cores": bool(pin and pool == "actors"),
            "worker_cores_1": one["worker_cores"],
            "worker_cores_g": many["worker_cores"],
            "frames": int(frames),
            "t1_s": t1,
            "t1_from": None if k1 == runs else k1,
            "tg_s": tg,
            "run_s_1": one["run_s"],
            "run_s_g": many["run_s"],
            "busy_1": one["busy"],
            "busy_g": many["busy"],
            "run_ratio": one["run_s"] / many["run_s"],
            "busy_ratio": many["busy"] / one["busy"],
            "stages_1": one["stages"],
            "stages_g": many["stages"],
            "used_1": one["used"],  # CUDA_VISIBLE_DEVICES:device of the runs
            "used_g": many["used"],
            "workers_seen_g": many["workers_seen"],
            "pool_start_1": s1,
            "pool_start_g": sg,
            "overhead_1": one["overhead_s"],
            "overhead_g": many["overhead_s"],
            "speedup": t1 / tg,
            "parallel_efficiency": t1 / (workers * tg),
            "parallel_efficiency_cold": (s1 + t1) / (workers * (sg + tg)),
            "equivalent": equivalent,
            "ray": ray.__version__,
            "cpu_count": os.cpu_count(),
            "versions": versions(),
        }
    finally:
        if tmp is not None:
            tmp.cleanup()


class BatchSuite:
    """``wptrack bench --tracker batch``: parallel efficiency over every GPU (CUDA device) or CPU core."""

    name = "batch"
    second = "runs"
    HEADER = HEADER
    format_row = staticmethod(format_row)

    @staticmethod
    def default_grid(is_cuda: bool) -> list[BatchCase]:
        if is_cuda:
            return [BatchCase(1_000_000, k) for k in (8, 16, 32)]
        return [BatchCase(5_000, 4)]

    @staticmethod
    def run_case(case: BatchCase, device: str, frames: int = 50, numpy_max: int = 0) -> dict[str, Any]:
        import warp as wp

        gpu = wp.get_device(device).is_cuda
        workers = wp.get_cuda_device_count() if gpu else (os.cpu_count() or 1)
        return parallel_efficiency(case.runs, workers, case.particles, frames, gpu)


LENGTHS = {"color": {"short": 200, "long": 8000}, "templates": {"short": 100, "long": 2000}}
"""Frames of a short (about 1-2 s on an H100) and a long run (about 20-60 s) per tracker; ``--frames`` overrides."""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="parallel efficiency of wptrack batch on Ray (1 vs G workers)")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--gpus", type=int, help="G GPUs")
    g.add_argument("--cpus", type=int, help="G CPU workers (one core per run, device cpu)")
    ap.add_argument("--runs", type=int, nargs="+", default=[8], help="K runs per batch (default 8)")
    ap.add_argument("--tracker", nargs="+", default=["color"], choices=("color", "templates"))
    ap.add_argument("--length", nargs="+", default=["short"], choices=("short", "long"), help="run lengths")
    ap.add_argument("--frames", type=int, default=None, help="frames per run (default: by --length, LENGTHS)")
    ap.add_argument("--pool", nargs="+", default=["actors"], choices=("actors", "tasks"))
    ap.add_argument("--slots", type=int, nargs="+", default=[1], help="workers per GPU in the G batch (default 1)")
    ap.add_argument("--particles", type=float, default=None, help="default: 1e6 colour, 1000 templates")
    ap.add_argument("--cpus-per-task", type=float, default=None, help="cores per worker (default: cores / workers)")
    ap.add_argument("--t1-runs", type=int, default=None, help="measure T1 on this many runs, extrapolated to K")
    ap.add_argument("--cold", action="store_true", help="actors: start the pool inside the timed batches")
    ap.add_argument(
        "--pin",
        nargs="+",
        default=["off"],
        choices=("on", "off"),
        help="actors: workers bound to cores of their own (on: wptrack batch --pin-cores) or free on every core (off, "
        "default); both: a row each",
    )
    ap.add_argument("--out", default=None, help="write the results as JSON here (rewritten after each case)")
    ap.add_argument("--work", default=None, help="work folder (videos, run outputs; default: a temporary one)")
    a = ap.parse_args(argv)
    gpu = a.gpus is not None
    results = []
    baselines: dict = {}
    print(HEADER, flush=True)
    with tempfile.TemporaryDirectory(prefix="wptrack-batch-bench-") as tmp:
        for tracker in a.tracker:
            particles = int(a.particles or (1_000_000 if tracker == "color" else 1000))
            for length in a.length:
                frames = a.frames or LENGTHS[tracker][length]
                for pool, pin in itertools.product(a.pool, a.pin):
                    if pool == "tasks" and pin == "on" and "off" in a.pin:
                        continue  # tasks are never pinned: one row
                    for slots in a.slots if gpu else [1]:
                        for k in a.runs:
                            r = parallel_efficiency(
                                k, a.gpus if gpu else a.cpus, particles, frames, gpu, a.work or tmp, pool, tracker,
                                slots, a.cpus_per_task, a.t1_runs, length, not a.cold, baselines, pin == "on",
                            )  # fmt: skip
                            results.append(r)
                            print(format_row(r), flush=True)
                            if a.out:
                                Path(a.out).write_text(json.dumps(results, indent=2))
    return 0 if all(r["equivalent"] for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
