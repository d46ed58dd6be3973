"""Occlusion-aware prediction of the S3 template tracker (beyond Juza et al.; ``kernels.templates.occlusion`` and the
occlusion/size terms of ``dynamics.template_predict_kernel``), on every device.

* ``occlusion_kernel`` against a float64 NumPy reference of its box formula on random scenes, and on a scene whose
  answer is known (one person right behind another, two people far apart, an object outside the image);
* deletion rates and noise deviations of hidden objects in binomial / normal 4-sigma bands;
* the mean-reverting size (``dims_revert``), exactly;
* the config fields' validation.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import warp as wp
from test_kernels_templates import (
    HUMAN,
    VEHICLE,
    e2e_rig,
    make_state,
    predict,
    quiet_dynamics,
    random_camera,
    random_scene,
    raster,
)

from wptrack.cameras.rig import GroundPlane
from wptrack.core.errors import ConfigError
from wptrack.kernels.templates import occlusion as kocc
from wptrack.kernels.templates import raster as kraster
from wptrack.trackers.templates.tracker import TemplateConfig

PIECES = int(kraster.PIECES)


def occlusion(device, hulls, n: int, r: int, width: int, height: int) -> np.ndarray:
    out = wp.full((n, r), -1.0, dtype=wp.float32, device=device)
    wp.launch(
        kocc.occlusion_kernel,
        dim=(n, r),
        inputs=[hulls.pts, hulls.n, hulls.depth, width, height],
        outputs=[out],
        device=device,
    )
    return out.numpy()


def occlusion_ref(pts: np.ndarray, cnt: np.ndarray, depth: np.ndarray, r: int, width: int, height: int) -> np.ndarray:
    """The module docstring's formula in float64 from the hulls (N, R*PIECES, HULL_MAX, 2), counts and depths."""
    n = cnt.shape[0]
    out = np.zeros((n, r))

    def box(i, q):
        p = pts[i, q, : cnt[i, q]].astype(np.float64)
        return (
            np.clip(p[:, 0].min(), 0, width),
            np.clip(p[:, 0].max(), 0, width),
            np.clip(p[:, 1].min(), 0, height),
            np.clip(p[:, 1].max(), 0, height),
        )

    def inter(a, b):
        return max(min(a[1], b[1]) - max(a[0], b[0]), 0.0) * max(min(a[3], b[3]) - max(a[2], b[2]), 0.0)

    for i in range(n):
        for s in range(r):
            own = [box(i, s * PIECES + a) for a in range(PIECES) if cnt[i, s * PIECES + a] > 0]
            area = sum(max(b[1] - b[0], 0.0) * max(b[3] - b[2], 0.0) for b in own)
            if area <= 0:
                continue
            d = depth[i, s * PIECES]
            hidden = 0.0
            for t in range(r):
                dt = depth[i, t * PIECES]
                if t == s or not (dt < d or (dt == d and t < s)):
                    continue
                for b in range(PIECES):
                    if cnt[i, t * PIECES + b] > 0:
                        bt = box(i, t * PIECES + b)
                        hidden += sum(inter(a, bt) for a in own)
            out[i, s] = min(hidden / area, 1.0)
    return out


def test_occlusion_matches_numpy(device):
    rng = np.random.default_rng(7)
    plane = GroundPlane()
    cam = random_camera(rng, plane=plane)
    n, r = 24, 5
    kind, pos, heading, dims = random_scene(rng, cam, plane, n, r)
    hulls = raster(device, cam, plane, kind, pos, heading, dims)
    got = occlusion(device, hulls, n, r, cam.width, cam.height)
    ref = occlusion_ref(hulls.pts.numpy(), hulls.n.numpy(), hulls.depth.numpy(), r, cam.width, cam.height)
    np.testing.assert_allclose(got, ref, atol=2e-4)
    assert np.all(got[kind == 0] == 0.0)
    assert 0.05 < np.mean(got[kind > 0] > 0) < 0.95  # the scenes have hidden and unhidden objects (not vacuous)


def test_occlusion_known_scene(device):
    """The e2e camera looks down along +y: a person 0.4 m behind another on the same line of sight is mostly hidden, the
    front one not at all; a person 4 m to the side is not hidden; an object far outside the image has occlusion 0;
    an empty slot 0."""
    cam = e2e_rig()["cam0"]
    plane = GroundPlane()
    man = [1.75, 0.22, 0.11]
    kind = np.array([[HUMAN, HUMAN, HUMAN, VEHICLE, 0]])
    pos = np.array([[[0.0, 6.0], [0.0, 6.4], [4.0, 6.4], [200.0, 7.0], [0.0, 0.0]]])
    dims = np.array([[man, man, man, [4.4, 1.8, 1.5], [0, 0, 0]]])
    hulls = raster(device, cam, plane, kind, pos, np.zeros((1, 5)), dims)
    got = occlusion(device, hulls, 1, 5, cam.width, cam.height)[0]
    assert got[0] == 0.0 and got[2] == 0.0 and got[3] == 0.0 and got[4] == 0.0
    assert got[1] > 0.6


