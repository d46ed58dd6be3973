"""Scene ``s1-lab``: the lab experiment of Barrera et al. (colour particle filter, section III), and its jump variant.

Two webcams at the paper's positions - ``cam1`` at (0.5, 0.0, 0.195) m (320x240) and ``cam2`` at (0.07, 0.485,
0.085) m, mounted sideways (240x320, ``roll_deg=90``) - watch a pink ball of radius 0.033 m resting on a paper cup at
(0.42, 0.5, 0.06) m on a lab bench (wooden top at z = 0, world z up). As in the paper, camera 1 looks roughly along
+y and camera 2 roughly along +x: their rays meet at the ball at about 95 degrees. The paper starts its particles
at (0.4, 0.1, 0.2) m, 'just in front of camera 1': camera 1 aims between that point and the ball so both are in
its image, and the point is outside camera 2's view.

Around the ball: a wood-textured bench, two walls with posters (no pink), books, a monitor, a red-orange mug (a
near-miss colour, seen by both cameras), a magenta box (a true distractor in the target colour, seen by cam1 only,
placed on the bench at ``distractor_from``) and a cardboard box that hides the ball from cam1 for about ten frames
of its loop. Pixels get Lambert + ambient + specular shading, a soft shadow blob, a +25 % warm illumination change
and Gaussian sensor noise. In ``s1-lab-jump`` the ball jumps 2 m along the bench at frame 30, to a place seen by
cam1 only (the paper's two webcams share a field of view well under 2 m across; the jump experiment of the
extended paper, section III.C, uses 3D observations of the ball, not its images).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wptrack.cameras.rig import Camera, Rig
from wptrack.synth.base import Scene, register_scene
from wptrack.synth.render import (
    Box,
    Cylinder,
    Light,
    Sphere,
    StaticView,
    noisy,
    posters,
    render_static,
    shade_frame,
    solid,
    wood,
)

__all__ = ["BALL_RGB", "INIT_POINT", "LabConfig", "LabScene", "TARGET_HSI", "jump_target"]

log = logging.getLogger(__name__)

CAM1_POSITION = (0.5, 0.0, 0.195)
"""Camera 1 centre, metres (paper)."""
CAM2_POSITION = (0.07, 0.485, 0.085)
"""Camera 2 centre, metres (paper)."""
INIT_POINT = (0.4, 0.1, 0.2)
"""The paper's initial particle position, metres."""
BALL_REST = (0.42, 0.5, 0.06)
"""Rest position of the ball centre (on its stand), metres."""
BALL_RADIUS = 0.033
"""Ball radius, metres."""
BALL_RGB = (0.78, 0.24, 0.5)
"""Ball albedo, linear RGB: HSI hue ~330 deg, saturation ~0.52."""
TARGET_HSI = {"hue": [312.0, 348.0], "sat": [0.3, 0.8], "intensity": [20.0, 240.0]}
"""Target colour description for the S1 tracker: hue in degrees, saturation in [0, 1], intensity in [0, 255]."""

LABEL_BALL = 100
"""Label of the ball in label images."""
LABEL_MUG = 20
"""Label of the red-orange mug (near-miss colour)."""
LABEL_MAGENTA = 21
"""Label of the magenta box (target colour: a deliberate distractor)."""
LABEL_OCCLUDER = 22
"""Label of the occluding cardboard box."""
DISTRACTOR_LABELS = (LABEL_MAGENTA,)
"""Labels of objects whose colour deliberately matches the target."""


