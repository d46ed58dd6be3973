"""The report of the S3 template tracker (``tracker: templates`` in run.json, written by ``wptrack track templates``).

Sections, in page order:

1. Calibration check: the first frame with the 1 m ground-plane grid and the world axes projected through the
   calibrated camera (lens distortion included) - :func:`calibration_check`, usable on a rig and a frame alone.
2. The tracked templates on the chosen frames: each object's template (the same vertices as ``kernels/raster.py``,
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

Units: metres and radians on the ground plane (``wptrack.rig.GroundPlane`` coordinates), pixels in the image.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, WptrackError
from ..io import atomic_imwrite
from . import plots, scene3d
from .data import GROUNDTRUTH_FILE, RunData, _resolve_file, trajectories
from .model import Figure, ReportContext, Section, register_reporter
from .overlays import compose

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

# --------------------------------------------------------------------------------------- template geometry

LOWER = 0.55
"""Vehicle: lower body height / total height (``kernels.raster.LOWER``)."""
CABIN_LENGTH = 0.6
"""Vehicle: cabin length / total length (``kernels.raster.CABIN_LENGTH``)."""
CABIN_WIDTH = 0.9
"""Vehicle: cabin width / total width (``kernels.raster.CABIN_WIDTH``)."""
MIN_BODY_TOP = 0.1
"""Human: lowest top of the body prism, metres (as in the kernel)."""
DEFAULT_HEAD_RADIUS = 0.10
"""Head radius drawn for humans when run.json has no human prior (tracks.csv does not store it), metres."""

GRID_BGR = (0, 255, 255)
"""Colour of the ground grid in :func:`calibration_check` (yellow, BGR)."""
GRID_ALPHA = 0.7
"""Opacity of the ground grid over the frame."""
AXES_BGR = ((0, 0, 255), (0, 200, 0), (255, 80, 0))
"""Colours of the world x, y, z axes in :func:`calibration_check` (red, green, blue; BGR)."""
TRUTH_BGR = (scene3d.TRUTH_RGB[2], scene3d.TRUTH_RGB[1], scene3d.TRUTH_RGB[0])
"""Colour of ground-truth markers (BGR)."""
MAX_RANGE = 50.0
"""Ground drawn at most this far from the camera's foot point, metres."""


