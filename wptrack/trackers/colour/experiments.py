"""Reproduction of the filter-dynamics experiments of the extended Barrera et al. paper (section III.C):
error vs iteration when the object jumps (Fig. 6) and the sigma_m sweep (Fig. 7)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from wptrack.core.device import resolve_device
from wptrack.core.errors import ConfigError
from wptrack.evaluation.convergence import convergence_frame
from wptrack.io.atomic import ensure_writable_dir
from wptrack.trackers.colour.gaussian3d import Gaussian3DTracker
from wptrack.trackers.colour.sweep import write_sweep

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
    from wptrack.batch import check_ray_address, run_batch
    from wptrack.batch.manifest import Manifest, RunSpec

    if len(sigmas) == 0:
        raise ConfigError("sigma: give at least one value")
    if any(not (s > 0) for s in sigmas):
        raise ConfigError(f"sigma: values must be > 0 metres, got {list(sigmas)}")
    if not (0 < jump_at < iterations):
        raise ConfigError(f"jump_at: expected 0 < jump_at < iterations ({iterations}), got {jump_at}")
    check_ray_address(address)  # a Ray head that does not answer: said before the sweep's folder is made
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