@dataclass(frozen=True)
class LabConfig:
    """Geometry, motion and photometry of the lab scene (metres, pixels, frames).

    Attributes:
        motion: ``"loop"`` (rest, a smooth closed loop, rest) or ``"jump"`` (rest, then a 2 m jump, rest).
        frames: Default number of frames.
        fps: Frames per second.
        rest_frames: Frames the ball rests before moving (loop) or jumping (jump: it jumps at this frame).
        move_frames: Duration of the loop, frames.
        loop_lateral: Half extent of the loop across camera 1's view, metres.
        loop_depth: Half extent of the loop along camera 1's view, metres.
        loop_lift: Extra height at the far end of the loop, metres.
        jump_distance: Length of the jump, metres.
        jump_azimuth_deg: Horizontal direction of the jump (degrees from +x towards +y).
        light_ramp: ``(first, last)`` frames of the illumination change.
        light_gain: Brightness factor after the ramp.
        warmth: Relative red gain (and blue loss) after the ramp: the colour-temperature change.
        noise_sigma: Sensor noise standard deviation, DN.
        distractor_from: Frame from which the magenta box (the target's colour, seen by camera 1 only) stands on
            the bench. Before it, the box is absent: a cloud initialised near camera 1 spreads over most of its
            image and would lock onto any target-coloured object seen by camera 1 alone (the paper's drift), so
            the distractor tests the converged filter instead.
        fx1: Camera 1 focal length, pixels.
        fx2: Camera 2 focal length, pixels.
        dist1: Camera 1 distortion ``k1 k2 p1 p2 k3``.
        dist2: Camera 2 distortion.
    """

    motion: str = "loop"
    frames: int = 200
    fps: float = 25.0
    rest_frames: int = 80
    move_frames: int = 90
    loop_lateral: float = 0.08
    loop_depth: float = 0.03
    loop_lift: float = 0.03
    jump_distance: float = 2.0
    jump_azimuth_deg: float = 120.0
    light_ramp: tuple[int, int] = (110, 130)
    light_gain: float = 1.25
    warmth: float = 0.04
    noise_sigma: float = 3.0
    distractor_from: int = 100
    fx1: float = 220.0
    fx2: float = 220.0
    dist1: tuple[float, ...] = (-0.08, 0.01, 0.0, 0.0, 0.0)
    dist2: tuple[float, ...] = (-0.06, 0.01, 0.0, 0.0, 0.0)
    extra: dict[str, Any] = field(default_factory=dict)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def lab_rig(cfg: LabConfig) -> Rig:
    """The two paper cameras, aimed as explained in the module docstring.

    Camera 1 aims 1 m along the bisector of its rays to the initial point and to the ball (5 cm lower, so it looks
    slightly down); camera 2 aims 3 cm below the ball. Their rays meet at the ball at about 95 degrees.
    """
    c1 = np.asarray(CAM1_POSITION)
    ball = np.asarray(BALL_REST)
    init = np.asarray(INIT_POINT)
    target1 = c1 + _unit(_unit(init - c1) + _unit(ball - c1)) - np.array([0.0, 0.0, 0.05])
    cam1 = Camera.look_at("cam1", 320, 240, c1, target1, fx=cfg.fx1, dist=cfg.dist1)
    target2 = ball - np.array([0.0, 0.0, 0.03])
    cam2 = Camera.look_at("cam2", 240, 320, CAM2_POSITION, target2, fx=cfg.fx2, roll_deg=90.0, dist=cfg.dist2)
    volume = (np.array([-2.8, -0.8, 0.0]), np.array([0.9, 2.4, 1.0]))
    return Rig(cameras=(cam1, cam2), volume=volume)


def jump_target(cfg: LabConfig) -> np.ndarray:
    """Where the ball lands in the jump variant: on the bench, ``jump_distance`` from the rest position.

    Returns:
        (3,) ball centre after the jump, metres (resting on the bench top: z = radius).
    """
    start = np.asarray(BALL_REST, dtype=np.float64)
    dz = BALL_RADIUS - start[2]
    horizontal = math.sqrt(cfg.jump_distance**2 - dz**2)
    a = math.radians(cfg.jump_azimuth_deg)
    return start + np.array([horizontal * math.cos(a), horizontal * math.sin(a), dz])


