"""Scenes ``s2-office`` and ``s2-office-twocolour``: two people meeting in a cluttered office, after the S2 paper
(a multi-camera 3D particle filter with motion and colour observations; its section 4 and figures 5-9).

The paper's test room is an office 'equipped with a large number of pieces of office furniture' that hides people
'almost always partially ... especially from the feet up to the waist', watched by 'three fully-calibrated static
cameras ... placed in the top corners of the room' with partly overlapping views. Its sequence: 'two people coming
into the office room from opposite sides and walking towards each other', meeting and 'shaking their hands', then
leaving 'by different ways'. Its Fig. 9 case: a person in two colours where camera 1 sees mostly one of them and
camera 2 mostly the other.

The synthetic room (world frame: metres, z up, floor z = 0) is 6 m (x) by 5 m (y) with a 2.8 m ceiling. Doors: the
west wall (x = 0) has one at 0.75 m < y < 1.75 m, the east wall (x = 6) one at 3.25 m < y < 4.25 m, both 2.1 m high,
opening on corridors (seen through the doors). Three cameras (default 640x480, fx = fy = width / 2: a 90 degree
horizontal field of view, OpenCV distortion k1 = -0.05, k2 = 0.01) hang 2.65 m high in three top corners
(``cam1`` south-west (0.2, 0.2), ``cam2`` north-east (5.8, 4.8), ``cam3`` south-east (5.8, 0.2)) and look at
(3.0, 2.5, 0.7), the room centre at waist height: every camera sees the middle of the room. Furniture: a south desk
island (1.75 < x < 4.6, 1.3 < y < 1.95) with a 1.3 m partition on its north edge (y = 2.0), a north desk island
(1.4 < x < 4.0, 3.3 < y < 3.95) with a 1.4 m partition on its south edge (y = 3.25), wall cabinets (1.1-1.3 m), a
1.05 m counter by the east door, a 1.1 m printer table by the west door, chairs, monitors, a plant and ceiling light
panels. The two people meet in the 1.25 m wide aisle between the partitions, which hide their legs and waists from
the cameras on the far side (cam1 and cam3 look over the south partition, cam2 over the north one).

People (reusing :class:`wptrack.synth.actors.Person`: legs, pelvis, chest, arms and head as ellipsoids): person 0
enters through the west door, person 1 through the east door; they walk to the middle of the aisle (0.68-0.80 m
apart, facing each other), stop, raise their right arms until the hands meet between them, shake (a small vertical
oscillation), lower the arms and leave through the opposite doors, passing each other in the aisle. With the
default 300 frames at 25 fps both have left the room before the end. In ``s2-office-twocolour`` person 0 wears a
red front and a blue back (torso and arms split by the plane through the body's vertical axis, across the walking
direction): at the meeting, the west camera ``cam1`` sees mostly the back, the east cameras mostly the front, as in
the paper's Fig. 9.

Image formation: textured static scene (ray cast once per camera), people ray cast each frame inside the image
boxes of their body parts (z-buffered against the furniture), Lambert + ambient shading by the ceiling light, a
soft shadow on the floor under each person (a darkened ellipse, stretched away from the room's central light, soft
edged), Gaussian sensor noise (sigma 2.5 DN) and an illumination change (global gain falling by 18 % over frames
120-150, a bank of lights switched off). The tracker is meant to make its motion masks from the videos with the
default motion pipeline; the perfect masks ``cam*_mask.avi`` (visible pixels of the people) are for debugging
only. With the default :class:`wptrack.motion.masks.MaskConfig` (MOG2, shadows as background) on seed 0, after 30 frames
of learning, the motion masks cover about half of the people's visible pixels (mean IoU with the perfect masks
0.48 / 0.54 / 0.67 for cam1 / cam2 / cam3 on the frames with people, no foreground on the empty frames):
incomplete and fragmented, as the paper's Fig. 4.

The ``seed`` of :func:`~wptrack.synth.base.render_scene` changes the sensor noise and, slightly, the people: their
paths (waypoints +-0.08 m, meeting point +-0.15 m), speeds (1.0-1.3 m/s), timing, heights, builds and clothing
shades. Seed 0 of ``s2-office`` is the tuning scene; other seeds and ``s2-office-twocolour`` are held out
(``held_out`` in scene.json).

Variants (issue 31, held out): ``s2-office-lowfps``, the same scene seen at 3.125 frames/s (every 8th frame: the
same 12 s in 38 frames; the tracker's dynamics and its birth and removal times are in seconds), and
``s2-office-meeting``, four cameras (``cam4`` in the north-west corner) and the two people standing and talking for
8 s at the meeting point before the handshake (500 frames; the light dims while they stand: the background model
and the tracker must keep people who do not move).

Light conditions (issue 26, ``--conditions clouds,exposure``, off by default; :data:`OFFICE_CONDITIONS`): ``clouds``,
daylight from windows along the south wall that fades and comes back across the floor as clouds pass
(:data:`DAYLIGHT_SHARE`, :data:`DAYLIGHT_REACH`); ``exposure``, each camera's own auto-exposure jumps and white-balance
shifts (:data:`EXPOSURE_CAMERA_DELAY_S`) and two lights switching on in part of the room (:data:`OFFICE_LIGHT_POOLS`).
They change the light only: the people, the perfect masks and the ground truth stay (:meth:`OfficeScene.light_factors`).

Ground truth (``groundtruth.csv``): ``frame,id,x,y,z,gx,gy,height,heading,handshake``: the centroid of the body
volume (volume-weighted mean of the body parts' ellipsoid centres, metres, world frame), the ground position (gx,
gy) (z = 0 below the body axis), the person's height (metres), heading (radians, ``atan2`` of the facing direction)
and the arm extension of the handshake (0 = arm hanging, 1 = hands meeting). A person is in the ground truth on the
frames where the ground position lies inside the room's floor rectangle (0 <= gx <= 6, 0 <= gy <= 5); they are
rendered whenever on their way (also in the corridors, through the doors). The per-camera ``visibility`` of
scene.json is the visible fraction of the least visible person of the ground truth.

Render time (measured on this project's shared 2-core CPU under a load average of about 11): the static room is ray
cast once per process and image size, 23 s for the three 640x480 cameras (4 s at 320x240); then a frame of the
three cameras takes 0.17 s median (0.15-0.21 s; 0.07 s at 320x240), before video encoding. ``python3 -m wptrack.cli
synth s2-office --frames 300`` wrote the 300 frames (6 lossless videos, about 135 MB per camera video) in 3 min 40 s
on the same loaded machine. Smaller images for quick experiments: ``OfficeScene(OfficeConfig(width=320,
height=240))``.

Length: one module because it is one specification, the synthetic counterpart of the paper's experiment: the
room's constants (walls, doors, camera corners) place the furniture, the cameras and the people's paths alike, and
the scene class renders exactly those; split, each part would import the others' constants and the scene could
only be read across files. The variants at the end are a few lines each.
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wptrack.cameras.rig import Camera, Rig
from wptrack.core.errors import ConfigError
from wptrack.synth import conditions as C
from wptrack.synth.actors import Path, Person, _Prim
from wptrack.synth.base import Scene, register_scene
from wptrack.synth.plaza import _image_box
from wptrack.synth.render import Box, Cylinder, Light, StaticView, noisy, posters, render_static, solid, wood

__all__ = [
    "CAMERA_HEIGHT",
    "DOORS",
    "ROOM",
    "OfficeConfig",
    "OfficeScene",
    "Walker",
    "office_rig",
    "office_walkers",
]

log = logging.getLogger(__name__)

ROOM = (6.0, 5.0, 2.8)
"""Room size x, y and ceiling height, metres (floor rectangle from the origin)."""
DOORS = {"west": (0.75, 1.75), "east": (3.25, 4.25)}
"""Door openings: y range on the west wall (x = 0) and the east wall (x = 6), metres; doors are 2.1 m high."""
DOOR_HEIGHT = 2.1
"""Height of the door openings, metres."""
CAMERA_HEIGHT = 2.65
"""Height of the camera centres, metres."""
CAMERA_CORNERS = {"cam1": (0.2, 0.2), "cam2": (5.8, 4.8), "cam3": (5.8, 0.2), "cam4": (0.2, 4.8)}
"""Camera centres (x, y) in the top corners, metres (``cam4``, the north-west corner, only in four-camera rigs)."""
CAMERA_TARGET = (3.0, 2.5, 0.7)
"""Point every camera looks at (room centre, waist height), metres."""
CAMERA_DIST = (-0.05, 0.01, 0.0, 0.0, 0.0)
"""OpenCV distortion k1 k2 p1 p2 k3 of every camera."""
CEILING_LIGHT = (3.0, 2.5)
"""(x, y) of the room's central light, metres: the floor shadows stretch away from it."""
LIGHT = Light(direction=(0.12, 0.18, 1.0), ambient=0.5, diffuse=0.55, exposure=0.82)
"""Indoor lighting (mostly from above)."""

