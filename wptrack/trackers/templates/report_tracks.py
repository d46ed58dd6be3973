"""Section 4 of the S3 template tracker's report (:mod:`wptrack.trackers.templates.report`): every track seen from
above on the ground plane (ground truth dashed, the ground the camera sees) and the objects, existence and speed per
frame.

Units: metres on the ground plane (``wptrack.cameras.rig.GroundPlane`` coordinates), frames.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.report import plots
from wptrack.report.calibration import (
    MAX_RANGE,
    ground_footprint,
)
from wptrack.report.model import Figure, ReportContext, Section
from wptrack.trackers.templates.geometry import (
    _rgb01,
    id_bgr,
)
from wptrack.trackers.templates.report_data import TemplateRun, template_run

log = logging.getLogger(__name__)


def _per_id(table: dict[str, np.ndarray]) -> dict[int, np.ndarray]:
    """Row indices of each id, sorted by frame."""
    out = {}
    for obj in np.unique(table["id"]):
        rows = np.flatnonzero(table["id"] == obj)
        out[int(obj)] = rows[np.argsort(table["frame"][rows], kind="stable")]
    return out


def _ground_xy(run: TemplateRun, table: dict[str, np.ndarray], rows: np.ndarray) -> np.ndarray:
    if "gx" in table and "gy" in table:
        return np.column_stack([table["gx"][rows], table["gy"][rows]]).astype(np.float64)
    xyz = np.column_stack([table["x"][rows], table["y"][rows], table["z"][rows]]).astype(np.float64)
    return run.plane.to_ground(xyz)


def _split_gaps(frames: np.ndarray, values: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(frames, values)`` pieces of a track between missing frames (not joined by a line); ``values`` has one
    row per frame."""
    cut = np.flatnonzero(np.diff(frames) > 1) + 1
    return list(zip(np.split(frames, cut), np.split(values, cut), strict=True))


