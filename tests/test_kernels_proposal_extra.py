"""Detection-jump kernels (``kernels.colour.proposal``, issue 29) against NumPy references on every device: the fused
S1 iteration with jumps (``colour_jump_predict_score_kernel`` and its camera-set form): the jump decision from the
fourth motion normal, the component from the proposal stream, the draw of every particle from a NumPy Philox, eqs.
5-7 from cv2 projections, the weights' accumulation, the uniform first frame after a random initialisation, no jump
without candidates, and the per-block partials; the mode test (``jump_decision_kernel``) frame by frame: candidate
count, component weights, the cloud's score, the CUSUM and the threshold; ``set_anchor_kernel``."""

from __future__ import annotations

from statistics import NormalDist

import numpy as np
import pytest
import warp as wp
from kernel_refs import check_partials, normal4_ref, uniform4_ref
from test_kernels_colour import TARGETS, make_rig, mask_and_integral, random_frames, upload, window_ref
from test_kernels_scoring_extra import FRAME, SEED, launch_fused, partials_rtol
from test_proposal import HI, LO

from wptrack.cameras.structs import DeviceRig
from wptrack.kernels.colour import proposal as kproposal
from wptrack.kernels.colour import scoring as kscoring
from wptrack.kernels.core import random as krand
from wptrack.kernels.core import reduce as kreduce

LOG_ZERO = float(kproposal.LOG_ZERO)


def jump_ref(parents, det_pos, det_cum, count, threshold, uniform, sigma, sd):
    """(x (n, 3), jumped (n,), box (n,)) of every particle, float64, from the NumPy Philox streams of the kernel."""
    n = len(parents)
    z = normal4_ref(SEED, n, FRAME, int(krand.STREAM_MOTION))
    u = uniform4_ref(SEED, n, FRAME, int(kproposal.STREAM_PROPOSAL_MIX))
    b = uniform4_ref(SEED, n, FRAME, int(kproposal.STREAM_PROPOSAL_BOX))[:, :3]
    jumped = (z[:, 3] < np.float32(threshold)) & (count > 0)
    comp = np.array([min(int(np.sum(det_cum[:count] <= v)), count - 1) for v in u[:, 0]]) if count else np.zeros(n, int)
    x = parents + sigma * z[:, :3]
    if uniform:
        x = LO + (HI - LO) * b
    x = np.where(jumped[:, None], det_pos[comp] + sd * z[:, :3], x)
    return x, jumped, ~jumped & bool(uniform)


