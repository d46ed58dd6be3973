"""The fused S1 predict + score kernels (``scoring.colour_predict_score_kernel``, eqs. 1-7, and
``scoring.gaussian3d_predict_score_kernel``) against NumPy references on every device: the gather and gaussian walk
from a NumPy Philox + Box-Muller, the log-weights from window counts of cv2 projections (eqs. 5-7) or the 3D gaussian,
the accumulation without resampling and the -inf floor, and the per-block partials (max, MAP index, sums of w, w^2,
w x, w x^2 relative to the block maximum) from NumPy. The tests of whole trackers only check convergence."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from kernel_refs import check_partials, normal4_ref
from test_kernels_colour import TARGETS, make_rig, mask_and_integral, random_frames, upload, window_ref

from wptrack.cameras.rig import Camera, Rig
from wptrack.cameras.structs import DeviceRig
from wptrack.kernels.colour import scoring as kscoring
from wptrack.kernels.core import random as krand
from wptrack.kernels.core import reduce as kreduce

BLOCK = 256  # as wptrack.core.filter launches the fused kernels
SEED = (7, 3)
FRAME = 5


def partials_rtol(device) -> float:
    """The scoring module is compiled with fast_math: on CUDA its exp is __expf (a few ulp more per unit of |x|)."""
    return 2e-5 if wp.get_device(device).is_cuda else 2e-6


def launch_fused(kernel, observation, parents, anc, logw_prev, resampled, sigma, n, chunk, device):
    """Launch a fused kernel as ``ParticleFilter._launch_fused`` does; returns (x, logw, (part_max, part_arg, part))."""
    blocks = (n + chunk - 1) // chunk
    x_out = wp.full(n, wp.vec3(7.0, 7.0, 7.0), dtype=wp.vec3, device=device)
    lw_out = wp.full(n, 7.0, dtype=wp.float32, device=device)
    pm = wp.full(blocks, 7.0, dtype=wp.float32, device=device)
    pa = wp.full(blocks, -7, dtype=wp.int32, device=device)
    part = wp.full((blocks, int(kreduce.N_SUMS)), 7.0, dtype=wp.float64, device=device)
    wp.launch_tiled(
        kernel,
        dim=[blocks],
        inputs=[
            *observation,
            wp.array(parents.astype(np.float32), dtype=wp.vec3, device=device),
            wp.array(anc.astype(np.int32), dtype=wp.int32, device=device),
            wp.array(logw_prev.astype(np.float32), dtype=wp.float32, device=device),
            wp.array([int(resampled)], dtype=wp.int32, device=device),
            wp.array([sigma], dtype=wp.float32, device=device),
            wp.vec2ui(*SEED),
            wp.array([FRAME], dtype=wp.int32, device=device),
            n,
            chunk,
        ],
        outputs=[x_out, lw_out, pm, pa, part],
        block_dim=BLOCK,
        device=device,
    )
    return x_out.numpy(), lw_out.numpy(), (pm.numpy(), pa.numpy(), part.numpy())


def particle_state(rng, n: int, lo, hi):
    parents = rng.uniform(lo, hi, (n, 3))
    anc = rng.integers(0, n, n)
    logw_prev = rng.normal(-3.0, 2.0, n)
    logw_prev[::97] = -np.inf  # must come out floored, not -inf, when the weights accumulate
    return parents, anc, logw_prev


@pytest.mark.parametrize("resampled", [True, False], ids=["resampled", "accumulate"])
@pytest.mark.parametrize("mode", ["direct", "integral", "map", "map-set"])
def test_colour_predict_score_matches_numpy(device, rng, mode, resampled):
    rig = make_rig(rng)
    frames = random_frames(rig, rng)
    drig = DeviceRig(rig, device)
    target = TARGETS[0]
    bgr = upload(frames, device)
    mask, integral, window, _ = mask_and_integral(drig, target, bgr, device)
    n, chunk, sigma = 1500, 256, 0.02  # 6 blocks, the last one partial
    parents, anc, logw_prev = particle_state(rng, n, [0.0, 0.0, -0.1], [0.9, 0.9, 0.4])
    kernel = kscoring.colour_predict_score_kernel
    if mode == "map-set":  # the large-N kernel: map scoring, the cameras by value
        kernel, obs = kscoring.colour_predict_score_map_kernel(len(rig.cameras)), [drig.cam_set, window]
        assert drig.cam_set.count == len(rig.cameras)
    else:
        m = {"direct": kscoring.SCORE_DIRECT, "integral": kscoring.SCORE_INTEGRAL, "map": kscoring.SCORE_MAP}[mode]
        obs = [drig.cams, target.to_struct(device), bgr, integral, window, int(m)]
    x, lw, parts = launch_fused(kernel, obs, parents, anc, logw_prev, resampled, sigma, n, chunk, device)
    # eqs. 1-3: the resampled parent plus sigma N(0, I) of the (seed, i, frame, STREAM_MOTION) stream
    z = normal4_ref(SEED, n, FRAME, int(krand.STREAM_MOTION))
    ref_x = parents.astype(np.float32).astype(np.float64)[anc] + sigma * z[:, :3]
    np.testing.assert_allclose(x, ref_x, rtol=0, atol=2e-6)
    # eqs. 5-7 at the kernel's own particles: log(1/25) outside a view, log(max(m, 1)/25) inside
    mk = mask.numpy()
    ll = np.zeros(n)
    amb = np.zeros(n, bool)
    inside = 0
    for c, cam in enumerate(rig.cameras):
        m2 = mk[drig.pixel_offsets[c] : drig.pixel_offsets[c + 1]].reshape(cam.height, cam.width).astype(np.int64)
        counts, a = window_ref(cam, m2, x.astype(np.float64))
        ll += np.where(counts < 0, np.log(1 / 25), np.log(np.maximum(counts, 1) / 25))
        amb |= a
        inside += int((counts > 0).sum())
    assert inside > 200 and amb.sum() < 0.02 * n  # the scene has target pixels under the particles
    ref_lw = ll if resampled else ll + logw_prev
    ref_lw = np.maximum(ref_lw, kreduce.LOGW_FLOOR)  # -inf + ll -> the floor
    np.testing.assert_allclose(lw[~amb], ref_lw[~amb], rtol=1e-5, atol=1e-5)
    if not resampled:
        assert np.all(lw[::97] == np.float32(kreduce.LOGW_FLOOR))
    check_partials(parts, lw, x, chunk, rtol=partials_rtol(device))


def test_colour_predict_score_map_kernel_equals_general(device, rng):
    """The large-N kernel (map scoring, cameras by value) is only a faster form of the general kernel in map mode:
    same particles and log-weights (bit for bit on the CPU) for 1 to 8 cameras (each member of the camera set is
    read)."""
    base = make_rig(rng).cameras
    cams = tuple(
        Camera.look_at(f"c{k}", 48, 40, (0.5 + 0.4 * np.cos(a), 0.45 + 0.4 * np.sin(a), 0.3), (0.45, 0.45, 0.1), 45.0)
        for k, a in enumerate(np.linspace(0.0, 2 * np.pi, 6, endpoint=False))
    )
    n, chunk, sigma = 700, 256, 0.02
    parents, anc, logw_prev = particle_state(rng, n, [0.2, 0.2, -0.1], [0.7, 0.7, 0.3])
    for count in (1, 3, 4, 8):
        rig = Rig((base + cams)[:count])
        drig = DeviceRig(rig, device)
        bgr = upload(random_frames(rig, rng), device)
        _mask, integral, window, _ = mask_and_integral(drig, TARGETS[0], bgr, device)
        general = [drig.cams, TARGETS[0].to_struct(device), bgr, integral, window, int(kscoring.SCORE_MAP)]
        outs = []
        for kernel, obs in (
            (kscoring.colour_predict_score_map_kernel(count), [drig.cam_set, window]),
            (kscoring.colour_predict_score_kernel, general),
        ):
            x, lw, _parts = launch_fused(
                kernel,
                obs,
                parents,
                anc,
                logw_prev,
                True,
                sigma,
                n,
                chunk,
                device,
            )
            outs.append((x, lw))
        assert drig.cam_set.count == count
        if wp.get_device(device).is_cpu:
            np.testing.assert_array_equal(outs[0][0], outs[1][0])
            np.testing.assert_array_equal(outs[0][1], outs[1][1])
        else:  # the compiler may contract the two kernels' arithmetic differently (fast_math): a pixel-boundary case
            np.testing.assert_allclose(outs[0][0], outs[1][0], rtol=0, atol=2e-6)
            assert np.mean(np.abs(outs[0][1] - outs[1][1]) > 1e-5) < 0.01
        assert np.unique(outs[0][1]).size > 20  # the cameras see the blobs: the log-weights vary


def test_camera_set_beyond_eight_cameras_uses_the_array():
    cam = Camera.look_at("a", 32, 24, (1.0, 0.0, 0.5), (0.0, 0.0, 0.0), 30.0)
    rig = Rig(tuple(Camera.look_at(f"c{k}", 32, 24, (1.0, 0.1 * k, 0.5), (0.0, 0.0, 0.0), 30.0) for k in range(9)))
    assert DeviceRig(rig, "cpu").cam_set.count == 0
    assert DeviceRig(Rig((cam,)), "cpu").cam_set.count == 1


@pytest.mark.parametrize("resampled", [True, False], ids=["resampled", "accumulate"])
def test_gaussian3d_predict_score_matches_numpy(device, rng, resampled):
    n, chunk, sigma, sigma_obs = 1000, 300, 0.05, 0.1
    obs_pt = np.array([0.2, -0.1, 0.5])
    parents, anc, logw_prev = particle_state(rng, n, obs_pt - 0.3, obs_pt + 0.3)
    obs = [
        wp.array(obs_pt[None].astype(np.float32), dtype=wp.vec3, device=device),
        wp.array([sigma_obs], dtype=wp.float32, device=device),
    ]
    x, lw, parts = launch_fused(
        kscoring.gaussian3d_predict_score_kernel, obs, parents, anc, logw_prev, resampled, sigma, n, chunk, device
    )
    z = normal4_ref(SEED, n, FRAME, int(krand.STREAM_MOTION))
    ref_x = parents.astype(np.float32).astype(np.float64)[anc] + sigma * z[:, :3]
    np.testing.assert_allclose(x, ref_x, rtol=0, atol=2e-6)
    ll = -np.sum((x.astype(np.float64) - np.float32(obs_pt)) ** 2, axis=1) / (2 * sigma_obs**2)
    ref_lw = np.maximum(ll if resampled else ll + logw_prev, kreduce.LOGW_FLOOR)
    np.testing.assert_allclose(lw, ref_lw, rtol=1e-5, atol=1e-5)
    check_partials(parts, lw, x, chunk, rtol=partials_rtol(device))


@pytest.mark.parametrize("count", [0, 9])
def test_camera_set_kernel_rejects_a_count_it_cannot_hold(count):
    with pytest.raises(ValueError, match="1 to 8 cameras"):
        kscoring.colour_predict_score_map_kernel(count)
