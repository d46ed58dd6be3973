"""Class-aware addition of the S3 template tracker (beyond Juza et al.; ``kernels.templates.classify`` and the
``absorb`` move of ``dynamics.template_predict_kernel``), on every device.

* ``vehicle_fit_kernel`` on the tracker's candidate set against each candidate's rendered one-slot silhouette;
* the replacement's threshold rule (in ``uoh.choose_addition_kernel``);
* the absorb move: in the particles that receive an added vehicle (the same draw as the addition), the humans on its
  footprint are removed, the others kept; off, nothing is removed.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import warp as wp
from test_kernels_templates import (
    CANDIDATE_BLOCK,
    CANDS,
    HUMAN,
    PIECES,
    VEHICLE,
    make_state,
    predict,
    quiet_dynamics,
    random_camera,
    random_mask,
    render,
)

from wptrack.cameras.rig import GroundPlane
from wptrack.cameras.structs import camera_struct
from wptrack.core.errors import ConfigError
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.templates import classify as kcls
from wptrack.kernels.templates import slots as kslots
from wptrack.kernels.templates import uoh as kuoh
from wptrack.trackers.templates.tracker import Candidates, TemplateConfig, VehiclePrior, _plane_struct

NEG_INF32 = np.float32(-3.0e38)


@pytest.mark.parametrize("block_dim", [CANDIDATE_BLOCK, 5])
def test_vehicle_fit_matches_silhouettes(device, block_dim):
    """fit = |q AND silhouette| / |silhouette| exactly (float32 of the ratio) for the vehicle candidates within the
    radius of the chosen human candidate with area >= min_area; -3e38 for every other candidate; all -3e38 when the
    chosen candidate is a vehicle or there is none."""
    rng = np.random.default_rng(11)
    cam = random_camera(rng)
    plane = GroundPlane()
    config = TemplateConfig(  # the human candidates under the image only: b below is one of them
        candidate_step_px=16, max_range=40.0, vehicle=VehiclePrior(orientations=2), human_entry_px=0
    )
    cands = Candidates(cam, plane, camera_struct(cam), _plane_struct(plane), config, device)
    h, w = cam.height, cam.width
    q = random_mask(rng, w, h) != 0
    qrow = np.zeros((h, w + 1), np.int32)
    qrow[:, 1:] = np.cumsum(q, axis=1)
    sil = render(device, cands.hulls, 1, w, h, np.arange(cands.count)).astype(bool)
    area = sil.sum(axis=(1, 2))
    fg = np.einsum("khw,hw->k", sil.astype(np.int64), q.astype(np.int64))
    humans = np.flatnonzero(cands.kind_np == HUMAN)
    b = int(humans[len(humans) // 2])
    radius, min_area = 4.0, 30

    def run(best: int, slot_est=None, slot_kind=(0, 0)) -> np.ndarray:
        est = np.zeros((2, int(kslots.NE))) if slot_est is None else slot_est
        out = wp.zeros(cands.count, dtype=wp.float32, device=device)
        wp.launch_tiled(
            kcls.vehicle_fit_kernel,
            dim=[cands.count],
            inputs=[
                cands.hulls.rows,
                cands.hulls.n,
                cands.offsets,
                cands.spans,
                cands.pixels,
                PIECES,
                cands.kind,
                cands.pos,
                cands.heading,
                wp.array([best], dtype=wp.int32, device=device),
                wp.array(qrow, dtype=wp.int32, device=device),
                radius,
                min_area,
                wp.vec3(*config.vehicle.dims_mean),
                wp.array(est, dtype=wp.float64, device=device),
                wp.array(np.asarray(slot_kind, np.int32), dtype=wp.int32, device=device),
                0.5,
            ],
            outputs=[out],
            block_dim=block_dim,
            device=device,
        )
        return out.numpy()

    got = run(b)
    near = (cands.kind_np == VEHICLE) & (np.linalg.norm(cands.pos_np - cands.pos_np[b], axis=1) <= radius)
    ok = near & (area >= min_area)
    assert ok.sum() >= 4 and (near & ~ok).sum() + (~near).sum() > 0
    np.testing.assert_array_equal(got[ok], (fg[ok] / np.maximum(area[ok], 1)).astype(np.float32))
    assert np.all(got[~ok] == NEG_INF32)
    assert 0.0 < got[ok].max() <= 1.0
    vehicles = np.flatnonzero(cands.kind_np == VEHICLE)
    assert np.all(run(int(vehicles[0])) == NEG_INF32)
    assert np.all(run(-1) == NEG_INF32)
    # a reported vehicle (existence 0.9) on candidate v blocks v and the candidates whose footprint meets it; one
    # below min_existence (slot 1) or a human slot blocks nothing
    v = int(np.flatnonzero(ok)[0])
    est = np.zeros((2, int(kslots.NE)))
    for row, exist in ((0, 0.9), (1, 0.3)):
        est[row, kslots.SE_EXIST] = exist
        est[row, kslots.SE_X : kslots.SE_X + 2] = cands.pos_np[v]
        est[row, kslots.SE_HEADING] = cands.heading_np[v]
        est[row, kslots.SE_DIMS : kslots.SE_DIMS + 3] = config.vehicle.dims_mean
    blocked = run(b, est, (VEHICLE, VEHICLE))
    assert blocked[v] == NEG_INF32
    far = ok & (np.linalg.norm(cands.pos_np - cands.pos_np[v], axis=1) > 6.0)
    np.testing.assert_array_equal(blocked[far], got[far])
    assert np.all(blocked[~ok] == NEG_INF32) and far.sum() >= 1
    np.testing.assert_array_equal(run(b, est, (HUMAN, 0)), got)


@pytest.mark.parametrize(
    ("fit", "min_fit", "expect"), [(0.8, 0.7, 9), (0.7, 0.7, 9), (0.6, 0.7, 3), (-3e38, 0.5, 3), (0.8, math.inf, 3)]
)
def test_prefer_vehicle_threshold(device, fit, min_fit, expect):
    """choose_addition_kernel's class-aware replacement: the chosen human 3 becomes the best-fitting vehicle 9 when
    its fit reaches ``min_fit`` (never with inf, never without a fit); the addition then takes the vehicle's kind."""
    fit_est = np.zeros(int(kreduce.EST_SIZE))
    fit_est[int(kreduce.EST_MAXLOGW)] = fit
    score = np.zeros(int(kreduce.EST_SIZE))
    best = wp.array([3], dtype=wp.int32, device=device)
    kind = np.full(10, HUMAN, np.int32)
    kind[9] = VEHICLE
    slot_kind = wp.zeros(2, dtype=wp.int32, device=device)
    add = wp.zeros(2, dtype=wp.int32, device=device)
    wp.launch(
        kuoh.choose_addition_kernel,
        dim=1,
        inputs=[best, wp.array(score, dtype=wp.float64, device=device), int(kreduce.EST_MAXLOGW),
                wp.array(kind, dtype=wp.int32, device=device), wp.array([1.0, 0.0], dtype=wp.float64, device=device),
                2, wp.array([9], dtype=wp.int32, device=device), wp.array(fit_est, dtype=wp.float64, device=device),
                min_fit],
        outputs=[wp.zeros(1, dtype=wp.int32, device=device), wp.zeros(2, dtype=wp.int32, device=device), slot_kind,
                 add],
        device=device,
    )  # fmt: skip
    assert int(best.numpy()[0]) == expect
    np.testing.assert_array_equal(add.numpy(), [1, expect])
    assert int(slot_kind.numpy()[1]) == kind[expect]


