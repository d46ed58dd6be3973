"""Benchmark of the offline background model (``MaskConfig(method="offline")``) against decoding the same video.

Per case (frame size), ``frames`` synthetic frames (smooth colour texture, gaussian noise of 3 levels, a few
moving rectangles) are encoded to a temporary FFV1 ``.avi`` (the project's lossless writer). Measured:

* ``decode``: reading the video with :class:`wptrack.io.frames.VideoSource`, per frame (median of 3 passes);
* ``sample+build``: one background window (the sampler's reads of its ``samples`` frames, the upload, the
  median/MAD kernel and the host statistics: gains, spread, neighbourhood scale, shadow ratio), amortised over the
  ``window // 2`` frames between window starts (a window is built every ``window // 2`` frames). The video is
  shorter than ``window``, so its one window samples every other frame of it and the sampler decodes all
  ``frames`` frames for it, about a third of a decoding pass per frame; in a long video with the default window
  (a sample every 12 frames) the sampler reads forward and decodes each frame about once (see
  :mod:`wptrack.motion.background`): add about one ``decode`` for a video source;
* ``kernel``: the per-frame step (frame gain, upload, foreground and neighbourhood kernels, mask and probability
  back, hysteresis), per frame;
* ``clean``: the host morphology (cv2 opening + closing) per frame;
* ``model``: sample+build + kernel, and ``model / decode``: a sum of the components' times, each timed alone in
  the calling thread, not the wall time a user waits for (the sampler's decoding runs ahead in a worker thread in
  the real pipeline, the video's decoding in another, and the clean-up is left out);
* ``numpy``: the NumPy reference of the per-frame step (:mod:`benchmarks.numpy_masks`), per frame;
* **end to end** (:func:`end_to_end`; at 1920x1080 with a GPU device only: minutes on a CPU): a second video of
  ``2 window`` frames (600 with the defaults: three background windows ``window / 2`` apart, as in a long video),
  made the same way (the noise cycling through 8 fields). ``decode``: reading it; ``e2e``: the wall time of the
  default mask pipeline a user runs, ``open_masks(video=path, config=MaskConfig(device=...))`` iterated over all
  frames (offline model with its defaults, decoding, window builds, per-frame step and clean-up), per frame;
  ``added = e2e - decode``: what making the masks adds to decoding per frame, and ``added / decode``. The target:
  ``added < decode`` (``added / decode < 1``). Decode and mask passes alternate, two of each on a GPU device
  (medians), one on the CPU. The kernels are compiled before (by the cases above). With three windows the builds
  come once per 200 frames, against once per ``window / 2`` = 150 in a long video. The first mask waits for the
  first window, whose samples span half a window of frames read before any mask (``e2e_first_ms``, a start-up
  latency that a long recording pays once); ``e2e_steady_ms`` and ``added_steady`` are the per-frame figures after
  the first mask (the worker then reads each next window ahead).

``equivalent``: the Warp masks equal the NumPy reference's on all timed frames except pixels within 1e-3 robust
standard deviations of a threshold (float32 vs float64), and probabilities agree to 1e-4.
"""

from __future__ import annotations

import logging
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Case:
    """One frame size, pixels."""

    width: int
    height: int
    e2e: bool = True  # also time the end-to-end mask pass (:func:`end_to_end`)


