"""Per-object recall of motion masks (wptrack.motion.recall): attribution of the perfect mask to ground-truth boxes,
occlusion by the nearer object, recall and false positives per frame."""

from __future__ import annotations

import numpy as np

from wptrack.cameras.rig import Camera
from wptrack.motion.recall import GroundTruthFrames, mask_recall, object_labels, score_frame


def _camera() -> Camera:
    return Camera.look_at("cam0", 160, 120, position=(0.0, -10.0, 4.0), target=(0.0, 2.0, 0.0), fx=150.0)


def _silhouette(cam: Camera, x: float, y: float, h: float = 1.7, r: float = 0.25) -> np.ndarray:
    """Perfect mask of a vertical box (r x r x h) standing at (x, y): its projected convex hull."""
    import cv2

    pts = np.array([[x + dx, y + dy, z] for dx in (-r, r) for dy in (-r, r) for z in (0.0, h)])
    uv, _ = cam.project(pts)
    out = np.zeros((cam.height, cam.width), np.uint8)
    cv2.fillConvexPoly(out, cv2.convexHull(np.round(uv).astype(np.int32)), 1)
    return out > 0


def test_labels_follow_boxes_and_occlusion():
    cam = _camera()
    far = _silhouette(cam, 0.8, 6.0)
    near = _silhouette(cam, 0.2, 2.0)
    perfect = far | near
    rows = np.array([[7, 0.8, 6.0, 0, 0.5, 0.5, 1.7, 0.0], [3, 0.2, 2.0, 0, 0.5, 0.5, 1.7, 0.0]])
    labels, ids = object_labels(perfect, rows, cam, pad=0.0)  # boxes = the silhouettes
    assert ids == [7, 3]
    assert np.all(labels[near] == 2)  # the nearer object owns the overlap
    assert np.all(labels[far & ~near] == 1)
    assert np.all(labels[~perfect] == 0)
    padded, _ = object_labels(perfect, rows, cam)  # the padded near box takes a rim of the far object
    assert np.all(padded[near] == 2) and 0.6 < np.mean(padded[far & ~near] == 1) < 1.0


def test_recall_and_false_positives():
    cam = _camera()
    a = _silhouette(cam, -1.5, 4.0)
    b = _silhouette(cam, 1.5, 4.0)
    perfect = a | b
    rows = np.array([[0, -1.5, 4.0, 0, 0.5, 0.5, 1.7, 0.0], [1, 1.5, 4.0, 0, 0.5, 0.5, 1.7, 0.0]])
    labels, ids = object_labels(perfect, rows, cam)
    mask = a.copy()
    ys, xs = np.nonzero(b)
    keep = ys < np.median(ys)  # the top half of b only (its legs vanish)
    mask[ys[keep], xs[keep]] = True
    mask[2:6, 2:6] = True  # 16 false pixels far from any object
    per, fp, far = score_frame(mask, perfect, labels, ids)
    assert per[0] == (int(a.sum()), int(a.sum()))
    assert 0.35 < per[1][0] / per[1][1] < 0.65
    assert fp == 16 and far == 16
    gt = GroundTruthFrames({0: rows, 1: rows})
    res = mask_recall([mask, a], [perfect, perfect], gt, cam)
    assert res["frames"] == 2 and res["objects"][0]["recall"] == 1.0
    assert res["objects"][1]["min_recall"] == 0.0 and 0.15 < res["objects"][1]["recall"] < 0.35
    assert res["fp_per_frame"] == 8.0 and res["fp_far_max"] == 16


def test_groundtruth_from_columns():
    cols = {
        "frame": np.array([0, 0, 2]),
        "id": np.array([1, 2, 1]),
        **{k: np.zeros(3) for k in ("x", "y", "z", "orientation")},
        **{k: np.ones(3) for k in ("length", "width", "height")},
    }
    gt = GroundTruthFrames.from_columns(cols)
    assert gt.frame(0).shape == (2, 8) and gt.frame(1).shape == (0, 8) and gt.frame(2)[0, 0] == 1
