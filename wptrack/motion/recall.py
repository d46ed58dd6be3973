"""Per-object recall and false-positive pixels of motion masks against a scene's perfect silhouettes.

The pixel totals of :mod:`wptrack.motion.experiments` hide what matters to a tracker: whether *each object*
shows up in the mask. A person whose legs vanish (clothes like the paving) costs a few hundred pixels of a frame's
total but makes that person untrackable. This module attributes the perfect mask's pixels to the objects of the
ground truth and reports, per object, the fraction of its silhouette the mask covers.

Attribution (:func:`object_labels`): each ground-truth object is a box on the ground plane (``x, y, z`` the centre
of its footprint at the bottom, ``length`` along the heading ``orientation``, ``width`` across, ``height`` up,
metres), enlarged by ``pad`` metres on every side (swinging legs and arms); its eight corners are projected into
the camera and the convex hull of those in front of it is filled. A pixel of the perfect mask inside one hull
belongs to that object; inside several, to the object nearest the camera (it occludes the others); inside none,
to no object (left out of the recall, still not a false positive).

Per frame and object (:func:`score_frame`): ``true`` = its labelled pixels, ``hit`` = those the mask marks as
foreground. Per frame: ``fp`` = mask pixels outside the perfect mask, ``fp_far`` = mask pixels farther than
``far_px`` pixels from the perfect mask (shadows, ghosts, noise; not the mask's edge a pixel or two off).

Summary per object (:func:`mask_recall`): ``recall`` = mean over the frames where it has at least ``min_pixels``
labelled pixels of ``hit / true``; ``pixel_recall`` = ``sum hit / sum true`` over those frames.

Command (one row per object)::

    python3 -m wptrack.motion.recall --scene-dir SCENE/s0 --masks SCENE/s0/masks-offline/masks.avi [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wptrack.cameras.rig import Camera

__all__ = ["GroundTruthFrames", "mask_recall", "object_labels", "score_frame", "scene_recall"]


@dataclass(frozen=True)
class GroundTruthFrames:
    """Ground-truth objects per frame: ``rows[frame]`` is an ``(N, 8)`` float array of
    ``id, x, y, z, length, width, height, orientation`` (metres, radians)."""

    rows: Mapping[int, np.ndarray]

    @classmethod
    def from_columns(cls, cols: Mapping[str, np.ndarray]) -> GroundTruthFrames:
        """From ``groundtruth.csv`` columns (:func:`wptrack.io.tables.read_tracks`)."""
        names = ("id", "x", "y", "z", "length", "width", "height", "orientation")
        table = np.stack([np.asarray(cols[n], dtype=np.float64) for n in names], axis=1)
        frames = np.asarray(cols["frame"], dtype=np.int64)
        return cls({int(f): table[frames == f] for f in np.unique(frames)})

    @classmethod
    def read(cls, path: str | os.PathLike) -> GroundTruthFrames:
        from wptrack.io.tables import read_tracks

        return cls.from_columns(read_tracks(path))

    def frame(self, index: int) -> np.ndarray:
        return self.rows.get(int(index), np.zeros((0, 8)))


def _box_corners(row: np.ndarray, pad: float) -> np.ndarray:
    """``(8, 3)`` world corners of one object's padded box (see the module docstring)."""
    _, x, y, z, length, width, height, theta = row
    c, s = np.cos(theta), np.sin(theta)
    hl, hw = length / 2 + pad, width / 2 + pad
    out = []
    for dl in (-hl, hl):
        for dw in (-hw, hw):
            for h in (z, z + height + pad):
                out.append((x + c * dl - s * dw, y + s * dl + c * dw, h))
    return np.asarray(out)


