"""Host side of the S3 template tracker's frame: the per-frame ``TemplateEstimate`` from the arrays read back after
the chain (objects above ``min_existence``, the best particle's scene, the addition) and the in-image test of the
reported objects (``min_in_image``: the fraction of an object's image bounding box inside the image)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from wptrack.cameras.rig import Camera, GroundPlane
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.templates import slots as kslots
from wptrack.trackers.templates.config import CLASSES, TemplateEstimate, TrackedObject

if TYPE_CHECKING:
    from wptrack.trackers.templates.tracker import TemplateTracker

_BOX_CORNERS = np.array([[sx, sy, sz] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5) for sz in (0.0, 1.0)])


def image_box_fraction(camera: Camera, plane: GroundPlane, objects: list[TrackedObject]) -> np.ndarray:
    """Fraction of each object's image bounding box that lies inside the image (``TemplateConfig.min_in_image``).

    The image bounding box is the box around the 8 projected corners of the object's 3D bounding box (``size``:
    length x width x height, metres, turned by its heading, standing on the ground plane), lens distortion included.
    An object with a corner behind the camera counts as outside (0).

    Args:
        camera: The tracker's ``wptrack.cameras.rig.Camera`` (its ``width`` x ``height`` pixels is the image).
        plane: The ``wptrack.cameras.rig.GroundPlane``.
        objects: ``TrackedObject`` s.

    Returns:
        (len(objects),) fractions in [0, 1].
    """
    if not objects:
        return np.zeros(0)
    return box_fraction_in_image(
        camera,
        plane,
        np.array([o.ground for o in objects], dtype=np.float64),
        np.array([o.size for o in objects], dtype=np.float64),
        np.array([o.heading for o in objects], dtype=np.float64),
    )


def box_fraction_in_image(
    camera: Camera, plane: GroundPlane, ground: np.ndarray, size: np.ndarray, heading: np.ndarray
) -> np.ndarray:
    """:func:`image_box_fraction` of objects given as arrays.

    Args:
        camera: The camera (its ``width`` x ``height`` pixels is the image).
        plane: The ground plane.
        ground: (n, 2) ground-plane positions of the objects' footprint centres, metres.
        size: (n, 3) length, width, height, metres.
        heading: (n,) headings on the ground plane, radians.

    Returns:
        (n,) fractions in [0, 1].
    """
    ground = np.asarray(ground, dtype=np.float64).reshape(-1, 2)
    if len(ground) == 0:
        return np.zeros(0)
    ok, area, inside = camera.image_box_cover(object_box_corners(plane, ground, size, heading))
    return np.where(ok, inside / area, 0.0)


def object_box_corners(plane: GroundPlane, ground: np.ndarray, size: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """The 8 world corners of each object's 3D box (the box whose image is the object's image box).

    Args:
        plane: The ground plane.
        ground: (n, 2) ground-plane positions of the footprint centres, metres.
        size: (n, 3) length, width, height, metres.
        heading: (n,) headings on the ground plane, radians.

    Returns:
        (n, 8, 3) world points, metres.
    """
    ground = np.asarray(ground, dtype=np.float64).reshape(-1, 2)
    size = np.asarray(size, dtype=np.float64).reshape(-1, 3)
    heading = np.asarray(heading, dtype=np.float64).reshape(-1)
    c = np.cos(heading)[:, None]
    s = np.sin(heading)[:, None]
    local = _BOX_CORNERS[None] * size[:, None, :]  # (n, 8, 3)
    gx = ground[:, :1] + c * local[..., 0] - s * local[..., 1]
    gy = ground[:, 1:] + s * local[..., 0] + c * local[..., 1]
    return plane.to_world(np.stack([gx, gy], axis=-1), local[..., 2])


def tracked_object(
    plane: GroundPlane, label: int, kind: int, ground: np.ndarray, dims: np.ndarray, heading: float, speed: float
) -> TrackedObject:
    """A ``TrackedObject`` of class ``CLASSES[kind - 1]`` at ground point ``ground`` (2,) metres (copied: the host
    buffers are reused every frame)."""
    return TrackedObject(
        id=int(label),
        cls=CLASSES[kind - 1],
        position=plane.to_world(ground),
        ground=np.array(ground, dtype=np.float64),
        dims=np.array(dims, dtype=np.float64),
        heading=float(heading),
        speed=float(speed),
    )


def estimate_from_host(t: TemplateTracker) -> TemplateEstimate:
    """The frame's estimate from the tracker's host copies (``t.host``, read back at the end of the chain)."""
    h = t.host
    se = h["slot_est"].numpy()
    labels = h["slot_label"].numpy()
    kinds = h["slot_kind"].numpy()
    objects = []
    for s in range(t.r):
        exist = float(se[s, kslots.SE_EXIST])
        if exist >= t.config.min_existence and se[s, kslots.SE_COUNT] > 0 and kinds[s] > 0:
            o = tracked_object(
                t.plane,
                labels[s],
                int(kinds[s]),
                se[s, kslots.SE_X : kslots.SE_X + 2],
                se[s, kslots.SE_DIMS : kslots.SE_DIMS + 3],
                se[s, kslots.SE_HEADING],
                se[s, kslots.SE_SPEED],
            )
            o.existence = exist
            o.std = se[s, kslots.SE_STD : kslots.SE_STD + 2].copy()
            o.age = float(se[s, kslots.SE_AGE])
            objects.append(o)
    for o, f in zip(objects, image_box_fraction(t.camera, t.plane, objects), strict=True):
        o.in_image = float(f)
    objects = [o for o in objects if o.in_image >= t.config.min_in_image]
    objects.sort(key=lambda o: o.id)
    bs = h["best_state"].numpy()
    best = []
    for s in range(t.r):
        k = int(bs[s, 0])
        if k > 0:
            v = bs[s, 5:7]
            speed = float(np.hypot(*v)) if k == 1 else abs(float(v[0]))
            heading = float(bs[s, 4]) + (math.pi if k >= 2 and v[0] < 0 else 0.0)
            best.append(tracked_object(t.plane, int(bs[s, 1]), k, bs[s, 2:4], bs[s, 7:10], heading, speed))
    add = h["add"].numpy()
    added = None
    if add[0] >= 0:
        added = (int(labels[add[0]]), CLASSES[int(kinds[add[0]]) - 1])
    est = TemplateEstimate(
        frame=t.frames_done,
        objects=objects,
        best=best,
        penalty=int(bs[0, 10]),
        foreground=int(h["qtotal"].numpy()[0]),
        ess=float(se[0, kslots.SE_ESS]),
        loglik=float(se[0, kslots.SE_LOGLIK]),
        added=added,
        # every log-weight -inf/NaN (floored in the score kernel): uniform weights, the predicted particles kept
        degenerate=bool(h["est"].numpy()[kreduce.EST_MAXLOGW] <= float(kreduce.LOGW_FLOOR)),
        groups=int(h["n_groups"].numpy()[0]) if t.partition else 1,
    )
    if t.keep_virtual:
        est.virtual = h["virtual"].numpy().copy()
    if t.keep_uoh:
        est.uoh = h["uoh"].numpy().copy()
    return est
