"""S2 people-tracker kernels not covered (or only statistically / through other kernels) by test_kernels_people.py,
against NumPy references on every device: the ground-grid motion votes used to add and remove people
(``ground_votes_kernel``), the birth draw uniform in a vertical cylinder (``init_cylinder_kernel``: exact against a
NumPy Philox, and statistically: radial CDF r^2/R^2, uniform angle and height), the estimate -> ground position copy
(``person_xy_kernel``), the constant-velocity draw of ``predict_kernel`` (eq. 5) draw by draw, and
``score_moments_kernel`` (eq. 11 = eqs. 9-10 + eqs. 23-26, and its block partials, MAP index included)."""

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
    project_all,
    random_frames,
    random_histograms,
    random_points,
    run_descriptor,
    run_predict,
)

from wptrack.cameras.rig import Rig
from wptrack.cameras.structs import DeviceRig
from wptrack.kernels.core import random as krand
from wptrack.kernels.core import reduce as kreduce
from wptrack.kernels.people import filter as kpeople

# ------------------------------------------------------------------------------------------ ground votes

ORIGIN = (-0.25, -0.25)
CELL = 0.1
NX, NY = 15, 14  # not square: catches a swapped ix / iy
HEIGHTS = np.array([0.1, 0.3, 0.5, 0.7, 0.9], dtype=np.float32)
PERSON_A = (0.3, 0.35)  # tracked
PERSON_B = (0.75, 0.65)  # moving, not tracked
RADIUS_BODY = 0.12


def person_masks(rig: Rig, drig: DeviceRig, device, rng) -> np.ndarray:
    """Flat uint8 motion masks of two solid cylinders (radius 0.12 m, height 1 m) at PERSON_A and PERSON_B, drawn by
    projecting dense interior points, plus a few speckles of noise."""
    pts = []
    for cx, cy in (PERSON_A, PERSON_B):
        r = RADIUS_BODY * np.sqrt(rng.uniform(0, 1, 6000))
        a = rng.uniform(0, 2 * np.pi, 6000)
        pts.append(np.column_stack([cx + r * np.cos(a), cy + r * np.sin(a), rng.uniform(0, 1.0, 6000)]))
    pts = np.concatenate(pts).astype(np.float32)
    uvz = project_all(drig, pts, device)
    out = []
    for c, cam in enumerate(rig.cameras):
        m = np.zeros((cam.height, cam.width), np.uint8)
        u, v, z = uvz[c].T
        px, py = np.floor(u + 0.5).astype(int), np.floor(v + 0.5).astype(int)
        ok = (z > 0) & (px >= 0) & (py >= 0) & (px < cam.width) & (py < cam.height)
        m[py[ok], px[ok]] = 1
        speckle = rng.uniform(0, 1, m.shape) < 0.01
        out.append((m | speckle).astype(np.uint8).reshape(-1))
    return np.concatenate(out)


def near_axis_distance(centre: np.ndarray, ray: np.ndarray, axis: np.ndarray, z_top: float) -> float:
    """Horizontal distance (float64) from the vertical segment at ``axis`` (z in [0, z_top]) to the part of the ray
    ``centre + s ray`` (s >= 0) between those heights; inf when the ray never is between them."""
    if abs(ray[2]) > 1e-9:
        s_a, s_b = (0.0 - centre[2]) / ray[2], (z_top - centre[2]) / ray[2]
        lo, hi = max(min(s_a, s_b), 0.0), max(s_a, s_b)
    elif 0.0 <= centre[2] <= z_top:
        lo, hi = 0.0, 1.0e6
    else:
        return np.inf
    if hi <= lo:
        return np.inf
    c2, r2 = centre[:2], ray[:2]
    rr = float(r2 @ r2)
    s = lo if rr < 1e-12 else float(np.clip((axis - c2) @ r2 / rr, lo, hi))  # closest point of the horizontal line
    return float(np.linalg.norm(c2 + s * r2 - axis))


def all_rays(rig: Rig) -> np.ndarray:
    """(P, 3) world directions of every pixel's viewing ray, cameras concatenated (the driver's ``rays``)."""
    out = []
    for cam in rig.cameras:
        v, u = np.mgrid[0 : cam.height, 0 : cam.width]
        out.append(cam.pixel_rays(np.column_stack([u.ravel(), v.ravel()])))
    return np.concatenate(out)


