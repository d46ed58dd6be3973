"""Multi-core CPU measurement: do independent colour trackers (or NumPy reference filters) run in parallel when
stepped from worker threads or worker processes?

Warp's CPU backend runs each kernel launch on one core. A multi-core path needs launches from several threads to
overlap, which they do only if Warp releases the GIL for the duration of a CPU launch; processes overlap regardless.
Each worker owns its tracker (its own particle arrays and frame buffers) and tracks its own sequence: ``W`` workers x
``F`` frames are timed from a common start (a barrier) to the last worker's end, after warm-up (kernel compilation
and the first frames outside the timing). Throughput = W F / wall; the speed-up is against one worker.

Run: ``python -m wptrack.bench.cpu_threads --particles 1e5 --cameras 4 --frames 20 --workers 1 2`` (add
``--impl numpy`` for the NumPy reference filter, ``--impl warp-observe`` for the tracker's observation stage alone,
whose launches are untiled; ``taskset -c 0`` in front pins everything to one core).

Finding (Warp 1.19, see BENCHMARKS.md "CPU: multi-core"): a CPU launch is a ctypes call, which releases the GIL, so
untiled launches from two threads do overlap; but tiled launches (``wp.launch_tiled``: the tracker's fused
predict+score and resampling passes) share one module-global tile shared-memory pointer on the CPU (warp/native/
tile.h: "Ideally this would be thread_local, but LLVM's JIT doesn't support TLS yet"), so two trackers stepped from
two threads crash (segmentation fault). ``--mode threads --impl warp`` reproduces it: it is not run by default.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import threading
import time

import numpy as np

from wptrack.bench.colour import HUE, INTENSITY, SAT, bench_frames, bench_rig

WARMUP = 3


def _make(impl: str, particles: int, cameras: int, seed: int):
    """One worker's filter and frames: (step function, list of per-camera image lists)."""
    rig = bench_rig(cameras)
    images, balls = bench_frames(rig, 8, seed)
    init = tuple(balls[0] + np.array([0.05, -0.05, 0.05]))
    if impl in ("warp", "warp-observe"):
        from wptrack.trackers.colour.tracker import ColorTracker, HSITarget

        tr = ColorTracker(
            rig,
            HSITarget(HUE, SAT, INTENSITY),
            particles=particles,
            sigma=0.01,
            init=init,
            device="cpu",
            seed=seed,
            proposal="prior",
            keep_particles=0,
        )
        step = tr.step
        if impl == "warp-observe":  # the observation stage alone (mask + window map: plain, untiled launches)
            tr.upload(images[0])
            if tr.maps is None:
                raise ValueError("--impl warp-observe needs map scoring (25 N > pixels, e.g. 1e5 particles)")

            def step(_images, tr=tr):
                tr._launch_observation()
    else:
        from wptrack.bench.numpy_colour import NumpyColorFilter

        step = NumpyColorFilter(rig, HUE, SAT, INTENSITY, particles, 0.01, init, seed=seed).step
    for k in range(WARMUP):
        step(images[k])
    return step, images


def _loop(step, images, frames: int) -> tuple[float, float, float]:
    """(start, end, CPU seconds of this process) of ``frames`` steps."""
    t0, c0 = time.perf_counter(), time.process_time()
    for k in range(frames):
        step(images[k % len(images)])
    return t0, time.perf_counter(), time.process_time() - c0


def _process_worker(impl, particles, cameras, seed, frames, barrier, queue) -> None:
    step, images = _make(impl, particles, cameras, seed)
    barrier.wait()
    queue.put(_loop(step, images, frames))


