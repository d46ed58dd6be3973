"""Benchmark of the S2 people tracker: frames per second of the whole frame (upload of 3 BGR frames and 3 motion
masks, HSV planes, image noise, every person's fused predict + descriptor + likelihood + estimate + resampling, the
ground evidence map, the column tops, the host bookkeeping) plus every person's occupancy grid, per-stage times, and
the equivalence of the descriptor with the NumPy reference (``wptrack/bench/numpy_people.py``) on the same particles,
whose time per particle is measured in the same run.

The scene: three 640x480 cameras 2.6 m high in three corners of a 4 x 4 m room looking at its centre; ``objects``
people (vertical cylinders of radius 0.22 m and height 1.7 m, one colour each) standing on a 3 x 4 grid of places in
the room; perfect motion masks. Each person is added at its true place and tracked with ``particles`` particles; no
person is added or removed during the timing (the bookkeeping runs, its thresholds are out of reach).

Targets (issue 11): 2 people x 500 particles x 3 cameras >= 500 frames/s on the GPU, >= 25 frames/s on one CPU core,
descriptor and occupancy included; 10 people x 1e4 particles measured too.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

log = logging.getLogger(__name__)

WIDTH, HEIGHT = 640, 480
TARGET_CASE = (500, 2)
TARGET_FPS = {"cuda": 500.0, "cpu": 25.0}
NUMPY_PARTICLES = 40
"""Particles of one person whose descriptors the NumPy reference recomputes (its time is per particle)."""
EQUIV_ATOL = 2e-3
"""The check passes when the median over those particles of max |desc_warp - desc_numpy| is below this (float32
kernels, and a pixel within rounding of a disc's rim may fall on either side)."""


@dataclass(frozen=True)
class Case:
    """One benchmark case: ``particles`` per person and ``objects`` people."""

    particles: int
    objects: int


def bench_rig():
    """Three 640x480 cameras (90 degrees wide) in the corners of a 4 x 4 m room, 2.6 m high, looking at its
    centre at 0.8 m; working volume the room up to 2 m."""
    from wptrack.cameras.rig import Camera, Rig

    target = (2.0, 2.0, 0.8)
    f = WIDTH / 2.0
    cams = (
        Camera.look_at("c0", WIDTH, HEIGHT, (-0.3, -0.3, 2.6), target, f),
        Camera.look_at("c1", WIDTH, HEIGHT, (4.3, -0.3, 2.6), target, f),
        Camera.look_at("c2", WIDTH, HEIGHT, (2.0, 4.4, 2.6), target, f),
    )
    return Rig(cams, volume=(np.array([0.0, 0.0, 0.0]), np.array([4.0, 4.0, 2.0])))


def bench_places(objects: int) -> np.ndarray:
    """Ground positions of the people: a 3 x 4 grid of places 1 m apart in the room (``objects`` <= 12)."""
    xs, ys = np.meshgrid([1.0, 2.0, 3.0], [0.6, 1.6, 2.6, 3.6])
    return np.column_stack([xs.ravel(), ys.ravel()])[:objects]


def cylinder_points(xy, radius: float = 0.22, height: float = 1.7) -> np.ndarray:
    """Points on the surface of a standing person's cylinder, metres."""
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    z = np.linspace(0.0, height, 12)
    ring = np.stack([xy[0] + radius * np.cos(a), xy[1] + radius * np.sin(a)], axis=1)
    return np.array([[x, y, zz] for zz in z for x, y in ring])


def render_people(rig, places: np.ndarray, seed: int = 0) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Images (grey noise, each person's silhouette in its own colour, far ones first) and perfect masks."""
    import cv2

    rng = np.random.default_rng(seed)
    colours = rng.integers(30, 230, (len(places), 3))
    images, masks = [], []
    for cam in rig.cameras:
        img = rng.integers(95, 125, (cam.height, cam.width, 3)).astype(np.uint8)
        mask = np.zeros((cam.height, cam.width), np.uint8)
        order = np.argsort(-np.linalg.norm(places - cam.center[:2], axis=1))
        for k in order:
            uv, depth = cam.project(cylinder_points(places[k]))
            if np.any(depth <= 0):
                continue
            hull = cv2.convexHull(np.round(uv).astype(np.int32))
            cv2.fillConvexPoly(img, hull, tuple(int(c) for c in colours[k]))
            cv2.fillConvexPoly(mask, hull, 255)
        images.append(img)
        masks.append(mask)
    return images, masks


class PeopleSuite:
    """S2 people tracker: N particles per person x K people, three 640x480 cameras."""

    name = "people"
    second = "objects"
    """The case's second field (``wptrack bench --objects``: people)."""

    HEADER = (
        f"{'suite':7s} {'N':>7s} {'ppl':>4s} {'frame ms':>9s} {'fps':>8s} {'occ ms':>8s} {'desc np us':>10s} "
        f"{'eq':>3s}  stages (ms, median)"
    )

    @staticmethod
    def format_row(r: dict) -> str:
        """One table row: frame time (occupancy included) and frames/s, the occupancy's part, the NumPy descriptor's
        time per particle, the equivalence, per-stage medians and the target when the case has one."""
        eq = {True: "yes", False: "NO"}.get(r.get("equivalent"), "-")
        npy = f"{r['numpy_us_per_particle']:10.0f}" if r.get("numpy_us_per_particle") is not None else "         -"
        st = " ".join(f"{k}={v:.3f}" for k, v in r["stages_ms"].items())
        target = ""
        if "target_fps" in r:
            target = f"  [target {r['target_fps']:g} fps: {'met' if r['meets_target'] else 'NOT met'}]"
        return (
            f"{r['tracker']:7s} {r['particles']:>7d} {r['objects']:>4d} {r['frame_ms']:9.3f} {r['frames_per_s']:8.1f} "
            f"{r['occupancy_ms']:8.3f} {npy} {eq:>3s}  {st}{target}"
        )

    @staticmethod
    def default_grid(is_cuda: bool) -> list[Case]:
        """2 x 500 (the target) and 10 x 1e4 on GPUs; 2 x 500 and 10 x 1000 on the CPU."""
        big = 10_000 if is_cuda else 1_000
        return [Case(500, 2), Case(big, 10)]

    @staticmethod
    def run_case(case: Case, device: str, frames: int = 50, numpy_max: int = 100_000, seed: int = 0) -> dict:
        """Time ``frames`` frames of the case (after two warm-up frames: kernel loading and CUDA graph capture)."""
        import warp as wp

        from wptrack.bench import numpy_people
        from wptrack.trackers.people.config import BirthConfig, PeopleConfig
        from wptrack.trackers.people.tracker import PeopleTracker

        n, k = int(case.particles), int(case.objects)
        if not 1 <= k <= 12:
            raise ValueError(f"people: 1 to 12 people, got {k}")
        rig = bench_rig()
        places = bench_places(k)
        images, masks = render_people(rig, places, seed)
        # a fixed set of people (no additions or removals, their bookkeeping still runs): the same work every frame
        birth = BirthConfig(max_people=k, add_seconds=1e9, remove_seconds=1e9, merge_distance=0.0)
        config = PeopleConfig(particles=n, seed=seed, birth=birth)
        tracker = PeopleTracker(rig, config, device=device, keep_particles=min(n, 500))
        for xy in places:
            tracker.add_person(xy)
        ids = tracker.tracked_ids
        for _ in range(2):  # load the modules, capture the graphs
            tracker.step(images, masks)
            tracker.occupancies(ids)
        times, occ, stages = [], [], {"upload": [], "filter": [], "population": []}
        for _ in range(frames):
            t0 = time.perf_counter()
            est = tracker.step(images, masks)
            t1 = time.perf_counter()
            tracker.occupancies(ids)
            t2 = time.perf_counter()
            times.append(t2 - t0)
            occ.append(t2 - t1)
            for name in stages:
                stages[name].append(est.timings[name])
        frame_ms = 1e3 * float(np.median(times))
        result: dict = {
            "tracker": "people",
            "particles": n,
            "objects": k,
            "cameras": len(rig),
            "width": WIDTH,
            "height": HEIGHT,
            "device": tracker.device,
            "score_mode": f"{k} ppl",
            "frames": frames,
            "frame_ms": frame_ms,
            "step_ms": frame_ms,
            "frames_per_s": 1e3 / frame_ms,
            "occupancy_ms": 1e3 * float(np.median(occ)),
            "particles_per_s": n * k * 1e3 / frame_ms,
            "stages_ms": {name: 1e3 * float(np.median(v)) for name, v in stages.items()},
            "people_tracked": len(est.people),
            "max_error_m": float(
                max(np.min(np.linalg.norm(places - p.mean[:2], axis=1)) for p in est.people) if est.people else np.nan
            ),
        }
        if (n, k) == TARGET_CASE:
            kind = "cuda" if wp.get_device(device).is_cuda else "cpu"
            result["target_fps"] = TARGET_FPS[kind]
            result["meets_target"] = result["frames_per_s"] >= TARGET_FPS[kind]
        # equivalence of the descriptor on one person's particles, and the NumPy reference's time per particle
        if numpy_max > 0:
            p = tracker.pool[0]
            pts = p.x[p.parity].numpy()[:NUMPY_PARTICLES].astype(np.float64)
            dc = config.descriptor
            t0 = time.perf_counter()
            ref, ref_mass = numpy_people.descriptor(
                list(rig.cameras), images, pts, dc.r_n, dc.n_bins, dc.r_min, dc.r_max, dc.step
            )
            result["numpy_us_per_particle"] = 1e6 * (time.perf_counter() - t0) / len(pts)
            got = p.desc[p.parity].numpy()[: len(pts)].astype(np.float64)
            diff = np.abs(got - ref).max(axis=1)
            result["descriptor_median_max_abs_diff"] = float(np.median(diff))
            result["equivalent"] = bool(np.median(diff) < EQUIV_ATOL and np.all(ref_mass > 0))
        return result
