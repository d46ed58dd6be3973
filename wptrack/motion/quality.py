"""Mask quality of the offline motion model under local illumination changes and short clips (issue 26): what each
test of the model buys, on synthetic scenes with perfect masks and on the real development clips' labelled boxes.

Synthetic rows (:func:`synthetic_row`): a plaza scene ``wptrack synth SCENE --seed SEED --conditions COND`` is
rendered once into a cache folder (the same files ``wptrack synth`` writes), its masks are made with each method
(a named set of :class:`wptrack.motion.masks.MaskConfig` fields, :data:`METHODS`), and each mask is compared with the
scene's perfect mask (the visible pixels of the moving objects, shadows excluded):

- ``precision``, ``recall``, ``f1``: pixel totals over all frames;
- ``fp``: false-positive pixels per frame as a fraction of the image;
- ``fp_lit``: the fraction of the pixels whose static radiance the local conditions changed by more than 5 %
  (:meth:`wptrack.synth.plaza.PlazaScene.local_light`: under a cloud, in a light's pool), farther than 5 px from
  the perfect mask, that the mask marks (NaN when there are none): false foreground where the light changed;
- ``obj_recall``, ``obj_min``: the mean and the smallest per-object recall of :mod:`wptrack.motion.recall` (the
  fraction of an object's silhouette the mask covers, mean over its frames).

Real rows (:func:`real_row`): the development clips' labelled boxes (PETS 2009 S2.L1 View 001: A. Milan's boxes,
768x576 units scaled to the video; Oxford TownCentre: the body boxes flagged valid). ``inside``: the fraction of the
pixels inside the boxes (their union) that are foreground (a person fills about half of a box, so about 0.5 is the
most a good mask gives); ``outside``: the fraction of the pixels farther than ``margin`` (10 % of the box height)
from every box that are foreground (unlabelled people, shadows, ghosts, flicker).

Background quality (:func:`background_error`): the model's background of the middle frame against the scene's true
background (the static scene rendered without objects and without noise, under the same light): the mean absolute
error and the fraction of pixels off by more than 12 levels in some channel (ghosts of objects taken into the
background).

Command::

    python3 -m wptrack.motion.quality --scenes s3-mixed --conditions none,clouds --seeds 0 \\
        --methods base,tiles --cache /tmp/motion-cache [--real pets,towncentre] [--out table.json]
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.motion.masks import MaskConfig, open_masks

log = logging.getLogger(__name__)

__all__ = ["METHODS", "background_error", "main", "real_row", "synthetic_row"]

#: The methods compared: name -> MaskConfig fields changed from the defaults.
METHODS: dict[str, dict[str, Any]] = {
    "base": {"illum_tiles": 0, "illum_veto": 0.0, "mode_band": 0.0},  # the model before issue 26
    "noband": {"illum_tiles": 0, "illum_veto": 0.0, "mode_band": 0.0, "shadow_band": 0.0},
    "T": {"illum_veto": 0.0, "mode_band": 0.0},  # the local field alone (windows compensated too)
    "Tf": {"illum_veto": 0.0, "mode_band": 0.0, "illum_windows": False},  # ... frames only
    "N": {"illum_tiles": 0, "mode_band": 0.0},  # the NCC veto alone
    "G": {"illum_tiles": 0, "illum_veto": 0.0, "illum_grad": 0.7, "mode_band": 0.0},  # the gradient veto alone
    "M": {"illum_tiles": 0, "illum_veto": 0.0},  # the densest-samples background alone
    "TN": {"mode_band": 0.0},
    "TG": {"illum_veto": 0.0, "illum_grad": 0.7, "mode_band": 0.0},
    "TM": {"illum_veto": 0.0},
    "nostill": {"mode_still": 0.0},  # the default with every sample weighing 1 in the densest cluster (before 11-27)
    "default": {},  # MaskConfig() as it is: T + N + M
}

PETS = Path("/work/shared/data/pets09-s2l1-view001-dev")
TOWNCENTRE = Path("/work/shared/data/towncentre-dev")


def _config(method: str | dict[str, Any], device: str) -> MaskConfig:
    kw = dict(METHODS[method]) if isinstance(method, str) else dict(method)
    kw.setdefault("device", device)
    return MaskConfig(**kw)


def scene_dir(cache: str | Path, scene: str, condition: str | None, seed: int, frames: int | None = None) -> Path:
    """The rendered scene folder in ``cache`` (rendered on first use, as ``wptrack synth`` renders it)."""
    from wptrack.synth import render_scene

    name = f"{scene}_{(condition or 'none').replace(',', '+')}_{seed}" + (f"_{frames}f" if frames else "")
    out = Path(cache) / name
    if not (out / "scene.json").is_file():
        render_scene(scene, out, frames=frames, seed=seed, conditions=condition)
    return out


def _scene_object(scene: str, condition: str | None, seed: int) -> Any:
    from wptrack.synth import get_scene
    from wptrack.synth.conditions import parse_conditions

    spec = get_scene(scene)
    obj = spec.build(int(seed)) if spec.seeded else spec.build()
    cond = parse_conditions(condition)
    return obj.with_conditions(cond) if cond.any else obj


def synthetic_row(
    cache: str | Path,
    scene: str,
    condition: str | None,
    seed: int,
    method: str | dict[str, Any],
    device: str = "cpu",
    frames: int | None = None,
    make_masks: Callable[..., dict[int, np.ndarray]] | None = None,
    stride: int = 1,
    camera: str = "cam0",
) -> dict[str, Any]:
    """Mask quality of one method on one rendered scene's ``camera`` (see the module docstring), on every
    ``stride``-th frame; ``make_masks(video, config, frames)`` (frame -> mask) replaces :func:`masks_at`
    (experiments). Scenes whose ground truth has no object sizes (the office) get no per-object recall."""
    import cv2

    from wptrack.cameras.rig import Rig
    from wptrack.io.frames import open_source
    from wptrack.motion.recall import GroundTruthFrames, object_labels, score_frame

    d = scene_dir(cache, scene, condition, seed, frames)
    obj = _scene_object(scene, condition, seed)
    n = len(open_source(d / f"{camera}.avi"))
    chosen = list(range(0, n, max(int(stride), 1)))
    t0 = time.perf_counter()
    made = _make(str(d / f"{camera}.avi"), _config(method, device), make_masks, chosen)
    seconds = time.perf_counter() - t0
    masks = [made[t] for t in chosen]
    perfect = [(p.max(axis=2) if p.ndim == 3 else p) > 0 for t, p in enumerate(open_source(d / f"{camera}_mask.avi"))
               if t in made]  # fmt: skip
    near_kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (11, 11))
    inter = pred = true = fp = 0
    lit_fp = lit_px = 0
    try:
        gt: GroundTruthFrames | None = GroundTruthFrames.read(d / "groundtruth.csv")
    except KeyError:  # no object sizes
        gt = None
    cam = Rig.load(d / "rig.yaml")[camera]
    conditions = getattr(obj, "conditions", None)
    local = conditions is not None and (conditions.clouds or conditions.exposure)
    hits: dict[int, list[float]] = {}
    for t, mask, ref in zip(chosen, masks, perfect, strict=True):
        if gt is not None:
            labels, ids = object_labels(ref, gt.frame(t), cam)
            per, _, _ = score_frame(mask, ref, labels, ids)
            for oid, (hit, tot) in per.items():
                if tot >= 50:
                    hits.setdefault(oid, []).append(hit / tot)
        m = mask > 0
        inter += int(np.count_nonzero(m & ref))
        pred += int(np.count_nonzero(m))
        true += int(np.count_nonzero(ref))
        fp += int(np.count_nonzero(m & ~ref))
        if local:
            changed = np.abs(obj.local_light(t) - 1.0) > 0.05
            changed &= cv2.dilate(ref.view(np.uint8), near_kernel) == 0
            lit_px += int(np.count_nonzero(changed))
            lit_fp += int(np.count_nonzero(changed & m))
    objs = [float(np.mean(v)) for v in hits.values()]
    precision = inter / pred if pred else math.nan
    recall = inter / true if true else math.nan
    size = masks[0].size
    return {
        "scene": scene if camera == "cam0" else f"{scene}/{camera}",
        "condition": condition or "none",
        "seed": int(seed),
        "method": method if isinstance(method, str) else json.dumps(method, sort_keys=True),
        "frames": len(masks),
        "precision": precision,
        "recall": recall,
        "f1": 2 * precision * recall / (precision + recall) if pred and true and inter else 0.0,
        "fp": fp / (len(masks) * size),
        "fp_lit": lit_fp / lit_px if lit_px else math.nan,
        "obj_recall": float(np.mean(objs)) if objs else math.nan,
        "obj_min": float(np.min(objs)) if objs else math.nan,
        "seconds": seconds,
    }


def masks_at(video: Any, config: MaskConfig, frames: Sequence[int] | None = None) -> dict[int, np.ndarray]:
    """The cleaned masks of ``frames`` (all when None) of a video, as :class:`wptrack.motion.masks.MotionMasks` makes
    them (the offline model's evidence of a frame does not depend on the other frames' masks, so a subset is exact)."""
    from wptrack.io.frames import open_source
    from wptrack.motion.masks import clean_mask

    mm = open_masks(video=video, config=config)
    if config.method != "offline":
        return {t: m.copy() for t, m in enumerate(mm) if frames is None or t in set(frames)}
    wanted = None if frames is None else set(int(f) for f in frames)
    model = mm.model
    out = {}
    try:
        for t, frame in enumerate(open_source(video) if not isinstance(video, np.ndarray) else video):
            if wanted is None or t in wanted:
                raw, _ = model.evidence(t, frame)
                out[t] = clean_mask(raw, config)
    finally:
        model.close()
    return out


def _make(video: Any, config: MaskConfig, make_masks: Any, frames: Sequence[int] | None) -> dict[int, np.ndarray]:
    if make_masks is not None:
        return dict(make_masks(video, config, frames))
    return masks_at(video, config, frames)


def _boxes(clip: str, size: tuple[int, int]) -> dict[int, np.ndarray]:
    """Frame -> ``(N, 4)`` boxes ``left, top, right, bottom`` in video pixels of a development clip."""
    out: dict[int, list[list[float]]] = {}
    if clip == "pets":
        from wptrack.evaluation.groundtruth import read_boxes

        b = read_boxes(PETS / "PETS2009-S2L1-frames0-399.xml")
        s = size[0] / 768.0
        for f, xc, yc, w, h in zip(b["frame"], b["xc"], b["yc"], b["w"], b["h"], strict=True):
            out.setdefault(int(f), []).append([s * (xc - w / 2), s * (yc - h / 2), s * (xc + w / 2), s * (yc + h / 2)])
    else:
        from wptrack.io.tables import read_tracks

        cols = read_tracks(TOWNCENTRE / "groundtruth.csv")
        valid = np.asarray(cols["body_valid"], dtype=np.float64) > 0
        names = ("body_l", "body_t", "body_r", "body_b")
        table = np.stack([np.asarray(cols[n], dtype=np.float64) for n in names], axis=1)
        s = size[0] / 1920.0
        for f, box, ok in zip(np.asarray(cols["frame"], dtype=np.int64), table, valid, strict=True):
            if ok:
                out.setdefault(int(f), []).append(list(s * box))
    return {f: np.asarray(v) for f, v in out.items()}


def real_row(
    clip: str,
    method: str | dict[str, Any],
    device: str = "cpu",
    first: int = 0,
    frames: int | None = None,
    margin: float = 0.1,
    make_masks: Callable[..., dict[int, np.ndarray]] | None = None,
    stride: int = 1,
) -> dict[str, Any]:
    """Inside/outside-box foreground of one method on a real clip (``"pets"`` or ``"towncentre"``), optionally on the
    excerpt ``first .. first + frames - 1`` (masks made from the excerpt alone, as a short recording)."""
    from wptrack.io.frames import open_source

    path = PETS / "video.avi" if clip == "pets" else TOWNCENTRE / "video.mp4"
    source = open_source(str(path))
    video: Any = str(path)
    if first or frames is not None:
        stop = len(source) if frames is None else min(len(source), first + frames)
        video = np.stack([f for i, f in enumerate(source) if first <= i < stop])
    count = (len(source) - first) if frames is None else min(frames, len(source) - first)
    t0 = time.perf_counter()
    made = _make(video, _config(method, device), make_masks, list(range(0, count, max(int(stride), 1))))
    seconds = time.perf_counter() - t0
    masks = list(made.values())
    h, w = masks[0].shape
    boxes = _boxes(clip, (w, h))
    in_fg = in_px = out_fg = out_px = 0
    for k, m in made.items():
        b = boxes.get(first + k)
        if b is None:
            continue
        inside = np.zeros((h, w), dtype=bool)
        near = np.zeros((h, w), dtype=bool)
        for left, top, right, bottom in b:
            pad = margin * (bottom - top)
            x0, y0 = max(int(round(left)), 0), max(int(round(top)), 0)
            x1, y1 = min(int(round(right)), w), min(int(round(bottom)), h)
            inside[y0:y1, x0:x1] = True
            y0n, y1n = max(int(top - pad), 0), min(int(bottom + pad) + 1, h)
            near[y0n:y1n, max(int(left - pad), 0) : min(int(right + pad) + 1, w)] = True
        fg = m > 0
        in_fg += int(np.count_nonzero(fg & inside))
        in_px += int(np.count_nonzero(inside))
        out_fg += int(np.count_nonzero(fg & ~near))
        out_px += int(np.count_nonzero(~near))
    return {
        "clip": clip + (f"[{first}:{first + count}]" if first or frames is not None else ""),
        "method": method if isinstance(method, str) else json.dumps(method, sort_keys=True),
        "frames": len(masks),
        "inside": in_fg / in_px if in_px else math.nan,
        "outside": out_fg / out_px if out_px else math.nan,
        "seconds": seconds,
    }


def true_background(scene: str, condition: str | None, seed: int, index: int) -> np.ndarray:
    """``(H, W, 3)`` uint8 BGR: the scene's static view at frame ``index`` without objects and without noise."""
    from wptrack.synth.plaza import PlazaScene

    obj = _scene_object(scene, condition, seed)
    empty = PlazaScene([], frames=obj.base_frames, fps=obj.fps, conditions=obj.conditions)
    empty.noise_sigma = 0.0
    if obj.conditions.sensor_noise:
        raise ValueError("true_background: the noise condition's noise cannot be switched off")
    bgr, _, _ = empty.render_labels(index, np.random.default_rng(0))
    return bgr