def run_workers(mode: str, impl: str, workers: int, particles: int, cameras: int, frames: int) -> dict:
    """Wall time of ``workers`` independent filters x ``frames`` frames run concurrently (threads or processes).

    Returns:
        dict with ``wall_s`` (common start to last end), ``frames_per_s`` (all workers), ``ms_per_frame`` (wall per
        frame of one worker), the per-worker times, ``cpu_s`` (CPU seconds of all workers; on a shared box the
        per-frame CPU time ``cpu_ms_per_frame`` is the load-independent cost) and ``cpu_per_wall`` (above 1: the
        workers did run at the same time).
    """
    if mode == "threads":
        made = [_make(impl, particles, cameras, seed) for seed in range(workers)]
        barrier = threading.Barrier(workers + 1)
        spans: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)] * workers

        def work(i: int) -> None:
            barrier.wait()
            spans[i] = _loop(*made[i], frames)

        threads = [threading.Thread(target=work, args=(i,)) for i in range(workers)]
        for t in threads:
            t.start()
        c0 = time.process_time()
        barrier.wait()
        for t in threads:
            t.join()
        cpu = time.process_time() - c0  # all threads of this process
    else:
        ctx = mp.get_context("spawn")
        barrier, queue = ctx.Barrier(workers), ctx.Queue()
        procs = [
            ctx.Process(target=_process_worker, args=(impl, particles, cameras, seed, frames, barrier, queue))
            for seed in range(workers)
        ]
        for p in procs:
            p.start()
        spans = [queue.get() for _ in procs]
        for p in procs:
            p.join()
        cpu = sum(c for _, _, c in spans)
    wall = max(e for _, e, _ in spans) - min(s for s, _, _ in spans)
    return {
        "mode": mode,
        "impl": impl,
        "workers": workers,
        "particles": particles,
        "cameras": cameras,
        "frames": frames,
        "wall_s": wall,
        "frames_per_s": workers * frames / wall,
        "ms_per_frame": 1e3 * wall / frames,
        "worker_s": [e - s for s, e, _ in spans],
        "cpu_s": cpu,
        "cpu_ms_per_frame": 1e3 * cpu / (workers * frames),
        "cpu_per_wall": cpu / wall,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m wptrack.bench.cpu_threads", description=__doc__.split("\n\n")[0])
    p.add_argument("--impl", choices=["warp", "warp-observe", "numpy"], default="warp")
    p.add_argument("--mode", choices=["threads", "processes"], nargs="+", default=None)
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--particles", type=float, default=1e5)
    p.add_argument("--cameras", type=int, default=4)
    p.add_argument("--frames", type=int, default=20)
    p.add_argument("--repeats", type=int, default=3, help="interleaved repeats of each case; the best wall is kept")
    p.add_argument("--out", default=None, help="write the rows as JSON here")
    args = p.parse_args(argv)
    import warp as wp

    wp.config.quiet = True
    wp.init()
    cores = len(os.sched_getaffinity(0))
    print(f"{cores} usable cores, load average {os.getloadavg()[0]:.2f}")
    if args.mode is None:  # the whole tracker from threads crashes in Warp 1.19 (module docstring)
        args.mode = ["processes"] if args.impl == "warp" else ["threads", "processes"]
    best: dict[tuple[str, int], dict] = {}
    for rep in range(args.repeats):  # interleaved repeats, best wall kept: the box may be shared
        for mode in args.mode:
            for w in args.workers:
                r = run_workers(mode, args.impl, w, int(args.particles), args.cameras, args.frames)
                print(
                    f"  repeat {rep}: {mode} workers {w}: {r['wall_s']:.3f} s wall, CPU {r['cpu_s']:.3f} s "
                    f"({r['cpu_ms_per_frame']:.1f} ms per frame, CPU/wall {r['cpu_per_wall']:.2f})",
                    flush=True,
                )
                if (mode, w) not in best or r["wall_s"] < best[mode, w]["wall_s"]:
                    best[mode, w] = r
    rows = []
    for mode in args.mode:
        for w in args.workers:
            r = best[mode, w]
            r["speedup"] = r["frames_per_s"] / best[mode, args.workers[0]]["frames_per_s"]
            r["repeats"] = args.repeats
            rows.append(r)
            print(
                f"{args.impl:5s} {mode:9s} workers {w}: {r['wall_s']:.3f} s wall, {r['ms_per_frame']:.1f} ms per "
                f"frame per worker, {r['frames_per_s']:.2f} frames/s in all, {r['speedup']:.2f}x "
                f"{args.workers[0]} worker(s), CPU {r['cpu_ms_per_frame']:.1f} ms per frame, CPU/wall "
                f"{r['cpu_per_wall']:.2f} (best wall of {args.repeats})",
                flush=True,
            )
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"cores": cores, "load_average": os.getloadavg(), "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