def object_labels(
    perfect: np.ndarray, objects: np.ndarray, camera: Camera, pad: float = 0.15
) -> tuple[np.ndarray, list[int]]:
    """Attribute the perfect mask's pixels to ground-truth objects.

    Args:
        perfect: ``(H, W)`` bool perfect foreground mask.
        objects: ``(N, 8)`` rows ``id, x, y, z, length, width, height, orientation`` (:class:`GroundTruthFrames`).
        camera: The camera that made the image.
        pad: Box enlargement on every side and on top, metres.

    Returns:
        ``(labels, ids)``: ``(H, W)`` int32, ``k + 1`` on the perfect-mask pixels of object ``ids[k]``, 0 elsewhere.
    """
    import cv2

    h, w = perfect.shape
    labels = np.zeros((h, w), dtype=np.int32)
    depth = np.full((h, w), np.inf)
    ids = [int(r[0]) for r in objects]
    for k, row in enumerate(objects):
        corners = _box_corners(row, pad)
        uv, d = camera.project(corners)
        front = d > 0.05
        if front.sum() < 3:
            continue
        hull = cv2.convexHull(np.round(uv[front]).astype(np.int32))
        area = np.zeros((h, w), dtype=np.uint8)
        cv2.fillConvexPoly(area, hull, 1)
        centre = float(np.mean(d[front]))
        take = (area > 0) & perfect & (centre < depth)
        labels[take] = k + 1
        depth[take] = centre
    return labels, ids


def score_frame(
    mask: np.ndarray, perfect: np.ndarray, labels: np.ndarray, ids: Sequence[int], far_px: int = 5
) -> tuple[dict[int, tuple[int, int]], int, int]:
    """One frame's counts.

    Args:
        mask: ``(H, W)`` mask (foreground: > 0).
        perfect: ``(H, W)`` bool perfect mask.
        labels, ids: From :func:`object_labels`.
        far_px: Distance (pixels) from the perfect mask beyond which a false positive counts as far.

    Returns:
        ``({id: (hit, true)}, fp, fp_far)``.
    """
    import cv2

    m = mask > 0
    counts_true = np.bincount(labels.ravel(), minlength=len(ids) + 1)
    counts_hit = np.bincount(labels[m].ravel(), minlength=len(ids) + 1)
    per = {oid: (int(counts_hit[k + 1]), int(counts_true[k + 1])) for k, oid in enumerate(ids)}
    fp = int(np.count_nonzero(m & ~perfect))
    if far_px > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * far_px + 1, 2 * far_px + 1))
        near = cv2.dilate(perfect.astype(np.uint8), kernel) > 0
    else:
        near = perfect
    return per, fp, int(np.count_nonzero(m & ~near))


def mask_recall(
    masks: Iterable[np.ndarray],
    perfect: Iterable[np.ndarray],
    groundtruth: GroundTruthFrames,
    camera: Camera,
    *,
    pad: float = 0.15,
    min_pixels: int = 50,
    far_px: int = 5,
) -> dict[str, Any]:
    """Per-object recall and per-frame false positives of a mask sequence (see the module docstring).

    Args:
        masks: Masks per frame, ``(H, W)`` (foreground: > 0).
        perfect: Perfect masks per frame, ``(H, W)`` (foreground: > 0), as many as ``masks``.
        groundtruth: The objects per frame.
        camera: The camera.
        pad: Box padding for the attribution, metres.
        min_pixels: An object enters the recall of a frame where it has at least this many labelled pixels.
        far_px: See :func:`score_frame`.

    Returns:
        ``{"frames", "objects": {id: {"frames", "recall", "pixel_recall", "min_recall"}}, "fp_per_frame",
        "fp_far_per_frame", "fp_far_max", "recall_per_frame": {id: [(frame, recall), ...]}}``.
    """
    hits: dict[int, list[int]] = {}
    trues: dict[int, list[int]] = {}
    frames_of: dict[int, list[int]] = {}
    fps: list[int] = []
    fars: list[int] = []
    n = 0
    for t, (mask, ref) in enumerate(zip(masks, perfect, strict=True)):
        p = np.asarray(ref)
        p = (p.max(axis=2) if p.ndim == 3 else p) > 0
        m = np.asarray(mask)
        m = (m.max(axis=2) if m.ndim == 3 else m) > 0
        labels, ids = object_labels(p, groundtruth.frame(t), camera, pad)
        per, fp, far = score_frame(m, p, labels, ids, far_px)
        for oid, (hit, true) in per.items():
            if true >= min_pixels:
                hits.setdefault(oid, []).append(hit)
                trues.setdefault(oid, []).append(true)
                frames_of.setdefault(oid, []).append(t)
        fps.append(fp)
        fars.append(far)
        n += 1
    objects = {}
    per_frame = {}
    for oid in sorted(hits):
        h = np.asarray(hits[oid], dtype=np.float64)
        tr = np.asarray(trues[oid], dtype=np.float64)
        r = h / tr
        objects[oid] = {
            "frames": len(r),
            "recall": float(r.mean()),
            "pixel_recall": float(h.sum() / tr.sum()),
            "min_recall": float(r.min()),
        }
        per_frame[oid] = [(f, float(v)) for f, v in zip(frames_of[oid], r, strict=True)]
    return {
        "frames": n,
        "objects": objects,
        "fp_per_frame": float(np.mean(fps)) if fps else float("nan"),
        "fp_far_per_frame": float(np.mean(fars)) if fars else float("nan"),
        "fp_far_max": int(max(fars)) if fars else 0,
        "recall_per_frame": per_frame,
    }