@pytest.mark.parametrize("absorb", [1, 0])
def test_absorb_removes_humans_on_the_added_vehicle(device, absorb):
    """Vehicle candidate 1 (at (-3, 7.5), heading 0.7) added to slot 3 with T_add = 0.4 on 4000 particles: slot 0 is
    a human on its footprint, slot 1 a human 5 m away, slot 2 a vehicle on it. With absorb, the human on the
    footprint is removed exactly in the particles that received the vehicle (their share within 4 binomial sigmas
    of T_add), the far human and the vehicle never; without absorb nobody is removed."""
    n, r, t_add = 4000, 4, 0.4
    kind = np.tile(np.array([HUMAN, HUMAN, VEHICLE, 0], np.int32), (n, 1))
    c = CANDS["pos"][1]
    pos = np.tile(np.array([c + [0.3, 0.2], c + [5.0, 0.0], c, [0, 0]], np.float32), (n, 1, 1))
    dims = np.tile(np.array([[1.7, 0.22, 0.11], [1.7, 0.22, 0.11], [4.4, 1.8, 1.5], [0, 0, 0]], np.float32), (n, 1, 1))
    src = make_state(device, n, r, kind=kind, pos=pos, dims=dims, label=np.tile(np.arange(r), (n, 1)))
    dyn = quiet_dynamics(t_add=t_add, absorb=absorb)
    got = predict(device, dyn, src, n, r, add=(3, 1))
    received = got["kind"][:, 3] == VEHICLE
    assert abs(received.mean() - t_add) < 4 * math.sqrt(t_add * (1 - t_add) / n)
    if absorb:
        np.testing.assert_array_equal(got["kind"][:, 0] == 0, received)
    else:
        assert np.all(got["kind"][:, 0] == HUMAN)
    assert np.all(got["kind"][:, 1] == HUMAN) and np.all(got["kind"][:, 2] == VEHICLE)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("vehicle_fit", 1.2),
        ("vehicle_fit", -0.1),
        ("absorb", 1),
        ("vehicle_entry_px", -8),
        ("vehicle_entry_px", 4.5),
        ("human_entry_px", -8),
        ("human_entry_px", True),
        ("min_track_frames", 0),
        ("min_track_frames", 2.5),
        ("min_track_frames", True),
    ],
)
def test_config_validated(field, value):
    with pytest.raises(ConfigError, match=field):
        TemplateConfig(**{field: value})


