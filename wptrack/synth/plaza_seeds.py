"""New sequences of the s3 plaza scenes for scene seeds other than 0.

Scene seed 0 of ``s3-people``, ``s3-cars``, ``s3-groups`` and ``s3-mixed`` is the fixed sequence written out in
:mod:`wptrack.synth.plaza` (all published numbers use it; a test pins its ground truth). Any other seed ``s`` draws a
new sequence of the same scene type (Juza et al., Table 2) on the same plaza, camera and clutter: only the moving
objects change. Every random number comes from one ``np.random.default_rng([zlib.crc32(name), s])`` (``name`` the
scene's registry name), so a seed always gives the same sequence and the scene types draw independently. (Draws
are accepted or rejected by thresholds on computed distances and projections; another NumPy/OpenCV build could in
principle flip a borderline decision and so give another sequence for that seed: compare ``groundtruth.csv``.)

- ``s3-people``: five people (one in clothes close to the paving/asphalt colours, as at seed 0), each on a smooth
  path from outside the image (left, right or bottom edge) through 1-3 random waypoints on the plaza or the road
  (there is no traffic in this scene) to outside the image at another edge; speeds 0.85-1.55 m/s (varied by +-8 %
  along the path, within that range); start times drawn so that 2.5-9 s of each person's time in view fall inside
  the sequence (so some are in view at frame 0, others enter and leave). At least three are in view at once, one
  pair occludes the other in the image for at least 5 frames (see :func:`_occluding_frames`), at least three enter
  at different frames and at least one leaves.
- ``s3-cars``: three cars (lengths 4.0-4.8 m, widths 1.7-1.9 m, heights 1.4-1.6 m; one paint from a dark palette,
  two from a light one, as at seed 0). Two pass each other in opposite lanes (near lane +x, far lane -x, +-0.2 m
  off the lane centre) at a random point (|x| <= 4.5 m) and time (2-9 s), 4.5-7.2 m/s (+-7 %), both in view then:
  the near one hides part of the far one. The third makes the seed-0 U-turn (far lane to near lane, or mirrored and
  reversed: near lane to far lane), shifted by up to +-3 m along the road, stretched by 0.85-1.15 along it, its turn
  narrowed to 80-86 % across the road (seed 0's brushes the kerb and the parking line) with its turn waypoints moved
  by up to 0.1 m, its speeds scaled by 0.92-1.3; the middle of its turn comes 3-9 s into the sequence.
- ``s3-groups``: a group of five or six people (two people of the scene camouflaged) in a random formation whose
  nearest neighbours are 0.6-1.2 m apart at every frame (the formation wobbles as at seed 0), walking 1.0-1.15 m/s
  along a route wide enough for it: at 65 % of the seeds from below the image up the free middle of the plaza,
  between the central kerb bollards and in a wide curve out along the road at a side (or that way reversed), else
  along the road from side to side; every member in view for at least 90 frames. A straggler follows the route
  1.5-4.5 s behind, offset by up to 0.4 m, at 0.95-1.12 times the group's speed.
- ``s3-mixed``: two cars (one dark, one light paint; each in a random lane, 3.5-7 m/s) and two people: one walks
  from the plaza between the kerb bollards across the road and through a gap between the parked cars towards the
  sidewalk, reaching the kerb 2-7.5 s into the sequence; one car passes the crossing point 0.3-2.5 s before that,
  the other 1-4 s after; the other person strolls across the plaza (left, right or bottom edge to another).

A draw is kept only when it passes :func:`layout_problems` (else the same generator draws again): every object in the
ground truth for at least 30 of the default 180 frames; no object appearing or vanishing inside the image during
those frames (its image box wholly outside the image when it starts or ends its path); speeds within the scene's
ranges (people 0.8-1.6 m/s, cars 2-8 m/s); people at least 0.45 m (centre) from the static clutter (lamp posts,
bollards, benches, planters, bin, tree, parked cars) and, over 360 frames, 0.7 m from each other (members of the
group: 0.6 m) and 1.0 m from a car's footprint; car footprints inside the road (10.8 m <= y <= 19.3 m: kerb to
parked cars) and 1.0 m apart. Seed 0 breaks three of these slightly: person 2 of ``s3-people`` starts its path with
its image box touching the image's bottom edge, the U-turn of ``s3-cars`` reaches 0.23 m over the kerb line and
0.27 m over the parking line, and the crossing person of ``s3-mixed`` passes 0.86 m from a car. A draw takes about
0.05-0.2 s of CPU.
"""

from __future__ import annotations

import functools
import math
import zlib
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError
from wptrack.synth import plaza as P
from wptrack.synth import plaza_cast
from wptrack.synth.actors import Car, Formation, Path, Person, PlazaActor, _Rgb
from wptrack.synth.plaza_background import FPS, FRAMES, ROAD_LANES, _static_objects, plaza_camera
from wptrack.synth.render import Cylinder

__all__ = [
    "CAR_GAP",
    "CHECK_FRAMES",
    "CLUTTER_GAP",
    "GROUP_SPACING",
    "MIN_PRESENT",
    "PERSON_CAR_GAP",
    "PERSON_GAP",
    "ROAD_Y",
    "clutter_distance",
    "draw_actors",
    "layout_problems",
    "scene_rng",
    "view_half_width",
]

