"""The 3D movie of a run: the scene of every kept frame (trajectories, the particle clouds, the ground truth) rendered
off-screen and encoded (:mod:`wptrack.report.movie`), as a report section."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from wptrack.report.data import RunData
from wptrack.report.model import ReportContext, Section
from wptrack.report.offscreen import import_pyvista, new_plotter
from wptrack.report.scene3d import (
    SCALE_TEXT,
    TRUTH_RGB,
    _cloud_actor,
    _polyline,
    _rgb,
    add_axes_and_scale,
    add_ground,
    add_rig,
    add_trajectories,
    cloud_polydata,
    estimate_rgb,
    overview_view,
    scene_geometry,
    shot,
)


def movie_frames(data: RunData, limit: int) -> list[int]:
    """Frames shown in the movie: those with particles (else all tracked frames), evenly thinned to ``limit``."""
    frames = data.particles.frames if data.particles is not None else data.frames
    frames = np.asarray(frames, dtype=np.int64)
    if len(frames) > limit > 0:
        frames = frames[np.unique(np.round(np.linspace(0, len(frames) - 1, limit)).astype(np.int64))]
    return [int(f) for f in frames]


def iter_movie(ctx: ReportContext, data: RunData) -> Iterator[np.ndarray]:
    """Render the movie's frames ((H, W, 3) uint8 RGB), reusing one plotter; it is closed when the loop ends.

    Static actors (frusta, ground, ground truth) are added once; the cloud, the estimated trajectories so far and
    the markers are meshes updated in place, so each movie frame costs one render.
    """
    import cv2

    pv = import_pyvista()
    geo = scene_geometry(data, ctx.frames)
    w, h = ctx.options.movie_size
    pl = new_plotter(w, h)
    try:
        if data.rig is not None:
            add_rig(pl, pv, data.rig, geo.frustum_depth)
        add_axes_and_scale(pl, add_ground(pl, pv, geo, data.rig))
        add_trajectories(pl, pv, data, upto=-(10**12), width=2.0)  # ground truth only
        overview_view(pl, geo, data.rig)
        cloud = _empty_cloud(pv)
        cloud_actor = _cloud_actor(pl, cloud, 5, scalar_bar=False)
        est_lines, est_points = [], []
        for k, _ in enumerate(data.estimates):
            est_lines.append(pv.PolyData())
            pl.add_mesh(est_lines[-1], color=_rgb(estimate_rgb(k)), line_width=3, lighting=False, render=False)
        truth_marks = pv.PolyData()
        marker_size = max(8.0, h / 30.0)
        pl.add_mesh(
            truth_marks,
            color=_rgb(TRUTH_RGB),
            point_size=marker_size,
            render_points_as_spheres=True,
            lighting=False,
            render=False,
        )
        for k, _ in enumerate(data.estimates):
            est_points.append(pv.PolyData())
            pl.add_mesh(
                est_points[-1],
                color=_rgb(estimate_rgb(k)),
                point_size=marker_size,
                render_points_as_spheres=True,
                lighting=False,
                render=False,
            )
        for f in movie_frames(data, ctx.options.movie_frames):
            if data.particles is not None:
                pos, wt = data.particles.cloud(f)
                cloud.copy_from(cloud_polydata(pv, pos, wt, ctx.options.max_points) if len(pos) else _empty_cloud(pv))
            cloud_actor.SetVisibility(data.particles is not None and cloud.n_points > 0)
            for k, traj in enumerate(data.estimates.values()):
                line = _polyline(pv, traj.xyz[traj.frames <= f])
                est_lines[k].copy_from(line if line is not None else pv.PolyData())
                p = traj.at(np.array([f]))
                est_points[k].copy_from(pv.PolyData(p) if np.all(np.isfinite(p)) else pv.PolyData())
            truths = [t.at(np.array([f]))[0] for t in (data.groundtruth or {}).values()]
            truths = [p for p in truths if np.all(np.isfinite(p))]
            truth_marks.copy_from(pv.PolyData(np.array(truths)) if truths else pv.PolyData())
            pl.renderer.ResetCameraClippingRange()
            img = np.ascontiguousarray(shot(pl)[..., :3])
            # the frame number drawn on the image: updating a VTK text actor costs ~15 ms per frame in software
            cv2.putText(img, f"frame {f}", (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
            yield img
    finally:
        pl.close()


def _empty_cloud(pv: Any) -> Any:
    mesh = pv.PolyData(np.zeros((0, 3)))
    mesh.point_data["weight"] = np.zeros(0)
    return mesh


def section_movie(ctx: ReportContext) -> Section | None:
    """The 3D view over time: ``movie.mp4`` plus ``movie.webm`` (or ``movie.gif``) for the page."""
    from wptrack.report.movie import add_movie_figures, encode_movie

    data = ctx.data
    if data is None:
        return None
    what = "The particle cloud (weight colours), the estimated" if data.particles is not None else "The estimated"
    sec = Section(
        "movie",
        "3D view over time",
        text=f"{what} trajectories so far (one colour per track) and the ground truth (green), frame by frame. "
        + SCALE_TEXT
        + ".",
    )
    if not ctx.options.movie:
        sec.notes.append("movie not rendered (disabled)")
        return sec
    with ctx.timed("movie"):
        files = encode_movie(iter_movie(ctx, data), ctx.out_dir, ctx.options.movie_fps)
    n_total = len(data.particles.frames) if data.particles is not None else len(data.frames)
    add_movie_figures(sec, files, ctx.options.movie_fps, n_total)
    return sec
