"""The report of the S3 template tracker (``tracker: templates`` in run.json, written by ``wptrack track templates``).

Sections, in page order:

1. Calibration check: the first frame with the 1 m ground-plane grid and the world axes projected through the
   calibrated camera (lens distortion included) - :func:`calibration_check`, usable on a rig and a frame alone.
2. The tracked templates on the chosen frames: each object's template (the same vertices as
   ``kernels/templates/raster.py``,
   :func:`template_pieces`) projected and outlined by the convex hulls of its pieces, in a colour per id (the
   colours of ``virtual.avi``), with its id and class; ground-truth ground points when a ground truth is found.
3. The paper's Fig. 5: frame, motion mask (``masks.avi`` or the run's given masks), the best particle's virtual
   scene (``virtual.avi``) and their XOR (eq. 4).
4. Bird's-eye view of all tracks on the ground plane (ground truth dashed), and number of objects, existence and
   speed vs frame.
5. A 3D PyVista scene (imported lazily, off-screen): ground grid, camera frustum, the templates as meshes at one or
   two frames, the trajectories.
6. A movie of the template overlays (``ReportOptions.movie``), and the per-stage timings of run.json.

Ground truth: ``ReportOptions.groundtruth`` (applied by :func:`wptrack.report.build_report`), else
``groundtruth.csv`` in the run folder or beside the rig (:mod:`.data`), else ``../scene/groundtruth.csv`` next to
the run folder (the layout of ``wptrack synth ... --out X/scene`` + ``wptrack track ... --out X/run``).

Units: metres and radians on the ground plane (``wptrack.cameras.rig.GroundPlane`` coordinates), pixels in the image.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError
from wptrack.io.atomic import atomic_imwrite
from wptrack.report import plots, scene3d
from wptrack.report.calibration import (
    GRID_ALPHA,
    GRID_BGR,
    MAX_RANGE,
    TRUTH_BGR,
    _bgr_image,
    _legend,
    _text,
    _visible_samples,
    calibration_check,
    ground_footprint,
)
from wptrack.report.model import Figure, ReportContext, Section, register_reporter
from wptrack.report.overlays import compose
from wptrack.trackers.templates.geometry import (
    CABIN_LENGTH,
    CABIN_WIDTH,
    HIP,
    LEG_RATIO,
    LOWER,
    SHOULDER,
    _rgb01,
    id_bgr,
    template_outlines,
    template_pieces,
    template_world,
)
from wptrack.trackers.templates.report_data import TemplateObject, TemplateRun, _read, template_run

log = logging.getLogger(__name__)

__all__ = [
    "CABIN_LENGTH",
    "CABIN_WIDTH",
    "GRID_ALPHA",
    "GRID_BGR",
    "LOWER",
    "TEMPLATE_SECTIONS",
    "TemplateObject",
    "TemplateRun",
    "calibration_check",
    "draw_templates",
    "ground_footprint",
    "id_bgr",
    "template_outlines",
    "template_pieces",
    "template_run",
    "template_world",
]


def draw_templates(
    image: np.ndarray,
    camera: Any,
    plane: Any,
    objects: Sequence[TemplateObject],
    truths: Sequence[tuple[int, str, np.ndarray]] = (),
    scale: int = 1,
) -> np.ndarray:
    """Outline each object's template on a frame, with its id and class; mark the ground-truth ground points.

    Each piece's hull (:func:`template_outlines`) is drawn in the object's colour (:func:`id_bgr`), a filled dot
    marks its ground-contact point; ground truth is a green ring with a cross at its ground point.

    Args:
        image: (H, W[, 3]) uint8 frame of ``camera``.
        camera: The tracking camera (at the image's size).
        plane: Ground plane.
        objects: Objects to draw.
        truths: ``(id, class, ground point (2,))`` ground truth.
        scale: The frame is upscaled by this integer factor first (pixel ``(u, v)`` is drawn at
            ``(scale u + (scale - 1) / 2, ...)``).

    Returns:
        A new (scale H, scale W, 3) uint8 BGR image.
    """
    import cv2

    s = max(1, int(scale))
    img = _bgr_image(image)
    out = cv2.resize(img, (img.shape[1] * s, img.shape[0] * s), interpolation=cv2.INTER_NEAREST) if s > 1 else img
    shift = 4

    def px(uv: np.ndarray) -> np.ndarray:
        return np.round((np.asarray(uv) * s + (s - 1) / 2.0) * (1 << shift)).astype(np.int32)

    for g_id, g_cls, g in truths:
        uv, ok = _visible_samples(camera, plane.to_world(np.asarray(g).reshape(1, 2)), margin=0.0)
        if ok[0]:
            c = px(uv[0])
            r = (5 * s) << shift
            cv2.circle(out, (int(c[0]), int(c[1])), r, TRUTH_BGR, 2, cv2.LINE_AA, shift)
            cv2.line(out, (int(c[0] - r), int(c[1])), (int(c[0] + r), int(c[1])), TRUTH_BGR, 1, cv2.LINE_AA, shift)
            cv2.line(out, (int(c[0]), int(c[1] - r)), (int(c[0]), int(c[1] + r)), TRUTH_BGR, 1, cv2.LINE_AA, shift)
            label = f"gt {g_id}" + (f" {g_cls}" if g_cls else "")
            _text(out, label, (uv[0, 0] * s + 7 * s, uv[0, 1] * s + 14 * s), TRUTH_BGR, 0.3 * s)
    for o in objects:
        colour = id_bgr(o.id)
        hulls = template_outlines(camera, plane, o.cls, o.ground, o.dims, o.heading)
        for hull in hulls:
            cv2.polylines(out, [px(hull).reshape(-1, 1, 2)], True, colour, max(1, s), cv2.LINE_AA, shift)
        uv, ok = _visible_samples(camera, plane.to_world(np.asarray(o.ground).reshape(1, 2)), margin=0.0)
        if ok[0]:
            c = px(uv[0])
            cv2.circle(out, (int(c[0]), int(c[1])), (2 * s) << shift, colour, -1, cv2.LINE_AA, shift)
        if hulls:
            allp = np.vstack(hulls)
            top = allp[np.argmin(allp[:, 1])]
            label = f"{o.id} {o.cls}"
            (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.35 * s, 1)
            x = min(max(top[0] * s - 12 * s, 2), out.shape[1] - tw - 2)
            y = min(max(top[1] * s - 5 * s, th + 2), out.shape[0] - 4)
            _text(out, label, (x, y), colour, 0.35 * s)
    return out


def _need_camera(sec: Section, run: TemplateRun) -> bool:
    if run.camera is None:
        sec.notes.append("no rig camera: projected figures are left out")
        return False
    return True


def section_calibration(ctx: ReportContext) -> Section | None:
    """The first frame with the ground grid and the world axes (:func:`calibration_check`)."""
    data = ctx.data
    if data is None:
        return None
    run = template_run(ctx)
    sec = Section(
        "calibration",
        "Calibration check",
        text=(
            "The ground-plane grid (yellow, 1 m lines, every 5 m thicker and labelled) and the world axes (x red, "
            "y green, z blue) projected through the calibrated camera, lens distortion included. Lines should follow "
            "the ground's seams and markings, and objects should stand on the grid; a wrong height, tilt or focal "
            "length shows as a grid that slides off the ground towards the horizon."
        ),
    )
    sec.notes.extend(run.notes)
    if not _need_camera(sec, run):
        return sec
    cam = run.camera
    n = np.asarray(run.plane.normal)
    height = float((cam.center - np.asarray(run.plane.origin)) @ n)
    tilt = math.degrees(math.asin(float(np.clip(-(np.asarray(cam.R)[2] @ n), -1.0, 1.0))))
    sec.table = [
        ("camera", f"{cam.name}, {cam.width}x{cam.height} px"),
        ("focal length", f"fx {cam.fx:.1f} px, fy {cam.fy:.1f} px; principal point ({cam.cx:.1f}, {cam.cy:.1f})"),
        ("distortion k1 k2 p1 p2 k3", " ".join(f"{v:.4g}" for v in np.asarray(cam.dist))),
        ("camera centre", "(" + ", ".join(f"{round(float(v), 3) + 0.0:.3f}" for v in cam.center) + ") m"),
        ("height above the ground", f"{height:.3f} m"),
        ("optical axis below the ground plane's horizon", f"{tilt:.1f} deg"),
        (
            "ground plane",
            "origin ("
            + ", ".join(f"{v:g}" for v in np.asarray(run.plane.origin))
            + "), normal ("
            + ", ".join(f"{v:.3g}" for v in n)
            + ")",
        ),
    ]
    source = run.source_image()
    if source is None:
        sec.notes.append("no video or mask frames found: the grid is drawn on a blank image")
    with ctx.timed("calibration"):
        image = _read(ctx, source, [0]).get(0)
        if image is None:
            image = np.full((cam.height, cam.width, 3), 96, np.uint8)
        out = calibration_check(data.rig, cam, image)

        path = ctx.out_dir / "calibration.png"
        atomic_imwrite(path, out)
    what = "first video frame" if run.video else ("first motion mask" if run.masks else "blank image")
    sec.figures.append(Figure(path.name, f"Ground grid and world axes on the {what} ({cam.name})"))
    return sec


def section_overlays(ctx: ReportContext) -> Section | None:
    """The tracked templates outlined on the chosen frames."""
    data = ctx.data
    if data is None:
        return None
    run = template_run(ctx)
    sec = Section(
        "overlays",
        "Tracked templates on the frames",
        text=(
            "Each tracked object's 3D template (human: octagonal body prism and head; vehicle: lower body and cabin "
            "boxes) projected through the camera: the convex hull of each piece, in the object's colour (the same "
            "colours as the virtual scene), its id and class, and a dot at its ground-contact point. Green rings: "
            "the ground-truth ground points."
        ),
    )
    if not _need_camera(sec, run):
        return sec
    source = run.source_image()
    if source is None:
        sec.notes.append("no video or mask frames found: overlays are left out")
        return sec
    if run.video is None:
        sec.notes.append("no video: the templates are drawn on the motion masks")
    if run.truth is None:
        sec.notes.append("no ground truth found (give ReportOptions.groundtruth): ground-truth markers left out")

    with ctx.timed("overlays"):
        images = _read(ctx, source, ctx.frames)
        for f in ctx.frames:
            if f not in images:
                continue
            objs = run.objects_at(f)
            out = draw_templates(images[f], run.camera, run.plane, objs, run.truth_at(f), ctx.options.overlay_scale)
            _legend(out, [(f"frame {f}: {len(objs)} objects", (255, 255, 255))], 0.5)
            path = ctx.out_dir / f"overlay_frame{f:05d}.png"
            atomic_imwrite(path, out)
            ids = ", ".join(f"{o.id} ({o.cls})" for o in objs) or "none"
            sec.figures.append(
                Figure(
                    path.name,
                    f"Frame {f}: tracked objects {ids}: template outlines in each object's colour with its id and "
                    "class, a dot at its ground point; green rings: the ground truth",
                )
            )
    missing = [f for f in ctx.frames if f not in images]
    if missing:
        sec.notes.append(f"frames {missing} are beyond the end of {Path(source).name}: left out")
    return sec


def _binary(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img)
    return (a.max(axis=2) if a.ndim == 3 else a) > 127


def _backgrounds(run_dir: Path) -> list[tuple[int, float, Path]]:
    """``(window, centre frame, png)`` of the background windows a run with offline masks saved
    (``backgrounds/index.json``, see :class:`wptrack.trackers.templates.run.BackgroundSaver`); empty when there are none
    or the index cannot be read."""
    import json

    index = Path(run_dir) / "backgrounds" / "index.json"
    try:
        windows = json.loads(index.read_text())["windows"]
        out = [(int(w["window"]), float(w["centre"]), index.parent / str(w["file"])) for w in windows]
    except (OSError, ValueError, KeyError, TypeError):
        return []
    return [w for w in out if w[2].is_file()]


def _background_for(backgrounds: list[tuple[int, float, Path]], frame: int) -> tuple[int, np.ndarray] | None:
    """The saved background whose window centre is nearest ``frame``: ``(window, BGR image)``, or None."""
    if not backgrounds:
        return None
    import cv2

    window, _, path = min(backgrounds, key=lambda w: abs(w[1] - frame))
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    return None if image is None else (window, image)


def section_fig5(ctx: ReportContext) -> Section | None:
    """The paper's Fig. 5: frame, motion mask, best particle's virtual scene and their XOR."""
    data = ctx.data
    if data is None:
        return None
    run = template_run(ctx)
    sec = Section(
        "fig5",
        "Motion mask and virtual scene (Fig. 5)",
        text=(
            "Per chosen frame: the camera frame, the background of the offline motion model (the window nearest the "
            "frame, when the run made its masks offline), the binary motion mask q the tracker matched, the virtual "
            "scene of "
            "the best particle (each object's templates in its colour) and their XOR (eq. 4): white where both agree, "
            "red where the mask has foreground no template covers, blue where a template covers background; m is "
            "the number of XOR pixels."
        ),
    )
    if run.masks is None:
        sec.notes.append("no masks.avi in the run (track with --save-masks): the motion-mask panels are left out")
    if run.virtual is None:
        sec.notes.append(
            "no virtual.avi in the run (tracked with --no-virtual, or frames above 640x480 without --virtual): the "
            "virtual scene is left out"
        )
    if run.masks is None and run.virtual is None:
        return sec

    with ctx.timed("fig5"):
        backgrounds = _backgrounds(data.run_dir)
        video = _read(ctx, run.video, ctx.frames)
        masks = _read(ctx, run.masks, ctx.frames)
        virtual = _read(ctx, run.virtual, ctx.frames)
        for f in ctx.frames:
            panels, labels = [], []
            if f in video:
                panels.append(_bgr_image(video[f]))
                labels.append(f"frame {f}")
            bg = _background_for(backgrounds, f)
            if bg is not None:
                panels.append(bg[1])
                labels.append(f"background (window {bg[0]})")
            q = _binary(masks[f]) if f in masks else None
            v = _binary(virtual[f]) if f in virtual else None
            if q is not None:
                panels.append(np.repeat((q * 255).astype(np.uint8)[..., None], 3, axis=2))
                labels.append(f"motion mask q ({int(q.sum())} px)")
            if v is not None:
                panels.append(_bgr_image(virtual[f]))
                labels.append("virtual scene (best particle)")
            if q is not None and v is not None and q.shape == v.shape:
                x = np.zeros(q.shape + (3,), np.uint8)
                x[q & v] = (255, 255, 255)
                x[q & ~v] = (0, 0, 255)
                x[v & ~q] = (255, 0, 0)
                panels.append(x)
                labels.append(f"XOR: m = {int((q ^ v).sum())} px")
            if len(panels) < 2:
                continue
            canvas, _ = compose(panels, labels)
            path = ctx.out_dir / f"fig5_frame{f:05d}.png"
            atomic_imwrite(path, canvas)
            sec.figures.append(Figure(path.name, f"Frame {f}: " + ", ".join(labels[1:]), wide=True))
    return sec


# --------------------------------------------------------------------------------------- plots


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


# --------------------------------------------------------------------------------------- 3D


def _plane_matrix(plane: Any) -> np.ndarray:
    """4x4 transform from ground-plane coordinates (x, y, height) to world coordinates."""
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = plane.x_axis, plane.y_axis, plane.normal, plane.origin
    return m


def template_mesh(pv: Any, plane: Any, obj: TemplateObject) -> Any:
    """A PyVista mesh of an object's template in world coordinates: leg and torso cylinders + a head sphere (human)
    or two boxes (vehicle), smooth shapes close to the tracker's polyhedra."""
    gx, gy = (float(v) for v in obj.ground)
    if obj.cls == "human":
        height, body_r, head_r = obj.dims
        hip = HIP * height
        top = max(height - SHOULDER * head_r, hip + 0.01)
        parts = [
            pv.Cylinder(
                center=(gx, gy, hip / 2.0), direction=(0, 0, 1), radius=LEG_RATIO * body_r, height=hip, resolution=24
            ),
            pv.Cylinder(
                center=(gx, gy, (hip + top) / 2.0), direction=(0, 0, 1), radius=body_r, height=top - hip, resolution=24
            ),
            pv.Sphere(radius=head_r, center=(gx, gy, height - head_r), theta_resolution=16, phi_resolution=12),
        ]
    else:
        length, width, height = obj.dims
        parts = []
        for ln, wd, z0, z1 in (
            (length, width, 0.0, LOWER * height),
            (CABIN_LENGTH * length, CABIN_WIDTH * width, LOWER * height, height),
        ):
            box = pv.Cube(center=(0.0, 0.0, 0.5 * (z0 + z1)), x_length=ln, y_length=wd, z_length=z1 - z0)
            box = box.rotate_z(math.degrees(obj.heading), inplace=False)
            parts.append(box.translate((gx, gy, 0.0), inplace=False))
    mesh = parts[0].merge(parts[1:]) if len(parts) > 1 else parts[0]
    return mesh.transform(_plane_matrix(plane), inplace=False)


def _add_footprint(plotter: Any, pv: Any, run: TemplateRun, max_range: float) -> None:
    """The ground the camera sees (:func:`ground_footprint`) as an outline on the ground, and the rays of the image
    corners from the camera centre down to it, in the frustum colour."""
    per_edge = 32
    fp = ground_footprint(run.camera, run.plane, max_range, per_edge=per_edge)
    if len(fp) < 3:
        return
    ring = run.plane.to_world(np.vstack([fp, fp[:1]]), 0.02)
    colour = scene3d._rgb(scene3d.FRUSTUM_RGB)
    outline = scene3d._polyline(pv, ring)
    if outline is not None:
        plotter.add_mesh(outline, color=colour, line_width=2, lighting=False, render=False)
    if len(fp) == 4 * per_edge:  # every border ray kept: the corners are every per_edge-th point
        corners = ring[: 4 * per_edge : per_edge]
        pts = np.vstack([run.camera.center, corners])
        lines = np.array([[2, 0, k] for k in range(1, 5)], dtype=np.int64).ravel()
        plotter.add_mesh(pv.PolyData(pts, lines=lines), color=colour, line_width=1, lighting=False, render=False)


def _scene_frames(frames: Sequence[int]) -> list[int]:
    """One or two frames for the 3D stills: the middle and the last chosen frame."""
    if not frames:
        return []
    picks = {frames[len(frames) // 2], frames[-1]}
    return sorted(picks)


def section_scene3d(ctx: ReportContext) -> Section | None:
    """3D stills: ground grid, camera frustum, trajectories and the templates at one or two frames."""
    data = ctx.data
    if data is None:
        return None
    run = template_run(ctx)
    sec = Section(
        "scene",
        "3D scene",
        text=(
            "The camera frustum (blue) with the rays of the image corners down to the ground it sees (blue outline, "
            "clipped to the region shown), the ground grid, every track on the ground in its id colour, the ground "
            "truth (green) and the objects' templates at the frame shown (humans: body cylinder and head sphere; "
            "vehicles: lower body and cabin). " + scene3d.SCALE_TEXT + "."
        ),
    )
    with ctx.timed("3D stills"):
        try:
            sec.figures.extend(_render_scene3d(ctx, run))
        except ConfigError as e:  # PyVista is not installed: the rest of the report stands without the 3D views
            sec.notes.append(str(e))
    return sec


def _render_scene3d(ctx: ReportContext, run: TemplateRun) -> list[Figure]:
    from wptrack.report.offscreen import import_pyvista, new_plotter, renderer_info

    pv = import_pyvista()
    data = run.data
    geo = scene3d.scene_geometry(data, ctx.frames)
    w, h = ctx.options.still_size
    figs = []
    lift = 0.03  # trajectories slightly above the grid
    pl = new_plotter(w, h, multi_samples=4)
    try:
        ctx.renderer = renderer_info(pl)
        if data.rig is not None:
            scene3d.add_rig(pl, pv, data.rig, geo.frustum_depth)
        if run.camera is not None:
            _add_footprint(pl, pv, run, max_range=min(MAX_RANGE, 2.0 * geo.radius))
        scene3d.add_axes_and_scale(pl, scene3d.add_ground(pl, pv, geo, data.rig))
        if run.truth is not None:
            for rows in _per_id(run.truth).values():
                for _, seg in _split_gaps(run.truth["frame"][rows], _ground_xy(run, run.truth, rows)):
                    line = scene3d._polyline(pv, run.plane.to_world(seg, lift))
                    if line is not None:
                        pl.add_mesh(line, color=scene3d._rgb(scene3d.TRUTH_RGB), line_width=2, lighting=False)
        for obj, rows in _per_id(run.tracks).items():
            for _, seg in _split_gaps(run.tracks["frame"][rows], _ground_xy(run, run.tracks, rows)):
                line = scene3d._polyline(pv, run.plane.to_world(seg, lift))
                if line is not None:
                    pl.add_mesh(line, color=_rgb01(id_bgr(obj)), line_width=4, lighting=False)
        scene3d.overview_view(pl, geo, data.rig)
        title = pl.add_text("", position="upper_left", font_size=11, color="black")
        for f in _scene_frames(ctx.frames):
            dynamic = []
            objs = run.objects_at(f)
            for o in objs:
                dynamic.append(
                    pl.add_mesh(template_mesh(pv, run.plane, o), color=_rgb01(id_bgr(o.id)), smooth_shading=True)
                )
            if objs:
                tops = np.array(
                    [run.plane.to_world(o.ground, o.dims[2] if o.cls == "vehicle" else o.dims[0]) for o in objs]
                )
                dynamic.append(
                    pl.add_point_labels(
                        tops + 0.3 * np.asarray(run.plane.normal),
                        [f"{o.id} {o.cls}" for o in objs],
                        font_size=12,
                        text_color="black",
                        shape=None,
                        show_points=False,
                        always_visible=True,
                    )
                )
            scene3d._set_text(title, f"frame {f}: {len(objs)} objects")
            path = ctx.out_dir / f"scene_frame{f:05d}.png"
            pl.renderer.ResetCameraClippingRange()
            scene3d.shot(pl, path)
            figs.append(Figure(path.name, f"Frame {f}: templates, tracks and the camera"))
            for a in dynamic:
                pl.remove_actor(a, render=False)
    finally:
        pl.close()
    return figs


# --------------------------------------------------------------------------------------- movie


def _movie_frames(run: TemplateRun, limit: int) -> list[int]:
    frames = np.arange(run.n_frames)
    if len(frames) > limit > 0:
        frames = frames[np.unique(np.round(np.linspace(0, len(frames) - 1, limit)).astype(np.int64))]
    return [int(f) for f in frames]


def iter_overlay_movie(ctx: ReportContext, run: TemplateRun, chunk: int = 16) -> Iterator[np.ndarray]:
    """The movie's frames ((H, W, 3) uint8 RGB, ``options.movie_size``'s width): the template overlays of up to
    ``options.movie_frames`` evenly spaced frames, read from the video (or the masks) ``chunk`` frames at a time
    (:func:`wptrack.report.scene3d.read_frames` seeks over long gaps)."""
    import cv2

    wanted = _movie_frames(run, ctx.options.movie_frames)
    width = max(2, int(ctx.options.movie_size[0]) // 2 * 2)
    source = run.source_image()
    for start in range(0, len(wanted), chunk):
        part = wanted[start : start + chunk]
        images = scene3d.read_frames([source], part)
        for k in part:
            if k not in images:  # past the end of the video
                return
            out = draw_templates(images[k][0], run.camera, run.plane, run.objects_at(k), run.truth_at(k), scale=1)
            height = max(2, int(round(width * out.shape[0] / out.shape[1])) // 2 * 2)
            out = cv2.resize(out, (width, height), interpolation=cv2.INTER_AREA)
            _legend(out, [(f"frame {k}", (255, 255, 255))], 0.45)
            yield np.ascontiguousarray(out[..., ::-1])


def section_movie(ctx: ReportContext) -> Section | None:
    """The template overlays over time: ``movie.mp4`` and ``movie.webm`` (or ``movie.gif``)."""
    from wptrack.report.movie import add_movie_figures, encode_movie

    data = ctx.data
    if data is None:
        return None
    run = template_run(ctx)
    sec = Section(
        "movie",
        "Tracked templates over time",
        text="The template outlines of the tracked objects on the frames (ground truth: green rings).",
    )
    if not ctx.options.movie:
        sec.notes.append("movie not rendered (disabled)")
        return sec
    if run.camera is None or run.source_image() is None:
        sec.notes.append("no rig camera or no frames: the movie is left out")
        return sec
    with ctx.timed("movie"):
        files = encode_movie(iter_overlay_movie(ctx, run), ctx.out_dir, ctx.options.movie_fps)
    add_movie_figures(sec, files, ctx.options.movie_fps, run.n_frames)
    return sec


TEMPLATE_SECTIONS = (
    section_calibration,
    section_overlays,
    section_fig5,
    section_tracks,
    section_scene3d,
    section_movie,
    plots.section_timings,
)
"""Section builders of the template tracker's report, in page order."""

register_reporter("templates", "S3 3D template tracker (Juza et al.)", TEMPLATE_SECTIONS)
