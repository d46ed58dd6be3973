"""``wptrack bench --tracker pipeline``: the whole command a user runs on a recording, against decoding it (issue 27).

What a user waits for is the command, not a kernel: decoding, motion masks, the filter and the writers. This suite
times exactly the CLI pipeline, in this process, through :func:`wptrack.cli.main` with the defaults:

1. the video: ``--video V`` (with ``--rig R`` for its camera; without, the suite's camera at the video's size, so
   the work is real but the geometry is not the scene's), or a synthetic recording of ``--size WxH`` (default
   1920x1080 on a GPU, 480x360, the PETS size, on the CPU) and ``--frames`` frames (600 / 400) written as MJPG,
   as recordings come: people walking on a textured, noisy paving (:func:`write_scene`) seen by a camera 7 m up
   (:func:`scene_rig`);
2. **decode**: ``cv2.VideoCapture`` reading every frame in one thread, before and after the commands (the decode
   rate is their mean: the same video, the same process, the same minutes);
3. **masks**: ``wptrack masks --video V --out TMP --device D`` (the offline background model, masks.avi);
4. **track**: ``wptrack track templates --rig R --video V --out TMP --device D -q`` (defaults: masks by the offline
   model, 1000 particles, tracks.csv, best.csv, virtual.avi where the frame size writes it by default);
5. **track from masks**: ``wptrack track templates --masks masks.avi --no-virtual`` (the filter fed by the masks of
   step 3: decoding a mask video instead of making the masks).

With several videos (``--video A B C --rig R``, one per rig camera, e.g. a ``wptrack synth s2-office`` scene) the
command is the people tracker's, ``wptrack track people --rig R --video A B C`` with its defaults (each camera's
masks by the offline model), against decoding the cameras' videos frame by frame in one thread (issue 27's target:
within 1.5x of that, ratio >= 0.67).

With ``--variant ENV=VALUE[,ENV=VALUE...]`` (repeatable) the masks and track commands run again under each set of
environment variables (the thread levers of issue 27: ``WPTRACK_MASK_WORKERS``, ``WPTRACK_DECODE_WORKERS``,
``WPTRACK_CPU_THREADS``, ``WPTRACK_DECODE_THREADS``; ``WPTRACK_JPEG_DECODE=0``: Motion-JPEG by FFmpeg's
decoder), on the same video in the same run, so one command compares them against the defaults and the same decode
rate.

Each command is warmed up first on 3 frames (kernels compiled and cached, not timed). Reported per command: wall
time of ``main()``, frames/s, and ``ratio`` = its frames/s over the decode-only frames/s (issue 27's targets on
one H100 at 1080p: track >= 100 frames/s and ratio >= 0.65, masks >= 120 frames/s; on the 2-core CPU at 480x360:
track >= 30 frames/s). For the track commands, the stage timeline of the run itself (run.json ``timeline``,
:mod:`wptrack.io.timeline`): per stage its total seconds, share of the frame loop's wall time and mean ms per frame,
with ``overlap`` (busy stage time over wall time: how much ran at once) and the waits (``wait_masks``: the filter
waited for masks; ``wait_decode``: the masks waited for decoding), and the start-up: when the frame loop got its
first observation (``first_item_s``: with offline masks, after the first background window was read and built) and
the frames/s after it (``after_first_per_s``, the rate a long recording approaches).
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError

log = logging.getLogger(__name__)

TARGETS = {
    "cuda": {"track_fps": 100.0, "track_ratio": 0.65, "masks_fps": 120.0},
    "cpu": {"track_fps": 30.0},
}
"""Issue 27's targets: on one H100 at 1080p (the lead's run) and on the 2-core CPU at 480x360."""

PEOPLE = 10
"""People walking in the synthetic recording."""

WARM_FRAMES = 3
"""Frames of the untimed warm-up run of each command."""


@dataclass(frozen=True)
class Case:
    """One recording: its frame size (pixels; the first camera's) and, when given, its video files (one per camera)
    and rig."""

    width: int
    height: int
    video: tuple[str, ...] | None = None
    rig: str | None = None
    variants: tuple[tuple[tuple[str, str], ...], ...] = ()  # environment settings to run the commands again under


def parse_size(text: str) -> tuple[int, int]:
    """``"1920x1080"`` -> ``(1920, 1080)``.

    Raises:
        ConfigError: not ``WIDTHxHEIGHT`` with both from 16 to 8192 pixels.
    """
    try:
        w, h = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise ConfigError(f"--size: expected WIDTHxHEIGHT in pixels (e.g. 1920x1080), got {text!r}") from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise ConfigError(f"--size: width and height from 16 to 8192 pixels, got {w}x{h}")
    return w, h


def scene_camera(width: int, height: int):
    """The recording's camera: 7 m above the ground, 8 m behind the scene, looking at a point 15 m ahead, focal
    length 550 px per 640 px of width (the templates suite's camera, scaled), k1 = -0.05."""
    from wptrack.cameras.rig import Camera

    f = 550.0 * width / 640.0
    return Camera.look_at("cam0", width, height, (0.0, -8.0, 7.0), (0.0, 7.0, 0.0), f, dist=(-0.05, 0.0, 0.0, 0.0, 0.0))


def scene_cameras(width: int, height: int, count: int) -> list:
    """``count`` cameras 6 m up on a 12 m circle around the walkers' area, looking at its centre (0, 7, 0) m (for a
    people run; one camera: :func:`scene_camera`)."""
    from wptrack.cameras.rig import Camera

    if count == 1:
        return [scene_camera(width, height)]
    f = 550.0 * width / 640.0
    out = []
    for k in range(count):
        a = 2 * np.pi * k / count - np.pi / 2
        pos = (12.0 * np.cos(a), 7.0 + 12.0 * np.sin(a), 6.0)
        out.append(Camera.look_at(f"cam{k}", width, height, pos, (0.0, 7.0, 0.0), f))
    return out


def scene_rig(width: int, height: int, path: Path, cameras: int = 1) -> Path:
    """Write the rig of :func:`scene_cameras` (ground plane z = 0) to ``path`` (YAML)."""
    from wptrack.cameras.rig import Rig

    Rig(tuple(scene_cameras(width, height, cameras))).save(path)
    return path


def _walkers(count: int, frames: int, fps: float, seed: int) -> np.ndarray:
    """Ground positions (frames, count, 2) of people walking at 1.0-1.6 m/s in the box x in [-6, 6], y in [0, 14] m,
    turning back at its sides."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array([-6.0, 0.0]), np.array([6.0, 14.0])
    pos = rng.uniform(lo, hi, (count, 2))
    angle = rng.uniform(0, 2 * np.pi, count)
    vel = rng.uniform(1.0, 1.6, count)[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1) / fps
    out = np.empty((frames, count, 2))
    for t in range(frames):
        out[t] = pos
        pos = pos + vel
        bounce = (pos < lo) | (pos > hi)
        vel = np.where(bounce, -vel, vel)
        pos = np.clip(pos, lo, hi)
    return out


def scene_frames(width: int, height: int, frames: int, fps: float = 25.0, seed: int = 0, camera: Any = None):
    """``(height, width, 3)`` uint8 BGR frames of :data:`PEOPLE` people walking on a textured paving (smooth colour
    variation, a tile grid, gaussian noise of 3 levels cycling through 8 fields), drawn as a body ellipse and a head
    from their projections (1.75 m tall, 0.5 m wide) in :func:`scene_camera`, nearest last."""
    import cv2

    cam = camera if camera is not None else scene_camera(width, height)
    rng = np.random.default_rng(seed)
    base = cv2.resize(rng.uniform(70, 180, (max(height // 24, 2), max(width // 24, 2), 3)), (width, height))
    tiles = np.zeros((height, width))
    step = max(8, width // 40)
    tiles[::step, :] = 1.0
    tiles[:, ::step] = 1.0
    base = np.clip(base - 35.0 * tiles[..., None], 0, 255).astype(np.float32)
    bank = [rng.normal(0, 3, base.shape).astype(np.float32) for _ in range(8)]
    clothes = rng.integers(20, 235, (PEOPLE, 3))
    paths = _walkers(PEOPLE, frames, fps, seed + 1)
    for t in range(frames):
        img = np.clip(base + bank[t % len(bank)], 0, 255).astype(np.uint8)
        g = paths[t]
        order = np.argsort(-np.linalg.norm(g - np.asarray(cam.center[:2]), axis=1))  # far first
        for j in order:
            x, y = g[j]
            pts = np.array([[x, y, 0.0], [x, y, 1.75], [x - 0.25, y, 0.9], [x + 0.25, y, 0.9], [x, y, 1.55]])
            uv, ok = cam.project(pts)
            if not np.all(ok):
                continue
            foot, head, left, right, neck = uv
            half_w = max(1, int(abs(right[0] - left[0]) / 2))
            centre = (int((foot[0] + neck[0]) / 2), int((foot[1] + neck[1]) / 2))
            half_h = max(1, int(abs(foot[1] - neck[1]) / 2))
            colour = tuple(int(c) for c in clothes[j])
            cv2.ellipse(img, centre, (half_w, half_h), 0, 0, 360, colour, -1)
            r = max(1, int(abs(head[1] - neck[1]) / 2))
            cv2.circle(img, (int(head[0]), int(head[1]) + r), r, (40, 60, 90), -1)
        yield img


def write_scene(
    path: Path, width: int, height: int, frames: int, fps: float = 25.0, seed: int = 0, camera: Any = None
) -> Path:
    """Write :func:`scene_frames` (seen by ``camera``, default :func:`scene_camera`) as an MJPG ``.avi`` (OpenCV's
    default quality)."""
    import cv2

    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (width, height))
    if not writer.isOpened():
        raise ConfigError(f"cannot write the benchmark video {path} (no MJPG encoder in this OpenCV)")
    try:
        for img in scene_frames(width, height, frames, fps, seed, camera):
            writer.write(img)
    finally:
        writer.release()
    return path


def decode_only(video: str | tuple[str, ...], frames: int) -> tuple[float, float]:
    """``(wall seconds, process CPU seconds)`` to read ``frames`` frames (or to the end) of ``video`` with one
    ``cv2.VideoCapture`` in this thread (OpenCV's decoder may use threads of its own: the CPU time counts them);
    several videos: frame by frame in turn, as a multi-camera run reads them."""
    import cv2

    caps = [cv2.VideoCapture(str(v)) for v in ((video,) if isinstance(video, str) else video)]
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(frames):
            if not all(cap.read()[0] for cap in caps):
                break
        return time.perf_counter() - t0, time.process_time() - c0
    finally:
        for cap in caps:
            cap.release()


def _cli(argv: list[str]) -> tuple[float, float]:
    """Run ``wptrack ARGV`` in this process (its printed lines dropped): ``(wall seconds, process CPU seconds)``.
    Raises on a non-zero exit."""
    from wptrack.cli import main

    out, err = io.StringIO(), io.StringIO()
    t0, c0 = time.perf_counter(), time.process_time()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    if code != 0:
        raise RuntimeError(f"wptrack {' '.join(argv)} exited with {code}: {err.getvalue().strip()[-500:]}")
    return seconds, cpu


VARIANT_ENV = (
    "WPTRACK_MASK_WORKERS", "WPTRACK_DECODE_WORKERS", "WPTRACK_CPU_THREADS", "WPTRACK_DECODE_THREADS",
    "WPTRACK_DEVICE_CLEANUP", "WPTRACK_SAMPLE_READERS", "WPTRACK_JPEG_DECODE", "WPTRACK_JPEG_WORKERS",
    "WPTRACK_PNG_WORKERS",
)  # fmt: skip
"""The environment variables ``--variant`` may set."""


def parse_variant(text: str) -> tuple[tuple[str, str], ...]:
    """``"WPTRACK_MASK_WORKERS=2,WPTRACK_DECODE_WORKERS=4"`` -> ``(("WPTRACK_MASK_WORKERS", "2"), ...)``.

    Raises:
        ConfigError: not ``NAME=VALUE`` pairs of :data:`VARIANT_ENV` names with non-negative integer values.
    """
    out = []
    for part in str(text).split(","):
        name, sep, value = part.strip().partition("=")
        if not sep or name not in VARIANT_ENV or not value.strip().isdigit():
            raise ConfigError(
                f"--variant: expected NAME=N[,NAME=N...] with NAME one of {', '.join(VARIANT_ENV)}, got {text!r}"
            )
        out.append((name, value.strip()))
    return tuple(out)


@contextlib.contextmanager
def _environment(settings: tuple[tuple[str, str], ...]):
    import os

    old = {name: os.environ.get(name) for name, _ in settings}
    os.environ.update(dict(settings))
    try:
        yield
    finally:
        for name, value in old.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _timeline(run_dir: Path) -> dict[str, Any]:
    run = json.loads((run_dir / "run.json").read_text(encoding="utf-8"))
    return {"timeline": run.get("timeline", {}), "frames": int(run.get("frames") or 0), "summary": run.get("summary")}


class PipelineSuite:
    """The CLI pipeline against decoding (see the module)."""

    name = "pipeline"
    default_frames = 0  # 0: the suite's own default (600 frames on a GPU, 400 on the CPU)

    @staticmethod
    def default_grid(is_cuda: bool) -> list[Case]:
        return [Case(1920, 1080) if is_cuda else Case(480, 360)]

    @staticmethod
    def grid_from_args(args: Any, is_cuda: bool) -> list[Case]:
        """The case of ``--video V... [--rig R]`` or ``--size WxH`` (else the default grid), with the ``--variant``
        settings."""
        from dataclasses import replace

        variants = tuple(parse_variant(v) for v in (getattr(args, "variant", None) or ()))
        cases = [replace(case, variants=variants) for case in PipelineSuite._cases(args, is_cuda)]
        if variants and any(c.video is not None and len(c.video) > 1 for c in cases):
            raise ConfigError("--variant: the template commands' settings; a people run (several --video) takes none")
        return cases

    @staticmethod
    def _cases(args: Any, is_cuda: bool) -> list[Case]:
        video, rig, size = getattr(args, "video", None), getattr(args, "rig", None), getattr(args, "size", None)
        if video:
            if size is not None:
                raise ConfigError("--size: the pipeline suite takes the size of --video; give one of them")
            videos = (video,) if isinstance(video, str) else tuple(str(v) for v in video)
            if len(videos) > 1 and rig is None:
                raise ConfigError("--video: several videos are the cameras of a people run: give their --rig")
            from wptrack.io.frames import open_source

            src = open_source(videos[0])
            return [Case(src.width, src.height, videos, rig)]
        if rig is not None:
            raise ConfigError("--rig: the camera of a --video; the suite's own video has its own rig")
        if size is not None:
            return [Case(*parse_size(size))]
        return PipelineSuite.default_grid(is_cuda)

    @staticmethod
    def describe(case: Case, frames: int, e2e: Any = None) -> str:
        what = " ".join(case.video) if case.video else "synthetic MJPG"
        return f"{case.width}x{case.height} {what}" + (f", {frames} frames" if frames else "")

    @staticmethod
    def run_case(case: Case, device: str, frames: int = 0, numpy_max: int = 0) -> dict:
        import os

        import warp as wp

        from wptrack.motion.masks import MaskConfig

        is_cuda = wp.get_device(device).is_cuda
        if case.video is not None and len(case.video) > 1:
            return _people_case(case, device, frames)
        with tempfile.TemporaryDirectory(prefix="wptrack-bench-pipeline-") as tmp:
            tmp = Path(tmp)
            if case.video is None:
                frames = frames or (600 if is_cuda else 400)
                video = str(write_scene(tmp / "scene.avi", case.width, case.height, frames))
                rig = str(scene_rig(case.width, case.height, tmp / "rig.yaml"))
            else:
                from wptrack.io.frames import open_source

                video = case.video[0]
                frames = min(frames, len(open_source(video))) if frames else len(open_source(video))
                rig = case.rig or str(scene_rig(case.width, case.height, tmp / "rig.yaml"))
            limit = ["--max-frames", str(frames)]
            dev = ["--device", device]
            track = ["track", "templates", "-q", "--rig", rig, *dev]
            if frames < MaskConfig().window:  # the suite's short video: one background window, as the log says
                logging.getLogger("wptrack.motion.background").setLevel(logging.ERROR)
            # warm-up: kernels compiled and cached, OpenCV's codecs loaded (not timed)
            _cli(["masks", "--video", video, "--out", str(tmp / "warm-masks"), "--max-frames", str(WARM_FRAMES), *dev])
            _cli([*track, "--video", video, "--out", str(tmp / "warm"), "--max-frames", str(WARM_FRAMES)])
            load = os.getloadavg()[0]
            decode = [decode_only(video, frames)]
            masks_s = _cli(["masks", "--video", video, "--out", str(tmp / "masks"), *limit, *dev])
            track_s = _cli([*track, "--video", video, "--out", str(tmp / "run"), *limit])
            run = _timeline(tmp / "run")
            from_masks_s = _cli(
                [*track, "--masks", str(tmp / "masks" / "masks.avi"), "--no-virtual", "--out", str(tmp / "run-masks"),
                 *limit]
            )  # fmt: skip
            run_masks = _timeline(tmp / "run-masks")
            variants = []
            for k, settings in enumerate(case.variants):
                with _environment(settings):
                    v_masks = _cli(["masks", "--video", video, "--out", str(tmp / f"masks-v{k}"), *limit, *dev])
                    v_track = _cli([*track, "--video", video, "--out", str(tmp / f"run-v{k}"), *limit])
                variants.append((settings, v_masks, v_track, _timeline(tmp / f"run-v{k}")))
            decode.append(decode_only(video, frames))
            load = max(load, os.getloadavg()[0])
        logging.getLogger("wptrack.motion.background").setLevel(logging.NOTSET)
        decode_fps = frames / float(np.mean([d[0] for d in decode]))

        def rate(times: tuple[float, float], n: int = frames) -> dict[str, float]:
            seconds, cpu = times
            fps = n / seconds
            return {"seconds": seconds, "fps": fps, "ratio": fps / decode_fps, "cpu_s": cpu, "cpu_ms": 1000 * cpu / n}

        result = {
            "tracker": "pipeline",
            "device": device,
            "width": case.width,
            "height": case.height,
            "video": case.video[0] if case.video else "synthetic MJPG",
            "frames": frames,
            "cores": os.cpu_count(),
            "load": load,
            "decode_s": [d[0] for d in decode],
            "decode_cpu_ms": 1000 * float(np.mean([d[1] for d in decode])) / frames,
            "decode_fps": decode_fps,
            "masks": rate(masks_s),
            "track": {**rate(track_s, run["frames"] or frames), **run},
            "track_from_masks": {**rate(from_masks_s, run_masks["frames"] or frames), **run_masks},
            "variants": [
                {"env": dict(settings), "masks": rate(v_masks), "track": {**rate(v_track, v_run["frames"] or frames),
                                                                           **v_run}}
                for settings, v_masks, v_track, v_run in variants
            ],
        }  # fmt: skip
        targets = TARGETS["cuda" if is_cuda else "cpu"]
        checks = {
            "track_fps": result["track"]["fps"],
            "track_ratio": result["track"]["ratio"],
            "masks_fps": result["masks"]["fps"],
        }
        result["targets"] = {k: {"target": v, "got": checks[k], "met": checks[k] >= v} for k, v in targets.items()}
        return result

    HEADER = "pipeline: wall time of each command in this process (frames/s; ratio = its frames/s over decode-only)"

    @staticmethod
    def format_row(r: dict) -> str:
        lines = [
            f"{r['width']}x{r['height']} {r['video']}, {r['frames']} frames on {r['device']} ({r['cores']} cores, "
            f"load average up to {r['load']:.1f} while it ran: other processes' share is in the wall times)",
            f"  decode only (cv2.VideoCapture, one thread): {r['decode_fps']:8.1f} frames/s "
            f"({', '.join(f'{s:.2f}' for s in r['decode_s'])} s; CPU {r['decode_cpu_ms']:.2f} ms/frame)",
        ]
        for key, label in (
            ("masks", "wptrack masks"),
            ("track", "wptrack track templates --video (defaults)"),
            ("track_from_masks", "wptrack track templates --masks masks.avi --no-virtual"),
            ("people", f"wptrack track people --video ({r.get('cameras', 0)} cameras, defaults)"),
        ):
            if key not in r:
                continue
            c = r[key]
            lines.append(
                f"  {label:54s} {c['fps']:8.1f} frames/s  ratio {c['ratio']:.2f}  ({c['seconds']:.2f} s; process CPU "
                f"{c['cpu_ms']:.1f} ms/frame)"
            )
        for v in r.get("variants", []):
            env = ",".join(f"{k}={val}" for k, val in v["env"].items())
            for key in ("masks", "track"):
                c = v[key]
                lines.append(
                    f"  {env}: {'wptrack masks' if key == 'masks' else 'track templates --video':24s} {c['fps']:8.1f} "
                    f"frames/s  ratio {c['ratio']:.2f}  (process CPU {c['cpu_ms']:.1f} ms/frame)"
                )
        for key in ("track", "track_from_masks", "people"):
            tl = r.get(key, {}).get("timeline") or {}
            stages = tl.get("stages", {})
            if not stages:
                continue
            n = max(r[key].get("frames") or r["frames"], 1)
            lines.append(
                f"  timeline of {key} (frame loop {tl['wall_s']:.2f} s = {n / tl['wall_s']:.1f} frames/s, "
                f"overlap {tl['overlap']:.2f}): stage total s / share of the loop / ms per frame"
            )
            for name, s in sorted(stages.items(), key=lambda kv: -kv[1]["total_s"]):
                lines.append(
                    f"    {name:16s} {s['total_s']:8.3f} s {100 * s['share']:6.1f} % {1000 * s['total_s'] / n:8.2f} ms"
                )
            cpu = tl.get("cpu_s", {})
            if cpu:
                lines.append(
                    "    CPU ms per frame by thread: " + ", ".join(f"{k} {1000 * v / n:.1f}" for k, v in cpu.items())
                )
            if "first_item_s" in tl:  # the start-up, and the rate a long recording approaches
                after = tl.get("after_first_per_s")
                lines.append(
                    f"    start-up: the first frame's observation after {tl['first_item_s']:.2f} s"
                    + (f"; {after:.1f} frames/s after it" if after else "")
                )
        for k, t in r.get("targets", {}).items():
            lines.append(f"  target {k} >= {t['target']:g}: {t['got']:.2f} {'met' if t['met'] else 'NOT met'}")
        return "\n".join(lines)


def _people_case(case: Case, device: str, frames: int) -> dict:
    """The people tracker's command on the cameras' videos of ``case`` against decoding them (see the module)."""
    import os

    import warp as wp

    from wptrack.io.frames import open_source
    from wptrack.motion.masks import MaskConfig

    videos = list(case.video)
    count = min(len(open_source(v)) for v in videos)
    frames = min(frames, count) if frames else count
    with tempfile.TemporaryDirectory(prefix="wptrack-bench-pipeline-") as tmp:
        tmp = Path(tmp)
        track = ["track", "people", "-q", "--rig", str(case.rig), "--video", *videos, "--device", device]
        if frames < MaskConfig().window:
            logging.getLogger("wptrack.motion.background").setLevel(logging.ERROR)
        quiet = logging.getLogger("wptrack.trackers.people.tracker")  # per-frame notes (a full scene): not timings
        level = quiet.level
        quiet.setLevel(logging.ERROR)
        _cli([*track, "--out", str(tmp / "warm"), "--max-frames", str(WARM_FRAMES)])
        load = os.getloadavg()[0]
        decode = [decode_only(tuple(videos), frames)]
        people_s = _cli([*track, "--out", str(tmp / "run"), "--max-frames", str(frames)])
        run = _timeline(tmp / "run")
        decode.append(decode_only(tuple(videos), frames))
        load = max(load, os.getloadavg()[0])
    logging.getLogger("wptrack.motion.background").setLevel(logging.NOTSET)
    quiet.setLevel(level)
    decode_fps = frames / float(np.mean([d[0] for d in decode]))
    seconds, cpu = people_s
    n = run["frames"] or frames
    fps = n / seconds
    target = 1.0 / 1.5  # within 1.5x of decoding the cameras
    return {
        "tracker": "pipeline",
        "device": device,
        "width": case.width,
        "height": case.height,
        "video": " ".join(videos),
        "cameras": len(videos),
        "frames": frames,
        "cores": os.cpu_count(),
        "load": load,
        "decode_s": [d[0] for d in decode],
        "decode_cpu_ms": 1000 * float(np.mean([d[1] for d in decode])) / frames,
        "decode_fps": decode_fps,
        "people": {"seconds": seconds, "fps": fps, "ratio": fps / decode_fps, "cpu_s": cpu, "cpu_ms": 1000 * cpu / n,
                   **run},
        "targets": {"people_ratio": {"target": target, "got": fps / decode_fps, "met": fps / decode_fps >= target}},
        "is_cuda": wp.get_device(device).is_cuda,
    }  # fmt: skip
