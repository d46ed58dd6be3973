"""The report of the S2 people tracker (``tracker: people`` in run.json, written by ``wptrack track people``).

Sections, in page order:

1. 3D scene (the generic one): camera frusta, ground grid, each person's trajectory, ground truth.
2. Occupancy and bounding volumes (paper Figs. 6 and 8): at the chosen frames, each person's occupancy pdf from
   ``occupancy.npz`` as iso-surfaces (PyVista contours of the voxel grid, off-screen) and the convex hull of the
   particles holding P_H of the weight from the run's ``hulls/`` chunks as a mesh, with the camera frusta.
3. Each camera's frame with the hulls projected (the per-camera segmentation, Figs. 5 and 7) and the ids.
4. Bird's-eye view of the trajectories, error vs frame against the ground truth, tracking metrics (MOTA, IDF1 at
   0.5 m, mean 3D centroid error), timings.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.io.atomic import atomic_imwrite
from wptrack.report import plots, scene3d, scene_movie
from wptrack.report.model import Figure, ReportContext, Section, register_reporter
from wptrack.report.offscreen import import_pyvista, new_plotter, renderer_info
from wptrack.trackers.templates.report import id_bgr

log = logging.getLogger(__name__)

HULLS_FILE = "hulls.npz"
"""The hulls of runs written before they were streamed in chunks (``hulls/``); still read."""
HULLS_DIR = "hulls"
OCCUPANCY_FILE = "occupancy.npz"
MATCH_DISTANCE = 0.5
"""Ground-plane matching radius of the metrics, metres (issue 11)."""


def load_hulls(run_dir: Path, frames: Any = None) -> dict[tuple[int, int], np.ndarray]:
    """``{(frame, id): (V, 3) hull vertices}`` from the run's ``hulls/`` chunks (``wptrack.io.chunklog``) or, for older
    runs, ``hulls.npz`` (same index/vertices layout); empty when neither exists. ``frames``: only these frames (the
    report's), so a long run's hulls are never all in memory."""
    from wptrack.io.chunklog import read_chunks

    index, verts = read_chunks(run_dir / HULLS_DIR, frames)
    path = run_dir / HULLS_FILE
    if not len(index) and path.exists():
        with np.load(path) as z:
            index, verts = z["index"], z["vertices"]
    return {(int(f), int(i)): verts[s : s + c].astype(np.float64) for f, i, s, c in index}


def load_occupancy(run_dir: Path) -> tuple[dict[tuple[int, int], tuple[np.ndarray, np.ndarray]], float]:
    """``({(frame, id): (origin (3,), grid (nx, ny, nz) float32)}, voxel)`` from ``occupancy.npz``."""
    path = run_dir / OCCUPANCY_FILE
    if not path.exists():
        return {}, 0.0
    with np.load(path) as z:
        out = {
            (int(f), int(i)): (o.astype(np.float64), g.astype(np.float32))
            for (f, i), o, g in zip(z["index"], z["origin"], z["grid"], strict=True)
        }
        return out, float(z["voxel"])


def _nearest(keys: list[int], frame: int) -> int | None:
    return min(keys, key=lambda f: abs(f - frame)) if keys else None


def section_occupancy(ctx: ReportContext) -> Section | None:
    """The occupancy pdfs (iso-surfaces) and the P_H bounding volumes (hull meshes) at the chosen frames."""
    data = ctx.data
    if data is None:
        return None
    sec = Section(
        "occupancy",
        "Occupancy and bounding volumes",
        text="Each person's volumetric occupancy pdf (3D Gaussian kernel over its particles, paper Figs. 6 and 8) as "
        "iso-surfaces at 25 % and 60 % of its peak, and the convex hull of the particles that hold 95 % of the "
        "weight (the bounding volume) as a wire mesh, one colour per id, with the camera frusta. "
        + scene3d.SCALE_TEXT
        + ".",
    )
    hulls = load_hulls(data.run_dir, ctx.frames)
    occ, voxel = load_occupancy(data.run_dir)
    if not hulls:
        sec.notes.append(f"no hulls ({HULLS_DIR}/): the bounding volumes are left out")
    if not occ:
        sec.notes.append(f"no {OCCUPANCY_FILE} (tracked with --occupancy-every 0?): the occupancy is left out")
    if not hulls and not occ:
        return sec
    occ_frames = sorted({f for f, _ in occ})
    with ctx.timed("occupancy"):
        sec.figures.extend(_render_occupancy(ctx, data, hulls, occ, voxel, occ_frames))
    return sec


def _render_occupancy(ctx, data, hulls, occ, voxel, occ_frames) -> list[Figure]:
    pv = import_pyvista()
    geo = scene3d.scene_geometry(data, ctx.frames)
    w, h = ctx.options.still_size
    figs: list[Figure] = []
    pl = new_plotter(w, h, multi_samples=4)
    try:
        ctx.renderer = renderer_info(pl)
        if data.rig is not None:
            scene3d.add_rig(pl, pv, data.rig, geo.frustum_depth)
        scene3d.add_axes_and_scale(pl, scene3d.add_ground(pl, pv, geo, data.rig))
        scene3d.overview_view(pl, geo, data.rig)
        for f in ctx.frames:
            dynamic = []
            fo = _nearest(occ_frames, f)
            for (ff, pid), (origin, grid) in occ.items():
                if ff != fo or not np.any(grid > 0):
                    continue
                img = pv.ImageData(dimensions=grid.shape, spacing=(voxel,) * 3, origin=tuple(origin + 0.5 * voxel))
                img.point_data["pdf"] = grid.ravel(order="F")
                peak = float(grid.max())
                surf = img.contour([0.25 * peak, 0.6 * peak], scalars="pdf")
                if surf.n_points:
                    rgb = tuple(c / 255 for c in id_bgr(pid)[::-1])
                    dynamic.append(pl.add_mesh(surf, color=rgb, opacity=0.35, smooth_shading=True))
            for (ff, pid), verts in hulls.items():
                if ff != f or len(verts) < 4:
                    continue
                mesh = _hull_mesh(pv, verts)
                if mesh is not None:
                    rgb = tuple(c / 255 for c in id_bgr(pid)[::-1])
                    dynamic.append(pl.add_mesh(mesh, color=rgb, style="wireframe", line_width=2))
                    dynamic.append(
                        pl.add_point_labels(
                            [verts.mean(0) + np.array([0.0, 0.0, 0.3 + np.ptp(verts[:, 2]) / 2])],
                            [f"#{pid}"],
                            font_size=14,
                            shape=None,
                            text_color=rgb,
                            always_visible=True,
                        )
                    )
            title = pl.add_text(f"frame {f} (occupancy of frame {fo})", position="upper_left", font_size=11)
            dynamic.append(title)
            path = ctx.out_dir / f"occupancy_frame{f:05d}.png"
            pl.renderer.ResetCameraClippingRange()
            scene3d.shot(pl, path)
            figs.append(
                Figure(
                    path.name,
                    f"Frame {f}: each person's occupancy iso-surfaces (translucent, 25 % and 60 % of the peak) and "
                    "95 % bounding volume (wire mesh), in the colour of its #id",
                )
            )
            for a in dynamic:
                pl.remove_actor(a, render=False)
    finally:
        pl.close()
    return figs


def _hull_mesh(pv: Any, verts: np.ndarray) -> Any | None:
    """The convex hull of ``verts`` as a triangle mesh (scipy's Qhull), or None for a flat set."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(verts)
    except QhullError:
        return None
    faces = np.column_stack([np.full(len(hull.simplices), 3), hull.simplices]).ravel()
    return pv.PolyData(verts, faces)


def project_hull(camera: Any, verts: np.ndarray) -> np.ndarray | None:
    """The image outline (convex polygon, (K, 2) pixels) of a 3D hull seen by ``camera``, or None when any vertex
    is behind it."""
    import cv2

    uv, depth = camera.project(verts)
    if np.any(depth <= 0) or not np.all(np.isfinite(uv)):
        return None
    return cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2)


def draw_people(image: np.ndarray, camera: Any, people: list[tuple[int, np.ndarray]], scale: int = 1) -> np.ndarray:
    """``image`` (BGR) with each person's projected hull filled translucent and outlined in its id's colour,
    labelled ``#id`` (the per-camera segmentation of Figs. 5 and 7)."""
    import cv2

    out = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_LINEAR) if scale > 1 else image.copy()
    fill = out.copy()
    for pid, verts in people:
        poly = project_hull(camera, verts)
        if poly is None:
            continue
        pts = np.round(poly * scale).astype(np.int32)
        cv2.fillPoly(fill, [pts], id_bgr(pid))
    out = cv2.addWeighted(fill, 0.35, out, 0.65, 0.0)
    for pid, verts in people:
        poly = project_hull(camera, verts)
        if poly is None:
            continue
        pts = np.round(poly * scale).astype(np.int32)
        cv2.polylines(out, [pts], True, id_bgr(pid), max(1, scale), cv2.LINE_AA)
        x, y = pts[:, 0].min(), pts[:, 1].min()
        cv2.putText(out, f"#{pid}", (int(x), max(int(y) - 4, 12)), cv2.FONT_HERSHEY_SIMPLEX, 0.5 * scale,
                    id_bgr(pid), max(1, scale), cv2.LINE_AA)  # fmt: skip
    return out


