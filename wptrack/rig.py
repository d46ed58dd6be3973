"""Camera rig model shared by every tracker.

A :class:`Rig` is an ordered tuple of calibrated pinhole :class:`Camera` objects (OpenCV conventions: camera axes x
right, y down, z forward; ``X_cam = R @ X_world + t``; world units are metres, image units pixels, and pixel centres
lie at integer coordinates) plus an optional working volume and an optional ground plane (default: z = 0, the
plane the S3 template tracker's objects stand on; ``x_axis`` defaults to world x projected onto the plane).

Rig files are YAML (``.yaml``/``.yml``) or JSON (``.json``) with the same keys::

    volume: {min: [x, y, z], max: [x, y, z]}   # optional, metres
    ground: {origin: [x, y, z], normal: [nx, ny, nz], x_axis: [ax, ay, az]}   # optional plane objects move on
    cameras:
      - name: cam0
        width: 320                     # pixels
        height: 240
        K: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
        dist: [k1, k2, p1, p2, k3]     # optional (zeros if absent; 4 or 5 entries)
        R: [[...], [...], [...]]       # world-to-camera rotation, or  rvec: [rx, ry, rz]
        t: [tx, ty, tz]                # metres
      - name: cam1                     # optional for an opencv: entry (default: the file stem)
        opencv: cam1.yml               # cv2.FileStorage file, relative to the rig file
      - name: cam2                     # optional for a tsai: entry (default: the file stem)
        tsai: View_001.xml             # Tsai calibration XML (PETS), relative to the rig file; see wptrack.tsai
        units: mm                      # optional: the file's world units, mm (default) or m
        width: 480                     # optional: image size to scale the calibration to
        height: 360

An ``opencv:`` entry reads ``camera_matrix``, ``distortion_coefficients``, ``rvec`` or ``R``, ``tvec`` or ``T``,
``image_width`` and ``image_height``; keys written beside ``opencv:`` override the file's values.

Every problem raises :class:`~wptrack.errors.RigError` with a one-line message naming the file, the camera (index and
name) and the field, e.g. ``rig.yaml: cameras[1] 'cam1': K: focal length fx must be > 0, got -3.0``.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from wptrack.errors import OutputError, RigError
from wptrack.io import default_file_mode
from wptrack.rig_checks import (
    ROTATION_TOL,
    _array,
    _camera_where,
    _check_rotation,
    _fmt,
    _parse_volume,
    _positive_int,
    _readonly,
    _rodrigues_to_matrix,
    _validated_fields,
)

__all__ = ["Camera", "Rig", "save_opencv"]

log = logging.getLogger(__name__)

BOUNDS_PAD_M = 0.25
"""Padding (metres) around the camera centres used by :meth:`Rig.bounds` when no volume is set."""

_CAMERA_KEYS = ("name", "width", "height", "K", "dist", "R", "rvec", "t", "opencv")
_RIG_KEYS = ("cameras", "volume", "ground")
_FIELD_HELP = {
    "width": "image width in pixels",
    "height": "image height in pixels",
    "K": "3x3 intrinsic matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]",
    "t": "world-to-camera translation [tx, ty, tz] in metres",
}
_SUFFIXES = (".yaml", ".yml", ".json")
_OPENCV_KEYS = {  # rig-entry field -> OpenCV FileStorage key(s), first found wins
    "width": ("image_width",),
    "height": ("image_height",),
    "K": ("camera_matrix",),
    "dist": ("distortion_coefficients",),
    "t": ("tvec", "T"),
}


# ----------------------------------------------------------------------------------------------------- OpenCV files


def _read_node(node: Any) -> Any:
    """Convert a cv2.FileNode to a Python/numpy value (matrix, nested list, number or string)."""
    if node.isMap():
        mat = node.mat()
        if mat is None:
            raise ValueError("not an opencv-matrix")
        return np.asarray(mat, dtype=np.float64)
    if node.isSeq():
        return [_read_node(node.at(i)) for i in range(node.size())]
    if node.isString():
        return node.string()
    return node.real()


def _read_opencv(path: Path, where: str) -> dict[str, Any]:
    """Read the camera keys of an OpenCV FileStorage calibration file into rig-entry keys."""
    import cv2

    if not path.is_file():
        raise RigError(f"{where}: opencv: file not found: {path}")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        opened = fs.isOpened()
    except Exception as exc:  # cv2 raises cv2.error or SystemError on unparsable files
        raise RigError(f"{where}: opencv: cannot read {path} as an OpenCV FileStorage file: {_fmt(str(exc))}") from None
    if not opened:
        raise RigError(f"{where}: opencv: cannot open {path} as an OpenCV FileStorage file")
    out: dict[str, Any] = {}
    try:

        def get(key: str) -> Any:
            try:
                node = fs.getNode(key)
                if node.empty() or node.isNone():
                    return None
                return _read_node(node)
            except Exception:
                raise RigError(f"{where}: opencv: {path}: key '{key}' is not a number or matrix") from None

        for field, keys in _OPENCV_KEYS.items():
            value = next((v for v in (get(k) for k in keys) if v is not None), None)
            if value is not None:
                out[field] = value
        rvec, R = get("rvec"), get("R")
        if rvec is not None:
            out["rvec"] = rvec
        if R is not None:
            out["R"] = R
    finally:
        fs.release()
    return out


def save_opencv(camera: Camera, path: str | os.PathLike[str]) -> None:
    """Write ``camera`` as an OpenCV FileStorage file (format chosen by cv2 from the suffix: .yml/.yaml/.xml/.json).

    Keys written: ``image_width``, ``image_height``, ``camera_matrix`` (3x3), ``distortion_coefficients`` (1x5),
    ``R`` (3x3), ``rvec`` (3x1) and ``tvec`` (3x1, metres) - the keys a rig ``opencv:`` entry reads. The file is
    written atomically (temporary file in the same directory, then ``os.replace``).

    Raises:
        OutputError: the file cannot be written.
    """
    import cv2

    path = Path(path)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")
    try:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        if not fs.isOpened():
            raise OSError("cannot open for writing")
        fs.write("image_width", int(camera.width))
        fs.write("image_height", int(camera.height))
        fs.write("camera_matrix", np.array(camera.K))
        fs.write("distortion_coefficients", np.array(camera.dist).reshape(1, 5))
        fs.write("R", np.array(camera.R))
        fs.write("rvec", camera.rvec.reshape(3, 1))
        fs.write("tvec", np.array(camera.t).reshape(3, 1))
        fs.release()
        os.replace(tmp, path)
    except (OSError, cv2.error) as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise OutputError(f"{path}: cannot write OpenCV camera file: {_fmt(str(exc))}") from None


# ----------------------------------------------------------------------------------------------------- Camera


@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated pinhole camera with OpenCV (Brown-Conrady) distortion.

    Attributes:
        name: Unique name within a rig.
        width: Image width, pixels.
        height: Image height, pixels.
        K: (3, 3) float64 intrinsics ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels (zero skew).
        dist: (5,) float64 OpenCV distortion coefficients ``k1 k2 p1 p2 k3`` (zeros if absent).
        R: (3, 3) float64 world-to-camera rotation (camera axes x right, y down, z forward).
        t: (3,) float64 world-to-camera translation, metres: ``X_cam = R @ X_world + t``.

    Arrays are stored as contiguous read-only float64 copies. Construction validates every field and raises
    :class:`RigError` (source ``<memory>``) on bad input; ``dist=None`` means no distortion.
    """

    name: str
    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray

    def __post_init__(self) -> None:
        where = _camera_where("<memory>", None, self.name)
        name, width, height, K, dist, R, t = _validated_fields(
            self.name, self.width, self.height, self.K, self.dist, self.R, self.t, where
        )
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "width", width)
        object.__setattr__(self, "height", height)
        object.__setattr__(self, "K", _readonly(K))
        object.__setattr__(self, "dist", _readonly(dist))
        object.__setattr__(self, "R", _readonly(R))
        object.__setattr__(self, "t", _readonly(t))

    # -- derived quantities

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates, metres (``-R.T @ t``)."""
        return -self.R.T @ self.t

    @property
    def rvec(self) -> np.ndarray:
        """(3,) Rodrigues rotation vector of ``R``, radians."""
        import cv2

        rvec, _ = cv2.Rodrigues(np.array(self.R))
        return np.asarray(rvec, dtype=np.float64).reshape(3)

    @property
    def fx(self) -> float:
        """Horizontal focal length, pixels."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Vertical focal length, pixels."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """Principal point x, pixels."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """Principal point y, pixels."""
        return float(self.K[1, 2])

    # -- construction helpers

    @classmethod
    def look_at(
        cls,
        name: str,
        width: int,
        height: int,
        position: Sequence[float] | np.ndarray,
        target: Sequence[float] | np.ndarray,
        fx: float,
        fy: float | None = None,
        cx: float | None = None,
        cy: float | None = None,
        up: Sequence[float] | np.ndarray = (0, 0, 1),
        roll_deg: float = 0.0,
        dist: Sequence[float] | np.ndarray | None = None,
    ) -> Camera:
        """A camera at ``position`` looking at ``target``.

        The optical axis (+z) points from ``position`` to ``target``; the image 'up' direction (camera -y) is as
        close to world ``up`` as possible. ``roll_deg`` then rotates the camera about its optical axis: with
        ``roll_deg=90`` world ``up`` appears towards image left (-u), as for a camera mounted sideways that delivers
        a portrait image; with ``-90`` it appears towards image right (+u).

        Args:
            name: Camera name.
            width: Image width, pixels.
            height: Image height, pixels.
            position: (3,) camera centre, world metres.
            target: (3,) point looked at, world metres.
            fx: Horizontal focal length, pixels.
            fy: Vertical focal length, pixels (default ``fx``).
            cx: Principal point x, pixels (default ``(width - 1) / 2``).
            cy: Principal point y, pixels (default ``(height - 1) / 2``).
            up: (3,) world 'up' direction (need not be unit length).
            roll_deg: Rotation about the optical axis, degrees.
            dist: Optional distortion coefficients (4 or 5).

        Raises:
            RigError: invalid values, ``position == target`` or viewing direction parallel to ``up``.
        """
        where = f"<memory>: look_at {_fmt(name)}"
        pos = _array(position, (3,), "3 values [x, y, z] in metres", where, "position")
        tgt = _array(target, (3,), "3 values [x, y, z] in metres", where, "target")
        upv = _array(up, (3,), "3 values [x, y, z]", where, "up")
        if not math.isfinite(float(roll_deg)):
            raise RigError(f"{where}: roll_deg: must be finite, got {roll_deg!r}")
        forward = tgt - pos
        norm = float(np.linalg.norm(forward))
        if norm == 0.0:
            raise RigError(f"{where}: target: must differ from position, both are {_fmt(pos.tolist())}")
        z = forward / norm
        up_norm = float(np.linalg.norm(upv))
        if up_norm == 0.0:
            raise RigError(f"{where}: up: must be a non-zero vector")
        upv = upv / up_norm
        up_perp = upv - float(upv @ z) * z
        if float(np.linalg.norm(up_perp)) < 1e-9:
            raise RigError(f"{where}: up: viewing direction {_fmt(z.tolist())} is parallel to up; choose another up")
        y = -up_perp / np.linalg.norm(up_perp)
        x = np.cross(y, z)
        a = math.radians(float(roll_deg))
        c, s = math.cos(a), math.sin(a)
        x, y = c * x + s * y, -s * x + c * y
        R = np.stack([x, y, z])
        t = -R @ pos
        fy = fx if fy is None else fy
        cx = (width - 1) / 2.0 if cx is None else cx
        cy = (height - 1) / 2.0 if cy is None else cy
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=np.float64)
        return cls(name=name, width=width, height=height, K=K, dist=dist, R=R, t=t)

    # -- geometry

    def project(self, points: Sequence[Sequence[float]] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points into the image (with lens distortion, via ``cv2.projectPoints``).

        Points behind the camera still get pixel coordinates (mirrored); check ``depth > 0``.

        Args:
            points: (N, 3) world points, metres.

        Returns:
            ``(uv, depth)``: (N, 2) float64 pixel coordinates and (N,) float64 depth (camera-frame z, metres).

        Raises:
            ValueError: ``points`` is not an (N, 3) array.
        """
        import cv2

        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
        depth = pts @ self.R[2] + self.t[2]
        if pts.shape[0] == 0:
            return np.zeros((0, 2)), depth
        uv, _ = cv2.projectPoints(
            np.ascontiguousarray(pts).reshape(-1, 1, 3),
            self.rvec.reshape(3, 1),
            np.array(self.t).reshape(3, 1),
            np.array(self.K),
            np.array(self.dist),
        )
        return np.asarray(uv, dtype=np.float64).reshape(-1, 2), depth

    def pixel_rays(self, uv: Sequence[Sequence[float]] | np.ndarray) -> np.ndarray:
        """World directions of the viewing rays through pixels (distortion removed, via ``cv2.undistortPoints``).

        Args:
            uv: (K, 2) pixel coordinates.

        Returns:
            (K, 3) float64 unit vectors in the world frame, pointing away from the camera centre.
        """
        import cv2

        pts = np.asarray(uv, dtype=np.float64).reshape(-1, 1, 2)
        norm = cv2.undistortPoints(pts, np.array(self.K), np.array(self.dist)).reshape(-1, 2)
        rays = np.column_stack([norm, np.ones(len(norm))]) @ self.R  # R^T d per row
        return rays / np.linalg.norm(rays, axis=1, keepdims=True)

    def scaled(self, width: int, height: int) -> Camera:
        """The same camera at another resolution.

        ``fx`` and ``cx`` are multiplied by ``width / self.width``, ``fy`` and ``cy`` by ``height / self.height``;
        distortion and pose are unchanged, so projections scale: ``u' = u * sx``, ``v' = v * sy``.

        Args:
            width: New image width, pixels.
            height: New image height, pixels.
        """
        where = _camera_where("<memory>", None, self.name) + " scaled()"
        width = _positive_int(width, where, "width")
        height = _positive_int(height, where, "height")
        sx, sy = width / self.width, height / self.height
        K = np.array(self.K)
        K[0, 0] *= sx
        K[0, 2] *= sx
        K[1, 1] *= sy
        K[1, 2] *= sy
        return Camera(name=self.name, width=width, height=height, K=K, dist=self.dist, R=self.R, t=self.t)

    # -- serialisation

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python representation (the rig-file camera entry): name, width, height, K, dist, R, t."""
        return {
            "name": self.name,
            "width": int(self.width),
            "height": int(self.height),
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
        }

    @classmethod
    def from_dict(
        cls, d: Mapping[str, Any], source: str = "<dict>", index: int = 0, base_dir: Path | None = None
    ) -> Camera:
        """Build a camera from a rig-file entry.

        Args:
            d: The entry: ``name``, ``width``, ``height``, ``K``, optional ``dist``, ``R`` and/or ``rvec``, ``t``;
                or ``opencv: file`` (plus optional overriding keys).
            source: File name used in error messages.
            index: Index of the entry in the rig's camera list (error messages; default name ``cam{index}``).
            base_dir: Directory that relative ``opencv:`` paths are resolved against (default: current directory).

        Raises:
            RigError: any invalid, missing or unknown field.
        """
        if not isinstance(d, Mapping):
            raise RigError(f"{source}: cameras[{index}]: expected a mapping of camera fields, got {_fmt(d)}")
        if "tsai" in d:
            from .tsai import camera_from_entry

            return camera_from_entry(d, source, index, base_dir)
        raw_name = d.get("name")
        entry: dict[str, Any] = {}
        cv_path: Path | None = None
        if "opencv" in d:
            ref = d["opencv"]
            if not isinstance(ref, (str, os.PathLike)) or not str(ref):
                where = _camera_where(source, index, raw_name if raw_name is not None else f"cam{index}")
                raise RigError(f"{where}: opencv: expected a file path, got {_fmt(ref)}")
            cv_path = Path(ref)
            if not cv_path.is_absolute() and base_dir is not None:
                cv_path = Path(base_dir) / cv_path
            if raw_name is None:
                raw_name = cv_path.stem
            entry.update(_read_opencv(cv_path, _camera_where(source, index, raw_name)))
        if raw_name is None:
            raw_name = f"cam{index}"
        if isinstance(raw_name, (int, np.integer)) and not isinstance(raw_name, bool):
            raw_name = str(raw_name)
        where = _camera_where(source, index, raw_name)

        unknown = [k for k in d if k not in _CAMERA_KEYS]
        if unknown:
            raise RigError(f"{where}: unknown field {_fmt(unknown[0])} (expected one of {', '.join(_CAMERA_KEYS)})")
        if "R" in d or "rvec" in d:  # a rotation given beside opencv: replaces the file's rotation (either form)
            entry.pop("R", None)
            entry.pop("rvec", None)
        entry.update({k: v for k, v in d.items() if k not in ("name", "opencv")})

        missing = [f for f in ("width", "height", "K", "t") if f not in entry]
        if "R" not in entry and "rvec" not in entry:
            missing.append("R")
        if missing:
            field = missing[0]
            help_ = _FIELD_HELP.get(field, "world-to-camera rotation")
            if cv_path is not None:
                keys = ("rvec", "R") if field == "R" else _OPENCV_KEYS[field]
                names = " or ".join(f"'{k}'" for k in keys)
                raise RigError(f"{where}: opencv: {cv_path}: missing key {names} ({help_})")
            names = "'R' or 'rvec'" if field == "R" else f"'{field}'"
            raise RigError(f"{where}: missing field {names} ({help_})")

        R = entry.get("R")
        if "rvec" in entry:
            rvec = _array(entry["rvec"], (3,), "a Rodrigues vector [rx, ry, rz] in radians", where, "rvec")
            R_from_rvec = _rodrigues_to_matrix(rvec)
            if R is None:
                R = R_from_rvec
            else:
                R = _array(R, (3, 3), "a 3x3 world-to-camera rotation matrix", where, "R")
                _check_rotation(R, where)
                diff = float(np.max(np.abs(R - R_from_rvec)))
                if diff > ROTATION_TOL:
                    raise RigError(
                        f"{where}: rvec: disagrees with R (max difference {diff:.3g} > {ROTATION_TOL:g}); give only one"
                    )
        fields = _validated_fields(
            raw_name, entry["width"], entry["height"], entry["K"], entry.get("dist"), R, entry["t"], where
        )
        return cls(*fields)


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
                    list(self.volume[0]),
                    list(self.volume[1]),
                )
        if self.ground is not None and not isinstance(self.ground, GroundPlane):
            object.__setattr__(self, "ground", GroundPlane.from_dict(self.ground, source))

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
        path = Path(path)
        source = str(path)
        suffix = path.suffix.lower()
        if suffix not in _SUFFIXES:
            raise RigError(f"{source}: unsupported rig file extension {path.suffix!r} (expected .yaml, .yml or .json)")
        if not path.exists():
            raise RigError(f"{source}: rig file not found")
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise RigError(f"{source}: cannot read rig file: {_fmt(str(exc))}") from None
        try:
            data = json.loads(text) if suffix == ".json" else yaml.safe_load(text)
        except (json.JSONDecodeError, yaml.YAMLError) as exc:
            kind = "JSON" if suffix == ".json" else "YAML"
            raise RigError(f"{source}: not valid {kind}: {' '.join(str(exc).split())}") from None
        return cls.from_dict(data, source=source, base_dir=path.parent)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the rig as YAML or JSON (chosen by suffix), atomically (temp file in the same dir + ``os.replace``).

        Raises:
            RigError: unsupported suffix.
            OutputError: the file cannot be written.
        """
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix not in _SUFFIXES:
            raise RigError(f"{path}: unsupported rig file extension {path.suffix!r} (expected .yaml, .yml or .json)")
        data = self.to_dict()
        if suffix == ".json":
            text = json.dumps(data, indent=2) + "\n"
        else:
            text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None)
        tmp_name: str | None = None
        try:
            with tempfile.NamedTemporaryFile(
                "w", encoding="utf-8", dir=path.parent, prefix=f".{path.name}.", suffix=".tmp", delete=False
            ) as fh:
                tmp_name = fh.name
                os.fchmod(fh.fileno(), default_file_mode())  # NamedTemporaryFile's 0600 -> the umask's mode
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp_name, path)
        except OSError as exc:
            if tmp_name is not None:
                with contextlib.suppress(OSError):
                    os.unlink(tmp_name)
            raise OutputError(f"{path}: cannot write rig file: {_fmt(str(exc))}") from None

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
        """Build a rig from the rig-file layout (see the module docstring).

        Args:
            d: Mapping with ``cameras`` (list of camera entries) and optional ``volume`` ``{min, max}``.
            source: File name used in error messages.
            base_dir: Directory for relative ``opencv:`` paths.

        Raises:
            RigError: any invalid field.
        """
        if not isinstance(d, Mapping):
            raise RigError(f"{source}: expected a mapping with a 'cameras' list at the top level, got {_fmt(d)}")
        unknown = [k for k in d if k not in _RIG_KEYS]
        if unknown:
            raise RigError(f"{source}: unknown top-level field {_fmt(unknown[0])} (expected cameras, volume, ground)")
        if "cameras" not in d:
            raise RigError(f"{source}: missing field 'cameras' (a non-empty list of cameras)")
        entries = d["cameras"]
        if not isinstance(entries, list) or not entries:
            raise RigError(f"{source}: cameras: expected a non-empty list of cameras, got {_fmt(entries)}")
        cameras = tuple(Camera.from_dict(e, source=source, index=i, base_dir=base_dir) for i, e in enumerate(entries))
        volume = None
        if d.get("volume") is not None:
            vol = d["volume"]
            if not isinstance(vol, Mapping) or set(vol) != {"min", "max"}:
                raise RigError(
                    f"{source}: volume: expected {{min: [x, y, z], max: [x, y, z]}} in metres, got {_fmt(vol)}"
                )
            volume = (vol["min"], vol["max"])
        ground = GroundPlane.from_dict(d["ground"], source) if d.get("ground") is not None else None
        return cls(cameras=cameras, volume=volume, source=source, ground=ground)

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

    def check_frame_size(self, index: int, width: int, height: int, source: str) -> None:
        """Check that a frame from ``source`` matches camera ``index``'s calibrated size.

        Args:
            index: Camera index in the rig.
            width: Frame width, pixels.
            height: Frame height, pixels.
            source: The frame source (video path, folder...) for the message.

        Raises:
            RigError: the sizes differ.
        """
        cam = self[index]
        if int(width) != cam.width or int(height) != cam.height:
            raise RigError(
                f"{source}: frame size {width}x{height} differs from camera '{cam.name}' calibration "
                f"{cam.width}x{cam.height} in {self.source}"
            )


