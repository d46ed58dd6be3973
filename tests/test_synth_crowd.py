"""The ``crowd`` and ``cyclists`` conditions of the s3 plaza scenes (issue 26, ``wptrack.synth.plaza_crowd``): the
counts, groups, gaps and borders they promise, reproducible per scene seed, the scene's own objects untouched."""

from __future__ import annotations

import numpy as np
import pytest

from wptrack.synth import SCENES, render_scene
from wptrack.synth import conditions as C
from wptrack.synth import plaza as P
from wptrack.synth import plaza_crowd as PC
from wptrack.synth.base import _groundtruth_csv


def _scene(name: str, seed: int, **on: bool) -> P.PlazaScene:
    return SCENES[name].build(seed).with_conditions(C.PlazaConditions(**on))


def _gt(scene: P.PlazaScene, n: int = 180) -> str:
    return _groundtruth_csv(scene.trajectories(n), scene.groundtruth_columns(n))


@pytest.fixture(scope="module")
def crowds() -> dict[tuple[str, int], P.PlazaScene]:
    return {(name, seed): _scene(name, seed, crowd=True) for name in ("s3-people", "s3-groups") for seed in (0, 10)}


def test_crowd_counts_groups_and_gaps(crowds) -> None:
    """20-40 crowd people in the ground truth at once on average (the scene's own on top), singles, pairs and
    threes whose members walk 0.6-1.2 m apart, everybody else at least 0.7 m apart, nobody nearer than 0.45 m to the
    clutter; the scene's own objects keep their ground truth."""
    from wptrack.synth import plaza_rules as R

    all_sizes: set[int] = set()
    for (name, seed), scene in crowds.items():
        default = SCENES[name].build(seed)
        own = len(default.actors)
        st = scene.states(180)
        crowd = st.present[own:, :180].sum(axis=0)
        assert PC.CROWD_AT_ONCE[0] <= crowd.mean() <= PC.CROWD_AT_ONCE[1] + 1, (name, seed, crowd.mean())
        assert crowd[0] >= 10, "people in view from the first frame"
        ref, got = default.trajectories(180), scene.trajectories(180)
        for oid in ref:
            np.testing.assert_array_equal(got[oid], ref[oid])
        formations = {}
        for a, actor in enumerate(scene.actors):
            f = getattr(actor.track, "formation", None)
            formations.setdefault(id(f) if f is not None else -1 - a, []).append(a)
        sizes = [len(v) for v in formations.values()]
        assert {1, 2} <= set(sizes), sizes
        all_sizes.update(sizes)
        pos, act = st.pos[:, :360], st.active[:, :360]
        group_of = {a: k for k, members in formations.items() for a in members}
        for a in range(len(scene.actors)):
            for b in range(a + 1, len(scene.actors)):
                both = act[a] & act[b]
                if not both.any():
                    continue
                gap = np.linalg.norm(pos[a, both] - pos[b, both], axis=1)
                need = 0.6 if group_of[a] == group_of[b] else 0.7
                assert gap.min() >= need - 1e-6, (name, seed, a, b, gap.min())
        for members in formations.values():  # each member's nearest fellow walks beside it (within 1.2 m)
            for a in members if len(members) > 1 else ():
                near = np.min([np.linalg.norm(pos[a] - pos[b], axis=1) for b in members if b != a], axis=0)
                assert near[act[a]].max() <= 1.2, (name, seed, a, near[act[a]].max())
        for a in range(own, len(scene.actors)):
            assert R.clutter_distance(pos[a, act[a]]).min() >= R.CLUTTER_GAP - 1e-6
    assert {1, 2, 3} <= all_sizes, all_sizes


