"""Scene ``s1-room``: four cameras in the upper corners of a 4 x 4 x 2.5 m room watch a pink ball (the S1 colour
tracker on more than two cameras, issue 12; the paper's first future line).

The ball (radius 0.1 m, the lab ball's colour) rests 20 frames at (0.3, -0.2, 0.9) m, then moves on a horizontal
circle of radius 0.8 m at 1.0 m height (one turn in 150 frames). Around it: a grey floor, four plain walls, a table,
a red-orange box (a near-miss colour, like the lab's mug) and a blue cabinet. Cameras: 320x240, fx 200 px, mild
barrel distortion, at (+-1.9, +-1.9, 2.3) m aimed at (0, 0, 0.8) m. Shading, illumination and noise as ``s1-lab``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from wptrack.cameras.rig import Camera, Rig
from wptrack.synth.base import Scene, register_scene
from wptrack.synth.lab import BALL_RGB, LABEL_BALL, LABEL_MUG, TARGET_HSI, LabConfig, LabScene
from wptrack.synth.render import Box, Light, Sphere, StaticView, noisy, render_static, solid

__all__ = ["ROOM_BALL_RADIUS", "ROOM_REST", "RoomScene", "room_rig"]

ROOM_BALL_RADIUS = 0.1
"""Ball radius, metres."""
ROOM_REST = (0.3, -0.2, 0.9)
"""Rest position of the ball centre, metres."""


def room_rig() -> Rig:
    """Four cameras in the upper corners, aimed at the room's centre; working volume = the room."""
    cams = []
    for k, (sx, sy) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1))):
        dist = (-0.05 + 0.01 * k, 0.01, 0.0, 0.0, 0.0)
        cams.append(
            Camera.look_at(f"cam{k + 1}", 320, 240, (1.9 * sx, 1.9 * sy, 2.3), (0.0, 0.0, 0.8), 200.0, dist=dist)
        )
    return Rig(cameras=tuple(cams), volume=(np.array([-2.0, -2.0, 0.0]), np.array([2.0, 2.0, 2.5])))


class RoomScene(LabScene):
    """The 4-camera room (object id 0 = the ball). Reuses the lab's renderer, shading and photometry."""

    def __init__(self, config: LabConfig) -> None:
        self.config = config
        self.fps = config.fps
        self.default_frames = config.frames
        self.rig = room_rig()
        self.light = Light()
        self.sphere = Sphere(radius=ROOM_BALL_RADIUS, rgb=BALL_RGB, specular=0.25, shininess=40.0, label=LABEL_BALL)
        wall = noisy((0.72, 0.71, 0.66), amplitude=0.05, scale_m=0.3, seed=11)
        self.objects = [
            Box((-2.5, -2.5, -0.05), (2.5, 2.5, 0.0), noisy((0.3, 0.32, 0.35), 0.1, 0.2, seed=3), label=1),
            Box((-2.05, -2.5, 0.0), (-2.0, 2.5, 2.5), wall, label=3),
            Box((2.0, -2.5, 0.0), (2.05, 2.5, 2.5), wall, label=4),
            Box((-2.5, -2.05, 0.0), (2.5, -2.0, 2.5), wall, label=5),
            Box((-2.5, 2.0, 0.0), (2.5, 2.05, 2.5), wall, label=6),
            Box((-1.5, 0.8, 0.0), (-0.7, 1.4, 0.75), noisy((0.55, 0.36, 0.2), 0.05, 0.1, seed=5), label=7),
            Box((1.2, 1.2, 0.0), (1.5, 1.5, 0.3), solid((0.75, 0.16, 0.07)), label=LABEL_MUG),
            Box((-1.9, -1.9, 0.0), (-1.3, -1.6, 1.2), solid((0.15, 0.25, 0.55)), label=8),
        ]
        self._views: list[StaticView] | None = None

    def trajectories(self, frames: int) -> dict[int, np.ndarray]:
        """Ball centre per frame: rest, then a circle of radius 0.8 m at 1.0 m height."""
        rest = np.asarray(ROOM_REST, dtype=np.float64)
        f = np.arange(frames, dtype=np.float64)
        s = np.clip((f - self.config.rest_frames) / self.config.move_frames, 0.0, 1.0)
        a = 2.0 * math.pi * s
        circle = np.stack([0.8 * np.cos(a), 0.8 * np.sin(a), np.full_like(a, 1.0)], axis=1)
        w = np.clip((f - self.config.rest_frames) / 10.0, 0.0, 1.0)[:, None]  # 10 frames from rest onto the circle
        return {0: (1 - w) * rest + w * circle}

    def hints(self) -> dict:
        """Tracker hints: target colour, initial position (the rest point), particles, sigma."""
        return {
            "target": {k: list(v) for k, v in TARGET_HSI.items()},
            "init": list(ROOM_REST),
            "particles": 500,
            "sigma": 0.03,
            "ball_radius": ROOM_BALL_RADIUS,
        }

    def views(self, index: int | None = None) -> list[StaticView]:
        """Static ray-cast views of the room, one per camera (computed on first use)."""
        if self._views is None:
            self._views = [render_static(cam, self.objects, self.light) for cam in self.rig]
        return self._views


@register_scene("s1-room", "4-camera room: pink ball (r 0.1 m) rests 20 frames, then circles at 1 m height")
def _s1_room() -> Scene:
    return RoomScene(replace(LabConfig(), frames=170, rest_frames=20, move_frames=150, light_ramp=(10_000, 10_001)))