def test_predict_deletion_lowered_by_occlusion(device):
    """T_del = 0.3, occlusion_del = 1 and 0.5 on 3000 particles: objects hidden 0, 0.5 and 1 are deleted at T_del (1 -
    occlusion_del o), within 4 binomial sigmas; with occlusion_del = 0 every slot is deleted at T_del (eq. 13)."""
    n, r = 3000, 3
    kind = np.full((n, r), HUMAN, np.int32)
    dims = np.tile(np.array([1.7, 0.22, 0.11], np.float32), (n, r, 1))
    occ = np.tile(np.array([0.0, 0.5, 1.0], np.float32), (n, 1))
    src = make_state(device, n, r, kind=kind, label=np.zeros((n, r)), dims=dims)
    for w in (1.0, 0.5, 0.0):
        got = predict(device, quiet_dynamics(t_del=0.3, occlusion_del=w), src, n, r, occlusion=occ)
        for s, o in enumerate((0.0, 0.5, 1.0)):
            p = 0.3 * (1.0 - w * o)
            rate = (got["kind"][:, s] == 0).mean()
            assert abs(rate - p) <= 4 * math.sqrt(p * (1 - p) / n) + 1e-12, (w, o, rate, p)


def test_predict_noise_lowered_by_occlusion(device):
    """occlusion_noise = 0.6 with a slot hidden 0.5 (scale 0.7) and one hidden 1 (scale 0.4) on 4000 particles: the
    human velocity change and the vehicle speed and turn changes have deviations sigma x (1 - 0.6 o) within 4 /
    sqrt(2N) relative; occlusion_noise = 0 leaves them at sigma."""
    n, r = 4000, 2
    sh, sv, st = 0.25, 0.6, 0.15
    kind = np.tile(np.array([HUMAN, VEHICLE], np.int32), (n, 1))
    dims = np.tile(np.array([[1.7, 0.25, 0.11], [4.4, 1.8, 1.5]], np.float32), (n, 1, 1))
    vel = np.tile(np.array([[0.5, -0.3], [5.0, 0.1]], np.float32), (n, 1, 1))
    src = make_state(device, n, r, kind=kind, dims=dims, vel=vel, label=np.zeros((n, r)))
    for w, o in ((0.6, 0.5), (0.6, 1.0), (0.0, 1.0)):
        dyn = quiet_dynamics(
            sigma_speed=wp.vec3(0.0, sh, sv),
            sigma_turn=st,
            speed_max=wp.vec3(1.0, 1e6, 1e6),
            turn_max=1e6,
            occlusion_noise=w,
        )
        got = predict(device, dyn, src, n, r, occlusion=np.full((n, r), o))
        scale = 1.0 - w * o
        for x, sigma in (
            (got["vel"][:, 0, 0] - 0.5, sh),
            (got["vel"][:, 0, 1] + 0.3, sh),
            (got["vel"][:, 1, 0] - 5.0, sv),
            (got["vel"][:, 1, 1] - 0.1, st),
        ):
            assert abs(np.std(x) / (scale * sigma) - 1) < 4 / math.sqrt(2 * n)


def test_predict_dims_revert_exact(device):
    """Without noise, dims_revert k moves each dimension by k (mean - d) (float32), both kinds."""
    n, r, k = 8, 2, 0.05
    dyn = quiet_dynamics(dims_revert=k)
    kind = np.tile(np.array([HUMAN, VEHICLE], np.int32), (n, 1))
    rng = np.random.default_rng(3)
    dims = np.stack(
        [rng.uniform([1.3, 0.12, 0.08], [2.0, 0.3, 0.14], (n, 3)), rng.uniform([3.2, 1.5, 1.2], [6, 2.3, 2.2], (n, 3))],
        axis=1,
    ).astype(np.float32)
    got = predict(device, dyn, make_state(device, n, r, kind=kind, dims=dims), n, r)["dims"]
    for s, mean in ((0, dyn.dims_mean_human), (1, dyn.dims_mean_vehicle)):
        m = np.array(mean, np.float64)
        np.testing.assert_allclose(got[:, s], dims[:, s] + k * (m - dims[:, s]), atol=1e-5)


@pytest.mark.parametrize("field", ["occlusion_del", "occlusion_noise", "dims_revert"])
@pytest.mark.parametrize("value", [-0.1, 1.5, "x", float("nan")])
def test_config_fields_validated(field, value):
    with pytest.raises(ConfigError, match=field):
        TemplateConfig(**{field: value})
