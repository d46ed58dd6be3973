"""Issue 27: where the template tracker's frame goes, kernel by kernel, at several R_max (``--max-objects``).

The pipeline suite's synthetic recording (``wptrack.bench.pipeline.write_scene``: people walking on a textured
paving, camera 7 m up) is written at ``--size``, its masks made by ``wptrack masks`` on the device, and the tracker
(1000 particles, the defaults) run on them with each R_max: on CUDA each kernel's GPU time from Warp's activity timing
(``wp.timing_begin``; the frame chain launched without CUDA graphs so each kernel is seen) and the step time with
graphs; on the CPU each launch's wall time. Per kernel: ms a frame, the frames after ``--warm`` averaged.

Run: ``python benchmarks/template_kernels.py [--device cuda] [--size 1920x1080] [--frames 260] [--max-objects 64 16]``
(BENCHMARKS.md, runs 60-62: ``xor_band_kernel`` 1.69 ms a 1080p frame at R_max 64 against 0.25 at 16 before the
scoring scanned only the held slots, 0.75 after).
"""

from __future__ import annotations

import argparse
import collections
import tempfile
import time
from pathlib import Path


def _cpu_launch_times(stats: dict) -> tuple:
    """Wrap ``wp.launch`` and ``wp.launch_tiled`` to add each CPU launch's wall time to ``stats`` (name -> seconds);
    returns the originals."""
    import warp as wp

    originals = (wp.launch, wp.launch_tiled)

    def timed(f):
        def g(kernel, *args, **kwargs):
            t = time.perf_counter()
            out = f(kernel, *args, **kwargs)
            stats[getattr(kernel, "key", str(kernel))] += time.perf_counter() - t
            return out

        return g

    wp.launch, wp.launch_tiled = timed(originals[0]), timed(originals[1])
    return originals


def main() -> None:
    import cv2
    import numpy as np
    import warp as wp

    from wptrack.bench.pipeline import scene_rig, write_scene
    from wptrack.cameras.rig import Rig
    from wptrack.cli import main as cli
    from wptrack.trackers.templates.config import TemplateConfig
    from wptrack.trackers.templates.tracker import TemplateTracker

    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--frames", type=int, default=260)
    ap.add_argument("--warm", type=int, default=60, help="frames run before the timing")
    ap.add_argument("--max-objects", type=int, nargs="+", default=[64, 16])
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    wp.init()
    cuda = wp.get_device(a.device).is_cuda
    with tempfile.TemporaryDirectory() as tmp:
        video, rig_path = Path(tmp) / "v.avi", Path(tmp) / "rig.yaml"
        write_scene(video, w, h, a.frames)
        scene_rig(w, h, rig_path)
        cli(["masks", "--video", str(video), "--out", str(Path(tmp) / "m"), "--device", a.device, "-q"])
        cap = cv2.VideoCapture(str(Path(tmp) / "m" / "masks.avi"))
        masks = []
        while True:
            ok, m = cap.read()
            if not ok:
                break
            masks.append((m[..., 0] > 127).astype(np.uint8))
        rig = Rig.load(rig_path)
    timed = masks[a.warm :]
    for r in a.max_objects:
        tracker = TemplateTracker(rig, TemplateConfig(max_objects=r), device=a.device, use_graph=False)
        for m in masks[: a.warm]:
            tracker.step(m)
        stats: dict = collections.defaultdict(float)
        wp.synchronize_device(a.device)
        t = time.perf_counter()
        if cuda:
            wp.timing_begin(cuda_filter=wp.TIMING_KERNEL | wp.TIMING_MEMCPY | wp.TIMING_MEMSET)
            for m in timed:
                tracker.step(m)
            for result in wp.timing_end():
                stats[result.name] += result.elapsed / 1000.0
        else:
            originals = _cpu_launch_times(stats)
            try:
                for m in timed:
                    tracker.step(m)
            finally:
                wp.launch, wp.launch_tiled = originals
        wall = (time.perf_counter() - t) / len(timed)
        busy = sum(stats.values()) / len(timed)
        what = "GPU activity (ms)" if cuda else "launches (ms)"
        print(f"R_max {r} on {a.device}, {w}x{h}: {wall * 1e3:.2f} ms a frame without graphs, {what} {busy * 1e3:.3f}")
        for name, s in sorted(stats.items(), key=lambda kv: -kv[1])[:12]:
            print(f"    {name[:58]:58s} {s * 1e3 / len(timed):7.3f} ms")
        if cuda:  # the same frames replayed as CUDA graphs, as the CLI runs them
            tracker = TemplateTracker(rig, TemplateConfig(max_objects=r), device=a.device)
            for m in masks[: a.warm]:
                tracker.step(m)
            wp.synchronize_device(a.device)
            t = time.perf_counter()
            for m in timed:
                tracker.step(m)
            print(f"    with CUDA graphs: {(time.perf_counter() - t) * 1e3 / len(timed):.2f} ms a step")


if __name__ == "__main__":
    main()
