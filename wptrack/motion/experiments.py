"""How each hard condition of the s3 scenes (:mod:`wptrack.synth.conditions`) alone affects the offline motion masks.

For a scene, a seed and one condition (or none), the scene is rendered exactly as ``wptrack synth SCENE --seed SEED
--conditions CONDITION`` renders it (the same noise draws; the frames stay in memory, the written video being
lossless), its motion masks are made as ``wptrack masks`` makes them (:class:`wptrack.motion.masks.MaskConfig`, default:
the offline background model with its shadow test and clean-up), and each mask is compared with the scene's perfect
mask (the visible pixels of the moving objects, shadows excluded):

- ``iou``: mean over frames of ``|M & P| / |M | P|`` (frames where both are empty are left out);
- ``precision``, ``recall``: pixel totals over all frames, ``sum |M & P| / sum |M|`` and ``sum |M & P| / sum |P|``;
- ``fp_fraction``: false-positive pixels per frame as a fraction of the image (shadows, ghosts, noise).

Command (one row per condition, CPU)::

    python3 -m wptrack.motion.experiments --scene s3-mixed --seeds 0 [--frames 180] [--out table.json]

``--shake 0,2,4,8,16`` instead shakes frames 60-71 of the scene (:func:`shake`) and reports the masks' foreground
fraction and the frames the run's flood guard (:mod:`wptrack.motion.flood`) flags.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from wptrack.motion.masks import MaskConfig, open_masks
from wptrack.synth import get_scene
from wptrack.synth.conditions import CONDITION_NAMES, parse_conditions

log = logging.getLogger(__name__)

__all__ = ["condition_mask_quality", "condition_table", "main", "render_arrays", "shake", "shake_floods"]


def render_arrays(
    scene_name: str, condition: str | None, seed: int = 0, frames: int | None = None
) -> tuple[np.ndarray, np.ndarray, int]:
    """Frames and perfect masks of an s3 scene under ``condition``, as :func:`wptrack.synth.render_scene` renders.

    Args:
        scene_name: A plaza scene (``s3-*``).
        condition: Comma-separated condition names, or None / ``"none"`` for the scene as registered.
        seed: Noise seed.
        frames: Number of frames (default: the scene's).

    Returns:
        ``(frames (T, H, W, 3) uint8 BGR, perfect masks (T, H, W) bool, fps)``.
    """
    spec = get_scene(scene_name)
    scene = spec.build(int(seed)) if spec.seeded else spec.build()
    cond = parse_conditions(condition)
    if cond.any:
        scene = scene.with_conditions(cond)
    if not scene.writes_masks:
        raise ValueError(f"scene {scene_name!r} has no perfect masks")
    n = int(frames if frames is not None else scene.default_frames)
    rngs = [np.random.default_rng([int(seed), k]) for k in range(len(scene.rig))]
    cam = scene.rig[0]
    images = np.empty((n, cam.height, cam.width, 3), dtype=np.uint8)
    perfect = np.empty((n, cam.height, cam.width), dtype=bool)
    trajectories = scene.trajectories(n)
    for f in range(n):
        imgs, _, masks = scene.render_frame_masks(f, {oid: t[f] for oid, t in trajectories.items()}, rngs)
        images[f] = imgs[0]
        perfect[f] = masks[0] > 0
    return images, perfect, scene.fps


def condition_mask_quality(
    scene_name: str = "s3-mixed",
    condition: str | None = None,
    seed: int = 0,
    frames: int | None = None,
    config: MaskConfig | None = None,
) -> dict[str, Any]:
    """Mask quality of the offline (or any) motion masks against the perfect masks (see the module docstring).

    Returns:
        ``{"scene", "condition", "seed", "frames", "iou", "precision", "recall", "fp_fraction", "seconds"}``.
    """
    config = MaskConfig() if config is None else config
    t0 = time.perf_counter()
    images, perfect, _ = render_arrays(scene_name, condition, seed, frames)
    t1 = time.perf_counter()
    ious = []
    inter = pred = true = fp = 0
    for mask, ref in zip(open_masks(video=images, config=config), perfect, strict=True):
        m = mask > 0
        i = int(np.count_nonzero(m & ref))
        u = int(np.count_nonzero(m | ref))
        if u:
            ious.append(i / u)
        inter += i
        pred += int(np.count_nonzero(m))
        true += int(np.count_nonzero(ref))
        fp += int(np.count_nonzero(m & ~ref))
    t2 = time.perf_counter()
    log.info("%s %s seed %d: rendered in %.1f s, masks in %.1f s", scene_name, condition, seed, t1 - t0, t2 - t1)
    return {
        "scene": scene_name,
        "condition": condition or "none",
        "seed": int(seed),
        "frames": len(images),
        "iou": float(np.mean(ious)) if ious else float("nan"),
        "precision": inter / pred if pred else float("nan"),
        "recall": inter / true if true else float("nan"),
        "fp_fraction": fp / (images.shape[0] * images.shape[1] * images.shape[2]),
        "seconds": t2 - t0,
    }


def condition_table(
    scene_name: str = "s3-mixed",
    seeds: Sequence[int] = (0,),
    conditions: Sequence[str | None] = (None, *CONDITION_NAMES),
    frames: int | None = None,
    config: MaskConfig | None = None,
) -> list[dict[str, Any]]:
    """:func:`condition_mask_quality` for every condition and seed (rows in that order)."""
    return [condition_mask_quality(scene_name, cond, seed, frames, config) for cond in conditions for seed in seeds]


def shake(images: np.ndarray, first: int, count: int, amplitude: int, seed: int = 5) -> np.ndarray:
    """A copy of ``images`` (T, H, W, 3) whose frames ``first .. first + count - 1`` are shifted (camera shake).

    Each shaken frame moves by a random (dy, dx) in ``[-amplitude, amplitude]`` pixels per axis, an axis drawn
    under ``amplitude / 2`` taking ``amplitude`` (so every shaken frame moves); pixels wrap around (np.roll).
    """
    rng = np.random.default_rng(seed)
    out = images.copy()
    for f in range(first, min(first + count, len(images))):
        d = rng.integers(-amplitude, amplitude + 1, 2)
        d[np.abs(d) < amplitude // 2] = amplitude
        out[f] = np.roll(images[f], (int(d[0]), int(d[1])), axis=(0, 1))
    return out


def shake_floods(
    scene_name: str = "s3-mixed",
    amplitudes: Sequence[int] = (2, 4, 8, 16),
    first: int = 60,
    count: int = 12,
    seed: int = 0,
    config: MaskConfig | None = None,
) -> list[dict[str, Any]]:
    """Foreground fraction of the motion masks and the frames :class:`wptrack.motion.flood.FloodGuard` flags, when
    frames ``first .. first + count - 1`` of the scene are shaken by each amplitude (pixels; 0: no shake)."""
    from wptrack.motion.flood import FloodGuard

    config = MaskConfig() if config is None else config
    images, _, _ = render_arrays(scene_name, None, seed)
    rows = []
    for amp in amplitudes:
        video = shake(images, first, count, int(amp)) if amp else images
        guard = FloodGuard()
        fractions = []
        for m in open_masks(video=video, config=config):
            fractions.append(float(np.count_nonzero(m)) / m.size)
            guard.filter(m)
        shaken = fractions[first : first + count]
        rest = fractions[:first] + fractions[first + count :]
        rows.append(
            {
                "amplitude_px": int(amp),
                "median_fraction_unshaken": float(np.median(rest)),
                "median_fraction_shaken": float(np.median(shaken)),
                "flagged_shaken": sum(first <= i < first + count for i in guard.flooded),
                "flagged_other": sum(not first <= i < first + count for i in guard.flooded),
            }
        )
    return rows


def _markdown(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| condition | seed | mean IoU | precision | recall | false-positive pixels |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['condition']} | {r['seed']} | {r['iou']:.3f} | {r['precision']:.3f} | {r['recall']:.3f} "
            f"| {100 * r['fp_fraction']:.2f} % |"
        )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: print a markdown table of mask quality per condition (see the module docstring)."""
    p = argparse.ArgumentParser(prog="python3 -m wptrack.motion.experiments", description=__doc__.split("\n")[0])
    p.add_argument("--scene", default="s3-mixed")
    p.add_argument("--seeds", default="0", help="comma-separated seeds (default 0)")
    p.add_argument("--conditions", default=None, help="comma-separated: none and/or condition names (default: all)")
    p.add_argument("--frames", type=int, default=None)
    p.add_argument("--mask-config", default=None, help="JSON object of MaskConfig fields, e.g. '{\"shadow_lo\": 0.3}'")
    p.add_argument("--out", default=None, help="also write the rows as JSON here")
    p.add_argument("--shake", default=None, help="instead: camera shake of frames 60-71 by these amplitudes (px)")
    args = p.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    conds: list[str | None] = (
        [None, *CONDITION_NAMES]
        if args.conditions is None
        else [None if c.strip() == "none" else c.strip() for c in args.conditions.split(",")]
    )
    config = MaskConfig(**json.loads(args.mask_config)) if args.mask_config else MaskConfig()
    if args.shake:
        amps = [int(a) for a in args.shake.split(",")]
        shaken = shake_floods(args.scene, amps, seed=seeds[0], config=config)
        print("| shake (px) | foreground, other frames | foreground, shaken frames | flagged: shaken / 12, other |")
        print("|---|---|---|---|")
        for r in shaken:
            print(
                f"| {r['amplitude_px']} | {100 * r['median_fraction_unshaken']:.1f} % "
                f"| {100 * r['median_fraction_shaken']:.1f} % | {r['flagged_shaken']}, {r['flagged_other']} |"
            )
        return 0
    rows = condition_table(args.scene, seeds, conds, args.frames, config)
    print(f"scene {args.scene}, seeds {seeds}, mask config {dataclasses.asdict(config)}")
    print(_markdown(rows))
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
