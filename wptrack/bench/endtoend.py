"""End-to-end benchmark of the colour tracker from video files: decode alone vs decode + upload + tracking with
the bounded prefetch queue (decoding overlaps with the device work)."""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wptrack.bench.colour import HUE, INTENSITY, SAT, bench_frames, bench_rig


@dataclass(frozen=True)
class Case:
    particles: int
    cameras: int


class EndToEndSuite:
    """Colour tracker on 640x480 FFV1 videos: total time of decode alone and of the full run."""

    name = "color-e2e"

    @staticmethod
    def default_grid(is_cuda: bool) -> list[Case]:
        return [Case(1_000_000 if is_cuda else 100_000, 4)]

    @staticmethod
    def run_case(case: Case, device: str, frames: int = 100, numpy_max: int = 0, seed: int = 0) -> dict:
        from wptrack.io.frames import open_frames
        from wptrack.io.prefetch import prefetch
        from wptrack.io.video import write_video
        from wptrack.trackers.colour.tracker import ColorTracker, HSITarget

        rig = bench_rig(case.cameras)
        images, balls = bench_frames(rig, frames, seed)
        with tempfile.TemporaryDirectory() as tmp:
            paths = []
            for c, cam in enumerate(rig.cameras):
                p = Path(tmp) / f"{cam.name}.avi"
                write_video(p, (images[k][c] for k in range(frames)), fps=25)
                paths.append(str(p))
            decode = []
            for _ in range(3):
                t0 = time.perf_counter()
                for _imgs in open_frames(paths):
                    pass
                decode.append(time.perf_counter() - t0)
            target = HSITarget(hue=HUE, sat=SAT, intensity=INTENSITY)
            tracker = ColorTracker(
                rig,
                target,
                particles=case.particles,
                sigma=0.01,
                init=tuple(balls[0] + 0.03),
                device=device,
                seed=seed,
                proposal="prior",
                keep_particles=0,
            )
            for _ in range(3):  # compile + capture outside the timing
                tracker.step(images[0])
            totals = []
            for _ in range(3):
                t0 = time.perf_counter()
                for imgs in prefetch(open_frames(paths), depth=4):
                    tracker.step(imgs)
                totals.append(time.perf_counter() - t0)
        d, t = float(np.median(decode)), float(np.median(totals))
        return {
            "tracker": "color-e2e",
            "particles": case.particles,
            "cameras": case.cameras,
            "frames": frames,
            "device": tracker.device,
            "score_mode": tracker.score_mode,
            "decode_s": d,
            "total_s": t,
            "overhead_vs_decode": t / d - 1.0,
            "frame_ms": 1e3 * t / frames,
            "step_ms": 1e3 * t / frames,
            "particles_per_s": case.particles * frames / t,
            "stages_ms": {"decode": 1e3 * d / frames},
        }