@dataclass(frozen=True)
class GroundPlane:
    """The plane objects move on (S3 template tracker), as an orthonormal frame in world coordinates.

    Attributes:
        origin: (3,) a point of the plane, metres (ground coordinates (0, 0)).
        normal: (3,) unit normal pointing up (away from the ground, towards the objects' tops).
        x_axis: (3,) unit in-plane direction of the ground x coordinate; ground y is ``normal x x_axis``.
    """

    origin: np.ndarray | Sequence[float] = (0.0, 0.0, 0.0)
    normal: np.ndarray | Sequence[float] = (0.0, 0.0, 1.0)
    x_axis: np.ndarray | Sequence[float] | None = None

    def __post_init__(self) -> None:
        where = "ground"
        origin = _array(self.origin, (3,), "3 values [x, y, z] in metres", "<memory>", f"{where}: origin")
        normal = _array(self.normal, (3,), "3 values [nx, ny, nz]", "<memory>", f"{where}: normal")
        nn = float(np.linalg.norm(normal))
        if not nn > 1e-9:
            raise RigError(f"<memory>: {where}: normal: expected a non-zero vector, got {_fmt(normal.tolist())}")
        normal = normal / nn
        if self.x_axis is None:
            guess = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        else:
            guess = _array(self.x_axis, (3,), "3 values [ax, ay, az]", "<memory>", f"{where}: x_axis")
        axis = guess - normal * float(guess @ normal)
        na = float(np.linalg.norm(axis))
        if not na > 1e-6:
            raise RigError(f"<memory>: {where}: x_axis: must not be parallel to the normal, got {_fmt(guess.tolist())}")
        object.__setattr__(self, "origin", _readonly(origin))
        object.__setattr__(self, "normal", _readonly(normal))
        object.__setattr__(self, "x_axis", _readonly(axis / na))

    @property
    def y_axis(self) -> np.ndarray:
        """(3,) unit in-plane direction of the ground y coordinate (``normal x x_axis``)."""
        return np.cross(self.normal, self.x_axis)

    def to_world(self, xy: np.ndarray, height: np.ndarray | float = 0.0) -> np.ndarray:
        """World points of ground coordinates ``xy`` (..., 2) at ``height`` above the plane, metres -> (..., 3)."""
        xy = np.asarray(xy, dtype=np.float64)
        h = np.asarray(height, dtype=np.float64)[..., None]
        return self.origin + xy[..., :1] * self.x_axis + xy[..., 1:2] * self.y_axis + h * self.normal

    def to_ground(self, points: np.ndarray) -> np.ndarray:
        """Ground coordinates (..., 2) of world points (..., 3) projected onto the plane, metres."""
        d = np.asarray(points, dtype=np.float64) - self.origin
        return np.stack([d @ self.x_axis, d @ self.y_axis], axis=-1)

    def to_dict(self) -> dict[str, Any]:
        """The rig-file entry: origin, normal, x_axis."""
        return {"origin": self.origin.tolist(), "normal": self.normal.tolist(), "x_axis": self.x_axis.tolist()}

    @classmethod
    def from_dict(cls, d: Any, source: str) -> GroundPlane:
        """Parse a rig file's ``ground`` entry.

        Raises:
            RigError: not a mapping, unknown keys, or invalid vectors (the message names the file and field).
        """
        if isinstance(d, GroundPlane):
            return d
        if not isinstance(d, Mapping) or not set(d) <= {"origin", "normal", "x_axis"}:
            raise RigError(
                f"{source}: ground: expected {{origin: [x, y, z], normal: [nx, ny, nz], x_axis: [ax, ay, az]}} "
                f"(metres; x_axis optional), got {_fmt(d)}"
            )
        try:
            return cls(
                origin=d.get("origin", (0.0, 0.0, 0.0)), normal=d.get("normal", (0.0, 0.0, 1.0)), x_axis=d.get("x_axis")
            )
        except RigError as exc:
            raise RigError(str(exc).replace("<memory>", source, 1)) from None