def scene_recall(
    scene_dir: str | os.PathLike,
    masks: str | os.PathLike | np.ndarray | Iterable[np.ndarray],
    camera: str = "cam0",
    **kwargs: Any,
) -> dict[str, Any]:
    """:func:`mask_recall` of a rendered scene folder (``rig.yaml``, ``groundtruth.csv``, ``<camera>_mask.avi``).

    Args:
        scene_dir: The scene folder (``wptrack synth`` output).
        masks: A mask video/folder path or array, or any iterable of masks (e.g. a :class:`MotionMasks`).
        camera: Camera name in the rig.
        **kwargs: Passed to :func:`mask_recall`.
    """
    from pathlib import Path

    from wptrack.cameras.rig import Rig
    from wptrack.io.frames import open_source

    d = Path(scene_dir)
    cam = Rig.load(d / "rig.yaml")[camera]
    gt = GroundTruthFrames.read(d / "groundtruth.csv")
    perfect = open_source(d / f"{camera}_mask.avi")
    source = open_source(masks) if isinstance(masks, (str, os.PathLike, np.ndarray)) else masks
    return mask_recall(source, perfect, gt, cam, **kwargs)


def markdown(result: Mapping[str, Any]) -> str:
    """A markdown table of :func:`mask_recall`'s result: one row per object, then the false positives."""
    lines = ["| object | frames | recall (mean) | pixel recall | min |", "|---|---|---|---|---|"]
    for oid, o in result["objects"].items():
        lines.append(f"| {oid} | {o['frames']} | {o['recall']:.3f} | {o['pixel_recall']:.3f} | {o['min_recall']:.3f} |")
    lines.append(
        f"\nfalse-positive pixels per frame: {result['fp_per_frame']:.1f} "
        f"(farther than the edge: {result['fp_far_per_frame']:.1f}, max {result['fp_far_max']})"
    )
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: per-object recall of a mask video against a scene's perfect masks."""
    p = argparse.ArgumentParser(prog="python3 -m wptrack.motion.recall", description=__doc__.split("\n")[0])
    p.add_argument("--scene-dir", required=True, help="rendered scene folder (rig.yaml, groundtruth.csv, masks)")
    p.add_argument("--masks", required=True, help="mask video or folder to score")
    p.add_argument("--camera", default="cam0")
    p.add_argument("--json", default=None, help="also write the result here")
    args = p.parse_args(argv)
    result = scene_recall(args.scene_dir, args.masks, args.camera)
    print(markdown(result))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({k: v for k, v in result.items() if k != "recall_per_frame"}, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
