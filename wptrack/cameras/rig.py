"""Camera rig model shared by every tracker.

A :class:`Rig` is an ordered tuple of calibrated pinhole :class:`Camera` objects (OpenCV conventions: camera axes x
right, y down, z forward; ``X_cam = R @ X_world + t``; world units are metres, image units pixels, and pixel centres
lie at integer coordinates) plus an optional working volume and an optional ground plane (default: z = 0, the
plane the S3 template tracker's objects stand on; ``x_axis`` defaults to world x projected onto the plane).

This module holds the rig (cameras, volume, ground, blind cameras); the cameras and the plane are
:mod:`wptrack.cameras.camera` (re-exported here). Rig files (YAML/JSON layout, ``opencv:`` and ``tsai:`` camera
entries, writing) are :mod:`wptrack.cameras.files`, which ``Rig.load``, ``Rig.save`` and ``Rig.from_dict`` call; the
value checks and the wording of error messages are :mod:`wptrack.cameras.checks`. ``save_opencv`` and
``ROTATION_TOL`` are re-exported here.

Every problem raises :class:`~wptrack.core.errors.RigError` with a one-line message naming the file, the camera (index
and name) and the field, e.g. ``rig.yaml: cameras[1] 'cam1': K: focal length fx must be > 0, got -3.0``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.cameras.camera import Camera, GroundPlane
from wptrack.cameras.checks import (  # noqa: F401  (ROTATION_TOL: re-exported)
    ROTATION_TOL,
    _array,
    _camera_where,
    _fmt,
    _parse_volume,
    _positive_int,
    _readonly,
    _validated_fields,
)
from wptrack.cameras.files import camera_from_dict, load_rig, rig_from_dict, save_opencv, save_rig
from wptrack.core.errors import RigError

__all__ = ["Camera", "GroundPlane", "Rig", "camera_from_dict", "save_opencv"]

log = logging.getLogger(__name__)

BOUNDS_PAD_M = 0.25
"""Padding (metres) around the camera centres used by :meth:`Rig.bounds` when no volume is set."""


# ----------------------------------------------------------------------------------------------------- Rig


@dataclass(frozen=True, eq=False)
class Rig:
    """An ordered set of uniquely named cameras plus an optional working volume.

    Attributes:
        cameras: The cameras, in file order.
        volume: Optional working volume ``(min_xyz, max_xyz)``, each (3,) float64 metres, ``min < max``.
        source: The file the rig came from (used in error messages), ``<memory>`` otherwise.
    """

    cameras: tuple[Camera, ...]
    volume: tuple[np.ndarray, np.ndarray] | None = None
    source: str = "<memory>"
    ground: GroundPlane | None = None

    def __post_init__(self) -> None:
        source = str(self.source)
        object.__setattr__(self, "source", source)
        cameras = tuple(self.cameras)
        if not cameras:
            raise RigError(f"{source}: cameras: the rig has no cameras (expected a non-empty list)")
        seen: dict[str, int] = {}
        for i, cam in enumerate(cameras):
            if not isinstance(cam, Camera):
                raise RigError(f"{source}: cameras[{i}]: expected a Camera, got {type(cam).__name__}")
            if cam.name in seen:
                raise RigError(
                    f"{source}: cameras[{i}] {_fmt(cam.name)}: name: duplicate camera name "
                    f"(also cameras[{seen[cam.name]}]); names must be unique"
                )
            seen[cam.name] = i
        object.__setattr__(self, "cameras", cameras)
        if self.volume is not None:
            object.__setattr__(self, "volume", _parse_volume(self.volume, source))
            for name in self.blind_cameras():
                log.warning(
                    "%s: camera '%s' sees nothing of the working volume %s..%s m (check its pose: R/rvec, t)",
                    source,
                    name,
                    _fmt(self.volume[0].tolist()),
                    _fmt(self.volume[1].tolist()),
                )
        if self.ground is not None and not isinstance(self.ground, GroundPlane):
            object.__setattr__(self, "ground", GroundPlane.from_dict(self.ground, source))
        if self.ground is not None:  # every camera above the plane, on its normal's side: else nothing stands in view
            for cam in cameras:
                height = float((cam.center - self.ground.origin) @ self.ground.normal)
                if not height > 0:
                    raise RigError(
                        f"{source}: ground: camera '{cam.name}' is {-height:.2f} m below the ground plane (origin "
                        f"{_fmt(self.ground.origin.tolist())}, normal {_fmt(self.ground.normal.tolist())}): the plane "
                        "must lie below every camera, its normal pointing up towards them; check the sign of 'normal' "
                        "and the height of 'origin'"
                    )

    @property
    def ground_plane(self) -> GroundPlane:
        """The configured ground plane, or z = 0 (world x and y as plane axes)."""
        return self.ground if self.ground is not None else GroundPlane()

    def __len__(self) -> int:
        return len(self.cameras)

    def __iter__(self) -> Iterator[Camera]:
        return iter(self.cameras)

    def __getitem__(self, key: int | str) -> Camera:
        """Camera by position (negative allowed) or by name.

        Raises:
            RigError: no such index or name.
            TypeError: ``key`` is neither an int nor a str.
        """
        if isinstance(key, str):
            for cam in self.cameras:
                if cam.name == key:
                    return cam
            raise RigError(f"{self.source}: no camera named {key!r} (cameras: {', '.join(self.names)})")
        if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
            n = len(self.cameras)
            if not -n <= key < n:
                raise RigError(f"{self.source}: camera index {int(key)} out of range (the rig has {n} cameras)")
            return self.cameras[int(key)]
        raise TypeError(f"camera key must be an int index or a str name, got {type(key).__name__}")

    @property
    def names(self) -> list[str]:
        """Camera names, in rig order."""
        return [cam.name for cam in self.cameras]

    # -- files

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Rig:
        """Load a rig from a ``.yaml``/``.yml`` or ``.json`` file.

        Raises:
            RigError: missing, unreadable or invalid file.
        """
        return load_rig(cls, path)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the rig as YAML or JSON (chosen by suffix), atomically (temp file in the same dir + ``os.replace``).

        Raises:
            RigError: unsupported suffix.
            OutputError: the file cannot be written.
        """
        save_rig(self, path)

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python representation (the rig-file layout): ``cameras`` and, if set, ``volume``."""
        out: dict[str, Any] = {}
        if self.volume is not None:
            out["volume"] = {"min": self.volume[0].tolist(), "max": self.volume[1].tolist()}
        if self.ground is not None:
            out["ground"] = self.ground.to_dict()
        out["cameras"] = [cam.to_dict() for cam in self.cameras]
        return out

    @classmethod
    def from_dict(cls, d: Any, source: str = "<dict>", base_dir: Path | None = None) -> Rig:
        """Build a rig from the rig-file layout (see :mod:`wptrack.cameras.files`).

        Args:
            d: Mapping with ``cameras`` (list of camera entries) and optional ``volume`` ``{min, max}``.
            source: File name used in error messages.
            base_dir: Directory for relative ``opencv:`` paths.

        Raises:
            RigError: any invalid field.
        """
        return rig_from_dict(cls, d, source, base_dir)

    # -- queries

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Working volume ``(min_xyz, max_xyz)``, each (3,) float64 metres.

        The configured volume if set, else the bounding box of the camera centres padded by 0.25 m on every side.
        """
        if self.volume is not None:
            return np.array(self.volume[0]), np.array(self.volume[1])
        centres = np.stack([cam.center for cam in self.cameras])
        return centres.min(axis=0) - BOUNDS_PAD_M, centres.max(axis=0) + BOUNDS_PAD_M

    def blind_cameras(self, samples: int = 9) -> list[str]:
        """Names of the cameras that see no point of the working volume (:meth:`bounds`).

        A ``samples``^3 grid over the volume (corners included) is projected into each camera; a camera is blind
        when no grid point lies in front of it and inside its image. Such a camera only adds the constant
        "outside" likelihood to every particle - usually a pose given in the wrong convention.
        """
        lo, hi = self.bounds()
        axes = [np.linspace(lo[k], hi[k], samples) for k in range(3)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        blind = []
        for cam in self.cameras:
            with np.errstate(all="ignore"):
                uv, depth = cam.project(grid)
            ok = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
            if not np.any(ok):
                blind.append(cam.name)
        return blind

    def at_sizes(self, sizes: Sequence[tuple[int, int]], sources: Sequence[str]) -> Rig:
        """The rig for frames of the given sizes, one per camera in rig order: each camera as it is when its frames
        have its calibrated size, scaled (:meth:`Camera.for_size`) when they are a resized copy.

        Raises:
            RigError: frames of another aspect ratio (naming the source and the camera).
        """
        cams = tuple(
            cam.for_size(w, h, str(src), self.source)
            for cam, (w, h), src in zip(self.cameras, sizes, sources, strict=True)
        )
        if all(a is b for a, b in zip(cams, self.cameras, strict=True)):
            return self
        return Rig(cameras=cams, volume=self.volume, source=self.source, ground=self.ground)

    def with_camera(self, camera: Camera) -> Rig:
        """The rig with the camera of the same name replaced by ``camera`` (e.g. scaled to another frame size)."""
        if camera is self[camera.name]:
            return self
        cams = tuple(camera if c.name == camera.name else c for c in self.cameras)
        return Rig(cameras=cams, volume=self.volume, source=self.source, ground=self.ground)