CHECK_FRAMES = 2 * FRAMES
"""Frames over which objects must keep apart (24 s at 15 fps, twice the default length)."""
MIN_PRESENT = 30
"""Frames (of the default 180) every object is in the ground truth."""
PERSON_GAP = 0.7
"""Least distance between two people's ground centres, metres."""
PERSON_CAR_GAP = 1.0
"""Least distance from a person's ground centre to a car's footprint rectangle, metres."""
CAR_GAP = 1.0
"""Least gap between two cars' footprint rectangles, metres."""
CLUTTER_GAP = 0.45
"""Least distance from a person's ground centre to the footprint of the static clutter, metres."""
ROAD_Y = (10.8, 19.3)
"""World y range of the road a car's footprint stays in (kerb to the parked cars), metres."""
GROUP_SPACING = (0.6, 1.2)
"""Range of each group member's distance to its nearest fellow member, metres (paper Table 2)."""
HUMAN_SPEEDS = (0.8, 1.6)
"""Speed range of people, m/s (module docstring of :mod:`wptrack.synth.plaza`)."""
CAR_SPEEDS = (2.0, 8.0)
"""Speed range of cars, m/s."""
MAX_DRAWS = 400
"""Draws of a whole scene before giving up (never reached for seeds 0-50, see the tests)."""

_DARK_PAINTS: tuple[_Rgb, ...] = ((0.24, 0.24, 0.26), (0.1, 0.16, 0.4), (0.3, 0.08, 0.08), (0.12, 0.22, 0.14))
_LIGHT_PAINTS: tuple[_Rgb, ...] = (
    (0.8, 0.8, 0.78),
    (0.32, 0.4, 0.55),
    (0.55, 0.56, 0.58),
    (0.62, 0.12, 0.1),
    (0.75, 0.62, 0.25),
    (0.86, 0.86, 0.9),
    (0.3, 0.5, 0.35),
)
DARK_PAINT_MAX = 0.45
"""A car paint is dark when its brightest channel is below this (one car per scene, as at seed 0)."""

_KERB_GAPS = ((-5.4, -3.6), (-2.4, 2.4), (3.6, 5.2))
"""x ranges where a person walks between the kerb bollards (x = +-3, +-6, +-9) inside the view, metres."""
_PARKING_GAPS = ((-6.3, -4.0), (-1.1, 3.8), (6.7, 9.0))
"""x ranges between the parked cars (x = -10.35, -7.75, -2.55, 5.25, 10.45, 1.8 m wide), metres."""


# ----------------------------------------------------------------------------------------------------- geometry


def scene_rng(name: str, seed: int) -> np.random.Generator:
    """The generator of scene ``name`` at scene seed ``seed``: ``default_rng([crc32(name), seed])``."""
    return np.random.default_rng([zlib.crc32(name.encode()), int(seed)])


@functools.cache
def _clutter() -> tuple[np.ndarray, np.ndarray]:
    """Footprints of the static objects a body can touch (below 2 m): discs (K, 3) x, y, r; rectangles (M, 4)."""
    discs, rects = [], []
    for obj in _static_objects():
        if obj.label == 1:  # the ground
            continue
        if isinstance(obj, Cylinder):
            if obj.z0 < 2.0:
                discs.append((obj.center[0], obj.center[1], obj.radius))
        elif obj.lo[2] < 2.0:
            rects.append((obj.lo[0], obj.lo[1], obj.hi[0], obj.hi[1]))
    return np.asarray(discs, dtype=np.float64), np.asarray(rects, dtype=np.float64)


def clutter_distance(points: np.ndarray) -> np.ndarray:
    """Distance from ground points (N, 2) to the nearest footprint of the static clutter, metres (N,)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    discs, rects = _clutter()
    dd = np.linalg.norm(pts[:, None, :] - discs[None, :, :2], axis=2) - discs[None, :, 2]
    dx = np.maximum(np.maximum(rects[None, :, 0] - pts[:, 0, None], pts[:, 0, None] - rects[None, :, 2]), 0.0)
    dy = np.maximum(np.maximum(rects[None, :, 1] - pts[:, 1, None], pts[:, 1, None] - rects[None, :, 3]), 0.0)
    return np.minimum(dd.min(axis=1), np.hypot(dx, dy).min(axis=1))


@functools.cache
def _view_table() -> tuple[np.ndarray, np.ndarray]:
    cam = plaza_camera()
    ys = np.arange(4.0, 28.01, 0.25)
    xs = np.linspace(-20.0, 20.0, 2001)
    half = np.zeros(len(ys))
    for i, y in enumerate(ys):
        uv, depth = cam.project(np.stack([xs, np.full_like(xs, y), np.zeros_like(xs)], axis=1))
        ok = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
        half[i] = np.abs(xs[ok]).max() if np.any(ok) else 0.0
    return ys, half


def view_half_width(y: float | np.ndarray) -> np.ndarray:
    """Half width of the ground strip the camera sees at world ``y``, metres (about 2.8 + 0.45 y beyond y = 4.5)."""
    ys, half = _view_table()
    return np.interp(y, ys, half)


def _rects(pos: np.ndarray, heading: np.ndarray, car: Car) -> np.ndarray:
    """(N, 4, 2) corners of a car's footprint at (N, 2) positions and (N,) headings."""
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    lx = np.array([1.0, 1.0, -1.0, -1.0]) * 0.5 * car.length
    ly = np.array([1.0, -1.0, -1.0, 1.0]) * 0.5 * car.width
    return np.stack([pos[:, 0, None] + c * lx - s * ly, pos[:, 1, None] + s * lx + c * ly], axis=2)


