"""2D plots with matplotlib (imported lazily, Agg canvas, no pyplot state): bird's-eye view of the particle clouds
over time (S1 Fig. 4), error vs frame (S1 Fig. 6), the sigma_m sweep heatmap (S1 Fig. 7) and per-stage timings."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.report.model import Figure, ReportContext, Section
from wptrack.report.scene3d import TRUTH_RGB, estimate_rgb, up_axis

log = logging.getLogger(__name__)

AXES = "xyz"
MAX_BIRDSEYE_POINTS = 30000
"""At most this many particles drawn in the bird's-eye view (display subsample over all frames)."""


def _figure(width: float, height: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure as MplFigure

    fig = MplFigure(figsize=(width, height), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Any, path: Path) -> None:
    fig.savefig(path, format="png", facecolor="white")


def _c(rgb: tuple[int, int, int]) -> tuple[float, float, float]:
    return (rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0)


# -------------------------------------------------------------------------------------------- bird's-eye view


def section_birdseye(ctx: ReportContext) -> Section | None:
    """Particle clouds of every saved frame seen from above, coloured by frame (S1 Fig. 4); the trajectories alone
    for a run without particles."""
    data = ctx.data
    if data is None:
        return None
    if data.particles is not None:
        sec = Section(
            "birdseye",
            "Bird's-eye view of the particle cloud over time",
            text="The saved particles of every frame seen from above (colour: frame number), the estimated "
            "trajectory (orange), the ground truth (green) and the camera centres (navy triangles).",
        )
        caption = "Particle clouds over time, seen from above"
    else:  # a run that saves no particles (the people tracker), or whose particles.npz is gone
        sec = Section(
            "birdseye",
            "Bird's-eye view of the trajectories",
            text="The estimated trajectories seen from above (one colour per track), the ground truth (green) and "
            "the camera centres (navy triangles).",
        )
        caption = "Trajectories seen from above"
        if (data.run.get("files") or {}).get("particles"):
            sec.notes.append("particles.npz is missing: only the trajectories are shown")
    with ctx.timed("plots"):
        path = ctx.out_dir / "birdseye.png"
        birdseye_plot(data, path)
        sec.figures.append(Figure(path.name, caption))
    return sec


def birdseye_plot(data: Any, path: Path) -> None:
    """Write the bird's-eye PNG (the two horizontal axes of the rig's up axis)."""
    up = up_axis(data.rig)
    a, b = [k for k in range(3) if k != up]
    fig = _figure(7.5, 6.0)
    ax = fig.add_subplot()
    if data.particles is not None:
        p = data.particles
        f_idx = np.repeat(p.frames, p.positions.shape[1])
        pos = p.positions.reshape(-1, 3)
        ok = np.all(np.isfinite(pos), axis=1)
        pos, f_idx = pos[ok], f_idx[ok]
        if len(pos) > MAX_BIRDSEYE_POINTS:
            sel = (np.arange(MAX_BIRDSEYE_POINTS) * len(pos)) // MAX_BIRDSEYE_POINTS
            pos, f_idx = pos[sel], f_idx[sel]
        sc = ax.scatter(pos[:, a], pos[:, b], c=f_idx, s=2, cmap="plasma", alpha=0.35, linewidths=0, rasterized=True)
        fig.colorbar(sc, ax=ax, label="frame")
    for traj in (data.groundtruth or {}).values():
        ax.plot(traj.xyz[:, a], traj.xyz[:, b], "-", color=_c(TRUTH_RGB), lw=2, label=f"ground truth {traj.id}")
    for k, traj in enumerate(data.estimates.values()):
        ax.plot(traj.xyz[:, a], traj.xyz[:, b], "-", color=_c(estimate_rgb(k)), lw=1.5, label=f"estimate {traj.id}")
    if data.rig is not None:
        for cam in data.rig.cameras:
            c = cam.center
            d = np.asarray(cam.R)[2]
            ax.plot(c[a], c[b], "^", color="navy", ms=8)
            ax.annotate(cam.name, (c[a], c[b]), textcoords="offset points", xytext=(5, 5), color="navy")
            ax.arrow(c[a], c[b], 0.08 * d[a], 0.08 * d[b], color="navy", width=0.002, length_includes_head=True)
    ax.set_xlabel(f"{AXES[a]} (m)")
    ax.set_ylabel(f"{AXES[b]} (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    _save(fig, path)


# -------------------------------------------------------------------------------------------- error vs frame


def section_errors(ctx: ReportContext) -> Section | None:
    """Error vs frame against ground truth (S1 Fig. 6), the particle spread and the effective sample size."""
    data = ctx.data
    if data is None:
        return None
    sec = Section(
        "errors",
        "Error vs frame",
        text="Distance between the estimate and the ground truth per frame, the cloud's spread (norm of the "
        "per-axis standard deviations) and the effective sample size.",
    )
    err = (data.run.get("summary") or {}).get("error") if isinstance(data.run.get("summary"), dict) else None
    if isinstance(err, dict):
        sec.table = [(k.replace("_", " "), _fmt_metric(k, v)) for k, v in err.items()]
    if not data.groundtruth:
        sec.notes.append("no ground truth: the error panel is left out")
    with ctx.timed("plots"):
        path = ctx.out_dir / "error_vs_frame.png"
        error_plot(data, path, err)
        sec.figures.append(Figure(path.name, "Error, spread and ESS vs frame"))
    return sec


def _fmt_metric(key: str, value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float) and ("error" in key):
        return f"{100 * value:.2f} cm"
    return str(value)


def error_per_frame(data: Any) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """``{object id: (frames, error in metres)}`` for the estimates that have ground truth."""
    out = {}
    for obj, traj in data.estimates.items():
        gt = data.matched_truth(obj)
        if gt is None:
            continue
        truth = gt.at(traj.frames)
        e = np.linalg.norm(traj.xyz - truth, axis=1)
        ok = np.isfinite(e)
        if ok.any():
            out[obj] = (traj.frames[ok], e[ok])
    return out


def error_plot(data: Any, path: Path, summary: dict | None = None) -> None:
    """Write the error / spread / ESS figure."""
    errors = error_per_frame(data)
    t = data.tracks
    n_panels = 2 + (1 if errors else 0)
    fig = _figure(8.0, 2.3 * n_panels)
    axes = fig.subplots(n_panels, 1, sharex=True)
    i = 0
    if errors:
        ax = axes[0]
        for k, (obj, (frames, e)) in enumerate(errors.items()):
            ax.plot(frames, 100 * e, color=_c(estimate_rgb(k)), lw=1.5, label=f"object {obj}")
        conv = (summary or {}).get("converged_at")
        if conv is not None:
            ax.axvline(conv, color="gray", ls="--", lw=1, label=f"converged (frame {conv})")
        ax.set_ylabel("error (cm)")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        i = 1
    ax = axes[i]
    if all(c in t for c in ("sx", "sy", "sz")):
        for k, obj in enumerate(data.estimates):
            sel = t["id"] == obj
            spread = np.sqrt(t["sx"][sel] ** 2 + t["sy"][sel] ** 2 + t["sz"][sel] ** 2)
            ax.plot(t["frame"][sel], 100 * spread, color=_c(estimate_rgb(k)), lw=1.2, label=f"object {obj}")
        ax.set_ylim(bottom=0)
    ax.set_ylabel("spread (cm)")
    ax.grid(True, alpha=0.3)
    ax = axes[i + 1]
    if "ess" in t:
        n = ((data.config.get("tracker") or {}).get("particles")) if isinstance(data.config, dict) else None
        for k, obj in enumerate(data.estimates):
            sel = t["id"] == obj
            ess = t["ess"][sel] / n if n else t["ess"][sel]
            ax.plot(t["frame"][sel], ess, color=_c(estimate_rgb(k)), lw=1.0)
        ax.set_ylabel("ESS / N" if n else "ESS")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("frame")
    _save(fig, path)


# -------------------------------------------------------------------------------------------- timings


def section_timings(ctx: ReportContext) -> Section | None:
    """Per-stage time per frame (median and mean over the run) from run.json."""
    data = ctx.data
    if data is None:
        return None
    sec = Section(
        "timings",
        "Time per frame, per stage",
        text="Median and mean wall time per frame of each stage of the tracking run (run.json holds per-stage "
        "aggregates, not per-frame samples).",
    )
    timings = data.run.get("timings") or {}
    stages = {k: v for k, v in timings.items() if isinstance(v, dict) and "median_ms" in v}
    if not stages:
        sec.notes.append("run.json holds no timings")
        return sec
    sec.table = [
        (
            k,
            f"median {v['median_ms']:.2f} ms, mean {v.get('mean_ms', float('nan')):.2f} ms, "
            f"total {v.get('total_s', float('nan')):.2f} s over {v.get('count', '?')} frames",
        )
        for k, v in stages.items()
    ]
    with ctx.timed("plots"):
        path = ctx.out_dir / "timings.png"
        timing_plot(stages, path)
        sec.figures.append(Figure(path.name, "Per-stage time per frame"))
    return sec


def timing_plot(stages: dict[str, dict], path: Path) -> None:
    """Horizontal bars: median and mean milliseconds per frame of each stage."""
    names = list(stages)
    med = np.array([float(stages[s]["median_ms"]) for s in names])
    mean = np.array([float(stages[s].get("mean_ms", np.nan)) for s in names])
    fig = _figure(7.0, 0.6 * len(names) + 1.4)
    ax = fig.add_subplot()
    y = np.arange(len(names))
    ax.barh(y - 0.2, med, height=0.4, color="tab:blue", label="median")
    ax.barh(y + 0.2, mean, height=0.4, color="tab:orange", label="mean")
    for yi, m in zip(y, med, strict=True):
        ax.annotate(f"{m:.2f}", (m, yi - 0.2), xytext=(3, 0), textcoords="offset points", va="center", fontsize=8)
    ax.set_yticks(y, names)
    ax.invert_yaxis()
    ax.set_xlabel("ms per frame")
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend(fontsize=8)
    _save(fig, path)


# -------------------------------------------------------------------------------------------- sigma sweep


def section_sweep(ctx: ReportContext) -> Section | None:
    """The sigma_m sweep of ``wptrack convergence`` as a heatmap (S1 Fig. 7) and error curves."""
    sweep = ctx.sweep
    if sweep is None:
        return None
    sec = Section(
        "sweep",
        "sigma_m sweep (convergence after a jump)",
        text=f"Mean error of the estimate per iteration for each sigma_m, from {sweep['path']}.",
    )
    summary = (sweep.get("summary") or {}).get("summary") or []
    if summary:
        sec.table = [
            (
                f"sigma_m = {row.get('sigma', float('nan')):.4f} m",
                f"converges in {row.get('converge_initial')} iterations, after the jump in "
                f"{row.get('converge_after_jump')}",
            )
            for row in summary
        ]
    with ctx.timed("plots"):
        path = ctx.out_dir / "sweep_heatmap.png"
        sweep_plot(sweep, path)
        sec.figures.append(Figure(path.name, "Error (log colour scale) per iteration and sigma_m"))
    return sec


def sweep_plot(sweep: dict, path: Path) -> None:
    """Heatmap of error (log scale) vs (iteration, sigma_m) above the error curves."""
    from matplotlib.colors import LogNorm

    sigmas = np.asarray(sweep["sigmas"], dtype=np.float64)
    errors = np.asarray(sweep["errors"], dtype=np.float64)
    fig = _figure(8.0, 7.0)
    ax, ax2 = fig.subplots(2, 1)
    pos = errors[errors > 0]
    vmin = float(pos.min()) if pos.size else 1e-4
    vmax = float(pos.max()) if pos.size else 1.0
    im = ax.imshow(
        np.clip(errors, vmin, None),
        aspect="auto",
        origin="lower",
        cmap="magma",
        norm=LogNorm(vmin=vmin, vmax=max(vmax, vmin * 1.0001)),
        extent=(-0.5, errors.shape[1] - 0.5, -0.5, len(sigmas) - 0.5),
        interpolation="nearest",
    )
    ax.set_yticks(np.arange(len(sigmas)), [f"{s:.3f}" for s in sigmas])
    ax.set_ylabel("sigma_m (m)")
    ax.set_xlabel("iteration")
    fig.colorbar(im, ax=ax, label="mean error (m)")
    cmap = _cmap("viridis")
    for k, (s, e) in enumerate(zip(sigmas, errors, strict=True)):
        ax2.plot(
            np.arange(len(e)), np.maximum(e, vmin), color=cmap(k / max(1, len(sigmas) - 1)), lw=1, label=f"{s:.3f}"
        )
    ax2.set_yscale("log")
    ax2.set_xlabel("iteration")
    ax2.set_ylabel("mean error (m)")
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(title="sigma_m", fontsize=7, ncol=2)
    _save(fig, path)


def _cmap(name: str) -> Any:
    import matplotlib

    return matplotlib.colormaps[name]
