"""Scene registry and the generic writer of synthetic data sets.

A scene is a :class:`Scene` object (rig, ground truth, per-frame renderer, tracker hints) built by a function
registered with :func:`register_scene`; :func:`render_scene` writes any registered scene to a folder::

    out_dir/rig.yaml            the calibrated rig (wptrack.cameras.rig format)
    out_dir/<camera>.avi        one lossless video per camera (FFV1, MJPG fallback)
    out_dir/<camera>_mask.avi   only for scenes with perfect foreground masks (:attr:`Scene.writes_masks`, e.g. the
                                s3 scenes): binary silhouettes of the moving objects, 0/255, same size, lossless
    out_dir/groundtruth.csv     frame,id,x,y,z (0-based frames, metres, world frame), followed by the scene's extra
                                columns if it has any (:meth:`Scene.groundtruth_columns`; s3: class, length, width,
                                height, orientation)
    out_dir/scene.json          scene name, seed, frames, fps, description, the tracker hints as top-level keys
                                (s1: target, init, particles, sigma; s3: tracker, ground, max_objects, classes),
                                ``mask_videos`` when masks are written, per-camera visible fraction per frame

Every file is written atomically (temporary file + rename), so an interrupted run leaves no partial file.
"""

from __future__ import annotations

import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.cameras.rig import Rig
from wptrack.core.errors import ConfigError

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
    writes_masks: bool = False
    """True when :meth:`render_frame_masks` returns perfect foreground masks (written as ``<camera>_mask.avi``)."""

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

    def render_frame_masks(
        self, index: int, positions: dict[int, np.ndarray], rngs: list[np.random.Generator]
    ) -> tuple[list[np.ndarray], dict[str, float], list[np.ndarray] | None]:
        """Render frame ``index`` and, for scenes with :attr:`writes_masks`, the perfect foreground masks.

        The default calls :meth:`render_frame` and returns no masks; scenes that set :attr:`writes_masks` override
        it.

        Args:
            index: 0-based frame index.
            positions: Object id -> (3,) position this frame, metres.
            rngs: One noise generator per camera (rig order).

        Returns:
            ``(images, visibility, masks)``: as :meth:`render_frame`, plus one (H, W) uint8 mask per camera (rig
            order; 255 on the visible pixels of the moving objects, 0 elsewhere) or None.
        """
        images, vis = self.render_frame(index, positions, rngs)
        return images, vis, None

    def with_conditions(self, conditions: Any) -> Scene:
        """The same scene under hard conditions (:mod:`wptrack.synth.conditions`); the s3 plaza scenes take them all,
        the s2 office scenes the light conditions (``clouds``, ``exposure``).

        Raises:
            ConfigError: the scene takes no conditions.
        """
        raise ConfigError("this scene takes no conditions (the s3 plaza scenes and the s2 office scenes do)")

    def save_rig(self, path: Path) -> None:
        """Write the scene's rig file (default: ``self.rig.save(path)``, inline camera entries). Scenes that show
        other calibration formats override it (``s1-clutter``: OpenCV FileStorage files through ``opencv:`` entries)."""
        self.rig.save(path)

    def groundtruth_columns(self, frames: int) -> dict[str, dict[int, np.ndarray]] | None:
        """Extra ground-truth columns written after ``frame,id,x,y,z`` (default: none).

        Args:
            frames: Number of frames (as given to :meth:`trajectories`).

        Returns:
            None, or column name -> object id -> (frames,) per-frame values (floats, written with 6 decimals, or
            strings), in column order; every object of :meth:`trajectories` must appear in every column. Values are
            written only on the rows of frames where the object is present (finite position).
        """
        return None


