"""Scene registry and the generic writer of synthetic data sets.

A scene is a :class:`Scene` object (rig, ground truth, per-frame renderer, tracker hints) built by a function
registered with :func:`register_scene`; :func:`render_scene` writes any registered scene to a folder::

    out_dir/rig.yaml            the calibrated rig (wptrack.rig format)
    out_dir/<camera>.avi        one lossless video per camera (FFV1, MJPG fallback)
    out_dir/groundtruth.csv     frame,id,x,y,z (0-based frames, metres, world frame)
    out_dir/scene.json          scene name, seed, frames, fps, description, the tracker hints as top-level keys
                                (s1: target, init, particles, sigma), per-camera visible fraction per frame

Every file is written atomically (temporary file + rename), so an interrupted run leaves no partial file.
"""

from __future__ import annotations

import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.errors import ConfigError
from wptrack.rig import Rig

__all__ = ["SCENES", "Scene", "SceneResult", "SceneSpec", "register_scene", "render_scene", "scene_names"]

log = logging.getLogger(__name__)


class Scene(ABC):
    """A synthetic scene: a rig, moving objects with known 3D positions, and a renderer.

    Attributes:
        rig: The calibrated cameras.
        fps: Frame rate written to the videos, frames per second.
        default_frames: Number of frames rendered when the caller does not choose.
    """

    rig: Rig
    fps: float = 25.0
    default_frames: int = 100

    @abstractmethod
    def trajectories(self, frames: int) -> dict[int, np.ndarray]:
        """Ground truth: object id -> (frames, 3) positions in metres (world frame); NaN rows where absent."""

    @abstractmethod
    def hints(self) -> dict[str, Any]:
        """Tracker hints written to scene.json (target colour ranges, initial position, particle count...)."""

    @abstractmethod
    def render_frame(
        self, index: int, positions: dict[int, np.ndarray], rngs: list[np.random.Generator]
    ) -> tuple[list[np.ndarray], dict[str, float]]:
        """Render frame ``index``.

        Args:
            index: 0-based frame index.
            positions: Object id -> (3,) position this frame, metres.
            rngs: One noise generator per camera (rig order).

        Returns:
            One (H, W, 3) uint8 BGR image per camera (rig order), and camera name -> visible fraction of the
            tracked object (1 = fully visible, 0 = hidden or out of view; NaN when it projects nowhere).
        """


@dataclass(frozen=True)
class SceneSpec:
    """A registered scene.

    Attributes:
        name: Registry name, e.g. ``"s1-lab"``.
        description: One line shown by ``wptrack synth --list`` and written to scene.json.
        build: Function returning a fresh :class:`Scene`.
    """

    name: str
    description: str
    build: Callable[[], Scene]


@dataclass(frozen=True)
class SceneResult:
    """What :func:`render_scene` wrote.

    Attributes:
        out_dir: Output folder.
        rig_path: ``out_dir/rig.yaml``.
        videos: One video per camera, rig order.
        groundtruth_path: ``out_dir/groundtruth.csv``.
        scene_json: ``out_dir/scene.json``.
        frames: Number of frames rendered.
    """

    out_dir: Path
    rig_path: Path
    videos: list[Path]
    groundtruth_path: Path
    scene_json: Path
    frames: int


SCENES: dict[str, SceneSpec] = {}
"""Registry of scenes by name (filled by :func:`register_scene`)."""


def register_scene(name: str, description: str) -> Callable[[Callable[[], Scene]], Callable[[], Scene]]:
    """Decorator registering a scene-building function under ``name``.

    Example::

        @register_scene("s9-demo", "a demo scene")
        def _demo() -> Scene:
            return MyScene(...)

    Raises:
        ValueError: ``name`` is already registered.
    """

    def decorate(build: Callable[[], Scene]) -> Callable[[], Scene]:
        if name in SCENES:
            raise ValueError(f"scene {name!r} is already registered")
        SCENES[name] = SceneSpec(name=name, description=description, build=build)
        return build

    return decorate