def video_frames(width: int, height: int, frames: int, seed: int = 0, noise_fields: int = 0) -> Iterator[np.ndarray]:
    """``(height, width, 3)`` uint8 frames, one at a time: smooth texture + gaussian noise (sigma 3 levels), 4
    rectangles moving 4 px per frame. ``noise_fields > 0``: the noise cycles through that many fields drawn once
    (cheap to make a long video; the decoder and the model see noise all the same), else a fresh field per frame."""
    import cv2

    rng = np.random.default_rng(seed)
    base = cv2.resize(rng.uniform(40, 200, (height // 16, width // 16, 3)).astype(np.float32), (width, height))
    size = (width // 10, height // 8)
    starts = rng.integers(0, [width - size[0], height - size[1]], (4, 2))
    colours = rng.integers(0, 255, (4, 3))
    bank = [rng.normal(0, 3, base.shape).astype(np.float32) for _ in range(noise_fields)]
    for t in range(frames):
        noise = bank[t % noise_fields] if bank else rng.normal(0, 3, base.shape)
        img = np.clip(base + noise, 0, 255).astype(np.uint8)
        for (x, y), col in zip(starts, colours, strict=True):
            x = int((x + 4 * t) % (width - size[0]))
            img[y : y + size[1], x : x + size[0]] = col
        yield img


def bench_video(width: int, height: int, frames: int, seed: int = 0) -> np.ndarray:
    """``(frames, height, width, 3)`` uint8: :func:`video_frames` (a fresh noise field per frame) stacked."""
    out = np.empty((frames, height, width, 3), np.uint8)
    for t, img in enumerate(video_frames(width, height, frames, seed)):
        out[t] = img
    return out


def e2e_frames(window: int) -> int:
    """Frames of the end-to-end video: ``2 window``, three background windows ``window / 2`` apart (as in a long
    video, where the sampler decodes each frame about once)."""
    return 2 * window


def end_to_end(case: Case, device: str, frames: int, seed: int = 0, repeats: int = 1) -> dict:
    """Wall time of the default mask pipeline over a ``frames``-frame FFV1 video of ``case``'s size against
    decoding it: ``open_masks(video=path, config=MaskConfig(device=device))`` iterated to the end (the offline
    model with its defaults, the frames decoded ahead by :func:`wptrack.io.prefetch.prefetch`, the windows' samples read
    ahead by the model's worker, the clean-up), alternating with decode-only passes, ``repeats`` of each.

    Returns:
        ``e2e_frames``, ``e2e_windows``, ``e2e_repeats``, ``e2e_ms`` (the mask passes' median, ms per frame),
        ``e2e_decode_ms`` (the decode-only passes' median, ms per frame), ``added_ms`` (their difference: what the
        masks add to decoding per frame), ``added_vs_decode``; ``e2e_first_ms`` (time to the first mask, ms),
        ``e2e_steady_ms`` (ms per frame after it), ``added_steady_ms`` (that less decoding), ``added_steady_vs_decode``.
    """
    from wptrack.io.frames import open_source
    from wptrack.io.video import VideoWriter
    from wptrack.motion.masks import MaskConfig, open_masks

    config = MaskConfig(device=device)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "e2e.avi"
        with VideoWriter(path, fps=25) as writer:
            for img in video_frames(case.width, case.height, frames, seed, noise_fields=8):
                writer.write(img)

        def decode() -> float:
            t0 = time.perf_counter()
            for _f in open_source(path):
                pass
            return time.perf_counter() - t0

        decodes, passes, firsts = [], [], []
        for _ in range(repeats):
            decodes.append(decode())
            t0 = time.perf_counter()
            masks = open_masks(video=path, config=config)
            it = iter(masks)
            next(it)
            firsts.append(time.perf_counter() - t0)
            count = 1 + sum(1 for _mask in it)
            passes.append(time.perf_counter() - t0)
        windows = len(masks.model.windows)
    e2e_ms = 1e3 * float(np.median(passes)) / count
    decode_ms = 1e3 * float(np.median(decodes)) / count
    first_ms = 1e3 * float(np.median(firsts))
    steady_ms = 1e3 * float(np.median([p - f for p, f in zip(passes, firsts, strict=True)])) / max(count - 1, 1)
    return {
        "e2e_frames": count,
        "e2e_windows": windows,
        "e2e_repeats": repeats,
        "e2e_ms": e2e_ms,
        "e2e_decode_ms": decode_ms,
        "added_ms": e2e_ms - decode_ms,
        "added_vs_decode": (e2e_ms - decode_ms) / decode_ms,
        "e2e_first_ms": first_ms,
        "e2e_steady_ms": steady_ms,
        "added_steady_ms": steady_ms - decode_ms,
        "added_steady_vs_decode": (steady_ms - decode_ms) / decode_ms,
    }


class _DropShortWindowWarning(logging.Filter):
    """The bench's own short temporary videos are shorter than a background window on purpose: the model's warning
    about it (naming the temporary file) says nothing to the user."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "shorter than the background window" not in record.getMessage()


class MasksSuite:
    """Offline background model vs decoding, at 640x480 and 1920x1080."""

    name = "masks"
    HEADER = (
        f"{'suite':6s} {'size':>10s} {'frames':>6s} {'decode':>8s} {'smp+bld':>8s} {'kernel':>8s} {'clean':>8s} "
        f"{'model':>8s} {'numpy':>8s} {'eq':>4s}  (ms per frame; model = smp+bld + kernel; end to end: decode, "
        "e2e = the default mask pass, added = e2e - decode)"
    )

    @staticmethod
    def default_grid(is_cuda: bool) -> list[Case]:
        # the end-to-end pass at 1920x1080 takes minutes on a CPU device: there only with a GPU
        return [Case(640, 480), Case(1920, 1080, e2e=is_cuda)]

    @staticmethod
    def format_row(r: dict) -> str:
        eq = {True: "yes", False: "NO"}.get(r.get("equivalent"), "-")
        row = (
            f"{r['tracker']:6s} {r['width']:>5d}x{r['height']:<4d} {r['frames']:>6d} {r['decode_ms']:8.2f} "
            f"{r['build_ms']:8.2f} {r['kernel_ms']:8.2f} {r['clean_ms']:8.2f} {r['model_ms']:8.2f} "
            f"{r['numpy_ms']:8.2f} {eq:>4s}  model/decode {r['model_vs_decode']:.2f}"
        )
        if "added_ms" not in r:
            return row + "  end to end: -"
        return (
            f"{row}  end to end ({r['e2e_frames']} frames, {r['e2e_windows']} windows): decode "
            f"{r['e2e_decode_ms']:.2f} e2e {r['e2e_ms']:.2f} added {r['added_ms']:.2f} "
            f"added/decode {r['added_vs_decode']:.2f}; first mask after {r['e2e_first_ms']:.0f} ms, then "
            f"{r['e2e_steady_ms']:.2f} per frame: added {r['added_steady_ms']:.2f}, added/decode "
            f"{r['added_steady_vs_decode']:.2f}"
        )

    @staticmethod
    def describe(case: Case, frames: int, e2e: int | None = None) -> str:
        """What a case times (said before it runs: the end-to-end pass takes a while on a CPU)."""
        from wptrack.motion.masks import MaskConfig

        what = f"{case.width}x{case.height}, {frames} frames"
        if case.e2e:
            what += f", then the end-to-end mask pass over {e2e or e2e_frames(MaskConfig().window)} frames"
        return what

    @staticmethod
    def run_case(
        case: Case, device: str, frames: int = 50, numpy_max: int = 0, seed: int = 0, e2e: int | None = None
    ) -> dict:
        quiet = _DropShortWindowWarning()
        logger = logging.getLogger("wptrack.motion.background")
        logger.addFilter(quiet)
        try:
            return MasksSuite._run_case(case, device, frames, numpy_max, seed, e2e)
        finally:
            logger.removeFilter(quiet)

    @staticmethod
    def _run_case(case: Case, device: str, frames: int, numpy_max: int, seed: int, e2e: int | None) -> dict:
        import cv2

        from wptrack.bench import numpy_masks
        from wptrack.io.frames import open_source
        from wptrack.io.video import write_video
        from wptrack.motion.background import OfflineBackground
        from wptrack.motion.illumination import ILLUM_MIN_WEIGHT, ILLUM_WIDEN
        from wptrack.motion.masks import MaskConfig

        config = MaskConfig(method="offline", device=device)
        video = bench_video(case.width, case.height, frames, seed)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "bench.avi"
            write_video(path, video, fps=25)
            source = open_source(path)
            decode = []
            for _ in range(3):
                t0 = time.perf_counter()
                for _f in source:
                    pass
                decode.append(time.perf_counter() - t0)
            decoded = list(source)
            # a window over the whole recording when it is shorter than config.window: the same K samples
            model = OfflineBackground(source, config, device)
            model.evidence(0, decoded[0])  # compile the kernels, outside the timing
            builds = []
            for _ in range(3):
                model._built.clear()
                model.close()  # a fresh sampler
                t0 = time.perf_counter()
                model._window(0)
                builds.append(time.perf_counter() - t0)
            median, mad = (a.numpy().reshape(case.height, case.width, 3) for a in model._window(0))
            kernel, masks, probs, gains, fields = [], [], [], [], []
            for t, f in enumerate(decoded):
                t0 = time.perf_counter()
                m, p = model.evidence(min(t, 0), f)  # window 0 only: time the step, not window builds
                kernel.append(time.perf_counter() - t0)
                masks.append(m)
                probs.append(p)
                gains.append(model.last_gain.copy())
                if t < 10 and model.light.active:  # the device's local field and patch statistics, for the reference
                    fields.append((model.light.local.numpy().copy(), model.light.patch.numpy().copy()))
            model.close()
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
        k5 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
        clean = []
        for m in masks:
            t0 = time.perf_counter()
            cv2.morphologyEx(cv2.morphologyEx(m, cv2.MORPH_OPEN, k), cv2.MORPH_CLOSE, k5)
            clean.append(time.perf_counter() - t0)
        c = config
        ref_t, equivalent = [], True
        mp = model.params
        for t, f in enumerate(decoded[: min(frames, 10)]):
            t0 = time.perf_counter()
            field = veto = None
            if fields:
                # the NumPy local field is computed (and timed) too; the masks are compared given the device's
                # field and patch statistics (a tile's median vote may differ by a quantisation step, float32)
                lum = numpy_masks.luma(f, gains[t], median, mad, median, mad, 0.0, c.noise_floor, mp.spread_cap)
                st = numpy_masks.patch(lum, c.illum_patch)
                if mp.tile:
                    shadow = (mp.shadow_lo, mp.shadow_hi, mp.chroma_max) if mp.shadow else None
                    tiles = numpy_masks.tile_gains(f, gains[t], median, median, 0.0, st, mp.tile, mp.veto_texture,
                                                   mp.verify_ncc, shadow, mp.veto_resid, mp.gain_gap,
                                                   mp.illum_chroma)  # fmt: skip
                    numpy_masks.tile_smooth(tiles, c.illum_radius, ILLUM_MIN_WEIGHT, c.illum_keep, c.illum_dead,
                                            ILLUM_WIDEN)  # fmt: skip
                    local = fields[t][0].reshape(mp.tiles_y, mp.tiles_x, 3).astype(np.float64)
                    field = numpy_masks.local_field(local, mp.tile, case.height, case.width)
                if mp.veto_ncc > 0 or mp.veto_grad > 0:
                    veto = dict(st=fields[t][1].reshape(case.height, case.width, 6).astype(np.float64),
                                texture=mp.veto_texture, veto_ncc=mp.veto_ncc, veto_grad=mp.veto_grad,
                                resid=mp.veto_resid, illum_lo=mp.illum_lo, illum_hi=mp.illum_hi,
                                illum_chroma=mp.illum_chroma, gap=mp.gain_gap)  # fmt: skip
            ref = numpy_masks.foreground(
                f, median, mad, median, mad, 0.0, c.fg_threshold, c.soft_scale, c.noise_floor, c.detect_shadows,
                mp.shadow_lo, mp.shadow_hi, c.shadow_chroma, gains[t], mp.low_threshold, mp.spread_cap,
                mp.shadow_edge_hi, c.neighbourhood, model._nb_scale.get(0, 1.0), field=field, veto=veto,
            )  # fmt: skip
            ref_t.append(time.perf_counter() - t0)
            near = (np.abs(ref["z"] - c.fg_threshold) < 1e-3) | (np.abs(ref["z"] - model.params.low_threshold) < 1e-3)
            equivalent &= bool(np.all((masks[t] == ref["mask"]) | near))
            equivalent &= bool(np.allclose(probs[t], ref["prob"], atol=1e-4) or near.any())
        stride = max(c.window // 2, 1)
        decode_ms = 1e3 * float(np.median(decode)) / frames
        build_ms = 1e3 * float(np.median(builds)) / stride
        kernel_ms = 1e3 * float(np.median(kernel))
        repeats = 1 if device == "cpu" else 2  # 600 frames take about 40 s on a 2-core CPU
        end = end_to_end(case, device, e2e or e2e_frames(c.window), seed, repeats) if case.e2e else {}
        return {
            "tracker": "masks",
            "width": case.width,
            "height": case.height,
            "frames": frames,
            "device": device,
            "samples": len(model.windows[0].samples),
            "window": c.window,
            "decode_ms": decode_ms,
            "build_window_s": float(np.median(builds)),
            "build_ms": build_ms,
            "kernel_ms": kernel_ms,
            "clean_ms": 1e3 * float(np.median(clean)),
            "model_ms": build_ms + kernel_ms,
            "model_vs_decode": (build_ms + kernel_ms) / decode_ms,
            "numpy_ms": 1e3 * float(np.median(ref_t)),
            "equivalent": equivalent,
            **end,
        }
