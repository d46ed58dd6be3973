"""Scenes ``s3-*``: people and cars on a plaza seen by one high camera, after Juza et al. (Table 2).

Juza et al. track humans and vehicles with 3D templates from the binary motion images of one calibrated camera.
Their ten test sequences fall into four types (Table 2), replicated here on one synthetic plaza:

- ``s3-people``: up to five people walking randomly (smooth waypoint paths), entering and leaving at different
  times, occluding each other;
- ``s3-cars``: up to three cars: two pass each other in opposite lanes (the far one is partly hidden by the near
  one), the third makes a slow U-turn;
- ``s3-groups``: five or six people (six at seed 0) walking together (0.6-1.2 m apart, slowly changing formation)
  and one straggler;
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
path.

Scene seeds (the ``seed`` of :func:`~wptrack.synth.base.render_scene`, also the sensor noise's): the plaza, its
clutter and the camera never change. At seed 0 the objects, their looks and paths are the fixed sequences written
out below (all published numbers use them; a test pins their ground truth). Any other seed draws a new sequence of
the same scene type (the counts, events and speed ranges above): new paths, speeds, start times, sizes, clothes and
paints, all from ``np.random.default_rng([zlib.crc32(name), seed])``, kept only when the objects stay apart, off the
clutter (people) or on the road (cars), and in view long enough (:mod:`wptrack.synth.plaza_seeds`).

Ground truth (``groundtruth.csv``): ``frame,id,x,y,z,class,length,width,height,orientation`` with the object's
ground-contact centre (z = 0), class ``human`` or ``vehicle``, its dimensions in metres (a human's length and width
are its body diameter: the width over the shoulders and arms) and its heading in the ground plane (radians,
``atan2(dy, dx)`` of the velocity, world frame). An object is listed on the frames where at least 90 % of the image
bounding box of its listed dimensions lies inside the image (``MIN_IN_IMAGE``: nearly whole in view, as real clips'
annotators label people; until 2026-11-27 25 % of a box holding a person's arms' reach); it is rendered, and in the
masks, whenever it is on its path. ``cam0_mask.avi`` holds the perfect foreground masks: the visible pixels of the
moving objects (shadows excluded). The per-frame ``visibility`` of scene.json is the visible fraction of the least
visible object in view (``IN_VIEW``: 25 % of the box holding it; hidden by clutter or another object; null when there
is none), and ``max_objects`` counts the objects in view at once over the scene's default length (180 frames at 15
fps): both as before the ground truth's rule changed, as are the scenes' draws and timings.

Hard conditions, each a switch off by default (objects standing in view at frame 0, people stopping and walking
on, a low sun with hard shadows, a global illumination change, stronger sensor noise, JPEG compression, a car as
dark as the road, a crowd, cyclists): :mod:`wptrack.synth.conditions`, ``wptrack synth s3-... --conditions ...``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wptrack.cameras.rig import Camera, Rig
from wptrack.synth import conditions as C
from wptrack.synth.actors import _BOX_SIGNS, HUMAN, VEHICLE, Car, Formation, Path, Person, PlazaActor, _Prim
from wptrack.synth.base import Scene
from wptrack.synth.conditions import (
    PlazaConditions,
    Retimed,
    TimeWarp,
    jpeg_roundtrip,
    light_change_factor,
    sensor_sigma,
)
from wptrack.synth.plaza_background import (
    CAMERA_POSITION,
    FPS,
    FRAMES,
    IN_VIEW,
    MIN_IN_IMAGE,
    NOISE_SIGMA,
    plaza_background,
    plaza_camera,
    static_points,
    static_share,
)
from wptrack.synth.plaza_cast import _dark_car
from wptrack.synth.render import value_noise

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


@dataclass
class _States:
    """Per-frame states of every actor: (A, N) arrays."""

    frames: int
    pos: np.ndarray  # (A, N, 2)
    active: np.ndarray  # (A, N) on its path
    present: np.ndarray  # (A, N) in view (IN_VIEW of the box holding it): the scene's timing, rules and hints
    heading: np.ndarray  # (A, N)
    speed: np.ndarray  # (A, N)
    phase: np.ndarray  # (A, N)
    labelled: np.ndarray  # (A, N) in the ground truth (MIN_IN_IMAGE of its labelled box)


# ----------------------------------------------------------------------------------------------------- background


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


def image_box_cover(
    cam: Camera, shape: Person | Car, pos: np.ndarray, heading: np.ndarray, labelled: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How much of an object's image bounding box lies inside the image, per frame.

    Args:
        cam: The camera.
        shape: The object's :class:`Person` or :class:`Car` (its :meth:`box`).
        pos: (N, 2) ground positions, metres.
        heading: (N,) headings, radians.
        labelled: The box of its ground-truth dimensions (``shape.dims``: a person's body diameter square, as the
            template tracker's reported box, ``wptrack.trackers.templates.readout``) instead of the box holding the
            whole person (:meth:`box`, arms swinging out included).

    Returns:
        ``(ok, area, inside)``: (N,) bool, all box corners in front of the camera; (N,) area of the image bounding
        box of the 8 box corners and (N,) the part of it inside the image, square pixels.
    """
    half, height = shape.box()
    if labelled:
        half = 0.5 * np.asarray(shape.dims, dtype=np.float64)
    c, s = np.cos(heading), np.sin(heading)
    local = _BOX_SIGNS * half[None, :] + np.array([0.0, 0.0, 0.5 * height])
    wx = pos[:, 0, None] + c[:, None] * local[None, :, 0] - s[:, None] * local[None, :, 1]
    wy = pos[:, 1, None] + s[:, None] * local[None, :, 0] + c[:, None] * local[None, :, 1]
    wz = np.broadcast_to(local[None, :, 2], wx.shape)
    return cam.image_box_cover(np.stack([wx, wy, wz], axis=-1), min_depth=0.1)


