"""Calibration check of a camera against its ground plane: the 1 m ground grid and the world axes drawn over a
frame through the calibrated camera (lens distortion included), the ground footprint of the image, and the small
image-drawing helpers the template report shares."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from wptrack.report import scene3d

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
        rig: The rig (its ground plane and working volume; ``wptrack.cameras.rig.Rig``).
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
