"""3D views rendered off-screen with PyVista: the rig's camera frusta, the ground and working volume, particle
clouds coloured by weight, estimated trajectories against ground truth; stills, views from the rig cameras
composited over their (undistorted) frames, and the frames of the movie.

World units are metres. The scene's "up" is the world axis closest to the cameras' mean image-up direction
(+z for the lab scene).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wptrack.io.atomic import atomic_imwrite
from wptrack.report.data import RunData
from wptrack.report.model import Figure, ReportContext, Section
from wptrack.report.offscreen import import_pyvista, new_plotter, renderer_info

log = logging.getLogger(__name__)

ESTIMATE_RGB = (255, 128, 0)
"""Colour of estimated trajectories and markers (orange)."""
TRUTH_RGB = (0, 190, 0)
"""Colour of ground-truth trajectories and markers (green)."""
FRUSTUM_RGB = (40, 70, 200)
"""Colour of camera frusta (blue)."""
CLOUD_CMAP = "viridis"
"""Colour map of particle weights (relative to the frame's largest weight)."""

_PALETTE = [(255, 128, 0), (200, 40, 160), (30, 160, 220), (150, 110, 40), (220, 40, 40), (100, 100, 100)]


def estimate_rgb(index: int) -> tuple[int, int, int]:
    """Colour of the ``index``-th estimated object (the first one is :data:`ESTIMATE_RGB`)."""
    return _PALETTE[index % len(_PALETTE)]


def _rgb(c: Sequence[int]) -> tuple[float, float, float]:
    return (c[0] / 255.0, c[1] / 255.0, c[2] / 255.0)


# ------------------------------------------------------------------------------------------------- geometry


def frustum_corners(camera: Any, depth: float) -> np.ndarray:
    """(5, 3) world points: the camera centre then the image corners (TL, TR, BR, BL) at ``depth`` metres."""
    w, h = camera.width, camera.height
    uv = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
    x = (uv[:, 0] - camera.cx) / camera.fx
    y = (uv[:, 1] - camera.cy) / camera.fy
    cam_pts = np.column_stack([x, y, np.ones(4)]) * depth
    world = (np.asarray(camera.R).T @ (cam_pts - np.asarray(camera.t)).T).T
    return np.vstack([camera.center, world])


def up_axis(rig: Any) -> int:
    """Index (0, 1, 2) of the world axis closest to the cameras' mean image-up direction (its sign ignored)."""
    if rig is None or len(rig) == 0:
        return 2
    up = np.mean([-np.asarray(c.R)[1] for c in rig.cameras], axis=0)
    if not np.any(np.abs(up) > 1e-9):
        return 2
    return int(np.argmax(np.abs(up)))


@dataclass(frozen=True)
class SceneGeometry:
    """Region of interest and layout of the 3D views.

    Attributes:
        lo: (3,) lower corner of the region shown, metres.
        hi: (3,) upper corner.
        up: Index of the up axis.
        up_sign: +1 or -1 (which way is up along that axis).
        ground: Height of the ground plane along the up axis.
        frustum_depth: Length of the drawn frusta, metres.
    """

    lo: np.ndarray
    hi: np.ndarray
    up: int
    up_sign: float
    ground: float
    frustum_depth: float

    @property
    def center(self) -> np.ndarray:
        return 0.5 * (self.lo + self.hi)

    @property
    def radius(self) -> float:
        return float(0.5 * np.linalg.norm(self.hi - self.lo))


def scene_geometry(data: RunData, frames: Sequence[int]) -> SceneGeometry:
    """Region of interest: camera centres, trajectories and the chosen particle clouds (2-98 % quantiles)."""
    pts = []
    for traj in data.estimates.values():
        pts.append(traj.xyz[np.all(np.isfinite(traj.xyz), axis=1)])
    for traj in (data.groundtruth or {}).values():
        pts.append(traj.xyz[np.all(np.isfinite(traj.xyz), axis=1)])
    if data.particles is not None:
        for f in frames:
            pos, _ = data.particles.cloud(f)
            if len(pos) >= 10:
                pts.append(np.quantile(pos, [0.02, 0.98], axis=0))
            elif len(pos):
                pts.append(pos)
    rig = data.rig
    if rig is not None:
        pts.append(np.array([c.center for c in rig.cameras]))
    allp = np.vstack([p for p in pts if len(p)]) if any(len(p) for p in pts) else np.zeros((1, 3))
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    span = float(np.max(hi - lo))
    pad = max(0.05, 0.08 * span)
    lo, hi = lo - pad, hi + pad
    up = up_axis(rig)
    sign = 1.0
    if rig is not None and len(rig):
        sign = 1.0 if np.mean([-np.asarray(c.R)[1][up] for c in rig.cameras]) >= 0 else -1.0
    ground = lo[up] if sign > 0 else hi[up]
    if rig is not None and rig.volume is not None:
        vlo, vhi = rig.bounds()
        ground = float(vlo[up] if sign > 0 else vhi[up])
        if sign > 0:
            lo[up] = min(lo[up], ground)
        else:
            hi[up] = max(hi[up], ground)
    depth = max(0.03, 0.12 * float(np.max(hi - lo)))
    return SceneGeometry(lo, hi, up, sign, float(ground), depth)


# ------------------------------------------------------------------------------------------------- actors


def _polyline(pv: Any, xyz: np.ndarray) -> Any | None:
    """Line strips through the finite rows of ``xyz`` (NaN rows split the line); None if fewer than 2 points."""
    ok = np.all(np.isfinite(xyz), axis=1)
    runs, start = [], None
    for i, good in enumerate(np.append(ok, False)):
        if good and start is None:
            start = i
        elif not good and start is not None:
            if i - start >= 2:
                runs.append((start, i))
            start = None
    if not runs:
        return None
    points = np.vstack([xyz[a:b] for a, b in runs])
    cells, offset = [], 0
    for a, b in runs:
        n = b - a
        cells.append(np.concatenate([[n], np.arange(offset, offset + n)]))
        offset += n
    return pv.PolyData(points, lines=np.concatenate(cells).astype(np.int64))


def add_rig(plotter: Any, pv: Any, rig: Any, depth: float, labels: bool = True) -> None:
    """Draw each camera's frustum (centre to image corners at ``depth``), an 'up' tick and its name."""
    for cam in rig.cameras:
        c = frustum_corners(cam, depth)
        lines = [2, 0, 1, 2, 0, 2, 2, 0, 3, 2, 0, 4, 5, 1, 2, 3, 4, 1]
        mesh = pv.PolyData(c, lines=np.array(lines, dtype=np.int64))
        plotter.add_mesh(mesh, color=_rgb(FRUSTUM_RGB), line_width=2, lighting=False, render=False)
        top_mid = 0.5 * (c[1] + c[2])  # TL-TR midpoint: the image top
        tick = top_mid + 0.25 * (top_mid - 0.5 * (c[3] + c[4]))
        plotter.add_mesh(
            pv.PolyData(np.vstack([c[1], tick, c[2]]), lines=np.array([3, 0, 1, 2], dtype=np.int64)),
            color=_rgb(FRUSTUM_RGB),
            line_width=2,
            lighting=False,
            render=False,
        )
    if labels:
        centers = np.array([cam.center for cam in rig.cameras])
        plotter.add_point_labels(
            centers,
            [cam.name for cam in rig.cameras],
            font_size=14,
            text_color=_rgb(FRUSTUM_RGB),
            shape=None,
            show_points=False,
            always_visible=True,
            render=False,
        )


def add_axes_and_scale(plotter: Any, step: float) -> None:
    """The world axes (an x/y/z marker in the lower left corner) and the ground grid's spacing (a ``grid: 0.5 m``
    label in the upper right corner), so that a 3D view has directions and a scale."""
    plotter.add_axes(xlabel="x", ylabel="y", zlabel="z", line_width=2, color="black")
    plotter.add_text(f"ground grid: {step:g} m", position="upper_right", font_size=10, color="black")


SCALE_TEXT = "x/y/z: the world axes (lower left); the ground grid's spacing in metres is written upper right"
"""What :func:`add_axes_and_scale` draws, for the sections' texts."""


def add_ground(plotter: Any, pv: Any, geo: SceneGeometry, rig: Any) -> float:
    """A light grid on the ground plane under the region of interest, and the rig's working volume outline; returns
    the grid spacing (metres)."""
    axes = [a for a in range(3) if a != geo.up]
    ext = [(geo.lo[a], geo.hi[a]) for a in axes]
    step = _nice_step(max(e[1] - e[0] for e in ext) / 8.0)
    segs = []
    for k, a in enumerate(axes):
        b = axes[1 - k]
        for v in np.arange(np.ceil(ext[k][0] / step) * step, ext[k][1] + 1e-9, step):
            p0, p1 = np.zeros(3), np.zeros(3)
            p0[a] = p1[a] = v
            p0[b], p1[b] = ext[1 - k]
            p0[geo.up] = p1[geo.up] = geo.ground
            segs.append((p0, p1))
    if segs:
        pts = np.array([p for s in segs for p in s])
        lines = np.column_stack([np.full(len(segs), 2), np.arange(0, 2 * len(segs), 2), np.arange(1, 2 * len(segs), 2)])
        plotter.add_mesh(
            pv.PolyData(pts, lines=lines.ravel()), color=(0.78, 0.78, 0.78), line_width=1, lighting=False, render=False
        )
    if rig is not None and rig.volume is not None:
        vlo, vhi = rig.bounds()
        if np.linalg.norm(vhi - vlo) > 3.0 * np.linalg.norm(geo.hi - geo.lo):
            return step  # a room-sized volume around a bench-sized scene: its outline would only cross the view
        box = pv.Box(bounds=(vlo[0], vhi[0], vlo[1], vhi[1], vlo[2], vhi[2]))
        plotter.add_mesh(box.extract_all_edges(), color=(0.55, 0.55, 0.55), line_width=1, lighting=False, render=False)
    return step


def _nice_step(x: float) -> float:
    if x <= 0:
        return 0.1
    e = 10 ** np.floor(np.log10(x))
    for m in (1, 2, 5, 10):
        if m * e >= x:
            return float(m * e)
    return float(10 * e)


def cloud_polydata(pv: Any, pos: np.ndarray, w: np.ndarray, max_points: int) -> Any:
    """Points with a ``weight`` array in [0, 1] (relative to the largest weight), display-subsampled."""
    if len(pos) > max_points:
        idx = (np.arange(max_points) * len(pos)) // max_points
        pos, w = pos[idx], w[idx]
    wmax = float(np.max(w)) if len(w) and np.max(w) > 0 else 1.0
    mesh = pv.PolyData(np.ascontiguousarray(pos, dtype=np.float64))
    mesh.point_data["weight"] = np.clip(w / wmax, 0.0, 1.0)
    return mesh


def overview_view(plotter: Any, geo: SceneGeometry, rig: Any) -> None:
    """An oblique perspective view of the region of interest, from behind and above the cameras."""
    center = geo.center
    up = np.zeros(3)
    up[geo.up] = geo.up_sign
    if rig is not None and len(rig):
        back = np.mean([c.center for c in rig.cameras], axis=0) - center
    else:
        back = np.array([-1.0, -1.3, 0.0])
    back = back - float(back @ up) * up
    if np.linalg.norm(back) < 1e-9:
        back = np.roll(up, 1)
    back /= np.linalg.norm(back)
    side = np.cross(up, back)
    direction = np.cos(np.radians(40)) * (np.cos(np.radians(25)) * back + np.sin(np.radians(25)) * side)
    direction = direction + np.sin(np.radians(40)) * up
    dist = geo.radius / np.tan(np.radians(15.0)) * 0.7
    plotter.camera_position = [tuple(center + dist * direction), tuple(center), tuple(up)]
    plotter.camera.view_angle = 30.0
    plotter.renderer.ResetCameraClippingRange()


def add_trajectories(
    plotter: Any, pv: Any, data: RunData, upto: int | None = None, truth: bool = True, width: float = 3.0
) -> list[Any]:
    """Estimated trajectories (orange, up to frame ``upto``) and ground truth (green, whole run); returns actors."""
    actors = []
    if truth and data.groundtruth:
        for traj in data.groundtruth.values():
            line = _polyline(pv, traj.xyz)
            if line is not None:
                actors.append(
                    plotter.add_mesh(line, color=_rgb(TRUTH_RGB), line_width=width, lighting=False, render=False)
                )
    for k, traj in enumerate(data.estimates.values()):
        xyz = traj.xyz if upto is None else traj.xyz[traj.frames <= upto]
        line = _polyline(pv, xyz)
        if line is not None:
            actors.append(
                plotter.add_mesh(line, color=_rgb(estimate_rgb(k)), line_width=width, lighting=False, render=False)
            )
    return actors


def markers_at(data: RunData, frame: int) -> list[tuple[np.ndarray, tuple[int, int, int]]]:
    """Marker positions and colours at ``frame``: each estimate (palette) and its ground truth (green)."""
    out = []
    for k, traj in enumerate(data.estimates.values()):
        p = traj.at(np.array([frame]))[0]
        if np.all(np.isfinite(p)):
            out.append((p, estimate_rgb(k)))
    for traj in (data.groundtruth or {}).values():
        p = traj.at(np.array([frame]))[0]
        if np.all(np.isfinite(p)):
            out.append((p, TRUTH_RGB))
    return out


def add_markers(plotter: Any, pv: Any, data: RunData, frame: int, radius: float) -> list[Any]:
    """Small unlit spheres at the estimate(s) and ground truth of ``frame``; returns the actors."""
    actors = []
    for p, rgb in markers_at(data, frame):
        actors.append(
            plotter.add_mesh(
                pv.Sphere(radius=radius, center=p, theta_resolution=12, phi_resolution=12),
                color=_rgb(rgb),
                lighting=False,
            )
        )
    return actors


# ------------------------------------------------------------------------------------------------- sections


def _cloud_actor(plotter: Any, mesh: Any, point_size: float, scalar_bar: bool) -> Any:
    kw: dict[str, Any] = {}
    if scalar_bar:
        kw["scalar_bar_args"] = {"title": "particle weight / max", "n_labels": 3, "fmt": "%.1f", "color": "black"}
    return plotter.add_mesh(
        mesh,
        scalars="weight",
        cmap=CLOUD_CMAP,
        clim=(0.0, 1.0),
        render_points_as_spheres=True,
        point_size=point_size,
        show_scalar_bar=scalar_bar,
        lighting=False,
        render=False,
        **kw,
    )


def section_scene(ctx: ReportContext) -> Section | None:
    """3D stills: the overview (whole run) and one view per chosen frame, plus the rig cameras' views."""
    data = ctx.data
    if data is None:
        return None
    sec = Section(
        "scene",
        "3D scene",
        text=(
            "Camera frusta (blue) from the rig, the ground grid, the estimated trajectory (orange) and the ground "
            "truth (green). Particles are coloured by weight relative to the frame's largest weight. "
            + SCALE_TEXT
            + "."
        ),
    )
    with ctx.timed("3D stills"):
        sec.figures.extend(_render_stills(ctx, data))
    if data.rig is not None and data.videos:
        with ctx.timed("camera views"):
            sec.figures.extend(render_camera_views(ctx, data))
    elif data.rig is not None:
        sec.notes.append("no video frames: the views from the rig cameras are left out")
    return sec


def _render_stills(ctx: ReportContext, data: RunData) -> list[Figure]:
    pv = import_pyvista()
    geo = scene_geometry(data, ctx.frames)
    w, h = ctx.options.still_size
    figs = []
    pl = new_plotter(w, h, multi_samples=4)
    try:
        ctx.renderer = renderer_info(pl)
        if data.rig is not None:
            add_rig(pl, pv, data.rig, geo.frustum_depth)
        add_axes_and_scale(pl, add_ground(pl, pv, geo, data.rig))
        add_trajectories(pl, pv, data)
        radius = 0.012 * float(np.max(geo.hi - geo.lo))
        # overview: the clouds of every chosen frame
        dynamic = []
        if data.particles is not None:
            for k, f in enumerate(ctx.frames):
                pos, wt = data.particles.cloud(f)
                if len(pos):
                    mesh = cloud_polydata(pv, pos, wt, ctx.options.max_points)
                    dynamic.append(_cloud_actor(pl, mesh, 5, scalar_bar=k == 0))
        overview_view(pl, geo, data.rig)
        title = pl.add_text("whole run", position="upper_left", font_size=11, color="black")
        path = ctx.out_dir / "scene_overview.png"
        shot(pl, path)
        frames_txt = ", ".join(str(f) for f in ctx.frames)
        figs.append(Figure(path.name, f"Whole run: trajectories, and particle clouds of frames {frames_txt}"))
        for a in dynamic:
            pl.remove_actor(a, render=False)
        # one still per chosen frame
        for f in ctx.frames:
            dynamic = []
            if data.particles is not None:
                pos, wt = data.particles.cloud(f)
                if len(pos):
                    dynamic.append(_cloud_actor(pl, cloud_polydata(pv, pos, wt, ctx.options.max_points), 7, False))
            dynamic += add_markers(pl, pv, data, f, radius)
            _set_text(title, f"frame {f}")
            path = ctx.out_dir / f"scene_frame{f:05d}.png"
            pl.renderer.ResetCameraClippingRange()
            shot(pl, path)
            figs.append(
                Figure(
                    path.name,
                    f"Frame {f}: particle cloud (colour: weight / max), estimate (orange sphere) and ground truth "
                    "(green sphere)",
                )
            )
            for a in dynamic:
                pl.remove_actor(a, render=False)
    finally:
        pl.close()
    return figs


def read_frames(videos: list[str], wanted: Sequence[int]) -> dict[int, list[np.ndarray]]:
    """Read the wanted frames (0-based) of each camera: ``{frame: [BGR image per camera]}``.

    Video files are read sequentially, skipping unwanted frames without converting them (``grab``); image
    sequences read only the wanted files. Frames beyond the end of any camera's sequence are absent from the
    result.
    """
    wanted_set = sorted({int(f) for f in wanted if int(f) >= 0})
    if not wanted_set:
        return {}
    per_camera = [_source_frames(spec, wanted_set) for spec in videos]
    return {f: [pc[f] for pc in per_camera] for f in wanted_set if all(f in pc for pc in per_camera)}


def _source_frames(spec: str, wanted: list[int]) -> dict[int, np.ndarray]:
    from wptrack.io.frames import VideoSource, open_source

    src = open_source(spec)
    out: dict[int, np.ndarray] = {}
    last = wanted[-1]
    if isinstance(src, VideoSource):
        return _video_frames(src, wanted)
    for k, frame in enumerate(src):
        if k in wanted:
            out[k] = np.array(frame)
        if k >= last:
            break
    return out


def _video_frames(src: Any, wanted: list[int]) -> dict[int, np.ndarray]:
    """Wanted frames of a video (:class:`wptrack.io.frames.VideoReader`: exact seeks over long gaps)."""
    from wptrack.io.frames import VideoReader

    out: dict[int, np.ndarray] = {}
    reader = VideoReader(src, seek_gap=9)
    try:
        for f in wanted:
            if f >= len(src):
                break
            frame = reader.read(f)
            if frame is None:
                break
            out[f] = frame
    finally:
        reader.close()
    return out


def frames_for(ctx: ReportContext, data: RunData) -> dict[int, list[np.ndarray]]:
    """The chosen frames' images (read once per report, cached in the context)."""
    if "images" not in ctx.cache:
        with ctx.timed("reading frames"):
            ctx.cache["images"] = read_frames(data.videos or [], ctx.frames) if data.videos else {}
    return ctx.cache["images"]


def render_camera_views(ctx: ReportContext, data: RunData) -> list[Figure]:
    """The 3D scene rendered from each rig camera (exact pinhole, see :mod:`.vtkcam`) over its undistorted frame.

    One plotter renders every camera (its window resized per camera), at ``overlay_scale`` times the camera's
    resolution (``Camera.scaled``). The frame shown is the last chosen frame.
    """
    import cv2

    from wptrack.report.vtkcam import apply_camera

    pv = import_pyvista()
    rig = data.rig
    frame = ctx.frames[-1] if ctx.frames else int(data.frames[-1])
    images = frames_for(ctx, data).get(frame)
    if images is None:
        return []
    figs = []
    geo = scene_geometry(data, ctx.frames)
    radius = 0.006 * float(np.max(geo.hi - geo.lo))
    pl = new_plotter(rig[0].width, rig[0].height, background="black", multi_samples=4)
    try:
        add_trajectories(pl, pv, data, width=2.0)
        add_markers(pl, pv, data, frame, radius)
        if data.particles is not None:
            pos, wt = data.particles.cloud(frame)
            if len(pos):
                _cloud_actor(pl, cloud_polydata(pv, pos, wt, ctx.options.max_points), 4, False)
        k = max(1, int(ctx.options.overlay_scale))
        for cam0, image in zip(rig.cameras, images, strict=False):
            cam = cam0.scaled(k * cam0.width, k * cam0.height) if k > 1 else cam0
            pl.window_size = (cam.width, cam.height)
            apply_camera(pl, cam)
            rgba = shot(pl, transparent=True)
            und = cv2.undistort(image, np.asarray(cam0.K), np.asarray(cam0.dist))
            if k > 1:
                und = cv2.resize(und, (cam.width, cam.height), interpolation=cv2.INTER_LINEAR)
            out = composite(und, rgba)
            path = ctx.out_dir / f"camview_{_safe(cam.name)}.png"
            atomic_imwrite(path, out)
            figs.append(
                Figure(
                    path.name,
                    f"{cam.name}, frame {frame}: the 3D scene rendered from the calibrated camera over its undistorted "
                    "frame: estimated trajectory (orange), ground truth (green), particles (colour: weight / max)",
                )
            )
    finally:
        pl.close()
    return figs


def composite(bgr: np.ndarray, rgba: np.ndarray) -> np.ndarray:
    """Alpha-blend an RGBA render over a BGR image of the same size."""
    alpha = rgba[..., 3:4].astype(np.float32) / 255.0
    render_bgr = rgba[..., 2::-1].astype(np.float32)
    out = bgr.astype(np.float32) * (1.0 - alpha) + render_bgr * alpha
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def _set_text(actor: Any, text: str) -> None:
    """Change the text of an ``add_text`` actor (a corner annotation or a text actor)."""
    if hasattr(actor, "SetInput"):
        actor.SetInput(text)
    else:
        actor.SetText(2, text)  # corner annotation: 2 = upper left


def _safe(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in name) or "camera"


# ------------------------------------------------------------------------------------------------- movie


def shot(plotter: Any, path: Any = None, transparent: bool = False) -> np.ndarray | None:
    """Render now and return the image (RGB, or RGBA if ``transparent``) or write it to ``path``."""
    plotter.render()  # a no-op before the first screenshot, which renders by itself
    if path is not None:
        plotter.screenshot(str(path), transparent_background=transparent)
        return None
    return plotter.screenshot(transparent_background=transparent, return_img=True)