def _bgr(frame: np.ndarray) -> np.ndarray:
    import cv2

    if frame.ndim == 2:
        return cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    return frame if frame.shape[2] == 3 else cv2.cvtColor(frame, cv2.COLOR_BGRA2BGR)


def section_segmentation(ctx: ReportContext) -> Section | None:
    """Each camera's frame with the people's bounding volumes projected and their ids, at the chosen frames."""
    data = ctx.data
    if data is None or data.rig is None:
        return None
    sec = Section(
        "segmentation",
        "Per-camera segmentation",
        text="The 95 % bounding volume of each person projected into every camera (filled, outlined, with its id):"
        " the multi-camera segmentation of the paper's Figs. 5 and 7.",
    )
    hulls = load_hulls(data.run_dir, ctx.frames)
    if not hulls:
        sec.notes.append(f"no hulls ({HULLS_DIR}/): nothing to project")
        return sec
    images = scene3d.frames_for(ctx, data)
    if not images:
        sec.notes.append("no video frames (moved or deleted): the segmentation is left out")
        return sec
    from wptrack.report.overlays import compose

    with ctx.timed("segmentation"):
        for f in ctx.frames:
            frames = images.get(f)
            if frames is None:
                continue
            people = [(pid, v) for (ff, pid), v in hulls.items() if ff == f]
            panels = [
                draw_people(_bgr(img), cam, people, ctx.options.overlay_scale)
                for img, cam in zip(frames, data.rig.cameras, strict=False)
            ]
            canvas, _ = compose(panels, [f"{cam.name}, frame {f}" for cam in data.rig.cameras])
            path = ctx.out_dir / f"segmentation_frame{f:05d}.png"
            atomic_imwrite(path, canvas)
            ids = ", ".join(f"#{pid}" for pid, _ in people) or "nobody"
            sec.figures.append(
                Figure(
                    path.name,
                    f"Frame {f}: {ids}; each person's 95 % bounding volume projected into every camera (filled and "
                    "outlined in the colour of its #id)",
                    wide=True,
                )
            )
    return sec