def ground_votes_ref(
    rig, drig, mask, rays, people, person_radius, person_height, min_fraction, device, origin=ORIGIN, cell=CELL
):
    """(votes, free_votes, ambiguous) per cell, row-major (iy, ix) flattened as ix + nx iy. ``ambiguous`` marks
    cells whose free vote depends on a ray within 1e-4 m of ``person_radius`` (float32 may decide either way)."""
    ix, iy = np.meshgrid(np.arange(NX), np.arange(NY))
    cx = origin[0] + cell * (ix.ravel() + 0.5)
    cy = origin[1] + cell * (iy.ravel() + 0.5)
    ncell, nh = len(cx), len(HEIGHTS)
    pts = np.column_stack([np.repeat(cx, nh), np.repeat(cy, nh), np.tile(HEIGHTS, ncell)]).astype(np.float32)
    uvz = project_all(drig, pts, device).reshape(len(rig.cameras), ncell, nh, 3)
    votes = np.zeros(ncell, int)
    free_votes = np.zeros(ncell, int)
    ambiguous = np.zeros(ncell, bool)
    for c, cam in enumerate(rig.cameras):
        centre = cam.center
        for t in range(ncell):
            vis = hit = free_lo = free_hi = 0
            for k in range(nh):
                u, v, z = uvz[c, t, k]
                px, py = int(np.floor(u + 0.5)), int(np.floor(v + 0.5))
                if not (z > 0 and 0 <= px < cam.width and 0 <= py < cam.height):
                    continue
                vis += 1
                pix = drig.pixel_offsets[c] + py * cam.width + px
                if mask[pix] == 0:
                    continue
                hit += 1
                d = min(
                    (near_axis_distance(centre, rays[pix].astype(np.float64), p, person_height) for p in people),
                    default=np.inf,
                )
                free_lo += d > person_radius + 1e-4  # unexplained even with a slightly larger radius
                free_hi += d > person_radius - 1e-4
            if vis:
                votes[t] += hit >= min_fraction * vis
                lo, hi = free_lo >= min_fraction * vis, free_hi >= min_fraction * vis
                free_votes[t] += lo
                ambiguous[t] |= lo != hi
    return votes, free_votes, ambiguous


