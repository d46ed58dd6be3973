"""Rig files: reading a ``.yaml``/``.yml``/``.json`` rig file into a :class:`~wptrack.cameras.rig.Rig` (camera entries
given inline, by an OpenCV FileStorage file or by a Tsai calibration), writing a rig back, and writing a camera as an
OpenCV FileStorage file. The rig model itself is :mod:`wptrack.cameras.rig`, whose ``Rig.load``, ``Rig.save``,
``Rig.from_dict`` call the functions here; :func:`camera_from_dict` builds one camera from its entry.

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
        tsai: View_001.xml             # Tsai calibration XML (PETS), relative to the rig file; see wptrack.cameras.tsai
        units: mm                      # optional: the file's world units, mm (default) or m
        width: 480                     # optional: image size to scale the calibration to
        height: 360

An ``opencv:`` entry reads ``camera_matrix``, ``distortion_coefficients``, ``rvec`` or ``R``, ``tvec`` or ``T``,
``image_width`` and ``image_height``; keys written beside ``opencv:`` override the file's values.

Every problem raises :class:`~wptrack.core.errors.RigError` with a one-line message naming the file, the camera (index
and name) and the field, e.g. ``rig.yaml: cameras[1] 'cam1': K: focal length fx must be > 0, got -3.0``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from wptrack.cameras.camera import Camera, GroundPlane
from wptrack.cameras.checks import (
    ROTATION_TOL,
    _array,
    _camera_where,
    _check_rotation,
    _fmt,
    _rodrigues_to_matrix,
    _validated_fields,
)
from wptrack.cameras.tsai import camera_from_entry
from wptrack.core.errors import OutputError, RigError
from wptrack.io.atomic import atomic_path, atomic_write_text

if TYPE_CHECKING:
    from wptrack.cameras.rig import Rig

__all__ = ["camera_from_dict", "load_rig", "rig_from_dict", "save_opencv", "save_rig"]

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


# ----------------------------------------------------------------------------------------------------- rig files


def load_rig(cls: type[Rig], path: str | os.PathLike[str]) -> Rig:
    """:meth:`Rig.load <wptrack.cameras.rig.Rig.load>`: read and parse a rig file, then build the rig with
    ``cls.from_dict``."""
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


def save_rig(rig: Rig, path: str | os.PathLike[str]) -> None:
    """:meth:`Rig.save <wptrack.cameras.rig.Rig.save>`: write ``rig.to_dict()`` as YAML or JSON (by suffix),
    atomically."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in _SUFFIXES:
        raise RigError(f"{path}: unsupported rig file extension {path.suffix!r} (expected .yaml, .yml or .json)")
    data = rig.to_dict()
    if suffix == ".json":
        text = json.dumps(data, indent=2) + "\n"
    else:
        text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None)
    try:
        atomic_write_text(path, text)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write rig file: {_fmt(str(exc))}") from None


def rig_from_dict(cls: type[Rig], d: Any, source: str = "<dict>", base_dir: Path | None = None) -> Rig:
    """:meth:`Rig.from_dict <wptrack.cameras.rig.Rig.from_dict>`: check the top-level layout, parse the camera entries,
    volume and ground plane, and build the rig (``cls``)."""
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
    cameras = tuple(camera_from_dict(e, source=source, index=i, base_dir=base_dir) for i, e in enumerate(entries))
    volume = None
    if d.get("volume") is not None:
        vol = d["volume"]
        if not isinstance(vol, Mapping) or set(vol) != {"min", "max"}:
            raise RigError(f"{source}: volume: expected {{min: [x, y, z], max: [x, y, z]}} in metres, got {_fmt(vol)}")
        volume = (vol["min"], vol["max"])
    ground = GroundPlane.from_dict(d["ground"], source) if d.get("ground") is not None else None
    return cls(cameras=cameras, volume=volume, source=source, ground=ground)


def camera_from_dict(d: Any, source: str = "<dict>", index: int = 0, base_dir: Path | None = None) -> Camera:
    """Build a camera from a rig-file entry.

    Args:
        d: The entry: ``name``, ``width``, ``height``, ``K``, optional ``dist``, ``R`` and/or ``rvec``, ``t``; or
            ``opencv: file`` (plus optional overriding keys); or ``tsai: file`` (:mod:`wptrack.cameras.tsai`).
        source: File name used in error messages.
        index: Index of the entry in the rig's camera list (error messages; default name ``cam{index}``).
        base_dir: Directory that relative ``opencv:`` / ``tsai:`` paths are resolved against (default: current
            directory).

    Raises:
        RigError: any invalid, missing or unknown field.
    """
    if not isinstance(d, Mapping):
        raise RigError(f"{source}: cameras[{index}]: expected a mapping of camera fields, got {_fmt(d)}")
    if "tsai" in d:
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
    return Camera(*fields)


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
    try:
        with atomic_path(path) as tmp:
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
    except (OSError, cv2.error) as exc:
        raise OutputError(f"{path}: cannot write OpenCV camera file: {_fmt(str(exc))}") from None