def background_error(
    cache: str | Path, scene: str, condition: str | None, seed: int, method: str | dict[str, Any], device: str = "cpu"
) -> dict[str, Any]:
    """The model's background of the middle frame against the true one (see the module docstring)."""
    from wptrack.io.frames import open_source

    d = scene_dir(cache, scene, condition, seed)
    source = open_source(str(d / "cam0.avi"))
    masks = open_masks(video=str(d / "cam0.avi"), config=_config(method, device))
    model = masks.model
    mid = len(source) // 2
    i, j, w = _bracket(model, mid)
    b = (1.0 - w) * model.background(i).astype(np.float64) + w * model.background(j).astype(np.float64)
    truth = true_background(scene, condition, seed, mid).astype(np.float64)
    err = np.abs(b - truth)
    return {
        "scene": scene,
        "condition": condition or "none",
        "seed": int(seed),
        "method": method if isinstance(method, str) else json.dumps(method, sort_keys=True),
        "mae": float(err.mean()),
        "bad": float((err.max(axis=2) > 12).mean()),
    }


def _bracket(model: Any, t: int) -> tuple[int, int, float]:
    from wptrack.motion.windows import bracket

    return bracket(model.centres, t)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.4f}"
    return str(v)


def markdown(rows: Iterable[dict[str, Any]], keys: Sequence[str]) -> str:
    """A markdown table of ``rows`` with columns ``keys``."""
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(_fmt(r.get(k)) for k in keys) + " |" for r in rows]
    return "\n".join(lines)