def _point_rect_distance(p: np.ndarray, pos: np.ndarray, heading: np.ndarray, car: Car) -> np.ndarray:
    """(N,) distance from points (N, 2) to a car's footprint (0 inside), metres."""
    d = p - pos
    c, s = np.cos(heading), np.sin(heading)
    lx = np.abs(c * d[:, 0] + s * d[:, 1]) - 0.5 * car.length
    ly = np.abs(-s * d[:, 0] + c * d[:, 1]) - 0.5 * car.width
    return np.hypot(np.maximum(lx, 0.0), np.maximum(ly, 0.0))


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points p (..., 2) to segments a-b (..., 2)."""
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def _rect_gap(ra: np.ndarray, rb: np.ndarray) -> np.ndarray:
    """(N,) gap between two convex quadrilaterals (N, 4, 2) per frame, 0 where they overlap, metres."""
    gaps = []
    for p, q in ((ra, rb), (rb, ra)):
        a, b = q, np.roll(q, -1, axis=1)
        gaps.append(_segment_distance(p[:, :, None, :], a[:, None, :, :], b[:, None, :, :]).min(axis=(1, 2)))
    gap = np.minimum(gaps[0], gaps[1])
    separated = np.zeros(len(ra), dtype=bool)
    for r in (ra, rb):  # separating axis test over the edge normals of both rectangles
        for k in range(2):
            e = r[:, k + 1] - r[:, k]
            axis = np.stack([-e[:, 1], e[:, 0]], axis=1)
            pa, pb = np.einsum("nkd,nd->nk", ra, axis), np.einsum("nkd,nd->nk", rb, axis)
            separated |= (pa.max(axis=1) < pb.min(axis=1)) | (pb.max(axis=1) < pa.min(axis=1))
    return np.where(separated, gap, 0.0)


# ----------------------------------------------------------------------------------------------------- checks


@dataclass
class _Track:
    """One actor's motion over the check horizon: from :meth:`PlazaScene.states` (``full``) or from its path alone."""

    actor: PlazaActor
    pos: np.ndarray  # (H, 2)
    active: np.ndarray  # (H,)
    heading: np.ndarray  # (H,)
    speed: np.ndarray  # (H,)
    present: np.ndarray | None = None  # (H,), full tracks only


def _track(actor: PlazaActor, horizon: int = CHECK_FRAMES) -> _Track:
    """The full track: the scene's own states (ground truth presence included)."""
    st = P.PlazaScene([actor]).states(horizon)
    return _Track(actor, st.pos[0, :horizon], st.active[0, :horizon], st.heading[0, :horizon],
                  st.speed[0, :horizon], st.present[0, :horizon])  # fmt: skip


def _geo(actor: PlazaActor, horizon: int = CHECK_FRAMES) -> _Track:
    """A cheap track from the path alone (no projection, no presence), for rejecting draws early."""
    times = np.arange(horizon) / FPS
    pos, act = actor.track.positions(times)
    ahead, _ = actor.track.positions(times + 0.02)
    behind, _ = actor.track.positions(times - 0.02)
    vel = (ahead - behind) / 0.04
    return _Track(actor, pos, act, np.arctan2(vel[:, 1], vel[:, 0]), np.linalg.norm(vel, axis=1))


def _in_view(pos: np.ndarray) -> np.ndarray:
    """(N,) whether ground points (N, 2) are seen by the camera (a cheap stand-in for the ground truth's presence)."""
    return (pos[:, 1] >= 4.6) & (np.abs(pos[:, 0]) <= view_half_width(pos[:, 1]))


def _solo_problems(t: _Track, frames: int = FRAMES) -> list[str]:
    """What is wrong with one object on its own (see the module docstring)."""
    out = []
    oid, shape = t.actor.oid, t.actor.shape
    if t.present is None:
        raise ValueError("_solo_problems needs a full track")
    if int(t.present[:frames].sum()) < MIN_PRESENT:
        out.append(f"object {oid}: in the ground truth on {int(t.present[:frames].sum())} < {MIN_PRESENT} frames")
    toggles = np.flatnonzero(t.active[1:frames] != t.active[: frames - 1]) + 1
    if len(toggles):
        at = np.where(t.active[toggles], toggles, toggles - 1)  # the frame where it is drawn
        ok, _, inside = P.image_box_cover(plaza_camera(), shape, t.pos[at], t.heading[at])
        if np.any(ok & (inside > 0)):
            out.append(f"object {oid}: appears or vanishes inside the image")
    return out + _geo_problems(t)


