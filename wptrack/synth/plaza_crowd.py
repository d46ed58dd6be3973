"""The ``crowd`` and ``cyclists`` conditions of the s3 plaza scenes (issue 26): a busy street and people on bikes.

Both add moving objects to a plaza scene (its own objects stay as they are) and follow its rules (people keep 0.7 m
from each other, 0.6 m inside a group, 0.45 m from the clutter and 1 m from cars; objects start and end their paths
outside the image). The extra objects are drawn from ``np.random.default_rng([crc32(name), key])`` where ``key`` is
the crc32 of the scene's own objects (their ids, looks and paths): the same scene and seed always get the same crowd,
and every scene seed another one. Ids follow the scene's own.

- ``crowd``: 20-40 people in the ground truth at once (the mean over the default length is drawn in that range per
  scene): singles, pairs walking side by side (0.7-0.9 m apart) and groups of three (abreast or in a shallow V,
  each member's nearest fellow within 1.2 m, the paper's group spacing), walking along the street in
  both directions (the plaza in front of the kerb, the road when the scene has no car, the far side of the road
  along the parked cars, 25 m from the camera, where people are 8-10 pixels wide, and the far sidewalk behind the
  parked cars, where they are half hidden by the cars and cut by the top of the image), and some crossing in from
  the bottom of the image; in view from the first frame and entering at the left, right and bottom borders all
  through the sequence.
- ``cyclists``: :data:`CYCLISTS` people riding bicycles at 3.5-6 m/s along the road (near the kerb when the scene
  has cars) and across the plaza; a rider and a bike are one object (class :data:`CYCLIST_CLASS`, length the bike's,
  width the handlebar's, height the rider's head).

The camera, plaza and clutter are the plaza's (:mod:`wptrack.synth.plaza`): 7.5 m above the ground looking 38 degrees
down over a plaza and a road, the high camera over a street of the issue at 640x480. The conditions' parameters
(:data:`CROWD_AT_ONCE`, :data:`CYCLISTS` ...) are :mod:`wptrack.synth.conditions`'s, which writes them to scene.json.
This module registers both conditions with the plaza scene (:func:`wptrack.synth.plaza.register_actor_condition`,
cyclists first: the crowd keeps off them); ``wptrack.synth`` imports it, so the plaza does not import this module.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from wptrack.synth import plaza as P
from wptrack.synth import plaza_rules as R
from wptrack.synth import plaza_seeds as S
from wptrack.synth.actors import Car, Formation, Path, Person, PlazaActor, _pitch, _Prim, _Rgb, _yaw
from wptrack.synth.conditions import (
    CROWD_AT_ONCE,
    CYCLE_SPEEDS,
    CYCLIST_CLASS,
    CYCLISTS,
    GROUP_SIZES,
    SIDE_BY_SIDE,
    WALK_SPEEDS,
)
from wptrack.synth.plaza_background import FPS, FRAMES
from wptrack.synth.plaza_cast import _people

__all__ = ["CROWD_AT_ONCE", "CYCLISTS", "CYCLIST_CLASS", "Cyclist", "add_crowd", "add_cyclists", "scene_key"]

CROSSING_SHARE = 0.2
"""Share of crowd groups that walk in from the bottom of the image instead of along the street."""
PLAZA_BANDS = ((5.0, 7.3), (7.7, 9.8))
"""World y bands of the plaza where crowd groups walk towards +x and towards -x, metres."""
ROAD_BANDS = ((11.4, 14.4), (15.0, 18.4))
"""The same on the road, used when the scene has no car."""
FAR_BAND = (18.7, 19.05)
"""World y band along the parked cars (the far side of the road, 25 m from the camera, people 8-10 pixels wide):
singles only, metres."""
FAR_SIDEWALK = (24.2, 24.3)
"""World y band of the far sidewalk (behind the parked cars, before the facade; people there are half hidden by the
cars and cut by the top of the image), metres."""
FAR_SHARE = 0.2
"""Share of crowd singles on the far band or the far sidewalk (half each)."""
CYCLE_LANES = (11.35, 18.35)
"""World y of the cycle lanes along the road when the scene has cars (1 m from the cars' footprints), metres."""
TRIES = 60
"""Draws of one group or cyclist before it is given up."""
FULL = 6
"""Crowd groups given up before the street counts as full (a scene with cars holds fewer people: the road is
theirs)."""


def scene_key(actors: Sequence[PlazaActor]) -> int:
    """crc32 of the scene's own objects (ids, looks and paths; their reprs are exact), the extra objects' seed."""
    return zlib.crc32(repr([(a.oid, a.shape, a.track) for a in actors]).encode())


def _rng(name: str, actors: Sequence[PlazaActor]) -> np.random.Generator:
    return np.random.default_rng([zlib.crc32(name.encode()), scene_key(actors)])


# ----------------------------------------------------------------------------------------------------- cyclists


@dataclass(frozen=True)
class Cyclist:
    """A person riding a bicycle, one object: two wheels, a frame, a pedalling rider leaning forward.

    Attributes:
        rider: The rider's height (standing), build and clothes (a :class:`~wptrack.synth.actors.Person`).
        frame_rgb: Albedo of the bicycle's frame, linear RGB.
        wheelbase: Distance of the wheel hubs, metres.
    """

    rider: Person
    frame_rgb: _Rgb = (0.1, 0.1, 0.12)
    wheelbase: float = 1.05

    cls = CYCLIST_CLASS

    WHEEL_R = 0.34
    """Wheel radius, metres."""

    LEAN_DEG = 30.0
    """Forward lean of the rider's torso, degrees."""
    SADDLE = 0.5
    """Saddle height over the rider's (standing) height."""

    @property
    def seated_height(self) -> float:
        """Height of the top of the rider's head above the ground, metres (as :meth:`primitives` draws it)."""
        k = self.rider.height / 1.75
        reach = (0.31 + 0.22 + 0.08 + 0.115) * k  # saddle to the head's centre along the leaning torso
        return self.SADDLE * self.rider.height + 0.05 + reach * math.cos(math.radians(self.LEAN_DEG)) + 0.115 * k

    @property
    def dims(self) -> tuple[float, float, float]:
        """(length, width, height) for the ground truth: the bike's length, the handlebar's width, the head, m."""
        return self.wheelbase + 2 * self.WHEEL_R, 0.6, self.seated_height

    def box(self) -> tuple[np.ndarray, float]:
        """(3,) local half extents of a box holding rider and bike (centred at height/2), and its height, metres."""
        length, width, height = self.dims
        return np.array([0.5 * length + 0.1, 0.5 * width + 0.1, 0.5 * height]), height

    def stride(self, speed: np.ndarray) -> np.ndarray:
        """Distance per pedal turn (the phase of the legs), metres."""
        return np.full_like(np.asarray(speed, dtype=np.float64), 4.5)

    def primitives(self, x: float, y: float, heading: float, phase: float, speed: float) -> list[_Prim]:
        """Parts at ground position (x, y) metres (the bike's centre), heading radians, pedal phase radians."""
        p = self.rider
        k = p.height / 1.75
        g = p.girth
        yaw = _yaw(heading)
        base = np.array([x, y, 0.0])
        half_base = 0.5 * self.wheelbase
        r = self.WHEEL_R
        tyre = np.array([0.04, 0.04, 0.045])
        frame = np.asarray(self.frame_rgb, dtype=np.float64)
        shirt = np.asarray(p.shirt, dtype=np.float64)
        trousers = np.asarray(p.trousers, dtype=np.float64)

        def part(local: Sequence[float], rot: np.ndarray, half: Sequence[float], rgb: np.ndarray, top=None) -> _Prim:
            return _Prim("ellipsoid", base + yaw @ np.asarray(local, float), yaw @ rot, np.asarray(half, float), rgb,
                         top)  # fmt: skip

        eye = np.eye(3)
        parts = [
            part((half_base, 0.0, r), eye, (r, 0.025, r), tyre),
            part((-half_base, 0.0, r), eye, (r, 0.025, r), tyre),
            part((0.0, 0.0, 0.55), _pitch(0.25), (0.42, 0.03, 0.07), frame),  # top tube and down tube
            part((0.5 * half_base + 0.1, 0.0, 0.95), eye, (0.04, 0.3, 0.03), frame),  # handlebar
        ]
        saddle = np.array([-0.18, 0.0, self.SADDLE * p.height])
        crank = np.array([0.05, 0.0, 0.3])
        for side, sgn in ((1.0, 0.0), (-1.0, math.pi)):
            pedal = crank + 0.17 * np.array([math.cos(phase + sgn), 0.0, math.sin(phase + sgn)])
            hip = saddle + np.array([0.0, side * 0.1 * g, 0.0])
            d = pedal + np.array([0.0, side * 0.12, 0.0]) - hip
            length = float(np.linalg.norm(d))
            theta = math.atan2(-d[0], -d[2])  # the leg's tilt from hanging straight down
            parts.append(part(hip + 0.5 * d, _pitch(theta), (0.075 * g, 0.07 * g, 0.5 * length + 0.02), trousers))
        lean = _pitch(math.radians(self.LEAN_DEG))  # the torso's top towards +x (forward)
        torso = saddle + lean @ np.array([0.0, 0.0, 0.31 * k]) + np.array([0.0, 0.0, 0.05])
        parts.append(part(saddle + np.array([0.0, 0.0, 0.05]), eye, (0.13 * g, 0.16 * g, 0.12 * k), trousers))
        parts.append(part(torso, lean, (0.125 * g, 0.17 * g, 0.27 * k), shirt))
        shoulder_z = torso + lean @ np.array([0.0, 0.0, 0.22 * k])
        grip = np.array([0.5 * half_base + 0.1, 0.0, 0.97])
        for side in (1.0, -1.0):
            sh = shoulder_z + np.array([0.0, side * (0.17 * g + 0.03), 0.0])
            hand = grip + np.array([0.0, side * 0.25, 0.0])
            d = hand - sh
            length = float(np.linalg.norm(d))
            theta = math.atan2(-d[0], -d[2])
            parts.append(part(sh + 0.5 * d, _pitch(theta), (0.05 * g, 0.045 * g, 0.5 * length), shirt))
        hr = 0.115 * k
        head = shoulder_z + lean @ np.array([0.0, 0.0, 0.08 * k + hr])
        parts.append(part(head, eye, (hr, 0.9 * hr, hr), np.asarray(p.skin, float), np.asarray(p.hair, float)))
        return parts


# ----------------------------------------------------------------------------------------------------- drawing


def _has_cars(actors: Sequence[PlazaActor]) -> bool:
    return any(isinstance(a.shape, Car) for a in actors)


def _tracks(actors: Sequence[PlazaActor]):
    return [R._geo(a) for a in actors]


def _clear(new: Sequence[PlazaActor], accepted: list) -> tuple[bool, list]:
    """Whether the actors ``new`` keep the plaza's rules with each other and with ``accepted`` (tracks of the actors
    taken so far): clutter, speeds, gaps; returns their tracks too."""
    tracks = [R._geo(a) for a in new]
    for t in tracks:
        if isinstance(t.actor.shape, Cyclist):
            act = t.active
            sp = t.speed[act]
            if sp.size and (sp.min() < CYCLE_SPEEDS[0] - 0.3 or sp.max() > CYCLE_SPEEDS[1] + 0.3):
                return False, tracks
            if np.any(act) and R.clutter_distance(t.pos[act]).min() < R.CLUTTER_GAP + 0.3:
                return False, tracks
        elif R._geo_problems(t):
            return False, tracks
    for i, t in enumerate(tracks):
        for u in tracks[i + 1 :] + accepted:
            if _gap_problem(t, u):
                return False, tracks
    return True, tracks


def _gap_problem(a, b) -> bool:
    """Too close while both are on their paths (cyclists count as people with 0.5 m more room)."""
    if not (isinstance(a.actor.shape, Cyclist) or isinstance(b.actor.shape, Cyclist)):
        return bool(R._pair_problems(a, b))
    both = a.active & b.active
    if not np.any(both):
        return False
    if isinstance(a.actor.shape, Car) or isinstance(b.actor.shape, Car):
        car, other = (a, b) if isinstance(a.actor.shape, Car) else (b, a)
        gap = R._point_rect_distance(other.pos[both], car.pos[both], car.heading[both], car.actor.shape).min()
        return bool(gap < R.PERSON_CAR_GAP)
    return bool(np.linalg.norm(a.pos[both] - b.pos[both], axis=1).min() < R.PERSON_GAP + 0.5)


def _present_count(tracks: list) -> np.ndarray:
    """(FRAMES,) people of ``tracks`` seen by the camera per frame (the cheap stand-in of the ground truth)."""
    out = np.zeros(FRAMES)
    for t in tracks:
        out += t.active[:FRAMES] & R._in_view(t.pos[:FRAMES])
    return out


def _street_path(rng: np.random.Generator, band: tuple[float, float], towards: float, speed: float) -> Path:
    """A walk along the street (x) inside ``band`` from beyond one side of the image to beyond the other."""
    ys = rng.uniform(*band, size=3)
    xs = [float(R.view_half_width(y)) + float(rng.uniform(2.0, 3.5)) for y in (ys[0], ys[2])]
    x0, x1 = -towards * xs[0], towards * xs[1]
    mid = float(rng.uniform(-0.3, 0.3)) * (x1 - x0) / 2
    pts = ((x0, float(ys[0])), (mid, float(ys[1])), (x1, float(ys[2])))
    return Path(pts, tuple(float(v) for v in speed * rng.uniform(0.95, 1.05, size=3)), 0.0)


def _started(rng: np.random.Generator, path: Path, lead: float) -> Path:
    """``path`` started so that it is in view at a random time of the sequence (or already at its first frame)."""
    window = S._view_window(path, path.end)
    if window is None:
        return path
    t_in, t_out = window
    # in view at time u in [-(t_out - t_in) / 2, FRAMES / FPS]: some are in view at frame 0, others come later
    u = float(rng.uniform(-0.5 * (t_out - t_in), FRAMES / FPS - 1.0))
    return replace(path, start=u - t_in + lead)


def _group(rng: np.random.Generator, oid: int, looks: list[Person], scene_has_cars: bool) -> list[PlazaActor]:
    """One crowd group (1-3 people) on its path, not yet checked."""
    size = int(rng.choice([s for s, _ in GROUP_SIZES], p=[w for _, w in GROUP_SIZES]))
    speed = float(rng.uniform(*WALK_SPEEDS))
    if size == 1 and rng.uniform() < FAR_SHARE:  # along the parked cars, or behind them at the top of the image
        band = FAR_BAND if rng.uniform() < 0.5 else FAR_SIDEWALK
        path = _street_path(rng, band, float(rng.choice([-1.0, 1.0])), speed)
    elif rng.uniform() < CROSSING_SHARE:
        pts = S._route(rng, inner_y=(5.0, 9.8), edge_y=(5.0, 9.8))  # in at the bottom or a side, out at another
        path = Path(pts, tuple(float(v) for v in speed * rng.uniform(0.95, 1.05, size=len(pts))), 0.0)
    else:
        towards = float(rng.choice([-1.0, 1.0]))
        bands = PLAZA_BANDS if scene_has_cars or rng.uniform() < 0.5 else ROAD_BANDS
        band = bands[0] if towards > 0 else bands[1]
        path = _street_path(rng, band, towards, speed)
    path = _started(rng, path, 0.0)
    if size == 1:
        return [PlazaActor(oid, looks[0], path)]
    gap = float(rng.uniform(*SIDE_BY_SIDE))
    across = [(k - 0.5 * (size - 1)) * gap for k in range(size)]
    along = [0.0] * size if size == 2 or rng.uniform() < 0.5 else [-0.3, 0.2, -0.3]  # abreast or a shallow V
    formation = Formation(path, offsets=tuple(zip(along, across, strict=True)), wobble=0.05)
    return [PlazaActor(oid + k, looks[k], formation.member(k)) for k in range(size)]


def add_crowd(actors: Sequence[PlazaActor]) -> list[PlazaActor]:
    """``crowd``: the scene's objects and a crowd (module docstring)."""
    actors = list(actors)
    rng = _rng("crowd", actors)
    target = float(rng.uniform(*CROWD_AT_ONCE))
    accepted = _tracks(actors)
    own = len(accepted)
    oid = max((a.oid for a in actors), default=-1) + 1
    cars = _has_cars(actors)
    out = list(actors)
    camouflage_every = 7  # one person in seven wears ground-like colours, as in the plaza scenes
    full = 0
    while _present_count(accepted[own:]).mean() < target and full < FULL:
        looks = _people(3, seed=int(rng.integers(2**31)), camouflage=(0,) if oid % camouflage_every == 0 else ())
        for _ in range(TRIES):
            group = _group(rng, oid, looks, cars)
            ok, tracks = _clear(group, accepted)
            if ok:
                out += group
                accepted += tracks
                oid += len(group)
                break
        else:
            full += 1  # no room for this group in TRIES draws
    return out


def add_cyclists(actors: Sequence[PlazaActor]) -> list[PlazaActor]:
    """``cyclists``: the scene's objects and :data:`CYCLISTS` cyclists (module docstring)."""
    actors = list(actors)
    rng = _rng("cyclists", actors)
    count = int(rng.integers(CYCLISTS[0], CYCLISTS[1] + 1))
    accepted = _tracks(actors)
    oid = max((a.oid for a in actors), default=-1) + 1
    cars = _has_cars(actors)
    out = list(actors)
    frames = ((0.1, 0.1, 0.12), (0.55, 0.05, 0.05), (0.75, 0.75, 0.78), (0.1, 0.25, 0.55))
    for i in range(count):
        rider = _people(1, seed=int(rng.integers(2**31)))[0]
        shape = Cyclist(rider, frame_rgb=frames[int(rng.integers(len(frames)))])
        for _ in range(TRIES):
            speed = float(rng.uniform(*CYCLE_SPEEDS))
            towards = float(rng.choice([-1.0, 1.0]))
            if i == 0 and not cars:  # one across the plaza when there is no traffic (a pedestrian street)
                band = PLAZA_BANDS[0] if towards > 0 else PLAZA_BANDS[1]
            elif cars:
                lane = CYCLE_LANES[0] if towards > 0 else CYCLE_LANES[1]
                band = (lane - 0.05, lane + 0.05)
            else:
                band = ROAD_BANDS[0] if towards > 0 else ROAD_BANDS[1]
            ys = rng.uniform(*band, size=2)
            xs = [float(R.view_half_width(y)) + float(rng.uniform(3.0, 5.0)) for y in ys]
            path = Path(((-towards * xs[0], float(ys[0])), (towards * xs[1], float(ys[1]))), speed, 0.0, smooth_m=4.0)
            path = _started(rng, path, 0.0)
            ok, tracks = _clear([PlazaActor(oid, shape, path)], accepted)
            if ok:
                out.append(PlazaActor(oid, shape, path))
                accepted += tracks
                oid += 1
                break
    return out


P.register_actor_condition("cyclists", add_cyclists)  # first: the crowd is drawn around the bikes
P.register_actor_condition("crowd", add_crowd)
