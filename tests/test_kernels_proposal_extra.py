"""Proposal kernels not covered by test_proposal.py, against NumPy references on every device: the detection
components (``detection_components_kernel``: camera pair, rejection-sampled target pixels, triangulation or a point
along one ray, from a NumPy Philox and cv2 rays; test_proposal only checks that they lie on the ball), the count of
valid components (``detection_count_kernel``) and the fused S1 iteration with the mixture proposal
(``colour_mixture_predict_score_kernel``): branch choice, draw and log p/q of every particle from a NumPy Philox
and the NumPy densities of test_proposal, eqs. 5-7 from cv2 projections, the weights' accumulation, alpha = 1 on the
first frame after a uniform initialisation, eps = 0 when no component is valid, and the per-block partials."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from kernel_refs import check_partials, normal4_ref, uniform4_ref
from test_kernels_colour import TARGETS, make_rig, mask_and_integral, random_frames, upload, window_ref
from test_kernels_random import philox_ref
from test_kernels_scoring_extra import FRAME, SEED, launch_fused
from test_proposal import HI, LO, np_log_det, np_log_motion, ray_dir, rig3

from wptrack.cameras.structs import DeviceRig
from wptrack.kernels.colour import proposal as kproposal
from wptrack.kernels.colour import scoring as kscoring
from wptrack.kernels.core import random as krand


def components_ref(rig, masks, seed, frame, k, tries, max_gap, depth_lo, depth_hi):
    """(centres (K, 3), valid (K,), ambiguous (K,)) float64: ``ambiguous`` marks a gap within 1e-4 m of max_gap."""
    m = len(rig.cameras)

    def words(t):
        ctr = np.stack([np.arange(k), np.full(k, frame), np.full(k, int(kproposal.STREAM_PROPOSAL_PIXELS)), t], 1)
        return philox_ref(ctr.astype(np.uint64), seed).astype(np.int64)

    w0 = words(np.zeros(k))
    cam_a = w0[:, 0] % m
    cam_b = (cam_a + 1 + w0[:, 1] % (m - 1)) % m if m > 1 else cam_a
    draws = np.stack([words(np.full(k, t + 1)) for t in range(tries)])  # (tries, K, 4)
    centres = np.zeros((k, 3))
    valid = np.zeros(k, int)
    amb = np.zeros(k, bool)
    for i in range(k):
        ca, cb = rig.cameras[cam_a[i]], rig.cameras[cam_b[i]]

        def first_hit(c, col, cam, i=i):
            q = draws[:, i, col] % (cam.width * cam.height)  # uniform pixel draws, the first on the target wins
            hits = np.flatnonzero(masks[c].reshape(-1)[q])
            return int(q[hits[0]]) if len(hits) else -1

        pa = first_hit(cam_a[i], 0, ca)
        pb = first_hit(cam_b[i], 1, cb) if m > 1 else -1
        if pa < 0:
            continue
        da = ray_dir(ca, (pa % ca.width, pa // ca.width))
        if pb >= 0:
            db = ray_dir(cb, (pb % cb.width, pb // cb.width))
            (s, t), *_ = np.linalg.lstsq(np.stack([da, -db], 1), cb.center - ca.center, rcond=None)
            p1, p2 = ca.center + s * da, cb.center + t * db
            gap = np.linalg.norm(p1 - p2)
            amb[i] = abs(gap - max_gap) < 1e-4
            if s > 0 and t > 0 and gap <= max_gap:
                centres[i], valid[i] = 0.5 * (p1 + p2), 1
                continue
        depth = depth_lo + (depth_hi - depth_lo) * ((w0[i, 2] >> 8) + 0.5) / 16777216.0
        centres[i], valid[i] = ca.center + depth * da, 2
    return centres, valid, amb


@pytest.mark.parametrize("blank", [None, 1], ids=["all_cameras", "camera1_blank"])
def test_detection_components_match_numpy(device, rng, blank):
    rig = rig3()
    frames = random_frames(rig, rng)
    if blank is not None:
        frames[blank][:] = 90  # grey: no target pixel in that camera
    drig = DeviceRig(rig, device)
    target = TARGETS[0]
    bgr = upload(frames, device)
    mask, *_ = mask_and_integral(drig, target, bgr, device)
    mk = mask.numpy().astype(bool)
    masks = [mk[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]] for c in range(len(rig.cameras))]
    k, tries, max_gap, depth_lo, depth_hi = 96, 40, 0.2, 0.1, 2.5
    centres = wp.full(k, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device)
    valid = wp.full(k, 7, dtype=wp.int32, device=device)
    wp.launch(
        kproposal.detection_components_kernel,
        dim=k,
        inputs=[
            drig.cams,
            target.to_struct(device),
            bgr,
            wp.vec2ui(*SEED),
            wp.array([FRAME], dtype=wp.int32, device=device),
            tries,
            max_gap,
            depth_lo,
            depth_hi,
        ],
        outputs=[centres, valid],
        device=device,
    )
    ref_c, ref_v, amb = components_ref(rig, masks, SEED, FRAME, k, tries, max_gap, depth_lo, depth_hi)
    got_c, got_v = centres.numpy(), valid.numpy()
    assert amb.sum() <= 2
    np.testing.assert_array_equal(got_v[~amb], ref_v[~amb])
    np.testing.assert_allclose(got_c[~amb], ref_c[~amb], atol=2e-3)
    if blank is None:
        assert (ref_v == 1).sum() >= 10 and (ref_v == 2).sum() >= 10  # both kinds of component
    else:
        assert (ref_v == 0).sum() >= 10 and (ref_v == 2).sum() >= 10  # camera a blank: none; camera b blank: a ray


def detection_count(device, valid) -> int:
    count = wp.full(1, -7, dtype=wp.int32, device=device)
    wp.launch(
        kproposal.detection_count_kernel,
        dim=1,
        inputs=[wp.array(np.asarray(valid, np.int32), dtype=wp.int32, device=device)],
        outputs=[count],
        device=device,
    )
    return int(count.numpy()[0])


def test_detection_count_matches_numpy(device, rng):
    for k in (1, 5, 64, 257):
        valid = rng.integers(0, 3, k)  # 0 invalid, 1 and 2 valid (paired or single-camera components)
        assert detection_count(device, valid) == int(np.count_nonzero(valid))
    assert detection_count(device, np.zeros(16)) == 0
    assert detection_count(device, np.full(16, 2)) == 16


def mixture_ref(parents, centres, valid, sigma, alpha, eps, sd):
    """(x, log p - log q) of every particle (float64) from the NumPy Philox streams of the kernel."""
    n = len(parents)
    count = int(np.count_nonzero(valid))
    e = np.float32(eps if count else 0.0)
    u = uniform4_ref(SEED, n, FRAME, int(kproposal.STREAM_PROPOSAL_MIX))
    z = normal4_ref(SEED, n, FRAME, int(krand.STREAM_MOTION))[:, :3]
    box = uniform4_ref(SEED, n, FRAME, int(kproposal.STREAM_PROPOSAL_BOX))[:, :3]
    det = u[:, 0] < e
    reset = ~det & (u[:, 2] < np.float32(alpha))
    idx = np.flatnonzero(valid)
    j = np.minimum((u[:, 1].astype(np.float32) * np.float32(max(count, 1))).astype(int), max(count - 1, 0))
    c = centres[idx[j]] if count else np.zeros((n, 3))
    x = np.where(det[:, None], c + sd * z, np.where(reset[:, None], LO + (HI - LO) * box, parents + sigma * z))
    with np.errstate(divide="ignore"):
        lp = np_log_motion(x, parents, sigma, alpha)
        lq = lp if e == 0 else np.logaddexp(np.log(1 - e) + lp, np.log(e) + np_log_det(x, centres, valid, sd))
    return x, lp - lq, det, reset


@pytest.mark.parametrize(
    ("case", "resampled"),
    [("plain", True), ("plain", False), ("first_frame", True), ("no_detection", False)],
)
def test_colour_mixture_predict_score_matches_numpy(device, rng, case, resampled):
    rig = make_rig(rng)
    frames = random_frames(rig, rng)
    drig = DeviceRig(rig, device)
    target = TARGETS[0]
    bgr = upload(frames, device)
    mask, integral, window, _ = mask_and_integral(drig, target, bgr, device)
    n, chunk, sigma, sd, eps, alpha = 1200, 256, 0.02, 0.03, 0.3, 0.05
    parents = rng.uniform([0.0, 0.0, 0.0], [0.8, 0.8, 0.4], (n, 3)).astype(np.float32).astype(np.float64)
    anc = rng.integers(0, n, n)
    logw_prev = rng.normal(-3.0, 2.0, n)
    centres = rng.uniform([0.2, 0.2, 0.05], [0.6, 0.6, 0.3], (12, 3)).astype(np.float32).astype(np.float64)
    valid = np.zeros(12, int) if case == "no_detection" else rng.integers(0, 3, 12)
    valid[3] = 0 if case == "no_detection" else 2  # at least one valid component when there are detections
    count = wp.zeros(1, dtype=wp.int32, device=device)
    valid_dev = wp.array(valid.astype(np.int32), dtype=wp.int32, device=device)
    wp.launch(kproposal.detection_count_kernel, dim=1, inputs=[valid_dev], outputs=[count], device=device)
    uniform_frame = FRAME if case == "first_frame" else -1
    obs = [drig.cams, target.to_struct(device), bgr, integral, window, int(kscoring.SCORE_INTEGRAL)]
    obs += [wp.array(centres.astype(np.float32), dtype=wp.vec3, device=device), valid_dev, count, sd, eps, alpha]
    obs += [wp.array([uniform_frame], dtype=wp.int32, device=device), wp.vec3(*LO), wp.vec3(*HI)]
    x, lw, parts = launch_fused(
        kproposal.colour_mixture_predict_score_kernel, obs, parents, anc, logw_prev, resampled, sigma, n, chunk, device
    )
    a = 1.0 if case == "first_frame" else alpha
    ref_x, ratio, det, reset = mixture_ref(parents[anc], centres, valid, sigma, a, eps, sd)
    np.testing.assert_allclose(x, ref_x, rtol=0, atol=3e-6)
    # every branch was taken (and only those possible)
    if case == "no_detection":
        assert not det.any() and reset.any()
        np.testing.assert_array_equal(ratio, 0.0)
    elif case == "first_frame":
        assert det.any() and reset[~det].all()
    else:
        assert det.sum() > 0.2 * n and reset.any() and (~det & ~reset).sum() > 0.5 * n
    ll = np.zeros(n)
    amb = np.zeros(n, bool)
    mk = mask.numpy()
    for c, cam in enumerate(rig.cameras):
        m2 = mk[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(cam.height, cam.width).astype(np.int64)
        cnt, am = window_ref(cam, m2, x.astype(np.float64))
        ll += np.where(cnt < 0, np.log(1 / 25), np.log(np.maximum(cnt, 1) / 25))
        amb |= am
    assert amb.sum() < 0.02 * n
    ref_lw = ll + ratio + (0.0 if resampled else logw_prev)
    zero_prior = np.isneginf(ref_lw)  # p(x | parent) = 0 (outside the box on the first frame): log 0 is LOG_ZERO
    assert np.all(lw[zero_prior] < -1e29)
    ok = ~amb & ~zero_prior
    np.testing.assert_allclose(lw[ok], ref_lw[ok], rtol=1e-4, atol=2e-3)
    check_partials(parts, lw, x, chunk)