def launch_ground_votes(
    drig, mask, rays, people_all, n_people, radius, height, min_fraction, device, origin=ORIGIN, cell=CELL
):
    votes = wp.full(NX * NY, -7, dtype=wp.int32, device=device)
    free = wp.full(NX * NY, -7, dtype=wp.int32, device=device)
    wp.launch(
        kpeople.ground_votes_kernel,
        dim=NX * NY,
        inputs=[
            drig.cams,
            wp.array(mask, dtype=wp.uint8, device=device),
            wp.array(rays.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array(HEIGHTS, dtype=wp.float32, device=device),
            wp.array(np.asarray(people_all, np.float32), dtype=wp.vec2, device=device),
            n_people,
            radius,
            height,
            wp.vec2(*origin),
            cell,
            NX,
            min_fraction,
        ],
        outputs=[votes, free],
        device=device,
    )
    return votes.numpy(), free.numpy()


@pytest.mark.parametrize("min_fraction", [0.5, 0.8])
def test_ground_votes_match_numpy(device, min_fraction):
    rng = np.random.default_rng(11)
    rig = make_rig()
    drig = DeviceRig(rig, device)
    mask = person_masks(rig, drig, device, rng)
    rays = all_rays(rig)
    # people[1] is PERSON_B but n_people = 1: only PERSON_A is tracked (the kernel must not read past n_people)
    people_all = [PERSON_A, PERSON_B]
    radius, height = 0.2, 1.1
    votes, free = launch_ground_votes(drig, mask, rays, people_all, 1, radius, height, min_fraction, device)
    ref_votes, ref_free, amb = ground_votes_ref(
        rig, drig, mask, rays, [np.array(PERSON_A)], radius, height, min_fraction, device
    )
    np.testing.assert_array_equal(votes, ref_votes)
    assert amb.sum() <= 0.05 * amb.size
    np.testing.assert_array_equal(free[~amb], ref_free[~amb])
    # the scene exercises the rules: both people get votes from every camera, only B's are unexplained
    grid_votes = votes.reshape(NY, NX)
    grid_free = free.reshape(NY, NX)

    def cell_of(p):
        return int((p[1] - ORIGIN[1]) / CELL), int((p[0] - ORIGIN[0]) / CELL)

    assert grid_votes[cell_of(PERSON_A)] == 3 and grid_votes[cell_of(PERSON_B)] == 3
    assert grid_free[cell_of(PERSON_A)] == 0 and grid_free[cell_of(PERSON_B)] == 3
    assert len(np.unique(votes)) >= 3 and (free < votes).any() and (free[votes > 0] == votes[votes > 0]).any()

    # nobody tracked: free votes equal all votes; both tracked: no free votes at either person
    votes0, free0 = launch_ground_votes(drig, mask, rays, people_all, 0, radius, height, min_fraction, device)
    np.testing.assert_array_equal(votes0, ref_votes)
    np.testing.assert_array_equal(free0, ref_votes)
    _, free2 = launch_ground_votes(drig, mask, rays, people_all, 2, radius, height, min_fraction, device)
    ref2 = ground_votes_ref(
        rig, drig, mask, rays, [np.array(p) for p in people_all], radius, height, min_fraction, device
    )
    np.testing.assert_array_equal(free2[~ref2[2]], ref2[1][~ref2[2]])
    assert free2.reshape(NY, NX)[cell_of(PERSON_B)] == 0


def test_ground_votes_explained_only_between_ground_and_person_height(device):
    """A tracked person explains a motion pixel only through the part of its viewing ray between z = 0 and
    ``person_height`` (s > 0): with motion everywhere in one camera, every cell's free vote depends on where its
    column's rays enter and leave that slab. People on the camera's line of sight to the grid, one near the camera
    (the rays pass over its head) and one far beyond the grid (the rays are under the ground there), and one in the
    grid; the full horizontal lines of many rays pass through all three axes."""
    rig = Rig(make_rig().cameras[:1])
    drig = DeviceRig(rig, device)
    mask = np.ones(drig.total_pixels, np.uint8)
    rays = all_rays(rig)
    cam = rig.cameras[0]
    mid = np.array([0.5, 0.5])
    toward = (mid - cam.center[:2]) / np.linalg.norm(mid - cam.center[:2])
    people = [cam.center[:2] + 0.4 * toward, mid + 4.0 * toward, mid + np.array([0.1, -0.2])]
    radius, height = 0.25, 1.1
    votes, free = launch_ground_votes(drig, mask, rays, people, 3, radius, height, 0.5, device)
    ref_votes, ref_free, amb = ground_votes_ref(
        rig, drig, mask, rays, [np.asarray(p) for p in people], radius, height, 0.5, device
    )
    np.testing.assert_array_equal(votes, ref_votes)
    assert amb.sum() <= 0.05 * amb.size
    np.testing.assert_array_equal(free[~amb], ref_free[~amb])
    seen = ref_votes == 1
    assert seen.sum() > 50 and 10 < (ref_free[seen] == 0).sum() < seen.sum() - 10  # explained and unexplained cells


def test_ground_votes_camera_that_sees_nothing_does_not_vote(device):
    """With motion everywhere a camera votes for every cell it sees and for no other (vis = 0 is no vote, not
    0 >= 0 x fraction): on a coarse grid from -3 m to 4 m some cells are out of some or all views."""
    rig = make_rig()
    drig = DeviceRig(rig, device)
    mask = np.ones(drig.total_pixels, np.uint8)  # motion everywhere
    rays = np.tile(np.array([[0.0, 0.0, -1.0]]), (drig.total_pixels, 1))
    grid = {"origin": (-3.0, -3.0), "cell": 0.5}
    votes, free = launch_ground_votes(drig, mask, rays, np.zeros((1, 2)), 0, 0.1, 1.0, 0.5, device, **grid)
    ref_votes, ref_free, _ = ground_votes_ref(rig, drig, mask, rays, [], 0.1, 1.0, 0.5, device, **grid)
    np.testing.assert_array_equal(votes, ref_votes)
    np.testing.assert_array_equal(free, ref_free)
    assert (votes == 0).any() and (votes == 3).any() and len(np.unique(votes)) == 4


# ------------------------------------------------------------------------------------------ birth cylinder


def init_cylinder(device, centre, radius, z_lo, z_hi, seed, frame, n):
    pos = wp.full(n, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device)
    vel = wp.full(n, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device)
    wp.launch(
        kpeople.init_cylinder_kernel,
        dim=n,
        inputs=[wp.vec3(*centre), radius, z_lo, z_hi, wp.vec2ui(*seed), frame],
        outputs=[pos, vel],
        device=device,
    )
    return pos.numpy().astype(np.float64), vel.numpy()


def test_init_cylinder_matches_numpy_philox(device):
    """Exact draw: r = R sqrt(u0), angle 2 pi u1, z = z_lo + (z_hi - z_lo) u2 of the (seed, i, frame, STREAM_MOTION)
    Philox block, velocity 0; the centre's z is ignored (heights are absolute)."""
    n, seed, frame = 1000, (123, 456), 9
    centre, radius, z_lo, z_hi = (2.0, -1.0, 5.0), 0.3, 0.2, 1.6
    pos, vel = init_cylinder(device, centre, radius, z_lo, z_hi, seed, frame, n)
    u = uniform4_ref(seed, n, frame, int(krand.STREAM_MOTION))
    r = radius * np.sqrt(u[:, 0])
    a = 2 * np.pi * u[:, 1]
    ref = np.column_stack([centre[0] + r * np.cos(a), centre[1] + r * np.sin(a), z_lo + (z_hi - z_lo) * u[:, 2]])
    np.testing.assert_allclose(pos, ref, rtol=0, atol=2e-6)
    np.testing.assert_array_equal(vel, 0.0)


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


def test_predict_constant_velocity_matches_numpy_philox(device, rng):
    """Eq. 5 draw by draw: P = P_a + Pdot_a + sigma_pos z_P, Pdot = Pdot_a + sigma_vel z_V with z_P, z_V the first
    three normals of the (seed, i, frame, STREAM_MOTION) and (..., STREAM_PEOPLE_VELOCITY) blocks."""
    n, sp, sv, seed, frame = 2000, 0.02, 0.005, 11, 5
    pos = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    vel = rng.normal(0, 0.05, (n, 3)).astype(np.float32)
    model, desc = random_histograms(rng, n), random_histograms(rng, n)
    anc = rng.integers(0, n, n).astype(np.int32)
    p, v, _ = run_predict(device, pos, vel, model, desc, np.ones(n, np.float32), anc, sp, sv, 0.1, seed, frame)
    zp = normal4_ref((seed, 0), n, frame, int(krand.STREAM_MOTION))[:, :3]
    zv = normal4_ref((seed, 0), n, frame, int(krand.STREAM_PEOPLE_VELOCITY))[:, :3]
    p64, v64 = pos.astype(np.float64)[anc], vel.astype(np.float64)[anc]
    np.testing.assert_allclose(p, p64 + v64 + np.float32(sp) * zp, rtol=0, atol=3e-6)
    np.testing.assert_allclose(v, v64 + np.float32(sv) * zv, rtol=0, atol=1e-6)


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
        + [wp.array([sn], dtype=wp.float32, device=device), sigma_p, n, chunk],
        outputs=[logw, pm, pa, part],
        block_dim=block,
        device=device,
    )
    uvz = project_all(drig, pts, device)
    lm = motion_ref(rig, uvz, mask, drig.pixel_offsets, p_b, 0.0, drop_worst)
    la = appearance_ref(model, desc.numpy(), mass.numpy(), rgb.numpy(), sn, sigma_p)
    ref = lm + la + (0.0 if resampled else logw_prev)
    got = logw.numpy()
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-4)
    assert (mass.numpy() == 0).sum() >= 3 and len(np.unique(np.round(lm, 4))) >= 4  # unseen and varied particles
    check_partials((pm.numpy(), pa.numpy(), part.numpy()), got, pts, chunk)