def section_metrics(ctx: ReportContext) -> Section | None:
    """MOTA, IDF1 (motmetrics, 0.5 m on the ground) and the mean 3D centroid error against the ground truth."""
    data = ctx.data
    if data is None:
        return None
    sec = Section(
        "metrics", "Tracking metrics", text="Against the ground truth, people matched within 0.5 m on the ground."
    )
    summary = data.run.get("summary") if isinstance(data.run.get("summary"), dict) else {}
    sec.table = [("people tracked", str(summary.get("people", "?"))), ("frames", str(summary.get("frames", "?")))]
    if data.groundtruth_path is None:
        sec.notes.append("no ground truth found: metrics left out")
        return sec
    try:
        from wptrack.evaluation.mot import evaluate

        ev = evaluate(data.groundtruth_path, data.tracks, threshold=MATCH_DISTANCE)
    except Exception as e:  # noqa: BLE001 - motmetrics missing or a table it refuses: the page says why
        sec.notes.append(f"metrics not computed: {e}")
        return sec
    err = centroid_errors(data)
    sec.table += [
        ("MOTA", f"{ev.mota:.3f}"),
        ("IDF1", f"{ev.idf1:.3f}"),
        ("identity switches", str(ev.id_switches)),
        ("misses / false positives", f"{ev.num_misses} / {ev.num_false_positives}"),
        ("mean 3D centroid error", f"{100 * np.mean(err):.1f} cm" if len(err) else "n/a"),
    ]
    return sec


def centroid_errors(data: Any) -> np.ndarray:
    """3D distance from each ground-truth person to the nearest track within 0.5 m on the ground, per frame."""
    gt = data.groundtruth or {}
    t = data.tracks
    out = []
    for traj in gt.values():
        for f, p in zip(traj.frames, traj.xyz, strict=True):
            sel = t["frame"] == f
            if not sel.any():
                continue
            q = np.column_stack([t["x"][sel], t["y"][sel], t["z"][sel]])
            d = np.hypot(q[:, 0] - p[0], q[:, 1] - p[1])
            j = int(np.argmin(d))
            if d[j] <= MATCH_DISTANCE:
                out.append(float(np.linalg.norm(q[j] - p)))
    return np.asarray(out)


PEOPLE_SECTIONS = (
    scene3d.section_scene,
    section_occupancy,
    section_segmentation,
    plots.section_birdseye,
    section_metrics,
    plots.section_errors,
    scene_movie.section_movie,
    plots.section_timings,
)
"""Section builders of the people tracker's report, in page order."""

register_reporter("people", "S2 multi-camera people tracker (motion and multi-view colour)", PEOPLE_SECTIONS)
