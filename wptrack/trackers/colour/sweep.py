"""The files of the sigma_m sweep (extended paper, section III.C, Fig. 7): ``errors.csv`` (sigma, iteration, mean
error and its deviation, metres) and ``summary.json``, written by ``wptrack convergence`` and read by the report."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from wptrack.io.atomic import atomic_write_json, atomic_write_text, ensure_writable_dir


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
