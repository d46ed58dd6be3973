"""S2 people-tracker kernels (Lopez-Cifuentes et al.) against NumPy references on every device: HSV planes
(eqs. 12-14), sigma_n (eq. 18), alpha weights (eqs. 15-17), the 3D colour descriptor (eqs. 19-21), the appearance
probability (eqs. 23-26), the motion likelihood (eqs. 7-10), eq. 11, the constant-velocity predict with the
appearance update (eqs. 5-6) and the occupancy grid."""

from __future__ import annotations

import colorsys

import kernel_harness as harness
import numpy as np
import pytest
import warp as wp

from wptrack.cameras.rig import Camera, Rig
from wptrack.cameras.structs import DeviceRig
from wptrack.kernels.core.camera import Camera as KCamera
from wptrack.kernels.people import descriptor as kdesc
from wptrack.kernels.people import filter as kpeople
from wptrack.kernels.people import occupancy as kocc

NB = 8
R_N = 0.12
R_MIN, R_MAX = 1.0, 9.0


def make_rig() -> Rig:
    """Three 64x48 cameras around the box [0, 1]^2 x [0, 1] (z up)."""
    cams = (
        Camera.look_at("a", 64, 48, (-1.5, 0.5, 1.5), (0.5, 0.5, 0.5), 50.0),
        Camera.look_at("b", 64, 48, (2.5, -0.5, 1.8), (0.5, 0.5, 0.5), 55.0, dist=[-0.03, 0, 0, 0, 0]),
        Camera.look_at("c", 64, 48, (0.5, 2.8, 1.2), (0.5, 0.5, 0.4), 45.0, roll_deg=10),
    )
    return Rig(cams)


def random_frames(rig: Rig, rng) -> np.ndarray:
    """Flat BGR buffer of random images with coloured blocks (so that histograms are not flat)."""
    out = []
    for cam in rig.cameras:
        img = rng.integers(0, 256, (cam.height, cam.width, 3), dtype=np.uint8)
        for _ in range(8):
            y, x = rng.integers(0, cam.height), rng.integers(0, cam.width)
            img[max(0, y - 6) : y + 6, max(0, x - 6) : x + 6] = rng.integers(0, 256, 3)
        out.append(img.reshape(-1))
    return np.concatenate(out)


def hsv_ref(bgr_flat: np.ndarray) -> np.ndarray:
    """(P, 3) H [0, 1), S, V by colorsys (an independent implementation of the hexcone model)."""
    px = bgr_flat.reshape(-1, 3).astype(np.float64) / 255.0
    return np.array([colorsys.rgb_to_hsv(p[2], p[1], p[0]) for p in px])


def hsv_planes(bgr: np.ndarray, device):
    n = len(bgr) // 3
    planes = [wp.zeros(n, dtype=wp.float32, device=device) for _ in range(3)]
    wp.launch(
        harness.hsv_planes_kernel,
        dim=n,
        inputs=[wp.array(bgr, dtype=wp.uint8, device=device)],
        outputs=planes,
        device=device,
    )
    return planes


def project_all(drig: DeviceRig, pts: np.ndarray, device) -> np.ndarray:
    """(M, N, 3) (u, v, depth) from the tested projection (test_kernels_camera checks it against OpenCV)."""
    out = wp.zeros((drig.num_cameras, len(pts)), dtype=wp.vec3, device=device)
    wp.launch(
        harness.project_kernel,
        dim=(drig.num_cameras, len(pts)),
        inputs=[drig.cams, wp.array(pts, dtype=wp.vec3, device=device)],
        outputs=[out],
        device=device,
    )
    return out.numpy().astype(np.float64)


