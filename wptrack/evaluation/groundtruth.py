"""Image-box ground truth (PETS 2009 / A. Milan's XML annotations) as ground-plane tables for evaluation.

The annotation file lists, per frame, the people's bounding boxes in image pixels::

    <dataset><frame number="0"><objectlist><object id="9"><box h= w= xc= yc=/></object>...

A box's foot point ``(xc, yc + h / 2)`` is back-projected through the camera onto the rig's ground plane
(z = 0 by default); the result is the table :func:`wptrack.evaluation.mot.evaluate` takes: columns
``frame, id, x, y, z`` in metres. Frame numbers are used as they are (``frame_offset`` is added: PETS S2.L1's
annotation counts from 0 like wptrack's frames).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from wptrack.core.errors import ConfigError

__all__ = ["read_boxes", "boxes_to_ground", "read_box_groundtruth"]


def read_boxes(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Read the boxes of a PETS/Milan annotation XML.

    Returns:
        Columns ``frame`` (N,) int, ``id`` (N,) int, ``xc``, ``yc``, ``w``, ``h`` (N,) float64 pixels.

    Raises:
        ConfigError: missing file, malformed XML, a missing or non-numeric attribute (names file, frame, field).
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"ground truth {path}: file not found")
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise ConfigError(f"ground truth {path}: cannot read as annotation XML: {exc}") from None
    rows: list[tuple[float, ...]] = []
    for frame in root.iter("frame"):
        fno = _number(frame, "number", f"ground truth {path}: <frame>", integer=True)
        for obj in frame.iter("object"):
            where = f"ground truth {path}: frame {fno} <object>"
            oid = _number(obj, "id", where, integer=True)
            box = obj.find("box")
            if box is None:
                raise ConfigError(f"{where} id {oid}: missing <box xc yc w h>")
            where = f"ground truth {path}: frame {fno} object {oid} <box>"
            rows.append((fno, oid, *(_number(box, k, where) for k in ("xc", "yc", "w", "h"))))
    if not rows:
        raise ConfigError(f"ground truth {path}: no <frame><objectlist><object><box> entries")
    a = np.array(rows, dtype=np.float64)
    return {
        "frame": a[:, 0].astype(np.int64),
        "id": a[:, 1].astype(np.int64),
        "xc": a[:, 2],
        "yc": a[:, 3],
        "w": a[:, 4],
        "h": a[:, 5],
    }


def _number(elem: ET.Element, field: str, where: str, integer: bool = False) -> float:
    raw = elem.get(field)
    if raw is None:
        raise ConfigError(f"{where}: missing attribute '{field}'")
    try:
        value = float(raw)
    except ValueError:
        raise ConfigError(f"{where} {field}: expected a number, got {raw!r}") from None
    if not math.isfinite(value) or (integer and value != int(value)):
        raise ConfigError(f"{where} {field}: expected {'an integer' if integer else 'a finite number'}, got {raw!r}")
    return int(value) if integer else value


def boxes_to_ground(boxes: dict[str, np.ndarray], camera, ground=None, frame_offset: int = 0) -> dict[str, np.ndarray]:
    """Back-project box foot points ``(xc, yc + h / 2)`` onto the ground plane.

    Args:
        boxes: As returned by :func:`read_boxes`, in the pixel coordinates of ``camera``.
        camera: The :class:`wptrack.cameras.rig.Camera` the boxes were drawn in (its calibrated image size).
        ground: A :class:`wptrack.cameras.rig.GroundPlane` (default: z = 0).
        frame_offset: Added to the file's frame numbers.

    Returns:
        Columns ``frame``, ``id``, ``x``, ``y``, ``z`` (metres, world frame). Feet whose ray does not meet the
        plane in front of the camera are dropped.
    """
    feet = np.column_stack([boxes["xc"], boxes["yc"] + 0.5 * boxes["h"]])
    rays = camera.pixel_rays(feet)  # (N, 3) world directions
    c = camera.center
    origin = np.zeros(3) if ground is None else np.asarray(ground.origin, dtype=np.float64)
    normal = np.array([0.0, 0.0, 1.0]) if ground is None else np.asarray(ground.normal, dtype=np.float64)
    denom = rays @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        s = ((origin - c) @ normal) / denom
    ok = np.isfinite(s) & (s > 0)
    pts = c + s[ok, None] * rays[ok]
    return {
        "frame": boxes["frame"][ok] + int(frame_offset),
        "id": boxes["id"][ok],
        "x": pts[:, 0],
        "y": pts[:, 1],
        "z": pts[:, 2],
    }


def read_box_groundtruth(
    path: str | os.PathLike[str],
    rig_path: str | os.PathLike[str],
    camera: str | int = 0,
    box_size: tuple[int, int] | None = None,
    frame_offset: int = 0,
) -> dict[str, np.ndarray]:
    """Ground-plane ground truth from an annotation XML and a rig.

    Args:
        path: The annotation XML.
        rig_path: The rig file (e.g. with a ``tsai:`` entry).
        camera: Name or index of the annotated camera in the rig.
        box_size: ``(width, height)`` of the image the boxes were drawn in, when it differs from the rig
            camera's size (the camera is scaled to it); PETS boxes are in 768x576.
        frame_offset: Added to the file's frame numbers.

    Raises:
        ConfigError, RigError: bad files or fields.
    """
    from wptrack.cameras.rig import Rig

    rig = Rig.load(rig_path)
    cam = rig[camera]
    boxes = read_boxes(path)
    if box_size is not None and tuple(box_size) != (cam.width, cam.height):
        cam = cam.scaled(*box_size)
    elif box_size is None:
        # boxes drawn in a larger image than the camera's (PETS: 768x576 boxes, 480x360 copies) would be
        # back-projected to wrong ground points without an error: refuse and say what to give
        right = float(np.max(boxes["xc"] + 0.5 * boxes["w"]))
        bottom = float(np.max(boxes["yc"] + 0.5 * boxes["h"]))
        if right > 1.1 * cam.width or bottom > 1.1 * cam.height:
            raise ConfigError(
                f"ground truth {path}: boxes reach x = {right:.0f}, y = {bottom:.0f} px, beyond camera "
                f"'{cam.name}' ({cam.width}x{cam.height}): give the size of the image they were drawn in "
                "(--box-size WIDTHxHEIGHT; PETS 2009: 768x576)"
            )
    return boxes_to_ground(boxes, cam, rig.ground, frame_offset)
