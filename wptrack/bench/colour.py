"""Benchmark of the S1 colour tracker: per-stage and per-frame device time, end-to-end step time, particles per
second, device memory, and the equivalence of the estimates with the NumPy reference measured in the same run."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

log = logging.getLogger(__name__)

WIDTH, HEIGHT = 640, 480
HUE, SAT, INTENSITY = (300.0, 340.0), (0.3, 1.0), (20.0, 240.0)
BALL_RADIUS = 0.05


@dataclass(frozen=True)
class Case:
    particles: int
    cameras: int


def bench_rig(cameras: int):
    """``cameras`` 640x480 cameras on a 2 m circle at 1 m height, all looking at the origin."""
    from wptrack.cameras.rig import Camera, Rig

    angles = np.linspace(0, 2 * np.pi, cameras, endpoint=False) + 0.3
    cams = tuple(
        Camera.look_at(
            f"cam{i}",
            WIDTH,
            HEIGHT,
            (2 * np.cos(a), 2 * np.sin(a), 1.0),
            (0.0, 0.0, 0.0),
            550.0,
            dist=(-0.05, 0.0, 0.0, 0.0, 0.0),
        )
        for i, a in enumerate(angles)
    )
    return Rig(cams)


def bench_frames(rig, frames: int, seed: int = 0):
    """Synthetic frames: noisy grey background with a few distractor blobs and a pink ball moving on a 10 cm
    circle around the origin. Returns (list of per-camera image lists, (frames, 3) ball positions)."""
    import cv2

    rng = np.random.default_rng(seed)
    t = np.arange(frames)
    balls = np.column_stack([0.1 * np.cos(t / 15), 0.1 * np.sin(t / 15), 0.1 + 0.0 * t])
    backgrounds = []
    for _ in rig.cameras:
        bg = rng.integers(40, 140, (HEIGHT, WIDTH, 3), dtype=np.uint8)
        for _ in range(6):
            c = (int(rng.integers(0, WIDTH)), int(rng.integers(0, HEIGHT)))
            cv2.circle(bg, c, int(rng.integers(5, 30)), tuple(int(v) for v in rng.integers(0, 255, 3)), -1)
        backgrounds.append(bg)
    out = []
    for k in range(frames):
        imgs = []
        for cam, bg in zip(rig.cameras, backgrounds, strict=True):
            img = bg.copy()
            uv, depth = cam.project(balls[k][None])
            r = max(2, int(round(BALL_RADIUS * cam.fx / depth[0])))
            cv2.circle(img, (int(round(uv[0, 0])), int(round(uv[0, 1]))), r, (180, 60, 230), -1)
            imgs.append(img)
        out.append(imgs)
    return out, balls


class ColourSuite:
    """S1 colour tracker: N particles x C cameras at 640x480."""

    name = "color"

    @staticmethod
    def default_grid(is_cuda: bool) -> list[Case]:
        ns = [10**k for k in range(3, 9)] if is_cuda else [10**k for k in range(3, 6)]
        cams = [1, 2, 4, 8] if is_cuda else [1, 2, 4]
        return [Case(n, c) for c in cams for n in ns]

    @staticmethod
    def run_case(
        case: Case,
        device: str,
        frames: int = 50,
        numpy_max: int = 100_000,
        numpy_frames: int = 30,
        seed: int = 0,
        offspring_at: tuple[int, ...] = (10**7,),
        weights: str | None = None,
        proposal: str = "prior",
    ) -> dict:
        if weights is not None:  # --weights: the resampling pass alone on synthetic log-weights (cameras unused)
            from wptrack.bench.resample_weights import run_weights_case

            return run_weights_case(case.particles, device, weights, frames, numpy_max, seed)
        import warp as wp

        from wptrack.bench.numpy_colour import NumpyColorFilter
        from wptrack.trackers.colour.tracker import ColorTracker, HSITarget

        rig = bench_rig(case.cameras)
        n_frames = max(frames, numpy_frames) + 5
        images, balls = bench_frames(rig, n_frames, seed)
        target = HSITarget(hue=HUE, sat=SAT, intensity=INTENSITY)
        init = tuple(balls[0] + np.array([0.05, -0.05, 0.05]))
        dev = wp.get_device(device)
        mem0 = wp.get_mempool_used_mem_current(dev) if dev.is_cuda else 0
        tracker = ColorTracker(
            rig,
            target,
            particles=case.particles,
            sigma=0.01,
            init=init,
            device=device,
            seed=seed,
            proposal=proposal,
            keep_particles=0,
        )  # prior (default): the paper's filter, as the NumPy reference
        result = {
            "tracker": "color" if proposal == "prior" else "color+m",
            "proposal": proposal,
            "particles": case.particles,
            "cameras": case.cameras,
            "width": WIDTH,
            "height": HEIGHT,
            "device": tracker.device,
            "score_mode": tracker.score_mode,
        }
        # equivalence: the first numpy_frames frames through both filters (Warp with its graph, as users run it)
        warp_est = [tracker.step(images[k]) for k in range(numpy_frames)]
        result["state_bytes"] = (wp.get_mempool_used_mem_current(dev) - mem0) if dev.is_cuda else None
        truth = balls[numpy_frames - 1]
        result["warp_error_m"] = float(np.linalg.norm(warp_est[-1].mean - truth))
        if case.particles <= numpy_max:
            from wptrack.cameras.structs import camera_struct

            ref = NumpyColorFilter(
                rig,
                HUE,
                SAT,
                INTENSITY,
                case.particles,
                0.01,
                init,
                seed=seed,
                r2_max=[camera_struct(c).r2_max for c in rig.cameras],
            )
            t_np = []
            for k in range(numpy_frames):
                t0 = time.perf_counter()
                mean, _std, _map = ref.step(images[k])
                t_np.append(time.perf_counter() - t0)
            result["numpy_ms"] = 1e3 * float(np.median(t_np))
            result["numpy_error_m"] = float(np.linalg.norm(mean - truth))
            w_mean, w_std, ess = warp_est[-1].mean, warp_est[-1].std, max(warp_est[-1].ess, 1.0)
            # Both filters estimate the same posterior with independent random numbers: their means differ by the
            # Monte Carlo error, a few times spread / sqrt(ESS) (2 mm floor). One camera does not observe depth,
            # so there the check compares the two estimates' projections (pixels) instead.
            tol = max(0.002, 5.0 * float(np.linalg.norm(w_std)) / np.sqrt(ess))
            diff = float(np.linalg.norm(mean - w_mean))
            result["warp_numpy_diff_m"] = diff
            px = [float(np.linalg.norm(np.subtract(*cam.project(np.array([mean, w_mean]))[0]))) for cam in rig.cameras]
            result["warp_numpy_diff_px"] = max(px)
            if case.cameras >= 2:
                result["equivalent"] = bool(diff <= tol and result["warp_error_m"] < 0.05)
            else:
                result["equivalent"] = bool(max(px) <= 2.0)
        # timings on a fixed frame: end-to-end step, device chain, per stage
        frame = images[numpy_frames]
        steps = []
        for _ in range(frames):
            t0 = time.perf_counter()
            tracker.step(frame)
            steps.append(time.perf_counter() - t0)
        tracker.upload(frame)
        dev_times = tracker.time_frames(frames)
        stages: dict[str, list[float]] = {}
        for _ in range(max(5, frames // 5)):
            for k, v in tracker.profile().items():
                stages.setdefault(k, []).append(v)
        result["step_ms"] = 1e3 * float(np.median(steps))
        result["frame_ms"] = 1e3 * float(np.median(dev_times))
        result["stages_ms"] = {k: 1e3 * float(np.median(v)) for k, v in stages.items()}
        result["particles_per_s"] = case.particles / float(np.median(dev_times))
        if dev.is_cuda:
            result["peak_mempool_bytes"] = int(wp.get_mempool_used_mem_high(dev))
        if case.particles in offspring_at:
            result["offspring"] = offspring_check(tracker)
        if "numpy_ms" in result:
            result["speedup_vs_numpy"] = result["numpy_ms"] / result["step_ms"]
        del tracker
        return result

    @staticmethod
    def format_row(r: dict) -> str:
        from wptrack.bench import format_row

        if "weights" in r:
            from wptrack.bench.resample_weights import format_weights_row

            return format_weights_row(r)
        return format_row(r)


def offspring_check(tracker, replays: int = 32, groups: int = 1000) -> dict:
    """Resampling at scale, on the tracker's own last frame (its log-weights, max and resampler, on its device).

    Every one of ``replays`` draws (frame numbers = fresh uniforms) must give each particle floor or ceil of its
    expected offspring N q_i / T (q: the device's quantised weights), N offspring in all and none to zero weights;
    unbiasedness: the offspring of ``groups`` contiguous groups of particles, averaged over the replays, against
    their expectation (z-scores with the systematic scheme's per-group standard deviation, at most 1/2 per draw).
    """
    import warp as wp

    from wptrack.kernels.core import reduce as kreduce
    from wptrack.kernels.core import resample as kres

    r = tracker.resampler
    if not r.exact:
        return {"checked": False, "reason": f"scheme {r.scheme}"}
    n, d = tracker.n, tracker.device
    logw = tracker.logw[tracker.parity]
    q_dev = wp.zeros(n, dtype=wp.int64, device=d)
    wp.launch(
        kres.quantised_weights_kernel,
        dim=n,
        inputs=[logw, tracker.est, int(kreduce.EST_MAXLOGW), r.scale],
        outputs=[q_dev],
        device=d,
    )
    q = q_dev.numpy()
    del q_dev
    x = n * q.astype(np.float64) / float(q.sum())
    lo, hi = np.floor(x), np.ceil(x)
    anc = wp.zeros(n, dtype=wp.int32, device=d)
    frame = wp.zeros(1, dtype=wp.int32, device=d)
    edges = np.linspace(0, n, groups + 1).astype(np.int64)
    pooled = np.zeros(groups)
    bounds_ok = True
    for k in range(replays):
        frame.fill_(1_000_000 + k)
        r.from_log_weights(logw, tracker.est, int(kreduce.EST_MAXLOGW), tracker.seed, frame, anc)
        c = np.bincount(anc.numpy(), minlength=n)
        bounds_ok &= bool(c.sum() == n and np.all((c == lo) | (c == hi)) and c[q == 0].sum() == 0)
        pooled += np.add.reduceat(c, edges[:-1])
    expected = np.add.reduceat(x, edges[:-1])
    z = (pooled / replays - expected) / (0.5 / np.sqrt(replays))
    return {
        "checked": True,
        "particles": n,
        "replays": replays,
        "bounds_ok": bounds_ok,
        "max_abs_z": float(np.abs(z).max()),
        "ok": bool(bounds_ok and np.abs(z).max() < 5.0),
        "ess": float(tracker.est.numpy()[kreduce.EST_ESS]),
    }
