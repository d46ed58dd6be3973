"""The S2 office scenes: rig, ground truth against the perfect masks, occlusion by furniture, two-colour clothes,
seeds (small images, few frames)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from wptrack.core.errors import ConfigError
from wptrack.synth import SCENES, render_scene, scene_names
from wptrack.synth.office import ROOM, OfficeConfig, OfficeScene

W, H = 160, 120


def _scene(**kw) -> OfficeScene:
    return OfficeScene(OfficeConfig(width=W, height=H, **kw))


@pytest.fixture(scope="module")
def scene() -> OfficeScene:
    return _scene()


@pytest.fixture(scope="module")
def twocolour() -> OfficeScene:
    return _scene(two_colour=True)


def _meeting_frame(sc: OfficeScene) -> int:
    t0, t1 = sc.walkers[0].shake
    return int(round(0.5 * (t0 + t1) * sc.fps))


def test_registered_and_seeded():
    assert {"s2-office", "s2-office-twocolour"} <= set(scene_names())
    assert SCENES["s2-office"].seeded and SCENES["s2-office-twocolour"].seeded
    assert not SCENES["s1-lab"].seeded


def test_config_validation():
    with pytest.raises(ConfigError, match="width"):
        OfficeConfig(width=8)
    with pytest.raises(ConfigError, match="light_ramp"):
        OfficeConfig(light_ramp=(30, 10))
    with pytest.raises(ConfigError, match="seed"):
        OfficeConfig(seed=-1)


def test_rig_three_overlapping_cameras(scene):
    rig = scene.rig
    assert len(rig) == 3
    lo, hi = rig.volume
    np.testing.assert_allclose(lo, [0, 0, 0])
    np.testing.assert_allclose(hi[:2], ROOM[:2])
    for cam in rig:
        assert cam.center[2] > 2.5  # top corners
        uv, depth = cam.project(np.array([[3.0, 2.5, 1.0], [3.0, 2.5, 0.0]]))
        assert np.all(depth > 0)
        assert np.all((uv[:, 0] > 0) & (uv[:, 0] < cam.width - 1) & (uv[:, 1] > 0) & (uv[:, 1] < cam.height - 1))


def test_timeline_people_enter_meet_and_leave(scene):
    n = scene.default_frames
    inside = scene.inside(n)
    for a in range(2):
        frames = np.flatnonzero(inside[a])
        assert frames.min() > 10 and frames.max() < n - 5  # empty room at both ends
    st = scene.states(n)
    f = _meeting_frame(scene)
    gap = np.linalg.norm(st.pos[0, f] - st.pos[1, f])
    assert 0.6 < gap < 0.85
    assert np.all(st.arm[:, f] == 1.0) and np.all(st.speed[:, f] < 0.05)
    # they come from opposite doors and leave through the opposite ones
    first = [np.flatnonzero(inside[a])[0] for a in range(2)]
    last = [np.flatnonzero(inside[a])[-1] for a in range(2)]
    assert st.pos[0, first[0], 0] < 0.5 < ROOM[0] - 0.5 < st.pos[1, first[1], 0]
    assert st.pos[0, last[0], 0] > ROOM[0] - 0.5 and st.pos[1, last[1], 0] < 0.5
    traj = scene.trajectories(n)
    assert np.all(np.isnan(traj[0][~inside[0]])) and np.all(np.isfinite(traj[0][inside[0]]))
    z = traj[0][inside[0], 2]
    assert np.all((z > 0.35 * scene.walkers[0].person.height) & (z < 0.65 * scene.walkers[0].person.height))


def test_groundtruth_matches_perfect_masks(scene):
    n = scene.default_frames
    traj = scene.trajectories(n)
    cols = scene.groundtruth_columns(n)
    rngs = [np.random.default_rng([0, k]) for k in range(3)]
    checked = 0
    _, _, masks = scene.render_frame_masks(60, {}, rngs)
    for k in range(3):
        assert np.array_equal(masks[k] > 0, scene.render_camera(k, 60, rngs[k])[1] > 0)
    for f in (60, _meeting_frame(scene), 200):
        for k, cam in enumerate(scene.rig):
            _, labels, _, _ = scene.render_camera(k, f, rngs[k])
            for oid, t in traj.items():
                if not np.all(np.isfinite(t[f])):
                    continue
                mine = labels == oid + 1
                if mine.sum() < 5:
                    continue
                gx, gy, height = cols["gx"][oid][f], cols["gy"][oid][f], cols["height"][oid][f]
                # every mask pixel lies inside the image of a 0.7 m cylinder around the person's ground position
                ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
                ring = np.stack([gx + 0.7 * np.cos(ang), gy + 0.7 * np.sin(ang)], axis=1)
                pts = np.vstack([np.c_[ring, np.zeros(16)], np.c_[ring, np.full(16, height + 0.1)]])
                uv, _ = cam.project(pts)
                vs, us = np.nonzero(mine)
                assert us.min() >= uv[:, 0].min() - 1 and us.max() <= uv[:, 0].max() + 1
                assert vs.min() >= uv[:, 1].min() - 1 and vs.max() <= uv[:, 1].max() + 1
                # the ground-truth centroid projects inside the mask's bounding box (widened by 3 px)
                c, _ = cam.project(t[f][None, :])
                assert us.min() - 3 <= c[0, 0] <= us.max() + 3
                assert abs(c[0, 0] - np.median(us)) < 0.5 * (us.max() - us.min()) + 3
                checked += 1
    assert checked >= 10


def test_furniture_hides_lower_body_somewhere(scene):
    rng = np.random.default_rng(0)
    n = scene.default_frames
    inside = scene.inside(n)
    found = []
    for f in range(130, 250, 15):
        for k in range(3):
            _, labels, lower, _ = scene.render_camera(k, f, rng)
            for a in range(2):
                mine = labels == a + 1
                upper = np.count_nonzero(mine & ~lower)
                if inside[a, f] and upper > 30 and not np.any(mine & lower):
                    found.append((f, k, a))
    assert found, "no frame where furniture hides a person's legs and pelvis while the upper body is visible"
    # and not everywhere: the legs are visible in some camera at those frames
    f, k, a = found[0]
    seen = [np.any((scene.render_camera(j, f, rng)[1] == a + 1) & scene.render_camera(j, f, rng)[2]) for j in range(3)]
    assert any(seen)


def _red_blue(sc: OfficeScene, cam: int, f: int, oid: int) -> tuple[int, int]:
    bgr, labels, lower, _ = sc.render_camera(cam, f, np.random.default_rng(1))
    px = bgr[(labels == oid + 1) & ~lower].astype(int)
    b, r = px[:, 0], px[:, 2]
    return int(np.count_nonzero(r > b + 40)), int(np.count_nonzero(b > r + 40))


def test_two_colour_person_looks_different_per_camera(scene, twocolour):
    f = _meeting_frame(twocolour)
    red1, blue1 = _red_blue(twocolour, 0, f, 0)  # cam1, west: sees the back
    red2, blue2 = _red_blue(twocolour, 1, f, 0)  # cam2, east: sees the front
    assert blue1 > 2 * red1 and red2 > 2 * blue2
    # the one-colour person is red in both
    for cam in (0, 1):
        red, blue = _red_blue(scene, cam, _meeting_frame(scene), 0)
        assert red > 4 * max(blue, 1)


def test_deterministic_and_seeded(scene):
    f = 150
    again = _scene()
    a = scene.render_frame_masks(f, {}, [np.random.default_rng([3, k]) for k in range(3)])
    b = again.render_frame_masks(f, {}, [np.random.default_rng([3, k]) for k in range(3)])
    for x, y in zip(a[0] + a[2], b[0] + b[2], strict=True):
        assert np.array_equal(x, y)
    other = _scene(seed=1)
    n = scene.default_frames
    t0, t1 = scene.trajectories(n), other.trajectories(n)
    both = np.isfinite(t0[0][:, 0]) & np.isfinite(t1[0][:, 0])
    assert both.sum() > 100
    assert np.max(np.linalg.norm(t0[0][both] - t1[0][both], axis=1)) > 0.05
    assert scene.walkers[0].person != other.walkers[0].person
    assert scene.hints()["held_out"] is False and other.hints()["held_out"] is True
    assert _scene(two_colour=True).hints()["held_out"] is True


def test_illumination_change(scene):
    a, b = scene.config.light_ramp
    assert scene.gain(a) == 1.0 and scene.gain(0) == 1.0
    assert scene.gain(b) == pytest.approx(0.82) and scene.gain(scene.default_frames - 1) == pytest.approx(0.82)
    g = [scene.gain(i) for i in range(a, b + 1)]
    assert np.all(np.diff(g) <= 0)


def test_render_scene_passes_the_seed(tmp_path, monkeypatch):
    spec = SCENES["s2-office-twocolour"]
    small = dataclasses.replace(spec, build=lambda seed: OfficeScene(OfficeConfig(seed=seed, width=W, height=H)))
    monkeypatch.setitem(SCENES, "s2-office-twocolour", small)
    res = render_scene("s2-office-twocolour", tmp_path, frames=2, seed=4)
    meta = json.loads(res.scene_json.read_text())
    assert meta["seed"] == 4 and meta["held_out"] is True and meta["masks"] == "motion"
    assert meta["cameras"] == ["cam1", "cam2", "cam3"] and len(res.mask_videos) == 3
    header = res.groundtruth_path.read_text().splitlines()[0]
    assert header == "frame,id,x,y,z,gx,gy,height,heading,handshake"
    assert OfficeScene(OfficeConfig(seed=4)).walkers[0].meet == small.build(4).walkers[0].meet


def test_low_frame_rate_variant_is_the_same_scene_every_8th_frame():
    """``s2-office-lowfps``: at 3.125 frames/s the people are where the 25 frames/s scene has them 8 frames later
    each (times in seconds), the 12 s fit 38 frames, the light dims at the same time."""
    assert "s2-office-lowfps" in scene_names() and SCENES["s2-office-lowfps"].seeded
    low = SCENES["s2-office-lowfps"].build(1)
    assert low.fps == pytest.approx(3.125) and low.default_frames == 38
    full = OfficeScene(OfficeConfig(seed=1))
    a, b = low.states(38), full.states(300)
    np.testing.assert_allclose(a.pos[:, :37], b.pos[:, ::8][:, :37], atol=1e-9)
    assert np.any(low.inside(38)) and low.hints()["held_out"]
    assert low.gain(15) == pytest.approx(full.gain(120)) and low.gain(19) == pytest.approx(full.gain(152), abs=1e-3)


def test_meeting_variant_four_cameras_people_stand_and_talk():
    """``s2-office-meeting``: a fourth camera in the north-west corner sees the room centre; the two people stand
    still at the meeting point for the 8 s of talk before the handshake, then leave."""
    sc = SCENES["s2-office-meeting"].build(0)
    assert len(sc.rig) == 4 and sc.rig.names[-1] == "cam4" and sc.hints()["held_out"]
    cam4 = sc.rig["cam4"]
    assert cam4.center[0] < 0.5 and cam4.center[1] > 4.5
    uv, depth = cam4.project(np.array([[3.0, 2.5, 1.0]]))
    assert depth[0] > 0 and 0 < uv[0, 0] < cam4.width and 0 < uv[0, 1] < cam4.height
    n = sc.default_frames
    st = sc.states(n)
    still = np.all(st.speed < 0.05, axis=0)  # both standing
    longest, run = 0, 0
    for s in still:
        run = run + 1 if s else 0
        longest = max(longest, run)
    assert longest >= 8.0 * sc.fps  # at least the 8 s of talk
    base = OfficeScene(OfficeConfig(seed=0))
    assert sc.walkers[0].shake[0] == pytest.approx(base.walkers[0].shake[0] + 8.0)
    inside = sc.inside(n)
    assert inside.any(axis=0)[n // 2] and not inside[:, -1].any()  # both have left by the end
    with pytest.raises(ConfigError, match="cameras"):
        OfficeConfig(cameras=5)
    with pytest.raises(ConfigError, match="talk"):
        OfficeConfig(talk=-1.0)


def test_light_conditions_change_the_light_only(scene):
    """``clouds`` and ``exposure`` (issue 26's light conditions indoors): the people, their perfect masks and the
    ground truth stay; the images change as specified. ``clouds``: the daylight by the south windows fades as a cloud
    passes (the floor by the windows darkens more than the floor far from them, never brightens); ``exposure``: each
    camera's auto-exposure jumps at its own time, and the light over the aisle brightens the floor under it."""
    from wptrack.synth import conditions as C
    from wptrack.synth.office import DAYLIGHT_REACH, EXPOSURE_CAMERA_DELAY_S, OFFICE_LIGHT_POOLS

    rngs = lambda: [np.random.default_rng([5, k]) for k in range(3)]  # noqa: E731
    clouds = scene.with_conditions(C.parse_conditions("clouds"))
    exposure = scene.with_conditions(C.parse_conditions("exposure"))
    assert clouds.config.clouds and not clouds.config.exposure and exposure.config.exposure
    n = scene.default_frames
    for lit in (clouds, exposure):
        t0, t1 = scene.trajectories(n), lit.trajectories(n)
        assert all(np.array_equal(t0[k], t1[k], equal_nan=True) for k in t0)
        assert lit.hints()["held_out"]
    f = _meeting_frame(scene)
    base_img, _, base_masks = scene.render_frame_masks(f, {}, rngs())
    for lit in (clouds, exposure):
        img, _, masks = lit.render_frame_masks(f, {}, rngs())
        assert all(np.array_equal(a, b) for a, b in zip(masks, base_masks, strict=True))  # same people, same pixels
        assert any(not np.array_equal(a, b) for a, b in zip(img, base_img, strict=True))
    assert set(clouds.hints()["conditions"]) == {"clouds"} and set(exposure.hints()["conditions"]) == {"exposure"}
    assert "conditions" not in scene.hints()

    # clouds: the static floor's factor, by distance from the window wall, over the whole clip
    pts, share = clouds._static_daylight(0)
    labels = np.zeros((H, W), dtype=np.int32)
    near = np.isfinite(pts[:, 1]) & (pts[:, 1] < 1.0) & (share > 0.3)
    far = np.isfinite(pts[:, 1]) & (pts[:, 1] > 4.0)
    assert near.sum() > 50 and far.sum() > 50
    darkest_near = darkest_far = 1.0
    for i in range(0, n, 10):
        fac = clouds.light_factors(0, i, labels).reshape(-1, 3)
        assert np.all(fac <= 1.0 + 1e-12)  # a cloud only takes daylight away
        darkest_near = min(darkest_near, float(fac[near, 1].min()))
        darkest_far = min(darkest_far, float(fac[far, 1].min()))
    assert darkest_near < 0.9  # a passing cloud takes a tenth or more of the light by the windows
    assert 1.0 - darkest_far < 0.5 * (1.0 - darkest_near)  # ... and much less deep in the room
    assert np.median(share[near]) > np.exp(3.0 / DAYLIGHT_REACH) * np.median(share[far]) * 0.9  # falls with y

    # exposure: camera 1's first auto-exposure jump comes EXPOSURE_CAMERA_DELAY_S after camera 0's
    step_t = C.EXPOSURE_STEPS[0][0] + C.EXPOSURE_RAMP_S
    i0 = int(np.ceil(step_t * scene.fps)) + 1
    g0 = exposure.light_factors(0, i0, labels).reshape(-1, 3)
    g1 = exposure.light_factors(1, i0, labels).reshape(-1, 3)
    gain0 = C.exposure_gain(i0 / scene.fps)
    gain1 = C.exposure_gain(i0 / scene.fps - EXPOSURE_CAMERA_DELAY_S)
    assert gain0[1] > gain1[1] * 1.2  # camera 0 has jumped, camera 1 not yet
    far_from_pools = np.isfinite(pts[:, 0]) & np.all(
        [np.hypot(pts[:, 0] - c[0], pts[:, 1] - c[1]) > 4 * r for _, c, r, _ in OFFICE_LIGHT_POOLS], axis=0
    )
    np.testing.assert_allclose(g0[far_from_pools & np.isfinite(pts[:, 0])][:, 1], gain0[1], rtol=1e-6)
    assert np.median(g1[far_from_pools][:, 1]) == pytest.approx(gain1[1], rel=1e-6)
    on, (cx, cy), radius, _ = OFFICE_LIGHT_POOLS[1]
    after = exposure.light_factors(0, int((on + 1.0) * scene.fps), labels).reshape(-1, 3)
    before = exposure.light_factors(0, int((on - 1.0) * scene.fps), labels).reshape(-1, 3)
    under = np.isfinite(pts[:, 0]) & (np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) < radius)
    assert under.sum() > 10
    ratio_under = after[under, 0] / before[under, 0]
    ratio_far = after[far_from_pools, 0] / before[far_from_pools, 0]
    assert np.median(ratio_under) > 1.15 * np.median(ratio_far)  # the light over the aisle came on
    ceiling = np.isfinite(pts[:, 0]) & (pts[:, 2] > 2.7) & (np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) < radius)
    assert ceiling.sum() > 10  # the ceiling above it is not lit by it (a pool on what stands below POOL_TOP)
    np.testing.assert_allclose(after[ceiling, 0] / before[ceiling, 0], np.median(ratio_far), rtol=0.02)


def test_office_takes_only_the_light_conditions(tmp_path):
    from wptrack.synth import conditions as C

    with pytest.raises(ConfigError, match="only the conditions clouds, exposure, got sun"):
        _scene().with_conditions(C.parse_conditions("clouds,sun"))
    with pytest.raises(ConfigError, match="office scene: clouds"):
        OfficeConfig(clouds="yes")
    with pytest.raises(ConfigError, match="only the conditions"):
        render_scene("s2-office", tmp_path, frames=1, conditions="crowd")