def _geo_problems(t: _Track) -> list[str]:
    """The rules of one object that need no projection: speeds, clutter (people), road (cars)."""
    out = []
    oid, shape, act = t.actor.oid, t.actor.shape, t.active
    lo, hi = HUMAN_SPEEDS if isinstance(shape, Person) else CAR_SPEEDS
    sp = t.speed[act]
    if sp.size and (sp.min() < lo or sp.max() > hi):
        out.append(f"object {oid}: speed {sp.min():.2f}-{sp.max():.2f} m/s outside {lo}-{hi}")
    if isinstance(shape, Person):
        if np.any(act) and clutter_distance(t.pos[act]).min() < CLUTTER_GAP:
            out.append(f"object {oid}: closer than {CLUTTER_GAP} m to the static clutter")
    elif np.any(act):
        ys = _rects(t.pos[act], t.heading[act], shape)[..., 1]
        if ys.min() < ROAD_Y[0] or ys.max() > ROAD_Y[1]:
            out.append(f"object {oid}: footprint leaves the road (y {ys.min():.2f}-{ys.max():.2f} m)")
    return out


def _pair_problems(a: _Track, b: _Track) -> list[str]:
    """What is wrong with two objects together: too close while both are on their paths."""
    both = a.active & b.active
    if not np.any(both):
        return []
    sa, sb = a.actor.shape, b.actor.shape
    if isinstance(sa, Person) and isinstance(sb, Person):
        together = getattr(a.actor.track, "formation", 0) is getattr(b.actor.track, "formation", 1)
        need = GROUP_SPACING[0] if together else PERSON_GAP  # members of one group: the paper's spacing
        gap = np.linalg.norm(a.pos[both] - b.pos[both], axis=1).min()
    elif isinstance(sa, Car) and isinstance(sb, Car):
        ra, rb = _rects(a.pos[both], a.heading[both], sa), _rects(b.pos[both], b.heading[both], sb)
        gap, need = _rect_gap(ra, rb).min(), CAR_GAP
    else:
        person, car = (a, b) if isinstance(sa, Person) else (b, a)
        gap = _point_rect_distance(person.pos[both], car.pos[both], car.heading[both], car.actor.shape).min()
        need = PERSON_CAR_GAP
    if gap < need:
        return [f"objects {a.actor.oid} and {b.actor.oid}: {gap:.2f} m < {need} m apart"]
    return []


def layout_problems(actors: list[PlazaActor], frames: int = FRAMES, horizon: int = CHECK_FRAMES) -> list[str]:
    """The rules of the module docstring that ``actors`` break (empty: none).

    Args:
        actors: The moving objects of a scene.
        frames: Frames in which objects must be in the ground truth long enough and not pop up (default 180).
        horizon: Frames over which objects must keep apart (default 360).

    Returns:
        One line per broken rule.
    """
    tracks = [_track(a, horizon) for a in actors]
    out = [p for t in tracks for p in _solo_problems(t, frames)]
    for i, a in enumerate(tracks):
        for b in tracks[i + 1 :]:
            out += _pair_problems(a, b)
    return out


def _occluding_frames(a: _Track, b: _Track, frames: int = FRAMES) -> int:
    """Frames where one person hides part of the other in the image (both in the ground truth).

    Seen from the camera above the origin, the nearer person (ground distance d1) covers the farther one where their
    bearings differ by less than their bodies' width (0.5 m at d1) and the farther one stands closer than 1.3 d1
    (the head of a 1.75 m person at d1 is seen in front of the ground at about 1.3 d1 from a 7.5 m high camera).
    """
    assert a.present is not None and b.present is not None
    both = a.present[:frames] & b.present[:frames]
    pa, pb = a.pos[:frames][both], b.pos[:frames][both]
    da, db = np.linalg.norm(pa, axis=1), np.linalg.norm(pb, axis=1)
    near = np.minimum(da, db)
    bearing = np.abs(np.angle(np.exp(1j * (np.arctan2(pa[:, 0], pa[:, 1]) - np.arctan2(pb[:, 0], pb[:, 1])))))
    return int(np.sum((near * bearing < 0.5) & (np.maximum(da, db) < 1.3 * near)))


# ----------------------------------------------------------------------------------------------------- drawing


def _looks(rng: np.random.Generator, count: int, camouflaged: int) -> list[Person]:
    """``count`` people (:func:`plaza_cast._people`), ``camouflaged`` of them in ground-like clothes."""
    which = tuple(sorted(int(i) for i in rng.choice(count, size=camouflaged, replace=False)))
    return plaza_cast._people(count, seed=int(rng.integers(2**31)), camouflage=which)


def _paint(rng: np.random.Generator, dark: bool, taken: list[_Rgb]) -> _Rgb:
    """A paint from the dark or the light palette (not one in ``taken``), its brightness varied by +-6 %."""
    palette = [c for c in (_DARK_PAINTS if dark else _LIGHT_PAINTS) if c not in taken]
    base = palette[int(rng.integers(len(palette)))]
    taken.append(base)
    gain = float(rng.uniform(0.94, 1.06))
    return base[0] * gain, base[1] * gain, base[2] * gain


def _cars(rng: np.random.Generator, count: int) -> list[Car]:
    """``count`` cars of random size, one in a dark paint (at a random position), the others light."""
    dark_at = int(rng.integers(count))
    taken: list[_Rgb] = []
    return [
        Car(
            length=float(rng.uniform(4.0, 4.8)),
            width=float(rng.uniform(1.7, 1.9)),
            height=float(rng.uniform(1.4, 1.6)),
            body=_paint(rng, i == dark_at, taken),
        )
        for i in range(count)
    ]


