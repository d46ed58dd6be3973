"""Soak benchmark (issue 14): the real run loop (:func:`wptrack.runs.run_tracker`) over a long synthetic sequence,
writing its outputs into a temporary folder, with the process's resident memory sampled every ``sample_every``
frames and, on CUDA, the device memory. Suites: ``soak`` (the colour tracker's job: tracks.csv, particles.npz,
run.json) and ``soak-templates`` (the template tracker's job: tracks.csv, best.csv, virtual.avi, run.json).

Criteria (a benchmark, not a timed test): resident memory must not grow more than 5 % after frame ``settle``
(default 1000) -- ``rss_growth = max(RSS after settle) / RSS at settle - 1`` -- and on a CUDA device the device
memory in use must not change after the first frame (``device_growth_bytes == 0``). The run loop checkpoints every
5 s (as ``--checkpoint-every 5``), so the memory of checkpointing is part of the measurement.

The frames are cheap: one short exactly periodic sequence (``PERIOD`` frames: a pink ball on a 10 cm circle, or a
person walking across one camera's motion masks) is rendered once in memory and cycled, so 10,000 frames cost no
rendering and no disk reads.

    PYTHONPATH=$PWD python3 -m wptrack.cli bench --tracker soak --device cpu --frames 10000
"""

from __future__ import annotations

import itertools
import os
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.trackers.colour.run import ColourRun
from wptrack.trackers.templates.run import TemplateRun

WIDTH, HEIGHT = 320, 240
PERIOD = 96
"""Frames of the cycled sequence: the ball goes once around its circle, so the cycle has no jump."""
RSS_LIMIT = 0.05
"""Largest relative growth of the resident memory after the settling frame (issue 14)."""


@dataclass(frozen=True)
class Case:
    particles: int
    cameras: int


def rss_bytes() -> int:
    """The process's resident set size now, bytes (``/proc/self/statm``; elsewhere the peak from ``getrusage``)."""
    try:
        with open("/proc/self/statm", encoding="ascii") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        import resource
        import sys

        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return int(peak) * (1 if sys.platform == "darwin" else 1024)


def device_bytes(device: str) -> int | None:
    """Device memory in use on a CUDA ``device``, bytes: Warp's memory pool when enabled, else total - free (the
    whole device's); None on the CPU."""
    import warp as wp

    d = wp.get_device(device)
    if not d.is_cuda:
        return None
    wp.synchronize_device(d)
    if wp.is_mempool_enabled(d):
        return int(wp.get_mempool_used_mem_current(d))
    return int(d.total_memory - d.free_memory)


def growth(samples: Sequence[tuple[int, int]], settle: int) -> float | None:
    """Relative growth of a memory series after frame ``settle``: ``max(v for f >= settle) / v(settle) - 1``.

    Args:
        samples: ``(frame, bytes)`` pairs in frame order.
        settle: The reference frame; the sample at the first frame >= ``settle`` is the reference.

    Returns:
        The growth (0.05 = 5 %), or None when no sample lies at or after ``settle``.
    """
    after = [(f, v) for f, v in samples if f >= settle]
    if not after or after[0][1] <= 0:
        return None
    ref = after[0][1]
    return max(v for _, v in after) / ref - 1.0


def cycle_scene(cameras: int, seed: int = 0) -> tuple[Any, list[np.ndarray], np.ndarray]:
    """A rig of ``cameras`` 320x240 cameras on a 2 m circle and one exactly periodic sequence.

    Returns:
        ``(rig, videos, balls)``: videos one ``(PERIOD, H, W, 3)`` uint8 BGR array per camera; balls the
        ``(PERIOD, 3)`` ball centres, metres.
    """
    import cv2

    from wptrack.cameras.rig import Camera, Rig

    angles = np.linspace(0, 2 * np.pi, cameras, endpoint=False) + 0.3
    rig = Rig(
        tuple(
            Camera.look_at(f"cam{i}", WIDTH, HEIGHT, (2 * np.cos(a), 2 * np.sin(a), 1.0), (0.0, 0.0, 0.0), 275.0)
            for i, a in enumerate(angles)
        )
    )
    t = 2 * np.pi * np.arange(PERIOD) / PERIOD
    balls = np.column_stack([0.1 * np.cos(t), 0.1 * np.sin(t), np.full(PERIOD, 0.1)])
    rng = np.random.default_rng(seed)
    videos = []
    for cam in rig.cameras:
        bg = rng.integers(40, 140, (HEIGHT, WIDTH, 3), dtype=np.uint8)
        frames = np.repeat(bg[None], PERIOD, axis=0)
        uv, depth = cam.project(balls)
        for k in range(PERIOD):
            r = max(2, int(round(0.05 * cam.fx / depth[k])))
            cv2.circle(frames[k], (int(round(uv[k, 0])), int(round(uv[k, 1]))), r, (180, 60, 230), -1)
        videos.append(frames)
    return rig, videos, balls


