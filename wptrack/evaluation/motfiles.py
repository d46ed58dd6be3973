"""MOTChallenge files of a run and its ground truth (``wptrack evaluate`` writes them into ``RUN/mot/``): world
coordinates, and for a template run the image box of each object's 3D box seen by the rig camera (see
:mod:`wptrack.evaluation.mot` for the layout).

**MOTChallenge files** (:func:`write_mot_files`, written by ``wptrack evaluate`` into ``RUN/mot/``): one line per row,
``frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z`` with 1-based frames (the MOT15 layout that py-motmetrics
reads with ``motmetrics.io.loadtxt(path, fmt="mot15-2D")`` and TrackEval's MOT format): ``world.txt`` with the
world ``x, y, z`` in metres and no box (-1), and for a run of the template tracker ``<camera>.txt`` with the image
box of each object's 3D box seen by the rig camera, in MOTChallenge's 1-based pixel coordinates (OpenCV's + 1;
``x, y, z`` -1); the same for the ground truth in
``RUN/mot/gt/`` (image boxes when it has the template columns ``length,width,height,orientation``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError, WptrackError
from wptrack.evaluation.groundtruth import box_ground_table, is_box_ground_table
from wptrack.evaluation.mot import REQUIRED_COLUMNS, _integers, _numeric
from wptrack.io.tables import read_tracks

MOT_DIR = "mot"
"""Folder of a run where ``wptrack evaluate`` writes the MOTChallenge files (:func:`write_mot_files`)."""


def _mot_lines(frame: np.ndarray, ids: np.ndarray, boxes: np.ndarray, conf: np.ndarray, xyz: np.ndarray) -> str:
    rows = np.column_stack([frame + 1, ids, boxes, conf, xyz])  # MOTChallenge frames are 1-based
    order = np.lexsort((rows[:, 1], rows[:, 0]))
    return "".join(
        f"{int(r[0])},{int(r[1])},{r[2]:.2f},{r[3]:.2f},{r[4]:.2f},{r[5]:.2f},{r[6]:.4g},{r[7]:.4f},{r[8]:.4f},"
        f"{r[9]:.4f}\n"
        for r in rows[order]
    )


def image_boxes(columns: Mapping[str, Any], camera: Any, plane: Any) -> tuple[np.ndarray, np.ndarray]:
    """The image box of each row's object: the bounding box of its 3D box (ground point ``x, y, z``, the template
    columns ``length, width, height, orientation``) projected by ``camera`` (lens distortion included).

    Returns:
        ``(boxes, ok)``: (N, 4) ``left, top, width, height`` in pixels (not clipped to the image), and (N,) whether
        every corner is in front of the camera (other rows have no box).
    """
    from wptrack.trackers.templates.tracker import object_box_corners

    xyz = np.column_stack([np.asarray(columns[k], dtype=np.float64) for k in ("x", "y", "z")])
    size = np.column_stack([np.asarray(columns[k], dtype=np.float64) for k in ("length", "width", "height")])
    corners = object_box_corners(plane, plane.to_ground(xyz), size, np.asarray(columns["orientation"], np.float64))
    n = len(xyz)
    if n == 0:
        return np.zeros((0, 4)), np.zeros(0, bool)
    uv, depth = camera.project(corners.reshape(-1, 3))
    uv = uv.reshape(n, 8, 2)
    lo, hi = uv.min(axis=1), uv.max(axis=1)
    ok = np.all(depth.reshape(n, 8) > 0, axis=1) & np.all(np.isfinite(uv), axis=(1, 2))
    return np.column_stack([lo, hi - lo]), ok


TEMPLATE_BOX_COLUMNS = ("length", "width", "height", "orientation")
"""Columns a table needs for its rows to have image boxes (the template tracker's tracks, the s3 ground truth)."""


def write_mot_files(
    table: Mapping[str, Any] | str | os.PathLike,
    out_dir: str | os.PathLike,
    camera: Any = None,
    plane: Any = None,
    what: str = "tracks",
) -> list[Any]:
    """Write a tracks or ground-truth table as MOTChallenge files into ``out_dir`` (see the module docstring):
    ``world.txt`` (world ``x, y, z`` in metres, no box) and, when ``camera`` is given and the table has the template
    columns, ``<camera name>.txt`` (image boxes in pixels). Rows without a finite position are left out; the
    confidence is the ``existence`` column when there is one, else 1. Files are written atomically.

    Args:
        table: A dict of columns or a CSV path (``frame,id,x,y,z`` and optional columns).
        out_dir: Folder to write into (created).
        camera: A rig camera for the image boxes, or None.
        plane: The rig's ground plane (``Rig.ground_plane``) for the boxes' footprints.
        what: What the table is, in error messages (``tracks``, ``ground truth``).

    Returns:
        The paths written.

    Raises:
        ConfigError: The table is unreadable or lacks ``frame,id,x,y,z``.
    """
    from pathlib import Path

    from wptrack.io.atomic import atomic_write_text

    columns = table if isinstance(table, Mapping) else None
    if columns is None:
        try:
            columns = read_tracks(table, what=f"{what} file")
        except WptrackError as e:
            raise ConfigError(str(e)) from None
    if is_box_ground_table(columns):  # image boxes with ground positions (TownCentre): the valid bodies, z = 0
        columns = box_ground_table(columns, what)
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if missing:
        raise ConfigError(f"{what}: missing column(s) {', '.join(missing)} for the MOTChallenge files")
    frame = _integers(what, "frame", np.asarray(columns["frame"]), non_negative=True)
    ids = _integers(what, "id", np.asarray(columns["id"]), non_negative=False)
    if "z" not in columns:  # ground-plane annotations (frame,id,x,y: EPFL's): on the ground
        columns = {**columns, "z": np.zeros(len(frame))}
    xyz = np.column_stack([_numeric(what, k, np.asarray(columns[k])) for k in ("x", "y", "z")])
    conf = np.asarray(columns["existence"], dtype=np.float64) if "existence" in columns else np.ones(len(frame))
    keep = np.all(np.isfinite(xyz), axis=1)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    none = -np.ones((len(frame), 4))
    paths = [out / "world.txt"]
    atomic_write_text(paths[0], _mot_lines(frame[keep], ids[keep], none[keep], conf[keep], xyz[keep]))
    if camera is not None and plane is not None and all(c in columns for c in TEMPLATE_BOX_COLUMNS):
        sub = {k: np.asarray(columns[k])[keep] for k in ("x", "y", "z", *TEMPLATE_BOX_COLUMNS)}
        boxes, ok = image_boxes(sub, camera, plane)
        f, i, c = frame[keep][ok], ids[keep][ok], conf[keep][ok]
        name = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(camera.name)) or "camera"
        paths.append(out / f"{name}.txt")
        one_based = boxes[ok] + np.array([1.0, 1.0, 0.0, 0.0])  # MOTChallenge pixel coordinates start at 1
        atomic_write_text(paths[1], _mot_lines(f, i, one_based, c, -np.ones((len(f), 3))))
    return paths
