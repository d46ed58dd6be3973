"""S2 people-tracker kernels not covered (or only statistically / through other kernels) by test_kernels_people.py,
against NumPy references on every device: the birth draw uniform in a vertical cylinder (``init_cylinder_kernel``:
exact against a NumPy Philox, and statistically: radial CDF r^2/R^2, uniform angle and height), the estimate ->
ground position copy
(``person_xy_kernel``), the constant-velocity draw of ``predict_kernel`` (eq. 5) draw by draw, and
``score_moments_kernel`` (eq. 11 = eqs. 9-10 + eqs. 23-26, plus the person-level terms of kernels/coverage.py, and
its block partials, MAP index included)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from kernel_refs import check_partials, normal4_ref, uniform4_ref
from scipy import stats
from test_kernels_people import (
    NB,
    appearance_ref,
    make_rig,
    motion_masks,
    motion_ref,
    person_inputs,
    person_terms_ref,
    project_all,
    random_frames,
    random_histograms,
    random_points,
    run_descriptor,
    run_predict,
)

from wptrack.cameras.structs import DeviceRig
from wptrack.kernels.core import random as krand
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.people import filter as kpeople

# ------------------------------------------------------------------------------------------ birth cylinder


def init_cylinder(device, centre, radius, z_lo, z_hi, seed, frame, n, speed=0.0):
    pos = wp.full(n, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device)
    vel = wp.full(n, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device)
    wp.launch(
        kpeople.init_cylinder_kernel,
        dim=n,
        inputs=[wp.vec3(*centre), radius, z_lo, z_hi, speed, wp.vec2ui(*seed), frame],
        outputs=[pos, vel],
        device=device,
    )
    return pos.numpy().astype(np.float64), vel.numpy()


def test_init_cylinder_matches_numpy_philox(device):
    """Exact draw: r = R sqrt(u0), angle 2 pi u1, z = z_lo + (z_hi - z_lo) u2 of the (seed, i, frame, STREAM_MOTION)
    Philox block; the centre's z is ignored (heights are absolute); the horizontal velocity speed (z0, z1) of the
    (seed, i, frame, STREAM_INIT) normals (0 with speed 0), no vertical velocity."""
    n, seed, frame = 1000, (123, 456), 9
    centre, radius, z_lo, z_hi = (2.0, -1.0, 5.0), 0.3, 0.2, 1.6
    pos, vel = init_cylinder(device, centre, radius, z_lo, z_hi, seed, frame, n)
    u = uniform4_ref(seed, n, frame, int(krand.STREAM_MOTION))
    r = radius * np.sqrt(u[:, 0])
    a = 2 * np.pi * u[:, 1]
    ref = np.column_stack([centre[0] + r * np.cos(a), centre[1] + r * np.sin(a), z_lo + (z_hi - z_lo) * u[:, 2]])
    np.testing.assert_allclose(pos, ref, rtol=0, atol=2e-6)
    np.testing.assert_array_equal(vel, 0.0)
    pos2, vel2 = init_cylinder(device, centre, radius, z_lo, z_hi, seed, frame, n, speed=1.5)
    np.testing.assert_array_equal(pos2, pos)  # the velocities do not change the positions' draws
    zv = normal4_ref(seed, n, frame, int(krand.STREAM_INIT))
    np.testing.assert_allclose(vel2[:, :2], 1.5 * zv[:, :2], rtol=1e-6, atol=1e-5)  # float32 products of normals
    np.testing.assert_array_equal(vel2[:, 2], 0.0)


def test_init_cylinder_is_uniform_in_the_cylinder(device):
    """Statistics of 20000 draws (fixed seed): r^2 / R^2, the angle / 2 pi and (z - z_lo) / (z_hi - z_lo) are each
    U(0, 1) (Kolmogorov-Smirnov, p > 1e-3; the 1 % critical D is 0.0115: drawing r = R u instead of R sqrt(u) gives
    D = 0.25), pairwise uncorrelated, all inside the cylinder; another frame or seed gives other draws."""
    n, seed, frame = 20_000, (2026, 11), 3
    centre, radius, z_lo, z_hi = (0.5, 1.5, 0.0), 0.25, 0.3, 1.8
    pos, vel = init_cylinder(device, centre, radius, z_lo, z_hi, seed, frame, n)
    dx, dy = pos[:, 0] - centre[0], pos[:, 1] - centre[1]
    r2 = (dx**2 + dy**2) / radius**2
    ang = np.mod(np.arctan2(dy, dx), 2 * np.pi) / (2 * np.pi)
    zu = (pos[:, 2] - z_lo) / (z_hi - z_lo)
    assert r2.max() <= 1 + 1e-5 and zu.min() >= 0 and zu.max() <= 1
    for name, v in (("r^2/R^2", r2), ("angle", ang), ("z", zu)):
        res = stats.kstest(v, "uniform")
        assert res.pvalue > 1e-3, f"{name}: KS D = {res.statistic:.4f}, p = {res.pvalue:.2e}"
    c = np.corrcoef(np.vstack([r2, ang, zu]))
    assert np.abs(c - np.eye(3)).max() < 0.03  # 4 sigma of a correlation estimate from 20000 pairs is 0.028
    # mean position is the centre: x, y within 4 standard errors (std of x is R / 2)
    assert abs(dx.mean()) < 4 * radius / 2 / np.sqrt(n) and abs(dy.mean()) < 4 * radius / 2 / np.sqrt(n)
    np.testing.assert_array_equal(vel, 0.0)
    other_frame, _ = init_cylinder(device, centre, radius, z_lo, z_hi, seed, frame + 1, 1000)
    other_seed, _ = init_cylinder(device, centre, radius, z_lo, z_hi, (2026, 12), frame, 1000)
    assert not np.any(np.all(other_frame == pos[:1000], axis=1))
    assert not np.any(np.all(other_seed == pos[:1000], axis=1))


# ------------------------------------------------------------------------------------------ person_xy


def test_person_xy_copies_the_estimate_mean(device):
    est = np.arange(kreduce.EST_SIZE, dtype=np.float64) * 1.25 - 3.0
    est[kreduce.EST_MEAN : kreduce.EST_MEAN + 2] = [1.2345678901, -0.5]
    est_dev = wp.array(est, dtype=wp.float64, device=device)
    people = wp.array(np.full((3, 2), 9.0, np.float32), dtype=wp.vec2, device=device)
    wp.launch(
        kpeople.person_xy_kernel, dim=1, inputs=[est_dev, int(kreduce.EST_MEAN), 1], outputs=[people], device=device
    )
    got = people.numpy()
    np.testing.assert_array_equal(got[1], np.float32([1.2345678901, -0.5]))
    np.testing.assert_array_equal(got[[0, 2]], 9.0)  # only row j is written
    wp.launch(kpeople.person_xy_kernel, dim=1, inputs=[est_dev, 4, 2], outputs=[people], device=device)
    np.testing.assert_array_equal(people.numpy()[2], np.float32(est[4:6]))


# ------------------------------------------------------------------------------------------ predict, score_moments


@pytest.mark.parametrize("dt", [1.0, 0.32])
def test_predict_constant_velocity_matches_numpy_philox(device, rng, dt):
    """Eq. 5 draw by draw: P = P_a + dt Pdot_a + sigma_pos z_P, Pdot = Pdot_a + sigma_vel z_V with z_P, z_V the first
    three normals of the (seed, i, frame, STREAM_MOTION) and (..., STREAM_PEOPLE_VELOCITY) blocks (dt = 1: the
    paper's per-frame form)."""
    n, sp, sv, seed, frame = 2000, 0.02, 0.005, 11, 5
    pos = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    vel = rng.normal(0, 0.05, (n, 3)).astype(np.float32)
    model, desc = random_histograms(rng, n), random_histograms(rng, n)
    anc = rng.integers(0, n, n).astype(np.int32)
    p, v, _ = run_predict(device, pos, vel, model, desc, np.ones(n, np.float32), anc, sp, sv, 0.1, seed, frame, dt)
    zp = normal4_ref((seed, 0), n, frame, int(krand.STREAM_MOTION))[:, :3]
    zv = normal4_ref((seed, 0), n, frame, int(krand.STREAM_PEOPLE_VELOCITY))[:, :3]
    p64, v64 = pos.astype(np.float64)[anc], vel.astype(np.float64)[anc]
    np.testing.assert_allclose(p, p64 + np.float32(dt) * v64 + np.float32(sp) * zp, rtol=0, atol=3e-6)
    np.testing.assert_allclose(v, v64 + np.float32(sv) * zv, rtol=0, atol=1e-6)
    pz, vz, _ = run_predict(
        device, pos, vel, model, desc, np.ones(n, np.float32), anc, sp, (sv, 3 * sv), 0.1, seed, frame, dt
    )
    np.testing.assert_array_equal(pz, p)  # the vertical velocity noise does not move the particle this frame
    np.testing.assert_allclose(vz[:, 2], v64[:, 2] + np.float32(3 * sv) * zv[:, 2], rtol=0, atol=1e-6)


@pytest.mark.parametrize(("resampled", "drop_worst"), [(1, 1), (0, 0)])
def test_score_moments_matches_numpy(device, rng, resampled, drop_worst):
    """log w = eqs. 9-10 (motion, the worst camera dropped or not) + eqs. 23-26 (appearance) + the previous log-weight
    unless resampled; block partials (max, MAP index, sums) from NumPy, at a size that leaves a partial block."""
    rig = make_rig()
    drig = DeviceRig(rig, device)
    n, chunk, block = 300, 64, 32
    blocks = (n + chunk - 1) // chunk
    bgr = random_frames(rig, rng)
    mask = motion_masks(rig, rng)
    person = person_inputs(rig, drig, mask, device, rng)
    pts = random_points(rng, n)
    desc, mass, rgb = run_descriptor(drig, bgr, pts, device)
    model = random_histograms(rng, n)
    logw_prev = rng.normal(0, 1, n).astype(np.float32)
    p_b, sn, sigma_p = 0.1, 0.01, 0.3
    logw = wp.full(n, 7.0, dtype=wp.float32, device=device)
    pm = wp.full(blocks, 7.0, dtype=wp.float32, device=device)
    pa = wp.full(blocks, -7, dtype=wp.int32, device=device)
    part = wp.full((blocks, int(kreduce.N_SUMS)), 7.0, dtype=wp.float64, device=device)
    wp.launch_tiled(
        kpeople.score_moments_kernel,
        dim=[blocks],
        inputs=[drig.cams, wp.array(mask, dtype=wp.uint8, device=device), p_b, 0.0, drop_worst]
        + [wp.array(pts, dtype=wp.vec3, device=device), wp.array(model, device=device), desc, mass, rgb, NB]
        + [wp.array(logw_prev, device=device), wp.array([resampled], dtype=wp.int32, device=device)]
        + [wp.array([sn], dtype=wp.float32, device=device), sigma_p, *person]
        + [wp.array(np.array([1, 1], np.int32), device=device), n, chunk],
        outputs=[logw, pm, pa, part],
        block_dim=block,
        device=device,
    )
    uvz = project_all(drig, pts, device)
    lm = motion_ref(rig, uvz, mask, drig.pixel_offsets, p_b, 0.0, drop_worst)
    la = appearance_ref(model, desc.numpy(), mass.numpy(), rgb.numpy(), sn, sigma_p)
    ref = lm + la + person_terms_ref(drig, person, pts, device) + (0.0 if resampled else logw_prev)
    got = logw.numpy()
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-4)
    assert (mass.numpy() == 0).sum() >= 3 and len(np.unique(np.round(lm, 4))) >= 4  # unseen and varied particles
    check_partials((pm.numpy(), pa.numpy(), part.numpy()), got, pts, chunk)
