"""Accuracy of the S3 template tracker on the synthetic scene types (Juza et al., Table 2): render the scenes, make
their masks (offline, MOG2 or the perfect silhouettes), track with several seeds in parallel processes and score
(``template_accuracy``; docs/templates.md has the tables)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from wptrack.core.device import resolve_device
from wptrack.core.errors import ConfigError
from wptrack.io.atomic import atomic_write_json, atomic_write_text, ensure_writable_dir

# --- S3: accuracy of the template tracker on the synthetic scene types (paper Table 2) ---------------------------
S3_SCENES: tuple[str, ...] = ("s3-people", "s3-cars", "s3-groups", "s3-mixed")


S3_MASKS: tuple[str, ...] = ("offline", "mog2", "perfect")
"""Motion masks of :func:`template_accuracy`: the default pipeline (offline background model), OpenCV MOG2, or the
scene's perfect silhouettes."""


def _s3_scene(
    name: str, scenes_dir: Path, frames: int | None, seed: int, progress: bool, conditions: str | None = None
):
    """Render scene ``name`` with scene seed ``seed`` into ``scenes_dir/<name>/s<seed>`` (reused when it is already
    there with the same frame count and ground truth: rendering is deterministic; one rendered by an older version,
    e.g. before scene seeds drew new plaza sequences, is rendered again and its cached masks are removed). Under
    ``conditions`` (comma-separated, :mod:`wptrack.synth.conditions`) into ``scenes_dir/<name>+<cond>+.../s<seed>``."""
    import logging
    import shutil

    from wptrack.synth import render_scene
    from wptrack.synth.base import SceneResult, _groundtruth_csv, get_scene
    from wptrack.synth.conditions import parse_conditions

    cond = parse_conditions(conditions)
    out = scenes_dir / "+".join([name, *cond.names]) / f"s{seed}"
    meta = out / "scene.json"
    if meta.exists():
        hints = json.loads(meta.read_text())
        if hints.get("scene") == name and hints.get("seed") == seed and (frames is None or hints["frames"] == frames):
            spec = get_scene(name)
            scene = spec.build(seed) if spec.seeded else spec.build()
            if cond.any:
                scene = scene.with_conditions(cond)
            n = int(hints["frames"])
            gt = out / "groundtruth.csv"
            if gt.exists() and gt.read_text() == _groundtruth_csv(scene.trajectories(n), scene.groundtruth_columns(n)):
                cams = hints["cameras"]
                return SceneResult(
                    out_dir=out,
                    rig_path=out / "rig.yaml",
                    videos=[out / v for v in hints["videos"]],
                    groundtruth_path=out / "groundtruth.csv",
                    scene_json=meta,
                    frames=int(hints["frames"]),
                    mask_videos=[out / f"{c}_mask.avi" for c in cams],
                )
            logging.getLogger(__name__).warning("%s: stale scene (its ground truth changed), rendered again", out)
            for old in out.glob("masks-*"):
                if old.is_dir():
                    shutil.rmtree(old)
    return render_scene(name, out, frames=frames, seed=seed, progress=progress, conditions=cond if cond.any else None)


def _s3_masks(res, masks: str, mask_config) -> Path:
    """The motion-mask video of a rendered scene: its perfect silhouettes, or masks made once from its video by
    ``wptrack.motion.masks`` (``masks`` = ``"offline"``: the default pipeline; ``"mog2"``) and cached next to it
    (made again when their ``masks.json`` records another configuration or another :func:`pipeline_hash`)."""
    from dataclasses import replace

    from wptrack.motion.masks import MaskConfig
    from wptrack.motion.writing import pipeline_hash, write_masks

    if masks == "perfect":
        return Path(res.mask_videos[0])
    cfg = mask_config if mask_config is not None else MaskConfig()
    cfg = replace(cfg, method=masks)
    out = Path(res.out_dir) / f"masks-{masks}"
    summary = out / "masks.json"
    if summary.exists():
        cached = json.loads(summary.read_text())
        # the same configuration *and* the same pipeline code (a changed kernel with the same fields made stale masks)
        if cached.get("config") == json.loads(json.dumps(asdict(cfg))) and cached.get("code") == pipeline_hash():
            return out / "masks.avi"
    write_masks(str(res.videos[0]), out, config=cfg)
    return out / "masks.avi"