def birdseye_tracks_plot(run: TemplateRun, path: Path) -> None:
    """Write the bird's-eye view of the tracks on the ground plane (ground truth dashed, the camera's foot point and
    the ground it sees)."""
    truth = {}
    if run.truth is not None:
        truth = {
            obj: (run.truth["frame"][rows], _ground_xy(run, run.truth, rows))
            for obj, rows in _per_id(run.truth).items()
        }
    tracks = {obj: (rows, _ground_xy(run, run.tracks, rows)) for obj, rows in _per_id(run.tracks).items()}
    pts = [xy for _, xy in truth.values()] + [xy for _, xy in tracks.values()]
    foot = run.plane.to_ground(run.camera.center) if run.camera is not None else None
    if foot is not None:
        pts.append(foot.reshape(1, 2))
    allp = np.vstack(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    pad = max(1.0, 0.08 * float(np.max(hi - lo)))
    lo, hi = lo - pad, hi + pad
    aspect = float((hi[1] - lo[1]) / (hi[0] - lo[0]))
    fig = plots._figure(7.5, float(np.clip(6.0 * aspect + 1.2, 3.0, 9.0)))
    ax = fig.add_subplot()
    if foot is not None:
        fp = ground_footprint(run.camera, run.plane, MAX_RANGE)
        if len(fp) >= 3:
            ax.fill(fp[:, 0], fp[:, 1], color=(0.85, 0.9, 1.0), zorder=0, label="camera field of view")
        ax.plot(foot[0], foot[1], "^", color="navy", ms=9, zorder=3)
        ax.annotate(run.camera.name, (foot[0], foot[1]), textcoords="offset points", xytext=(5, 5), color="navy")
    for k, (obj, (frames, xy)) in enumerate(truth.items()):
        for j, (_, seg) in enumerate(_split_gaps(frames, xy)):
            ax.plot(seg[:, 0], seg[:, 1], "--", color="0.25", lw=1.3, label="ground truth" if k == j == 0 else None)
        ax.annotate(f"gt {obj}", xy[-1], textcoords="offset points", xytext=(3, -10), color="0.25", fontsize=7)
    for obj, (rows, xy) in tracks.items():
        c = _rgb01(id_bgr(obj))
        cls = str(run.tracks["class"][rows[0]]) if "class" in run.tracks else ""
        for j, (_, seg) in enumerate(_split_gaps(run.tracks["frame"][rows], xy)):
            ax.plot(seg[:, 0], seg[:, 1], "-", color=c, lw=2, label=f"{obj} {cls}" if j == 0 else None)
        ax.plot(xy[0, 0], xy[0, 1], "o", color=c, ms=4)
        ax.plot(xy[-1, 0], xy[-1, 1], "s", color=c, ms=4)
        ax.annotate(str(obj), xy[-1], textcoords="offset points", xytext=(3, 3), color=c, fontsize=8)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_xlabel("ground x (m)")
    ax.set_ylabel("ground y (m)")
    ax.set_aspect("equal", adjustable="box")
    ax.grid(True, alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if len(labels) > 14:
        keep = [i for i, lab in enumerate(labels) if lab in ("ground truth", "camera field of view")]
        handles, labels = [handles[i] for i in keep], [labels[i] for i in keep]
    if labels:
        ax.legend(handles, labels, loc="best", fontsize=7, ncol=2)
    plots._save(fig, path)


def objects_plot(run: TemplateRun, path: Path) -> None:
    """Write the number of objects, existence and speed vs frame."""
    frames = np.arange(run.n_frames)
    fig = plots._figure(8.0, 7.0)
    ax1, ax2, ax3 = fig.subplots(3, 1, sharex=True)

    def count(table: dict[str, np.ndarray] | None) -> np.ndarray | None:
        if table is None or "frame" not in table:
            return None
        f = np.asarray(table["frame"], dtype=np.int64)
        f = f[(f >= 0) & (f < run.n_frames)]
        return np.bincount(f, minlength=run.n_frames)

    for table, style, label in ((run.tracks, "-", "tracked"), (run.best, ":", "best particle")):
        n = count(table)
        if n is not None:
            ax1.step(frames, n, style, where="mid", lw=1.8 if style == "-" else 1.2, label=label)
    n = count(run.truth)
    if n is not None:
        ax1.step(frames, n, "--", where="mid", color="0.25", lw=1.3, label="ground truth")
    ax1.set_ylabel("objects")
    ax1.set_ylim(bottom=0)
    ax1.legend(fontsize=8)
    for obj, rows in _per_id(run.tracks).items():
        c = _rgb01(id_bgr(obj))
        for f, r in _split_gaps(run.tracks["frame"][rows], rows):
            if "existence" in run.tracks:
                ax2.plot(f, run.tracks["existence"][r], "-", color=c, lw=1.3)
            if "speed" in run.tracks:
                ax3.plot(f, run.tracks["speed"][r], "-", color=c, lw=1.3)
    min_exist = (run.data.config.get("tracker") or {}).get("min_existence")
    if isinstance(min_exist, (int, float)):
        ax2.axhline(min_exist, color="gray", ls="--", lw=1, label=f"min_existence {min_exist:g}")
        ax2.legend(fontsize=8)
    ax2.set_ylabel("existence")
    ax2.set_ylim(0, 1.05)
    if run.truth is not None:
        labelled = False
        for rows in _per_id(run.truth).values():
            f = np.asarray(run.truth["frame"][rows], dtype=np.int64)
            xy = _ground_xy(run, run.truth, rows)
            if len(f) < 2:
                continue
            for fs, seg in _split_gaps(f, xy):
                if len(fs) >= 2:
                    v = np.linalg.norm(np.diff(seg, axis=0), axis=1) * run.fps / np.diff(fs)
                    ax3.plot(fs[1:], v, "--", color="0.35", lw=0.9, label=None if labelled else "ground truth")
                    labelled = True
        if labelled:
            ax3.legend(fontsize=8)
    ax3.set_ylabel("speed (m/s)")
    ax3.set_ylim(bottom=0)
    ax3.set_xlabel("frame")
    for ax in (ax1, ax2, ax3):
        ax.grid(True, alpha=0.3)
    plots._save(fig, path)


def _fmt_px(value: Any) -> str:
    return f"{value:.0f} px" if isinstance(value, (int, float)) else "-"


def section_tracks(ctx: ReportContext) -> Section | None:
    """Bird's-eye view of the tracks and the per-frame plots."""
    data = ctx.data
    if data is None:
        return None
    run = template_run(ctx)
    sec = Section(
        "tracks",
        "Tracks on the ground plane",
        text=(
            "Left: every track seen from above in ground-plane coordinates, in its id colour (circle: first frame, "
            "square: last), the ground truth dashed and the ground the camera sees (blue). Right: objects per frame "
            "(tracked, the best particle's, ground truth), each object's existence probability and speed."
        ),
    )
    classes = {}
    if "class" in run.tracks:
        for obj, rows in _per_id(run.tracks).items():
            classes[obj] = str(run.tracks["class"][rows[0]])
    summary = data.run.get("summary") if isinstance(data.run.get("summary"), dict) else {}
    sec.table = [
        ("frames", str(run.n_frames)),
        ("objects tracked", f"{len(run.ids)}: " + ", ".join(f"{i} {classes.get(i, '')}".strip() for i in run.ids)),
        ("mean XOR penalty of the best particle", _fmt_px(summary.get("mean_penalty"))),
    ]
    if run.truth is not None:
        sec.table.append(("ground-truth objects", str(len(np.unique(run.truth["id"])))))
    with ctx.timed("plots"):
        path = ctx.out_dir / "birdseye.png"
        birdseye_tracks_plot(run, path)
        sec.figures.append(Figure(path.name, "Tracks on the ground plane, seen from above"))
        path = ctx.out_dir / "objects_vs_frame.png"
        objects_plot(run, path)
        sec.figures.append(Figure(path.name, "Objects, existence and speed vs frame"))
    return sec