SYNTH_KEYS = ("scene", "condition", "seed", "method", "precision", "recall", "f1", "fp", "fp_lit", "obj_recall",
              "obj_min")  # fmt: skip
REAL_KEYS = ("clip", "method", "frames", "inside", "outside")


def main(argv: Sequence[str] | None = None) -> int:
    """Command line (see the module docstring)."""
    p = argparse.ArgumentParser(prog="python3 -m wptrack.motion.quality", description=__doc__.split("\n")[0])
    p.add_argument("--scenes", default="s3-mixed")
    p.add_argument("--conditions", default="none", help="comma-separated; '+' joins conditions of one row")
    p.add_argument("--seeds", default="0")
    p.add_argument("--methods", default="base", help="comma-separated names of METHODS, or JSON objects after ';'")
    p.add_argument("--method-json", action="append", default=[], help="a MaskConfig override as JSON (repeatable)")
    p.add_argument("--cache", default="/tmp/wptrack-motion-cache")
    p.add_argument("--real", default="", help="comma-separated: pets, pets100, towncentre")
    p.add_argument("--background", action="store_true", help="also the background error of each synthetic row")
    p.add_argument("--device", default="cpu")
    p.add_argument("--stride", type=int, default=1, help="score every n-th frame only (the others are not made)")
    p.add_argument("--cameras", default="cam0", help="comma-separated cameras of the synthetic scenes")
    p.add_argument("--out", default=None, help="append the rows (JSON lines) to this file")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    methods: list[str | dict[str, Any]] = [m for m in args.methods.split(",") if m]
    methods += [json.loads(j) for j in args.method_json]
    rows = []
    for scene in [s for s in args.scenes.split(",") if s]:
        for cond in [c for c in args.conditions.split(",") if c]:
            c = None if cond == "none" else cond.replace("+", ",")
            for seed in [int(s) for s in args.seeds.split(",") if s]:
                for m, cam in [(m, cam) for m in methods for cam in args.cameras.split(",")]:
                    r = synthetic_row(args.cache, scene, c, seed, m, args.device, stride=args.stride, camera=cam)
                    if args.background:
                        r.update({k: v for k, v in background_error(args.cache, scene, c, seed, m, args.device).items()
                                  if k in ("mae", "bad")})  # fmt: skip
                    rows.append(r)
                    print(markdown([r], (*SYNTH_KEYS, *(("mae", "bad") if args.background else ()))).split("\n")[-1],
                          flush=True)  # fmt: skip
                    if args.out:
                        with open(args.out, "a") as fh:
                            fh.write(json.dumps(r) + "\n")
    for clip in [c for c in args.real.split(",") if c]:
        for m in methods:
            if clip == "pets100":
                r = real_row("pets", m, args.device, 0, 100, stride=args.stride)
            else:
                r = real_row(clip, m, args.device, stride=args.stride)
            rows.append(r)
            print(markdown([r], REAL_KEYS).split("\n")[-1], flush=True)
            if args.out:
                with open(args.out, "a") as fh:
                    fh.write(json.dumps(r) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