def _template_run(task: dict) -> dict:
    """One run of :func:`template_accuracy` (a worker process may run it): track, evaluate, return the row."""
    from wptrack.evaluation.mot import evaluate
    from wptrack.trackers.templates.run import run_template_tracking
    from wptrack.trackers.templates.tracker import TemplateConfig

    cfg = TemplateConfig(**task["config"])
    run_template_tracking(
        task["rig"],
        task["run_dir"],
        cfg,
        video=task["video"],
        masks=task["masks"],
        device=task["device"],
        virtual=False,
        progress=task["progress"],
        overwrite=True,  # the experiment's own run folder: running the experiment again replaces it
    )
    return evaluate(task["groundtruth"], Path(task["run_dir"]) / "tracks.csv", threshold=1.0).to_dict()


def _template_scene(task: dict) -> tuple[str, str, str, str, str]:
    """Render one scene and make its masks (a worker process may run it): rig, video, masks, ground truth, hints."""
    res = _s3_scene(
        task["name"], Path(task["cache"]), task["frames"], task["scene_seed"], task["progress"], task.get("conditions")
    )
    mask_video = _s3_masks(res, task["masks"], task["mask_config"])
    return str(res.rig_path), str(res.videos[0]), str(mask_video), str(res.groundtruth_path), str(res.scene_json)


def _pool_map(fn, tasks: list, workers: int) -> list:
    """``[fn(t) for t in tasks]``, in ``workers`` spawned processes when more than one (results in task order)."""
    if workers <= 1 or len(tasks) <= 1:
        return [fn(t) for t in tasks]
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("spawn")  # no forked Warp/CUDA state in the workers
    with ProcessPoolExecutor(max_workers=min(workers, len(tasks)), mp_context=ctx) as pool:
        return list(pool.map(fn, tasks))