@dataclass(frozen=True)
class SceneSpec:
    """A registered scene.

    Attributes:
        name: Registry name, e.g. ``"s1-lab"``.
        description: One line shown by ``wptrack synth --list`` and written to scene.json.
        build: Function returning a fresh :class:`Scene` (called with the seed when ``seeded``).
        seeded: True when the scene's layout (paths, clothing) depends on the seed of :func:`render_scene`: ``build``
            is then called as ``build(seed)``; otherwise the seed only changes the sensor noise.
    """

    name: str
    description: str
    build: Callable[..., Scene]
    seeded: bool = False


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
        mask_videos: One perfect-mask video per camera (rig order), empty for scenes without masks.
    """

    out_dir: Path
    rig_path: Path
    videos: list[Path]
    groundtruth_path: Path
    scene_json: Path
    frames: int
    mask_videos: list[Path] = field(default_factory=list)


SCENES: dict[str, SceneSpec] = {}
"""Registry of scenes by name (filled by :func:`register_scene`)."""


def register_scene(
    name: str, description: str, seeded: bool = False
) -> Callable[[Callable[..., Scene]], Callable[..., Scene]]:
    """Decorator registering a scene-building function under ``name``.

    Example::

        @register_scene("s9-demo", "a demo scene")
        def _demo() -> Scene:
            return MyScene(...)

        @register_scene("s9-seeded", "a scene whose paths depend on the seed", seeded=True)
        def _seeded(seed: int) -> Scene:
            return MyScene(seed=seed)

    Raises:
        ValueError: ``name`` is already registered.
    """

    def decorate(build: Callable[..., Scene]) -> Callable[..., Scene]:
        if name in SCENES:
            raise ValueError(f"scene {name!r} is already registered")
        SCENES[name] = SceneSpec(name=name, description=description, build=build, seeded=bool(seeded))
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


def _csv_value(value: Any) -> str:
    if isinstance(value, str):
        return value
    return f"{float(value):.6f}"


def _groundtruth_csv(trajectories: dict[int, np.ndarray], extra: dict[str, dict[int, np.ndarray]] | None = None) -> str:
    extra = extra or {}
    lines = [",".join(["frame", "id", "x", "y", "z", *extra])]
    frames = max(len(p) for p in trajectories.values())
    for f in range(frames):
        for oid in sorted(trajectories):
            p = trajectories[oid][f]
            if np.all(np.isfinite(p)):
                cells = [_csv_value(column[oid][f]) for column in extra.values()]
                lines.append(",".join([f"{f},{oid},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f}", *cells]))
    return "\n".join(lines) + "\n"


def render_scene(
    name: str,
    out_dir: str | Path,
    frames: int | None = None,
    seed: int = 0,
    progress: bool = False,
    conditions: Any = None,
) -> SceneResult:
    """Render a registered scene to ``out_dir`` (see the module docstring for the files).

    Args:
        name: Registered scene name (:func:`scene_names`).
        out_dir: Output folder (created with parents; existing files of the same names are replaced).
        frames: Number of frames (default: the scene's own).
        seed: Seed of the sensor noise; for scenes registered with ``seeded=True`` also of the layout (paths,
            clothing), for the others the layout does not depend on it.
        progress: Show a tqdm progress bar.
        conditions: Hard conditions (:class:`wptrack.synth.conditions.PlazaConditions`, or its comma-separated
            names); None or all off: the scene as registered. Written to scene.json (``conditions``) when any is on.

    Returns:
        The paths written.

    Raises:
        ConfigError: unknown scene, ``frames < 1``, ``seed < 0``, an unknown condition, or conditions for a scene
            that takes none.
        OutputError: ``out_dir`` or a file in it cannot be written.
    """
    from tqdm import tqdm

    from wptrack.io.atomic import atomic_write_json, atomic_write_text, ensure_writable_dir
    from wptrack.io.video import VideoWriter

    spec = get_scene(name)
    if frames is not None and (isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1):
        raise ConfigError(f"frames must be a positive integer, got {frames!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    scene = spec.build(int(seed)) if spec.seeded else spec.build()
    if conditions is not None:
        from wptrack.synth.conditions import PlazaConditions, parse_conditions

        if not isinstance(conditions, PlazaConditions):
            conditions = parse_conditions(conditions)
        if conditions.any:
            try:
                scene = scene.with_conditions(conditions)
            except ConfigError as exc:
                raise ConfigError(f"scene {name!r}: {exc}") from None
    n_frames = int(frames if frames is not None else scene.default_frames)
    out = ensure_writable_dir(out_dir)

    trajectories = scene.trajectories(n_frames)
    extra_columns = scene.groundtruth_columns(n_frames)
    rngs = [np.random.default_rng([int(seed), k]) for k in range(len(scene.rig))]
    rig_path = out / "rig.yaml"
    videos = [out / f"{cam.name}.avi" for cam in scene.rig]
    mask_videos = [out / f"{cam.name}_mask.avi" for cam in scene.rig] if scene.writes_masks else []
    visibility: dict[str, list[float]] = {cam.name: [] for cam in scene.rig}

    start = time.perf_counter()
    sizes = [(cam.width, cam.height) for cam in scene.rig]
    writers = [VideoWriter(path, fps=scene.fps, size=size) for path, size in zip(videos, sizes, strict=True)]
    writers += [VideoWriter(path, fps=scene.fps, size=size) for path, size in zip(mask_videos, sizes, strict=False)]
    try:
        for f in tqdm(range(n_frames), desc=name, unit="frame", disable=not progress):
            positions = {oid: traj[f] for oid, traj in trajectories.items()}
            images, vis, masks = scene.render_frame_masks(f, positions, rngs)
            if mask_videos:
                if masks is None:
                    raise RuntimeError(f"scene {name!r} sets writes_masks but returned no masks at frame {f}")
                images = [*images, *masks]
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

    scene.save_rig(rig_path)
    gt_path = out / "groundtruth.csv"
    atomic_write_text(gt_path, _groundtruth_csv(trajectories, extra_columns))
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
            **({"mask_videos": [p.name for p in mask_videos]} if mask_videos else {}),
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
        mask_videos=mask_videos,
    )
