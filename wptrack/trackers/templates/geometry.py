"""Template geometry for reports: the S3 human/vehicle templates as 3D pieces (the same vertices as
``kernels/templates/raster.py``), placed in the world and outlined in an image, and the colour of each object id."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

LOWER = 0.55
"""Vehicle: lower body height / total height (``kernels.templates.raster.LOWER``)."""
CABIN_LENGTH = 0.6
"""Vehicle: cabin length / total length (``kernels.templates.raster.CABIN_LENGTH``)."""
CABIN_WIDTH = 0.9
"""Vehicle: cabin width / total width (``kernels.templates.raster.CABIN_WIDTH``)."""
LEG_RATIO = 0.65
"""Human: leg prism radius / body radius (``kernels.templates.raster.LEG_RATIO``)."""
HIP = 0.5
"""Human: hip height / height (``kernels.templates.raster.HIP``)."""
SHOULDER = 2.5
"""Human: shoulders this many head radii below the top of the head (``kernels.templates.raster.SHOULDER``)."""
DEFAULT_HEAD_RADIUS = 0.10
"""Head radius drawn for humans when run.json has no human prior (tracks.csv does not store it), metres."""


def template_pieces(cls: str, dims: Sequence[float], heading: float = 0.0) -> list[np.ndarray]:
    """Vertices of an object's convex pieces in its own frame, as ``kernels.templates.raster.piece_vertex`` builds them.

    Args:
        cls: ``"human"`` or ``"vehicle"``.
        dims: Human (height, body radius, head radius) or vehicle (length, width, height), metres.
        heading: Vehicle orientation in the ground plane, radians (humans are not rotated).

    Returns:
        Two (K, 3) arrays (body then head / lower body then cabin): (along ground x, along ground y, height above
        the plane), metres, relative to the object's ground-contact point. Human: the legs, an octagonal prism
        (16 vertices) of radius ``LEG_RATIO`` x body radius up to the hips (``HIP`` x height), and the upper body,
        hexagons of the body radius at the hips and the shoulders and a square of the head radius at the top (16
        vertices). Vehicle: the lower box (``LOWER`` of the height) and the
        cabin box (``CABIN_LENGTH`` x ``CABIN_WIDTH`` of the footprint, up to the full height), 8 vertices each.

    Raises:
        ValueError: Unknown class.
    """
    d = [float(v) for v in dims]
    if cls == "human":
        height, body_r, head_r = d
        hip = HIP * height
        a = np.arange(8) * (math.pi / 4.0)
        ring = LEG_RATIO * body_r * np.column_stack([np.cos(a), np.sin(a)])
        legs = np.vstack([np.column_stack([ring, np.zeros(8)]), np.column_stack([ring, np.full(8, hip)])])
        a6 = np.arange(6) * (math.pi / 3.0)
        hexa = body_r * np.column_stack([np.cos(a6), np.sin(a6)])
        shoulder = max(height - SHOULDER * head_r, hip)
        a4 = np.arange(4) * (math.pi / 2.0)
        top = head_r * np.column_stack([np.cos(a4), np.sin(a4)])
        upper = np.vstack(
            [
                np.column_stack([hexa, np.full(6, hip)]),
                np.column_stack([hexa, np.full(6, shoulder)]),
                np.column_stack([top, np.full(4, height)]),
            ]
        )
        return [legs, upper]
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
        plane: The ground plane (``wptrack.cameras.rig.GroundPlane``).
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
    from wptrack.trackers.templates.run import label_colours

    c = label_colours(np.array([max(int(obj), 0)]))[0]
    return (int(c[0]), int(c[1]), int(c[2]))


def _rgb01(bgr: Sequence[int]) -> tuple[float, float, float]:
    return (bgr[2] / 255.0, bgr[1] / 255.0, bgr[0] / 255.0)
