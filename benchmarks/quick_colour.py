"""Quick per-frame timing of the S1 colour tracker (median of repeats after warm-up); the full suite is
`wptrack bench` (issue 5). Usage: python benchmarks/quick_colour.py --device cuda --particles 1e4 1e5 1e6"""

from __future__ import annotations

import argparse
import time

import numpy as np

from wptrack.rig import Camera, Rig
from wptrack.trackers.colour import ColorTracker, HSITarget


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="auto")
    ap.add_argument("--particles", type=float, nargs="+", default=[1e3, 1e4, 1e5])
    ap.add_argument("--cameras", type=int, default=4)
    ap.add_argument("--frames", type=int, default=50)
    args = ap.parse_args()
    cams = tuple(
        Camera.look_at(f"c{i}", 640, 480, (2 * np.cos(a), 2 * np.sin(a), 1.0), (0, 0, 0), 500.0)
        for i, a in enumerate(np.linspace(0, 2 * np.pi, args.cameras, endpoint=False))
    )
    rig = Rig(cams)
    rng = np.random.default_rng(0)
    imgs = [rng.integers(0, 256, (480, 640, 3), dtype=np.uint8) for _ in cams]
    target = HSITarget(hue=(300, 340), sat=(0.3, 1.0))
    for n in args.particles:
        n = int(n)
        for mode in ("direct", "integral"):
            tr = ColorTracker(rig, target, particles=n, init=(0, 0, 0), device=args.device, score_mode=mode)
            for _ in range(5):
                tr.step(imgs)
            times = []
            for _ in range(args.frames):
                t0 = time.perf_counter()
                tr.step(imgs)
                times.append(time.perf_counter() - t0)
            print(f"{tr.device} N={n:>10d} cams={len(cams)} {mode:8s} median {1e3 * np.median(times):8.3f} ms/frame")


if __name__ == "__main__":
    main()