def _edge_point(rng: np.random.Generator, side: str, y_range: tuple[float, float]) -> tuple[float, float]:
    """A point outside the image: below its bottom edge, or beyond its left/right edge at a y in ``y_range``."""
    if side == "bottom":
        return float(rng.uniform(-4.0, 4.0)), float(rng.uniform(1.5, 2.5))
    y = float(rng.uniform(*y_range))
    x = float(view_half_width(y)) + float(rng.uniform(2.0, 3.0))
    return (-x if side == "left" else x), y


def _inner_point(rng: np.random.Generator, y_range: tuple[float, float], margin: float = 1.0) -> tuple[float, float]:
    y = float(rng.uniform(*y_range))
    half = max(float(view_half_width(y)) - margin, 0.5)
    return float(rng.uniform(-half, half)), y


def _segments_clear(points: Any, gap: float = CLUTTER_GAP + 0.25) -> bool:
    """Whether the straight segments between waypoints keep ``gap`` from the clutter (a cheap pre-test)."""
    p = np.asarray(points, dtype=np.float64)
    t = np.linspace(0.0, 1.0, 25)[None, :, None]
    samples = (p[:-1, None, :] * (1.0 - t) + p[1:, None, :] * t).reshape(-1, 2)
    return bool(clutter_distance(samples).min() >= gap)


def _smooth_enough(points: list[tuple[float, float]], min_step: float = 2.0, max_turn_deg: float = 100.0) -> bool:
    """Waypoints at least ``min_step`` apart, turning by at most ``max_turn_deg`` at each."""
    p = np.asarray(points)
    d = np.diff(p, axis=0)
    n = np.linalg.norm(d, axis=1)
    if np.any(n < min_step):
        return False
    cos = np.sum(d[1:] * d[:-1], axis=1) / (n[1:] * n[:-1])
    return bool(np.all(cos >= math.cos(math.radians(max_turn_deg))))


def _route(
    rng: np.random.Generator,
    inner_y: tuple[float, float],
    edge_y: tuple[float, float],
    inner: tuple[int, int] = (1, 3),
    max_turn_deg: float = 100.0,
) -> tuple[tuple[float, float], ...]:
    """Waypoints from outside the image (left, right or bottom edge) through 1-3 random inner points (ordered along
    the way) to outside the image at another edge."""
    sides = ("left", "right", "bottom")
    while True:
        entry, exit_ = (sides[int(i)] for i in rng.permutation(3)[:2])  # out at another edge than in
        k = int(rng.integers(inner[0], inner[1] + 1))
        a, b = _edge_point(rng, entry, edge_y), _edge_point(rng, exit_, edge_y)
        axis = np.subtract(b, a)
        inner_pts = sorted((_inner_point(rng, inner_y) for _ in range(k)), key=lambda q: float(np.dot(q, axis)))
        pts = [a, *inner_pts, b]
        if _smooth_enough(pts, max_turn_deg=max_turn_deg) and _segments_clear(pts):
            return tuple(pts)


def _speeds(
    rng: np.random.Generator, base: float, count: int, spread: float = 0.08, limits: tuple[float, float] = (0.0, 99.0)
) -> tuple[float, ...]:
    """Speeds at ``count`` waypoints: ``base`` varied by +-``spread`` (a fraction), clipped to ``limits``, m/s."""
    return tuple(float(np.clip(base * f, *limits)) for f in rng.uniform(1.0 - spread, 1.0 + spread, size=count))


def _clear_of_clutter(tracks: list[Any], start: float, end: float) -> bool:
    """Whether paths or formation members keep CLUTTER_GAP (+5 cm) from the clutter, sampled every 0.1 s."""
    times = np.arange(start, end, 0.1)
    for track in tracks:
        pos, act = track.positions(times)
        if np.any(act) and clutter_distance(pos[act]).min() < CLUTTER_GAP + 0.05:
            return False
    return True


def _view_window(track: Any, end: float) -> tuple[float, float] | None:
    """First and last time (s) in [0, end] that ``track`` (starting at 0) is on its path and in view, or None."""
    times = np.arange(0.0, end, 1.0 / FPS)
    pos, act = track.positions(times)
    f = np.flatnonzero(act & _in_view(pos))
    return None if len(f) == 0 else (float(times[f[0]]), float(times[f[-1]]))


def _start_for_presence(rng: np.random.Generator, window: tuple[float, float], need_s: float) -> float:
    """A start time that puts at least ``need_s`` of the presence window inside the default length."""
    t_in, t_out = window
    lo, hi = need_s - t_out, FRAMES / FPS - need_s - t_in
    return float(rng.uniform(lo, hi)) if hi > lo else float(-t_in)


def _time_near(path: Path, point: tuple[float, float]) -> float:
    """Time (s) at which ``path`` passes closest to ``point``."""
    times = np.arange(path.start, path.end, 0.02)
    pos, _ = path.positions(times)
    return float(times[np.argmin(np.linalg.norm(pos - np.asarray(point), axis=1))])