class _Cycled:
    """Mixin for a run-loop job: its frame source (``_source_attr``, re-iterable and in memory) repeated to
    ``frames`` frames, and ``on_record(job, estimate)`` called after each frame is recorded. Nothing accumulates."""

    _source_attr = "_frames"

    def __init__(self, *args: Any, frames: int, on_record: Callable[[Any, Any], None] | None = None, **kw: Any):
        super().__init__(*args, **kw)
        self.total = int(frames)
        self._on_record = on_record

    def frames(self) -> Iterator[Any]:
        source = getattr(self, self._source_attr)
        return itertools.islice(itertools.chain.from_iterable(itertools.repeat(source)), self.total)

    def record(self, est: Any, out: Any) -> None:
        super().record(est, out)
        if self._on_record is not None:
            self._on_record(self, est)


class SoakRun(_Cycled, ColourRun):
    """:class:`~wptrack.trackers.colour.run.ColourRun` over its in-memory videos repeated to ``frames`` frames."""


class TemplateSoakRun(_Cycled, TemplateRun):
    """:class:`~wptrack.trackers.templates.run.TemplateRun` over its in-memory motion masks repeated to ``frames``
    frames."""

    _source_attr = "_stream"


def template_cycle(seed: int = 0) -> tuple[Any, np.ndarray]:
    """A 320x240 camera above a ground plane and ``PERIOD`` motion masks rendered by a one-particle template tracker:
    a person walking 6 m across the view, then the next one entering where the first started (so objects are
    added and dropped every cycle), plus a few isolated noise pixels.

    Returns:
        ``(rig, masks)``: masks ``(PERIOD, H, W)`` uint8, 0 or 255.
    """
    from wptrack.cameras.rig import Camera, Rig
    from wptrack.trackers.templates.tracker import TemplateConfig, TemplateTracker

    cam = Camera.look_at("cam0", 320, 240, position=[0, -4, 10], target=[0, 9, 0], fx=250.0)
    rig = Rig(cameras=(cam,))
    painter = TemplateTracker(rig, TemplateConfig(particles=1, max_objects=1), device="cpu")
    rng = np.random.default_rng(seed)
    masks = np.zeros((PERIOD, 240, 320), np.uint8)
    for k in range(PERIOD):
        painter.set_particles(
            kind=np.array([[1]]),  # human
            label=np.array([[0]]),
            pos=np.array([[[-3.0 + 6.0 * k / PERIOD, 5.0]]], np.float32),
            dims=np.array([[[1.75, 0.5, 0.3]]], np.float32),
            heading=np.zeros((1, 1)),
        )
        masks[k] = painter.render_virtual()[0] != 0
        masks[k][rng.random((240, 320)) < 0.001] = 1
    return rig, masks * np.uint8(255)  # given masks: foreground above MaskConfig.threshold


def soak_job(
    case: Case,
    device: str,
    frames: int,
    out_dir: Path,
    seed: int = 0,
    keep_particles: int = 100,
    on_record: Callable[[Any, Any], None] | None = None,
) -> SoakRun:
    """The colour tracker's run-loop job on the cycled scene, ``frames`` frames long (its rig file written into
    ``out_dir``)."""
    from wptrack.trackers.colour.tracker import ColorConfig, HSITarget

    rig, videos, balls = cycle_scene(case.cameras, seed)
    rig_path = out_dir / "rig.yaml"
    rig.save(rig_path)
    cfg = ColorConfig(
        particles=case.particles,
        sigma=0.01,
        init=tuple(balls[0]),
        seed=seed,
        keep_particles=keep_particles,
        proposal="prior",
    )
    target = HSITarget(hue=(300.0, 340.0), sat=(0.3, 1.0), intensity=(20.0, 240.0))
    return SoakRun(rig_path, videos, target, cfg, device=device, frames=frames, on_record=on_record)


def template_soak_job(
    case: Case,
    device: str,
    frames: int,
    out_dir: Path,
    seed: int = 0,
    on_record: Callable[[Any, Any], None] | None = None,
) -> TemplateSoakRun:
    """The template tracker's run-loop job (virtual scenes written too) on the cycled masks, ``frames`` long."""
    from wptrack.trackers.templates.tracker import TemplateConfig

    rig, masks = template_cycle(seed)
    rig_path = out_dir / "rig.yaml"
    rig.save(rig_path)
    cfg = TemplateConfig(particles=case.particles, max_objects=4, seed=seed, fps=15.0)
    return TemplateSoakRun(rig_path, cfg, masks=masks, device=device, frames=frames, on_record=on_record)


