"""Section 5 of the S3 template tracker's report (:mod:`wptrack.trackers.templates.report`): a 3D PyVista scene
(imported lazily, off-screen) with the ground grid, the camera frustum, the templates as meshes at one or two frames
and the trajectories.

Units: metres (world coordinates).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError
from wptrack.report import scene3d
from wptrack.report.calibration import (
    MAX_RANGE,
    ground_footprint,
)
from wptrack.report.model import Figure, ReportContext, Section
from wptrack.trackers.templates.geometry import (
    CABIN_LENGTH,
    CABIN_WIDTH,
    HIP,
    LEG_RATIO,
    LOWER,
    SHOULDER,
    _rgb01,
    id_bgr,
)
from wptrack.trackers.templates.report_data import TemplateObject, TemplateRun, template_run
from wptrack.trackers.templates.report_tracks import _ground_xy, _per_id, _split_gaps

log = logging.getLogger(__name__)


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
                    [run.plane.to_world(o.ground, o.dims[0] if o.cls == "human" else o.dims[2]) for o in objs]
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