LABEL_FLOOR = 1
"""Label of the floor in the static label images (receives the people's shadows)."""
LOWER_PARTS = (0, 2, 4)
"""Indices of the legs and the pelvis in :meth:`Person.primitives` (the 'feet to waist' body)."""
SHIRT_PARTS = (1, 3, 5)
"""Indices of the arms and the chest (shirt colour)."""
RIGHT_ARM = 3
"""Index of the right arm (raised for the handshake)."""

OFFICE_CONDITIONS = ("clouds", "exposure")
"""The hard conditions of :mod:`wptrack.synth.conditions` an office scene takes (``--conditions clouds,exposure``)."""
DAYLIGHT_REACH = 2.5
"""clouds: the room's daylight comes through windows along the south wall (y = 0); its share of a surface's light
falls as ``exp(-y / DAYLIGHT_REACH)`` with the distance y from that wall, metres."""
DAYLIGHT_SHARE = {"floor": 0.55, "static": 0.3, "person": 0.35}
"""clouds: share of daylight in the light of the floor, of the other static surfaces (walls, furniture) and of the
people, at the window wall (the ceiling light gives the rest). A passing cloud removes its opacity's fraction of it:
the plaza's drifting, soft-edged cloud shadows (:func:`wptrack.synth.conditions.cloud_cover`) seen indoors as
daylight fading and coming back across the floor, strongest by the windows."""
EXPOSURE_CAMERA_DELAY_S = 0.8
"""exposure: each camera runs its own auto-exposure and white balance: camera k's jumps
(:func:`wptrack.synth.conditions.exposure_gain`) come ``k x`` this many seconds after camera 0's."""
OFFICE_LIGHT_POOLS = (
    (2.5, (1.3, 4.0), 1.0, (1.45, 1.36, 1.22)),
    (7.0, (3.6, 2.6), 0.9, (1.35, 1.3, 1.2)),
)
"""exposure: lights switching on in part of the room ``(time s, floor centre (x, y) m, gaussian radius m, (R, G, B)
peak factor)``: a desk lamp's pool by the north-west desks and a light over the aisle where the people meet
(:func:`wptrack.synth.conditions.light_pool_factor`). They light what stands below :data:`POOL_TOP` (the floor, the
furniture, the people), not the ceiling."""
POOL_TOP = (1.8, 2.6)
"""exposure: a light pool's effect is whole up to the first height and fades out by the second, metres."""

_Rgb = tuple[float, float, float]


# ----------------------------------------------------------------------------------------------------- config


