"""``raster.render_labels_kernel`` (the best particle's labelled virtual scene, for reports: Fig. 5 of Juza et al.)
against a NumPy painter's algorithm on every device: the float64 reference hulls of test_kernels_templates (cv2
projections, monotone chain, pixel centres in the closed hull) painted farthest first by the float64 depth of each
object's ground point, so that where objects overlap the nearest one's label (slot + 1) shows; 0 elsewhere."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from test_kernels_templates import (
    PIECES,
    TILTED,
    camera_r2,
    hull_pixels,
    random_camera,
    random_scene,
    raster,
    reference_scene,
)

from wptrack.cameras.rig import GroundPlane
from wptrack.kernels.templates import raster as kraster


def render_labels(device, hulls, r: int, width: int, height: int, best: int) -> np.ndarray:
    out = wp.full((height, width), 7, dtype=wp.uint8, device=device)  # 7: catches unwritten pixels
    best_dev = wp.array([best], dtype=wp.int32, device=device)
    wp.launch(
        kraster.render_labels_kernel,
        dim=height,
        inputs=[hulls.pts, hulls.n, hulls.rows, hulls.depth, r * PIECES, best_dev],
        outputs=[out],
        device=device,
    )
    return out.numpy()


def labels_ref(cam, plane, kind, pos, pieces, i: int):
    """(labels (H, W) uint8, near (H, W) bool, overlap pixels) of particle ``i`` by the painter's algorithm."""
    r = kind.shape[1]
    labels = np.zeros((cam.height, cam.width), np.uint8)
    near = np.zeros((cam.height, cam.width), bool)
    hits = np.zeros((cam.height, cam.width), int)
    depth = np.array([camera_r2(cam, plane.to_world(np.asarray(pos[i, s], np.float64))[None])[0][0] for s in range(r)])
    drawn = [s for s in range(r) if any(pieces[i][s * PIECES + p] is not None for p in range(PIECES))]
    d = depth[drawn]
    assert len(d) < 2 or np.min(np.abs(d[:, None] - d[None, :]) + np.eye(len(d))) > 1e-4 * d.max()  # no depth ties
    for s in sorted(drawn, key=lambda s: -depth[s]):  # farthest first
        cover = np.zeros_like(near)
        for p in range(PIECES):
            ref = pieces[i][s * PIECES + p]
            if ref is not None:
                inside, edge = hull_pixels(ref["hull"], cam.width, cam.height)
                cover |= inside
                near |= edge
        labels[cover] = s + 1
        hits += cover
    return labels, near, int((hits > 1).sum())


@pytest.mark.parametrize("tilted", [False, True], ids=["z0", "tilted"])
def test_render_labels_matches_painters_algorithm(device, rng, tilted):
    plane = TILTED if tilted else GroundPlane()
    overlap = covered = 0
    for _ in range(2):
        cam = random_camera(rng, plane=plane)
        n, r = 4, 4
        kind, pos, heading, dims = random_scene(rng, cam, plane, n, r, p_empty=0.15)
        kind[3] = 0  # an empty particle
        hulls = raster(device, cam, plane, kind, pos, heading, dims)
        _, _, pieces = reference_scene(cam, plane, kind, pos, heading, dims)
        for i in range(n):
            got = render_labels(device, hulls, r, cam.width, cam.height, i)
            ref, near, ov = labels_ref(cam, plane, kind, pos, pieces, i)
            assert near.sum() <= 0.01 * near.size
            mismatch = np.argwhere((got != ref) & ~near)
            assert len(mismatch) == 0, f"particle {i}: {len(mismatch)} pixels differ, first (v, u) {mismatch[:5]}"
            overlap += ov
            covered += int((ref > 0).sum())
        assert not render_labels(device, hulls, r, cam.width, cam.height, 3).any()
    assert covered > 3000 and overlap > 100, (covered, overlap)  # occlusions were exercised