class SoakSuite:
    """Colour tracker through the whole run loop for ``--frames`` frames (default 10,000): memory over time."""

    name = "soak"
    job = "color"
    default_frames = 10_000
    HEADER = (
        f"{'suite':14s} {'N':>7s} {'cams':>4s} {'frames':>6s} {'ms/frame':>8s} {'RSS@settle MiB':>14s} "
        f"{'RSS max MiB':>11s} {'growth':>7s} {'device growth':>13s}  verdict"
    )

    @staticmethod
    def default_grid(is_cuda: bool) -> list[Case]:
        return [Case(100_000 if is_cuda else 200, 2)]

    @classmethod
    def run_case(
        cls,
        case: Case,
        device: str,
        frames: int = 10_000,
        numpy_max: int = 0,
        seed: int = 0,
        sample_every: int = 500,
        settle: int = 1000,
        leak_bytes_per_frame: int = 0,
        checkpoint_seconds: float = 5.0,
    ) -> dict:
        """Run the case and return its memory series and verdict.

        Args:
            sample_every: Sample the memory after every this many frames (and after the first frame).
            settle: The frame after which resident memory must stay within 5 % (clamped to the run's length).
            leak_bytes_per_frame: Keep this many extra bytes per frame alive (a deliberate leak: checks that the
                benchmark detects growth; 0 in real use).
            checkpoint_seconds: The run loop's checkpoint interval (as ``--checkpoint-every``; default 5 s, not the
                CLI's 60 s, so that the run includes several checkpoints: their memory counts too).
        """
        from wptrack.runs import run_tracker

        settle = min(settle, max(frames - 1, 0))
        rss: list[tuple[int, int]] = []
        dev: list[tuple[int, int]] = []
        leak: list[bytes] = []
        with tempfile.TemporaryDirectory(prefix="wptrack-soak-") as tmp:

            def sample(job: SoakRun, est: Any) -> None:
                if leak_bytes_per_frame:
                    leak.append(b"\x01" * leak_bytes_per_frame)  # written to: resident, unlike bytes(n)
                n = est.frame + 1  # frames done
                if n == 1 or n % sample_every == 0 or n == settle or n == frames:
                    rss.append((n, rss_bytes()))
                    d = device_bytes(job.tracker.device)
                    if d is not None:
                        dev.append((n, d))

            make = soak_job if cls.job == "color" else template_soak_job
            job = make(case, device, frames, Path(tmp), seed, on_record=sample)
            out_dir = Path(tmp) / "run"
            t0 = time.perf_counter()
            summary = run_tracker(job, out_dir, checkpoint_seconds=checkpoint_seconds)
            seconds = time.perf_counter() - t0
            written = {p.name: p.stat().st_size for p in out_dir.iterdir()}
        rss_growth = growth(rss, settle)
        dev_growth = (max(v for _, v in dev) - dev[0][1]) if dev else None
        passed = rss_growth is not None and rss_growth <= RSS_LIMIT and (dev_growth is None or dev_growth == 0)
        ref = next((v for f, v in rss if f >= settle), None)
        return {
            "tracker": cls.name,
            "job": cls.job,
            "particles": case.particles,
            "cameras": case.cameras,
            "frames": int(summary["frames"]),
            "device": summary["device"],
            "seconds": seconds,
            "frame_ms": 1e3 * seconds / max(frames, 1),
            "sample_every": sample_every,
            "settle": settle,
            "rss": rss,
            "rss_settle": ref,
            "rss_max_after_settle": max((v for f, v in rss if f >= settle), default=None),
            "rss_growth": rss_growth,
            "rss_limit": RSS_LIMIT,
            "device_memory": dev,
            "device_growth_bytes": dev_growth,
            "passed": bool(passed),
            "output_bytes": written,
        }

    @staticmethod
    def format_row(r: dict) -> str:
        mib = 1 << 20
        g = "-" if r["rss_growth"] is None else f"{100 * r['rss_growth']:+.2f}%"
        d = "-" if r["device_growth_bytes"] is None else f"{r['device_growth_bytes']:d} B"
        ref = (r["rss_settle"] or 0) / mib
        top = (r["rss_max_after_settle"] or 0) / mib
        return (
            f"{r['tracker']:14s} {r['particles']:>7d} {r['cameras']:>4d} {r['frames']:>6d} {r['frame_ms']:8.2f} "
            f"{ref:14.1f} {top:11.1f} {g:>7s} {d:>13s}  {'pass' if r['passed'] else 'FAIL'}"
        )


class TemplateSoakSuite(SoakSuite):
    """The template tracker (S3) through the whole run loop, masks cycled: memory over time (``soak-templates``)."""

    name = "soak-templates"
    job = "templates"

    @staticmethod
    def default_grid(is_cuda: bool) -> list[Case]:
        return [Case(10_000 if is_cuda else 200, 1)]