@pytest.mark.parametrize("widened", ["vehicle", "human"])
def test_candidates_beyond_the_border(widened: str):
    """vehicle_entry_px (human_entry_px) widens the vehicle (human) candidates' pixel grid left, right and below the
    image (objects entering the view); the other class's candidates and, with 0, its own stay under the image's
    pixels."""
    rng = np.random.default_rng(5)
    cam = random_camera(rng)
    plane = GroundPlane()
    base = TemplateConfig(
        candidate_step_px=16, max_range=60.0, vehicle=VehiclePrior(orientations=1), vehicle_entry_px=0,
        human_entry_px=0,
    )  # fmt: skip
    margin = 48
    kind, other = (VEHICLE, HUMAN) if widened == "vehicle" else (HUMAN, VEHICLE)

    def image_coords(c: Candidates, k: int) -> np.ndarray:
        g = c.pos_np[c.kind_np == k].astype(np.float64)
        world = plane.origin + g[:, :1] * plane.x_axis + g[:, 1:] * plane.y_axis
        uv, _ = cam.project(world)
        return uv

    inside = Candidates(cam, plane, camera_struct(cam), _plane_struct(plane), base, "cpu")
    wide_cfg = dataclasses.replace(base, **{f"{widened}_entry_px": margin})
    wide = Candidates(cam, plane, camera_struct(cam), _plane_struct(plane), wide_cfg, "cpu")
    for c in (inside, wide):
        uv = image_coords(c, other)
        assert np.all((uv >= -0.5) & (uv <= [cam.width + 0.5, cam.height + 0.5]))
    uv0 = image_coords(inside, kind)
    assert np.all((uv0 >= -0.5) & (uv0 <= [cam.width + 0.5, cam.height + 0.5]))
    uv = image_coords(wide, kind)
    outside = (uv[:, 0] < 0) | (uv[:, 0] > cam.width) | (uv[:, 1] > cam.height)
    assert outside.sum() > 0 and len(uv) > len(uv0)
    assert np.all(uv[:, 0] > -margin - 1) and np.all(uv[:, 0] < cam.width + margin + 1)
    assert np.all(uv[:, 1] < cam.height + margin + 1) and np.all(uv[:, 1] > -1)
