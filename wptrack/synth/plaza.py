"""Scenes ``s3-*``: people and cars on a plaza seen by one high camera, after Juza et al. (Table 2).

Juza et al. track humans and vehicles with 3D templates from the binary motion images of one calibrated camera.
Their ten test sequences fall into four types (Table 2), replicated here on one synthetic plaza:

- ``s3-people``: up to five people walking randomly (smooth waypoint paths), entering and leaving at different
  times, occluding each other;
- ``s3-cars``: up to three cars: two pass each other in opposite lanes (the far one is partly hidden by the near
  one), the third makes a slow U-turn;
- ``s3-groups``: six people walking together (0.6-1.2 m apart, slowly changing formation) and one straggler;
- ``s3-mixed``: two cars and two people; one person crosses the road between the two cars' passages (partly
  hiding each car as it passes behind), the other strolls across the plaza.

The camera ``cam0`` (640x480, fx = fy = 580 px, OpenCV distortion k1 = -0.08, k2 = 0.01) hangs 7.5 m above the
ground at the world origin and looks along +y, 38 degrees down. The ground is the plane z = 0 (world x, y
horizontal, z up): a paved plaza (0.5 m tiles, y < 10.5 m), a kerb, an asphalt road with two lanes (centres
y = 12.9 m driving +x and y = 16.1 m driving -x, dashed centre line), parking bays with parked cars
(19.5 m < y < 23.5 m), a sidewalk and a building facade at y = 25 m. The image sees the ground from about 4 m (image
bottom, 9 m from the camera) to about 28 m (image top, 29 m from the camera). Static clutter: lamp posts, bollards,
benches, planters with bushes, a tree, a litter bin, parked cars.

Background-subtraction conditions are deliberately imperfect: textured ground, clutter that hides parts of the
objects, soft object shadows on up-facing static surfaces (ray cast towards the sun, a little bluish), static
shadows of the clutter, Gaussian sensor noise, a slow global illumination drift and bushes and a tree crown whose
leaves flicker in the wind. With OpenCV's MOG2 the shadow cores come out as foreground and their penumbrae as
shadow, camouflaged clothes as shadow or background, and the leaves as speckles. The static background is ray cast
once (and cached per process); per frame only the objects are ray cast, each body part inside its own image
bounding box, and the shadows inside theirs.

Objects: a person is two swinging legs, a pelvis, a chest, two swinging arms and a head with hair on top (all
ellipsoids), 1.6-1.9 m tall, in varied clothes (some close to the paving or asphalt colours); a car is a body box,
a cabin box (windows on the sides, roof in the body colour) and four dark wheels, 4.0-4.8 m long, 1.7-1.9 m wide,
1.4-1.6 m high, its heading along its velocity. Paths are centripetal Catmull-Rom splines through waypoints,
travelled with a smoothly varying speed (people 0.8-1.6 m/s, cars 2-8 m/s); a group is a formation around one
path. The layout, the objects and their paths are fixed (a fixed internal seed); the ``seed`` of
:func:`~wptrack.synth.base.render_scene` only changes the sensor noise.

Ground truth (``groundtruth.csv``): ``frame,id,x,y,z,class,length,width,height,orientation`` with the object's
ground-contact centre (z = 0), class ``human`` or ``vehicle``, its dimensions in metres (a human's length and width
are its body diameter: the width over the shoulders and arms) and its heading in the ground plane (radians,
``atan2(dy, dx)`` of the velocity, world frame). An object is listed on the frames where at least 25 % of its image
bounding box lies inside the image (it is rendered, and in the masks, whenever it is on its path). ``cam0_mask.avi``
holds the perfect foreground masks: the visible pixels of the moving objects (shadows excluded). The per-frame
``visibility`` of scene.json is the visible fraction of the least visible object of the ground truth (hidden by
clutter or another object; null when there is none). ``max_objects`` counts the objects of the ground truth at once
over the scene's default length (180 frames at 15 fps).
"""

from __future__ import annotations

import functools
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from wptrack.rig import Camera, Rig
from wptrack.synth.base import Scene, register_scene
from wptrack.synth.render import (
    Box,
    Cylinder,
    Light,
    StaticView,
    noisy,
    render_static,
    solid,
    value_noise,
    wood,
)

__all__ = [
    "CAMERA_POSITION",
    "HUMAN",
    "VEHICLE",
    "Car",
    "Formation",
    "Path",
    "Person",
    "PlazaActor",
    "PlazaScene",
    "plaza_background",
    "plaza_camera",
]

log = logging.getLogger(__name__)

HUMAN = "human"
"""Ground-truth class of people."""
VEHICLE = "vehicle"
"""Ground-truth class of cars."""

IMAGE_SIZE = (640, 480)
"""Image width and height, pixels."""
CAMERA_POSITION = (0.0, 0.0, 7.5)
"""Camera centre, metres."""
CAMERA_PITCH_DEG = 38.0
"""Downward tilt of the optical axis below the horizon, degrees (the camera looks along +y)."""
CAMERA_FOCAL = 580.0
"""Focal length fx = fy, pixels."""
CAMERA_DIST = (-0.08, 0.01, 0.0, 0.0, 0.0)
"""OpenCV distortion k1 k2 p1 p2 k3."""
FPS = 15.0
"""Frame rate, frames per second."""
FRAMES = 180
"""Default number of frames (12 s)."""
SUN = (-0.45, -0.35, 0.8)
"""Direction towards the sun (behind the camera, on its left: shadows fall away from it, to the right)."""
NOISE_SIGMA = 3.5
"""Sensor noise standard deviation, DN."""
SHADOW_STRENGTH = 0.55
"""Darkening of a fully shadowed up-facing surface (0..1)."""
SHADOW_TINT = (1.0, 0.92, 0.78)
"""Relative darkening of R, G, B in shadows (lit by the blue sky: red falls most), multiplies SHADOW_STRENGTH."""
MIN_IN_IMAGE = 0.25
"""Fraction of an object's image bounding box that must lie inside the image for it to be in the ground truth."""
ROAD_LANES = (12.9, 16.1)
"""Lane centres, y metres: the near lane drives +x, the far lane -x."""

LABEL_BUSH = 40
"""Label of the flickering vegetation (bushes, tree crown) in the static label image."""

_EPS = 1e-9
_BOX_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
_Rgb = tuple[float, float, float]


# ----------------------------------------------------------------------------------------------------- paths