def scene_names() -> list[str]:
    """Registered scene names, sorted."""
    return sorted(SCENES)


def get_scene(name: str) -> SceneSpec:
    """The registered scene ``name``.

    Raises:
        ConfigError: unknown name (the message lists the known ones).
    """
    if name not in SCENES:
        raise ConfigError(f"unknown scene {name!r} (known scenes: {', '.join(scene_names())})")
    return SCENES[name]


def _groundtruth_csv(trajectories: dict[int, np.ndarray]) -> str:
    lines = ["frame,id,x,y,z"]
    frames = max(len(p) for p in trajectories.values())
    for f in range(frames):
        for oid in sorted(trajectories):
            p = trajectories[oid][f]
            if np.all(np.isfinite(p)):
                lines.append(f"{f},{oid},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f}")
    return "\n".join(lines) + "\n"


def render_scene(
    name: str, out_dir: str | Path, frames: int | None = None, seed: int = 0, progress: bool = False
) -> SceneResult:
    """Render a registered scene to ``out_dir`` (see the module docstring for the files).

    Args:
        name: Registered scene name (:func:`scene_names`).
        out_dir: Output folder (created with parents; existing files of the same names are replaced).
        frames: Number of frames (default: the scene's own).
        seed: Seed of the sensor noise (the scene layout does not depend on it).
        progress: Show a tqdm progress bar.

    Returns:
        The paths written.

    Raises:
        ConfigError: unknown scene, ``frames < 1`` or ``seed < 0``.
        OutputError: ``out_dir`` or a file in it cannot be written.
    """
    from tqdm import tqdm

    from wptrack.frames import VideoWriter
    from wptrack.io import atomic_write_json, atomic_write_text, ensure_writable_dir

    spec = get_scene(name)
    if frames is not None and (isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1):
        raise ConfigError(f"frames must be a positive integer, got {frames!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    scene = spec.build()
    n_frames = int(frames if frames is not None else scene.default_frames)
    out = ensure_writable_dir(out_dir)

    trajectories = scene.trajectories(n_frames)
    rngs = [np.random.default_rng([int(seed), k]) for k in range(len(scene.rig))]
    rig_path = out / "rig.yaml"
    videos = [out / f"{cam.name}.avi" for cam in scene.rig]
    visibility: dict[str, list[float]] = {cam.name: [] for cam in scene.rig}

    start = time.perf_counter()
    writers = [
        VideoWriter(path, fps=scene.fps, size=(cam.width, cam.height))
        for path, cam in zip(videos, scene.rig, strict=True)
    ]
    try:
        for f in tqdm(range(n_frames), desc=name, unit="frame", disable=not progress):
            positions = {oid: traj[f] for oid, traj in trajectories.items()}
            images, vis = scene.render_frame(f, positions, rngs)
            for writer, image in zip(writers, images, strict=True):
                writer.write(image)
            for cam_name, value in vis.items():
                visibility[cam_name].append(round(float(value), 4) if np.isfinite(value) else None)
    except BaseException:
        for writer in writers:
            writer.abort()
        raise
    for writer in writers:
        writer.close()
    elapsed = time.perf_counter() - start

    scene.rig.save(rig_path)
    gt_path = out / "groundtruth.csv"
    atomic_write_text(gt_path, _groundtruth_csv(trajectories))
    scene_json = out / "scene.json"
    atomic_write_json(
        scene_json,
        {
            "scene": name,
            "description": spec.description,
            "seed": int(seed),
            "frames": n_frames,
            "fps": float(scene.fps),
            "cameras": scene.rig.names,
            "videos": [p.name for p in videos],
            **scene.hints(),
            "visibility": visibility,
        },
    )
    log.info("rendered scene %s: %d frames x %d cameras in %.2f s -> %s", name, n_frames, len(scene.rig), elapsed, out)
    return SceneResult(
        out_dir=out,
        rig_path=rig_path,
        videos=videos,
        groundtruth_path=gt_path,
        scene_json=scene_json,
        frames=n_frames,
    )
