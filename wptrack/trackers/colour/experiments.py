"""Reproduction of the filter-dynamics experiments of the extended Barrera et al. paper (section III.C):
error vs iteration when the object jumps (Fig. 6) and the sigma_m sweep (Fig. 7)."""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from wptrack.core.device import resolve_device
from wptrack.core.errors import ConfigError
from wptrack.evaluation.convergence import convergence_frame
from wptrack.io.atomic import atomic_write_json, atomic_write_text, ensure_writable_dir
from wptrack.trackers.colour.gaussian3d import Gaussian3DTracker

JUMP_DIRECTION = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
"""Direction of the jump (horizontal, diagonal): any fixed direction gives the same statistics."""


def default_sigmas(steps: int = 12) -> np.ndarray:
    """The paper's Fig. 7 sweep: sigma_m from 0.001 m to 0.3 m at regular increments."""
    return np.round(np.linspace(0.001, 0.3, steps), 4)


def jump_trajectory(iterations: int, jump_at: int, jump: float, start=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Object positions (iterations, 3), metres: at ``start`` until ``jump_at``, then ``jump`` metres away."""
    start = np.asarray(start, dtype=np.float64)
    traj = np.tile(start, (iterations, 1))
    traj[jump_at:] += jump * JUMP_DIRECTION
    return traj


def jump_experiment(
    sigmas: Sequence[float],
    particles: int = 200,
    iterations: int = 100,
    jump_at: int = 30,
    jump: float = 2.0,
    sigma_obs: float = 0.05,
    runs: int = 10,
    seed: int = 0,
    device: str = "auto",
    init_spread: float = 1.0,
    tol: float = 0.05,
    hold: int = 5,
    progress: bool = False,
) -> dict:
    """Error of the MMSE estimate vs iteration for each sigma_m, averaged over ``runs`` seeds.

    As in the paper, the observations are the object's true 3D position (no noise), scored by a 3D gaussian
    model (``sigma_obs``); particles start uniform in a cube of half-side ``init_spread`` metres around the
    object. The object jumps ``jump`` metres at iteration ``jump_at``.

    Returns:
        ``{"sigmas": (S,), "errors": (S, iterations) mean error in metres, "std": (S, iterations),
        "summary": [per sigma: iterations to converge initially and after the jump (error < tol for hold
        iterations)]}``.
    """
    if len(sigmas) == 0:
        raise ConfigError("sigma: give at least one value")
    if any(not (s > 0) for s in sigmas):
        raise ConfigError(f"sigma: values must be > 0 metres, got {list(sigmas)}")
    if not (0 < jump_at < iterations):
        raise ConfigError(f"jump_at: expected 0 < jump_at < iterations ({iterations}), got {jump_at}")
    device = resolve_device(device)
    errors = np.zeros((len(sigmas), runs, iterations))
    from tqdm import tqdm

    bar = tqdm(total=len(sigmas) * runs, desc="sigma sweep", disable=not progress, leave=False)
    for si, sigma in enumerate(sigmas):
        for r in range(runs):
            errors[si, r] = jump_run(
                sigma, sweep_seed(seed, si, r), particles, iterations, jump_at, jump, sigma_obs, device, init_spread
            )
            bar.update(1)
    bar.close()
    return sweep_table(sigmas, errors, particles, iterations, jump_at, jump, sigma_obs, runs, seed, device,
                       init_spread, tol, hold)  # fmt: skip


def sweep_seed(seed: int, sigma_index: int, run: int) -> int:
    """Tracker seed of run ``run`` of the ``sigma_index``-th sigma_m of a sweep started with ``seed``."""
    return seed + 1000 * run + sigma_index


def jump_run(
    sigma: float,
    seed: int,
    particles: int = 200,
    iterations: int = 100,
    jump_at: int = 30,
    jump: float = 2.0,
    sigma_obs: float = 0.05,
    device: str = "auto",
    init_spread: float = 1.0,
) -> np.ndarray:
    """One run of the jump experiment: error of the MMSE estimate per iteration (iterations,), metres."""
    truth = jump_trajectory(iterations, jump_at, jump)
    box = (truth[0] - init_spread, truth[0] + init_spread)
    pf = Gaussian3DTracker(
        particles=particles,
        sigma=float(sigma),
        sigma_obs=sigma_obs,
        init=None,
        init_box=box,
        device=resolve_device(device),
        seed=seed,
    )
    errors = np.zeros(iterations)
    for k in range(iterations):
        est = pf.step(truth[k])
        errors[k] = np.linalg.norm(est.mean - truth[k])
    return errors


def sweep_table(sigmas, errors, particles, iterations, jump_at, jump, sigma_obs, runs, seed, device, init_spread,
                tol, hold) -> dict:  # fmt: skip
    """The table of :func:`jump_experiment` from the errors of every run (S, runs, iterations), metres."""
    mean = errors.mean(axis=1)
    summary = []
    for si, sigma in enumerate(sigmas):
        c0 = convergence_frame(mean[si, :jump_at], tol, hold)
        c1 = convergence_frame(mean[si], tol, hold, start=jump_at)
        summary.append(
            {"sigma": float(sigma), "converge_initial": c0, "converge_after_jump": None if c1 is None else c1 - jump_at}
        )
    return {
        "sigmas": np.asarray(sigmas, dtype=np.float64),
        "errors": mean,
        "std": errors.std(axis=1),
        "summary": summary,
        "params": {
            "particles": particles,
            "iterations": iterations,
            "jump_at": jump_at,
            "jump": jump,
            "sigma_obs": sigma_obs,
            "runs": runs,
            "seed": seed,
            "device": device,
            "init_spread": init_spread,
            "tol": tol,
            "hold": hold,
        },
    }


def write_sweep(table: dict, out_dir) -> Path:
    """Write ``errors.csv`` (sigma, iteration, mean error, std; metres) and ``summary.json``."""
    out = ensure_writable_dir(out_dir)
    lines = ["sigma,iteration,error_mean,error_std"]
    for si, sigma in enumerate(table["sigmas"]):
        for k, (e, s) in enumerate(zip(table["errors"][si], table["std"][si], strict=True)):
            lines.append(f"{sigma:.6g},{k},{e:.6f},{s:.6f}")
    path = out / "errors.csv"
    atomic_write_text(path, "\n".join(lines) + "\n")
    atomic_write_json(out / "summary.json", {"params": table["params"], "summary": table["summary"]})
    return path


def read_sweep(path) -> dict:
    """Read ``errors.csv`` back into ``{"sigmas": (S,), "errors": (S, I)}``."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    sigmas = sorted({float(r["sigma"]) for r in rows})
    iters = max(int(r["iteration"]) for r in rows) + 1
    errors = np.zeros((len(sigmas), iters))
    for r in rows:
        errors[sigmas.index(float(r["sigma"])), int(r["iteration"])] = float(r["error_mean"])
    return {"sigmas": np.asarray(sigmas), "errors": errors}


def jump_task(out_dir, sigma: float, seed: int, **kw) -> dict:
    """One run of the jump experiment as a batch run (``tracker: function``): ``errors.npy`` (iterations,) metres.

    ``kw``: the other arguments of :func:`jump_run`."""
    errors = jump_run(sigma, seed, **kw)
    np.save(Path(out_dir) / "errors.npy", errors)
    return {"frames": int(errors.size), "sigma": float(sigma), "seed": int(seed), "final_error": float(errors[-1])}


def sweep_batch(
    out_dir,
    sigmas: Sequence[float],
    particles: int = 200,
    iterations: int = 100,
    jump_at: int = 30,
    jump: float = 2.0,
    sigma_obs: float = 0.05,
    runs: int = 10,
    seed: int = 0,
    device: str = "auto",
    init_spread: float = 1.0,
    tol: float = 0.05,
    hold: int = 5,
    address: str = "inline",
    retries: int | None = None,
    on_result=None,
) -> dict:
    """:func:`jump_experiment` as a batch (:mod:`wptrack.batch`): one run per (sigma_m, seed) into
    ``out_dir/runs/<id>/`` (with ``out_dir/runs/summary.csv``), spread over Ray workers with ``address`` (``local``,
    ``auto``, a cluster) or run here (``inline``). The table is the same as :func:`jump_experiment`'s (the same
    seeds) and is written with :func:`write_sweep` (``out_dir/errors.csv``, ``summary.json``). Completed runs are
    reused when the sweep is run again.
    """
    from wptrack.batch import Manifest, RunSpec, run_batch

    if len(sigmas) == 0:
        raise ConfigError("sigma: give at least one value")
    if any(not (s > 0) for s in sigmas):
        raise ConfigError(f"sigma: values must be > 0 metres, got {list(sigmas)}")
    if not (0 < jump_at < iterations):
        raise ConfigError(f"jump_at: expected 0 < jump_at < iterations ({iterations}), got {jump_at}")
    out = ensure_writable_dir(out_dir)
    device = resolve_device(device)  # resolved here: every run on the same device
    common = {"particles": particles, "iterations": iterations, "jump_at": jump_at, "jump": jump,
              "sigma_obs": sigma_obs, "device": device, "init_spread": init_spread}  # fmt: skip
    specs = []
    for si, sigma in enumerate(sigmas):
        for r in range(runs):
            s = sweep_seed(seed, si, r)
            params = {"sigma": float(sigma), "seed": s}
            specs.append(RunSpec(f"sigma{float(sigma):g}-seed{s}", "function", {**common, **params}, JUMP_TASK, params))
    results = run_batch(Manifest(out / "sweep.yaml", tuple(specs)), out / "runs", address=address,
                        gpus_per_task=0, retries=retries, on_result=on_result)  # fmt: skip
    failed = [r["id"] for r in results if r["status"] != "complete"]
    if failed:
        raise RuntimeError(f"sweep: {len(failed)} run(s) failed ({', '.join(failed[:5])}); see {out / 'runs'}")
    errors = np.stack([np.load(out / "runs" / spec.id / "errors.npy") for spec in specs])
    errors = errors.reshape(len(sigmas), runs, iterations)
    table = sweep_table(sigmas, errors, particles, iterations, jump_at, jump, sigma_obs, runs, seed, device,
                        init_spread, tol, hold)  # fmt: skip
    write_sweep(table, out)
    return table


JUMP_TASK = f"{__name__}:jump_task"


def drift_study(
    scene_dir,
    camera: int = 0,
    depths: Sequence[float] = (-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.5),
    sigma: float = 0.03,
    samples: int = 20000,
    frame_index: int = 0,
    device: str = "auto",
    seed: int = 0,
) -> list[dict]:
    """The systematic drift along a camera's optical ray (Barrera et al., section III, Fig. 5), measured.

    Points are placed on the ray from ``camera`` through the ball (ground truth of frame ``frame_index``) at
    ``depth`` metres beyond the ball (negative: nearer the camera). For each point the observation model of eqs.
    5-7 is evaluated per camera on the real frame, and ``samples`` gaussian moves N(0, sigma) of the point are
    scored: among moves that keep the point's likelihood in ``camera`` (window count m > 1), how many went further
    from the camera than closer. Far from the other cameras' views only ``camera`` rewards a particle, and a move
    towards the camera leaves the (narrowing) cone of the ball's image more often than a move away from it; the
    cloud then drifts away from the camera.

    Returns:
        One dict per depth: ``depth`` (m), ``loglik`` per camera (log p_c at the point), ``keep_further`` and
        ``keep_closer`` (fractions of moves that stay on the ball's image in ``camera``), ``bias`` (mean depth
        change of the moves that stay, metres: > 0 means drift away from the camera).
    """
    import warp as wp

    from wptrack.cameras.rig import Rig
    from wptrack.cameras.structs import DeviceRig
    from wptrack.io.frames import open_frames
    from wptrack.io.tables import read_tracks
    from wptrack.kernels.colour import scoring as kscoring
    from wptrack.trackers.colour.tracker import HSITarget

    scene_dir = Path(scene_dir)
    meta = json.loads((scene_dir / "scene.json").read_text())
    rig = Rig.load(scene_dir / "rig.yaml")
    gt = read_tracks(scene_dir / "groundtruth.csv")
    ball = np.array([gt["x"][frame_index], gt["y"][frame_index], gt["z"][frame_index]])
    frames = iter(open_frames([str(scene_dir / v) for v in meta["videos"]], max_frames=frame_index + 1))
    for _ in range(frame_index + 1):
        images = next(frames)
    device = resolve_device(device)
    t = meta["target"]
    target = HSITarget(hue=tuple(t["hue"]), sat=tuple(t["sat"]), intensity=tuple(t["intensity"])).to_struct(device)
    drig = DeviceRig(rig, device)
    bgr = wp.array(np.concatenate([im.reshape(-1) for im in images]), dtype=wp.uint8, device=device)
    dummy = wp.zeros(1, dtype=wp.int32, device=device)
    dummy8 = wp.zeros(1, dtype=wp.uint8, device=device)
    centre = rig[camera].center
    ray = (ball - centre) / np.linalg.norm(ball - centre)
    rng = np.random.default_rng(seed)
    rows = []
    for depth in depths:
        p = ball + depth * ray
        pts = np.concatenate([p[None], p + rng.normal(0.0, sigma, (samples, 3))]).astype(np.float32)
        counts = wp.zeros((len(rig), len(pts)), dtype=wp.int32, device=device)
        wp.launch(
            kscoring.window_count_kernel,
            dim=(len(rig), len(pts)),
            inputs=[
                drig.cams,
                target,
                bgr,
                dummy,
                dummy8,
                kscoring.SCORE_DIRECT,
                wp.array(pts, dtype=wp.vec3, device=device),
            ],
            outputs=[counts],
            device=device,
        )
        c = counts.numpy()
        loglik = [float(np.log(max(int(m), 1) / 25.0)) for m in c[:, 0]]
        moves = pts[1:] - p
        along = moves @ ray
        keep = c[camera, 1:] > 1
        rows.append(
            {
                "depth": float(depth),
                "loglik": loglik,
                "keep_further": float(keep[along > 0].mean()),
                "keep_closer": float(keep[along < 0].mean()),
                "bias": float(along[keep].mean()) if keep.any() else float("nan"),
            }
        )
    return rows


# --- S3: accuracy of the template tracker on the synthetic scene types (paper Table 2) ---------------------------
S3_SCENES: tuple[str, ...] = ("s3-people", "s3-cars", "s3-groups", "s3-mixed")


S3_MASKS: tuple[str, ...] = ("offline", "mog2", "perfect")
"""Motion masks of :func:`template_accuracy`: the default pipeline (offline background model), OpenCV MOG2, or the
scene's perfect silhouettes."""


def _s3_scene(name: str, scenes_dir: Path, frames: int | None, seed: int, progress: bool):
    """Render scene ``name`` with scene seed ``seed`` into ``scenes_dir/<name>/s<seed>`` (reused when it is already
    there with the same frame count and ground truth: rendering is deterministic; one rendered by an older version,
    e.g. before scene seeds drew new plaza sequences, is rendered again and its cached masks are removed)."""
    import logging
    import shutil

    from wptrack.synth import render_scene
    from wptrack.synth.base import SceneResult, _groundtruth_csv, get_scene

    out = scenes_dir / name / f"s{seed}"
    meta = out / "scene.json"
    if meta.exists():
        hints = json.loads(meta.read_text())
        if hints.get("scene") == name and hints.get("seed") == seed and (frames is None or hints["frames"] == frames):
            spec = get_scene(name)
            scene = spec.build(seed) if spec.seeded else spec.build()
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
    return render_scene(name, out, frames=frames, seed=seed, progress=progress)


def _s3_masks(res, masks: str, mask_config) -> Path:
    """The motion-mask video of a rendered scene: its perfect silhouettes, or masks made once from its video by
    ``wptrack.motion.masks`` (``masks`` = ``"offline"``: the default pipeline; ``"mog2"``) and cached next to it."""
    from dataclasses import replace

    from wptrack.motion.masks import MaskConfig, write_masks

    if masks == "perfect":
        return Path(res.mask_videos[0])
    cfg = mask_config if mask_config is not None else MaskConfig()
    cfg = replace(cfg, method=masks)
    out = Path(res.out_dir) / f"masks-{masks}"
    summary = out / "masks.json"
    if summary.exists() and json.loads(summary.read_text()).get("config") == json.loads(json.dumps(asdict(cfg))):
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
    res = _s3_scene(task["name"], Path(task["cache"]), task["frames"], task["scene_seed"], task["progress"])
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
             "masks": masks, "mask_config": mask_config}
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
                "max_objects": max(8, int(hints.get("max_objects", 8)) + 3),
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