def _time_at_y(path: Path, y: float) -> float:
    """First time (s) at which ``path`` reaches world ``y``."""
    times = np.arange(path.start, path.end, 0.02)
    pos, _ = path.positions(times)
    return float(times[np.argmax(pos[:, 1] >= y)])


def _walker(
    rng: np.random.Generator, oid: int, look: Person, path: Path, need_s: float, others: list[_Track]
) -> _Track | None:
    """A person on ``path`` (starting at 0), started so that about ``need_s`` of their presence is in view; None when
    they come too close to ``others`` or break a rule of their own."""
    window = _view_window(path, path.end)
    if window is None:
        return None
    actor = PlazaActor(oid, look, replace(path, start=_start_for_presence(rng, window, need_s)))
    geo = _geo(actor)
    if any(_pair_problems(geo, u) for u in others):
        return None
    full = _track(actor)
    return None if _solo_problems(full) else full


def _people(rng: np.random.Generator) -> list[PlazaActor]:
    looks = _looks(rng, 5, 1)
    for _ in range(MAX_DRAWS):
        tracks: list[_Track] = []
        for i in range(5):
            for _ in range(40):
                pts = _route(rng, inner_y=(5.0, 17.5), edge_y=(5.0, 16.0))
                path = Path(pts, _speeds(rng, float(rng.uniform(0.85, 1.55)), len(pts), limits=(0.85, 1.55)), 0.0)
                if not _clear_of_clutter([path], 0.0, path.end):
                    continue
                t = _walker(rng, i, looks[i], path, float(rng.uniform(2.5, 9)), tracks)
                if t is not None:
                    tracks.append(t)
                    break
            else:
                break
        if len(tracks) < 5:
            continue
        present = np.array([t.present[:FRAMES] for t in tracks])
        first = [int(np.flatnonzero(p)[0]) for p in present]
        last = [int(np.flatnonzero(p)[-1]) for p in present]
        occluding = max(_occluding_frames(a, b) for i, a in enumerate(tracks) for b in tracks[i + 1 :])
        if present.sum(axis=0).max() >= 3 and len(set(first)) >= 3 and min(last) < FRAMES - 1 and occluding >= 5:
            return [t.actor for t in tracks]
    raise RuntimeError("s3-people: no valid draw")


def _lane_path(rng: np.random.Generator, lane: int, x_pass: float, t_pass: float, speed: float) -> Path:
    """A straight drive along lane 0 (near, +x) or 1 (far, -x), at ``x_pass`` at time ``t_pass``."""
    y = ROAD_LANES[lane] + float(rng.uniform(-0.2, 0.2))
    xs = (-18.0, x_pass, 18.0) if lane == 0 else (18.0, x_pass, -18.0)
    path = Path(tuple((x, y) for x in xs), _speeds(rng, speed, 3, 0.07), 0.0)
    return replace(path, start=t_pass - _time_near(path, (x_pass, y)))