def template_pieces(cls: str, dims: Sequence[float], heading: float = 0.0) -> list[np.ndarray]:
    """Vertices of an object's convex pieces in its own frame, as ``kernels.raster.piece_vertex`` builds them.

    Args:
        cls: ``"human"`` or ``"vehicle"``.
        dims: Human (height, body radius, head radius) or vehicle (length, width, height), metres.
        heading: Vehicle orientation in the ground plane, radians (humans are not rotated).

    Returns:
        Two (K, 3) arrays (body then head / lower body then cabin): (along ground x, along ground y, height above
        the plane), metres, relative to the object's ground-contact point. Human: an octagonal prism (16 vertices)
        inscribed in the body cylinder from the ground to ``height - 2 head radius`` and a 14-vertex head
        (octahedron + cube vertices on the head sphere). Vehicle: the lower box (``LOWER`` of the height) and the
        cabin box (``CABIN_LENGTH`` x ``CABIN_WIDTH`` of the footprint, up to the full height), 8 vertices each.

    Raises:
        ValueError: Unknown class.
    """
    d = [float(v) for v in dims]
    if cls == "human":
        height, body_r, head_r = d
        top = max(height - 2.0 * head_r, MIN_BODY_TOP)
        a = np.arange(8) * (math.pi / 4.0)
        ring = np.column_stack([body_r * np.cos(a), body_r * np.sin(a)])
        body = np.vstack([np.column_stack([ring, np.zeros(8)]), np.column_stack([ring, np.full(8, top)])])
        c = height - head_r
        octa = np.zeros((6, 3))
        for k in range(6):
            octa[k, k // 2] = (1.0 - 2.0 * (k % 2)) * head_r
        j = np.arange(8)
        cube = np.column_stack([1.0 - 2.0 * (j % 2), 1.0 - 2.0 * ((j // 2) % 2), 1.0 - 2.0 * (j // 4)])
        head = np.vstack([octa, cube * (head_r / math.sqrt(3.0))]) + np.array([0.0, 0.0, c])
        return [body, head]
    if cls == "vehicle":
        length, width, height = d
        ca, sa = math.cos(heading), math.sin(heading)
        pieces = []
        for hl, hw, z0, z1 in (
            (0.5 * length, 0.5 * width, 0.0, LOWER * height),
            (0.5 * length * CABIN_LENGTH, 0.5 * width * CABIN_WIDTH, LOWER * height, height),
        ):
            k = np.arange(8)
            lx = hl * (1.0 - 2.0 * (k % 2))
            ly = hw * (1.0 - 2.0 * ((k // 2) % 2))
            z = np.where(k >= 4, z1, z0)
            pieces.append(np.column_stack([ca * lx - sa * ly, sa * lx + ca * ly, z]))
        return pieces
    raise ValueError(f"unknown object class {cls!r} (expected 'human' or 'vehicle')")


def template_world(
    plane: Any, cls: str, ground: Sequence[float], dims: Sequence[float], heading: float
) -> list[np.ndarray]:
    """The pieces of :func:`template_pieces` in world coordinates: a list of (K, 3) arrays, metres.

    Args:
        plane: The ground plane (``wptrack.rig.GroundPlane``).
        cls: ``"human"`` or ``"vehicle"``.
        ground: (2,) the object's ground-contact point in ground-plane coordinates, metres.
        dims: Template dims (see :func:`template_pieces`).
        heading: Orientation in the ground plane, radians.
    """
    g = np.asarray(ground, dtype=np.float64).reshape(2)
    return [plane.to_world(g + v[:, :2], v[:, 2]) for v in template_pieces(cls, dims, heading)]


def template_outlines(
    camera: Any, plane: Any, cls: str, ground: Sequence[float], dims: Sequence[float], heading: float
) -> list[np.ndarray]:
    """Image outlines of an object's template: the convex hull of each piece's projected vertices.

    As in the tracker, a piece with a vertex behind the camera is left out; projection includes lens distortion
    (``Camera.project``).

    Returns:
        (M, 2) float64 hull vertices in pixels (OpenCV convention: pixel centres at integers), one per visible piece.
    """
    import cv2

    out = []
    for pts in template_world(plane, cls, ground, dims, heading):
        uv, depth = camera.project(pts)
        if np.any(depth <= 0) or not np.all(np.isfinite(uv)):
            continue
        hull = cv2.convexHull(uv.astype(np.float32).reshape(-1, 1, 2)).reshape(-1, 2)
        out.append(hull.astype(np.float64))
    return out


# --------------------------------------------------------------------------------------- image helpers


def id_bgr(obj: int) -> tuple[int, int, int]:
    """The colour of object ``obj`` (BGR), the same as its colour in ``virtual.avi``."""
    from ..run_templates import label_colours

    c = label_colours(np.array([max(int(obj), 0)]))[0]
    return (int(c[0]), int(c[1]), int(c[2]))


def _rgb01(bgr: Sequence[int]) -> tuple[float, float, float]:
    return (bgr[2] / 255.0, bgr[1] / 255.0, bgr[0] / 255.0)


def _bgr_image(frame: np.ndarray) -> np.ndarray:
    """A (H, W, 3) uint8 BGR copy of a frame (grey, BGR or BGRA)."""
    import cv2

    img = np.asarray(frame)
    if img.dtype != np.uint8:
        img = np.clip(img, 0, 255).astype(np.uint8)
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    if img.ndim == 3 and img.shape[2] == 1:
        return cv2.cvtColor(img[..., 0], cv2.COLOR_GRAY2BGR)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    if img.ndim == 3 and img.shape[2] == 3:
        return img.copy()
    raise ValueError(f"expected an (H, W) or (H, W, 3) image, got shape {img.shape}")


def _camera_for(camera: Any, width: int, height: int) -> Any:
    """``camera`` at an image size: itself, a scaled copy (same aspect ratio), or a ValueError."""
    if (width, height) == (camera.width, camera.height):
        return camera
    if abs(width / height - camera.width / camera.height) <= 0.01 * camera.width / camera.height:
        return camera.scaled(width, height)
    raise ValueError(
        f"frame size {width}x{height} does not match camera '{camera.name}' ({camera.width}x{camera.height})"
    )


def _text(img: np.ndarray, text: str, org: tuple[int, int], bgr: Sequence[int], scale: float = 0.45) -> None:
    """Text with a dark outline (readable on any background)."""
    import cv2

    org = (int(org[0]), int(org[1]))
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, tuple(int(c) for c in bgr), 1, cv2.LINE_AA)


def _legend(img: np.ndarray, lines: Sequence[tuple[str, Sequence[int]]], scale: float = 0.45) -> None:
    """Lines of coloured text on a translucent dark box in the top-left corner."""
    import cv2

    if not lines:
        return
    sizes = [cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0] for t, _ in lines]
    step = max(s[1] for s in sizes) + 8
    w = min(img.shape[1], max(s[0] for s in sizes) + 12)
    h = min(img.shape[0], step * len(lines) + 6)
    img[:h, :w] = (img[:h, :w].astype(np.float32) * 0.35).astype(np.uint8)
    for k, (t, c) in enumerate(lines):
        _text(img, t, (6, step * (k + 1) - 2), c, scale)


def _border_pixels(camera: Any, per_edge: int = 32) -> np.ndarray:
    """(4 per_edge, 2) pixels around the image border, clockwise from the top-left corner."""
    w, h = camera.width - 1.0, camera.height - 1.0
    t = np.linspace(0.0, 1.0, per_edge, endpoint=False)
    return np.vstack(
        [
            np.column_stack([t * w, np.zeros_like(t)]),
            np.column_stack([np.full_like(t, w), t * h]),
            np.column_stack([(1 - t) * w, np.full_like(t, h)]),
            np.column_stack([np.zeros_like(t), (1 - t) * h]),
        ]
    )


def ground_footprint(camera: Any, plane: Any, max_range: float = MAX_RANGE, per_edge: int = 32) -> np.ndarray:
    """The part of the ground plane the camera sees, as a polygon in ground-plane coordinates.

    The image border's viewing rays are intersected with the plane (distortion included); rays that miss it, or
    hit it farther than ``max_range`` from the camera's foot point (its orthogonal projection on the plane), are
    replaced by the point ``max_range`` away in their horizontal direction.

    Args:
        camera: Rig camera.
        plane: Ground plane.
        max_range: Clipping distance, metres.
        per_edge: Samples per image edge.

    Returns:
        (K, 2) ground coordinates, metres, in border order (K <= 4 per_edge; rays along the normal are dropped).
    """
    rays = camera.pixel_rays(_border_pixels(camera, per_edge))
    n = np.asarray(plane.normal)
    c = camera.center
    hc = float((c - np.asarray(plane.origin)) @ n)
    foot = c - hc * n
    dn = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = -hc / dn
    hit = np.isfinite(lam) & (lam > 0)
    pts = c + np.where(hit, lam, 0.0)[:, None] * rays
    far = ~hit | (np.linalg.norm(pts - foot, axis=1) > max_range)
    horiz = rays - dn[:, None] * n
    hn = np.linalg.norm(horiz, axis=1)
    keep = ~far | (hn > 1e-9)
    with np.errstate(divide="ignore", invalid="ignore"):
        clipped = foot + max_range * horiz / hn[:, None]
    pts = np.where(far[:, None], clipped, pts)
    return plane.to_ground(pts[keep])


def _grid_extent(rig: Any, camera: Any, plane: Any, step: float, max_range: float) -> tuple[np.ndarray, np.ndarray]:
    """Ground-coordinate box (lo, hi) of the grid: the camera's footprint, within the rig volume when it overlaps."""
    fp = ground_footprint(camera, plane, max_range)
    if len(fp) == 0:
        foot = plane.to_ground(camera.center)
        fp = np.vstack([foot - max_range, foot + max_range])
    lo, hi = fp.min(axis=0), fp.max(axis=0)
    if rig is not None and getattr(rig, "volume", None) is not None:
        vlo, vhi = rig.bounds()
        corners = np.array([[x, y, z] for x in (vlo[0], vhi[0]) for y in (vlo[1], vhi[1]) for z in (vlo[2], vhi[2])])
        g = plane.to_ground(corners)
        ilo, ihi = np.maximum(lo, g.min(axis=0)), np.minimum(hi, g.max(axis=0))
        if np.all(ihi - ilo >= step):
            lo, hi = ilo, ihi
    return np.floor(lo / step) * step, np.ceil(hi / step) * step


def _visible_samples(camera: Any, pts: np.ndarray, margin: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Project world points (N, 3); ``ok`` where they are in front of the camera and inside the (slightly enlarged)
    field of view, where the distortion polynomial is valid (points far outside could fold back into the image)."""
    uv, depth = camera.project(pts)
    cam_pts = pts @ np.asarray(camera.R).T + np.asarray(camera.t)
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = cam_pts[:, 0] / cam_pts[:, 2]
        yn = cam_pts[:, 1] / cam_pts[:, 2]
    border = camera.pixel_rays(_border_pixels(camera, 16)) @ np.asarray(camera.R).T
    bx, by = border[:, 0] / border[:, 2], border[:, 1] / border[:, 2]
    mx, my = margin * (bx.max() - bx.min()), margin * (by.max() - by.min())
    ok = (depth > 1e-3) & np.all(np.isfinite(uv), axis=1)
    ok &= (xn >= bx.min() - mx) & (xn <= bx.max() + mx) & (yn >= by.min() - my) & (yn <= by.max() + my)
    return uv, ok


def _runs(ok: np.ndarray) -> Iterator[tuple[int, int]]:
    """(start, stop) of the runs of True in a boolean array."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    yield from zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True)


def _polylines(img: np.ndarray, uv: np.ndarray, ok: np.ndarray, bgr: Sequence[int], thickness: int) -> None:
    import cv2

    shift = 4
    for a, b in _runs(ok):
        if b - a >= 2:
            pts = np.round(uv[a:b] * (1 << shift)).astype(np.int32).reshape(-1, 1, 2)
            cv2.polylines(img, [pts], False, tuple(int(c) for c in bgr), thickness, cv2.LINE_AA, shift)


def calibration_check(
    rig: Any, camera: Any, frame: np.ndarray, step: float = 1.0, max_range: float = MAX_RANGE
) -> np.ndarray:
    """Draw the ground-plane grid and the world axes on a frame through the calibrated camera.

    A quick visual check of a calibration and of the rig's ground plane: grid lines should lie on the floor's
    seams, lane markings etc., and objects should stand on the grid. Lines are sampled densely and projected with
    ``Camera.project`` (lens distortion included), so they curve like the image does.

    The grid has a line every ``step`` metres (every fifth thicker and labelled with its ground coordinate) over
    the ground the camera sees (:func:`ground_footprint`, at most ``max_range`` from the camera), within the rig's
    working volume when the rig has one. The world axes (x red, y green, z blue, ``step`` long) are drawn at the
    world origin, or, when it is not in view, at the grid node nearest to the ground point seen at the image
    centre (labelled with its coordinates).

    Args:
        rig: The rig (its ground plane and working volume; ``wptrack.rig.Rig``).
        camera: The camera that took ``frame`` (scaled to the frame's size when it is a resized copy).
        frame: (H, W) or (H, W, 3) uint8 image.
        step: Grid spacing, metres.
        max_range: Ground drawn at most this far from the camera's foot point, metres.

    Returns:
        (H, W, 3) uint8 BGR image, a new array of the frame's size.

    Raises:
        ValueError: The frame's size does not match the camera (nor a resized copy of the same aspect ratio), or
            ``step`` is not positive.
    """
    import cv2

    if not step > 0:
        raise ValueError(f"grid step must be > 0 metres, got {step}")
    img = _bgr_image(frame)
    h, w = img.shape[:2]
    camera = _camera_for(camera, w, h)
    plane = rig.ground_plane
    lo, hi = _grid_extent(rig, camera, plane, step, max_range)
    n_lines = (hi - lo) / step
    if np.any(n_lines > 400):  # a huge area: thin the grid rather than drawing thousands of lines
        step = step * float(np.ceil(np.max(n_lines) / 400.0))
        lo, hi = np.floor(lo / step) * step, np.ceil(hi / step) * step
    ds = step / 10.0
    labels: list[tuple[str, tuple[float, float]]] = []
    layer = img.copy()
    for axis in (0, 1):
        other = 1 - axis
        ts = np.arange(lo[other], hi[other] + 0.5 * ds, ds)
        for value in np.arange(lo[axis], hi[axis] + 0.5 * step, step):
            g = np.empty((len(ts), 2))
            g[:, axis] = value
            g[:, other] = ts
            uv, ok = _visible_samples(camera, plane.to_world(g))
            major = abs(value / (5 * step) - round(value / (5 * step))) < 1e-6
            _polylines(layer, uv, ok, GRID_BGR, 2 if major else 1)
            inside = ok & (uv[:, 0] >= 0) & (uv[:, 0] < w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] < h - 1)
            if major and inside.any():
                idx = np.flatnonzero(inside)
                # x lines labelled near the image bottom, y lines near the left edge
                k = idx[np.argmax(uv[idx, 1])] if axis == 0 else idx[np.argmin(uv[idx, 0])]
                labels.append((f"{'xy'[axis]}={value:g}", (float(uv[k, 0]), float(uv[k, 1]))))
    img = cv2.addWeighted(img, 1.0 - GRID_ALPHA, layer, GRID_ALPHA, 0.0)
    placed: list[tuple[int, int, int, int]] = []
    for text, (u, v) in labels:
        (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.4, 1)
        x, y = int(min(max(u + 3, 2), w - tw - 2)), int(min(max(v - 4, th + 2), h - 4))
        box = (x - 2, y - th - 2, x + tw + 2, y + 3)
        if any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in placed):
            continue  # would cover another label
        placed.append(box)
        _text(img, text, (x, y), GRID_BGR, 0.4)
    # world axes
    origin = np.zeros(3)
    uv0, ok0 = _visible_samples(camera, origin.reshape(1, 3), margin=0.0)
    where = "world origin"
    if not (ok0[0] and 0 <= uv0[0, 0] < w and 0 <= uv0[0, 1] < h):
        centre = camera.pixel_rays(np.array([[(w - 1) / 2.0, (h - 1) / 2.0]]))[0]
        n = np.asarray(plane.normal)
        hc = float((camera.center - np.asarray(plane.origin)) @ n)
        dn = float(centre @ n)
        origin = None
        if dn != 0 and -hc / dn > 0:
            g = plane.to_ground(camera.center + (-hc / dn) * centre)
            if np.linalg.norm(g - plane.to_ground(camera.center)) <= max_range:
                origin = plane.to_world(np.round(g / step) * step)
                where = "(" + ", ".join(f"{v:g}" for v in np.round(origin, 3) + 0.0) + ")"
    if origin is not None:
        ends = origin + step * np.eye(3)
        uv, ok = _visible_samples(camera, np.vstack([origin, ends]), margin=0.5)
        if ok[0]:
            shift = 4
            p0 = tuple(np.round(uv[0] * (1 << shift)).astype(int).tolist())
            for k in range(3):
                if ok[k + 1]:
                    p1 = tuple(np.round(uv[k + 1] * (1 << shift)).astype(int).tolist())
                    cv2.arrowedLine(img, p0, p1, AXES_BGR[k], 2, cv2.LINE_AA, shift, 0.15)
                    _text(img, "xyz"[k], (uv[k + 1, 0] + 4, uv[k + 1, 1] - 4), AXES_BGR[k])
            cv2.circle(img, p0, 3 << shift, (255, 255, 255), -1, cv2.LINE_AA, shift)
    axes_txt = f"world axes at {where}" if origin is not None else "world origin not in view"
    _legend(
        img,
        [
            (f"ground grid: {step:g} m lines (thick: {5 * step:g} m)", GRID_BGR),
            (f"{axes_txt}: x red, y green, z blue ({step:g} m)", (255, 255, 255)),
        ],
    )
    return img


# --------------------------------------------------------------------------------------- the run


@dataclass(frozen=True)
class TemplateObject:
    """One object to draw (from tracks.csv / best.csv).

    Attributes:
        id: Object label.
        cls: ``"human"`` or ``"vehicle"``.
        ground: (2,) ground-contact point in ground-plane coordinates, metres.
        dims: Template dims: human (height, body radius, head radius), vehicle (length, width, height), metres.
        heading: Orientation in the ground plane, radians.
        existence: Existence probability (1 where unknown).
        speed: m/s (NaN where unknown).
    """

    id: int
    cls: str
    ground: np.ndarray
    dims: tuple[float, float, float]
    heading: float
    existence: float = 1.0
    speed: float = float("nan")


@dataclass
class TemplateRun:
    """What the template report reads from a run, resolved once per report (:func:`template_run`).

    Attributes:
        data: The loaded run.
        camera: The tracking camera at the run's frame size, or None without a rig.
        plane: The ground plane (z = 0 without a rig).
        video: The camera's video (resolved path), or None.
        masks: Motion masks: the run's ``masks.avi`` or the masks given as input, or None.
        virtual: The run's ``virtual.avi``, or None.
        tracks: tracks.csv columns.
        best: best.csv columns, or None.
        truth: Ground-truth columns (``frame,id,x,y,z[,class,...]``), or None.
        n_frames: Frames processed by the run.
        fps: Frame rate of the run, frames per second.
        head_radius: Head radius drawn for humans (tracks.csv does not store it), metres.
        notes: What is missing or unreadable (shown in the calibration section).
    """

    data: RunData
    camera: Any
    plane: Any
    video: str | None
    masks: str | None
    virtual: str | None
    tracks: dict[str, np.ndarray]
    best: dict[str, np.ndarray] | None
    truth: dict[str, np.ndarray] | None
    n_frames: int
    fps: float
    head_radius: float
    notes: list[str] = field(default_factory=list)

    @property
    def ids(self) -> list[int]:
        """Object ids of tracks.csv, sorted."""
        return sorted(int(i) for i in np.unique(self.tracks["id"]))

    def objects_at(self, frame: int, best: bool = False) -> list[TemplateObject]:
        """The objects of tracks.csv (or best.csv) at ``frame``."""
        table = self.best if best else self.tracks
        if table is None or "frame" not in table:
            return []
        return _objects(table, np.flatnonzero(table["frame"] == frame), self.plane, self.head_radius)

    def truth_at(self, frame: int) -> list[tuple[int, str, np.ndarray]]:
        """Ground truth at ``frame``: ``(id, class, ground point (2,))``."""
        t = self.truth
        if t is None:
            return []
        rows = np.flatnonzero(t["frame"] == frame)
        xyz = np.column_stack([t["x"][rows], t["y"][rows], t["z"][rows]]).astype(np.float64)
        g = self.plane.to_ground(xyz)
        cls = t["class"][rows] if "class" in t else np.full(len(rows), "")
        return [(int(t["id"][r]), str(c), g[k]) for k, (r, c) in enumerate(zip(rows, cls, strict=True))]

    def source_image(self) -> str | None:
        """The frames shown under overlays: the video, else the motion masks."""
        return self.video or self.masks


def _objects(table: dict[str, np.ndarray], rows: np.ndarray, plane: Any, head_r: float) -> list[TemplateObject]:
    out = []
    for r in rows:
        cls = str(table["class"][r]) if "class" in table else "human"
        if "gx" in table and "gy" in table:
            g = np.array([table["gx"][r], table["gy"][r]], dtype=np.float64)
        else:
            g = plane.to_ground(np.array([table["x"][r], table["y"][r], table["z"][r]], dtype=np.float64))
        length, width, height = (float(table[c][r]) for c in ("length", "width", "height"))
        dims = (height, 0.5 * length, head_r) if cls == "human" else (length, width, height)
        out.append(
            TemplateObject(
                id=int(table["id"][r]),
                cls=cls,
                ground=g,
                dims=dims,
                heading=float(table["orientation"][r]) if "orientation" in table else 0.0,
                existence=float(table["existence"][r]) if "existence" in table else 1.0,
                speed=float(table["speed"][r]) if "speed" in table else float("nan"),
            )
        )
    return out


_DROPPED_NOTES = ("no particles.npz", "run.json names no videos")


def template_run(ctx: ReportContext) -> TemplateRun:
    """Resolve the run's camera, ground plane, videos, best.csv and ground truth (cached in ``ctx.cache``).

    Notes of the generic loader that do not apply to template runs (no particles file, a single ``video``
    entry) are removed from ``ctx.data.notes``; when the loader found no ground truth, ``../scene/groundtruth.csv``
    beside the run folder is used (and recorded in ``ctx.data``).

    Args:
        ctx: The report context of a run (``ctx.data`` set).

    Returns:
        The resolved run; missing inputs are None and listed in its ``notes``.
    """
    if "templates" in ctx.cache:
        return ctx.cache["templates"]
    from ..io import read_tracks
    from ..rig import GroundPlane

    data = ctx.data
    assert data is not None
    cfg = data.config
    data.notes[:] = [n for n in data.notes if not n.startswith(_DROPPED_NOTES)]
    notes: list[str] = []
    camera = None
    plane = GroundPlane()
    if data.rig is not None:
        plane = data.rig.ground_plane
        try:
            camera = data.rig[cfg.get("camera", 0)]
            size = cfg.get("frame_size")
            if isinstance(size, (list, tuple)) and len(size) == 2:
                camera = _camera_for(camera, int(size[0]), int(size[1]))
        except (WptrackError, ValueError, TypeError) as e:  # an unknown camera, a frame size of another aspect
            notes.append(f"camera not usable ({e}): projections are left out")
            camera = None
    rig_dir = Path(str(cfg["rig"])).parent if cfg.get("rig") else None

    def resolve(spec: Any) -> str | None:
        if not spec:
            return None
        found = _resolve_file(str(spec), data.run_dir, rig_dir)
        if found is None:
            notes.append(f"{spec} not found")
        return found

    video = resolve(cfg.get("video"))
    masks = str(data.run_dir / "masks.avi") if (data.run_dir / "masks.avi").is_file() else resolve(cfg.get("masks"))
    virtual = str(data.run_dir / "virtual.avi") if (data.run_dir / "virtual.avi").is_file() else None
    best = None
    if (data.run_dir / "best.csv").is_file():
        try:
            best = read_tracks(data.run_dir / "best.csv")
        except WptrackError as e:  # a damaged best.csv only removes a curve
            notes.append(f"cannot read best.csv ({e})")
    if data.groundtruth is None:
        fallback = data.run_dir.resolve().parent / "scene" / GROUNDTRUTH_FILE
        if fallback.is_file():
            try:
                data.groundtruth = trajectories(read_tracks(fallback), fallback)
                data.groundtruth_path = fallback
                data.notes[:] = [n for n in data.notes if not n.startswith(f"no {GROUNDTRUTH_FILE}")]
            except WptrackError as e:
                notes.append(f"cannot read ground truth {fallback} ({e})")
    truth = None
    if data.groundtruth_path is not None:
        try:
            truth = read_tracks(data.groundtruth_path)
        except WptrackError as e:
            notes.append(f"cannot read ground truth {data.groundtruth_path} ({e})")
    tcfg = cfg.get("tracker") if isinstance(cfg.get("tracker"), dict) else {}
    head_r = DEFAULT_HEAD_RADIUS
    try:
        head_r = float(((tcfg.get("human") or {}).get("dims_mean") or [0, 0, DEFAULT_HEAD_RADIUS])[2])
    except (TypeError, ValueError, IndexError):
        pass
    summary = data.run.get("summary") if isinstance(data.run.get("summary"), dict) else {}
    n_frames = int(data.frames.max()) + 1
    if isinstance(summary.get("frames"), int):
        n_frames = max(n_frames, int(summary["frames"]))
    fps = float(tcfg.get("fps") or 15.0)
    run = TemplateRun(data, camera, plane, video, masks, virtual, data.tracks, best, truth, n_frames, fps, head_r)
    run.notes = notes
    ctx.cache["templates"] = run
    return run


def _read(ctx: ReportContext, spec: str | None, frames: Sequence[int]) -> dict[int, np.ndarray]:
    """Frames of one video (cached per file in ``ctx.cache``)."""
    if spec is None:
        return {}
    key = ("frames", spec)
    have: dict[int, np.ndarray] = ctx.cache.setdefault(key, {})
    missing = [f for f in frames if f not in have]
    if missing:
        with ctx.timed("reading frames"):
            try:
                got = scene3d.read_frames([spec], missing)
            except (WptrackError, OSError) as e:  # an unreadable video leaves figures out
                log.warning("cannot read %s: %s", spec, e)
                got = {}
        have.update({f: imgs[0] for f, imgs in got.items()})
    return {f: have[f] for f in frames if f in have}


# --------------------------------------------------------------------------------------- overlays


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
            sec.figures.append(Figure(path.name, f"Frame {f}: tracked objects {ids}"))
    missing = [f for f in ctx.frames if f not in images]
    if missing:
        sec.notes.append(f"frames {missing} are beyond the end of {Path(source).name}: left out")
    return sec


def _binary(img: np.ndarray) -> np.ndarray:
    a = np.asarray(img)
    return (a.max(axis=2) if a.ndim == 3 else a) > 127


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
            "Per chosen frame: the camera frame, the binary motion mask q the tracker matched, the virtual scene of "
            "the best particle (each object's templates in its colour) and their XOR (eq. 4): white where both agree, "
            "red where the mask has foreground no template covers, blue where a template covers background; m is "
            "the number of XOR pixels."
        ),
    )
    if run.masks is None:
        sec.notes.append("no masks.avi in the run (track with --save-masks): the motion-mask panels are left out")
    if run.virtual is None:
        sec.notes.append("no virtual.avi in the run (tracked with --no-virtual): the virtual scene is left out")
    if run.masks is None and run.virtual is None:
        return sec

    with ctx.timed("fig5"):
        video = _read(ctx, run.video, ctx.frames)
        masks = _read(ctx, run.masks, ctx.frames)
        virtual = _read(ctx, run.virtual, ctx.frames)
        for f in ctx.frames:
            panels, labels = [], []
            if f in video:
                panels.append(_bgr_image(video[f]))
                labels.append(f"frame {f}")
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
    """A PyVista mesh of an object's template in world coordinates: cylinder + sphere (human) or two boxes
    (vehicle), the smooth shapes the tracker's polyhedra are inscribed in."""
    gx, gy = (float(v) for v in obj.ground)
    if obj.cls == "human":
        height, body_r, head_r = obj.dims
        top = max(height - 2.0 * head_r, MIN_BODY_TOP)
        parts = [
            pv.Cylinder(center=(gx, gy, top / 2.0), direction=(0, 0, 1), radius=body_r, height=top, resolution=24),
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
            "vehicles: lower body and cabin)."
        ),
    )
    with ctx.timed("3D stills"):
        try:
            sec.figures.extend(_render_scene3d(ctx, run))
        except ConfigError as e:  # PyVista is not installed: the rest of the report stands without the 3D views
            sec.notes.append(str(e))
    return sec


def _render_scene3d(ctx: ReportContext, run: TemplateRun) -> list[Figure]:
    from .offscreen import import_pyvista, new_plotter, renderer_info

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
        scene3d.add_ground(pl, pv, geo, data.rig)
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
    from .movie import add_movie_figures, encode_movie

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
