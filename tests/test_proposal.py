"""The detection-driven mixture proposal (issue 12) on every device: ray-pair triangulation and the two densities
against NumPy, sampling statistics, validity of the importance weights on a linear-gaussian toy, and the colour
tracker with ``proposal="mixture"``: convergence from random initialisation, 'no detection' frames, determinism."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from test_tracker_colour import BALL, TARGET, frames_for, small_rig

from wptrack.cameras.rig import Camera, Rig
from wptrack.cameras.structs import DeviceRig
from wptrack.core.errors import ConfigError
from wptrack.kernels.colour import proposal as kproposal
from wptrack.trackers.colour.tracker import ColorConfig, ColorTracker, HSITarget

LO = np.array([-0.5, -0.5, 0.0])
HI = np.array([1.0, 1.0, 0.8])
BOX = ((-1.5, -1.0, 0.0), (1.5, 1.5, 1.0))  # 7.5 m^3 working volume for the random initialisation


def rig3() -> Rig:
    c1 = Camera.look_at("a", 160, 120, (0.5, 0.0, 0.195), (0.4, 0.45, 0.05), 110.0, dist=[-0.05, 0.01, 0.001, 0, 0])
    c2 = Camera.look_at("b", 120, 160, (0.07, 0.485, 0.085), (0.45, 0.5, 0.03), 110.0, roll_deg=90)
    c3 = Camera.look_at("c", 160, 120, (0.9, 0.9, 0.6), (0.4, 0.45, 0.05), 120.0, dist=[0.03, 0, 0, 0.002, 0])
    return Rig((c1, c2, c3))


def np_closest(o1, d1, o2, d2):
    a = np.stack([d1, -d2], axis=1)
    s, t = np.linalg.lstsq(a, o2 - o1, rcond=None)[0]
    p1, p2 = o1 + s * d1, o2 + t * d2
    return 0.5 * (p1 + p2), np.linalg.norm(p1 - p2)


def test_ray_pairs_triangulate_projected_points(device):
    rig = rig3()
    rng = np.random.default_rng(0)
    pts = BALL + rng.uniform(-0.08, 0.08, (64, 3))
    ca = rng.integers(0, 3, 64)
    cb = (ca + 1 + rng.integers(0, 2, 64)) % 3
    uva = np.stack([rig.cameras[a].project(p[None])[0][0] for a, p in zip(ca, pts, strict=True)])
    uvb = np.stack([rig.cameras[b].project(p[None])[0][0] for b, p in zip(cb, pts, strict=True)])
    # a pixel offset in camera b: rays no longer meet; compare the midpoint and gap with NumPy least squares
    uvb_off = uvb + np.array([3.0, -2.0])
    drig = DeviceRig(rig, device)
    out = wp.zeros(64, dtype=wp.vec4, device=device)
    for uv_b, exact in ((uvb, True), (uvb_off, False)):
        wp.launch(
            kproposal.ray_pair_kernel,
            dim=64,
            inputs=[
                drig.cams,
                wp.array(ca.astype(np.int32), device=device),
                wp.array(cb.astype(np.int32), device=device),
                wp.array(uva.astype(np.float32), dtype=wp.vec2, device=device),
                wp.array(uv_b.astype(np.float32), dtype=wp.vec2, device=device),
            ],
            outputs=[out],
            device=device,
        )
        r = out.numpy()
        if exact:
            np.testing.assert_allclose(r[:, :3], pts, atol=2e-4)
            assert np.all(r[:, 3] < 2e-4)
        # NumPy reference: directions from the rig's own (OpenCV) undistortion of the same pixels
        for i in range(64):
            cam_a, cam_b = rig.cameras[ca[i]], rig.cameras[cb[i]]
            da = ray_dir(cam_a, uva[i])
            db = ray_dir(cam_b, uv_b[i])
            mid, gap = np_closest(cam_a.center, da, cam_b.center, db)
            np.testing.assert_allclose(r[i, :3], mid, atol=5e-4)
            assert abs(r[i, 3] - gap) < 5e-4


def ray_dir(cam: Camera, uv) -> np.ndarray:
    import cv2

    n = cv2.undistortPoints(
        np.asarray(uv, np.float64).reshape(1, 1, 2), cam.K, np.asarray(cam.dist, np.float64), criteria=(3, 50, 1e-12)
    ).reshape(2)
    d = cam.R.T @ np.array([n[0], n[1], 1.0])
    return d / np.linalg.norm(d)


def components(device, centres, valid):
    return (
        wp.array(np.asarray(centres, np.float32), dtype=wp.vec3, device=device),
        wp.array(np.asarray(valid, np.int32), dtype=wp.int32, device=device),
    )


def np_log_motion(x, parent, s, alpha):
    r2 = ((x - parent) ** 2).sum(1)
    ln = -r2 / (2 * s * s) - np.log((2 * np.pi) ** 1.5 * s**3)
    inside = np.all((x >= LO) & (x <= HI), axis=1)
    lu = np.where(inside, np.log(alpha / np.prod(HI - LO)), -np.inf)
    return np.logaddexp(np.log(1 - alpha) + ln, lu)


def np_log_det(x, centres, valid, sd):
    c = np.asarray(centres)[np.asarray(valid) != 0]
    r2 = ((x[:, None, :] - c[None]) ** 2).sum(2)
    e = -r2 / (2 * sd * sd)
    m = e.max(1)
    return m + np.log(np.exp(e - m[:, None]).mean(1)) - np.log((2 * np.pi) ** 1.5 * sd**3)


def test_densities_match_numpy(device):
    rng = np.random.default_rng(1)
    centres = BALL + rng.normal(0, 0.05, (16, 3))
    valid = rng.integers(0, 3, 16)
    parents = BALL + rng.normal(0, 0.05, (200, 3))
    x = parents + rng.normal(0, 0.05, (200, 3))
    out = wp.zeros((200, 2), dtype=wp.float32, device=device)
    c, v = components(device, centres, valid)
    s, alpha, sd = 0.03, 0.05, 0.04
    wp.launch(
        kproposal.log_densities_kernel,
        dim=200,
        inputs=[
            wp.array(x.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array(parents.astype(np.float32), dtype=wp.vec3, device=device),
            s,
            alpha,
            wp.vec3(*LO),
            wp.vec3(*HI),
            c,
            v,
            int((valid != 0).sum()),
            sd,
        ],
        outputs=[out],
        device=device,
    )
    r = out.numpy()
    np.testing.assert_allclose(r[:, 0], np_log_motion(x, parents, s, alpha), rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(r[:, 1], np_log_det(x, centres, valid, sd), rtol=1e-4, atol=1e-3)


def sample(device, parents, centres, valid, s, alpha, eps, sd, seed=7):
    n = len(parents)
    z = np.random.default_rng(seed).normal(size=(n, 4)).astype(np.float32)
    c, v = components(device, centres, valid)
    out = wp.zeros(n, dtype=wp.vec4, device=device)
    wp.launch(
        kproposal.mixture_sample_kernel,
        dim=n,
        inputs=[
            wp.array(parents.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array(z, dtype=wp.vec4, device=device),
            wp.vec2ui(seed, 0),
            3,
            s,
            alpha,
            eps,
            wp.vec3(*LO),
            wp.vec3(*HI),
            c,
            v,
            int((np.asarray(valid) != 0).sum()),
            sd,
        ],
        outputs=[out],
        device=device,
    )
    return out.numpy().astype(np.float64)


def test_sampling_statistics_and_log_ratio(device):
    n = 40000
    parent = np.array([0.0, 0.0, 0.3])
    centres = np.array([[0.6, 0.6, 0.2], [0.6, 0.6, 0.2], [9.0, 9.0, 9.0]])
    valid = [1, 2, 0]  # the invalid component must never be sampled
    s, alpha, eps, sd = 0.03, 0.05, 0.3, 0.02
    r = sample(device, np.repeat(parent[None], n, 0), centres, valid, s, alpha, eps, sd)
    x = r[:, :3]
    near_det = np.linalg.norm(x - centres[0], axis=1) < 6 * sd
    near_parent = np.linalg.norm(x - parent, axis=1) < 6 * s
    p_det, p_par = eps, (1 - eps) * (1 - alpha)
    for frac, p in ((near_det.mean(), p_det), (near_parent.mean(), p_par)):
        assert abs(frac - p) < 5 * np.sqrt(p * (1 - p) / n) + 0.002  # + the uniform part landing there
    assert not np.any(np.linalg.norm(x - centres[2], axis=1) < 1.0)
    lp = np_log_motion(x, np.repeat(parent[None], n, 0), s, alpha)
    ld = np_log_det(x, centres, valid, sd)
    lq = np.logaddexp(np.log(1 - eps) + lp, np.log(eps) + ld)
    np.testing.assert_allclose(r[:, 3], lp - lq, atol=2e-3, rtol=1e-3)


def test_importance_weights_are_valid_on_a_linear_gaussian_toy(device):
    """Prior N(parent, s^2), likelihood N(obs; x, so^2): the weighted mean with the mixture proposal (detection
    components around a biased guess) equals the exact posterior mean; a wrong weight (no p/q) is visibly biased."""
    n = 200000
    parent = np.array([0.3, 0.3, 0.3])
    obs = parent + np.array([0.04, -0.02, 0.03])
    s, so, sd, eps = 0.03, 0.02, 0.02, 0.5
    centres = obs + np.array([[0.03, 0.0, 0.0], [0.0, 0.03, -0.01]])
    r = sample(device, np.repeat(parent[None], n, 0), centres, [1, 1], s, 0.0, eps, sd, seed=11)
    x = r[:, :3]
    loglik = -((x - obs) ** 2).sum(1) / (2 * so * so)
    exact = (parent / s**2 + obs / so**2) / (1 / s**2 + 1 / so**2)
    post_sd = 1 / np.sqrt(1 / s**2 + 1 / so**2)
    lw = loglik + r[:, 3]
    w = np.exp(lw - lw.max())
    est = (w[:, None] * x).sum(0) / w.sum()
    ess = w.sum() ** 2 / (w**2).sum()
    tol = 5 * post_sd / np.sqrt(ess)
    assert np.all(np.abs(est - exact) < tol), (est, exact, tol)
    w_bad = np.exp(loglik - loglik.max())
    bad = (w_bad[:, None] * x).sum(0) / w_bad.sum()
    assert np.max(np.abs(bad - exact)) > 10 * tol


def test_config_validation_of_the_proposal():
    for kw in ({"proposal": "magic"}, {"mixture": 1.0}, {"reset_rate": -0.1}, {"detection_sigma": 0.0}):
        with pytest.raises(ConfigError, match=next(iter(kw))):
            ColorConfig(**kw)


@pytest.fixture(scope="module")
def frames():
    # background noise in 60..90 (saturation < 0.25: no false target pixels; the 60..120 noise of
    # test_tracker_colour matches the target's hue and saturation in ~5 % of the pixels, which scatters the detection
    # components: the weights stay valid but convergence from random initialisation takes longer)
    rng = np.random.default_rng(5)
    rig = small_rig()
    out = []
    for _ in range(8):
        imgs = frames_for(rig, BALL, rng)
        for img in imgs:
            bg = np.any(img != np.array([180, 60, 230], np.uint8), axis=2)
            img[bg] = 60 + (img[bg] - 60) // 2
        out.append(imgs)
    return out


def run(device, frames, target=TARGET, **kw):
    kw = {"particles": 500, "sigma": 0.02, "init": "random", "init_box": BOX, "proposal": "mixture", **kw}
    tr = ColorTracker(small_rig(), target, device=device, **kw)
    return [tr.step(f) for f in frames]


def test_mixture_converges_from_random_init_where_the_prior_does_not(device, frames):
    mix = run(device, frames)
    prior = run(device, frames, proposal="prior")
    errs = [np.linalg.norm(e.mean - BALL) for e in mix]
    assert errs[5] < 0.03 and errs[-1] < 0.03, errs
    assert np.linalg.norm(prior[5].mean - BALL) > 0.1
    assert all(e.detection > 0 for e in mix) and all(e.detection == -1 for e in prior)
    assert all(np.isfinite(e.ess) and 1.0 <= e.ess <= 500.0 for e in mix)


def test_mixture_is_deterministic(device, frames):
    a = run(device, frames[:4], seed=3)
    b = run(device, frames[:4], seed=3)
    for ea, eb in zip(a, b, strict=True):
        np.testing.assert_array_equal(ea.mean, eb.mean)
        assert ea.ess == eb.ess


def test_no_detection_frames_are_flagged_without_nan(device, frames):
    green = HSITarget(hue=(100, 140), sat=(0.9, 1.0))  # nothing in these frames is saturated green
    out = run(device, frames[:4], target=green)
    for e in out:
        assert e.detection == 0
        assert np.all(np.isfinite(e.mean)) and np.all(np.isfinite(e.std)) and np.isfinite(e.ess)


def test_detection_components_from_target_pixels(device, frames):
    """Components triangulated from the ball's pixels lie on the ball (within its radius + a pixel); a frame with
    the ball in camera 0 only gives points along camera-0 rays through the ball; no target pixel: none valid."""
    rig = small_rig()
    drig = DeviceRig(rig, device)
    target = TARGET.to_struct(device)
    k = 64
    centres = wp.zeros(k, dtype=wp.vec3, device=device)
    valid = wp.zeros(k, dtype=wp.int32, device=device)
    frame = wp.zeros(1, dtype=wp.int32, device=device)

    def launch(images):
        bgr = wp.array(np.concatenate([im.reshape(-1) for im in images]), dtype=wp.uint8, device=device)
        wp.launch(
            kproposal.detection_components_kernel,
            dim=k,
            inputs=[drig.cams, target, bgr, wp.vec2ui(1, 2), frame, 1024, 0.1, 0.1, 3.0],
            outputs=[centres, valid],
            device=device,
        )
        return centres.numpy(), valid.numpy()

    c, v = launch(frames[0])
    # the test discs are drawn ~12 px in radius (~6 cm at the ball's depth): rays through opposite edges of the two
    # discs can pass more than max_gap = 0.1 m apart, and those pairs fall back to a point along ray a
    assert np.all(v > 0) and np.mean(v == 1) > 0.6
    dist = np.linalg.norm(c[v == 1] - BALL, axis=1)
    assert np.median(dist) < 0.04 and np.all(dist < 0.3), dist  # edge pairs meet at grazing angles, further out
    blank = [np.full_like(im, 70) for im in frames[0]]
    c, v = launch([frames[0][0], blank[1]])
    assert set(np.unique(v)) <= {0, 2} and np.sum(v == 2) > k // 4  # camera a = 0 half of the time, else no pixel
    cam0 = rig.cameras[0]
    uv, _ = cam0.project(c[v == 2])
    uv_ball, _ = cam0.project(BALL[None])
    assert np.all(np.linalg.norm(uv - uv_ball, axis=1) < 0.033 * cam0.K[0, 0] / 0.4 + 2)
    c, v = launch(blank)
    assert np.all(v == 0)


@pytest.mark.parametrize("cameras", [3, 1])
def test_mixture_on_three_cameras_and_one(device, cameras):
    """Any number of cameras: 3 converge from random initialisation; with 1 the detection proposal puts its
    components along the camera's rays (no triangulation) and stays finite."""
    import cv2

    rig = Rig(rig3().cameras[:cameras])
    rng = np.random.default_rng(2)
    frames = []
    for _ in range(6):
        imgs = []
        for cam in rig.cameras:
            img = rng.integers(60, 90, (cam.height, cam.width, 3)).astype(np.uint8)
            uv, depth = cam.project(BALL[None])
            r = max(2, int(round(0.033 * cam.K[0, 0] / depth[0])))
            cv2.circle(img, (int(round(uv[0, 0])), int(round(uv[0, 1]))), r, (180, 60, 230), -1)
            imgs.append(img)
        frames.append(imgs)
    tr = ColorTracker(
        rig, TARGET, particles=500, sigma=0.02, init="random", init_box=BOX, proposal="mixture", device=device
    )
    out = [tr.step(f) for f in frames]
    assert all(e.detection > 0 and np.all(np.isfinite(e.mean)) for e in out)
    if cameras == 3:
        assert np.linalg.norm(out[-1].mean - BALL) < 0.03
        assert np.all(tr.det_valid.numpy() == 1)
    else:
        assert np.all(tr.det_valid.numpy() == 2)
