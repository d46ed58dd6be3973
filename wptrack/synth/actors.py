"""Moving actors of the synthetic outdoor scenes: ground paths (Catmull-Rom splines with stops), formations of
walkers, and the ray-castable bodies of people (swinging legs and arms, torso, head) and cars, with their ground-truth
class and size. Used by the plaza scenes (:mod:`wptrack.synth.plaza`) and reusable by any scene with people or cars.

Units: metres, seconds, radians; the ground is the world plane z = 0.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

HUMAN = "human"
"""Ground-truth class of people."""
VEHICLE = "vehicle"
"""Ground-truth class of cars."""

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