def _static_objects(distractor: bool = True) -> list[Box | Cylinder]:
    """The furniture of the lab (fixed layout, independent of the noise seed), with or without the magenta box."""
    wall = noisy((0.72, 0.71, 0.66), amplitude=0.05, scale_m=0.3, seed=11)
    west_posters = [
        ((0.2, 0.5), (0.9, 1.3), (0.15, 0.3, 0.6), False),  # blue poster
        ((1.1, 0.3), (1.6, 0.9), (0.2, 0.5, 0.25), True),  # green striped
        ((-0.6, 0.6), (-0.1, 1.1), (0.85, 0.7, 0.2), False),  # yellow
        ((1.8, 0.4), (2.2, 1.4), (0.35, 0.35, 0.4), False),  # dark grey
    ]
    north_posters = [
        ((-2.2, 0.4), (-1.5, 1.0), (0.55, 0.75, 0.85), False),  # light blue
        ((-1.2, 0.3), (-0.5, 0.8), (0.9, 0.55, 0.2), True),  # orange striped
        ((-0.2, 0.5), (0.4, 1.2), (0.2, 0.6, 0.6), False),  # teal
    ]
    objects: list[Box | Cylinder] = [
        # floor, bench (top at z = 0) and walls
        Box((-4.0, -4.0, -0.8), (4.0, 4.0, -0.75), noisy((0.3, 0.32, 0.35), 0.1, 0.2, seed=3), label=1),
        Box((-2.8, -0.8, -0.04), (1.6, 2.4, 0.0), wood(), label=2),
        Box((-2.85, -4.0, -0.75), (-2.8, 4.0, 2.6), posters(wall, west_posters), label=3),
        Box((-3.0, 2.4, -0.75), (4.0, 2.45, 2.6), posters(wall, north_posters), label=4),
        Box((-3.0, -2.05, -0.75), (4.0, -2.0, 2.6), wall, label=5),
        Box((2.0, -4.0, -0.75), (2.05, 4.0, 2.6), wall, label=6),
        # the ball's stand: an upturned paper cup
        Cylinder((BALL_REST[0], BALL_REST[1]), 0.022, 0.0, BALL_REST[2] - BALL_RADIUS, solid((0.8, 0.8, 0.77)), 7),
        # clutter: books, a monitor, a keyboard, a pen pot
        Box((-1.15, 0.05, 0.0), (-0.9, 0.23, 0.05), solid((0.12, 0.2, 0.5)), label=8),
        Box((-1.13, 0.07, 0.05), (-0.92, 0.21, 0.08), solid((0.15, 0.45, 0.2)), label=9),
        Box((-1.4, 1.7, 0.0), (-0.9, 1.75, 0.35), solid((0.07, 0.07, 0.08)), label=10),
        Box((-1.3, 1.45, 0.0), (-0.95, 1.6, 0.02), solid((0.6, 0.6, 0.6)), label=11),
        Cylinder((-0.9, 0.3), 0.035, 0.0, 0.12, solid((0.2, 0.3, 0.22)), 12),
        Box((-1.9, 0.2, 0.0), (-1.6, 0.6, 0.15), noisy((0.62, 0.48, 0.3), 0.06, 0.05, seed=5), label=13),
        # near-miss colour: a red-orange mug, seen by both cameras
        Cylinder((0.6, 0.72), 0.04, 0.0, 0.1, solid((0.75, 0.16, 0.07)), LABEL_MUG),
        # cardboard box between cam1 and one end of the ball's loop: hides it from cam1 for ~10 frames (not cam2)
        Box(
            (0.375, 0.265, 0.0), (0.425, 0.315, 0.15), noisy((0.6, 0.47, 0.3), 0.06, 0.05, seed=9), label=LABEL_OCCLUDER
        ),
    ]
    if distractor:
        # deliberate distractor in the target colour, visible in cam1 only
        objects.append(Box((-0.35, 1.3, 0.0), (-0.2, 1.45, 0.09), solid((0.7, 0.2, 0.46)), label=LABEL_MAGENTA))
    return objects