def _catmull_rom(points: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Centripetal Catmull-Rom spline through ``points`` (K, 2), sampled about every ``step`` metres.

    Returns:
        ``(samples (M, 2), first_index (K,))``: the samples and the sample index of each waypoint.
    """
    p = np.vstack([2 * points[0] - points[1], points, 2 * points[-1] - points[-2]])
    out: list[np.ndarray] = []
    first = [0]
    for i in range(1, len(p) - 2):
        p0, p1, p2, p3 = p[i - 1], p[i], p[i + 1], p[i + 2]
        t0 = 0.0
        t1 = t0 + max(np.linalg.norm(p1 - p0), 1e-6) ** 0.5
        t2 = t1 + max(np.linalg.norm(p2 - p1), 1e-6) ** 0.5
        t3 = t2 + max(np.linalg.norm(p3 - p2), 1e-6) ** 0.5
        n = max(int(math.ceil(np.linalg.norm(p2 - p1) / step)), 2)
        t = np.linspace(t1, t2, n, endpoint=False)[:, None]
        a1 = (t1 - t) / (t1 - t0) * p0 + (t - t0) / (t1 - t0) * p1
        a2 = (t2 - t) / (t2 - t1) * p1 + (t - t1) / (t2 - t1) * p2
        a3 = (t3 - t) / (t3 - t2) * p2 + (t - t2) / (t3 - t2) * p3
        b1 = (t2 - t) / (t2 - t0) * a1 + (t - t0) / (t2 - t0) * a2
        b2 = (t3 - t) / (t3 - t1) * a2 + (t - t1) / (t3 - t1) * a3
        out.append((t2 - t) / (t2 - t1) * b1 + (t - t1) / (t2 - t1) * b2)
        first.append(first[-1] + n)
    out.append(points[-1:])
    return np.vstack(out), np.asarray(first)


@dataclass(frozen=True)
class Path:
    """A smooth ground path walked or driven with a smoothly varying speed.

    Attributes:
        waypoints: (x, y) points the path passes through, metres.
        speeds: Speed at each waypoint (or one speed for all), metres per second; interpolated along the path and
            smoothed over ``smooth_m``.
        start: Time at the first waypoint, seconds (negative: the object is already on its way at frame 0).
        smooth_m: Length of the speed-smoothing window, metres.
    """

    waypoints: tuple[tuple[float, float], ...]
    speeds: tuple[float, ...] | float
    start: float = 0.0
    smooth_m: float = 2.0

    @functools.cached_property
    def _table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pts = np.asarray(self.waypoints, dtype=np.float64)
        samples, first = _catmull_rom(pts, step=0.02)
        ds = np.linalg.norm(np.diff(samples, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(ds)])
        speeds = np.broadcast_to(np.asarray(self.speeds, dtype=np.float64), (len(pts),))
        v = np.interp(s, s[first], speeds)
        half = max(int(self.smooth_m / 0.02 / 2), 1)
        kernel = np.ones(2 * half + 1) / (2 * half + 1)
        v = np.convolve(np.pad(v, half, mode="edge"), kernel, mode="valid")
        t = self.start + np.concatenate([[0.0], np.cumsum(ds / np.maximum(0.5 * (v[1:] + v[:-1]), 0.05))])
        return samples, s, t

    @property
    def end(self) -> float:
        """Time at the last waypoint, seconds."""
        return float(self._table[2][-1])

    @property
    def length(self) -> float:
        """Path length, metres."""
        return float(self._table[1][-1])

    def positions(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions at ``times`` (seconds): ``((N, 2) metres, (N,) active)``.

        Outside the path's time span the motion continues straight along the end tangents at the end speeds (so
        that velocities are right at the ends); ``active`` is False there.
        """
        samples, s, t = self._table
        times = np.asarray(times, dtype=np.float64)
        arc = np.interp(times, t, s)
        pos = np.stack([np.interp(arc, s, samples[:, 0]), np.interp(arc, s, samples[:, 1])], axis=1)
        for sel, a, b in ((times < t[0], 0, 1), (times > t[-1], -1, -2)):
            if np.any(sel):
                step = samples[a] - samples[b]
                speed = abs(s[a] - s[b]) / abs(t[a] - t[b])
                pos[sel] = samples[a] + np.abs(times[sel] - t[a])[:, None] * speed * step / np.linalg.norm(step)
        return pos, (times >= t[0]) & (times <= t[-1])


@dataclass(frozen=True)
class Formation:
    """People walking together: slowly wobbling (along, across) offsets around a centre path.

    Attributes:
        centre: The group's path.
        offsets: Per member (along, across) offset from the centre in the walking direction's frame, metres.
        wobble: Amplitude of each member's slow offset oscillation, metres.
    """

    centre: Path
    offsets: tuple[tuple[float, float], ...]
    wobble: float = 0.12

    def member(self, k: int) -> _Member:
        """The track of member ``k``."""
        return _Member(self, k)


@dataclass(frozen=True)
class _Member:
    formation: Formation
    k: int

    def positions(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        f = self.formation
        times = np.asarray(times, dtype=np.float64)
        centre, active = f.centre.positions(times)
        ahead, _ = f.centre.positions(times + 0.5)
        behind, _ = f.centre.positions(times - 0.5)
        d = ahead - behind
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        d = np.where(norm > 1e-6, d / np.maximum(norm, 1e-12), np.array([1.0, 0.0]))
        left = np.stack([-d[:, 1], d[:, 0]], axis=1)
        along, across = f.offsets[self.k]
        ph = 1.7 * self.k
        along = along + f.wobble * np.sin(0.45 * times + ph)
        across = across + f.wobble * np.sin(0.33 * times + 2.1 * ph + 1.0)
        return centre + along[:, None] * d + across[:, None] * left, active


class _Track(Protocol):
    def positions(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...


# ----------------------------------------------------------------------------------------------------- shapes


def _yaw(psi: float) -> np.ndarray:
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _pitch(theta: float) -> np.ndarray:
    """Rotation about the local y axis (positive: the -z end swings towards -x)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@dataclass(frozen=True, eq=False)
class _Prim:
    """A body part: an oriented ellipsoid or box.

    Attributes:
        kind: ``"ellipsoid"`` or ``"box"``.
        center: (3,) world centre, metres.
        rot: (3, 3) local-to-world rotation (columns: the local axes in the world).
        half: (3,) semi-axes or half extents, metres.
        rgb: Albedo, linear RGB.
        top_rgb: Albedo where the local normal points up (hair, car roof), or None.
    """

    kind: str
    center: np.ndarray
    rot: np.ndarray
    half: np.ndarray
    rgb: np.ndarray
    top_rgb: np.ndarray | None = None

    def corners(self) -> np.ndarray:
        """(8, 3) corners of the oriented bounding box, metres."""
        return self.center[None, :] + (_BOX_SIGNS * self.half[None, :]) @ self.rot.T

    def intersect(self, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Nearest positive hit distance per ray (inf on a miss).

        Either the origins or the directions may be shared: camera rays have one origin, shadow rays one direction.

        Args:
            origin: (3,) or (N, 3) ray origins, metres.
            dirs: (N, 3) or (3,) ray directions (the distance is in units of their length).

        Returns:
            (N,) distances.
        """
        o = (origin - self.center) @ self.rot
        d = dirs @ self.rot
        if self.kind == "ellipsoid":
            inv = 1.0 / self.half
            os_ = o * inv
            ds = d * inv
            a = _rowdot(ds, ds)
            b = _rowdot(os_, ds)
            c = _rowdot(os_, os_) - 1.0
            disc = b * b - a * c
            hit = disc > 0
            t = (-b - np.sqrt(np.where(hit, disc, 0.0))) / a
            return np.where(hit & (t > 1e-6), t, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d
            t0 = (-self.half - o) * inv
            t1 = (self.half - o) * inv
        tmin = np.fmin(t0, t1)
        tmax = np.fmax(t0, t1)
        t_near = np.maximum(np.maximum(tmin[..., 0], tmin[..., 1]), tmin[..., 2])
        t_far = np.minimum(np.minimum(tmax[..., 0], tmax[..., 1]), tmax[..., 2])
        return np.where((t_near <= t_far) & (t_near > 1e-6), t_near, np.inf)

    def normals(self, origin: np.ndarray, dirs: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Local-frame unit normals at the hits ``origin + t dirs`` (``dirs`` (N, 3), ``t`` (N,) finite)."""
        p = (origin - self.center) @ self.rot + t[:, None] * (dirs @ self.rot)
        if self.kind == "ellipsoid":
            n = p / (self.half * self.half)
        else:
            q = np.abs(p) / self.half
            n = np.zeros_like(p)
            axis = np.argmax(q, axis=1)
            rows = np.arange(len(p))
            n[rows, axis] = np.sign(p[rows, axis])
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), _EPS)


def _rowdot(x: np.ndarray, y: np.ndarray) -> np.ndarray | float:
    """Row-wise dot product of (N, 3) or (3,) arrays."""
    if x.ndim == 2 and y.ndim == 2:
        return np.einsum("ij,ij->i", x, y)
    return x @ y if y.ndim == 1 else y @ x


@dataclass(frozen=True)
class Person:
    """A walking person.

    Attributes:
        height: Height, metres.
        girth: Horizontal scale of the body (1 = average build).
        shirt: Albedo of the torso and arms, linear RGB.
        trousers: Albedo of the legs and pelvis.
        skin: Albedo of the head.
        hair: Albedo of the top of the head.
    """

    height: float
    girth: float
    shirt: _Rgb
    trousers: _Rgb
    skin: _Rgb = (0.72, 0.52, 0.42)
    hair: _Rgb = (0.1, 0.07, 0.05)

    cls = HUMAN

    @property
    def diameter(self) -> float:
        """Body diameter: width over the shoulders and arms, metres."""
        return 2.0 * (0.215 * self.girth + 0.03)

    @property
    def dims(self) -> tuple[float, float, float]:
        """(length, width, height) for the ground truth, metres."""
        return self.diameter, self.diameter, self.height

    def box(self) -> tuple[np.ndarray, float]:
        """(3,) local half extents of a box holding the person (centred at height/2), and its height, metres."""
        r = 0.5 * self.diameter + 0.25
        return np.array([r, r, 0.5 * self.height]), self.height

    def stride(self, speed: np.ndarray) -> np.ndarray:
        """Length of a full gait cycle (two steps) at ``speed`` (m/s), metres."""
        return self.height * (0.52 + 0.25 * np.asarray(speed))

    def primitives(self, x: float, y: float, heading: float, phase: float, speed: float) -> list[_Prim]:
        """Body parts at ground position (x, y) metres, heading radians, gait phase radians, speed m/s."""
        k = self.height / 1.75
        g = self.girth
        leg = 0.86 * k
        amp = 0.42 * min(speed / 1.3, 1.2)
        swing = amp * math.sin(phase)
        hip = leg * math.cos(swing)
        yaw = _yaw(heading)
        base = np.array([x, y, 0.0])
        shirt = np.asarray(self.shirt, dtype=np.float64)
        trousers = np.asarray(self.trousers, dtype=np.float64)

        def part(local_center: Sequence[float], rot_local: np.ndarray, half: Sequence[float], rgb: np.ndarray) -> _Prim:
            return _Prim(
                "ellipsoid", base + yaw @ np.asarray(local_center), yaw @ rot_local, np.asarray(half, float), rgb
            )

        parts = []
        for side, sgn in ((1.0, 1.0), (-1.0, -1.0)):
            rot = _pitch(sgn * swing)
            centre = np.array([0.0, side * 0.095 * g, hip]) + rot @ np.array([0.0, 0.0, -0.5 * leg])
            parts.append(part(centre, rot, (0.075 * g, 0.07 * g, 0.5 * leg + 0.01), trousers))
            arm_rot = _pitch(-0.7 * sgn * swing)
            shoulder = np.array([0.0, side * (0.17 * g + 0.03), hip + 0.6 * k])
            centre = shoulder + arm_rot @ np.array([0.0, 0.0, -0.3 * k])
            parts.append(part(centre, arm_rot, (0.05 * g, 0.045 * g, 0.31 * k), shirt))
        eye = np.eye(3)
        parts.append(part((0.0, 0.0, hip + 0.1 * k), eye, (0.12 * g, 0.16 * g, 0.15 * k), trousers))
        parts.append(part((0.0, 0.0, hip + 0.4 * k), eye, (0.125 * g, 0.17 * g, 0.27 * k), shirt))
        r = 0.115 * k
        head = base + np.array([0.0, 0.0, hip + (self.height - leg) - r])
        parts.append(
            _Prim(
                "ellipsoid",
                head,
                yaw,
                np.array([r, 0.9 * r, r]),
                np.asarray(self.skin, float),
                np.asarray(self.hair, float),
            )
        )
        return parts


@dataclass(frozen=True)
class Car:
    """A car: body box, cabin box and four wheels.

    Attributes:
        length: Length, metres.
        width: Width, metres.
        height: Height (roof), metres.
        body: Albedo of the paint, linear RGB.
    """

    length: float
    width: float
    height: float
    body: _Rgb

    cls = VEHICLE

    @property
    def dims(self) -> tuple[float, float, float]:
        """(length, width, height) for the ground truth, metres."""
        return self.length, self.width, self.height

    def box(self) -> tuple[np.ndarray, float]:
        """(3,) local half extents of the car's box (centred at height/2), and its height, metres."""
        return np.array([0.5 * self.length, 0.5 * self.width, 0.5 * self.height]), self.height

    def stride(self, speed: np.ndarray) -> np.ndarray:
        """Unused for cars (no gait); ones."""
        return np.ones_like(np.asarray(speed, dtype=np.float64))

    def primitives(self, x: float, y: float, heading: float, phase: float = 0.0, speed: float = 0.0) -> list[_Prim]:
        """Car parts at ground position (x, y) metres and heading radians (``phase`` and ``speed`` unused)."""
        L, W, H = self.length, self.width, self.height
        yaw = _yaw(heading)
        base = np.array([x, y, 0.0])
        body = np.asarray(self.body, dtype=np.float64)
        glass = np.array([0.06, 0.07, 0.09])
        tyre = np.array([0.04, 0.04, 0.045])
        z_body = 0.56 * H + 0.05
        parts = [
            _Prim(
                "box",
                base + yaw @ np.array([0.0, 0.0, 0.5 * (0.2 + z_body)]),
                yaw,
                np.array([L / 2, W / 2, 0.5 * (z_body - 0.2)]),
                body,
            ),
            _Prim(
                "box",
                base + yaw @ np.array([-0.08 * L, 0.0, 0.5 * (z_body + H)]),
                yaw,
                np.array([0.24 * L, 0.44 * W, 0.5 * (H - z_body)]),
                glass,
                body,
            ),
        ]
        for fx in (-0.32 * L, 0.32 * L):
            for fy in (-(W / 2 - 0.12), W / 2 - 0.12):
                parts.append(
                    _Prim("ellipsoid", base + yaw @ np.array([fx, fy, 0.31]), yaw, np.array([0.31, 0.1, 0.31]), tyre)
                )
        return parts


Shape = Person | Car


@dataclass(frozen=True)
class PlazaActor:
    """A moving object of a plaza scene.

    Attributes:
        oid: Object id (ground truth).
        shape: Its :class:`Person` or :class:`Car`.
        track: Its :class:`Path` (or a :class:`Formation` member).
    """

    oid: int
    shape: Shape
    track: _Track


@dataclass
class _States:
    """Per-frame states of every actor: (A, N) arrays."""

    frames: int
    pos: np.ndarray  # (A, N, 2)
    active: np.ndarray  # (A, N) on its path
    present: np.ndarray  # (A, N) in the ground truth
    heading: np.ndarray  # (A, N)
    speed: np.ndarray  # (A, N)
    phase: np.ndarray  # (A, N)


# ----------------------------------------------------------------------------------------------------- background


def plaza_camera() -> Camera:
    """The scene camera ``cam0`` (see the module docstring)."""
    pitch = math.radians(CAMERA_PITCH_DEG)
    pos = np.asarray(CAMERA_POSITION, dtype=np.float64)
    target = pos + 10.0 * np.array([0.0, math.cos(pitch), -math.sin(pitch)])
    return Camera.look_at("cam0", IMAGE_SIZE[0], IMAGE_SIZE[1], pos, target, fx=CAMERA_FOCAL, dist=CAMERA_DIST)


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _tiles(x: np.ndarray, y: np.ndarray, size: float, rgb: np.ndarray, seed: int) -> np.ndarray:
    """Paving: square tiles of ``size`` metres, per-tile brightness, darker joints, fine grain."""
    lattice = np.random.default_rng(seed).random((256, 256))
    u, v = x / size, y / size
    tu, tv = np.floor(u).astype(np.int64) % 256, np.floor(v).astype(np.int64) % 256
    fu, fv = u - np.floor(u), v - np.floor(v)
    edge = np.minimum(np.minimum(fu, 1 - fu), np.minimum(fv, 1 - fv)) * size
    joint = 0.72 + 0.28 * _smoothstep(0.005, 0.02, edge)
    grain = value_noise(x / 0.06, y / 0.06, seed + 1) - 0.5
    stain = value_noise(x / 1.7, y / 1.7, seed + 2) - 0.5
    factor = joint * (0.92 + 0.16 * lattice[tu, tv] + 0.12 * grain + 0.15 * stain)
    return rgb[None, :] * factor[:, None]


def _ground_texture(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Plaza paving, kerb, asphalt with markings, parking bays, sidewalk (by world y, metres)."""
    x, y = points[:, 0], points[:, 1]
    out = _tiles(x, y, 0.5, np.array([0.55, 0.52, 0.47]), seed=21)
    kerb = (y >= 10.5) & (y < 10.8)
    out[kerb] = np.array([0.68, 0.67, 0.64]) * (0.95 + 0.1 * value_noise(x[kerb] / 0.1, y[kerb] / 0.1, 5))[:, None]
    road = (y >= 10.8) & (y < 23.5)
    xr, yr = x[road], y[road]
    n = value_noise(xr / 0.08, yr / 0.08, 31) - 0.5
    patch = value_noise(xr / 2.5, yr / 2.5, 32) - 0.5
    asphalt = np.array([0.21, 0.21, 0.22])[None, :] * (1.0 + 0.22 * n + 0.25 * patch)[:, None]
    paint = np.array([0.72, 0.72, 0.68])
    centre_line = (np.abs(yr - 14.5) < 0.07) & (np.mod(xr, 6.0) < 3.0)
    edge_line = np.abs(yr - 19.5) < 0.06
    bays = (yr > 19.5) & (yr < 23.4) & (np.mod(xr + 0.05, 2.6) < 0.1)
    asphalt[centre_line | edge_line | bays] = paint
    out[road] = asphalt
    walk = y >= 23.5
    out[walk] = _tiles(x[walk], y[walk], 0.3, np.array([0.6, 0.58, 0.55]), seed=41)
    return out


def _facade_texture(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """A building facade (wall facing -y): plaster with rows of windows and shop windows."""
    x, z = points[:, 0], points[:, 2]
    base = noisy((0.62, 0.55, 0.46), amplitude=0.06, scale_m=0.5, seed=51)(points, normals)
    win = (np.mod(x, 3.2) > 0.6) & (np.mod(x, 3.2) < 2.3) & (np.mod(z, 3.3) > 1.0) & (np.mod(z, 3.3) < 2.4) & (z > 3)
    shop = (np.mod(x, 6.0) > 0.5) & (np.mod(x, 6.0) < 5.0) & (z > 0.3) & (z < 2.6)
    base[win] = (0.12, 0.15, 0.2)
    base[shop] = (0.09, 0.1, 0.12)
    return base


def _parked_car(x: float, y: float, rgb: _Rgb, label: int) -> list[Box | Cylinder]:
    """A static parked car, nose along +-y (axis-aligned boxes)."""
    return [
        Box((x - 0.9, y - 2.2, 0.2), (x + 0.9, y + 2.2, 0.88), solid(rgb), label=label),
        Box((x - 0.8, y - 1.2, 0.88), (x + 0.8, y + 0.9, 1.45), solid((0.07, 0.08, 0.1)), label=label),
    ]


def _static_objects() -> list[Box | Cylinder]:
    """The plaza's ground, facade and clutter (fixed layout)."""
    concrete = noisy((0.6, 0.59, 0.56), amplitude=0.08, scale_m=0.08, seed=61)
    metal = solid((0.16, 0.17, 0.18))
    leaves = noisy((0.14, 0.26, 0.09), amplitude=0.35, scale_m=0.09, seed=62)
    objects: list[Box | Cylinder] = [
        Box((-80.0, -10.0, -0.5), (80.0, 25.0, 0.0), _ground_texture, label=1),
        Box((-80.0, 25.0, 0.0), (80.0, 25.5, 14.0), _facade_texture, label=2),
    ]
    # lamp posts (pole + lamp head)
    for i, (x, y) in enumerate(((-4.2, 7.4), (5.8, 10.0), (-9.5, 24.0), (6.0, 24.0))):
        objects.append(Cylinder((x, y), 0.07, 0.0, 4.6, metal, label=10 + i))
        objects.append(Box((x - 0.25, y - 0.15, 4.6), (x + 0.25, y + 0.15, 4.75), metal, label=10 + i))
    # bollards along the kerb
    for i, x in enumerate((-9.0, -6.0, -3.0, 3.0, 6.0, 9.0)):
        objects.append(Cylinder((x, 10.3), 0.09, 0.0, 0.9, solid((0.25, 0.25, 0.27)), label=20 + i))
    # benches (seat, back, two legs)
    for i, (x0, y0) in enumerate(((1.2, 5.0), (-7.8, 7.4))):
        bench = wood((0.5, 0.33, 0.18), ring_m=0.05, grain_axis=0, seed=70 + i)
        objects += [
            Box((x0, y0, 0.42), (x0 + 1.8, y0 + 0.45, 0.47), bench, label=30 + i),
            Box((x0, y0 + 0.4, 0.47), (x0 + 1.8, y0 + 0.46, 0.85), bench, label=30 + i),
            Box((x0 + 0.1, y0 + 0.05, 0.0), (x0 + 0.2, y0 + 0.4, 0.42), metal, label=30 + i),
            Box((x0 + 1.6, y0 + 0.05, 0.0), (x0 + 1.7, y0 + 0.4, 0.42), metal, label=30 + i),
        ]
    # planters with bushes (the bushes flicker), a tree, a litter bin
    for x0, y0 in ((4.2, 4.6), (6.4, 7.8)):
        objects.append(Box((x0 - 0.7, y0 - 0.5, 0.0), (x0 + 0.7, y0 + 0.5, 0.5), concrete, label=35))
        objects.append(Cylinder((x0, y0), 0.55, 0.5, 1.25, leaves, label=LABEL_BUSH))
    objects.append(Cylinder((-7.4, 10.0), 0.16, 0.0, 2.6, solid((0.3, 0.22, 0.15)), label=36))
    objects.append(Cylinder((-7.4, 10.0), 1.5, 2.6, 4.8, leaves, label=LABEL_BUSH))
    objects.append(Cylinder((2.6, 9.7), 0.28, 0.0, 0.95, solid((0.12, 0.25, 0.15)), label=37))
    # parked cars in the bays
    for i, (x, rgb) in enumerate(
        (
            (-10.35, (0.7, 0.7, 0.68)),
            (-7.75, (0.1, 0.14, 0.3)),
            (-2.55, (0.5, 0.51, 0.53)),
            (5.25, (0.55, 0.1, 0.07)),
            (10.45, (0.24, 0.24, 0.25)),
        )
    ):
        objects += _parked_car(x, 21.5, rgb, label=50 + i)
    return objects


def _shadow_hits(obj: Box | Cylinder, points: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """Whether rays from ``points`` (N, 3) towards the sun hit a static box or vertical cylinder."""
    if isinstance(obj, Box):
        prim = _Prim(
            "box",
            0.5 * (np.asarray(obj.lo) + np.asarray(obj.hi)),
            np.eye(3),
            0.5 * (np.asarray(obj.hi) - np.asarray(obj.lo)),
            np.zeros(3),
        )
        return np.isfinite(prim.intersect(points, sun))
    ox = points[:, 0] - obj.center[0]
    oy = points[:, 1] - obj.center[1]
    a = sun[0] ** 2 + sun[1] ** 2
    b = 2 * (ox * sun[0] + oy * sun[1])
    c = ox * ox + oy * oy - obj.radius**2
    disc = b * b - 4 * a * c
    ok = disc >= 0
    sq = np.sqrt(np.where(ok, disc, 0.0))
    t_in = (-b - sq) / (2 * a)
    t_out = (-b + sq) / (2 * a)
    z_in = points[:, 2] + np.maximum(t_in, 0.0) * sun[2]
    z_out = points[:, 2] + t_out * sun[2]
    return ok & (t_out > 1e-6) & (z_out >= obj.z0) & (z_in <= obj.z1)


@dataclass(frozen=True)
class PlazaBackground:
    """The static plaza as seen by ``cam0``, ray cast once.

    Attributes:
        view: The static view (radiance includes the static shadows).
        ground: (H, W, 3) float64 world points of up-facing static surfaces (shadow receivers), NaN elsewhere, metres.
        sunlit: (H, W) float32 fraction of direct sun on each pixel's surface (0 in static shadow).
        bush_index: (K,) flat indices of flickering vegetation pixels.
        bush_uv: (K, 2) float64 pixel coordinates of those pixels.
        light: The lighting.
    """

    view: StaticView
    ground: np.ndarray
    sunlit: np.ndarray
    bush_index: np.ndarray
    bush_uv: np.ndarray
    light: Light


@functools.lru_cache(maxsize=1)
def plaza_background() -> PlazaBackground:
    """Ray cast the static plaza once per process (cached; the arrays are read-only)."""
    import cv2

    start = time.perf_counter()
    cam = plaza_camera()
    light = Light(direction=SUN, ambient=0.4, diffuse=0.65, exposure=1.0)
    objects = _static_objects()
    view = render_static(cam, objects, light, background=(0.55, 0.62, 0.72))
    h, w = cam.height, cam.width
    ground = np.full((h * w, 3), np.nan)
    ground[view.up_index] = view.up_points
    # static shadows of the clutter on up-facing surfaces (culled by each object's shadow footprint)
    sun = light.unit
    pts = ground[view.up_index]
    shadow = np.zeros(len(pts), dtype=bool)
    for obj in objects[2:]:
        if isinstance(obj, Box):
            lo, hi = np.asarray(obj.lo), np.asarray(obj.hi)
        else:
            lo = np.array([obj.center[0] - obj.radius, obj.center[1] - obj.radius, obj.z0])
            hi = np.array([obj.center[0] + obj.radius, obj.center[1] + obj.radius, obj.z1])
        reach = hi[2] / sun[2] * np.abs(sun[:2])
        sel = (
            (pts[:, 2] < hi[2])
            & (pts[:, 0] >= lo[0] - reach[0] - 0.01)
            & (pts[:, 0] <= hi[0] + reach[0] + 0.01)
            & (pts[:, 1] >= lo[1] - reach[1] - 0.01)
            & (pts[:, 1] <= hi[1] + reach[1] + 0.01)
        )
        if np.any(sel):
            idx = np.flatnonzero(sel)
            shadow[idx] |= _shadow_hits(obj, pts[idx] + np.array([0.0, 0.0, 1e-4]), sun)
    hard = np.zeros(h * w, dtype=np.float32)
    hard[view.up_index] = shadow
    soft = cv2.GaussianBlur(hard.reshape(h, w), (5, 5), 1.0)
    up = np.zeros(h * w, dtype=np.float32)
    up[view.up_index] = 1.0
    soft *= up.reshape(h, w)
    sunlit = (1.0 - soft).astype(np.float32)
    tint = np.asarray(SHADOW_TINT, dtype=np.float32)
    radiance = view.radiance * (1.0 - SHADOW_STRENGTH * soft[..., None] * tint[None, None, :])
    view.radiance = radiance.astype(np.float32)
    bush_index = np.flatnonzero(view.label.reshape(-1) == LABEL_BUSH)
    bush_uv = np.stack([bush_index % w, bush_index // w], axis=1).astype(np.float64)
    for arr in (view.radiance, view.depth, view.label, view.dirs, ground, sunlit, bush_index, bush_uv):
        arr.setflags(write=False)
    log.debug("plaza background ray cast in %.2f s", time.perf_counter() - start)
    return PlazaBackground(
        view=view,
        ground=ground.reshape(h, w, 3),
        sunlit=sunlit,
        bush_index=bush_index,
        bush_uv=bush_uv,
        light=light,
    )


# ----------------------------------------------------------------------------------------------------- rendering


def _image_box(cam: Camera, corners: np.ndarray, pad: int = 2) -> tuple[int, int, int, int] | None:
    """Half-open pixel box ``(u0, u1, v0, v1)`` holding the projection of ``corners`` (M, 3), or None."""
    uv, depth = cam.project(corners)
    if np.all(depth <= 0.05):
        return None
    if np.any(depth <= 0.05):
        return 0, cam.width, 0, cam.height
    u0 = max(int(np.floor(uv[:, 0].min())) - pad, 0)
    u1 = min(int(np.ceil(uv[:, 0].max())) + pad + 1, cam.width)
    v0 = max(int(np.floor(uv[:, 1].min())) - pad, 0)
    v1 = min(int(np.ceil(uv[:, 1].max())) + pad + 1, cam.height)
    if u0 >= u1 or v0 >= v1:
        return None
    return u0, u1, v0, v1


class PlazaScene(Scene):
    """A plaza scene: one camera, people and cars with class, size and heading ground truth, perfect masks.

    Args:
        actors: The moving objects.
        frames: Default number of frames.
        fps: Frames per second.
    """

    writes_masks = True

    def __init__(self, actors: Sequence[PlazaActor], frames: int = FRAMES, fps: float = FPS) -> None:
        self.actors = list(actors)
        self.fps = float(fps)
        self.default_frames = int(frames)
        cam = plaza_camera()
        self.rig = Rig(cameras=(cam,), volume=((-16.0, 3.0, 0.0), (16.0, 27.0, 3.0)))
        self.noise_sigma = NOISE_SIGMA
        self._states: _States | None = None

    # -- motion and ground truth

    def states(self, frames: int) -> _States:
        """Per-frame states of every actor for at least ``frames`` frames (cached)."""
        if self._states is not None and self._states.frames >= frames:
            return self._states
        n = max(int(frames), self.default_frames)
        dt = 1.0 / self.fps
        times = np.arange(n) * dt
        h = 0.02
        cam = self.rig[0]
        count = len(self.actors)
        pos = np.zeros((count, n, 2))
        active = np.zeros((count, n), dtype=bool)
        present = np.zeros((count, n), dtype=bool)
        heading = np.zeros((count, n))
        speed = np.zeros((count, n))
        phase = np.zeros((count, n))
        for a, actor in enumerate(self.actors):
            p, act = actor.track.positions(times)
            ahead, _ = actor.track.positions(times + h)
            behind, _ = actor.track.positions(times - h)
            vel = (ahead - behind) / (2 * h)
            sp = np.linalg.norm(vel, axis=1)
            ang = np.arctan2(vel[:, 1], vel[:, 0])
            moving = sp > 0.05
            if np.any(moving):
                idx = np.where(moving, np.arange(n), -1)
                idx = np.maximum.accumulate(idx)
                idx[idx < 0] = np.flatnonzero(moving)[0]
                ang = ang[idx]
            else:
                ang = np.zeros(n)
            stride = actor.shape.stride(sp)
            ph = 2 * np.pi * np.cumsum(sp * dt / stride) + 1.3 * actor.oid
            pos[a], active[a], heading[a], speed[a], phase[a] = p, act, ang, sp, ph
            # in the ground truth where >= MIN_IN_IMAGE of the object's image bounding box is inside the image
            half, height = actor.shape.box()
            c, s = np.cos(ang), np.sin(ang)
            local = _BOX_SIGNS * half[None, :] + np.array([0.0, 0.0, 0.5 * height])
            wx = p[:, 0, None] + c[:, None] * local[None, :, 0] - s[:, None] * local[None, :, 1]
            wy = p[:, 1, None] + s[:, None] * local[None, :, 0] + c[:, None] * local[None, :, 1]
            wz = np.broadcast_to(local[None, :, 2], wx.shape)
            uv, depth = cam.project(np.stack([wx, wy, wz], axis=-1).reshape(-1, 3))
            uv = uv.reshape(n, 8, 2)
            ok = np.all(depth.reshape(n, 8) > 0.1, axis=1)
            lo, hi = uv.min(axis=1), uv.max(axis=1)
            area = np.prod(np.maximum(hi - lo, 1e-6), axis=1)
            inside = np.prod(np.clip(np.minimum(hi, [cam.width, cam.height]) - np.maximum(lo, 0.0), 0.0, None), axis=1)
            present[a] = act & ok & (inside >= MIN_IN_IMAGE * area)
        self._states = _States(n, pos, active, present, heading, speed, phase)
        return self._states

    def trajectories(self, frames: int) -> dict[int, np.ndarray]:
        """Ground-contact centres: object id -> (frames, 3) metres (z = 0); NaN where not in the ground truth."""
        st = self.states(frames)
        out = {}
        for a, actor in enumerate(self.actors):
            traj = np.full((frames, 3), np.nan)
            sel = st.present[a, :frames]
            traj[sel, :2] = st.pos[a, :frames][sel]
            traj[sel, 2] = 0.0
            out[actor.oid] = traj
        return out

    def groundtruth_columns(self, frames: int) -> dict[str, dict[int, np.ndarray]]:
        """class (human/vehicle), length, width, height (metres) and orientation (heading, radians) per object."""
        st = self.states(frames)
        cols: dict[str, dict[int, np.ndarray]] = {k: {} for k in ("class", "length", "width", "height", "orientation")}
        for a, actor in enumerate(self.actors):
            length, width, height = actor.shape.dims
            cols["class"][actor.oid] = np.full(frames, actor.shape.cls, dtype=object)
            cols["length"][actor.oid] = np.full(frames, length)
            cols["width"][actor.oid] = np.full(frames, width)
            cols["height"][actor.oid] = np.full(frames, height)
            cols["orientation"][actor.oid] = np.angle(np.exp(1j * st.heading[a, :frames]))
        return cols

    def classes(self) -> list[str]:
        """Classes present in the scene, sorted."""
        return sorted({actor.shape.cls for actor in self.actors})

    def max_objects(self, frames: int | None = None) -> int:
        """Largest number of objects in the ground truth at once over ``frames`` (default: the scene's)."""
        n = self.default_frames if frames is None else int(frames)
        return int(self.states(n).present[:, :n].sum(axis=0).max())

    def hints(self) -> dict[str, Any]:
        """Tracker hints: tracker family, ground plane, most objects at once, object classes."""
        return {
            "tracker": "templates",
            "ground": {"origin": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]},
            "max_objects": self.max_objects(),
            "classes": self.classes(),
        }

    # -- pixels

    def gain(self, index: int) -> np.ndarray:
        """(3,) RGB illumination gain at frame ``index``: a slow drift of brightness and colour temperature."""
        t = index / self.fps
        b = 1.0 + 0.035 * math.sin(2 * math.pi * t / 16.0 + 0.4) - 0.02 * math.sin(2 * math.pi * t / 37.0)
        warm = 0.012 * math.sin(2 * math.pi * t / 23.0)
        return b * np.array([1.0 + warm, 1.0, 1.0 - warm])

    def primitives(self, index: int) -> list[tuple[PlazaActor, list[_Prim]]]:
        """Body parts of every actor on its path at frame ``index``."""
        st = self.states(index + 1)
        out = []
        for a, actor in enumerate(self.actors):
            if not st.active[a, index]:
                continue
            x, y = st.pos[a, index]
            prims = actor.shape.primitives(
                float(x), float(y), float(st.heading[a, index]), float(st.phase[a, index]), float(st.speed[a, index])
            )
            out.append((actor, prims))
        return out

    def render_labels(
        self, index: int, rng: np.random.Generator
    ) -> tuple[np.ndarray, np.ndarray, dict[int, tuple[int, int]]]:
        """Render frame ``index`` with its label image (tests, debugging, perfect masks).

        Args:
            index: 0-based frame index.
            rng: Sensor noise generator (one (H, W, 3) draw per call).

        Returns:
            ``(bgr, labels, pixels)``: the (H, W, 3) uint8 BGR image; an (H, W) int32 label image with ``oid + 1`` on
            the visible pixels of each object, 0 elsewhere; object id -> (visible pixels, pixels it would cover
            without occluders) for the objects on their path.
        """
        import cv2

        bg = plaza_background()
        view, light = bg.view, bg.light
        cam = view.camera
        h, w = cam.height, cam.width
        t = index / self.fps
        img = view.radiance.copy()
        flat = img.reshape(-1, 3)

        # wind in the leaves: a drifting multiplicative pattern on the vegetation
        if len(bg.bush_index):
            gust = 0.12 + 0.06 * math.sin(2 * math.pi * t / 5.0)
            uu, vv = bg.bush_uv[:, 0], bg.bush_uv[:, 1]
            n = value_noise(uu / 4.0 + 1.3 * t, vv / 4.0 - 0.7 * t, 77) - 0.5
            flat[bg.bush_index] *= (1.0 + 2.0 * gust * n).astype(np.float32)[:, None]

        actors = self.primitives(index)
        sun = light.unit
        tint = np.asarray(SHADOW_TINT, dtype=np.float32)
        up = np.array([0.0, 0.0, 1e-3])
        for _actor, prims in actors:
            # shadow footprint: the parts' corners and their projections along the sun on z = 0
            corners = np.vstack([p.corners() for p in prims])
            foot = corners - (corners[:, 2:3] / sun[2]) * sun[None, :]
            lo = np.minimum(corners[:, :2].min(axis=0), foot[:, :2].min(axis=0))
            hi = np.maximum(corners[:, :2].max(axis=0), foot[:, :2].max(axis=0))
            rect = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (0.0, 1.0)])
            box = _image_box(cam, rect, pad=4)
            if box is None:
                continue
            u0, u1, v0, v1 = box
            pts = bg.ground[v0:v1, u0:u1].reshape(-1, 3)
            valid = np.isfinite(pts[:, 0])
            if not np.any(valid):
                continue
            origins = pts[valid] + up
            hit = np.zeros(len(origins), dtype=bool)
            for prim in prims:
                hit |= np.isfinite(prim.intersect(origins, sun))
            if not np.any(hit):
                continue
            hard = np.zeros(len(pts), dtype=np.float32)
            hard[np.flatnonzero(valid)[hit]] = 1.0
            soft = cv2.GaussianBlur(hard.reshape(v1 - v0, u1 - u0), (5, 5), 1.0)
            amount = SHADOW_STRENGTH * soft * bg.sunlit[v0:v1, u0:u1] * valid.reshape(v1 - v0, u1 - u0)
            img[v0:v1, u0:u1] *= 1.0 - amount[..., None] * tint[None, None, :]

        zbuf = view.depth.copy()
        labels = np.zeros((h, w), dtype=np.int32)
        dirs = view.dirs.reshape(h, w, 3)
        totals: dict[int, int] = {}
        for actor, prims in actors:
            covered = np.zeros((h, w), dtype=bool)
            for prim in prims:
                box = _image_box(cam, prim.corners())
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
                img[v0:v1, u0:u1][front] = albedo * (light.ambient + light.diffuse * lam)[:, None]
                zsub[front] = tf
                labels[v0:v1, u0:u1][front] = actor.oid + 1
            totals[actor.oid] = int(np.count_nonzero(covered))
        pixels = {oid: (int(np.count_nonzero(labels == oid + 1)), total) for oid, total in totals.items()}

        scale = (255.0 * light.exposure * self.gain(index)).astype(np.float32)
        img *= scale[None, None, :]
        if self.noise_sigma > 0:
            img += rng.standard_normal((h, w, 3), dtype=np.float32) * np.float32(self.noise_sigma)
        bgr = np.clip(np.rint(img[:, :, ::-1]), 0, 255).astype(np.uint8)
        return bgr, labels, pixels

    def render_frame_masks(
        self, index: int, positions: dict[int, np.ndarray], rngs: list[np.random.Generator]
    ) -> tuple[list[np.ndarray], dict[str, float], list[np.ndarray]]:
        """Render frame ``index`` and its perfect foreground mask (see :meth:`Scene.render_frame_masks`).

        The objects are drawn from the scene's own states (also where they are on their path but outside the ground
        truth, at the image border); ``positions`` is not needed. The visible fraction is that of the least visible
        object of the ground truth (NaN when there is none).
        """
        bgr, labels, pixels = self.render_labels(index, rngs[0])
        st = self.states(index + 1)
        fractions = [
            vis / total
            for a, actor in enumerate(self.actors)
            if st.present[a, index] and actor.oid in pixels
            for vis, total in [pixels[actor.oid]]
            if total > 0
        ]
        vis = {self.rig[0].name: min(fractions) if fractions else float("nan")}
        mask = np.where(labels > 0, 255, 0).astype(np.uint8)
        return [bgr], vis, [mask]

    def render_frame(
        self, index: int, positions: dict[int, np.ndarray], rngs: list[np.random.Generator]
    ) -> tuple[list[np.ndarray], dict[str, float]]:
        """Render frame ``index`` (see :meth:`Scene.render_frame`)."""
        images, vis, _ = self.render_frame_masks(index, positions, rngs)
        return images, vis


# ----------------------------------------------------------------------------------------------------- the scenes

_SHIRTS: tuple[_Rgb, ...] = (
    (0.6, 0.1, 0.1),
    (0.1, 0.18, 0.45),
    (0.82, 0.82, 0.78),
    (0.2, 0.42, 0.2),
    (0.75, 0.58, 0.2),
    (0.42, 0.28, 0.48),
    (0.12, 0.12, 0.13),
    (0.2, 0.5, 0.6),
)
_TROUSERS: tuple[_Rgb, ...] = ((0.14, 0.17, 0.3), (0.08, 0.08, 0.09), (0.35, 0.28, 0.22), (0.25, 0.25, 0.26))
_SKINS: tuple[_Rgb, ...] = ((0.75, 0.55, 0.45), (0.55, 0.38, 0.28), (0.35, 0.24, 0.18), (0.8, 0.64, 0.55))
_HAIRS: tuple[_Rgb, ...] = ((0.08, 0.06, 0.05), (0.3, 0.2, 0.1), (0.6, 0.5, 0.3), (0.4, 0.4, 0.4))
_PAVING_LIKE: _Rgb = (0.52, 0.49, 0.44)
"""Clothing close to the paving colour (hard for background subtraction)."""
_ASPHALT_LIKE: _Rgb = (0.2, 0.2, 0.21)
"""Clothing or paint close to the asphalt colour."""


def _people(count: int, seed: int, camouflage: Sequence[int] = ()) -> list[Person]:
    """``count`` people of varied height, build and clothing; those in ``camouflage`` wear ground-like colours."""
    rng = np.random.default_rng(seed)
    shirts = rng.permutation(len(_SHIRTS))
    trousers_order = rng.permutation(len(_TROUSERS))
    out = []
    for i in range(count):
        shirt = _SHIRTS[int(shirts[i % len(shirts)])]
        trousers = _TROUSERS[int(trousers_order[i % len(trousers_order)])]
        if i in camouflage:
            shirt, trousers = (_PAVING_LIKE, _ASPHALT_LIKE) if i % 2 == 0 else (_ASPHALT_LIKE, _PAVING_LIKE)
        out.append(
            Person(
                height=float(rng.uniform(1.6, 1.9)),
                girth=float(rng.uniform(0.9, 1.12)),
                shirt=shirt,
                trousers=trousers,
                skin=_SKINS[int(rng.integers(len(_SKINS)))],
                hair=_HAIRS[int(rng.integers(len(_HAIRS)))],
            )
        )
    return out


def people_actors() -> list[PlazaActor]:
    """``s3-people``: five people on waypoint paths, entering and leaving at different times."""
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


def _car(length: float, width: float, height: float, rgb: _Rgb) -> Car:
    return Car(length=length, width=width, height=height, body=rgb)


def cars_actors() -> list[PlazaActor]:
    """``s3-cars``: two cars passing each other in opposite lanes, a third making a U-turn."""
    near, far = ROAD_LANES
    u_turn = Path(
        (
            (15.5, far),
            (9.0, far),
            (4.0, far + 0.5),
            (0.8, 18.0),
            (-2.2, 17.3),
            (-3.2, 15.2),
            (-2.4, 12.9),
            (0.4, 11.9),
            (4.5, 12.2),
            (9.0, near),
            (17.0, near),
        ),
        (5.0, 4.5, 3.2, 2.3, 2.2, 2.2, 2.3, 2.8, 3.5, 4.5, 5.0),
        1.0,
        smooth_m=4.0,
    )
    return [
        PlazaActor(0, _car(4.5, 1.8, 1.5, (0.24, 0.24, 0.26)), Path(((-17.0, near), (17.0, near)), 6.5, -1.0)),
        PlazaActor(1, _car(4.2, 1.75, 1.45, (0.8, 0.8, 0.78)), Path(((18.0, far), (-18.0, far)), 5.5, -1.3)),
        PlazaActor(2, _car(4.7, 1.85, 1.55, (0.32, 0.4, 0.55)), u_turn),
    ]


def groups_actors() -> list[PlazaActor]:
    """``s3-groups``: a group of six walking together and one straggler following it."""
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


def mixed_actors() -> list[PlazaActor]:
    """``s3-mixed``: two cars on the road and two people, one crossing the road between the cars' passages."""
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


@register_scene("s3-people", "Juza et al.: up to 5 people walking randomly on a plaza, occlusions; 1 high camera")
def _s3_people() -> Scene:
    return PlazaScene(people_actors())


@register_scene("s3-cars", "Juza et al.: 3 cars, two passing each other (occlusion), one U-turn; 1 high camera")
def _s3_cars() -> Scene:
    return PlazaScene(cars_actors())


@register_scene("s3-groups", "Juza et al.: a group of 6 people walking together and a straggler; 1 high camera")
def _s3_groups() -> Scene:
    return PlazaScene(groups_actors())


@register_scene("s3-mixed", "Juza et al.: 2 cars and 2 people, one crossing the road between the cars; 1 high camera")
def _s3_mixed() -> Scene:
    return PlazaScene(mixed_actors())
