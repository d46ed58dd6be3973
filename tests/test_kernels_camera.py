"""Projection @wp.func against cv2.projectPoints (distortion included), on every device."""

from __future__ import annotations

import cv2
import kernel_harness as harness
import numpy as np
import warp as wp

from wptrack.cameras.rig import Camera, Rig
from wptrack.cameras.structs import DeviceRig, fold_radius2


def random_camera(rng: np.random.Generator, name: str = "c") -> Camera:
    w, h = int(rng.integers(160, 800)), int(rng.integers(120, 600))
    pos = rng.uniform(-2, 2, 3)
    target = pos + (rng.normal(size=3) + np.array([0, 2.0, 0]))
    # realistic lenses: the distortion stays monotonic over the image (a calibration that folds is invalid)
    dist = np.array(
        [
            rng.uniform(-0.15, 0.05),
            rng.uniform(-0.05, 0.05),
            rng.uniform(-2e-3, 2e-3),
            rng.uniform(-2e-3, 2e-3),
            rng.uniform(-0.01, 0.01),
        ]
    )
    fx = float(rng.uniform(0.8, 1.4) * w)
    return Camera.look_at(
        name,
        w,
        h,
        pos,
        target,
        fx,
        fy=fx * rng.uniform(0.95, 1.05),
        cx=w / 2 + rng.uniform(-10, 10),
        cy=h / 2 + rng.uniform(-10, 10),
        roll_deg=float(rng.uniform(-20, 20)),
        dist=dist,
    )


def points_in_view(cam: Camera, rng: np.random.Generator, n: int) -> np.ndarray:
    """World points whose projections fall inside the image (sampled in the image, random depth)."""
    uv = np.column_stack([rng.uniform(0, cam.width - 1, n), rng.uniform(0, cam.height - 1, n)])
    und = cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.K, cam.dist).reshape(-1, 2)
    depth = rng.uniform(0.2, 10.0, n)
    xc = np.column_stack([und * depth[:, None], depth])
    return (xc - cam.t) @ cam.R  # R^T (xc - t)


def test_project_matches_opencv(device, rng):
    cams = [random_camera(rng, f"c{i}") for i in range(4)]
    rig = Rig(tuple(cams))
    drig = DeviceRig(rig, device)
    pts = np.concatenate([points_in_view(c, rng, 300) for c in cams])
    out = wp.zeros((len(cams), len(pts)), dtype=wp.vec3, device=device)
    wp.launch(
        harness.project_kernel,
        dim=(len(cams), len(pts)),
        inputs=[drig.cams, wp.array(pts, dtype=wp.vec3, device=device)],
        outputs=[out],
        device=device,
    )
    got = out.numpy()
    checked = 0
    for c, cam in enumerate(cams):
        uv, depth = cam.project(pts)
        inside = (
            (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height - 1)
        )
        xc = pts @ cam.R.T + cam.t
        r2 = np.sum((xc[:, :2] / xc[:, 2:]) ** 2, axis=1)
        folded = inside & (r2 > fold_radius2(cam.dist))
        # cv2 "projects" points far outside the field of view back into the image where the distortion
        # polynomial folds; the kernel reports them as not seen.
        assert np.all(got[c, folded, 2] <= 0)
        inside &= ~folded
        assert np.all(got[c, inside, 2] > 0), "points inside the image must be seen"
        err = np.abs(got[c, inside, :2] - uv[inside]).max()
        assert err < 0.01, f"camera {c}: max deviation from cv2.projectPoints {err:.4f} px"
        np.testing.assert_allclose(got[c, inside, 2], depth[inside], rtol=1e-5)
        checked += int(inside.sum())
    assert checked >= 300


def test_behind_camera_not_seen(device, rng):
    cam = random_camera(rng)
    drig = DeviceRig(Rig((cam,)), device)
    behind = cam.center + (-(cam.R[2]) * rng.uniform(0.1, 5, (50, 1)))  # along the negative optical axis
    out = wp.zeros((1, 50), dtype=wp.vec3, device=device)
    wp.launch(
        harness.project_kernel,
        dim=(1, 50),
        inputs=[drig.cams, wp.array(behind, dtype=wp.vec3, device=device)],
        outputs=[out],
        device=device,
    )
    assert np.all(out.numpy()[0, :, 2] <= 0)


def test_fold_radius():
    assert fold_radius2(np.zeros(5)) == float("inf")
    k1 = -0.3
    # d/dr (r + k1 r^3) = 1 + 3 k1 r^2 = 0  ->  r^2 = -1 / (3 k1)
    np.testing.assert_allclose(fold_radius2(np.array([k1, 0, 0, 0, 0])), -1 / (3 * k1), rtol=1e-3)