class LabScene(Scene):
    """The lab of Barrera et al. with one pink ball (object id 0).

    Args:
        config: Geometry, motion and photometry.
    """

    def __init__(self, config: LabConfig) -> None:
        self.config = config
        self.fps = config.fps
        self.default_frames = config.frames
        self.rig = lab_rig(config)
        self.light = Light()
        self.sphere = Sphere(radius=BALL_RADIUS, rgb=BALL_RGB, specular=0.25, shininess=40.0, label=LABEL_BALL)
        self.objects = _static_objects(distractor=True)
        self._views: list[StaticView] | None = None
        self._views_early: list[StaticView] | None = None

    # -- ground truth

    def trajectories(self, frames: int) -> dict[int, np.ndarray]:
        """Ball centre per frame: object id 0 -> (frames, 3) metres."""
        cfg = self.config
        rest = np.asarray(BALL_REST, dtype=np.float64)
        f = np.arange(frames, dtype=np.float64)
        pos = np.repeat(rest[None, :], frames, axis=0)
        if cfg.motion == "jump":
            pos[f >= cfg.rest_frames] = jump_target(cfg)
            return {0: pos}
        c1 = np.asarray(CAM1_POSITION)
        view = rest - c1
        e_depth = _unit(np.array([view[0], view[1], 0.0]))
        e_lat = np.array([-e_depth[1], e_depth[0], 0.0])  # to the left in cam1
        s = np.clip((f - cfg.rest_frames) / cfg.move_frames, 0.0, 1.0)
        phi = math.pi * (1.0 - np.cos(math.pi * s))  # 0 -> 2 pi with zero speed at both ends
        lateral = cfg.loop_lateral * np.sin(phi)
        depth = cfg.loop_depth * (1.0 - np.cos(phi))
        lift = cfg.loop_lift * np.sin(0.5 * phi) ** 2
        pos = (
            rest[None, :] + lateral[:, None] * e_lat + depth[:, None] * e_depth + lift[:, None] * np.array([0, 0, 1.0])
        )
        return {0: pos}

    def hints(self) -> dict[str, Any]:
        """Tracker hints: target colour (HSI), initial position, particle count, motion sigma (metres)."""
        init = list(INIT_POINT) if self.config.motion != "jump" else list(BALL_REST)
        return {
            "target": {k: list(v) for k, v in TARGET_HSI.items()},
            "init": init,
            "particles": 200,
            "sigma": 0.03,
            "ball_radius": BALL_RADIUS,
        }

    # -- pixels

    def views(self, index: int | None = None) -> list[StaticView]:
        """Static ray-cast views, one per camera (computed on first use), for frame ``index`` (None: the
        full layout, distractor included)."""
        if index is not None and index < self.config.distractor_from:
            if self._views_early is None:
                early = _static_objects(distractor=False)
                self._views_early = [render_static(cam, early, self.light) for cam in self.rig]
            return self._views_early
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

    def render_labels(
        self, index: int, position: np.ndarray, rngs: list[np.random.Generator]
    ) -> tuple[list[np.ndarray], list[np.ndarray], dict[str, float]]:
        """Render one frame and return per-camera label images too (tests, debugging).

        Returns:
            ``(bgr images, label images (H, W) int16 with the ball as LABEL_BALL, camera -> visible fraction)``.
        """
        images: list[np.ndarray] = []
        labels: list[np.ndarray] = []
        vis: dict[str, float] = {}
        gain = self.gain(index)
        for view, rng in zip(self.views(index), rngs, strict=True):
            bgr, visible, total, mask = shade_frame(
                view, self.sphere, position, self.light, gain, self.config.noise_sigma, rng
            )
            label = view.label.copy()
            if mask is not None:
                label[mask] = LABEL_BALL
            images.append(bgr)
            labels.append(label)
            vis[view.camera.name] = visible / total if total else 0.0
        return images, labels, vis

    def render_frame(
        self, index: int, positions: dict[int, np.ndarray], rngs: list[np.random.Generator]
    ) -> tuple[list[np.ndarray], dict[str, float]]:
        """Render frame ``index`` (see :meth:`Scene.render_frame`)."""
        images, _, vis = self.render_labels(index, positions[0], rngs)
        return images, vis


@register_scene("s1-lab", "Barrera et al. lab: pink ball rests 80 frames, loops (occluded in cam1), rests; 2 webcams")
def _s1_lab() -> Scene:
    return LabScene(LabConfig())


@register_scene("s1-lab-jump", "Barrera et al. lab: pink ball rests 30 frames, then jumps 2.0 m along the bench")
def _s1_lab_jump() -> Scene:
    return LabScene(LabConfig(motion="jump", frames=120, rest_frames=30, light_ramp=(60, 80)))
