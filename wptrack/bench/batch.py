"""Parallel efficiency of ``wptrack batch`` on Ray: K identical-size colour runs with 1 worker, then with G workers.

Definition. ``K`` runs of the S1 colour tracker on the synthetic lab scene (``s1-lab``, 2 cameras, ``frames``
frames, ``particles`` particles, seeds 0..K-1, so every run does the same work) are run by ``run_batch`` on a fresh
local Ray instance that offers 1 worker slot (``num_gpus=1`` with one GPU per task, or ``num_cpus=1`` with one CPU
per task), then on one that offers ``G`` slots (``G`` GPUs, or ``G`` CPU cores). ``T1`` and ``TG`` are the wall
times of ``run_batch`` (all K tasks submitted to the last result; Ray's own start-up is outside, each task's worker
start-up and Warp initialisation inside). The parallel efficiency is

    E = T1 / (G * TG)          (1.0: linear scaling; K a multiple of G keeps the last wave full)

Before timing, one run compiles the kernels into Warp's kernel cache (shared by the workers). The G-worker batch
must give the same ``tracks.csv`` per run as the 1-worker batch (``equivalent``).

Run: ``python -m wptrack.bench.batch --gpus 2 --runs 8 16 32 --particles 1e6 --frames 300`` (GPU; ``--cpus N``
for CPU workers), or ``wptrack bench --tracker batch --device cuda|cpu [--runs K..] [--particles N] [--frames F]``
(G: every GPU, or every CPU core).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

HEADER = (
    f"{'suite':6s} {'N':>10s} {'K':>4s} {'G':>3s} {'kind':4s} {'frames':>6s} {'T1 s':>9s} {'TG s':>9s} "
    f"{'speed-up':>8s} {'efficiency':>10s} {'eq':>4s}"
)


def format_row(r: dict) -> str:
    eq = {True: "yes", False: "NO"}.get(r.get("equivalent"), "-")
    return (
        f"{'batch':6s} {r['particles']:>10d} {r['runs']:>4d} {r['workers']:>3d} {r['kind']:4s} {r['frames']:>6d} "
        f"{r['t1_s']:9.2f} {r['tg_s']:9.2f} {r['speedup']:8.3f} {r['parallel_efficiency']:10.3f} {eq:>4s}  "
        f"(one run: {r['run_s_1']:.2f} s alone, {r['run_s_g']:.2f} s with {r['workers']} workers; "
        f"GPU:device {' '.join(r['used_g'])})"
    )


@dataclass(frozen=True)
class BatchCase:
    particles: int
    runs: int


def _scene(work: Path, frames: int) -> tuple[Path, dict]:
    """The s1-lab scene with ``frames`` frames in ``work`` (rendered once per work folder and frame count)."""
    from wptrack.synth import render_scene

    out = work / f"scene-{frames}"
    if not (out / "scene.json").exists():
        render_scene("s1-lab", out, frames=frames, seed=0)
    return out, json.loads((out / "scene.json").read_text())


def _manifest(scene_dir: Path, hints: dict, particles: int, runs: int, frames: int, device: str) -> Path:
    import yaml

    t = hints["target"]
    doc = {
        "tracker": "color",
        "retries": 0,
        "args": {
            "rig": "rig.yaml",
            "video": list(hints["videos"]),
            "hue": list(t["hue"]),
            "sat": list(t["sat"]),
            "intensity": list(t["intensity"]),
            "init": list(hints["init"]),
            "sigma": float(hints.get("sigma", 0.03)),
            "particles": int(particles),
            "keep_particles": 100,
            "max_frames": int(frames),
            "device": device,
        },
        "runs": [{"id": "seed{seed}", "grid": {"seed": list(range(runs))}}],
    }
    path = scene_dir / f"batch-{particles}-{runs}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _timed_batch(manifest: Path, out: Path, workers: int, gpu: bool) -> tuple[float, float, list[str]]:
    """(wall seconds of the batch, mean seconds of one run inside its task, the GPU ids / devices the runs used)
    with ``workers`` worker slots."""
    import ray

    from wptrack.batch import run_batch

    if ray.is_initialized():
        ray.shutdown()
    kw = {"num_gpus": workers, "num_cpus": max(workers, 2)} if gpu else {"num_cpus": workers, "num_gpus": 0}
    ray.init(address="local", include_dashboard=False, log_to_driver=False, **kw)
    try:
        t0 = time.perf_counter()
        res = run_batch(manifest, out, gpus_per_task=1 if gpu else 0, cpus_per_task=1)
        seconds = time.perf_counter() - t0
    finally:
        ray.shutdown()
    bad = [r["id"] for r in res if r["status"] != "complete"]
    if bad:
        raise RuntimeError(f"batch bench: runs failed: {bad} ({res[0].get('error')})")
    used = sorted({f"{r.get('gpus') or '-'}:{(r.get('summary') or {}).get('device')}" for r in res})
    return seconds, sum(r["seconds"] for r in res) / len(res), used


def parallel_efficiency(
    runs: int = 8,
    workers: int = 2,
    particles: int = 10_000,
    frames: int = 50,
    gpu: bool = False,
    work_dir: str | Path | None = None,
) -> dict[str, Any]:
    """Measure E = T1 / (G TG) (see the module docstring) and return the numbers as a dict."""
    import ray

    from wptrack.batch import execute_run
    from wptrack.batch.manifest import load_manifest
    from wptrack.core.device import quiet_warp

    quiet_warp(True)
    tmp = tempfile.TemporaryDirectory(prefix="wptrack-batch-bench-") if work_dir is None else None
    work = Path(tmp.name if tmp else work_dir)
    try:
        scene_dir, hints = _scene(work, frames)
        device = "auto" if gpu else "cpu"  # auto in a GPU task: the task's GPU (CUDA_VISIBLE_DEVICES)
        manifest = _manifest(scene_dir, hints, particles, runs, frames, device)
        batches = work / f"batches-{particles}-{runs}-{frames}"
        shutil.rmtree(batches, ignore_errors=True)  # every run runs (none reused from an earlier measurement)
        execute_run(load_manifest(manifest).runs[0], batches / "warmup")  # compile the kernels into the cache
        t1, run1, used1 = _timed_batch(manifest, batches / "w1", 1, gpu)
        tg, rung, usedg = _timed_batch(manifest, batches / f"w{workers}", workers, gpu)
        ids = [s.id for s in load_manifest(manifest).runs]
        equivalent = all(
            (batches / "w1" / i / "tracks.csv").read_bytes()
            == (batches / f"w{workers}" / i / "tracks.csv").read_bytes()
            for i in ids
        )
        from wptrack.io.run import versions

        return {
            "suite": "batch",
            "kind": "gpu" if gpu else "cpu",
            "particles": int(particles),
            "runs": int(runs),
            "workers": int(workers),
            "frames": int(frames),
            "t1_s": t1,
            "tg_s": tg,
            "run_s_1": run1,
            "run_s_g": rung,
            "used_1": used1,  # CUDA_VISIBLE_DEVICES:device of the runs
            "used_g": usedg,
            "speedup": t1 / tg,
            "parallel_efficiency": t1 / (workers * tg),
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="parallel efficiency of wptrack batch on Ray (1 vs G workers)")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--gpus", type=int, help="G GPU workers (one GPU per run)")
    g.add_argument("--cpus", type=int, help="G CPU workers (one core per run, device cpu)")
    ap.add_argument("--runs", type=int, nargs="+", default=[8], help="K runs per batch (default 8)")
    ap.add_argument("--particles", type=float, default=10_000)
    ap.add_argument("--frames", type=int, default=50)
    ap.add_argument("--out", default=None, help="write the results as JSON here")
    ap.add_argument("--work", default=None, help="work folder (scene, run outputs; default: a temporary one)")
    a = ap.parse_args(argv)
    gpu = a.gpus is not None
    results = []
    print(HEADER)
    with tempfile.TemporaryDirectory(prefix="wptrack-batch-bench-") as tmp:
        for k in a.runs:  # one scene for every K
            r = parallel_efficiency(k, a.gpus if gpu else a.cpus, int(a.particles), a.frames, gpu, a.work or tmp)
            results.append(r)
            print(format_row(r), flush=True)
            if a.out:
                Path(a.out).write_text(json.dumps(results, indent=2))
    return 0 if all(r["equivalent"] for r in results) else 1


if __name__ == "__main__":
    raise SystemExit(main())