@dataclass(frozen=True)
class OfficeConfig:
    """Options of the office scene.

    Attributes:
        two_colour: Person 0 wears a red front and a blue back (the paper's Fig. 9 case).
        seed: Scene seed: paths, timing and looks vary slightly with it (0 = the tuning scene).
        width: Image width of every camera, pixels (the focal length scales with it).
        height: Image height, pixels.
        frames: Default number of frames.
        fps: Frames per second.
        noise_sigma: Sensor noise standard deviation, DN.
        light_ramp: ``(first, last)`` frames of the illumination change.
        light_gain: Global gain after the ramp (0.82: 18 % darker).
        shadow_strength: Darkening at the centre of a person's floor shadow (0..1).
        cameras: 3 (the paper's set-up) or 4 (a fourth camera in the north-west corner).
        talk: Seconds the two people stand and talk at the meeting point before the handshake (0: they shake
            hands as soon as both have arrived). The paths, speeds and looks do not depend on it; the handshake and
            the rest of the timeline move later by ``talk``.
        clouds: Daylight from the south windows fading and coming back as clouds pass (:data:`DAYLIGHT_SHARE`).
        exposure: Per-camera auto-exposure jumps and white-balance shifts, and two lights switching on in part of the
            room (:data:`OFFICE_LIGHT_POOLS`). Neither condition changes the people, the perfect masks or the ground
            truth; both off: the scene as before, frame for frame.
    """

    two_colour: bool = False
    seed: int = 0
    width: int = 640
    height: int = 480
    frames: int = 300
    fps: float = 25.0
    noise_sigma: float = 2.5
    light_ramp: tuple[int, int] = (120, 150)
    light_gain: float = 0.82
    shadow_strength: float = 0.45
    cameras: int = 3
    talk: float = 0.0
    clouds: bool = False
    exposure: bool = False

    def __post_init__(self) -> None:
        def integer(name: str, lo: int) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
                raise ConfigError(f"office scene: {name}: expected an integer >= {lo}, got {v!r}")

        integer("seed", 0)
        integer("width", 32)
        integer("height", 32)
        integer("frames", 1)
        for name, lo, hi in (("fps", 0.0, math.inf), ("light_gain", 0.0, math.inf), ("shadow_strength", -1e-12, 1.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo < v <= hi):
                raise ConfigError(f"office scene: {name}: expected a number in ({lo:g}, {hi:g}], got {v!r}")
        if isinstance(self.noise_sigma, bool) or not isinstance(self.noise_sigma, (int, float)) or self.noise_sigma < 0:
            raise ConfigError(f"office scene: noise_sigma: expected a number >= 0 (DN), got {self.noise_sigma!r}")
        if self.cameras not in (3, 4) or isinstance(self.cameras, bool):
            raise ConfigError(f"office scene: cameras: expected 3 or 4, got {self.cameras!r}")
        if isinstance(self.talk, bool) or not isinstance(self.talk, (int, float)) or not (0 <= self.talk < 1e4):
            raise ConfigError(f"office scene: talk: expected seconds >= 0, got {self.talk!r}")
        for name in ("clouds", "exposure"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise ConfigError(f"office scene: {name}: expected True or False, got {getattr(self, name)!r}")
        ramp = self.light_ramp
        if len(ramp) != 2 or not all(isinstance(r, (int, np.integer)) for r in ramp) or not 0 <= ramp[0] < ramp[1]:
            raise ConfigError(f"office scene: light_ramp: expected two frames 0 <= first < last, got {ramp!r}")


# ----------------------------------------------------------------------------------------------------- rig


def office_rig(width: int = 640, height: int = 480, cameras: int = 3) -> Rig:
    """The corner cameras (see the module docstring) and the room's working volume (floor to 2.2 m).

    Args:
        width: Image width, pixels.
        height: Image height, pixels.
        cameras: 3 (``cam1``-``cam3``) or 4 (and ``cam4``).
    """
    fx = 0.5 * width
    cams = [
        Camera.look_at(name, width, height, (x, y, CAMERA_HEIGHT), CAMERA_TARGET, fx=fx, dist=CAMERA_DIST)
        for name, (x, y) in list(CAMERA_CORNERS.items())[:cameras]
    ]
    volume = (np.array([0.0, 0.0, 0.0]), np.array([ROOM[0], ROOM[1], 2.2]))
    return Rig(cameras=tuple(cams), volume=volume)


def _static_objects() -> list[Box | Cylinder]:
    """Floor, walls with doors, corridors, ceiling and furniture (fixed layout)."""
    lx, ly, lz = ROOM
    wall = noisy((0.78, 0.76, 0.7), amplitude=0.05, scale_m=0.4, seed=81)
    north_posters = [((0.6, 1.3), (1.3, 1.9), (0.2, 0.35, 0.6), False), ((4.3, 1.2), (5.3, 1.8), (0.8, 0.6, 0.2), True)]
    south_posters = [((2.4, 1.4), (3.4, 2.0), (0.25, 0.5, 0.3), False)]
    west_posters = [((2.6, 1.4), (3.6, 2.0), (0.5, 0.3, 0.45), True)]
    east_posters = [((0.6, 1.3), (1.6, 2.0), (0.3, 0.55, 0.65), False)]
    carpet = noisy((0.36, 0.38, 0.42), amplitude=0.12, scale_m=0.05, seed=82)
    metal = noisy((0.62, 0.63, 0.64), amplitude=0.04, scale_m=0.2, seed=83)
    fabric_s = noisy((0.42, 0.46, 0.52), amplitude=0.1, scale_m=0.04, seed=84)
    fabric_n = noisy((0.5, 0.47, 0.38), amplitude=0.1, scale_m=0.04, seed=85)
    desk = wood((0.62, 0.48, 0.32), ring_m=0.07, grain_axis=0, seed=86)
    black = solid((0.05, 0.05, 0.06))
    chair = solid((0.1, 0.1, 0.12))
    (w0, w1), (e0, e1) = DOORS["west"], DOORS["east"]
    objects: list[Box | Cylinder] = [
        Box((-2.0, -1.0, -0.1), (lx + 2.0, ly + 1.0, 0.0), carpet, label=LABEL_FLOOR),
        # walls (0.1 m thick) with the door openings, lintels above them
        Box((-0.1, -0.1, 0.0), (0.0, w0, lz), posters(wall, []), label=2),
        Box((-0.1, w1, 0.0), (0.0, ly + 0.1, lz), posters(wall, west_posters), label=2),
        Box((-0.1, w0, DOOR_HEIGHT), (0.0, w1, lz), wall, label=2),
        Box((lx, -0.1, 0.0), (lx + 0.1, e0, lz), posters(wall, east_posters), label=3),
        Box((lx, e1, 0.0), (lx + 0.1, ly + 0.1, lz), wall, label=3),
        Box((lx, e0, DOOR_HEIGHT), (lx + 0.1, e1, lz), wall, label=3),
        Box((-0.1, -0.1, 0.0), (lx + 0.1, 0.0, lz), posters(wall, south_posters), label=4),
        Box((-0.1, ly, 0.0), (lx + 0.1, ly + 0.1, lz), posters(wall, north_posters), label=5),
        Box((-2.0, -1.0, lz), (lx + 2.0, ly + 1.0, lz + 0.1), solid((0.85, 0.85, 0.82)), label=6),
        # corridor walls behind the doors
        Box((-1.7, -1.0, 0.0), (-1.6, ly + 1.0, lz), noisy((0.66, 0.7, 0.72), 0.05, 0.3, seed=87), label=7),
        Box((lx + 1.6, -1.0, 0.0), (lx + 1.7, ly + 1.0, lz), noisy((0.72, 0.68, 0.6), 0.05, 0.3, seed=88), label=7),
        # ceiling light panels
        Box((1.2, 1.0, lz - 0.02), (2.4, 1.6, lz), solid((1.0, 1.0, 0.97)), label=8),
        Box((3.6, 3.4, lz - 0.02), (4.8, 4.0, lz), solid((1.0, 1.0, 0.97)), label=8),
        Box((2.4, 2.2, lz - 0.02), (3.6, 2.8, lz), solid((1.0, 1.0, 0.97)), label=8),
        # south desk island: top, modesty panels to the floor, a 1.2 m partition on its north edge
        Box((1.75, 1.3, 0.72), (4.6, 1.95, 0.76), desk, label=10),
        Box((1.75, 1.3, 0.0), (1.8, 1.95, 0.72), metal, label=10),
        Box((4.55, 1.3, 0.0), (4.6, 1.95, 0.72), metal, label=10),
        Box((3.15, 1.3, 0.0), (3.21, 1.95, 0.72), metal, label=10),
        Box((1.75, 1.95, 0.0), (4.6, 2.0, 1.3), fabric_s, label=11),
        Box((2.3, 1.7, 0.76), (2.85, 1.76, 1.12), black, label=12),
        Box((3.7, 1.7, 0.76), (4.25, 1.76, 1.12), black, label=12),
        # north desk island with a 1.35 m partition on its south edge
        Box((1.4, 3.3, 0.72), (4.0, 3.95, 0.76), desk, label=13),
        Box((1.4, 3.3, 0.0), (1.45, 3.95, 0.72), metal, label=13),
        Box((3.95, 3.3, 0.0), (4.0, 3.95, 0.72), metal, label=13),
        Box((1.4, 3.25, 0.0), (4.0, 3.3, 1.4), fabric_n, label=14),
        Box((1.9, 3.4, 0.76), (2.45, 3.46, 1.12), black, label=15),
        Box((3.0, 3.4, 0.76), (3.55, 3.46, 1.12), black, label=15),
        # a counter by the east door and a printer table by the west door
        Box((4.9, 2.3, 0.0), (5.5, 2.9, 1.05), noisy((0.7, 0.66, 0.6), 0.05, 0.2, seed=92), label=21),
        Box((1.0, 0.8, 0.0), (1.5, 1.35, 1.1), noisy((0.35, 0.35, 0.38), 0.05, 0.2, seed=93), label=22),
        # cabinets along the walls
        Box((0.0, 2.4, 0.0), (0.45, 4.6, 1.1), metal, label=16),
        Box((lx - 0.45, 1.0, 0.0), (lx, 2.6, 1.1), metal, label=17),
        Box((0.9, 0.0, 0.0), (1.8, 0.45, 1.3), noisy((0.55, 0.5, 0.42), 0.05, 0.2, seed=89), label=18),
        Box((4.6, ly - 0.45, 0.0), (5.4, ly, 1.25), noisy((0.55, 0.5, 0.42), 0.05, 0.2, seed=90), label=19),
        # a plant in the north-west corner
        Cylinder((0.4, 4.65), 0.2, 0.0, 0.45, solid((0.5, 0.3, 0.2)), label=20),
        Cylinder((0.4, 4.65), 0.32, 0.45, 1.5, noisy((0.15, 0.32, 0.12), 0.35, 0.08, seed=91), label=20),
    ]
    # chairs on the far sides of the desks (seat on a column, back)
    for i, (x, y, back_dy) in enumerate(((2.6, 1.05, -0.25), (4.0, 1.05, -0.25), (2.2, 4.2, 0.25), (3.3, 4.2, 0.25))):
        objects.append(Cylinder((x, y), 0.05, 0.0, 0.45, chair, label=30 + i))
        objects.append(Box((x - 0.23, y - 0.23, 0.45), (x + 0.23, y + 0.23, 0.52), chair, label=30 + i))
        yb = y + back_dy
        objects.append(Box((x - 0.22, min(yb, yb + 0.05), 0.52), (x + 0.22, max(yb, yb + 0.05), 0.95), chair, 30 + i))
    return objects


# ----------------------------------------------------------------------------------------------------- people


@dataclass(frozen=True)
class Walker:
    """One person of the office scene and their timeline.

    Attributes:
        oid: Object id (ground truth).
        person: Body and clothing (the shirt colour is the front colour).
        back: Colour of the back of the shirt (two-colour clothes), or None.
        enter: Path from the corridor through the door to the meeting point.
        leave: Path from the meeting point through the other door to the other corridor.
        meet: (x, y) where the person stands during the handshake, metres.
        partner: (x, y) where the other person stands, metres.
        hand: (3,) where the hands meet, metres.
        shake: ``(start, end)`` of the handshake (arm raised, shaken and lowered), seconds.
    """

    oid: int
    person: Person
    back: _Rgb | None
    enter: Path
    leave: Path
    meet: tuple[float, float]
    partner: tuple[float, float]
    hand: tuple[float, float, float]
    shake: tuple[float, float]


def _jitter(rgb: _Rgb, rng: np.random.Generator, amount: float = 0.04) -> _Rgb:
    out = np.clip(np.asarray(rgb) + rng.uniform(-amount, amount, 3), 0.02, 0.95)
    return (float(out[0]), float(out[1]), float(out[2]))


def office_walkers(seed: int = 0, two_colour: bool = False, talk: float = 0.0) -> list[Walker]:
    """The two people: paths, timing and looks for scene seed ``seed`` (see the module docstring).

    Args:
        seed: Scene seed (0 = the tuning scene).
        two_colour: Person 0 wears a red front and a blue back.
        talk: Seconds they stand and talk before the handshake.
    """
    rng = np.random.default_rng([2, int(seed)])

    def wobble(points: list[tuple[float, float]]) -> tuple[tuple[float, float], ...]:
        out = [points[0]]
        for x, y in points[1:-1]:
            dx, dy = rng.uniform(-0.08, 0.08, 2)
            out.append((x + float(dx), y + float(dy)))
        out.append(points[-1])
        return tuple(out)

    cx, cy = 3.0 + rng.uniform(-0.15, 0.15), 2.62 + rng.uniform(-0.08, 0.08)
    gap = rng.uniform(0.68, 0.8)
    meet_a = (float(cx - 0.5 * gap), float(cy))
    meet_b = (float(cx + 0.5 * gap), float(cy))
    (w0, w1), (e0, e1) = DOORS["west"], DOORS["east"]
    west_y, east_y = 0.5 * (w0 + w1), 0.5 * (e0 + e1)
    lx = ROOM[0]
    speeds = rng.uniform(1.0, 1.3, 2)
    looks = [
        Person(
            height=float(rng.uniform(1.7, 1.86)),
            girth=float(rng.uniform(0.95, 1.08)),
            shirt=_jitter((0.62, 0.12, 0.1), rng),
            trousers=_jitter((0.12, 0.13, 0.2), rng, 0.02),
            skin=_jitter((0.75, 0.55, 0.45), rng, 0.03),
            hair=(0.08, 0.06, 0.05),
        ),
        Person(
            height=float(rng.uniform(1.62, 1.78)),
            girth=float(rng.uniform(0.92, 1.05)),
            shirt=_jitter((0.16, 0.42, 0.2), rng),
            trousers=_jitter((0.32, 0.27, 0.21), rng, 0.02),
            skin=_jitter((0.55, 0.38, 0.28), rng, 0.03),
            hair=(0.3, 0.2, 0.1),
        ),
    ]
    back = _jitter((0.12, 0.2, 0.58), rng)  # drawn in both variants: the same seed gives the same paths
    backs: list[_Rgb | None] = [back if two_colour else None, None]
    enter_pts = [
        wobble([(-0.9, west_y), (0.6, west_y + 0.05), (1.3, 2.05), (2.0, cy - 0.1), meet_a]),
        wobble([(lx + 0.9, east_y), (5.4, east_y - 0.05), (4.6, 3.1), (3.9, cy + 0.08), meet_b]),
    ]
    leave_pts = [
        wobble([meet_a, (cx, cy + 0.3), (3.8, 2.95), (4.7, 3.2), (5.4, east_y - 0.05), (lx + 0.9, east_y)]),
        wobble([meet_b, (cx, cy - 0.3), (2.1, 2.35), (1.3, 2.05), (0.6, west_y + 0.05), (-0.9, west_y)]),
    ]
    enters = []
    for pts, v in zip(enter_pts, speeds, strict=True):
        sp = (v, v, v, 0.75 * v, 0.3)
        enters.append(Path(pts, sp, 0.0, smooth_m=0.8))
    t_meet = 4.0 + rng.uniform(-0.3, 0.3)
    late = rng.uniform(0.1, 0.6)
    arrive = (t_meet, t_meet + late)
    enters = [Path(p.waypoints, p.speeds, float(t - p.end), smooth_m=0.8) for p, t in zip(enters, arrive, strict=True)]
    shake = (max(arrive) + 0.2 + talk, max(arrive) + 0.2 + talk + rng.uniform(1.4, 1.8))
    hand_z = 0.55 * 0.5 * (looks[0].height + looks[1].height)
    hand = (float(cx), float(cy), float(hand_z))
    out = []
    for k in range(2):
        start = shake[1] + 0.1 + rng.uniform(0.0, 0.3) + 0.2 * k
        v = float(speeds[k])
        leave = Path(leave_pts[k], (0.5, 0.9 * v, v, v, v, v), float(start), smooth_m=0.8)
        meet, partner = (meet_a, meet_b) if k == 0 else (meet_b, meet_a)
        out.append(Walker(k, looks[k], backs[k], enters[k], leave, meet, partner, hand, shake))
    return out


def _smoothstep(x: np.ndarray | float) -> np.ndarray:
    t = np.clip(x, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _walker_positions(w: Walker, times: np.ndarray) -> np.ndarray:
    """(N, 2) ground positions at ``times`` (seconds): enter path, standing at the meeting point, leave path."""
    p1, _ = w.enter.positions(times)
    p2, _ = w.leave.positions(times)
    meet = np.broadcast_to(np.asarray(w.meet), p1.shape)
    out = np.where((times <= w.enter.end)[:, None], p1, meet)
    return np.where((times >= w.leave.start)[:, None], p2, out)


def _arm_extension(w: Walker, times: np.ndarray) -> np.ndarray:
    """(N,) handshake arm extension in [0, 1]: raised over 0.4 s, held, lowered over 0.4 s."""
    t0, t1 = w.shake
    return np.minimum(_smoothstep((times - t0) / 0.4), _smoothstep((t1 - times) / 0.4))


@dataclass
class _States:
    frames: int
    pos: np.ndarray  # (A, N, 2) ground positions
    heading: np.ndarray  # (A, N) facing direction, radians
    speed: np.ndarray  # (A, N) m/s
    phase: np.ndarray  # (A, N) gait phase, radians
    arm: np.ndarray  # (A, N) handshake arm extension
    times: np.ndarray  # (N,) seconds


def _ellipsoid_rot(axis: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Rotation whose local z is ``axis`` and local x is ``forward`` made perpendicular to it (columns)."""
    z = axis / np.linalg.norm(axis)
    x = forward - (forward @ z) * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


# ----------------------------------------------------------------------------------------------------- scene


@functools.lru_cache(maxsize=4)
def _office_views(
    width: int, height: int, cameras: int = 3
) -> tuple[list[StaticView], list[tuple[np.ndarray, np.ndarray]]]:
    """The static room ray cast for every camera of :func:`office_rig` at this size (cached per process).

    Returns:
        ``(views, floor)``: one :class:`StaticView` per camera and, per camera, the flat indices (M,) of its floor
        pixels with their world (x, y) (M, 2) float32 metres (the people's shadows fall there).
    """
    objects = _static_objects()
    views = [
        render_static(cam, objects, LIGHT, background=(0.3, 0.3, 0.3)) for cam in office_rig(width, height, cameras)
    ]
    floor = []
    for view in views:
        idx = np.flatnonzero(view.label.ravel() == LABEL_FLOOR)
        pts = view.origin[None, :] + view.dirs[idx] * view.depth.ravel()[idx, None].astype(np.float64)
        floor.append((idx, pts[:, :2].astype(np.float32)))
    for view in views:
        for arr in (view.radiance, view.depth, view.label, view.dirs):
            arr.flags.writeable = False
    return views, floor


class OfficeScene(Scene):
    """The office scene: three corner cameras, two people meeting and shaking hands, perfect masks.

    Args:
        config: Options (image size, seed, two-colour clothes, photometry).
    """

    writes_masks = True

    def __init__(self, config: OfficeConfig | None = None) -> None:
        self.config = config or OfficeConfig()
        self.fps = float(self.config.fps)
        self.default_frames = int(self.config.frames)
        self.rig = office_rig(self.config.width, self.config.height, self.config.cameras)
        self.walkers = office_walkers(self.config.seed, self.config.two_colour, self.config.talk)
        self._views: list[StaticView] | None = None
        self._floor: list[tuple[np.ndarray, np.ndarray]] | None = None
        self._states: _States | None = None
        self._daylight: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # camera -> static points, daylight shares

    def with_conditions(self, conditions: Any) -> OfficeScene:
        """The same scene under the hard conditions it takes (:data:`OFFICE_CONDITIONS`).

        Raises:
            ConfigError: a condition the office does not take (the plaza's motion and object conditions).
        """
        other = [n for n in conditions.names if n not in OFFICE_CONDITIONS]
        if other:
            raise ConfigError(
                f"the office scenes take only the conditions {', '.join(OFFICE_CONDITIONS)}, got {', '.join(other)}"
            )
        return OfficeScene(replace(self.config, clouds=bool(conditions.clouds), exposure=bool(conditions.exposure)))

    # -- motion and ground truth

    def states(self, frames: int) -> _States:
        """Per-frame states of both people for at least ``frames`` frames (cached)."""
        if self._states is not None and self._states.frames >= frames:
            return self._states
        n = max(int(frames), self.default_frames)
        dt = 1.0 / self.fps
        times = np.arange(n) * dt
        h = 0.02
        count = len(self.walkers)
        pos = np.zeros((count, n, 2))
        heading = np.zeros((count, n))
        speed = np.zeros((count, n))
        phase = np.zeros((count, n))
        arm = np.zeros((count, n))
        for a, w in enumerate(self.walkers):
            p = _walker_positions(w, times)
            vel = (_walker_positions(w, times + h) - _walker_positions(w, times - h)) / (2 * h)
            sp = np.linalg.norm(vel, axis=1)
            towards = np.asarray(w.partner) - np.asarray(w.meet)
            facing = np.where(
                (sp > 0.05)[:, None], vel / np.maximum(sp, 1e-9)[:, None], towards / np.linalg.norm(towards)
            )
            # turn smoothly: average the facing direction over +-0.2 s
            half = max(int(round(0.2 * self.fps)), 1)
            kernel = np.ones(2 * half + 1)
            fx = np.convolve(np.pad(facing[:, 0], half, mode="edge"), kernel, mode="valid")
            fy = np.convolve(np.pad(facing[:, 1], half, mode="edge"), kernel, mode="valid")
            stride = w.person.stride(sp)
            pos[a] = p
            heading[a] = np.arctan2(fy, fx)
            speed[a] = sp
            phase[a] = 2 * np.pi * np.cumsum(sp * dt / stride) + 1.3 * w.oid
            arm[a] = _arm_extension(w, times)
        self._states = _States(n, pos, heading, speed, phase, arm, times)
        return self._states

    def primitives(self, walker: int, index: int) -> list[_Prim]:
        """Body parts of person ``walker`` at frame ``index`` (the plaza person, right arm raised to shake hands)."""
        st = self.states(index + 1)
        w = self.walkers[walker]
        x, y = st.pos[walker, index]
        psi = float(st.heading[walker, index])
        parts = w.person.primitives(
            float(x), float(y), psi, float(st.phase[walker, index]), float(st.speed[walker, index])
        )
        ext = float(st.arm[walker, index])
        if ext > 0.0:
            p = w.person
            k = p.height / 1.75
            arm = parts[RIGHT_ARM]
            forward = np.array([math.cos(psi), math.sin(psi), 0.0])
            left = np.array([-math.sin(psi), math.cos(psi), 0.0])
            # the shoulder is the arm ellipsoid's upper end; the hanging hand its lower end
            axis = arm.rot[:, 2] * arm.half[2]
            shoulder = arm.center + axis
            hang = arm.center - axis
            wiggle = 0.035 * math.sin(2 * math.pi * 2.5 * st.times[index]) * ext
            target = np.asarray(w.hand) + np.array([0.0, 0.0, wiggle]) - 0.05 * forward - 0.03 * left
            hand = (1.0 - ext) * hang + ext * target
            seg = hand - shoulder
            length = float(np.linalg.norm(seg))
            rot = _ellipsoid_rot(seg, forward)
            half = np.array([0.05 * p.girth, 0.045 * p.girth, 0.5 * length + 0.01 * k])
            parts[RIGHT_ARM] = _Prim("ellipsoid", shoulder + 0.5 * seg, rot, half, arm.rgb)
        return parts

    def centroid(self, walker: int, index: int) -> np.ndarray:
        """(3,) centroid of the body volume of person ``walker`` at frame ``index``, metres."""
        parts = self.primitives(walker, index)
        vol = np.array([np.prod(p.half) for p in parts])
        centres = np.stack([p.center for p in parts])
        return (vol[:, None] * centres).sum(axis=0) / vol.sum()

    def inside(self, frames: int) -> np.ndarray:
        """(people, frames) bool: the ground position is inside the room's floor rectangle."""
        st = self.states(frames)
        p = st.pos[:, :frames]
        return (p[..., 0] >= 0) & (p[..., 0] <= ROOM[0]) & (p[..., 1] >= 0) & (p[..., 1] <= ROOM[1])

    def trajectories(self, frames: int) -> dict[int, np.ndarray]:
        """Body centroids: object id -> (frames, 3) metres; NaN where the person is not inside the room."""
        inside = self.inside(frames)
        out = {}
        for a, w in enumerate(self.walkers):
            traj = np.full((frames, 3), np.nan)
            for f in np.flatnonzero(inside[a]):
                traj[f] = self.centroid(a, int(f))
            out[w.oid] = traj
        return out

    def groundtruth_columns(self, frames: int) -> dict[str, dict[int, np.ndarray]]:
        """Extra columns: ground position ``gx, gy``, ``height``, ``heading`` (radians), ``handshake`` (0-1)."""
        st = self.states(frames)
        cols: dict[str, dict[int, np.ndarray]] = {k: {} for k in ("gx", "gy", "height", "heading", "handshake")}
        for a, w in enumerate(self.walkers):
            cols["gx"][w.oid] = st.pos[a, :frames, 0]
            cols["gy"][w.oid] = st.pos[a, :frames, 1]
            cols["height"][w.oid] = np.full(frames, w.person.height)
            cols["heading"][w.oid] = np.angle(np.exp(1j * st.heading[a, :frames]))
            cols["handshake"][w.oid] = st.arm[a, :frames]
        return cols

    def hints(self) -> dict[str, Any]:
        """Tracker hints: tracker family, mask source, people, particle count and P_H of the paper, room, clothing."""
        cfg = self.config
        clothing = {}
        for w in self.walkers:
            clothing[str(w.oid)] = {
                "front": [round(c, 4) for c in w.person.shirt],
                "back": [round(c, 4) for c in (w.back or w.person.shirt)],
                "trousers": [round(c, 4) for c in w.person.trousers],
            }
        return {
            "tracker": "multicamera-3d",
            "masks": "motion",
            "people": len(self.walkers),
            "particles": 500,
            "p_h": 0.95,
            "room": list(ROOM),
            "ground": {"origin": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]},
            "two_colour": bool(cfg.two_colour),
            "held_out": bool(
                cfg.two_colour or cfg.seed != 0 or cfg.cameras != 3 or cfg.talk > 0 or cfg.fps != 25.0 or self._lit
            ),
            "clothing_rgb": clothing,
            **({"conditions": self._describe_conditions()} if self._lit else {}),
        }

    @property
    def _lit(self) -> bool:
        """Whether a light condition is on."""
        return bool(self.config.clouds or self.config.exposure)

    def _describe_conditions(self) -> dict[str, dict[str, Any]]:
        """Name -> parameters of each condition that is on (scene.json)."""
        out: dict[str, dict[str, Any]] = {}
        if self.config.clouds:
            clouds = C.PlazaConditions(clouds=True).describe()["clouds"]
            out["clouds"] = {
                **clouds,
                "windows": "south wall (y = 0)",
                "daylight_reach_m": DAYLIGHT_REACH,
                "daylight_share": dict(DAYLIGHT_SHARE),
            }
        if self.config.exposure:
            out["exposure"] = {
                "steps": [list(x) for x in C.EXPOSURE_STEPS],
                "ramp_s": C.EXPOSURE_RAMP_S,
                "awb_shifts": [[t, list(f)] for t, f in C.AWB_SHIFTS],
                "awb_ramp_s": C.AWB_RAMP_S,
                "camera_delay_s": EXPOSURE_CAMERA_DELAY_S,
                "light_pools": [
                    {"on_s": t, "centre_m": list(c), "radius_m": r, "peak_rgb": list(f)}
                    for t, c, r, f in OFFICE_LIGHT_POOLS
                ],
                "pool_ramp_s": C.POOL_RAMP_S,
            }
        return out

    # -- pixels

    def views(self) -> list[StaticView]:
        """Static ray-cast views, one per camera (computed on first use, shared by scenes of the same size)."""
        if self._views is None:
            self._views, self._floor = _office_views(self.config.width, self.config.height, self.config.cameras)
        return self._views

    def gain(self, index: int) -> float:
        """Global illumination gain at frame ``index`` (1 before the ramp, ``light_gain`` after it)."""
        a, b = self.config.light_ramp
        x = float(_smoothstep((index - a) / (b - a)))
        return 1.0 + (self.config.light_gain - 1.0) * x

    def _shadow(self, cam: int, img: np.ndarray, ground: np.ndarray) -> None:
        """Darken the floor under a person at ground position ``ground`` (2,) in camera ``cam``'s radiance."""
        idx, xy = self._floor[cam]  # type: ignore[index]
        near = (np.abs(xy[:, 0] - ground[0]) < 1.2) & (np.abs(xy[:, 1] - ground[1]) < 1.2)
        if not np.any(near):
            return
        d = ground - np.asarray(CEILING_LIGHT)
        dist = float(np.linalg.norm(d))
        u = d / dist if dist > 1e-3 else np.array([1.0, 0.0])
        centre = ground + 0.12 * dist * u
        rel = xy[near] - centre[None, :]
        along = rel @ u
        across = rel @ np.array([-u[1], u[0]])
        r = np.sqrt((along / (0.3 + 0.12 * dist)) ** 2 + (across / 0.28) ** 2)
        amount = self.config.shadow_strength * (1.0 - _smoothstep((r - 0.35) / 0.65))
        flat = img.reshape(-1, 3)
        flat[idx[near]] *= (1.0 - amount).astype(np.float32)[:, None]

    def _static_daylight(self, cam: int) -> tuple[np.ndarray, np.ndarray]:
        """Camera ``cam``'s static hit points (H*W, 3) metres (NaN where a ray hits nothing) and their daylight
        shares (H*W,) (:data:`DAYLIGHT_SHARE`, falling with the distance from the window wall); cached."""
        got = self._daylight.get(cam)
        if got is None:
            view = self.views()[cam]
            depth = view.depth.ravel().astype(np.float64)
            pts = view.origin[None, :] + view.dirs * np.where(np.isfinite(depth), depth, np.nan)[:, None]
            share = np.where(view.label.ravel() == LABEL_FLOOR, DAYLIGHT_SHARE["floor"], DAYLIGHT_SHARE["static"])
            share = share * np.exp(-np.clip(np.nan_to_num(pts[:, 1], nan=1e9), 0.0, None) / DAYLIGHT_REACH)
            got = self._daylight[cam] = (pts, share)
        return got

    def light_factors(self, cam: int, index: int, labels: np.ndarray) -> np.ndarray:
        """``(H, W, 3)`` R, G, B radiance factors of the light conditions (``clouds``, ``exposure``) in camera ``cam``
        at frame ``index``, given its label image (``oid + 1`` on each person's visible pixels): static pixels at their
        own 3-D points, a person's pixels at the person's ground position (daylight share
        ``DAYLIGHT_SHARE["person"]``, lights at waist height); times the camera's global exposure and white-balance
        gain. All ones with both conditions off."""
        cfg = self.config
        h, w = labels.shape
        t = index / self.fps
        pts, share = self._static_daylight(cam)
        factor = np.ones((h * w, 3))
        st = self.states(index + 1)
        flat = labels.ravel()
        people = [(a, flat == walker.oid + 1) for a, walker in enumerate(self.walkers)]
        people = [(a, sel) for a, sel in people if np.any(sel)]
        if cfg.clouds:
            factor *= C.cloud_darkening(C.cloud_cover(pts[:, :2], t), share)
            for a, sel in people:
                g = st.pos[a, index]
                s = DAYLIGHT_SHARE["person"] * math.exp(-max(float(g[1]), 0.0) / DAYLIGHT_REACH)
                factor[sel] = C.cloud_darkening(C.cloud_cover(g[None, :], t), np.asarray([s]))[0]
        if cfg.exposure:
            lo, hi = POOL_TOP
            below = 1.0 - _smoothstep((np.nan_to_num(pts[:, 2], nan=hi) - lo) / (hi - lo))
            pool = 1.0 + (C.light_pool_factor(pts, t, OFFICE_LIGHT_POOLS) - 1.0) * below[:, None]
            for a, sel in people:
                g = st.pos[a, index]
                pool[sel] = C.light_pool_factor(np.asarray([[g[0], g[1], 1.0]]), t, OFFICE_LIGHT_POOLS)[0]
            factor *= pool
            factor *= C.exposure_gain(t - cam * EXPOSURE_CAMERA_DELAY_S)[None, :]
        return factor.reshape(h, w, 3)

    def render_camera(
        self, cam: int, index: int, rng: np.random.Generator, prims: list[list[_Prim]] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[int, tuple[int, int]]]:
        """Render camera ``cam`` at frame ``index`` with its label images (tests, debugging, perfect masks).

        Args:
            cam: Camera index (rig order).
            index: 0-based frame index.
            rng: Sensor noise generator (one (H, W, 3) draw per call).
            prims: Body parts per person (default: :meth:`primitives` of every person).

        Returns:
            ``(bgr, labels, lower, pixels)``: the (H, W, 3) uint8 BGR image; an (H, W) int32 label image with
            ``oid + 1`` on the visible pixels of each person, 0 elsewhere; an (H, W) bool image of the visible
            pixels of legs and pelvis (feet to waist); object id -> (visible pixels, pixels it would cover without
            occluders).
        """
        view = self.views()[cam]
        camera = view.camera
        h, w = camera.height, camera.width
        if prims is None:
            prims = [self.primitives(a, index) for a in range(len(self.walkers))]
        st = self.states(index + 1)
        img = view.radiance.copy()
        for a in range(len(self.walkers)):
            self._shadow(cam, img, st.pos[a, index])
        zbuf = view.depth.copy()
        labels = np.zeros((h, w), dtype=np.int32)
        lower = np.zeros((h, w), dtype=bool)
        dirs = view.dirs.reshape(h, w, 3)
        sun = LIGHT.unit
        pixels: dict[int, tuple[int, int]] = {}
        for a, walker in enumerate(self.walkers):
            covered = np.zeros((h, w), dtype=bool)
            back = None if walker.back is None else np.asarray(walker.back, dtype=np.float64)
            for part, prim in enumerate(prims[a]):
                box = _image_box(camera, prim.corners())
                if box is None:
                    continue
                u0, u1, v0, v1 = box
                d = dirs[v0:v1, u0:u1].reshape(-1, 3)
                tt = prim.intersect(view.origin, d).reshape(v1 - v0, u1 - u0)
                hit = np.isfinite(tt)
                if not np.any(hit):
                    continue
                covered[v0:v1, u0:u1] |= hit
                zsub = zbuf[v0:v1, u0:u1]
                front = hit & (tt < zsub)
                if not np.any(front):
                    continue
                tf = tt[front]
                nloc = prim.normals(view.origin, d[front.ravel()], tf)
                lam = np.clip((nloc @ prim.rot.T) @ sun, 0.0, None)
                albedo = np.broadcast_to(prim.rgb, nloc.shape)
                if prim.top_rgb is not None:
                    albedo = np.where(nloc[:, 2:3] > 0.55, prim.top_rgb[None, :], albedo)
                if back is not None and part in SHIRT_PARTS:
                    albedo = np.where(nloc[:, 0:1] < 0.0, back[None, :], albedo)
                img[v0:v1, u0:u1][front] = albedo * (LIGHT.ambient + LIGHT.diffuse * lam)[:, None]
                zsub[front] = tf
                labels[v0:v1, u0:u1][front] = walker.oid + 1
                lower[v0:v1, u0:u1][front] = part in LOWER_PARTS
            pixels[walker.oid] = (int(np.count_nonzero(labels == walker.oid + 1)), int(np.count_nonzero(covered)))
        scale = np.float32(255.0 * LIGHT.exposure * self.gain(index))
        img *= scale
        if self._lit:  # the light conditions (off: the frames as before, bit for bit)
            img *= self.light_factors(cam, index, labels).astype(np.float32)
        if self.config.noise_sigma > 0:
            img += rng.standard_normal((h, w, 3), dtype=np.float32) * np.float32(self.config.noise_sigma)
        bgr = np.clip(np.rint(img[:, :, ::-1]), 0, 255).astype(np.uint8)
        return bgr, labels, lower, pixels

    def render_frame_masks(
        self, index: int, positions: dict[int, np.ndarray], rngs: list[np.random.Generator]
    ) -> tuple[list[np.ndarray], dict[str, float], list[np.ndarray]]:
        """Render frame ``index`` in every camera with its perfect masks (see :meth:`Scene.render_frame_masks`).

        The people are drawn from the scene's own states (also outside the room, in the corridors); ``positions``
        is not needed. The visible fraction per camera is that of the least visible person inside the room (NaN
        when there is none or none projects into the image).
        """
        inside = self.inside(index + 1)[:, index]
        prims = [self.primitives(a, index) for a in range(len(self.walkers))]
        images, masks, vis = [], [], {}
        for k, (camera, rng) in enumerate(zip(self.rig, rngs, strict=True)):
            bgr, labels, _, pixels = self.render_camera(k, index, rng, prims)
            fractions = [
                pixels[w.oid][0] / pixels[w.oid][1]
                for a, w in enumerate(self.walkers)
                if inside[a] and pixels.get(w.oid, (0, 0))[1] > 0
            ]
            vis[camera.name] = min(fractions) if fractions else float("nan")
            images.append(bgr)
            masks.append(np.where(labels > 0, 255, 0).astype(np.uint8))
        return images, vis, masks

    def render_frame(
        self, index: int, positions: dict[int, np.ndarray], rngs: list[np.random.Generator]
    ) -> tuple[list[np.ndarray], dict[str, float]]:
        """Render frame ``index`` (see :meth:`Scene.render_frame`)."""
        images, vis, _ = self.render_frame_masks(index, positions, rngs)
        return images, vis


# ----------------------------------------------------------------------------------------------------- the scenes


@register_scene(
    "s2-office",
    "S2 office: 2 people enter from opposite doors, shake hands, leave; furniture hides legs; 3 cams",
    seeded=True,
)
def _s2_office(seed: int = 0) -> Scene:
    return OfficeScene(OfficeConfig(seed=seed))


@register_scene(
    "s2-office-twocolour",
    "S2 office, Fig. 9 case: person 0 in a red front and a blue back (held out); 3 cams",
    seeded=True,
)
def _s2_office_twocolour(seed: int = 0) -> Scene:
    return OfficeScene(OfficeConfig(seed=seed, two_colour=True))


LOW_FPS = 3.125
"""Frame rate of ``s2-office-lowfps``: every 8th frame of the 25 frames/s scene."""


@register_scene(
    "s2-office-lowfps",
    "S2 office at 3.125 frames/s (every 8th frame of s2-office: the same people, 12 s in 38 frames); 3 cams",
    seeded=True,
)
def _s2_office_lowfps(seed: int = 0) -> Scene:
    k = 25.0 / LOW_FPS
    return OfficeScene(OfficeConfig(seed=seed, fps=LOW_FPS, frames=38, light_ramp=(round(120 / k), round(150 / k))))


@register_scene(
    "s2-office-meeting",
    "S2 office, 4 cams: the two people stand and talk 8 s at the meeting point before shaking hands (18 s)",
    seeded=True,
)
def _s2_office_meeting(seed: int = 0) -> Scene:
    return OfficeScene(OfficeConfig(seed=seed, cameras=4, talk=8.0, frames=500, light_ramp=(200, 230)))