_ACTOR_CONDITIONS: dict[str, Callable[[list[PlazaActor]], list[PlazaActor]]] = {}
"""Conditions that add objects to a scene: :class:`PlazaConditions` field -> function of the scene's actors that
returns them with the new ones, applied in registration order (:func:`register_actor_condition`)."""


def register_actor_condition(name: str, add: Callable[[list[PlazaActor]], list[PlazaActor]]) -> None:
    """Register the function that adds the objects of condition ``name`` (a :class:`PlazaConditions` field), so that
    the modules that draw them (:mod:`wptrack.synth.plaza_crowd`) can use this one without it importing them."""
    _ACTOR_CONDITIONS[name] = add


class PlazaScene(Scene):
    """A plaza scene: one camera, people and cars with class, size and heading ground truth, perfect masks.

    Args:
        actors: The moving objects.
        frames: Default number of frames.
        fps: Frames per second.
        conditions: Hard conditions to render (:mod:`wptrack.synth.conditions`); default: none.
    """

    writes_masks = True

    def __init__(
        self,
        actors: Sequence[PlazaActor],
        frames: int = FRAMES,
        fps: float = FPS,
        conditions: PlazaConditions | None = None,
    ) -> None:
        self.base_actors = list(actors)
        self.actors = list(actors)
        self.fps = float(fps)
        self.default_frames = int(frames)
        self.base_frames = int(frames)
        cam = plaza_camera()
        self.rig = Rig(cameras=(cam,), volume=((-16.0, 3.0, 0.0), (16.0, 27.0, 3.0)))
        self.noise_sigma = NOISE_SIGMA
        self._states: _States | None = None
        self.conditions = PlazaConditions() if conditions is None else conditions
        if not isinstance(self.conditions, PlazaConditions):
            raise TypeError(f"conditions must be a PlazaConditions, got {type(self.conditions).__name__}")
        for name, add in _ACTOR_CONDITIONS.items():  # more objects (issue 26: crowd, cyclists)
            if getattr(self.conditions, name):
                self.actors = add(self.actors)
        missing = [n for n in ("crowd", "cyclists") if getattr(self.conditions, n) and n not in _ACTOR_CONDITIONS]
        if missing:
            raise RuntimeError(f"conditions {missing}: not registered (import wptrack.synth.plaza_crowd)")
        if self.conditions.dark_car:
            self.actors = _dark_car(self.actors)
        if self.conditions.short_clip:
            self.actors = self._short_clip(self.actors)
        if self.conditions.static_start:
            self.actors = self._static_start(self.actors)
        if self.conditions.stop_and_go:
            self.actors = self._stop_and_go(self.actors)

    def with_conditions(self, conditions: PlazaConditions) -> PlazaScene:
        """The same scene (actors, length, frame rate) rendered under ``conditions``."""
        return PlazaScene(self.base_actors, frames=self.base_frames, fps=self.fps, conditions=conditions)

    # -- conditions that change the motion (the ground truth follows)

    def _span(self) -> tuple[float, float]:
        """Scene times the retiming maps cover, seconds (beyond: slope 1)."""
        return -2.0, self.default_frames / self.fps + 60.0

    def _short_clip(self, actors: list[PlazaActor]) -> list[PlazaActor]:
        """``short``: a clip of :data:`~wptrack.synth.conditions.SHORT_S` seconds, starting where the default
        timeline's next ``SHORT_S`` seconds hold the most objects in view (the first such start); it becomes the
        scene's default length."""
        self.actors, self._states = actors, None
        n = self.default_frames
        clip = min(max(int(round(C.SHORT_S * self.fps)), 1), n)
        count = self.states(n).present[:, :n].sum(axis=0)
        sums = np.convolve(count, np.ones(clip), mode="valid")  # sums[s]: objects in view over frames s .. s+clip-1
        start = int(np.argmax(sums))
        self._states = None
        self.default_frames = clip
        self.short_origin_s = start / self.fps
        span = self._span()
        warp = TimeWarp.build([], origin=span[0] + self.short_origin_s, span=span)
        return [replace(a, track=Retimed(a.track, warp)) for a in actors]

    def _static_start(self, actors: list[PlazaActor]) -> list[PlazaActor]:
        """``static-start``: freeze the whole scene at the first frame with the most objects in view, then play."""
        self.actors, self._states = actors, None
        n = self.default_frames
        count = self.states(n).present[:, :n].sum(axis=0)
        origin = float(np.argmax(count)) / self.fps
        self._states = None
        warp = TimeWarp.build([(-math.inf, C.HOLD_S)], origin=origin, span=self._span())
        self.static_origin_s = origin
        return [replace(a, track=Retimed(a.track, warp)) for a in actors]

    def _stop_and_go(self, actors: list[PlazaActor]) -> list[PlazaActor]:
        """``stop-and-go``: each person (each group together) stops at 40 % of their frames in view."""
        self.actors, self._states = actors, None
        n = self.default_frames
        present = self.states(n).present[:, :n]
        self._states = None
        groups: dict[int, list[int]] = {}
        for a, actor in enumerate(actors):
            if actor.shape.cls != HUMAN or not np.any(present[a]):
                continue
            track = actor.track
            while isinstance(track, Retimed):
                track = track.inner
            key = id(track.formation) if hasattr(track, "formation") else -1 - a
            groups.setdefault(key, []).append(a)
        out = list(actors)
        start = C.HOLD_S + C.EASE_S if self.conditions.static_start else 0.0
        self.stops_s: dict[int, float] = {}
        for members in groups.values():
            frames = np.flatnonzero(np.any(present[members], axis=0))
            lo = max(float(frames[0]) / self.fps, start + C.EASE_S)
            hi = max(float(frames[-1]) / self.fps, lo)
            at = lo + C.STOP_AT * (hi - lo)
            warp = TimeWarp.build([(at, at + C.STOP_S)], origin=self._span()[0], span=self._span())
            for a in members:
                out[a] = replace(actors[a], track=Retimed(actors[a].track, warp))
                self.stops_s[actors[a].oid] = at
        return out

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
        labelled = np.zeros((count, n), dtype=bool)
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
            # in view (the scenes' draws, timings and hints) where >= IN_VIEW of the box holding the object is
            # inside the image; in the ground truth where >= MIN_IN_IMAGE of the box of its labelled dimensions is
            ok, area, inside = image_box_cover(cam, actor.shape, p, ang)
            present[a] = act & ok & (inside >= IN_VIEW * area)
            ok, area, inside = image_box_cover(cam, actor.shape, p, ang, labelled=True)
            labelled[a] = act & ok & (inside >= MIN_IN_IMAGE * area)
        self._states = _States(n, pos, active, present, heading, speed, phase, labelled)
        return self._states

    def trajectories(self, frames: int) -> dict[int, np.ndarray]:
        """Ground-contact centres: object id -> (frames, 3) metres (z = 0); NaN where not in the ground truth."""
        st = self.states(frames)
        out = {}
        for a, actor in enumerate(self.actors):
            traj = np.full((frames, 3), np.nan)
            sel = st.labelled[a, :frames]
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
        """Largest number of objects in view at once over ``frames`` (default: the scene's): :data:`IN_VIEW` of the
        box holding each, which the ground truth's :data:`MIN_IN_IMAGE` is stricter than (a tracker holds an object
        from its first pixels)."""
        n = self.default_frames if frames is None else int(frames)
        return int(self.states(n).present[:, :n].sum(axis=0).max())

    def hints(self) -> dict[str, Any]:
        """Tracker hints: tracker family, ground plane, most objects at once, object classes; the conditions."""
        out: dict[str, Any] = {
            "tracker": "templates",
            "ground": {"origin": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]},
            "max_objects": self.max_objects(),
            "classes": self.classes(),
        }
        if self.conditions.any:
            out["conditions"] = self.conditions.describe()
        return out

    # -- pixels

    def gain(self, index: int) -> np.ndarray:
        """(3,) RGB illumination gain at frame ``index``: a slow drift of brightness and colour temperature."""
        t = index / self.fps
        b = 1.0 + 0.035 * math.sin(2 * math.pi * t / 16.0 + 0.4) - 0.02 * math.sin(2 * math.pi * t / 37.0)
        warm = 0.012 * math.sin(2 * math.pi * t / 23.0)
        out = b * np.array([1.0 + warm, 1.0, 1.0 - warm])
        if self.conditions.light_change:
            out = out * light_change_factor(t)
        if self.conditions.exposure:
            out = out * C.exposure_gain(t)
        return out

    def local_light(self, index: int) -> np.ndarray:
        """(H, W) float64 mean R, G, B factor by which the local illumination conditions (``clouds``, the lights of
        ``exposure``) change the static scene's radiance at frame ``index`` (1 where they change nothing; global
        gains and the objects' cast shadows are left out): the ground truth of where the light changed locally."""
        cond = self.conditions
        bg = plaza_background(sun=True) if cond.sun_shadows else plaza_background()
        h, w = bg.view.camera.height, bg.view.camera.width
        out = np.ones((h, w, 3))
        t = index / self.fps
        if cond.clouds:
            pts = static_points(cond.sun_shadows)
            cover = C.cloud_cover(C.cloud_shadow_foot(pts, bg.light.unit), t)
            out *= C.cloud_darkening(cover, static_share(cond.sun_shadows))
        if cond.exposure:
            out *= C.light_pool_factor(static_points(cond.sun_shadows), t)
        return out.mean(axis=2)

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

        cond = self.conditions
        bg = plaza_background(sun=True) if cond.sun_shadows else plaza_background()
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
        tint = np.asarray(bg.shadow_tint, dtype=np.float32)
        # clouds: the share of direct sunlight in each pixel's radiance (static surfaces, then the cast shadows and
        # the objects change it), dimmed at the end by the cloud cover at its 3-D point; exposure: the lights' pools
        # at each pixel's 3-D point (static surface or object)
        share = static_share(cond.sun_shadows).copy() if cond.clouds else None
        points = static_points(cond.sun_shadows).copy() if cond.clouds or cond.exposure else None
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
            hard2 = hard.reshape(v1 - v0, u1 - u0)
            soft = cv2.GaussianBlur(hard2, (5, 5), 1.0) if bg.soft_shadows else hard2
            amount = bg.shadow_strength * soft * bg.sunlit[v0:v1, u0:u1] * valid.reshape(v1 - v0, u1 - u0)
            img[v0:v1, u0:u1] *= 1.0 - amount[..., None] * tint[None, None, :]
            if share is not None:  # the direct light left in the shadow
                sub = share[v0:v1, u0:u1]
                sub *= (1.0 - soft) / np.maximum(1.0 - amount, 1e-6)

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
                if share is not None:
                    share[v0:v1, u0:u1][front] = light.diffuse * lam / (light.ambient + light.diffuse * lam)
                if points is not None:
                    points[v0:v1, u0:u1][front] = view.origin[None, :] + tf[:, None] * d[front.ravel()]
                zsub[front] = tf
                labels[v0:v1, u0:u1][front] = actor.oid + 1
            totals[actor.oid] = int(np.count_nonzero(covered))
        pixels = {oid: (int(np.count_nonzero(labels == oid + 1)), total) for oid, total in totals.items()}

        if share is not None:
            cover = C.cloud_cover(C.cloud_shadow_foot(points, sun), t)
            img *= C.cloud_darkening(cover, share).astype(np.float32)
        if cond.exposure:
            img *= C.light_pool_factor(points, t).astype(np.float32)
        scale = (255.0 * light.exposure * self.gain(index)).astype(np.float32)
        img *= scale[None, None, :]
        if cond.sensor_noise:
            img += rng.standard_normal((h, w, 3), dtype=np.float32) * sensor_sigma(img)
        elif self.noise_sigma > 0:
            img += rng.standard_normal((h, w, 3), dtype=np.float32) * np.float32(self.noise_sigma)
        bgr = np.clip(np.rint(img[:, :, ::-1]), 0, 255).astype(np.uint8)
        if cond.compression:
            bgr = jpeg_roundtrip(bgr)
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
