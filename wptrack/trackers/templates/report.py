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
   speed vs frame (:mod:`~wptrack.trackers.templates.report_tracks`).
5. A 3D PyVista scene (imported lazily, off-screen): ground grid, camera frustum, the templates as meshes at one or
   two frames, the trajectories (:mod:`~wptrack.trackers.templates.report_scene`).
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

from wptrack.io.atomic import atomic_imwrite
from wptrack.report import plots, scene3d
from wptrack.report.calibration import (
    GRID_ALPHA,
    GRID_BGR,
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
    LOWER,
    id_bgr,
    template_outlines,
    template_pieces,
    template_world,
)
from wptrack.trackers.templates.report_data import TemplateObject, TemplateRun, _read, template_run
from wptrack.trackers.templates.report_scene import section_scene3d
from wptrack.trackers.templates.report_tracks import section_tracks

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
