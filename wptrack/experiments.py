"""Reproduction of the filter-dynamics experiments of the extended Barrera et al. paper (section III.C):
error vs iteration when the object jumps (Fig. 6) and the sigma_m sweep (Fig. 7)."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .device import resolve_device
from .errors import ConfigError
from .io import atomic_write_json, atomic_write_text, ensure_writable_dir
from .metrics import convergence_frame
from .trackers.gaussian3d import Gaussian3DTracker

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
    truth = jump_trajectory(iterations, jump_at, jump)
    errors = np.zeros((len(sigmas), runs, iterations))
    from tqdm import tqdm

    bar = tqdm(total=len(sigmas) * runs, desc="sigma sweep", disable=not progress, leave=False)
    for si, sigma in enumerate(sigmas):
        for r in range(runs):
            box = (truth[0] - init_spread, truth[0] + init_spread)
            pf = Gaussian3DTracker(
                particles=particles,
                sigma=float(sigma),
                sigma_obs=sigma_obs,
                init=None,
                init_box=box,
                device=device,
                seed=seed + 1000 * r + si,
            )
            for k in range(iterations):
                est = pf.step(truth[k])
                errors[si, r, k] = np.linalg.norm(est.mean - truth[k])
            bar.update(1)
    bar.close()
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
