"""Hard conditions of the s3 plaza scenes (issue 10): each switch changes what it should and nothing else; the
default scenes are unchanged byte for byte (hashes taken before the conditions existed)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from wptrack.cli import main
from wptrack.core.errors import ConfigError
from wptrack.synth import SCENES, plaza_cast, render_scene
from wptrack.synth import conditions as C
from wptrack.synth import plaza as P
from wptrack.synth import plaza_background as PB
from wptrack.synth.base import _groundtruth_csv
from wptrack.synth.plaza_background import LABEL_BUSH, plaza_background

S3 = ("s3-people", "s3-cars", "s3-groups", "s3-mixed")

# sha256[:20] of frames 0 and 60 (image, perfect mask), rendered with default_rng([7, frame]), and of the ground-truth
# CSV of the first 90 frames, computed on the scenes before the conditions were added
FRAME_HASHES = {
    ("s3-cars", 0): ("24373ac800bdf67f5ae7", "29caf598e5a41a985d89"),
    ("s3-mixed", 60): ("b01f12d7297a47a3de66", "39de40c58cc9022e51a7"),
}
# the ground truth labels objects nearly whole in view since 2026-11-27 (plaza_background.MIN_IN_IMAGE 0.9)
GT_HASHES = {
    "s3-people": "739963a2c2beb46cd4bd",
    "s3-cars": "8f6ee442e8ed6bf8e3c7",
    "s3-groups": "4b5bad5dba80c12d2414",
    "s3-mixed": "846b2322e9dc07247036",
}


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:20]


def _scene(name: str, **on: bool) -> P.PlazaScene:
    scene = SCENES[name].build()
    return scene.with_conditions(C.PlazaConditions(**on)) if on else scene


def _render(scene: P.PlazaScene, f: int, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    images, _, masks = scene.render_frame_masks(f, {}, [np.random.default_rng([seed, f])])
    return images[0], masks[0]


# ----------------------------------------------------------------------------------------------------- switches


def test_parse_names_all_none_and_errors() -> None:
    assert C.parse_conditions(None) == C.PlazaConditions() == C.parse_conditions("none") == C.parse_conditions("")
    c = C.parse_conditions("sun, dark-car")
    assert c.sun_shadows and c.dark_car and c.names == ["sun", "dark-car"] and c.any
    every = C.parse_conditions("all")
    assert every.names == list(C.CONDITION_NAMES) and set(every.describe()) == set(C.CONDITION_NAMES)
    assert not C.PlazaConditions().any and C.PlazaConditions().describe() == {}
    with pytest.raises(ConfigError, match="'fog'.*static-start"):
        C.parse_conditions("sun,fog")
    with pytest.raises(ConfigError, match="PlazaConditions.sun_shadows"):
        C.PlazaConditions(sun_shadows="yes")  # type: ignore[arg-type]


def test_default_scenes_unchanged() -> None:
    for name in S3:
        for scene in (_scene(name), SCENES[name].build().with_conditions(C.PlazaConditions())):
            csv = _groundtruth_csv(scene.trajectories(90), scene.groundtruth_columns(90))
            assert _sha(csv.encode()) == GT_HASHES[name], name
            assert "conditions" not in scene.hints()
    for (name, f), (h_img, h_mask) in FRAME_HASHES.items():
        img, mask = _render(_scene(name), f)
        assert (_sha(img.tobytes()), _sha(mask.tobytes())) == (h_img, h_mask), (name, f)


def test_scene_json_and_cli(tmp_path, capsys) -> None:
    res = render_scene("s3-cars", tmp_path / "a", frames=2, conditions="compression,noise")
    meta = json.loads(res.scene_json.read_text())
    assert set(meta["conditions"]) == {"noise", "compression"} and meta["conditions"]["compression"]["quality"] == 70
    res = render_scene("s3-cars", tmp_path / "b", frames=1)
    assert "conditions" not in json.loads(res.scene_json.read_text())
    for args, needle in (
        (["s3-cars", "--conditions", "sun,fog"], "unknown 'fog'"),
        (["s1-lab", "--conditions", "sun"], "scene 's1-lab': this scene takes no conditions"),
    ):
        out = tmp_path / "bad"
        code = main(["synth", *args, "--out", str(out), "--frames", "1", "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and err.startswith("wptrack: error:") and needle in err and "Traceback" not in err, err
        assert not out.exists()


# ----------------------------------------------------------------------------------------------------- motion


def test_static_start_objects_in_view_and_still() -> None:
    hold = int(C.HOLD_S * P.FPS)
    for name in S3:
        scene = _scene(name, static_start=True)
        n = scene.default_frames
        st = scene.states(n)  # in view (P.IN_VIEW): the frozen moment's rule; the labels are stricter
        still = [a for a in range(len(scene.actors)) if np.all(st.present[a, :hold])]
        assert len(still) >= 2, name
        for a in still:
            assert np.ptp(st.pos[a, :hold], axis=0).max() < 1e-9, (name, a)
            ok = st.present[a, :n]
            assert np.ptp(st.pos[a, :n][ok], axis=0).max() > 1.0, (name, a)  # and then it moves
        traj = scene.trajectories(n)  # the labelled ones among them are still too
        for oid, p in traj.items():
            if np.all(np.isfinite(p[:hold])):
                assert np.ptp(p[:hold], axis=0).max() < 1e-9, (name, oid)
        # the frozen moment is the default scene's busiest frame
        default = _scene(name)
        assert len(still) == default.max_objects(n)


def test_stop_and_go_people_stop_and_walk_on_cars_unchanged() -> None:
    for name in S3:
        scene, default = _scene(name, stop_and_go=True), _scene(name)
        n = scene.default_frames
        traj, ref = scene.trajectories(n), default.trajectories(n)
        cols = scene.groundtruth_columns(n)
        stopped = 0
        for oid, p in traj.items():
            if cols["class"][oid][0] == P.VEHICLE:
                np.testing.assert_array_equal(p, ref[oid])
                continue
            ok = np.all(np.isfinite(p), axis=1)
            if not ok.any():
                continue
            speed = np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1) * scene.fps
            standing = np.concatenate([[False], (speed < 1e-6) & ok[1:] & ok[:-1], [False]])
            edges = np.flatnonzero(np.diff(standing.astype(int)))
            runs = edges[1::2] - edges[::2]
            if len(runs) and runs.max() >= int(C.STOP_S * scene.fps) - 1:
                stopped += 1
                after = np.flatnonzero(standing)[-1]
                assert np.nanmax(speed[after:]) > 0.7, (name, oid)  # walks on
        humans = [oid for oid in traj if cols["class"][oid][0] == P.HUMAN and np.isfinite(traj[oid]).any()]
        assert stopped >= min(len(humans), 2), name


def _circles(actor: P.PlazaActor, xy: np.ndarray, heading: np.ndarray) -> list[tuple[np.ndarray, float]]:
    if isinstance(actor.shape, P.Person):
        return [(xy, 0.25)]
    car = actor.shape
    d = np.stack([np.cos(heading), np.sin(heading)], axis=1)
    offsets = np.linspace(-0.5 * car.length + 0.5 * car.width, 0.5 * car.length - 0.5 * car.width, 3)
    return [(xy + off * d, 0.5 * car.width) for off in offsets]


@pytest.mark.parametrize(
    "on", [{"static_start": True}, {"stop_and_go": True}, {"static_start": True, "stop_and_go": True}]
)
def test_retimed_objects_never_overlap(on: dict[str, bool]) -> None:
    for name in S3:
        scene = _scene(name, **on)
        st = scene.states(scene.default_frames)
        circles = [_circles(actor, st.pos[a], st.heading[a]) for a, actor in enumerate(scene.actors)]
        for a in range(len(scene.actors)):
            for b in range(a + 1, len(scene.actors)):
                both = st.active[a] & st.active[b]
                for ca, ra in circles[a]:
                    for cb, rb in circles[b]:
                        gap = np.linalg.norm(ca[both] - cb[both], axis=1) - ra - rb
                        assert gap.size == 0 or gap.min() > 0.0, (name, on, a, b)


# ----------------------------------------------------------------------------------------------------- pixels


def test_sun_shadows_hard_neutral_and_masks_unchanged() -> None:
    scene, default = _scene("s3-mixed", sun_shadows=True), _scene("s3-mixed")
    scene.noise_sigma = 0.0
    f = 60
    img, mask = _render(scene, f)
    _, mask_default = _render(default, f)
    np.testing.assert_array_equal(mask, mask_default)  # shadows are not objects
    bg = plaza_background(sun=True)
    static = bg.view.radiance * (255.0 * bg.light.exposure * scene.gain(f)).astype(np.float32)[None, None, :]
    static = np.clip(np.rint(static[:, :, ::-1]), 0, 255)
    keep = (mask == 0) & (bg.view.label != LABEL_BUSH) & (static.min(axis=2) >= 40)
    ratio = img.astype(np.float64) / np.maximum(static, 1.0)
    changed = keep & (np.abs(ratio - 1.0).max(axis=2) > 0.03)
    r = ratio[changed]
    assert changed.sum() > 1500  # long cast shadows next to the objects
    expected = C.sun_shadow_ratio()
    in_shadow = np.all(np.abs(r - expected) < 0.04, axis=1)
    assert in_shadow.mean() > 0.97  # hard: almost no penumbra
    assert np.abs(r[in_shadow] - r[in_shadow].mean(axis=1, keepdims=True)).max() < 0.03  # same ratio in B, G, R
    # nearly all shadow pixels lie next to the objects' pixels (the others: objects leaving the image)
    import cv2

    near = cv2.dilate(mask, np.ones((161, 161), np.uint8)) > 0
    assert near[changed].mean() > 0.9
    # the default shadows: soft (a penumbra) and bluish (red falls most)
    default.noise_sigma = 0.0
    img0, _ = _render(default, f)
    bg0 = plaza_background()
    static0 = bg0.view.radiance * (255.0 * bg0.light.exposure * default.gain(f)).astype(np.float32)[None, None, :]
    static0 = np.clip(np.rint(static0[:, :, ::-1]), 0, 255)
    ratio0 = img0.astype(np.float64) / np.maximum(static0, 1.0)
    r0 = ratio0[keep & (np.abs(ratio0 - 1.0).max(axis=2) > 0.03)]
    assert np.median(r0[:, 0] - r0[:, 2]) > 0.05  # B / B_bg above R / R_bg
    assert np.mean(np.abs(r0[:, 1] - np.median(r0[:, 1])) < 0.04) < 0.8  # a spread of ratios: penumbrae


def test_light_change_is_global_and_comes_back() -> None:
    scene, default = _scene("s3-people", light_change=True), _scene("s3-people")
    fps = scene.fps
    for t, factor in ((0.0, 1.0), (5.0, 1.0 - np.array(C.LIGHT_DROP)), (10.0, 1.0)):
        f = int(t * fps)
        np.testing.assert_allclose(scene.gain(f) / default.gain(f), factor, atol=1e-12)
    img0, _ = _render(default, 75)
    img1, m1 = _render(scene, 75)
    rgb = img1.reshape(-1, 3).mean(axis=0) / img0.reshape(-1, 3).mean(axis=0)
    np.testing.assert_allclose(rgb[::-1], 1.0 - np.array(C.LIGHT_DROP), atol=0.02)


def test_sensor_noise_stronger_and_signal_dependent() -> None:
    scene, default = _scene("s3-cars", sensor_noise=True), _scene("s3-cars")
    f = 3
    a, _ = _render(scene, f, seed=1)
    b, _ = _render(scene, f, seed=2)
    a0, _ = _render(default, f, seed=1)
    b0, _ = _render(default, f, seed=2)
    diff = (a.astype(np.float64) - b) / np.sqrt(2.0)
    diff0 = (a0.astype(np.float64) - b0) / np.sqrt(2.0)
    level = 0.5 * (a.astype(np.float64) + b)
    dark, bright = (level > 20) & (level < 60), (level > 150) & (level < 230)
    assert diff0[(level > 20) & (level < 230)].std() == pytest.approx(P.NOISE_SIGMA, rel=0.1)
    for sel in (dark, bright):
        expected = C.sensor_sigma(level[sel]).mean()
        assert diff[sel].std() == pytest.approx(float(np.sqrt(np.mean(C.sensor_sigma(level[sel]) ** 2))), rel=0.1)
        assert expected > P.NOISE_SIGMA
    assert diff[bright].std() > 1.3 * diff[dark].std()


def test_compression_bounded_change_masks_unchanged() -> None:
    scene, default = _scene("s3-mixed", compression=True), _scene("s3-mixed")
    img, mask = _render(scene, 60)
    ref, mask_ref = _render(default, 60)
    np.testing.assert_array_equal(mask, mask_ref)
    err = img.astype(np.float64) - ref
    mse = float(np.mean(err**2))
    assert 1.0 < np.abs(err).mean() < 6.0
    assert 30.0 < 10 * np.log10(255.0**2 / mse) < 45.0
    np.testing.assert_array_equal(img, C.jpeg_roundtrip(ref))


def test_dark_car_as_dark_as_the_road() -> None:
    scene, default = _scene("s3-mixed", dark_car=True), _scene("s3-mixed")
    dark = plaza_cast.ASPHALT_RGB
    assert scene.actors[0].shape.body == dark and default.actors[0].shape.body != dark
    assert [a.shape for a in scene.actors[1:]] == [a.shape for a in default.actors[1:]]
    f = 60
    rng = np.random.default_rng(0)
    out = {}
    for key, sc in (("dark", scene), ("default", default)):
        img, labels, _ = sc.render_labels(f, rng)
        car = labels == 1  # oid 0 + 1
        assert car.sum() > 2000
        rows = np.flatnonzero(car.any(axis=1))
        cols = np.flatnonzero(car.any(axis=0))
        band = np.zeros_like(car)
        band[rows[0] : rows[-1] + 1, max(cols[0] - 60, 0) : cols[-1] + 61] = True
        road = band & (labels == 0)
        out[key] = np.linalg.norm(np.median(img[car], axis=0) - np.median(img[road], axis=0).astype(np.float64))
        if key == "dark":
            grey_car, grey_road = img[car].mean(), np.median(img[road])
            assert abs(grey_car - grey_road) < 0.35 * grey_road
    assert out["dark"] < 0.6 * out["default"] and out["dark"] < 30.0
    # a scene without a car: unchanged (with a warning)
    people = _scene("s3-people", dark_car=True)
    assert [a.shape for a in people.actors] == [a.shape for a in _scene("s3-people").actors]


def test_condition_mask_quality_small() -> None:
    from wptrack.motion.experiments import _markdown, condition_mask_quality, render_arrays
    from wptrack.motion.masks import MaskConfig

    images, perfect, fps = render_arrays("s3-cars", "compression", seed=0, frames=3)
    assert images.shape == (3, 480, 640, 3) and perfect.shape == (3, 480, 640) and fps == P.FPS
    ref, _, _ = render_arrays("s3-cars", None, seed=0, frames=3)
    np.testing.assert_array_equal(images[1], C.jpeg_roundtrip(ref[1]))  # the noise draws of render_scene
    row = condition_mask_quality("s3-cars", "compression", seed=0, frames=6, config=MaskConfig(device="cpu"))
    assert row["frames"] == 6 and row["condition"] == "compression"
    assert 0.0 <= row["iou"] <= 1.0 and 0.0 <= row["fp_fraction"] < 0.05 and row["precision"] > 0.5
    assert "| compression | 0 |" in _markdown([row])


# ----------------------------------------------------------------------------------------------------- issue 26


def test_short_clip_objects_in_view_from_the_first_frame() -> None:
    for name in S3:
        default, scene = _scene(name), _scene(name, short_clip=True)
        n = scene.default_frames
        assert n == round(C.SHORT_S * P.FPS) < default.default_frames
        present = scene.states(n).present[:, :n]
        base = default.states(default.default_frames).present[:, : default.default_frames]
        count, full = present.sum(axis=0), base.sum(axis=0)
        assert count[0] >= 1 and (count >= 1).mean() > 0.9, name
        # the busiest clip of the default timeline: no other start holds more objects in view
        sums = np.convolve(full, np.ones(n), mode="valid")
        assert count.sum() == sums.max() and scene.short_origin_s == np.argmax(sums) / P.FPS, name
        # the same motion, shifted in time
        start = round(scene.short_origin_s * P.FPS)
        for oid, p in scene.trajectories(n).items():
            q = default.trajectories(default.default_frames)[oid][start : start + n]
            np.testing.assert_allclose(p, q, atol=1e-6, err_msg=f"{name} {oid}")


def test_clouds_darken_the_ground_softly_and_locally_masks_unchanged() -> None:
    scene, default = _scene("s3-people", clouds=True), _scene("s3-people")
    scene.noise_sigma = default.noise_sigma = 0.0
    bg = plaza_background()
    up = np.zeros(bg.sunlit.size, dtype=bool)
    up[bg.view.up_index] = True
    lit = up.reshape(bg.sunlit.shape) & (bg.sunlit > 0.99)  # sunlit up-facing ground
    seen = []
    for f in (0, 45, 90, 135):
        img, mask = _render(scene, f)
        ref, mask_ref = _render(default, f)
        np.testing.assert_array_equal(mask, mask_ref)  # cloud shadows are not objects
        ratio = (img.astype(np.float64) + 0.5) / (ref.astype(np.float64) + 0.5)
        keep = (mask == 0) & (ref.min(axis=2) >= 60)
        local = scene.local_light(f)
        g = ratio.mean(axis=2)
        # the ground truth of the darkening matches the pixels (static scene, away from the objects)
        sel = keep & (bg.view.label != LABEL_BUSH)
        assert np.abs(g[sel] - local[sel]).mean() < 0.01
        seen.append(local[lit & keep])
    cover = np.concatenate(seen)
    assert cover.min() < 0.8 and (cover > 0.99).mean() > 0.2  # deep shadows and clear ground, at once
    soft = ((cover > 0.8) & (cover < 0.97)).mean()
    assert soft > 0.05  # soft edges (and thin clouds)
    # the darkening keeps the hue: R falls most (bluish sky light), at most by a few percent more than B
    img, _ = _render(scene, 0)
    ref, _ = _render(default, 0)
    dark = (scene.local_light(0) < 0.85) & (ref.min(axis=2) >= 60)
    r = (img[dark].astype(np.float64) + 0.5) / (ref[dark] + 0.5)
    assert 0.0 < np.median(r[:, 0] - r[:, 2]) < 0.05  # B / B_bg above R / R_bg
    # the facade darkens less than the sunlit ground under the same cover
    pts = PB.static_points(False)
    cover_map = C.cloud_cover(C.cloud_shadow_foot(pts, bg.light.unit), 0.0)
    share = PB.static_share(False)
    assert np.allclose(share[bg.view.label == 2], C.CLOUD_SIDE_SHARE) and share[lit].min() > 0.5
    assert cover_map.max() > 0.3 and "clouds" in scene.hints()["conditions"]


def test_exposure_global_jumps_and_a_local_light() -> None:
    scene, default = _scene("s3-mixed", exposure=True), _scene("s3-mixed")
    fps = scene.fps
    for t, factor in ((0.0, 1.0), (2.0, C.EXPOSURE_STEPS[0][1]), (6.0, 1.3 * 0.8)):
        f = int(t * fps)
        g = scene.gain(f) / default.gain(f)
        assert np.allclose(g[1], factor)  # green: no white-balance shift
    g = scene.gain(int(4.5 * fps)) / default.gain(int(4.5 * fps))
    np.testing.assert_allclose(g, 1.3 * np.asarray(C.AWB_SHIFTS[0][1]))
    # the first light is off before its time and lights its pool after, locally
    before, after = scene.local_light(int(2.0 * fps)), scene.local_light(int(4.0 * fps))
    assert np.all(before == 1.0)
    assert after.max() > 1.25 and (after > 1.05).mean() < 0.6 and (after < 1.01).mean() > 0.3  # part of the view
    scene.noise_sigma = default.noise_sigma = 0.0
    f = int(4.0 * fps)
    img, mask = _render(scene, f)
    ref, mask_ref = _render(default, f)
    np.testing.assert_array_equal(mask, mask_ref)
    ratio = (img.astype(np.float64) + 0.5) / (ref.astype(np.float64) + 0.5)
    pool = (after > 1.2) & (mask == 0) & (ref.max(axis=2) < 180)
    outside = (after < 1.005) & (mask == 0) & (ref.min(axis=2) > 40) & (ref.max(axis=2) < 180)
    gain = scene.gain(f) / default.gain(f)  # R, G, B
    assert np.median(ratio[outside][:, 1]) == pytest.approx(gain[1], abs=0.02)
    assert np.median(ratio[pool][:, 1]) > 1.2 * gain[1]
