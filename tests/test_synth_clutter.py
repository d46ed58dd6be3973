"""The s1-clutter scenes (issue 29): look-alike colours, OpenCV FileStorage rig with distortion, JPEG frames, the ball
leaving one camera's view; few frames, CPU only."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from test_synth import hsi_match

from wptrack.cameras.rig import Rig
from wptrack.io.frames import open_frames
from wptrack.synth import clutter as C
from wptrack.synth import get_scene, render_scene
from wptrack.synth.lab import TARGET_HSI
from wptrack.synth.render import hsi


def test_hsi_to_rgb_inverts_the_trackers_hsi():
    rng = np.random.default_rng(0)
    for _ in range(200):
        h, s, i = rng.uniform(0, 360), rng.uniform(0.05, 0.9), rng.uniform(40, 150)
        rgb = C.hsi_to_rgb(h, s, i)
        h2, s2, i2 = hsi(rgb[None])
        assert abs((h2[0] - h + 180) % 360 - 180) < 1e-6 and abs(s2[0] - s) < 1e-9 and abs(i2[0] - i) < 1e-9


def test_lookalike_colours_sit_just_outside_the_target():
    rng = np.random.default_rng(1)
    lo_h, hi_h = TARGET_HSI["hue"]
    lo_s, hi_s = TARGET_HSI["sat"]
    for _ in range(100):
        h, s, _i = hsi(255 * np.array([C.lookalike_albedo("sat_low", rng)]))
        assert lo_h <= h[0] <= hi_h and lo_s - 0.11 < s[0] < lo_s
        h, s, _i = hsi(255 * np.array([C.lookalike_albedo("hue_near", rng)]))
        assert lo_s <= s[0] <= hi_s and not (lo_h <= h[0] <= hi_h)
        assert min(abs(h[0] - lo_h), abs(h[0] - hi_h)) <= 20.0 + 1e-9
    with pytest.raises(ValueError):
        C.lookalike_albedo("other", rng)


def test_layout_is_drawn_from_the_seed():
    a, b, a2 = (get_scene("s1-clutter").build(s) for s in (3, 4, 3))
    assert len(a.rig) == 3 and len(get_scene("s1-clutter-6cam").build(0).rig) == 6
    np.testing.assert_array_equal(a.trajectories(20)[0], a2.trajectories(20)[0])
    assert not np.allclose(a.trajectories(20)[0], b.trajectories(20)[0])
    assert not np.allclose(a.rig.cameras[0].t, b.rig.cameras[0].t)
    for sc in (a, b):
        assert all(np.any(np.abs(c.dist) > 0.01) for c in sc.rig.cameras)  # distortion on every camera


@pytest.mark.parametrize("seed", [0, 7])
def test_the_ball_leaves_the_last_cameras_view(seed):
    sc = get_scene("s1-clutter-4cam").build(seed)
    cam = sc.rig.cameras[-1]
    uv, depth = cam.project(sc.trajectories(31)[0])
    size = np.array([cam.width, cam.height])
    inside = (depth > 0) & np.all((uv >= 0) & (uv < size), axis=1)
    assert inside[0] and (~inside[8:31]).sum() >= 5


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    return render_scene("s1-clutter", tmp_path_factory.mktemp("clutter"), frames=3, seed=2)


def test_rig_file_is_opencv_filestorage_and_frames_are_stored_losslessly(rendered):
    scene = get_scene("s1-clutter").build(2)
    doc = yaml.safe_load(rendered.rig_path.read_text())
    assert [c["opencv"] for c in doc["cameras"]] == ["cam1.yml", "cam2.yml", "cam3.yml"]
    assert (rendered.out_dir / "cam1.yml").read_text().startswith("%YAML")
    rig = Rig.load(rendered.rig_path)
    for c, ref in zip(rig.cameras, scene.rig.cameras, strict=True):
        np.testing.assert_allclose(c.K, ref.K)
        np.testing.assert_allclose(c.dist, ref.dist)
        np.testing.assert_allclose(c.R, ref.R, atol=1e-12)
        np.testing.assert_allclose(c.t, ref.t, atol=1e-12)
    truth = scene.trajectories(3)[0]
    rngs = [np.random.default_rng([2, c]) for c in range(3)]
    for k, frames in enumerate(open_frames(rendered.videos)):
        images, _ = scene.render_frame(k, {0: truth[k]}, rngs)
        for got, want in zip(frames, images, strict=True):
            np.testing.assert_array_equal(got, want)


def test_frames_are_jpeg_compressed_and_full_of_lookalike_pixels():
    scene = get_scene("s1-clutter").build(1)
    raw = C.ClutterScene(C.ClutterConfig(jpeg_quality=0), 1)
    p = scene.trajectories(1)[0][0]
    jpg, _ = scene.render_frame(0, {0: p}, [np.random.default_rng([0, c]) for c in range(3)])
    lossless, _ = raw.render_frame(0, {0: p}, [np.random.default_rng([0, c]) for c in range(3)])
    assert any(np.abs(a.astype(int) - b.astype(int)).mean() > 0.5 for a, b in zip(jpg, lossless, strict=True))
    # target-coloured pixels away from the ball: several times the ball's own in at least one camera
    ratios = []
    for cam, img in zip(scene.rig.cameras, jpg, strict=True):
        mask = hsi_match(img[:, :, ::-1], TARGET_HSI)
        uv, depth = cam.project(p[None])
        yy, xx = np.mgrid[: cam.height, : cam.width]
        r = 1.5 * C.ClutterConfig().ball_radius * cam.fx / depth[0]
        near = (xx - uv[0, 0]) ** 2 + (yy - uv[0, 1]) ** 2 <= r * r
        ratios.append(mask[~near].sum() / max(1, mask[near].sum()))
    assert max(ratios) > 3.0, ratios