def _u_turn(rng: np.random.Generator) -> tuple[Path, tuple[float, float]]:
    """The seed-0 U-turn, shifted, stretched, jittered (or mirrored and reversed); and its middle waypoint."""
    pts = np.array(plaza_cast.U_TURN, dtype=np.float64)
    speeds = np.array(plaza_cast.U_TURN_SPEEDS) * rng.uniform(0.92, 1.3)
    shift, stretch = rng.uniform(-3.0, 3.0), rng.uniform(0.85, 1.15)
    pts[1:-1, 0] = shift + stretch * pts[1:-1, 0]
    # seed 0's turn (centre y 11.9-18.0) brushes the kerb and the parking line: narrowed here to fit ROAD_Y
    mid = 0.5 * (ROAD_Y[0] + ROAD_Y[1])
    pts[2:-2, 1] = mid + rng.uniform(0.8, 0.86) * (pts[2:-2, 1] - mid) + rng.uniform(-0.1, 0.1, size=len(pts) - 4)
    pts[0, 0], pts[-1, 0] = 18.0 + shift, 18.0 + shift
    if rng.random() < 0.5:  # near lane +x, turn left up to the far lane, back along -x
        pts[:, 0] = -pts[:, 0]
        pts, speeds = pts[::-1], speeds[::-1]
    apex = (float(pts[len(pts) // 2, 0]), float(pts[len(pts) // 2, 1]))
    path = Path(tuple(map(tuple, pts)), tuple(float(v) for v in speeds), 0.0, smooth_m=4.0)
    return replace(path, start=float(rng.uniform(3.0, 9.0)) - _time_near(path, apex)), apex


def _all_pairs_ok(tracks: list[_Track]) -> bool:
    return not any(_pair_problems(a, b) for i, a in enumerate(tracks) for b in tracks[i + 1 :])


def _cars_scene(rng: np.random.Generator) -> list[PlazaActor]:
    for _ in range(MAX_DRAWS):
        cars = _cars(rng, 3)
        x_meet, t_meet = float(rng.uniform(-4.5, 4.5)), float(rng.uniform(2.0, 9.0))
        lanes = [0, 1] if rng.random() < 0.5 else [1, 0]
        paths = [_lane_path(rng, lane, x_meet, t_meet, float(rng.uniform(4.5, 7.2))) for lane in lanes]
        u_turn, _ = _u_turn(rng)
        actors = [PlazaActor(k, car, path) for k, (car, path) in enumerate(zip(cars, [*paths, u_turn], strict=True))]
        geos = [_geo(a) for a in actors]
        if any(_geo_problems(t) for t in geos) or not _all_pairs_ok(geos):
            continue
        tracks = [_track(a) for a in actors]
        f = int(round(t_meet * FPS))
        if not all(t.present is not None and t.present[f] for t in tracks[:2]):  # the passing is in view
            continue
        if any(_solo_problems(t) for t in tracks):
            continue
        return actors
    raise RuntimeError("s3-cars: no valid draw")


@functools.cache
def _straight_line() -> Path:
    """A straight path along +x at 1 m/s over the check horizon: a formation on it keeps its (along, across) frame."""
    return Path(((-5.0, 0.0), (CHECK_FRAMES / FPS + 5.0, 0.0)), 1.0, -5.0)


def _group_offsets(rng: np.random.Generator, count: int) -> tuple[tuple[float, float], ...]:
    """(along, across) offsets of ``count`` members whose nearest neighbours stay 0.6-1.2 m apart as they wobble."""
    times = np.arange(0.0, CHECK_FRAMES / FPS, 0.2)  # the wobble is slow (periods of 14 and 19 s)
    while True:
        pts = [np.zeros(2)]
        for _ in range(200):
            if len(pts) == count:
                break
            base = pts[int(rng.integers(len(pts)))]
            ang, r = rng.uniform(0.0, 2 * math.pi), rng.uniform(0.78, 1.02)
            p = base + r * np.array([math.cos(ang), math.sin(ang)])
            if min(np.linalg.norm(p - q) for q in pts) >= 0.78:
                pts.append(p)
        if len(pts) < count:
            continue
        arr = np.array(pts) - np.mean(pts, axis=0)
        if np.linalg.norm(arr, axis=1).max() > 1.6:
            continue
        offsets = tuple((float(a), float(b)) for a, b in arr)
        line = Formation(_straight_line(), offsets)
        at = np.array([line.member(k).positions(times)[0] for k in range(count)])  # (count, T, 2), rigid frame
        d = np.linalg.norm(at[:, None] - at[None, :], axis=-1) + 99.0 * np.eye(count)[:, :, None]
        nearest = d.min(axis=1)
        if nearest.min() >= GROUP_SPACING[0] + 0.03 and nearest.max() <= GROUP_SPACING[1] - 0.03:
            return offsets


def _group_route(rng: np.random.Generator, across: bool) -> tuple[tuple[float, float], ...]:
    """A route wide enough for a group. ``across``: from below the image up the free middle of the plaza, between
    the central kerb bollards (x = +-3 m) and in a wide curve out along the road at a side (or that way reversed);
    else along the road from one side to the other."""
    while True:
        side = 1.0 if rng.random() < 0.5 else -1.0
        if across:
            y_exit = float(rng.uniform(16.2, 17.2))
            pts = [
                (float(rng.uniform(-2.5, 0.5)), float(rng.uniform(1.5, 2.5))),
                (float(rng.uniform(-1.4, 0.0)), float(rng.uniform(5.5, 7.5))),
                (float(rng.uniform(-0.6, 0.4)), 10.55),
                (side * float(rng.uniform(1.5, 2.5)), float(rng.uniform(13.0, 13.6))),
                (side * float(rng.uniform(5.0, 6.0)), float(rng.uniform(15.3, 15.9))),
                (side * (float(view_half_width(y_exit)) + float(rng.uniform(2.5, 3.5))), y_exit),
            ]
            if rng.random() < 0.4:
                pts = pts[::-1]
        else:
            k = int(rng.integers(1, 3))
            pts = [_edge_point(rng, "left", (12.5, 17.0))]
            pts += sorted((_inner_point(rng, (12.5, 17.5), margin=2.0) for _ in range(k)), key=lambda p: p[0])
            pts.append(_edge_point(rng, "right", (12.5, 17.0)))
            if side < 0:
                pts = pts[::-1]
        if _smooth_enough(pts, max_turn_deg=60.0):
            return tuple(pts)


def _groups(rng: np.random.Generator) -> list[PlazaActor]:
    across = bool(rng.random() < 0.65)  # drawn once: the rejections below must not favour the easier kind
    for _ in range(MAX_DRAWS):
        count = int(rng.integers(5, 7))
        looks = _looks(rng, count + 1, 2)
        offsets = _group_offsets(rng, count)
        route = _group_route(rng, across)
        speed = float(rng.uniform(1.0, 1.15))
        centre = Path(route, _speeds(rng, speed, len(route), 0.05), 0.0)
        if not _clear_of_clutter([Formation(centre, offsets).member(k) for k in range(count)], 0.0, centre.end):
            continue
        window = _view_window(centre, centre.end)
        if window is None:
            continue
        centre = replace(centre, start=_start_for_presence(rng, window, float(rng.uniform(8.0, 11.5))))
        group = Formation(centre, offsets)
        members = [PlazaActor(k, looks[k], group.member(k)) for k in range(count)]
        dx, dy = rng.uniform(-0.4, 0.4, size=2)
        trail = Path(
            tuple((x + float(dx), y + float(dy)) for x, y in route),
            _speeds(rng, speed * float(rng.uniform(0.95, 1.12)), len(route), 0.05),
            centre.start + float(rng.uniform(1.5, 4.5)),
        )
        actors = [*members, PlazaActor(count, looks[count], trail)]
        geos = [_geo(a) for a in actors]
        if any(_geo_problems(t) for t in geos) or not _all_pairs_ok(geos):
            continue
        tracks = [_track(a) for a in actors]
        if any(t.present is None or int(t.present[:FRAMES].sum()) < 90 for t in tracks[:count]):
            continue
        if any(_solo_problems(t) for t in tracks):
            continue
        return actors
    raise RuntimeError("s3-groups: no valid draw")


def _crossing_route(rng: np.random.Generator) -> tuple[tuple[float, float], ...]:
    """From the plaza between the kerb bollards, across the road, between the parked cars to the sidewalk."""
    widths = np.array([b - a for a, b in _KERB_GAPS])
    a, b = _KERB_GAPS[int(rng.choice(len(widths), p=widths / widths.sum()))]
    x_kerb = float(rng.uniform(a, b))
    gaps = [(max(a, x_kerb - 4.0), min(b, x_kerb + 4.0)) for a, b in _PARKING_GAPS if a < x_kerb + 4 and b > x_kerb - 4]
    a, b = gaps[int(rng.integers(len(gaps)))]
    x_park = float(rng.uniform(a, b))
    x_mid = 0.5 * (x_kerb + x_park) + float(rng.uniform(-0.3, 0.3))
    start = (x_kerb + float(rng.uniform(-3.0, 3.0)), float(rng.uniform(1.5, 2.5)))
    plaza = (x_kerb + float(rng.uniform(-1.2, 1.2)), float(rng.uniform(6.0, 8.0)))
    return (
        start,
        plaza,
        (x_kerb, 10.55),
        (x_mid, 15.0),
        (x_park, 19.6),
        (x_park, 22.0),
        (x_park + float(rng.uniform(-0.8, 0.8)), 24.0),
    )


def _mixed(rng: np.random.Generator) -> list[PlazaActor]:
    for _ in range(MAX_DRAWS):
        cars = _cars(rng, 2)
        looks = _looks(rng, 2, 1)
        route = _crossing_route(rng)
        path = Path(route, _speeds(rng, float(rng.uniform(0.95, 1.35)), len(route), limits=(0.85, 1.55)), 0.0)
        if not _clear_of_clutter([path], 0.0, path.end):
            continue
        t_kerb = float(rng.uniform(2.0, 7.5))
        path = replace(path, start=t_kerb - _time_at_y(path, 10.8))
        crosser = _geo(PlazaActor(2, looks[0], path))
        if _geo_problems(crosser):
            continue
        x_cross = route[3][0]
        passes = (t_kerb - float(rng.uniform(0.3, 2.5)), t_kerb + float(rng.uniform(1.0, 4.0)))
        if passes[0] < 0.3 or passes[1] > FRAMES / FPS - 0.5:
            continue
        order = [0, 1] if rng.random() < 0.5 else [1, 0]
        lanes = [int(v) for v in rng.integers(2, size=2)]
        actors = [
            PlazaActor(k, cars[k], _lane_path(rng, lanes[k], x_cross, passes[order[k]], float(rng.uniform(3.5, 7.0))))
            for k in range(2)
        ]
        geos = [_geo(a) for a in actors]
        if any(_geo_problems(t) for t in geos) or not _all_pairs_ok([*geos, crosser]):
            continue
        tracks = [_track(a) for a in [*actors, crosser.actor]]
        if any(_solo_problems(t) for t in tracks):
            continue
        for _ in range(40):
            pts = _route(rng, inner_y=(5.0, 9.6), edge_y=(5.0, 9.6), inner=(1, 2))
            path = Path(pts, _speeds(rng, float(rng.uniform(0.85, 1.4)), len(pts), limits=(0.85, 1.55)), 0.0)
            if not _clear_of_clutter([path], 0.0, path.end):
                continue
            stroller = _walker(rng, 3, looks[1], path, float(rng.uniform(3.0, 9.0)), tracks)
            if stroller is not None:
                return [*actors, crosser.actor, stroller.actor]
    raise RuntimeError("s3-mixed: no valid draw")


_DRAW = {"s3-people": _people, "s3-cars": _cars_scene, "s3-groups": _groups, "s3-mixed": _mixed}


def draw_actors(name: str, seed: int) -> list[PlazaActor]:
    """The moving objects of scene ``name`` at scene seed ``seed`` >= 1 (see the module docstring).

    Raises:
        ConfigError: unknown scene name, or a seed that is not a positive integer (seed 0 is the fixed sequence of
            :mod:`wptrack.synth.plaza`).
    """
    if name not in _DRAW:
        raise ConfigError(f"scene: expected one of {', '.join(sorted(_DRAW))}, got {name!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 1:
        raise ConfigError(f"seed: expected a positive integer (seed 0 is the fixed sequence), got {seed!r}")
    return _DRAW[name](scene_rng(name, int(seed)))
