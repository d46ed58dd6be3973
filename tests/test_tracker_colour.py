"""The S1 colour tracker end to end on a small in-memory scene, on every device: convergence, determinism,
identical results of the two scoring modes, graph replay, ESS trigger, and the 3D-observation filter."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import warp as wp

from wptrack.cameras.rig import Camera, Rig
from wptrack.core.errors import ConfigError, FrameError
from wptrack.trackers.colour.gaussian3d import Gaussian3DTracker
from wptrack.trackers.colour.tracker import ColorConfig, ColorTracker, HSITarget

BALL = np.array([0.42, 0.5, 0.06])
TARGET = HSITarget(hue=(300, 340), sat=(0.3, 1.0))


def small_rig() -> Rig:
    c1 = Camera.look_at("cam1", 160, 120, (0.5, 0.0, 0.195), (0.4, 0.45, 0.05), 110.0, dist=[-0.05, 0, 0, 0, 0])
    c2 = Camera.look_at("cam2", 120, 160, (0.07, 0.485, 0.085), (0.45, 0.5, 0.03), 110.0, roll_deg=90)
    return Rig((c1, c2))


def frames_for(rig: Rig, ball: np.ndarray, rng: np.random.Generator) -> list[np.ndarray]:
    out = []
    for cam in rig.cameras:
        img = rng.integers(60, 120, (cam.height, cam.width, 3)).astype(np.uint8)
        uv, depth = cam.project(ball[None])
        r = max(2, int(round(0.033 * cam.fx / depth[0])))
        cv2.circle(img, (int(round(uv[0, 0])), int(round(uv[0, 1]))), r, (180, 60, 230), -1)
        out.append(img)
    return out


def run(device, frames, n=500, **kw):
    tr = ColorTracker(small_rig(), TARGET, particles=n, sigma=0.02, init=(0.45, 0.45, 0.1), device=device, **kw)
    return tr, [tr.step(f) for f in frames]


@pytest.fixture(scope="module")
def frames():
    rng = np.random.default_rng(3)
    rig = small_rig()
    return [frames_for(rig, BALL, rng) for _ in range(25)]


def test_converges_and_is_deterministic(device, frames):
    _, a = run(device, frames)
    _, b = run(device, frames)
    assert np.linalg.norm(a[-1].mean - BALL) < 0.02
    assert np.all(a[-1].std < 0.05)
    for ea, eb in zip(a, b, strict=True):
        np.testing.assert_array_equal(ea.mean, eb.mean)
        np.testing.assert_array_equal(ea.map, eb.map)
    _, c = run(device, frames, seed=1)
    assert not np.array_equal(a[-1].mean, c[-1].mean)


@pytest.mark.parametrize("mode", ["integral", "map"])
def test_scoring_modes_identical(device, frames, mode):
    td, d = run(device, frames[:8], score_mode="direct")
    ti, i = run(device, frames[:8], score_mode=mode)
    assert (td.score_mode, ti.score_mode) == ("direct", mode)
    for ed, ei in zip(d, i, strict=True):
        np.testing.assert_array_equal(ed.mean, ei.mean)
        assert ed.ess == ei.ess
    np.testing.assert_array_equal(td.particles.numpy(), ti.particles.numpy())


def test_auto_mode_follows_the_crossover(device):
    rig = small_rig()  # 2 * 160 * 120 = 38400 pixels: crossover at N = 1536
    assert ColorTracker(rig, TARGET, particles=1000, init=(0, 0, 0), device=device).score_mode == "direct"
    assert ColorTracker(rig, TARGET, particles=2000, init=(0, 0, 0), device=device).score_mode == "map"


def test_graph_replay_matches_plain_launches(device, frames):
    if not wp.get_device(device).is_cuda:
        pytest.skip("CUDA graphs need a CUDA device")
    _, g = run(device, frames[:10], use_graph=True)
    _, p = run(device, frames[:10], use_graph=False)
    for eg, ep in zip(g, p, strict=True):
        np.testing.assert_array_equal(eg.mean, ep.mean)


def test_ess_trigger_skips_resampling(device, frames):
    _, est = run(device, frames[:15], ess_threshold=0.3)
    flags = [e.resampled for e in est]
    assert any(flags) and not all(flags)
    for e in est:
        assert e.resampled == (e.ess <= 0.3 * 500 + 1e-9)


@pytest.mark.parametrize("scheme", ["multinomial", "stratified", "systematic", "residual"])
def test_every_scheme_tracks(device, frames, scheme):
    _, est = run(device, frames, resampling=scheme)
    assert np.linalg.norm(est[-1].mean - BALL) < 0.03


def test_keep_particles_and_weights(device, frames):
    tr, est = run(device, frames[:3], keep_particles=100)
    assert est[-1].particles.shape == (100, 3) and est[-1].weights.shape == (100,)
    assert est[-1].weights.max() <= 1.0 + 1e-6


def test_frame_errors(device, frames):
    tr = ColorTracker(small_rig(), TARGET, particles=10, init=(0, 0, 0), device=device)
    with pytest.raises(FrameError, match="frame size 10x10 differs from camera 'cam1' calibration"):
        tr.step([np.zeros((10, 10, 3), np.uint8), frames[0][1]])
    with pytest.raises(FrameError, match="2 cameras"):
        tr.step(frames[0][:1])


def test_config_validation():
    for bad in (
        {"particles": 0},
        {"particles": -3},
        {"sigma": 0.0},
        {"sigma": float("nan")},
        {"resampling": "nope"},
        {"score_mode": "fast"},
        {"ess_threshold": 0.0},
    ):
        with pytest.raises(ConfigError):
            ColorConfig(**bad)
    with pytest.raises(ConfigError, match="hue"):
        HSITarget(hue=(10, 400))
    with pytest.raises(ConfigError, match="sat"):
        HSITarget(hue=(10, 20), sat=(0.8, 0.2))


def test_gaussian3d_filter_converges_after_a_jump(device):
    pf = Gaussian3DTracker(particles=400, sigma=0.1, sigma_obs=0.05, init=(0.0, 0.0, 0.0), device=device, seed=2)
    target = np.array([0.3, -0.2, 0.1])
    for _ in range(15):
        est = pf.step(target)
    assert np.linalg.norm(est.mean - target) < 0.05
    jumped = target + np.array([2.0, 0.0, 0.0])
    errs = [np.linalg.norm(pf.step(jumped).mean - jumped) for _ in range(40)]
    assert errs[0] > 1.0 and errs[-1] < 0.05


def test_too_many_particles_is_a_clear_error_before_allocation(device, monkeypatch):
    import wptrack.core.memory as pf

    monkeypatch.setattr(pf, "available_bytes", lambda dev: 64 * 2**20)  # pretend 64 MiB are free
    before = wp.get_mempool_used_mem_current(device) if wp.get_device(device).is_cuda else None
    with pytest.raises(ConfigError, match=r"particles: 2000000 particles need .* GiB .* free; the limit here is about"):
        ColorTracker(small_rig(), TARGET, particles=2_000_000, init=(0, 0, 0), device=device)
    if before is not None:
        assert wp.get_mempool_used_mem_current(device) == before  # nothing was allocated
    # the limit it names fits
    limit = int(0.9 * 64 * 2**20) // (pf.POINT_STATE_BYTES + pf.resampler_bytes("systematic"))
    ColorTracker(small_rig(), TARGET, particles=limit, init=(0, 0, 0), device=device)
