"""Scenes ``s1-clutter`` (3 cameras), ``s1-clutter-2cam``, ``-4cam`` and ``-6cam``: the S1 colour tracker in a
cluttered room full of colours near the target's (issue 29: lock on from a random initialisation despite look-alike
colours, on scenes it was not tuned on).

A 5 x 4 x 2.6 m room; a pink ball (the lab ball's colour, radius ``ball_radius``) flies a smooth random path through
the middle of it. The layout is drawn from the scene seed (``wptrack synth s1-clutter --seed S``): every seed is
another room with the same ingredients, so tuning on some seeds and reporting on others is a test on unseen scenes.

- **Look-alike colours** (:func:`lookalike_albedo`): large objects and wall panels (0.3 - 1.2 m, several times the
  ball) of the target's hue with a saturation just below its range (``sat_low``: "dusty pink"), and of the target's
  saturation with a hue just outside its range (``hue_near``: violet-magenta and raspberry); small cushions and books
  of both kinds. Sensor noise, shading, JPEG and the light change push a fraction of their pixels into the target's
  HSI range: the colour masks show sparse or dense speckle over areas much larger than the ball.
- **A true distractor**: a small box in exactly the target's colour, in camera 1's view and outside the images of at
  least half of the other cameras (with two cameras: seen by camera 1 only), so fewer cameras agree on it than on a
  ball seen by all (left out when no such place is found).
- **Partial occlusion**: a thin pole between camera 1 and the ball's position at a frame in 6-14 (where the ball moves
  most across camera 1's view) hides part of the ball for a few frames.
- **The ball leaves one camera's view**: the last camera is zoomed (1.6x focal length) and aimed so that the ball's
  centre starts in its image and the whole ball is outside it on 5 or more of frames 8-30 (``scene.json``
  ``visibility`` says when; on a few seeds, whose path runs along that camera's line of sight, no aim does it and
  the ball stays in view).
- **Illumination drift**: brightness x ``light_gain`` and a warmer colour temperature over ``light_ramp`` frames
  (hues move towards red: violet look-alikes drift to the edge of the target's hue range).
- **Compression**: each frame is JPEG-encoded at quality ``jpeg_quality`` and decoded (blocking, chroma subsampling),
  then written losslessly, so the files hold exactly the frames a tracker saw in memory.
- **Calibration**: OpenCV radial + tangential distortion on every camera; ``rig.yaml`` names one OpenCV FileStorage
  file per camera (``<camera>.yml``, written by ``cv2.FileStorage``) through ``opencv:`` entries.

Cameras stand on a ring at 1.9 - 2.4 m, spread in azimuth, aimed at the middle of the room; 320x240 pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.cameras.rig import Camera, Rig
from wptrack.synth.base import Scene, register_scene
from wptrack.synth.lab import BALL_RGB, LABEL_BALL, TARGET_HSI
from wptrack.synth.render import Box, Cylinder, Light, Sphere, StaticView, noisy, render_static, shade_frame, solid

__all__ = ["ClutterConfig", "ClutterScene", "clutter_rig", "hsi_to_rgb", "lookalike_albedo"]

ROOM_LO = (-2.5, -2.0, 0.0)
"""Room corner (min), metres."""
ROOM_HI = (2.5, 2.0, 2.6)
"""Room corner (max), metres."""
PATH_CENTRE = (0.0, 0.0, 0.9)
"""Middle of the ball's path, metres."""
PATH_HALF = (1.1, 0.8, 0.35)
"""Half extents of the box the ball's path stays in, metres."""
LABEL_LOOKALIKE = 30
"""Label of the look-alike objects."""
LABEL_TRUE_DISTRACTOR = 31
"""Label of the small box in the target's colour."""
LABEL_POLE = 32
"""Label of the occluding pole."""


