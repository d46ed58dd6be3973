"""The plaza scenes of Juza et al. as registered scenes: ``s3-people``, ``s3-cars``, ``s3-groups`` and ``s3-mixed``,
seed 0 the fixed casts below, any other seed a cast drawn by :mod:`wptrack.synth.plaza_seeds`; the scene itself is
:class:`wptrack.synth.plaza.PlazaScene`."""

from __future__ import annotations

from wptrack.synth import plaza_seeds
from wptrack.synth.actors import Formation, Path, PlazaActor
from wptrack.synth.base import Scene, register_scene
from wptrack.synth.plaza import PlazaScene
from wptrack.synth.plaza_background import ROAD_LANES
from wptrack.synth.plaza_cast import U_TURN, U_TURN_SPEEDS, _car, _people


def _drawn(name: str, seed: int) -> list[PlazaActor]:
    """The actors of scene ``name`` at a scene seed >= 1 (:mod:`wptrack.synth.plaza_seeds`)."""
    return plaza_seeds.draw_actors(name, seed)


def people_actors(seed: int = 0) -> list[PlazaActor]:
    """``s3-people``: five people on waypoint paths, entering and leaving at different times (seed 0: fixed)."""
    if seed:
        return _drawn("s3-people", seed)
    looks = _people(5, seed=301, camouflage=(2,))
    paths = [
        Path(
            ((-5.0, 5.8), (-2.0, 6.8), (1.0, 7.6), (3.4, 8.8), (4.5, 10.4), (5.6, 12.6), (8.5, 14.6), (12.0, 16.0)),
            1.4,
            -1.0,
        ),
        Path(((8.0, 9.4), (4.5, 9.0), (1.0, 8.8), (-2.0, 8.2), (-5.0, 8.8), (-8.5, 9.5), (-11.5, 9.6)), 1.35, -1.5),
        Path(((0.2, 2.6), (-0.2, 5.5), (-1.2, 8.0), (-1.6, 10.4), (-1.0, 13.5), (0.5, 16.5), (1.0, 19.0)), 0.95, 1.3),
        Path(
            ((-11.5, 12.2), (-7.0, 11.8), (-3.5, 11.2), (0.0, 11.4), (3.5, 12.0), (7.0, 13.0), (12.5, 14.6)), 1.5, 1.2
        ),
        Path(
            ((9.0, 5.6), (5.5, 6.2), (2.5, 6.6), (-1.0, 6.0), (-3.5, 4.8), (-5.5, 2.5)),
            (1.1, 1.1, 0.85, 0.85, 1.2, 1.2),
            5.5,
        ),
    ]
    return [PlazaActor(i, look, path) for i, (look, path) in enumerate(zip(looks, paths, strict=True))]


def cars_actors(seed: int = 0) -> list[PlazaActor]:
    """``s3-cars``: two cars passing each other in opposite lanes, a third making a U-turn (seed 0: fixed)."""
    if seed:
        return _drawn("s3-cars", seed)
    near, far = ROAD_LANES
    u_turn = Path(U_TURN, U_TURN_SPEEDS, 1.0, smooth_m=4.0)
    return [
        PlazaActor(0, _car(4.5, 1.8, 1.5, (0.24, 0.24, 0.26)), Path(((-17.0, near), (17.0, near)), 6.5, -1.0)),
        PlazaActor(1, _car(4.2, 1.75, 1.45, (0.8, 0.8, 0.78)), Path(((18.0, far), (-18.0, far)), 5.5, -1.3)),
        PlazaActor(2, _car(4.7, 1.85, 1.55, (0.32, 0.4, 0.55)), u_turn),
    ]


def groups_actors(seed: int = 0) -> list[PlazaActor]:
    """``s3-groups``: a group walking together (six at seed 0, five or six at other seeds) and a straggler."""
    if seed:
        return _drawn("s3-groups", seed)
    looks = _people(7, seed=303, camouflage=(1, 4))
    route = ((-4.0, 3.6), (-2.0, 5.6), (-0.5, 7.6), (0.0, 9.2), (0.3, 11.5), (1.5, 14.5), (3.5, 18.0))
    group = Formation(
        Path(route, 1.05, -2.0),
        offsets=((0.55, -0.95), (0.7, 0.05), (0.45, 1.0), (-0.45, -0.5), (-0.35, 0.55), (-1.3, 0.0)),
    )
    straggler = Path(((-6.0, 1.6), *((x + 0.3, y) for x, y in route)), 1.2, -0.5)
    actors = [PlazaActor(k, looks[k], group.member(k)) for k in range(6)]
    actors.append(PlazaActor(6, looks[6], straggler))
    return actors


def mixed_actors(seed: int = 0) -> list[PlazaActor]:
    """``s3-mixed``: two cars on the road and two people, one crossing the road between the cars' passages."""
    if seed:
        return _drawn("s3-mixed", seed)
    near, far = ROAD_LANES
    looks = _people(2, seed=306, camouflage=(1,))
    crossing = Path(
        ((1.0, 6.0), (1.2, 8.2), (1.6, 10.5), (1.8, 12.5), (2.0, 15.5), (2.4, 19.0), (3.5, 23.8)), 1.1, -1.6
    )
    stroll = Path(((5.2, 6.2), (2.0, 6.4), (-1.0, 7.0), (-3.0, 8.8), (-6.0, 9.0), (-10.0, 9.2)), 1.0, -0.5)
    return [
        PlazaActor(0, _car(4.4, 1.8, 1.5, (0.1, 0.16, 0.4)), Path(((-8.5, near), (17.0, near)), 4.0)),
        PlazaActor(1, _car(4.6, 1.85, 1.55, (0.55, 0.56, 0.58)), Path(((17.0, far), (-17.0, far)), 6.0, 2.7)),
        PlazaActor(2, looks[0], crossing),
        PlazaActor(3, looks[1], stroll),
    ]


@register_scene(
    "s3-people", "Juza et al.: up to 5 people walking randomly on a plaza, occlusions; 1 high camera", seeded=True
)
def _s3_people(seed: int = 0) -> Scene:
    return PlazaScene(people_actors(seed))


@register_scene(
    "s3-cars", "Juza et al.: 3 cars, two passing each other (occlusion), one U-turn; 1 high camera", seeded=True
)
def _s3_cars(seed: int = 0) -> Scene:
    return PlazaScene(cars_actors(seed))


@register_scene(
    "s3-groups", "Juza et al.: a group of 5-6 people walking together and a straggler; 1 high camera", seeded=True
)
def _s3_groups(seed: int = 0) -> Scene:
    return PlazaScene(groups_actors(seed))


@register_scene(
    "s3-mixed",
    "Juza et al.: 2 cars and 2 people, one crossing the road between the cars; 1 high camera",
    seeded=True,
)
def _s3_mixed(seed: int = 0) -> Scene:
    return PlazaScene(mixed_actors(seed))