def loglik_ref(rig, drig, mask, x):
    mk = mask.numpy()
    ll = np.zeros(len(x))
    amb = np.zeros(len(x), bool)
    for c, cam in enumerate(rig.cameras):
        m2 = mk[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(cam.height, cam.width).astype(np.int64)
        cnt, a = window_ref(cam, m2, x)
        ll += np.where(cnt < 0, np.log(1 / 25), np.log(np.maximum(cnt, 1) / 25))
        amb |= a
    return ll, amb


@pytest.mark.parametrize(
    ("case", "resampled", "kernel"),
    [
        ("jumps", True, "general"),
        ("jumps", False, "general"),
        ("jumps", True, "map-set"),
        ("first_frame", True, "general"),
        ("no_candidate", False, "general"),
        ("no_jump", True, "map-set"),
    ],
)
def test_colour_jump_predict_score_matches_numpy(device, rng, case, resampled, kernel):
    rig = make_rig(rng)
    frames = random_frames(rig, rng)
    drig = DeviceRig(rig, device)
    target = TARGETS[0]
    bgr = upload(frames, device)
    mask, integral, window, _ = mask_and_integral(drig, target, bgr, device)
    n, chunk, sigma, sd = 1200, 256, 0.02, 0.03
    parents = rng.uniform([0.0, 0.0, 0.0], [0.8, 0.8, 0.4], (n, 3)).astype(np.float32).astype(np.float64)
    anc = rng.integers(0, n, n)
    logw_prev = rng.normal(-3.0, 2.0, n)
    k = 6
    det_pos = rng.uniform([0.2, 0.2, 0.05], [0.6, 0.6, 0.3], (k, 3)).astype(np.float32).astype(np.float64)
    w = rng.uniform(0.05, 1.0, k)
    det_cum = (np.cumsum(w) / w.sum()).astype(np.float32)
    count = 0 if case == "no_candidate" else 4
    threshold = {"no_jump": float(kproposal.NO_JUMP)}.get(case, NormalDist().inv_cdf(0.3))
    uniform = int(case == "first_frame")
    mix = np.zeros(int(kproposal.MIX_SIZE), np.float32)
    mix[int(kproposal.MIX_THRESHOLD)] = threshold
    jumps = [
        wp.array(det_pos.astype(np.float32), dtype=wp.vec3, device=device),
        wp.array(det_cum, dtype=wp.float32, device=device),
        wp.array([count], dtype=wp.int32, device=device),
        wp.array(mix, dtype=wp.float32, device=device),
        sd,
        wp.array([FRAME if uniform else -1], dtype=wp.int32, device=device),
        wp.vec3(*LO),
        wp.vec3(*HI),
    ]
    if kernel == "map-set":
        k_fn = kproposal.colour_jump_predict_score_map_kernel(len(rig.cameras))
        obs = [drig.cam_set, window, *jumps]
    else:
        k_fn = kproposal.colour_jump_predict_score_kernel
        obs = [drig.cams, target.to_struct(device), bgr, integral, window, int(kscoring.SCORE_INTEGRAL), *jumps]
    x, lw, parts = launch_fused(k_fn, obs, parents, anc, logw_prev, resampled, sigma, n, chunk, device)
    ref_x, jumped, boxed = jump_ref(parents[anc], det_pos, det_cum, count, threshold, uniform, sigma, sd)
    np.testing.assert_allclose(x, ref_x, rtol=0, atol=3e-6)
    if case in ("no_candidate", "no_jump"):
        assert not jumped.any()
        # the paper's walk, draw for draw: the prior kernel on the same state gives the same particles and weights
        prior = kscoring.colour_predict_score_kernel
        pobs = [drig.cams, target.to_struct(device), bgr, integral, window, int(kscoring.SCORE_INTEGRAL)]
        px, plw, _ = launch_fused(prior, pobs, parents, anc, logw_prev, resampled, sigma, n, chunk, device)
        np.testing.assert_allclose(x, px, rtol=0, atol=1e-6 if kernel == "map-set" else 0.0)
        np.testing.assert_allclose(lw, plw, rtol=1e-5 if kernel == "map-set" else 0.0, atol=1e-5)
    else:
        assert 0.2 * n < jumped.sum() < 0.4 * n
        assert len(np.unique(np.argmin(np.linalg.norm(x[jumped, None] - det_pos[None, :count], axis=2), 1))) == count
        assert not uniform or boxed.sum() == n - jumped.sum()
    ll, amb = loglik_ref(rig, drig, mask, x.astype(np.float64))
    assert amb.sum() < 0.02 * n
    ref_lw = np.maximum(ll + (0.0 if resampled else logw_prev), kreduce.LOGW_FLOOR)
    np.testing.assert_allclose(lw[~amb], ref_lw[~amb], rtol=1e-5, atol=1e-5)
    check_partials(parts, lw, x, chunk, rtol=partials_rtol(device) if kernel == "map-set" else 2e-6)


def mode_score_ref(rig, drig, mask, x):
    mk = mask.numpy()
    total = 0.0
    for c, cam in enumerate(rig.cameras):
        m2 = mk[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(cam.height, cam.width).astype(np.int64)
        cnt, _ = window_ref(cam, m2, np.asarray(x, np.float64)[None])
        total += np.log(1 / 5) if cnt[0] < 0 else np.log(max(cnt[0], 1) / 25)
    return total


def test_jump_decision_matches_numpy(device, rng):
    """Several frames through the mode test: the evidence accumulates (CUSUM) over frames, a jump resets it, no
    candidate resets it and never jumps, the first frame after a random initialisation always jumps (when there is
    a candidate), a candidate on the cloud (within near + 2 |spread| of its mean) raises the cloud's score; the
    thresholds and component weights follow."""
    rig = make_rig(rng)
    drig = DeviceRig(rig, device)
    target = TARGETS[0]
    bgr = upload(random_frames(rig, rng), device)
    mask, integral, window, _ = mask_and_integral(drig, target, bgr, device)
    k = 5
    thresholds = (NormalDist().inv_cdf(0.4), float(kproposal.NO_JUMP))
    margin, evidence = 1.0, 1.5
    mix = wp.zeros(int(kproposal.MIX_SIZE), dtype=wp.float32, device=device)
    det_cum = wp.full(k, 7.0, dtype=wp.float32, device=device)
    det_count = wp.full(1, 7, dtype=wp.int32, device=device)
    frame = wp.zeros(1, dtype=wp.int32, device=device)
    cloud = np.array([0.3, 0.35, 0.1])
    est = np.zeros(int(kreduce.EST_SIZE))
    est[kreduce.EST_MEAN : kreduce.EST_MEAN + 3] = cloud
    est[kreduce.EST_MAP : kreduce.EST_MAP + 3] = cloud + 0.02
    l_cloud = max(mode_score_ref(rig, drig, mask, cloud), mode_score_ref(rig, drig, mask, cloud + 0.02))
    s_ref = 0.0
    jumps = []
    # (best candidate's score relative to the cloud, candidates, uniform frame)
    # (and whether candidate 1 lies on the cloud, scoring 4 nats better than its mean and MAP)
    plan = [
        (1.6, 3, False, False),
        (1.8, 3, False, False),
        (0.2, 2, False, False),
        (5.0, 4, False, False),
        (9.0, 0, False, False),
        (0.5, 1, True, False),
        (4.5, 3, False, True),
    ]
    spread = np.array([0.01, 0.02, 0.02])
    est[kreduce.EST_STD : kreduce.EST_STD + 3] = spread
    near = 0.06
    for f, (excess, count, uniform, on_cloud) in enumerate(plan):
        scores = np.full(k, LOG_ZERO, np.float32)
        scores[:count] = np.sort(l_cloud + excess - rng.uniform(0, 3, count))[::-1]
        scores[0] = l_cloud + excess if count else LOG_ZERO
        pos = rng.uniform(-1.0, 1.0, (k, 3)) + np.array([3.0, 0.0, 0.0])  # away from the cloud
        if on_cloud:
            scores[1] = l_cloud + 4.0
            pos[1] = cloud + 0.9 * (near + 2 * np.linalg.norm(spread)) * np.array([0.0, 0.6, 0.8])
        frame.fill_(f)
        wp.launch(
            kproposal.jump_decision_kernel,
            dim=1,
            inputs=[drig.cams, target.to_struct(device), bgr, integral, window, int(kscoring.SCORE_INTEGRAL)]
            + [wp.array(pos.astype(np.float32), dtype=wp.vec3, device=device), wp.array(scores, device=device)]
            + [wp.array(est, dtype=wp.float64, device=device), frame]
            + [wp.array([f if uniform else -1], dtype=wp.int32, device=device), wp.vec2(*thresholds)]
            + [margin, evidence, near],
            outputs=[det_cum, det_count, mix],
            device=device,
        )
        jump = False
        l_mode = max(l_cloud, float(scores[1])) if on_cloud else l_cloud
        if count:
            e = float(scores[0]) - l_mode
            s_ref = max(0.0, s_ref + e - margin)
            if s_ref > evidence:
                jump, s_ref = True, 0.0
        else:
            s_ref = 0.0
        if uniform and count:
            jump, s_ref = True, 0.0
        got = mix.numpy()
        jumps.append(bool(got[kproposal.MIX_JUMP]))
        assert det_count.numpy()[0] == count
        assert bool(got[kproposal.MIX_JUMP]) == jump, f
        assert abs(got[kproposal.MIX_CUSUM] - s_ref) < 1e-4, (f, got, s_ref)
        want_thr = np.float32(thresholds[0] if jump else thresholds[1]) if count else np.float32(kproposal.NO_JUMP)
        assert got[kproposal.MIX_THRESHOLD] == want_thr
        if count:
            assert abs(got[kproposal.MIX_EVIDENCE] - (scores[0] - l_mode)) < 1e-4
            w = np.exp(scores[:count].astype(np.float64) - scores[0])
            np.testing.assert_allclose(det_cum.numpy()[:count], np.cumsum(w) / w.sum(), rtol=1e-5)
    # the plan exercises every branch: evidence 0.6 (no jump), 0.6 + 0.8 = 1.4 (no), 1.4 - 0.8 = 0.6 (no), 0.6 + 4.0
    # (jump), no candidate, the first frame after a random initialisation (jump), 4.5 nats over the mean but 0.5
    # over the candidate on the cloud (no jump)
    assert jumps == [False, False, False, True, False, True, False]


def test_set_anchor_kernel(device):
    est = wp.zeros(int(kreduce.EST_SIZE), dtype=wp.float64, device=device)
    wp.launch(kproposal.set_anchor_kernel, dim=1, inputs=[wp.vec3(0.5, -1.0, 2.0)], outputs=[est], device=device)
    e = est.numpy()
    np.testing.assert_array_equal(e[kreduce.EST_MEAN : kreduce.EST_MEAN + 3], [0.5, -1.0, 2.0])
    np.testing.assert_array_equal(e[kreduce.EST_MAP : kreduce.EST_MAP + 3], [0.5, -1.0, 2.0])
    assert np.count_nonzero(e) == 6