def test_crowd_enters_at_every_border_and_far_away(crowds) -> None:
    """People come into view at the left, right and bottom borders during the sequence (not only at the first
    frame), and some walk far away (beyond y = 18.5 m: 8-10 pixels wide at 640x480, or behind the parked cars)."""
    cam = P.plaza_camera()
    for (name, seed), scene in crowds.items():
        st = scene.states(180)
        sides = set()
        far = 0
        for a in range(len(scene.actors)):
            frames = np.flatnonzero(st.present[a, :180])
            if len(frames) == 0:
                continue
            far += bool(np.any(st.pos[a, frames, 1] > 18.5))
            f = frames[0]
            if f == 0:
                continue
            uv = cam.project(np.array([[*st.pos[a, f], 0.0]]))[0][0]
            sides.add("left" if uv[0] < 0.2 * cam.width else "right" if uv[0] > 0.8 * cam.width else "bottom")
        assert sides == {"left", "right", "bottom"}, (name, seed, sides)
        assert far >= 1, (name, seed)


def test_crowd_reproducible_per_scene_seed(crowds) -> None:
    """The same scene and seed give the same crowd; another seed another one."""
    again = _scene("s3-people", 0, crowd=True)
    assert _gt(again) == _gt(crowds[("s3-people", 0)])
    assert _gt(crowds[("s3-people", 10)]) != _gt(crowds[("s3-people", 0)])


def test_cyclists_one_object_fast_and_rendered(tmp_path) -> None:
    """2-4 cyclists, one ground-truth object each (class ``cyclist``, the bike's length, the rider's height), riding
    3.5-6 m/s and kept 1 m from the cars; a rendered frame shows a cyclist's pixels in the perfect mask; the scene
    json names the condition."""
    for name, seed in (("s3-people", 0), ("s3-mixed", 10)):
        scene = _scene(name, seed, cyclists=True)
        bikes = [a for a, actor in enumerate(scene.actors) if isinstance(actor.shape, PC.Cyclist)]
        assert PC.CYCLISTS[0] <= len(bikes) <= PC.CYCLISTS[1], (name, seed, len(bikes))
        st = scene.states(180)
        cols = scene.groundtruth_columns(180)
        for a in bikes:
            oid = scene.actors[a].oid
            assert cols["class"][oid][0] == PC.CYCLIST_CLASS
            assert 1.6 < cols["length"][oid][0] < 1.9 and 1.4 < cols["height"][oid][0] < 1.8
            sp = st.speed[a][st.active[a]]
            assert PC.CYCLE_SPEEDS[0] - 0.35 <= sp.min() and sp.max() <= PC.CYCLE_SPEEDS[1] + 0.35
        assert PC.CYCLIST_CLASS in scene.classes()
    res = render_scene("s3-people", tmp_path / "c", frames=1, conditions="cyclists")
    assert "cyclists" in res.scene_json.read_text()
    scene = _scene("s3-people", 0, cyclists=True)
    st = scene.states(180)
    a = next(a for a, actor in enumerate(scene.actors) if isinstance(actor.shape, PC.Cyclist) and st.present[a].any())
    f = int(np.flatnonzero(st.present[a])[len(np.flatnonzero(st.present[a])) // 2])
    _, labels, pixels = scene.render_labels(f, np.random.default_rng(0))
    oid = scene.actors[a].oid
    assert pixels[oid][0] > 50 and np.count_nonzero(labels == oid + 1) == pixels[oid][0]


def test_crowd_and_cyclists_together() -> None:
    """Both conditions: the cyclists of the cyclists condition alone (drawn first), and a crowd that keeps off
    them (people at least 1.2 m from a cyclist while both are on their paths)."""
    both = _scene("s3-people", 10, crowd=True, cyclists=True)
    alone = _scene("s3-people", 10, cyclists=True)
    bikes = [a for a in both.actors if isinstance(a.shape, PC.Cyclist)]
    assert [a.oid for a in bikes] == [a.oid for a in alone.actors if isinstance(a.shape, PC.Cyclist)] and bikes
    st = both.states(360)
    people = [i for i, a in enumerate(both.actors) if isinstance(a.shape, P.Person)]
    assert len(people) > 30
    for b in (i for i, a in enumerate(both.actors) if isinstance(a.shape, PC.Cyclist)):
        for p in people:
            on = st.active[b] & st.active[p]
            if on.any():
                assert np.linalg.norm(st.pos[b, on] - st.pos[p, on], axis=1).min() >= 1.2 - 1e-6
