"""Scene seeds of the s3 plaza scenes: seed 0 is pinned, other seeds draw new sequences of the same scene type."""

from __future__ import annotations

import functools
import hashlib
import json
import math

import numpy as np
import pytest

from wptrack.core.errors import ConfigError
from wptrack.io.frames import open_frames
from wptrack.kernels.templates.raster import MAX_SLOTS
from wptrack.synth import SCENES, plaza_cast, render_scene
from wptrack.synth import plaza as P
from wptrack.synth import plaza_rules as R
from wptrack.synth import plaza_seeds as S
from wptrack.synth.base import _groundtruth_csv
from wptrack.trackers.templates.config import TemplateConfig, VehiclePrior

S3 = ("s3-people", "s3-cars", "s3-groups", "s3-mixed")
FRAMES = 180

# Computed before scene seeds changed the sequences (commit 1d54f66): sha256 of groundtruth.csv over the default 180
# frames, and of the repr of the scene's actors (looks and paths). The ground truth's hashes again on 2026-11-27, when
# it began to label objects nearly whole in view (plaza_background.MIN_IN_IMAGE 0.9; the actors' hashes unchanged).
PINNED = {
    "s3-people": (
        "0b50521e2e99b8aa2fc099e5c67bddafdd4096757301753f6d1f5851f6c45847",
        "0d7ace6c88f3331c860ac5b2ec37022223996606bf529761e51e4e034861ed97",
    ),
    "s3-cars": (
        "b974a9b69d7dbbe35de1663a3d06f75221ee87abe5c54dcaab62bdb38f930146",
        "b0bf6af6d9f8e28168f373eb0d60b60dc11336e57aff2ff1392074edd433c484",
    ),
    "s3-groups": (
        "a709704b319637d40c0a174b6ebb3cb8610fa05f819461fa56ef594a7cdebf1c",
        "fb1637b93a880cae159af01a7325c648b34272bf8b81a8ab23ce119c6fa24892",
    ),
    "s3-mixed": (
        "d6c9cbfe1e8757216b3a16a0f7bddaa766a23395682d3a94c3e3de7145412b4f",
        "26a448b55cb35569b0946006f23225b715d1181878c080864cf9f02eca4dd531",
    ),
}