def random_points(rng, n: int) -> np.ndarray:
    """Points mostly in the common view, some near the image borders and a few behind every camera / far away."""
    pts = rng.uniform([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], (n, 3))
    pts[: n // 10] = rng.uniform([-1.0, -1.0, -0.5], [2.0, 2.0, 2.0], (n // 10, 3))
    pts[n // 10 : n // 10 + 3] = [[50.0, 50.0, -40.0], [-30.0, 60.0, 10.0], [0.5, 0.5, 80.0]]
    return pts.astype(np.float32)


def test_hsv_planes_match_colorsys(device, rng):
    rig = make_rig()
    bgr = random_frames(rig, rng)
    # corner cases: black, white, greys, pure primaries, hue just below 1 (wrap)
    bgr[:30] = np.array(
        [0, 0, 0, 255, 255, 255, 90, 90, 90, 0, 0, 255, 0, 255, 0, 255, 0, 0, 8, 0, 255, 255, 0, 255, 1, 2, 3, 0, 1, 0]
    )
    h, s, v = (a.numpy() for a in hsv_planes(bgr, device))
    ref = hsv_ref(bgr)
    np.testing.assert_allclose(s, ref[:, 1], atol=2e-7)
    np.testing.assert_allclose(v, ref[:, 2], atol=1e-7)
    dh = np.abs(h - ref[:, 0])
    dh = np.minimum(dh, 1 - dh)  # 0.9999999 vs 0.0 are neighbours on the circle
    assert dh.max() < 1e-6
    assert np.all((h >= 0) & (h < 1))
    assert h[2] == 0.0 and s[2] == 0.0  # grey: hue 0 by convention
    assert h[3] == 0.0 and h[4] == pytest.approx(1 / 3) and h[5] == pytest.approx(2 / 3)  # red, green, blue
    assert h[6] == pytest.approx(1 - 8 / 255 / 6, abs=1e-6)  # (8, 0, 255) BGR: red with a little blue


def test_noise_sigma(device, rng):
    """Eq. 18 against NumPy on sizes that are not multiples of the block, and its expectation on pure noise:
    two independent noisy copies of a scene differ with variance 2 sigma^2 (the paper's formula gives sqrt 2 sigma)."""
    for n_pix, chunk, stride in [(1, 256, 1), (1000, 256, 1), (3 * 64 * 48, 1024, 1), (1001, 64, 4), (999, 64, 3)]:
        a = rng.integers(0, 256, 3 * n_pix).astype(np.uint8)
        b = rng.integers(0, 256, 3 * n_pix).astype(np.uint8)
        got = run_noise(a, b, chunk, device, stride)
        pa, pb = a.reshape(-1, 3)[::stride], b.reshape(-1, 3)[::stride]  # every stride-th pixel, its 3 values
        ref = np.sqrt(np.mean(((pa.astype(np.float64) - pb) / 255) ** 2))
        assert got == pytest.approx(ref, rel=1e-6)
    scene = rng.uniform(40, 210, 3 * 64 * 48 * 3)
    sigma = 4.0
    a = np.clip(np.rint(scene + rng.normal(0, sigma, scene.shape)), 0, 255).astype(np.uint8)
    b = np.clip(np.rint(scene + rng.normal(0, sigma, scene.shape)), 0, 255).astype(np.uint8)
    got = run_noise(a, b, 4096, device)
    # rounding to integers adds 1/12 per frame; 27648 values: the estimate's relative sd is ~0.4 %
    assert got == pytest.approx(np.sqrt(2 * (sigma**2 + 1 / 12)) / 255, rel=0.02)


def run_noise(a, b, chunk, device, stride=1) -> float:
    n = 3 * len(range(0, len(a) // 3, stride))  # the values summed
    nb = (n + chunk - 1) // chunk
    part = wp.zeros(nb, dtype=wp.float64, device=device)
    sig = wp.zeros(1, dtype=wp.float32, device=device)
    A = wp.array(a, dtype=wp.uint8, device=device)
    B = wp.array(b, dtype=wp.uint8, device=device)
    wp.launch_tiled(
        kdesc.noise_partials_kernel,
        dim=[nb],
        inputs=[A, B, n, stride, chunk],
        outputs=[part],
        block_dim=256,
        device=device,
    )
    wp.launch_tiled(
        kdesc.noise_sigma_kernel, dim=[1], inputs=[part, nb, n], outputs=[sig], block_dim=256, device=device
    )
    return float(sig.numpy()[0])


def alpha_ref(rgb: np.ndarray, sigma_n: float) -> np.ndarray:
    """(alpha_S, alpha_H) of eq. 17 with the delta-method variances (see kernels/people/descriptor.py)."""
    s = np.sort(rgb, axis=1)[:, ::-1]
    mx, mid, mn = s[:, 0], s[:, 1], s[:, 2]
    vv = sigma_n**2
    m2 = np.maximum(mx * mx, 1e-12)
    vs = vv * (1 / m2 + mn**2 / m2**2)
    d2 = np.maximum((mx - mn) ** 2, 1e-12)
    vh = vv * (1 / d2 + ((mid - mx) ** 2 + (mid - mn) ** 2) / d2**2) / 36
    return np.column_stack([(vv / np.maximum(vs, 1e-12)) ** 2, (vv / np.maximum(vh, 1e-12)) ** 2])


def test_alpha_weights_and_noise_propagation(device, rng):
    """The kernel's alpha_S, alpha_H equal the reference, and the propagated var(S_n), var(H_n) (eq. 16) agree with a
    Monte Carlo simulation of eq. 15 through the kernel's own HSV conversion."""
    sigma_n = 0.004
    rgb = rng.uniform(0.05, 1.0, (300, 3)).astype(np.float32)
    rgb[0] = [0.5, 0.5, 0.5]  # grey: hue meaningless -> alpha_H ~ 0
    out = wp.zeros(len(rgb), dtype=wp.vec2, device=device)
    wp.launch(
        harness.alpha_kernel,
        dim=len(rgb),
        inputs=[wp.array(rgb, dtype=wp.vec3, device=device), sigma_n],
        outputs=[out],
        device=device,
    )
    got = out.numpy()
    np.testing.assert_allclose(got, alpha_ref(rgb.astype(np.float64), sigma_n), rtol=1e-4)
    assert got[0, 1] < 1e-12
    # Monte Carlo: colours away from sextant edges and grey
    for mu in ([0.8, 0.5, 0.2], [0.3, 0.35, 0.9], [0.6, 0.2, 0.45]):
        noisy = np.clip(np.array(mu) + rng.normal(0, sigma_n, (20000, 3)), 0, 1)
        hsv = np.array([colorsys.rgb_to_hsv(*p) for p in noisy])
        a_s, a_h = alpha_ref(np.array([mu]), sigma_n)[0]
        # alpha = (sigma^2 / var)^2  ->  var = sigma^2 / sqrt(alpha); sample variance of 20000 draws: sd ~1 %
        assert np.var(hsv[:, 1]) == pytest.approx(sigma_n**2 / np.sqrt(a_s), rel=0.05)
        assert np.var(hsv[:, 0]) == pytest.approx(sigma_n**2 / np.sqrt(a_h), rel=0.05)


def bin_split_ref(x: np.ndarray, nb: int, wrap: bool) -> np.ndarray:
    """(len(x), nb) linear-interpolation weights (bin centres at (k + 1/2) / nb)."""
    t = x * nb - 0.5
    k0 = np.floor(t).astype(int)
    w1 = t - k0
    out = np.zeros((len(x), nb))
    rows = np.arange(len(x))
    if wrap:
        np.add.at(out, (rows, k0 % nb), 1 - w1)
        np.add.at(out, (rows, (k0 + 1) % nb), w1)
    else:
        lo, hi = k0 < 0, k0 + 1 > nb - 1
        w1 = np.where(lo | hi, 0.0, w1)
        np.add.at(out, (rows, np.clip(k0, 0, nb - 1)), 1 - w1)
        np.add.at(out, (rows, np.clip(k0 + 1, 0, nb - 1)), w1)
    return out


def descriptor_ref(rig: Rig, uvz: np.ndarray, hsv: np.ndarray, bgr: np.ndarray, offsets, i: int, step: int = 1):
    """D(P) of one point (eqs. 19-21) in float64 from the kernel's projections. Returns (desc, mass, rgb, ambiguous):
    ``ambiguous`` when a pixel lies within float32 rounding of a disc's rim (then the two may differ by that pixel)."""
    desc = np.zeros(3 * NB)
    mass = 0.0
    rgb = np.zeros(3)
    ambiguous = False
    for c, cam in enumerate(rig.cameras):
        u, v, z = uvz[c, i]
        if z <= 0:
            continue
        r = np.clip(0.5 * (cam.fx + cam.fy) * R_N / z, R_MIN, R_MAX)
        ys, xs = np.mgrid[0 : cam.height, 0 : cam.width]
        x0, y0 = max(int(np.ceil(u - r)), 0), max(int(np.ceil(v - r)), 0)
        on_grid = ((xs - x0) % step == 0) & ((ys - y0) % step == 0)  # every step-th pixel from the disc's corner
        d2 = (xs - u) ** 2 + (ys - v) ** 2
        ambiguous |= bool(np.any(np.abs(d2 - r * r) < 2e-5 * r * r))
        ambiguous |= bool(np.any(np.abs(np.array([u - r, v - r]) - np.round(np.array([u - r, v - r]))) < 1e-4))
        sel = (d2 <= r * r) & on_grid & (xs >= x0) & (ys >= y0)
        w = step * step * np.exp(-0.5 * d2[sel] / r**2) / (2 * np.pi * r * r)
        q = offsets[c] + ys[sel] * cam.width + xs[sel]
        for k, wrap in enumerate((True, False, False)):
            desc[k * NB : (k + 1) * NB] += (w[:, None] * bin_split_ref(hsv[q, k], NB, wrap)).sum(0)
        mass += w.sum()
        px = bgr.reshape(-1, 3)[q][:, ::-1] / 255.0
        rgb += (w[:, None] * px).sum(0)
    if mass > 0:
        desc /= mass
        rgb /= mass
    return desc, mass, rgb, ambiguous


def run_descriptor(drig, bgr, pts, device, step=1):
    n = len(pts)
    desc = wp.zeros((n, 3 * NB), dtype=wp.float32, device=device)
    mass = wp.zeros(n, dtype=wp.float32, device=device)
    rgb = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(
        kdesc.descriptor_kernel,
        dim=n,
        inputs=[
            drig.cams,
            wp.array(bgr, dtype=wp.uint8, device=device),
            wp.array(pts, dtype=wp.vec3, device=device),
            R_N,
            NB,
            R_MIN,
            R_MAX,
            step,
        ],
        outputs=[desc, mass, rgb],
        device=device,
    )
    return desc, mass, rgb


@pytest.mark.parametrize("step", [1, 2])
def test_descriptor_matches_numpy(device, rng, step):
    rig = make_rig()
    drig = DeviceRig(rig, device)
    bgr = random_frames(rig, rng)
    hsv = np.column_stack([p.numpy().astype(np.float64) for p in hsv_planes(bgr, device)])
    pts = random_points(rng, 200)
    uvz = project_all(drig, pts, device)
    desc, mass, rgb = (a.numpy() for a in run_descriptor(drig, bgr, pts, device, step))
    compared = unseen = clipped = 0
    for i in range(len(pts)):
        d_ref, m_ref, rgb_ref, ambiguous = descriptor_ref(rig, uvz, hsv, bgr, drig.pixel_offsets, i, step)
        if ambiguous:
            continue
        compared += 1
        np.testing.assert_allclose(mass[i], m_ref, rtol=1e-4, atol=1e-9)
        np.testing.assert_allclose(desc[i], d_ref, rtol=1e-4, atol=2e-6)
        np.testing.assert_allclose(rgb[i], rgb_ref, rtol=1e-4, atol=2e-6)
        if m_ref == 0:
            unseen += 1
            assert not desc[i].any()
        else:
            np.testing.assert_allclose(desc[i].reshape(3, NB).sum(1), 1.0, rtol=1e-5)
        seen = uvz[:, i, 2] > 0
        clipped += int(
            np.any(
                seen
                & (
                    (uvz[:, i, 0] < R_MAX)
                    | (uvz[:, i, 0] > 63 - R_MAX)
                    | (uvz[:, i, 1] < R_MAX)
                    | (uvz[:, i, 1] > 47 - R_MAX)
                )
            )
        )
    assert compared >= 190
    assert unseen >= 3  # the far points
    assert clipped >= 10  # discs crossing the image border were exercised


def test_descriptor_hue_wraps(device):
    """A uniform colour of hue just below 1 splits between the last and the first hue bin."""
    rig = make_rig()
    drig = DeviceRig(rig, device)
    bgr = np.tile(np.array([8, 0, 255], dtype=np.uint8), drig.total_pixels)  # BGR: red with a little blue
    pts = np.array([[0.5, 0.5, 0.5]], dtype=np.float32)
    desc, mass, rgb = (a.numpy() for a in run_descriptor(drig, bgr, pts, device))
    hue = 1 - 8 / 255 / 6
    t = hue * NB - 0.5  # between the centres of bins NB - 1 and NB (= 0)
    w1 = t - np.floor(t)
    assert mass[0] > 0
    np.testing.assert_allclose(desc[0, NB - 1], 1 - w1, atol=1e-5)
    np.testing.assert_allclose(desc[0, 0], w1, atol=1e-5)
    assert desc[0, 1 : NB - 1].sum() == 0
    np.testing.assert_allclose(rgb[0], [1.0, 0.0, 8 / 255], atol=1e-6)
    # saturation 1 and value 1: beyond the last centre, wholly in the last bin
    assert desc[0, 2 * NB - 1] == pytest.approx(1.0) and desc[0, 3 * NB - 1] == pytest.approx(1.0)


def appearance_ref(model, desc, mass, rgb, sigma_n, sigma_p):
    al = alpha_ref(rgb.astype(np.float64), sigma_n)
    a_s, a_h = al[:, 0], al[:, 1]
    e = [
        np.linalg.norm(model[:, k * NB : (k + 1) * NB] - desc[:, k * NB : (k + 1) * NB], axis=1) / np.sqrt(2)
        for k in range(3)
    ]
    d_h, d_s, d_v = e[0] * a_h, e[1] * a_s, e[2]  # eq. 23
    beta = np.exp(-(d_v**2) / (2 * sigma_n**2)) / (np.sqrt(2 * np.pi) * sigma_n)  # eq. 25
    m = (d_h + d_s + beta * d_v) / (a_h + a_s + beta)  # eq. 24
    m = np.where(mass > 0, m, 1.0)
    return -(m**2) / (2 * sigma_p**2) - np.log(np.sqrt(2 * np.pi) * sigma_p)  # eq. 26


def random_histograms(rng, n):
    h = rng.gamma(0.5, size=(n, 3, NB))
    return (h / h.sum(2, keepdims=True)).reshape(n, 3 * NB).astype(np.float32)


def test_appearance_matches_numpy(device, rng):
    n = 200
    model = random_histograms(rng, n)
    desc = random_histograms(rng, n)
    desc[:20] = model[:20]  # perfect matches: M = 0
    desc[20:40] = (0.9 * model[20:40] + 0.1 * desc[20:40]).astype(np.float32)
    mass = rng.uniform(0.5, 2, n).astype(np.float32)
    mass[-5:] = 0
    rgb = rng.uniform(0.05, 1, (n, 3)).astype(np.float32)
    sigma_n, sigma_p = 0.02, 0.3
    out = wp.zeros(n, dtype=wp.float32, device=device)
    wp.launch(
        harness.appearance_kernel,
        dim=n,
        inputs=[
            wp.array(model, device=device),
            wp.array(desc, device=device),
            wp.array(mass, device=device),
            wp.array(rgb, dtype=wp.vec3, device=device),
            NB,
            wp.array([sigma_n], dtype=wp.float32, device=device),
            sigma_p,
        ],
        outputs=[out],
        device=device,
    )
    got = out.numpy()
    ref = appearance_ref(model.astype(np.float64), desc.astype(np.float64), mass, rgb, sigma_n, sigma_p)
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-5)
    best = -np.log(np.sqrt(2 * np.pi) * sigma_p)
    np.testing.assert_allclose(got[:20], best, atol=1e-6)
    assert np.all(got[20:40] > np.median(got[40:-5]))  # near matches score above random pairs
    np.testing.assert_allclose(got[-5:], best - 1 / (2 * sigma_p**2), rtol=1e-6)


def motion_masks(rig: Rig, rng) -> np.ndarray:
    out = []
    for cam in rig.cameras:
        m = np.zeros((cam.height, cam.width), np.uint8)
        for _ in range(5):
            y, x = rng.integers(0, cam.height), rng.integers(0, cam.width)
            m[max(0, y - 8) : y + 8, max(0, x - 10) : x + 10] = 255
        out.append(m.reshape(-1))
    return np.concatenate(out)


def motion_ref(rig, uvz, mask, offsets, p_b, log_outside, drop_worst=0):
    m, n = uvz.shape[:2]
    terms = []
    for c, cam in enumerate(rig.cameras):
        u, v, z = uvz[c].T
        px, py = np.floor(u + 0.5).astype(int), np.floor(v + 0.5).astype(int)
        inside = (z > 0) & (px >= 0) & (py >= 0) & (px < cam.width) & (py < cam.height)
        q = offsets[c] + np.clip(py, 0, cam.height - 1) * cam.width + np.clip(px, 0, cam.width - 1)
        on = inside & (mask[q] != 0)
        terms.append(np.where(inside, np.where(on, np.log(1 - p_b), np.log(p_b)), log_outside))
    terms = np.array(terms)
    total = terms.sum(axis=0)
    if drop_worst and len(terms) >= 3:
        total -= terms.min(axis=0)
    return total


@pytest.mark.parametrize(("neutral", "drop_worst"), [(False, 0), (True, 0), (False, 1)])
def test_motion_likelihood(device, neutral, drop_worst):
    rng = np.random.default_rng(1)  # one scene for every case (it has points on motion in all cameras and in none)
    rig = make_rig()
    drig = DeviceRig(rig, device)
    mask = motion_masks(rig, rng)
    pts = random_points(rng, 300)
    uvz = project_all(drig, pts, device)
    p_b = 0.05
    log_outside = 0.0 if neutral else float(np.log(p_b))
    out = wp.zeros(len(pts), dtype=wp.float32, device=device)
    wp.launch(
        harness.motion_kernel,
        dim=len(pts),
        inputs=[
            drig.cams,
            wp.array(mask, dtype=wp.uint8, device=device),
            p_b,
            log_outside,
            drop_worst,
            wp.array(pts, dtype=wp.vec3, device=device),
        ],
        outputs=[out],
        device=device,
    )
    ref = motion_ref(rig, uvz, mask, drig.pixel_offsets, p_b, log_outside, drop_worst)
    np.testing.assert_allclose(out.numpy(), ref, rtol=1e-6, atol=1e-6)
    # every case was exercised: all on motion, none, and points off some image (and the worst camera dropped)
    full = motion_ref(rig, uvz, mask, drig.pixel_offsets, p_b, log_outside, 0)
    assert np.isclose(full, 3 * np.log(1 - p_b)).any() and np.isclose(full, 3 * np.log(p_b)).any()
    assert (not drop_worst) or (np.abs(ref - full) > 1e-3).any()
    assert len(np.unique(np.round(full, 5))) >= 4


def person_inputs(rig: Rig, drig: DeviceRig, mask: np.ndarray, device, rng, slope=0.02, weight=5.0) -> list:
    """The person-level inputs of the S2 kernels (kernels/coverage.py): the masks' integral images, three other
    people (one not alive) with their rectangles, this person's slot 0 and the terms."""
    from test_kernels_coverage import integral, make_terms

    from wptrack.kernels.people import coverage as kcov

    I = integral(rig, drig, (mask != 0).astype(np.uint8), device)  # noqa: E741
    others = wp.array(rng.uniform(0.0, 1.0, (3, 2)).astype(np.float32), dtype=wp.vec2, device=device)
    alive = wp.array(np.array([1, 0, 1], np.int32), device=device)
    boxes = wp.zeros((3, drig.num_cameras), dtype=wp.vec4, device=device)
    wp.launch(
        kcov.person_boxes_kernel,
        dim=boxes.shape,
        inputs=[drig.cams, others, alive, 0.25, 1.75],
        outputs=[boxes],
        device=device,
    )
    terms = make_terms(slope=slope, weight=weight)
    terms.half_width, terms.height = 0.25, 1.75
    return [drig.cams, I, others, alive, boxes, 0, terms]


def person_terms_ref(drig: DeviceRig, inputs: list, pts: np.ndarray, device) -> np.ndarray:
    """The person-level terms of ``pts`` by test_kernels_coverage's kernel (checked there against NumPy)."""
    from test_kernels_coverage import _terms_kernel

    out = wp.zeros(len(pts), dtype=wp.float32, device=device)
    wp.launch(
        _terms_kernel,
        dim=len(pts),
        inputs=[*inputs, wp.array(pts, dtype=wp.vec3, device=device)],
        outputs=[out],
        device=device,
    )
    return out.numpy().astype(np.float64)


def test_observation_is_motion_plus_appearance(device, rng):
    rig = make_rig()
    drig = DeviceRig(rig, device)
    bgr = random_frames(rig, rng)
    flat = motion_masks(rig, rng)
    mask = wp.array(flat, dtype=wp.uint8, device=device)
    person = person_inputs(rig, drig, flat, device, rng)
    pts = random_points(rng, 100)
    P = wp.array(pts, dtype=wp.vec3, device=device)
    desc, mass, rgb = run_descriptor(drig, bgr, pts, device)
    model = wp.array(random_histograms(rng, len(pts)), device=device)
    sn = wp.array([0.01], dtype=wp.float32, device=device)
    lm, la, lo = (wp.zeros(len(pts), dtype=wp.float32, device=device) for _ in range(3))
    p_b = 0.1
    wp.launch(
        harness.motion_kernel, dim=len(pts), inputs=[drig.cams, mask, p_b, 0.0, 0, P], outputs=[lm], device=device
    )
    wp.launch(
        harness.appearance_kernel,
        dim=len(pts),
        inputs=[model, desc, mass, rgb, NB, sn, 0.25],
        outputs=[la],
        device=device,
    )
    wp.launch(
        harness.observation_kernel,
        dim=len(pts),
        inputs=[drig.cams, mask, p_b, 0.0, 0, P, model, desc, mass, rgb, NB, sn, 0.25, *person],
        outputs=[lo],
        device=device,
    )
    lt = person_terms_ref(drig, person, pts, device)
    assert np.ptp(lt) > 1.0  # the person-level terms vary over the points
    np.testing.assert_allclose(lo.numpy(), lm.numpy() + la.numpy() + lt, rtol=1e-5, atol=1e-4)


def run_predict(
    device, pos, vel, model, desc, mass, anc, sp, sv, alpha, seed, frame, dt=1.0, observe=(1, 1), decay=1.0,
    jump_cams=None, jump_share=0.0, jump_span=0.0, others=None, alive=None, own=0, jump_clear=0.0,
):  # fmt: skip
    n = len(pos)
    if jump_cams is None:
        jump_cams = wp.zeros(0, dtype=KCamera, device=device)
    others = np.zeros((0, 2), np.float32) if others is None else np.asarray(others, np.float32)
    alive = np.ones(len(others), np.int32) if alive is None else np.asarray(alive, np.int32)
    outs = [
        wp.zeros(n, dtype=wp.vec3, device=device),
        wp.zeros(n, dtype=wp.vec3, device=device),
        wp.zeros(model.shape, dtype=wp.float32, device=device),
    ]
    wp.launch(
        kpeople.predict_kernel,
        dim=n,
        inputs=[
            wp.array(pos, dtype=wp.vec3, device=device),
            wp.array(vel, dtype=wp.vec3, device=device),
            wp.array(model, device=device),
            wp.array(desc, device=device),
            wp.array(mass, device=device),
            wp.array(anc, device=device),
            wp.array([sp], dtype=wp.float32, device=device),
            wp.array(np.broadcast_to(np.asarray(sv, np.float32), 2).copy(), dtype=wp.float32, device=device),
            wp.array([dt], dtype=wp.float32, device=device),
            wp.array([alpha], dtype=wp.float32, device=device),
            wp.array(np.asarray(observe, np.int32), device=device),
            wp.array([decay], dtype=wp.float32, device=device),
            wp.vec2ui(seed, 0),
            wp.array([frame], dtype=wp.int32, device=device),
            jump_cams,
            jump_share,
            jump_span,
            wp.array(others, dtype=wp.vec2, device=device),
            wp.array(alive, dtype=wp.int32, device=device),
            own,
            jump_clear,
        ],
        outputs=outs,
        device=device,
    )
    return [o.numpy() for o in outs]


def test_predict_statistics_and_appearance_update(device, rng):
    n = 20_000
    pos = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    vel = rng.normal(0, 0.05, (n, 3)).astype(np.float32)
    model = random_histograms(rng, n)
    desc = random_histograms(rng, n)
    mass = np.ones(n, np.float32)
    mass[::7] = 0  # unseen parents keep their appearance
    anc = rng.integers(0, n, n).astype(np.int32)
    sp, sv, alpha = 0.02, (0.005, 0.012), 0.1  # horizontal and vertical velocity noise
    p, v, c = run_predict(device, pos, vel, model, desc, mass, anc, sp, sv, alpha, 11, 5)
    npos = p.astype(np.float64) - pos[anc] - vel[anc]  # eq. 5: position noise
    nvel = v.astype(np.float64) - vel[anc]  # velocity noise
    for noise, s in ((npos, np.full(3, sp)), (nvel, np.array([sv[0], sv[0], sv[1]]))):
        assert np.all(np.abs(noise.mean(0)) < 5 * s / np.sqrt(n))
        np.testing.assert_allclose(noise.std(0), s, rtol=0.03)  # sd of the sd estimate: 0.5 %
    # the 6 components are uncorrelated (|r| < 0.03 is ~4 standard errors at n = 20000)
    r = np.corrcoef(np.hstack([npos, nvel]).T)
    assert np.abs(r - np.eye(6)).max() < 0.03
    ref = np.where(mass[anc, None] > 0, alpha * desc[anc] + (1 - alpha) * model[anc], model[anc])  # eq. 6
    np.testing.assert_allclose(c, ref, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(c.reshape(n, 3, NB).sum(2), 1.0, rtol=1e-5)
    # the same seed and frame give identical output; another frame or seed gives other noise
    again = run_predict(device, pos, vel, model, desc, mass, anc, sp, sv, alpha, 11, 5)
    for a, b in zip(again, (p, v, c), strict=True):
        np.testing.assert_array_equal(a, b)
    p2, v2, _ = run_predict(device, pos, vel, model, desc, mass, anc, sp, sv, alpha, 11, 6)
    p3, _, _ = run_predict(device, pos, vel, model, desc, mass, anc, sp, sv, alpha, 12, 5)
    assert not np.any(np.all(p2 == p, axis=1)) and not np.any(np.all(v2 == v, axis=1))
    assert not np.any(np.all(p3 == p, axis=1))


def test_predict_unseen_person_slows_down_and_keeps_its_appearance(device, rng):
    """observe[0] = 0 (this frame's masks do not show the person): the parent's velocity is multiplied by the decay
    before eq. 5; observe[1] = 0 (nor the last frame's): eq. 6 keeps the appearance model C_{t-1}."""
    n = 2000
    pos = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    vel = rng.normal(0, 0.5, (n, 3)).astype(np.float32)
    model, desc = random_histograms(rng, n), random_histograms(rng, n)
    anc = rng.integers(0, n, n).astype(np.int32)
    args = (device, pos, vel, model, desc, np.ones(n, np.float32), anc, 0.02, 0.01, 0.3, 3, 9)
    p1, v1, c1 = run_predict(*args, dt=0.2, observe=(1, 1), decay=0.5)
    p0, v0, c0 = run_predict(*args, dt=0.2, observe=(0, 0), decay=0.5)
    # the same noise draws: the differences are the decayed velocity (position: times dt)
    np.testing.assert_allclose(v1 - v0, 0.5 * vel[anc], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(p1 - p0, 0.2 * 0.5 * vel[anc], rtol=1e-4, atol=1e-5)
    np.testing.assert_array_equal(c0, model[anc])  # kept
    np.testing.assert_allclose(c1, 0.3 * desc[anc] + 0.7 * model[anc], rtol=1e-6, atol=1e-7)


def run_occupancy(device, pts, logw, sigma, cutoff, origin, voxel, shape):
    grid = wp.zeros(shape, dtype=wp.float32, device=device)
    l64 = logw.astype(np.float64)
    log_norm = l64.max() + np.log(np.exp(l64 - l64.max()).sum())
    wp.launch(
        kocc.occupancy_kernel,
        dim=shape,
        inputs=[
            wp.array(pts, dtype=wp.vec3, device=device),
            wp.array(logw, dtype=wp.float32, device=device),
            wp.array([log_norm], dtype=wp.float64, device=device),
            sigma,
            cutoff,
            wp.vec3(*origin),
            voxel,
        ],
        outputs=[grid],
        device=device,
    )
    return grid.numpy()


def test_occupancy_matches_brute_force_and_integrates(device, rng):
    n = 200
    pts = rng.uniform(0, 1, (n, 3)).astype(np.float32)
    logw = (rng.normal(size=n) * 2 - 30).astype(np.float32)
    sigma, cutoff, origin, voxel, shape = 0.1, 3.0, (-0.1, 0.05, -0.2), 0.07, (18, 14, 20)
    got = run_occupancy(device, pts, logw, sigma, cutoff, origin, voxel, shape)
    w = np.exp(logw.astype(np.float64) - logw.max())
    w /= w.sum()
    idx = np.stack(np.meshgrid(*[np.arange(s) for s in shape], indexing="ij"), -1)
    centres = np.array(origin) + (idx + 0.5) * voxel
    d2 = ((centres[..., None, :] - pts.astype(np.float64)) ** 2).sum(-1)
    k = np.where(d2 <= (cutoff * sigma) ** 2, np.exp(-d2 / (2 * sigma**2)), 0.0) / (2 * np.pi * sigma**2) ** 1.5
    ref = (k * w).sum(-1)
    np.testing.assert_allclose(got, ref, rtol=2e-5, atol=1e-6 * ref.max())
    np.testing.assert_array_equal(got, run_occupancy(device, pts, logw, sigma, cutoff, origin, voxel, shape))
    # a grid covering every kernel: the mass is 1 (cutoff 6 sigma) or P(chi2_3 <= 9) = 0.97071 (cutoff 3 sigma)
    big = dict(origin=(-0.7, -0.7, -0.7), voxel=0.05, shape=(48, 48, 48))
    for cut, mass in ((6.0, 1.0), (3.0, 0.970709)):
        g = run_occupancy(device, pts, logw, sigma, cut, big["origin"], big["voxel"], big["shape"])
        assert g.sum() * big["voxel"] ** 3 == pytest.approx(mass, abs=2e-3)


@pytest.mark.parametrize("resampled", [0, 1])
def test_step_kernel_equals_separate_kernels(device, rng, resampled):
    """The fused frame gives the same state, descriptor, log-weights and block partials as predict -> descriptor
    -> observation -> kernel_harness.block_partials_kernel launched one after another."""
    from wptrack.kernels.core import reduce as kred

    rig = make_rig()
    drig = DeviceRig(rig, device)
    n, chunk, block = 300, 64, 32
    nbk = (n + chunk - 1) // chunk
    bgr = random_frames(rig, rng)
    B = wp.array(bgr, dtype=wp.uint8, device=device)
    flat = motion_masks(rig, rng)
    mask = wp.array(flat, dtype=wp.uint8, device=device)
    person = person_inputs(rig, drig, flat, device, rng)
    observe = wp.array(np.array([1, 1], np.int32), device=device)
    decay = wp.array([0.5], dtype=wp.float32, device=device)
    pos = wp.array(random_points(rng, n), dtype=wp.vec3, device=device)
    vel = wp.array(rng.normal(0, 0.02, (n, 3)).astype(np.float32), dtype=wp.vec3, device=device)
    model = wp.array(random_histograms(rng, n), device=device)
    desc = wp.array(random_histograms(rng, n), device=device)
    m0 = rng.uniform(0.5, 1, n).astype(np.float32)
    m0[::9] = 0
    mass = wp.array(m0, device=device)
    anc = wp.array(rng.integers(0, n, n).astype(np.int32), device=device)
    logw_prev = wp.array(rng.normal(0, 1, n).astype(np.float32), device=device)
    flag = wp.array([resampled], dtype=wp.int32, device=device)
    sp, sn, dt, alpha = (wp.array([x], dtype=wp.float32, device=device) for x in (0.02, 0.01, 0.3, 0.05))
    sv = wp.array([0.004, 0.009], dtype=wp.float32, device=device)
    seed, frame = wp.vec2ui(3, 4), wp.array([7], dtype=wp.int32, device=device)
    p_b, sigma_p = 0.1, 0.3
    jumps = (0.6, 2.0, 0.3)  # ray_jump: share of the particles, span and clearance (m)

    def zeros(shape, dtype=wp.float32):
        return wp.zeros(shape, dtype=dtype, device=device)

    fused = dict(
        pos=zeros(n, wp.vec3),
        vel=zeros(n, wp.vec3),
        model=zeros((n, 3 * NB)),
        desc=zeros((n, 3 * NB)),
        mass=zeros(n),
        rgb=zeros(n, wp.vec3),
        logw=zeros(n),
        pmax=zeros(nbk),
        parg=zeros(nbk, wp.int32),
        part=zeros((nbk, kred.N_SUMS), wp.float64),
    )
    wp.launch_tiled(
        kpeople.step_kernel,
        dim=[nbk],
        inputs=[drig.cams, mask, p_b, 0.0, 1, B, R_N, NB, R_MIN, R_MAX, 2, pos, vel, model, desc, mass, anc]
        + [logw_prev, flag, sp, sv, dt, alpha, observe, decay, sn, sigma_p, seed, frame, *person, n, chunk, *jumps],
        outputs=list(fused.values()),
        block_dim=block,
        device=device,
    )
    sep = {k: zeros(v.shape, v.dtype) for k, v in fused.items()}
    wp.launch(
        kpeople.predict_kernel,
        dim=n,
        inputs=[pos, vel, model, desc, mass, anc, sp, sv, dt, alpha, observe, decay, seed, frame, drig.cams]
        + [*jumps[:2], person[2], person[3], person[5], jumps[2]],
        outputs=[sep["pos"], sep["vel"], sep["model"]],
        device=device,
    )
    wp.launch(
        kdesc.descriptor_kernel,
        dim=n,
        inputs=[drig.cams, B, sep["pos"], R_N, NB, R_MIN, R_MAX, 2],
        outputs=[sep["desc"], sep["mass"], sep["rgb"]],
        device=device,
    )
    wp.launch(
        harness.observation_kernel,
        dim=n,
        inputs=[drig.cams, mask, p_b, 0.0, 1, sep["pos"], sep["model"], sep["desc"], sep["mass"], sep["rgb"], NB, sn]
        + [sigma_p, *person],
        outputs=[sep["logw"]],
        device=device,
    )
    logw = sep["logw"].numpy() + (0 if resampled else logw_prev.numpy())
    wp.launch_tiled(
        harness.block_partials_kernel,
        dim=[nbk],
        inputs=[wp.array(logw, device=device), sep["pos"], n, chunk],
        outputs=[sep["pmax"], sep["parg"], sep["part"]],
        block_dim=block,
        device=device,
    )
    for k in ("pos", "vel", "model", "desc", "mass", "rgb", "pmax", "parg"):
        np.testing.assert_array_equal(fused[k].numpy(), sep[k].numpy(), err_msg=k)
    np.testing.assert_allclose(fused["logw"].numpy(), logw, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(fused["part"].numpy(), sep["part"].numpy(), rtol=1e-6)
    # the data covers both cases: particles no camera sees (2 on CUDA, 3 on the CPU: rounding at the image border)
    assert (fused["mass"].numpy() == 0).sum() >= 2 and (fused["mass"].numpy() > 0).sum() >= 200

    # the GPU chain of the tracker: predict -> descriptor (one block per particle) -> score + block moments
    gpu = {k: zeros(v.shape, v.dtype) for k, v in fused.items()}
    wp.launch(
        kpeople.predict_kernel,
        dim=n,
        inputs=[pos, vel, model, desc, mass, anc, sp, sv, dt, alpha, observe, decay, seed, frame, drig.cams]
        + [*jumps[:2], person[2], person[3], person[5], jumps[2]],
        outputs=[gpu["pos"], gpu["vel"], gpu["model"]],
        device=device,
    )
    wp.launch_tiled(
        kdesc.descriptor_block_kernel,
        dim=[n],
        inputs=[drig.cams, B, gpu["pos"], R_N, NB, R_MIN, R_MAX, 2],
        outputs=[gpu["desc"], gpu["mass"], gpu["rgb"]],
        block_dim=64,
        device=device,
    )
    wp.launch_tiled(
        kpeople.score_moments_kernel,
        dim=[nbk],
        inputs=[drig.cams, mask, p_b, 0.0, 1, gpu["pos"], gpu["model"], gpu["desc"], gpu["mass"], gpu["rgb"], NB]
        + [logw_prev, flag, sn, sigma_p, *person, observe, n, chunk],
        outputs=[gpu["logw"], gpu["pmax"], gpu["parg"], gpu["part"]],
        block_dim=block,
        device=device,
    )
    for k in ("pos", "vel", "model"):
        np.testing.assert_array_equal(gpu[k].numpy(), fused[k].numpy(), err_msg=k)
    for k in ("desc", "mass", "rgb", "logw", "pmax"):  # the block sums the disc pixels in another order
        np.testing.assert_allclose(gpu[k].numpy(), fused[k].numpy(), rtol=1e-4, atol=1e-5, err_msg=k)
    np.testing.assert_allclose(gpu["part"].numpy(), fused["part"].numpy(), rtol=1e-4, atol=1e-9)

    # a frame whose masks do not show the person: no weighting (the previous log-weights, or 0 after resampling),
    # the velocity decayed, the appearance model kept; the GPU chain's score kernel agrees
    observe.assign(np.array([0, 0], np.int32))
    unseen = {k: zeros(v.shape, v.dtype) for k, v in fused.items()}
    wp.launch_tiled(
        kpeople.step_kernel,
        dim=[nbk],
        inputs=[drig.cams, mask, p_b, 0.0, 1, B, R_N, NB, R_MIN, R_MAX, 2, pos, vel, model, desc, mass, anc]
        + [logw_prev, flag, sp, sv, dt, alpha, observe, decay, sn, sigma_p, seed, frame, *person, n, chunk, *jumps],
        outputs=list(unseen.values()),
        block_dim=block,
        device=device,
    )
    expect = np.zeros(n, np.float32) if resampled else logw_prev.numpy()
    np.testing.assert_array_equal(unseen["logw"].numpy(), expect)
    a = anc.numpy()
    np.testing.assert_array_equal(unseen["model"].numpy(), model.numpy()[a])
    np.testing.assert_allclose(fused["vel"].numpy() - unseen["vel"].numpy(), 0.5 * vel.numpy()[a], atol=1e-6)
    wp.launch_tiled(
        kpeople.score_moments_kernel,
        dim=[nbk],
        inputs=[drig.cams, mask, p_b, 0.0, 1, unseen["pos"], unseen["model"], unseen["desc"], unseen["mass"]]
        + [unseen["rgb"], NB, logw_prev, flag, sn, sigma_p, *person, observe, n, chunk],
        outputs=[gpu["logw"], gpu["pmax"], gpu["parg"], gpu["part"]],
        block_dim=block,
        device=device,
    )
    np.testing.assert_array_equal(gpu["logw"].numpy(), expect)


def test_occupancy_hashgrid_equals_brute_force(device, rng):
    n = 500
    pts = rng.uniform(0, 1, (n, 3)).astype(np.float32)
    logw = (rng.normal(size=n) * 2).astype(np.float32)
    sigma, cutoff, origin, voxel, shape = 0.08, 3.0, (-0.2, -0.2, -0.2), 0.06, (24, 24, 24)
    ref = run_occupancy(device, pts, logw, sigma, cutoff, origin, voxel, shape)
    l64 = logw.astype(np.float64)
    log_norm = l64.max() + np.log(np.exp(l64 - l64.max()).sum())
    P = wp.array(pts, dtype=wp.vec3, device=device)
    hg = wp.HashGrid(16, 16, 16, device=device)
    hg.build(P, cutoff * sigma)
    grid = wp.zeros(shape, dtype=wp.float32, device=device)
    args = [hg.id, P, wp.array(logw, device=device), wp.array([log_norm], dtype=wp.float64, device=device)]
    wp.launch(
        harness.occupancy_hashgrid_kernel,
        dim=shape,
        inputs=[*args, sigma, cutoff, wp.vec3(*origin), voxel],
        outputs=[grid],
        device=device,
    )
    got = grid.numpy()
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-6 * ref.max())
    assert (ref > 0).mean() > 0.3


def column_walk_ref(seen, min_cameras, max_gap, z_lo, dz):
    """The top of every (person, axis) column of camera counts ``seen`` (P, 9, nz) by the walk of
    ``column_top_kernel``, written as plain loops."""
    top = np.full(seen.shape[:2], -1.0)
    for i, a in np.ndindex(*top.shape):
        started, gap = False, 0
        for k in range(seen.shape[2]):
            if seen[i, a, k] >= min_cameras:
                top[i, a], started, gap = z_lo + dz * k, True, 0
            elif started:
                gap += 1
                if gap > max_gap:
                    break
    return top


def test_column_seen_counts(device, rng):
    rig = make_rig()
    drig = DeviceRig(rig, device)
    mask = motion_masks(rig, rng)
    people = np.concatenate([rng.uniform(0.0, 1.0, (5, 2)), [[9.0, 9.0]]]).astype(np.float32)  # one out of view
    z_lo, dz, nz, search = 0.05, 0.03, 40, 0.04
    grid = np.array(
        [
            (*(p + search * np.array([a // 3 - 1, a % 3 - 1])), z_lo + dz * k)
            for p in people
            for a in range(9)
            for k in range(nz)
        ],
        dtype=np.float32,
    )
    uvz = project_all(drig, grid, device)
    ref = np.zeros(len(grid), dtype=np.int64)
    for c, cam in enumerate(rig.cameras):
        u, v, z = uvz[c].T
        px, py = np.floor(u + 0.5).astype(int), np.floor(v + 0.5).astype(int)
        inside = (z > 0) & (px >= 0) & (py >= 0) & (px < cam.width) & (py < cam.height)
        q = drig.pixel_offsets[c] + np.clip(py, 0, cam.height - 1) * cam.width + np.clip(px, 0, cam.width - 1)
        ref += inside & (mask[q] != 0)
    seen = wp.full((len(people), kpeople.COLUMN_AXES, nz), 7, dtype=wp.uint8, device=device)
    alive = np.ones(len(people), np.int32)
    alive[2] = 0  # a free slot: its row is zero
    wp.launch(
        kpeople.column_seen_kernel,
        dim=seen.shape,
        inputs=[
            drig.cams,
            wp.array(mask, dtype=wp.uint8, device=device),
            wp.array(people, dtype=wp.vec2, device=device),
            wp.array(alive, dtype=wp.int32, device=device),
            z_lo,
            dz,
            search,
        ],
        outputs=[seen],
        device=device,
    )
    got = seen.numpy().reshape(len(people), -1)
    ref = ref.reshape(len(people), -1)
    assert ref[2].any()  # the free slot's position is in view: only alive zeroes it
    ref[2] = 0
    np.testing.assert_array_equal(got, ref)
    assert len(np.unique(got)) >= 3 and not got[-1].any()  # 0, 1, 2+ cameras; nothing seen out of view


@pytest.mark.parametrize(("min_cameras", "max_gap"), [(2, 2), (1, 0), (3, 3), (2, 10)])
def test_column_top_walk(device, rng, min_cameras, max_gap):
    # runs of support broken by holes of 0 to 6 steps, noise below and above
    nz = 60
    shape = (7, kpeople.COLUMN_AXES, nz)
    seen = (rng.integers(0, 4, shape) * (rng.random(shape) < 0.1)).astype(np.uint8)
    for i, a in np.ndindex(7, kpeople.COLUMN_AXES):
        lo, hole, hi = sorted(rng.integers(0, nz, 3))
        seen[i, a, lo:hi] = 3
        seen[i, a, hole : hole + rng.integers(0, 7)] = 0
    seen[0, 0] = 0  # an empty column
    z_lo, dz = 0.05, 0.03
    ref = column_walk_ref(seen.astype(np.int64), min_cameras, max_gap, z_lo, dz)
    top = wp.zeros(seen.shape[:2], dtype=wp.float32, device=device)
    wp.launch(
        kpeople.column_top_kernel,
        dim=top.shape,
        inputs=[wp.array(seen, dtype=wp.uint8, device=device), z_lo, dz, nz, min_cameras, max_gap],
        outputs=[top],
        device=device,
    )
    np.testing.assert_allclose(top.numpy(), ref, atol=1e-6)
    assert ref[0, 0] == -1.0 and len(np.unique(ref)) > 10 and (ref < 0).sum() == 1


def test_ray_jump_moves_a_share_of_the_particles_along_a_camera_ray(device):
    """``ray_jump`` (through ``predict_kernel``, no other noise): the given share of the particles jumps (binomial
    bounds), each jumped particle lies on the ground line from one camera's centre through the start point, at an
    offset uniform in [-span, span] along it, each camera's ray taken about equally, the height kept; share 0 moves
    nothing; no jump lands within ``jump_clear`` of another tracked person (a dead slot and the filter's own do not
    count), and without that person there, jumps do land there."""
    rig = make_rig()
    drig = DeviceRig(rig, device)
    n, share, span = 40_000, 0.2, 1.5
    start = np.array([0.7, 0.4, 0.9], np.float32)
    pos = np.tile(start, (n, 1))
    vel = np.zeros((n, 3), np.float32)
    model = np.full((n, 3 * NB), 1.0 / NB, np.float32)
    mass = np.zeros(n, np.float32)
    anc = np.arange(n, dtype=np.int32)
    args = (device, pos, vel, model, model, mass, anc, 0.0, 0.0, 0.0, 11, 5)
    still, _, _ = run_predict(*args, dt=0.1, jump_cams=drig.cams, jump_share=0.0, jump_span=span)
    assert np.array_equal(still, pos)
    got, _, _ = run_predict(*args, dt=0.1, jump_cams=drig.cams, jump_share=share, jump_span=span)
    moved = np.any(got != pos, axis=1)
    assert abs(moved.mean() - share) < 4.0 * np.sqrt(share * (1 - share) / n)
    assert np.array_equal(got[:, 2], pos[:, 2])
    d = got[moved, :2] - start[:2]
    centres = np.array([c.center[:2] for c in rig.cameras])
    rays = start[:2] - centres
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    across = np.abs(d[:, None, 0] * rays[None, :, 1] - d[:, None, 1] * rays[None, :, 0])  # (m, cameras)
    which = np.argmin(across, axis=1)
    assert across[np.arange(len(d)), which].max() < 1e-5
    along = np.sum(d * rays[which], axis=1)
    assert np.abs(along).max() <= span + 1e-5
    assert abs(along.mean()) < 0.05 and abs(np.mean(np.abs(along)) - span / 2) < 0.05  # U(-span, span)
    counts = np.bincount(which, minlength=len(centres)) / len(which)
    assert np.all(np.abs(counts - 1 / len(centres)) < 0.03)
    # another tracked person 1 m along camera 0's ray
    other = start[:2] + 1.0 * rays[0]
    kw = dict(dt=0.1, jump_cams=drig.cams, jump_share=share, jump_span=span, jump_clear=0.5)
    got, _, _ = run_predict(*args, others=[other, other + 0.01, start[:2]], alive=[1, 0, 1], own=2, **kw)
    moved = np.any(got != pos, axis=1)
    near = np.linalg.norm(got[:, :2] - other, axis=1) < 0.5
    assert not np.any(moved & near) and 0.005 < share - moved.mean() < 0.05  # the few jumps that would land there
    free, _, _ = run_predict(*args, others=[other], alive=[0], own=1, **kw)
    assert np.any(np.linalg.norm(free[:, :2] - other, axis=1) < 0.5)  # without that person, jumps land there