def hsi_to_rgb(h_deg: float, s: float, i: float) -> np.ndarray:
    """Linear RGB of an HSI colour, the inverse of :func:`wptrack.synth.render.hsi` (the tracker's HSI).

    Args:
        h_deg: hue, degrees [0, 360).
        s: saturation [0, 1].
        i: intensity (mean of R, G, B), any scale.

    Returns:
        (3,) R, G, B on the scale of ``i``.
    """
    h = math.radians(h_deg % 360.0)
    sector = int(h // (2.0 * math.pi / 3.0))
    hh = h - sector * 2.0 * math.pi / 3.0
    a = i * (1.0 - s)
    b = i * (1.0 + s * math.cos(hh) / math.cos(math.pi / 3.0 - hh))
    c = 3.0 * i - (a + b)
    if sector == 0:  # R >= ... : (b, c, a)
        rgb = (b, c, a)
    elif sector == 1:
        rgb = (a, b, c)
    else:
        rgb = (c, a, b)
    return np.asarray(rgb, dtype=np.float64)


def lookalike_albedo(kind: str, rng: np.random.Generator) -> tuple[float, float, float]:
    """An albedo near the target colour (``TARGET_HSI``: hue 312-348 deg, saturation 0.3-0.8).

    Args:
        kind: ``sat_low`` (the target's hue, saturation 0.20-0.285: just below the range) or ``hue_near`` (saturation
            0.4-0.65, hue 292-304 or 351-358 deg: outside the range on either side; the light change moves the violet
            ones 7-10 degrees towards it, to 299-314).
        rng: draws the colour.

    Returns:
        Linear RGB albedo in [0, 1].
    """
    if kind == "sat_low":
        h, s = rng.uniform(318.0, 342.0), rng.uniform(0.20, 0.285)
    elif kind == "hue_near":
        h = rng.uniform(292.0, 304.0) if rng.random() < 0.5 else rng.uniform(351.0, 358.0)
        s = rng.uniform(0.4, 0.65)
    else:
        raise ValueError(f"unknown look-alike kind {kind!r}")
    rgb = hsi_to_rgb(h, s, rng.uniform(0.38, 0.55))
    rgb = rgb / max(1.0, float(rgb.max()) / 0.95)
    return tuple(float(v) for v in np.clip(rgb, 0.0, 1.0))


@dataclass(frozen=True)
class ClutterConfig:
    """Layout and photometry of a clutter room (metres, pixels, frames).

    Attributes:
        cameras: number of cameras, 2 to 6.
        frames: default number of frames.
        fps: frames per second.
        width: image width, pixels.
        height: image height, pixels.
        fx: focal length range (min, max) of the cameras, pixels.
        ball_radius: ball radius, metres.
        speed: speed of the ball, m/s (constant along its path).
        large_lookalikes: number of large look-alike objects (furniture, wall panels).
        small_lookalikes: number of small look-alike objects (cushions, books).
        true_distractor: place a small box in the target's exact colour, seen by camera 1 and at most half of the
            other cameras (if such a place exists).
        pole: place a thin pole that partially hides the ball from camera 1 for a few frames (around frames 6-14).
        leave_view: zoom the last camera and aim it so that the ball leaves its view within frames 8-30.
        light_ramp: (first, last) frames of the illumination change.
        light_gain: brightness factor after the ramp.
        warmth: relative red gain (and blue loss) after the ramp.
        noise_sigma: sensor noise, DN.
        jpeg_quality: JPEG quality of the per-frame compression (0: none).
        distortion: largest |k1|; k2, p1, p2 scale with it.
    """

    cameras: int = 3
    frames: int = 60
    fps: float = 25.0
    width: int = 320
    height: int = 240
    fx: tuple[float, float] = (210.0, 270.0)
    ball_radius: float = 0.06
    speed: float = 0.2
    large_lookalikes: int = 7
    small_lookalikes: int = 10
    true_distractor: bool = True
    pole: bool = True
    leave_view: bool = True
    light_ramp: tuple[int, int] = (10, 40)
    light_gain: float = 1.2
    warmth: float = 0.05
    noise_sigma: float = 3.0
    jpeg_quality: int = 70
    distortion: float = 0.18


def clutter_rig(cfg: ClutterConfig, rng: np.random.Generator, path: np.ndarray) -> Rig:
    """``cfg.cameras`` cameras on a ring around the room, spread in azimuth with jitter, aimed near the path's middle;
    with ``cfg.leave_view`` the last one is zoomed (1.6x) and aimed so that the ball (``path``, (F, 3) metres) starts
    in its image and leaves it within frames 8-30. OpenCV distortion on all."""
    m = cfg.cameras
    base = rng.uniform(0.0, 2.0 * math.pi)
    cams = []
    centre = np.asarray(PATH_CENTRE)
    for k in range(m):
        a = base + 2.0 * math.pi * k / m + rng.uniform(-0.25, 0.25) * (2.0 * math.pi / m) * 0.5
        # on the room's walls: scale the unit direction to hit the 2.3 x 1.8 m rectangle inside the walls
        d = np.array([math.cos(a), math.sin(a)])
        s = min(2.3 / max(abs(d[0]), 1e-9), 1.8 / max(abs(d[1]), 1e-9))
        pos = np.array([d[0] * s, d[1] * s, rng.uniform(1.9, 2.4)])
        aim = centre + rng.uniform(-0.25, 0.25, 3) * np.array([1.0, 1.0, 0.4])
        fx = rng.uniform(*cfg.fx)
        k1 = -rng.uniform(0.4, 1.0) * cfg.distortion
        dist = (
            k1,
            0.3 * cfg.distortion * rng.uniform(-0.5, 1.0),
            0.01 * cfg.distortion * rng.uniform(-1, 1),
            0.01 * cfg.distortion * rng.uniform(-1, 1),
            0.0,
        )
        if cfg.leave_view and k == m - 1:
            fx *= 1.6
            aim = _leaving_view(cfg, pos, fx, dist, path)
        cams.append(Camera.look_at(f"cam{k + 1}", cfg.width, cfg.height, pos, aim, fx=fx, dist=dist))
    return Rig(cameras=tuple(cams), volume=(np.asarray(ROOM_LO, float), np.asarray(ROOM_HI, float)))


def _leaving_view(
    cfg: ClutterConfig, pos: np.ndarray, fx: float, dist: tuple[float, ...], path: np.ndarray
) -> np.ndarray:
    """An aim point for a camera at ``pos`` (focal length ``fx``, distortion ``dist``) such that the ball's centre
    (``path``) is in its image at frame 0 and the whole ball (radius ``cfg.ball_radius``) outside it on at least 5 of
    frames 8-30: the smallest offset of the aim from the ball's start, against where it goes, that does so (else the
    start)."""
    start = path[0]
    move = path[min(30, len(path) - 1)] - start
    view = (start - pos) / np.linalg.norm(start - pos)
    perp = move - (move @ view) * view
    perp = perp / max(np.linalg.norm(perp), 1e-9)
    size = np.array([cfg.width, cfg.height], dtype=np.float64)
    for offset in np.arange(0.0, 2.0, 0.02):
        aim = start - offset * perp  # the image centre lags behind: the ball starts on the side it moves to
        cam = Camera.look_at("probe", cfg.width, cfg.height, pos, aim, fx=fx, dist=dist)
        uv, depth = cam.project(path[:31])
        r = fx * cfg.ball_radius / np.maximum(depth, 1e-6)[:, None] + 1.0
        inside = (depth > 0) & np.all((uv >= 0.0) & (uv <= size - 1.0), axis=1)
        outside = (depth <= 0) | np.any((uv < -r) | (uv > size - 1.0 + r), axis=1)
        if inside[0] and np.sum(outside[8:31]) >= 5:
            return aim
    return start


def _mostly_in_first_view(cams, rng: np.random.Generator, tries: int = 400) -> np.ndarray | None:
    """A point 0.3-1.2 m in front of camera 1, in its image, above the floor, inside the room and outside the images
    (by 20 pixels, or behind) of at least half of the other cameras - with two cameras, of the other one - occlusion
    ignored; None when none of ``tries`` draws is."""
    first = cams[0]
    lo, hi = np.asarray(ROOM_LO) + 0.1, np.asarray(ROOM_HI) - 0.1
    need = max(1, -(-(len(cams) - 1) // 2))
    for _ in range(tries):
        uv = rng.uniform([10.0, 10.0], [first.width - 10.0, first.height - 10.0])
        p = first.center + rng.uniform(0.3, 1.2) * first.pixel_rays(uv[None])[0]
        if np.any(p < lo) or np.any(p > hi) or p[2] < 0.06:
            continue
        unseen = 0
        for cam in cams[1:]:
            q, depth = cam.project(p[None])
            inside = (q[0] > -20.0) & (q[0] < np.array([cam.width, cam.height]) + 20.0)
            unseen += int(not (depth[0] > 0 and np.all(inside)))
        if unseen >= need:
            return p
    return None


def _crossing_frame(path: np.ndarray, centre: np.ndarray) -> int:
    """The frame in 6-14 where the ball moves fastest across the view of a camera at ``centre``."""
    best, arg = -1.0, 6
    for f in range(6, min(15, len(path) - 1)):
        view = (path[f] - centre) / np.linalg.norm(path[f] - centre)
        step = path[f + 1] - path[f]
        across = float(np.linalg.norm(step - (step @ view) * view))
        if across > best:
            best, arg = across, f
    return arg


def _path(cfg: ClutterConfig, rng: np.random.Generator, frames: int) -> np.ndarray:
    """A smooth random curve (sums of three sinusoids per axis) inside the path box, travelled at ``cfg.speed``."""
    centre = np.asarray(PATH_CENTRE)
    half = np.asarray(PATH_HALF)
    u = np.linspace(0.0, 60.0, 24001)  # curve parameter, dense
    curve = np.zeros((len(u), 3))
    for ax in range(3):
        acc = np.zeros(len(u))
        for _ in range(3):
            acc += rng.uniform(0.3, 1.0) * np.sin(rng.uniform(0.15, 0.5) * u + rng.uniform(0, 2 * math.pi))
        curve[:, ax] = centre[ax] + half[ax] * np.clip(acc / 2.2, -1.0, 1.0)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(curve, axis=0), axis=1))])
    s = np.minimum(np.arange(frames, dtype=np.float64) * cfg.speed / cfg.fps, arc[-1])
    return np.stack([np.interp(s, arc, curve[:, ax]) for ax in range(3)], axis=1)