def _sha(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


@pytest.mark.parametrize("name", S3)
def test_seed_zero_is_pinned(name: str) -> None:
    """Scene seed 0 (all published numbers) keeps its ground truth and actors byte for byte."""
    scene = SCENES[name].build()
    n = scene.default_frames
    assert n == 180
    gt_hash, actors_hash = PINNED[name]
    assert _sha(repr(scene.base_actors)) == actors_hash
    assert _sha(_groundtruth_csv(scene.trajectories(n), scene.groundtruth_columns(n))) == gt_hash


# ----------------------------------------------------------------------------------------------------- new seeds


@functools.cache
def _scene(name: str, seed: int) -> P.PlazaScene:
    scene = SCENES[name].build(seed)
    assert isinstance(scene, P.PlazaScene)
    return scene


def _fingerprint(scene: P.PlazaScene) -> tuple[float, ...]:
    """Ground positions of every object at frames 0, 45, 90, 135 (NaN where absent), rounded to 1 cm."""
    traj = scene.trajectories(FRAMES)
    return tuple(np.round(np.concatenate([traj[k][::45, :2].ravel() for k in sorted(traj)]), 2).tolist())


def test_registered_as_seeded_with_seed_zero_the_default() -> None:
    for name in S3:
        spec = SCENES[name]
        assert spec.seeded
        assert repr(spec.build().base_actors) == repr(spec.build(0).base_actors)
        assert repr(spec.build(7).base_actors) == repr(SCENES[name].build(7).base_actors)  # same seed, same draw


@pytest.mark.parametrize("name", S3)
def test_new_seeds_draw_new_sequences(name: str) -> None:
    """Seeds 1-20: new trajectories, different from seed 0's and from each other's; new looks too."""
    prints = {seed: _fingerprint(_scene(name, seed)) for seed in range(21)}
    assert len(set(prints.values())) == 21, name
    looks = {repr([a.shape for a in _scene(name, seed).actors]) for seed in range(21)}
    assert len(looks) == 21, name


def test_draw_actors_rejects_bad_input() -> None:
    with pytest.raises(ConfigError, match="seed"):
        S.draw_actors("s3-cars", 0)
    with pytest.raises(ConfigError, match="seed"):
        S.draw_actors("s3-cars", -3)
    with pytest.raises(ConfigError, match="scene"):
        S.draw_actors("s1-lab", 1)


def _outline(pos: np.ndarray, heading: np.ndarray, car: P.Car) -> np.ndarray:
    """(N, K, 2) points on a car's footprint rectangle (every ~0.2 m of its outline) at (N, 2) and (N,) headings."""
    u = np.linspace(-0.5, 0.5, 21)
    local = np.concatenate(
        [np.stack([u * car.length, np.full_like(u, s * 0.5 * car.width)], 1) for s in (-1, 1)]
        + [np.stack([np.full_like(u, s * 0.5 * car.length), u * car.width], 1) for s in (-1, 1)]
    )
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    wx = pos[:, 0, None] + c * local[None, :, 0] - s * local[None, :, 1]
    wy = pos[:, 1, None] + s * local[None, :, 0] + c * local[None, :, 1]
    return np.stack([wx, wy], axis=2)


def _footprint_distance(p: np.ndarray, pos: np.ndarray, heading: np.ndarray, car: P.Car) -> np.ndarray:
    """Distance from points (N, ...) x 2 to a car's footprint rectangle at (N, 2), (N,) headings (0 inside)."""
    extra = (slice(None),) + (None,) * (p.ndim - 2)
    c, s = np.cos(heading)[extra], np.sin(heading)[extra]
    rx, ry = p[..., 0] - pos[:, 0][extra], p[..., 1] - pos[:, 1][extra]
    along = np.maximum(np.abs(c * rx + s * ry) - 0.5 * car.length, 0.0)
    across = np.maximum(np.abs(-s * rx + c * ry) - 0.5 * car.width, 0.0)
    return np.hypot(along, across)


def _check_invariants(name: str, seed: int) -> None:
    scene = _scene(name, seed)
    actors = scene.actors
    humans = [a for a in actors if isinstance(a.shape, P.Person)]
    cars = [a for a in actors if isinstance(a.shape, P.Car)]
    where = f"{name} seed {seed}"
    # counts per scene type (paper Table 2), the share of camouflaged clothes and of dark cars as at seed 0
    expected = {"s3-people": ((5,), 0), "s3-cars": ((0,), 3), "s3-groups": ((6, 7), 0), "s3-mixed": ((2,), 2)}
    assert len(humans) in expected[name][0] and len(cars) == expected[name][1], where
    camouflaged = sum(plaza_cast._PAVING_LIKE in (a.shape.shirt, a.shape.trousers) for a in humans)
    assert camouflaged == {"s3-people": 1, "s3-cars": 0, "s3-groups": 2, "s3-mixed": 1}[name], where
    assert sum(max(a.shape.body) < S.DARK_PAINT_MAX for a in cars) == (1 if cars else 0), where
    for a in cars:
        assert 4.0 <= a.shape.length <= 4.8 and 1.7 <= a.shape.width <= 1.9 and 1.4 <= a.shape.height <= 1.6, where

    st = scene.states(R.CHECK_FRAMES)
    act = st.active
    present = st.present[:, :FRAMES]
    # every object in the ground truth long enough; at most R_max objects at once
    assert present.sum(axis=1).min() >= R.MIN_PRESENT, (where, present.sum(axis=1))
    assert scene.max_objects() <= TemplateConfig().max_objects and scene.max_objects() + 3 <= int(MAX_SLOTS), where
    # speeds (m/s) where on the path
    for a, actor in enumerate(actors):
        lo, hi = (0.8, 1.6) if isinstance(actor.shape, P.Person) else (2.0, 8.0)
        sp = st.speed[a, act[a]]
        assert lo - 0.02 <= sp.min() and sp.max() <= hi + 0.02, (where, actor.oid, sp.min(), sp.max())
    # people keep off the clutter, cars stay on the road (seed 0's U-turn brushes the kerb and the parking line)
    road = (10.5, 19.6) if seed == 0 else (10.8, 19.3)
    for a, actor in enumerate(actors):
        pos = st.pos[a, act[a]]
        if isinstance(actor.shape, P.Person):
            assert R.clutter_distance(pos).min() >= 0.45, (where, actor.oid)
        else:
            h = st.heading[a, act[a]]
            for sx, sy in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                lx, ly = sx * 0.5 * actor.shape.length, sy * 0.5 * actor.shape.width
                y = pos[:, 1] + np.sin(h) * lx + np.cos(h) * ly
                assert road[0] <= y.min() and y.max() <= road[1], (where, actor.oid, y.min(), y.max())
    # objects keep apart while both are on their paths (group members: the paper's 0.6 m)
    for a in range(len(actors)):
        for b in range(a + 1, len(actors)):
            both = act[a] & act[b]
            if not np.any(both):
                continue
            sa, sb = actors[a].shape, actors[b].shape
            pa, pb = st.pos[a, both], st.pos[b, both]
            if isinstance(sa, P.Person) and isinstance(sb, P.Person):
                assert np.linalg.norm(pa - pb, axis=1).min() >= 0.6, (where, a, b)
            elif isinstance(sa, P.Car) and isinstance(sb, P.Car):
                ha, hb = st.heading[a, both], st.heading[b, both]
                gap = min(
                    _footprint_distance(_outline(pa, ha, sa), pb, hb, sb).min(),
                    _footprint_distance(_outline(pb, hb, sb), pa, ha, sa).min(),
                )
                assert gap >= 0.5, (where, a, b, gap)
            else:
                (pp, cc, car) = (pa, b, sb) if isinstance(sa, P.Person) else (pb, a, sa)
                gap = _footprint_distance(pp, st.pos[cc, both], st.heading[cc, both], car)
                assert gap.min() >= 0.6, (where, a, b, gap.min())
    # a group: 5-6 members, each 0.6-1.2 m from its nearest fellow member at every frame
    if name == "s3-groups":
        members = [a for a, actor in enumerate(actors) if hasattr(actor.track, "formation")]
        assert len(members) in (5, 6) and len(members) == len(actors) - 1, where
        pts = st.pos[members][:, :FRAMES]
        d = np.linalg.norm(pts[:, None] - pts[None, :], axis=-1) + 99.0 * np.eye(len(members))[:, :, None]
        nearest = d.min(axis=1)
        assert nearest.min() >= 0.6 and nearest.max() <= 1.2, (where, nearest.min(), nearest.max())
    # the rules of the generator itself, appearing/vanishing in view included (seed 0 is the fixed sequence and
    # breaks three of them slightly: see plaza_seeds)
    if 1 <= seed <= 10:
        assert R.layout_problems(list(actors)) == [], where


@pytest.mark.parametrize("name", S3)
def test_invariants_for_seeds_0_to_50(name: str) -> None:
    for seed in range(51):
        _check_invariants(name, seed)


def test_cars_pass_each_other_and_one_turns(name: str = "s3-cars") -> None:
    """s3-cars at new seeds: two cars in opposite lanes side by side in view (occlusion), one U-turn."""
    for seed in range(1, 21):
        scene = _scene(name, seed)
        cols = scene.groundtruth_columns(FRAMES)
        traj = scene.trajectories(FRAMES)
        seen = {k: np.all(np.isfinite(traj[k]), axis=1) for k in traj}
        turns = [k for k in traj if np.ptp(np.unwrap(cols["orientation"][k][seen[k]])) > 0.9 * math.pi]
        assert len(turns) == 1, seed
        a, b = (k for k in traj if k not in turns)
        both = seen[a] & seen[b]
        dx = np.abs(traj[a][both, 0] - traj[b][both, 0])
        assert dx.min() < 1.0, seed  # level with each other: the near car hides part of the far one
        f = np.flatnonzero(both)[np.argmin(dx)]
        assert np.cos(cols["orientation"][a][f] - cols["orientation"][b][f]) < -0.99, seed


def test_vehicle_prior_covers_the_cars_turns_and_speeds() -> None:
    """The clamps of eq. 9 (``VehiclePrior.turn_max``, ``speed_max``) cover what every scene's cars do, seeds 0-50.

    A turn limit below a car's yaw rate makes every hypothesis of that car lag outside its turn, and humans are then
    added on the part of the car it leaves uncovered (the U-turn lag of docs/notes.md: with the old limit of
    1 rad/s the U-turns of s3-cars, up to 2.4 rad/s, were out of the prior's reach)."""
    prior = VehiclePrior()
    for name in ("s3-cars", "s3-mixed"):
        for seed in range(51):
            scene = _scene(name, seed)
            st = scene.states(R.CHECK_FRAMES)
            for a, actor in enumerate(scene.actors):
                if not isinstance(actor.shape, P.Car) or st.active[a].sum() < 2:
                    continue
                heading = np.unwrap(st.heading[a, st.active[a]])
                yaw_rate = np.abs(np.diff(heading)).max() * scene.fps
                assert yaw_rate <= prior.turn_max, (name, seed, actor.oid, yaw_rate)
                assert st.speed[a, st.active[a]].max() <= prior.speed_max, (name, seed, actor.oid)


def test_people_enter_leave_and_occlude() -> None:
    for seed in range(1, 21):
        scene = _scene("s3-people", seed)
        present = scene.states(FRAMES).present[:, :FRAMES]
        first = [int(np.flatnonzero(p)[0]) for p in present]
        last = [int(np.flatnonzero(p)[-1]) for p in present]
        assert len(set(first)) >= 3 and min(last) < FRAMES - 1 and present.sum(axis=0).max() >= 3, seed


def test_mixed_crossing_between_the_passages() -> None:
    """s3-mixed at new seeds: one person crosses the road, one car passes the crossing point before and one after."""
    for seed in range(1, 21):
        scene = _scene("s3-mixed", seed)
        st = scene.states(FRAMES)
        crosser = 2
        on_road = st.active[crosser] & (st.pos[crosser, :, 1] > 10.8) & (st.pos[crosser, :, 1] < 19.3)
        assert np.any(on_road), seed
        kerb = int(np.argmax(st.pos[crosser, :, 1] >= 10.8))
        x_cross = st.pos[crosser, int(np.argmax(st.pos[crosser, :, 1] >= 15.0)), 0]
        passes = [int(np.argmin(np.where(st.active[k], np.abs(st.pos[k, :, 0] - x_cross), np.inf))) for k in (0, 1)]
        assert min(passes) < kerb < max(passes), (seed, passes, kerb)


@pytest.mark.parametrize("name", S3)
def test_render_scene_with_a_new_seed(tmp_path, name: str) -> None:
    seed = 11
    res = render_scene(name, tmp_path, frames=2, seed=seed)
    scene = _scene(name, seed)
    meta = json.loads(res.scene_json.read_text())
    assert meta["seed"] == seed and meta["max_objects"] == scene.max_objects() and meta["frames"] == 2
    assert res.groundtruth_path.read_text() == _groundtruth_csv(scene.trajectories(2), scene.groundtruth_columns(2))
    images = [frames[0] for frames in open_frames(res.videos)]
    masks = [frames[0] for frames in open_frames(res.mask_videos)]
    assert len(images) == len(masks) == 2 and all(image.shape == (480, 640, 3) for image in images)
    _, labels, _ = scene.render_labels(1, np.random.default_rng(0))
    np.testing.assert_array_equal(masks[1][..., 0], np.where(labels > 0, 255, 0))
    zero, n = _scene(name, 0), FRAMES  # another sequence (over the whole clip: s3-cars labels its first car at 10)
    assert _groundtruth_csv(scene.trajectories(n), scene.groundtruth_columns(n)) != _groundtruth_csv(
        zero.trajectories(n), zero.groundtruth_columns(n)
    )


def test_accuracy_cache_renders_stale_scenes_again(tmp_path, caplog) -> None:
    """A scene folder of template_accuracy rendered before seeds drew new sequences is not reused."""
    from wptrack.trackers.templates.experiments import _s3_scene

    first = _s3_scene("s3-people", tmp_path, 2, 2, False)  # people: labelled from frame 0 (s3-cars' from 10)
    assert _s3_scene("s3-people", tmp_path, 2, 2, False).groundtruth_path == first.groundtruth_path
    fresh = first.groundtruth_path.read_text()
    assert len(fresh.splitlines()) > 1
    old = render_scene("s3-people", tmp_path / "old", frames=2).groundtruth_path.read_text()
    assert old != fresh
    first.groundtruth_path.write_text(old)
    (first.out_dir / "masks-offline").mkdir()
    (first.out_dir / "masks-offline" / "masks.json").write_text("{}")
    again = _s3_scene("s3-people", tmp_path, 2, 2, False)
    assert again.groundtruth_path.read_text() == fresh
    assert not (first.out_dir / "masks-offline").exists()
    assert "stale scene" in caplog.text


def test_accuracy_workers_give_the_same_table(tmp_path) -> None:
    """template_accuracy with two worker processes gives the same per-run evaluations and table as in-process runs
    (every run is seeded and independent); a worker count below 1 is refused with the field named."""
    pytest.importorskip("motmetrics")
    from wptrack.core.errors import ConfigError
    from wptrack.trackers.templates.experiments import template_accuracy

    kw = dict(scenes=["s3-people"], seeds=[0, 1], frames=6, particles=60, masks="perfect", device="cpu",
              scenes_dir=tmp_path / "scenes")  # fmt: skip
    one = template_accuracy(out_dir=tmp_path / "one", **kw)
    two = template_accuracy(out_dir=tmp_path / "two", workers=2, **kw)
    assert one["scenes"] == two["scenes"] and len(two["scenes"]["s3-people"]["runs"]) == 2
    assert (tmp_path / "two" / "s3-people" / "s0" / "seed1" / "tracks.csv").exists()
    with pytest.raises(ConfigError, match="workers"):
        template_accuracy(out_dir=tmp_path / "bad", workers=0, **kw)


def test_accuracy_masks_made_again_when_the_pipeline_changed(tmp_path, monkeypatch) -> None:
    """template_accuracy's cached masks are reused for the same configuration and pipeline code, and made again when
    the pipeline's code changed with the same configuration (a kernel changed, its fields did not)."""
    import json

    import wptrack.motion.writing as writing
    from wptrack.motion.masks import MaskConfig
    from wptrack.trackers.templates.experiments import _s3_masks, _s3_scene

    res = _s3_scene("s3-cars", tmp_path, 4, 2, False)
    cfg = MaskConfig(window=4, samples=4, device="cpu")
    video = _s3_masks(res, "offline", cfg)
    summary = video.parent / "masks.json"
    first = json.loads(summary.read_text())
    assert first["code"] == writing.pipeline_hash() and len(first["code"]) == 16
    stamp = summary.stat().st_mtime_ns
    assert _s3_masks(res, "offline", cfg) == video and summary.stat().st_mtime_ns == stamp  # reused
    monkeypatch.setattr(writing, "pipeline_hash", lambda: "0" * 16)
    assert _s3_masks(res, "offline", cfg) == video
    assert json.loads(summary.read_text())["code"] == "0" * 16  # made again, by the "changed" pipeline