def template_accuracy(
    scenes: Sequence[str] = S3_SCENES,
    seeds: int | Sequence[int] = 6,
    out_dir: str | Path = "s3-accuracy",
    frames: int | None = None,
    particles: int = 1000,
    masks: str = "offline",
    device: str = "auto",
    progress: bool = False,
    config_overrides: dict | None = None,
    mask_config=None,
    scene_seeds: Sequence[int] = (0,),
    scenes_dir: str | Path | None = None,
    workers: int = 1,
    conditions: str | None = None,
) -> dict:
    """Section 5 of Juza et al.: run every scene ``seeds`` times with different tracker seeds, evaluate each run
    against the ground truth (paper accuracy, MOTA, IDF1 at 1 m) and average, as the paper does.

    Each scene is rendered once per scene seed into ``scenes_dir/<scene>/s<scene seed>`` (reused when present), its
    motion masks made once next to it (``masks-<method>/masks.avi``); runs go to
    ``out_dir/<scene>/s<scene seed>/seed<k>``. Writes ``out_dir/accuracy.json`` (per run, and averaged over all
    runs of a scene: every scene seed x tracker seed) and ``out_dir/accuracy.csv`` (one row per scene: mean and
    minimum over the runs).

    Args:
        scenes: registered s3 scene names.
        seeds: tracker seeds: a count k (seeds 0..k-1) or the seeds themselves.
        out_dir: output folder.
        frames: frames per scene (default: the scene's own).
        particles: N.
        masks: ``"offline"`` (the default pipeline of ``wptrack.motion.masks`` on the rendered video), ``"mog2"``
        (OpenCV
            background subtraction) or ``"perfect"`` (the scene's silhouettes).
        device: ``auto``, ``cpu``, ``cuda``...
        progress: tqdm progress bars.
        config_overrides: extra ``TemplateConfig`` fields.
        mask_config: ``wptrack.motion.masks.MaskConfig`` of the mask pipeline (default: its defaults; ``method`` is set
            from ``masks``).
        scene_seeds: scene seeds rendered per scene (``render_scene(seed=...)``).
        scenes_dir: where scenes and their masks are rendered and cached (default: ``out_dir``).
        workers: processes that render the scenes and run the tracker side by side (1: all in this process). Every
            run is independent and seeded, so the results do not depend on it. The workers are spawned (they import
            the calling script): from a script, call this under ``if __name__ == "__main__":``.
        conditions: hard conditions every scene is rendered under (comma-separated names of
            :mod:`wptrack.synth.conditions`, e.g. ``"crowd"``; default: none); the scene folders are then
            ``scenes_dir/<scene>+<condition>.../s<scene seed>``.

    Returns:
        ``{"scenes": {name: {"runs": [...], "average": {...}}}, ...}``.
    """
    from types import SimpleNamespace

    from wptrack.evaluation.mot import average

    if masks not in S3_MASKS:
        raise ConfigError(f"masks: expected one of {', '.join(repr(m) for m in S3_MASKS)}, got {masks!r}")
    if isinstance(seeds, (int, np.integer)) and not isinstance(seeds, bool):
        if seeds < 1:
            raise ConfigError(f"seeds: expected a positive integer or a list of seeds, got {seeds!r}")
        tracker_seeds = list(range(int(seeds)))
    else:
        try:
            tracker_seeds = [int(s) for s in seeds]  # type: ignore[union-attr]
        except (TypeError, ValueError):
            raise ConfigError(f"seeds: expected a positive integer or a list of seeds, got {seeds!r}") from None
        if not tracker_seeds or any(s < 0 for s in tracker_seeds):
            raise ConfigError(f"seeds: expected non-negative tracker seeds, got {seeds!r}")
    scene_seeds = [int(s) for s in scene_seeds]
    if not scene_seeds or any(s < 0 for s in scene_seeds):
        raise ConfigError(f"scene_seeds: expected non-negative scene seeds, got {scene_seeds!r}")
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise ConfigError(f"workers: expected a positive integer, got {workers!r}")
    out = ensure_writable_dir(out_dir)
    cache = ensure_writable_dir(scenes_dir if scenes_dir is not None else out)
    device = resolve_device(device)
    table: dict = {
        "masks": masks,
        "particles": particles,
        "seeds": tracker_seeds,
        "scene_seeds": scene_seeds,
        "device": device,
        "config_overrides": {k: repr(v) for k, v in (config_overrides or {}).items()},
        "scenes": {},
    }
    rows = [
        "scene,runs,accuracy,accuracy_min,tracking,classification,mota,mota_min,idf1,idf1_min,"
        "id_switches,id_switches_max"
    ]
    keys = [(name, ss) for name in scenes for ss in scene_seeds]
    rendered = _pool_map(
        _template_scene,
        [
            {"name": name, "cache": str(cache), "frames": frames, "scene_seed": ss, "progress": progress,
             "masks": masks, "mask_config": mask_config, "conditions": conditions}
            for name, ss in keys
        ],
        workers,
    )  # fmt: skip
    tasks, labels = [], []
    for (name, scene_seed), (rig, video, mask_video, gt, scene_json) in zip(keys, rendered, strict=True):
        hints = json.loads(Path(scene_json).read_text())
        for seed in tracker_seeds:
            config = {
                "particles": particles,
                "seed": seed,
                "fps": float(hints.get("fps", 15.0)),
                **(config_overrides or {}),
            }
            run_dir = out / name / f"s{scene_seed}" / f"seed{seed}"
            tasks.append({"rig": rig, "run_dir": str(run_dir), "config": config, "video": video, "masks": mask_video,
                          "device": device, "progress": progress, "groundtruth": gt})  # fmt: skip
            labels.append((name, {"scene_seed": scene_seed, "seed": seed}))
    results = _pool_map(_template_run, tasks, workers)
    for name in scenes:
        mine = [(lab, r) for (n, lab), r in zip(labels, results, strict=True) if n == name]
        avg = average([SimpleNamespace(**r) for _, r in mine])  # the evaluations' dicts (from the workers)
        table["scenes"][name] = {"runs": [lab | r for lab, r in mine], "average": avg}

        def m(key: str, stat: str = "mean", avg=avg) -> float:
            v = avg.get(key, {}).get(stat)
            return float("nan") if v is None else float(v)

        rows.append(
            f"{name},{len(mine)},{m('accuracy'):.3f},{m('accuracy', 'min'):.3f},{m('tracking_accuracy'):.3f},"
            f"{m('classification_accuracy'):.3f},{m('mota'):.3f},{m('mota', 'min'):.3f},{m('idf1'):.3f},"
            f"{m('idf1', 'min'):.3f},{m('id_switches'):.1f},{m('id_switches', 'max'):.0f}"
        )
    atomic_write_json(out / "accuracy.json", table)
    atomic_write_text(out / "accuracy.csv", "\n".join(rows) + "\n")
    return table