class ClutterScene(Scene):
    """A clutter room (object id 0 = the ball); see the module docstring.

    Args:
        config: layout and photometry.
        seed: draws the layout, the cameras and the ball's path.
    """

    def __init__(self, config: ClutterConfig, seed: int = 0) -> None:
        if not 2 <= config.cameras <= 6:
            raise ValueError(f"cameras: 2 to 6, got {config.cameras}")
        self.config = config
        self.seed = int(seed)
        self.fps = config.fps
        self.default_frames = config.frames
        rng = np.random.default_rng([29, self.seed, config.cameras])
        self._path_seed = int(rng.integers(0, 2**31))
        path = self.trajectories(max(config.frames, 200))[0]
        self.rig = clutter_rig(config, rng, path)
        self.light = Light()
        self.sphere = Sphere(radius=config.ball_radius, rgb=BALL_RGB, specular=0.25, shininess=40.0, label=LABEL_BALL)
        self.objects = self._layout(rng, path)
        self._views: list[StaticView] | None = None

    # -- layout

    def _layout(self, rng: np.random.Generator, path: np.ndarray) -> list[Box | Cylinder]:
        cfg = self.config
        lo, hi = np.asarray(ROOM_LO), np.asarray(ROOM_HI)
        wall = noisy((0.7, 0.69, 0.64), amplitude=0.05, scale_m=0.3, seed=int(rng.integers(1000)))
        floor = noisy((0.33, 0.3, 0.28), amplitude=0.12, scale_m=0.2, seed=int(rng.integers(1000)))
        objects: list[Box | Cylinder] = [
            Box((lo[0], lo[1], -0.05), (hi[0], hi[1], 0.0), floor, label=1),
            Box((lo[0] - 0.05, lo[1], 0.0), (lo[0], hi[1], hi[2]), wall, label=2),
            Box((hi[0], lo[1], 0.0), (hi[0] + 0.05, hi[1], hi[2]), wall, label=3),
            Box((lo[0], lo[1] - 0.05, 0.0), (hi[0], lo[1], hi[2]), wall, label=4),
            Box((lo[0], hi[1], 0.0), (hi[0], hi[1] + 0.05, hi[2]), wall, label=5),
        ]
        # neutral furniture
        for k in range(3):
            c = rng.uniform(lo[:2] + 0.5, hi[:2] - 0.5)
            size = rng.uniform([0.4, 0.4, 0.4], [1.0, 0.8, 0.9])
            grey = rng.uniform(0.25, 0.6)
            tint = rng.uniform(-0.05, 0.05, 3)
            objects.append(
                Box(tuple(c - size[:2] / 2) + (0.0,), tuple(c + size[:2] / 2) + (size[2],), solid(grey + tint), 6 + k)
            )
        kinds = ("sat_low", "hue_near")
        path_lo = path.min(0) - cfg.ball_radius - 0.05
        path_hi = path.max(0) + cfg.ball_radius + 0.05

        def clear_of_path(blo, bhi) -> bool:
            return bool(np.any(bhi < path_lo) or np.any(blo > path_hi))

        for k in range(cfg.large_lookalikes):
            kind = kinds[k % 2]
            albedo = lookalike_albedo(kind, rng)
            tex = noisy(albedo, amplitude=0.06, scale_m=0.15, seed=int(rng.integers(1000)))
            if rng.random() < 0.4:  # a panel on a wall (poster, curtain)
                wall_k = int(rng.integers(4))
                w, h = rng.uniform(0.5, 1.2), rng.uniform(0.4, 1.0)
                z0 = rng.uniform(0.3, 1.4)
                if wall_k < 2:
                    x = lo[0] + 0.001 if wall_k == 0 else hi[0] - 0.021
                    y = rng.uniform(lo[1] + w / 2, hi[1] - w / 2)
                    objects.append(Box((x, y - w / 2, z0), (x + 0.02, y + w / 2, z0 + h), tex, LABEL_LOOKALIKE))
                else:
                    y = lo[1] + 0.001 if wall_k == 2 else hi[1] - 0.021
                    x = rng.uniform(lo[0] + w / 2, hi[0] - w / 2)
                    objects.append(Box((x - w / 2, y, z0), (x + w / 2, y + 0.02, z0 + h), tex, LABEL_LOOKALIKE))
                continue
            for _try in range(50):  # furniture on the floor (sofa, armchair, cabinet), not on the ball's path
                size = rng.uniform([0.3, 0.3, 0.3], [1.2, 0.7, 1.0])
                c = rng.uniform(lo[:2] + size[:2] / 2 + 0.05, hi[:2] - size[:2] / 2 - 0.05)
                blo = np.array([c[0] - size[0] / 2, c[1] - size[1] / 2, 0.0])
                bhi = np.array([c[0] + size[0] / 2, c[1] + size[1] / 2, size[2]])
                if clear_of_path(blo, bhi):
                    break
            objects.append(Box(tuple(blo), tuple(bhi), tex, LABEL_LOOKALIKE))
        for k in range(cfg.small_lookalikes):
            albedo = lookalike_albedo(kinds[k % 2], rng)
            for _try in range(50):
                size = rng.uniform(0.08, 0.3, 3)
                c = rng.uniform(lo + size / 2 + 0.05, np.array([hi[0], hi[1], 1.6]) - size / 2 - 0.05)
                c[2] = max(c[2], size[2] / 2)
                blo, bhi = c - size / 2, c + size / 2
                if clear_of_path(blo, bhi):
                    break
            if rng.random() < 0.5:
                objects.append(Box(tuple(blo), tuple(bhi), solid(albedo), LABEL_LOOKALIKE))
            else:
                objects.append(Cylinder((c[0], c[1]), size[0] / 2, blo[2], bhi[2], solid(albedo), LABEL_LOOKALIKE))
        cams = self.rig.cameras
        if cfg.true_distractor:  # in the target's colour, in camera 1's view and out of half the others'
            p = _mostly_in_first_view(cams, rng)
            if p is not None:
                s = 0.05
                objects.append(Box(tuple(p - s), tuple(p + s), solid(BALL_RGB), LABEL_TRUE_DISTRACTOR))
        if cfg.pole:  # a thin pole between camera 1 and the ball: partial occlusion for a few frames
            c0 = np.asarray(cams[0].center)
            f = _crossing_frame(path, c0)
            p = c0 + 0.45 * (path[f] - c0)
            r = 0.12 * cfg.ball_radius
            objects.append(Cylinder((p[0], p[1]), r, 0.0, hi[2], solid((0.5, 0.5, 0.52)), LABEL_POLE))
        return objects

    # -- ground truth

    def trajectories(self, frames: int) -> dict[int, np.ndarray]:
        """Ball centre per frame: object id 0 -> (frames, 3) metres."""
        return {0: _path(self.config, np.random.default_rng(self._path_seed), frames)}

    def hints(self) -> dict[str, Any]:
        """Tracker hints: target colour (HSI), initial position (the ball at frame 0), particles, sigma (metres)."""
        start = self.trajectories(1)[0][0]
        return {
            "target": {k: list(v) for k, v in TARGET_HSI.items()},
            "init": [round(float(v), 6) for v in start],
            "particles": 20000,
            "sigma": 0.03,
            "ball_radius": self.config.ball_radius,
            "layout_seed": self.seed,
        }

    # -- pixels

    def views(self) -> list[StaticView]:
        """Static ray-cast views, one per camera (computed on first use)."""
        if self._views is None:
            self._views = [render_static(cam, self.objects, self.light) for cam in self.rig]
        return self._views

    def gain(self, index: int) -> np.ndarray:
        """(3,) RGB illumination gain at frame ``index`` (brightness ramp x warmer colour temperature)."""
        cfg = self.config
        a, b = cfg.light_ramp
        x = float(np.clip((index - a) / max(b - a, 1), 0.0, 1.0))
        x = x * x * (3 - 2 * x)
        brightness = 1.0 + (cfg.light_gain - 1.0) * x
        warm = cfg.warmth * x
        return brightness * np.array([1.0 + warm, 1.0, 1.0 - warm])

    def render_frame(
        self, index: int, positions: dict[int, np.ndarray], rngs: list[np.random.Generator]
    ) -> tuple[list[np.ndarray], dict[str, float]]:
        """Render frame ``index`` (see :meth:`Scene.render_frame`): shading, noise, then JPEG."""
        import cv2

        images: list[np.ndarray] = []
        vis: dict[str, float] = {}
        gain = self.gain(index)
        q = int(self.config.jpeg_quality)
        for view, rng in zip(self.views(), rngs, strict=True):
            bgr, visible, total, _mask = shade_frame(
                view, self.sphere, positions[0], self.light, gain, self.config.noise_sigma, rng
            )
            if q > 0:
                ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, q])
                bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR)
            images.append(bgr)
            vis[view.camera.name] = visible / total if total else 0.0
        return images, vis

    def save_rig(self, path: Path) -> None:
        """Write ``rig.yaml`` with one ``opencv:`` entry per camera and the cameras as OpenCV FileStorage files."""
        from wptrack.cameras.files import save_opencv
        from wptrack.io.atomic import atomic_write_text

        path = Path(path)
        lines = [
            f"volume: {{min: {list(map(float, ROOM_LO))}, max: {list(map(float, ROOM_HI))}}}",
            "cameras:",
        ]
        for cam in self.rig:
            save_opencv(cam, path.parent / f"{cam.name}.yml")
            lines += [f"  - name: {cam.name}", f"    opencv: {cam.name}.yml"]
        atomic_write_text(path, "\n".join(lines) + "\n")


def _builder(cameras: int):
    def build(seed: int = 0) -> Scene:
        return ClutterScene(ClutterConfig(cameras=cameras), seed)

    return build


register_scene(
    "s1-clutter",
    "S1 clutter room, 3 cameras: pink ball among look-alike colours, pole, light change, JPEG, OpenCV calibration",
    seeded=True,
)(_builder(3))
for _m in (2, 4, 6):
    register_scene(
        f"s1-clutter-{_m}cam",
        f"s1-clutter with {_m} cameras (layout, path and cameras drawn from the seed)",
        seeded=True,
    )(_builder(_m))
