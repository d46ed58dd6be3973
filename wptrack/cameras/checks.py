"""Checks of rig values: coercion of user values to validated numbers and arrays (camera fields, rotations, the
working volume) and the wording of :class:`~wptrack.core.errors.RigError` messages (``<where>: <field>: expected ...,
got ...``, values rendered by :func:`_fmt`).

Shared by the rig model (:mod:`wptrack.cameras.rig`), rig files (:mod:`wptrack.cameras.files`) and Tsai calibrations
(:mod:`wptrack.cameras.tsai`). ``where`` is the message prefix naming the file and camera (:func:`_camera_where`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from wptrack.core.errors import RigError

ROTATION_TOL = 1e-6
"""Tolerance on ``max |R^T R - I|``, on ``|det R - 1|`` and on the R/rvec agreement (max abs difference)."""


def _fmt(value: Any) -> str:
    """Short one-line rendering of a user value for error messages."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, np.ndarray):
        text = np.array2string(value, precision=6, separator=", ", threshold=20).replace("\n", "")
    else:
        text = repr(value)
    text = " ".join(text.split())
    return text if len(text) <= 120 else text[:117] + "..."


def _array(value: Any, shape: tuple[int, ...], what: str, where: str, field: str) -> np.ndarray:
    """Coerce ``value`` to a finite float64 array of ``shape``.

    Vectors (``shape == (n,)``) also accept ``(n, 1)`` and ``(1, n)`` input, as OpenCV writes them.

    Raises:
        RigError: not numeric, wrong shape or non-finite.
    """
    if isinstance(value, (str, bytes, Mapping)) or value is None:
        raise RigError(f"{where}: {field}: expected {what}, got {_fmt(value)}")
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise RigError(f"{where}: {field}: expected {what}, got {_fmt(value)}") from None
    if len(shape) == 1 and arr.ndim == 2 and 1 in arr.shape and arr.size == shape[0]:
        arr = arr.reshape(shape)
    if arr.shape != shape:
        raise RigError(f"{where}: {field}: expected {what}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise RigError(f"{where}: {field}: values must be finite, got {_fmt(arr)}")
    return arr


def _readonly(arr: np.ndarray) -> np.ndarray:
    out = np.ascontiguousarray(arr, dtype=np.float64).copy()
    out.setflags(write=False)
    return out


def _positive_int(value: Any, where: str, field: str) -> int:
    """A positive integer (integral floats such as ``320.0`` accepted, booleans refused)."""
    unit = "pixels" if field in ("width", "height") else "count"
    ok = False
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        ok = value > 0
    elif isinstance(value, (float, np.floating)):
        ok = math.isfinite(value) and value > 0 and float(value).is_integer()
    if not ok:
        raise RigError(f"{where}: {field}: must be a positive integer ({unit}), got {_fmt(value)}")
    return int(value)


def _check_rotation(R: np.ndarray, where: str, field: str = "R") -> None:
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if err > ROTATION_TOL:
        raise RigError(
            f"{where}: {field}: not a rotation matrix, max |R^T R - I| = {err:.3g} > {ROTATION_TOL:g} "
            "(rows must be orthonormal)"
        )
    det = float(np.linalg.det(R))
    if abs(det - 1.0) > ROTATION_TOL:
        raise RigError(f"{where}: {field}: determinant must be +1 (a rotation, not a reflection), got {det:.6g}")


def _rodrigues_to_matrix(rvec: np.ndarray) -> np.ndarray:
    import cv2

    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    return np.asarray(R, dtype=np.float64)


def _validated_fields(
    name: Any, width: Any, height: Any, K: Any, dist: Any, R: Any, t: Any, where: str
) -> tuple[str, int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validate and coerce camera fields; ``where`` prefixes every error message."""
    if not isinstance(name, str) or not name.strip():
        raise RigError(f"{where}: name: must be a non-empty string, got {_fmt(name)}")
    width = _positive_int(width, where, "width")
    height = _positive_int(height, where, "height")

    K = _array(K, (3, 3), "a 3x3 matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]", where, "K")
    for label, value in (("fx", K[0, 0]), ("fy", K[1, 1])):
        if not value > 0:
            raise RigError(f"{where}: K: focal length {label} must be > 0, got {float(value)!r}")
    if K[0, 1] != 0.0:
        raise RigError(f"{where}: K: skew K[0][1] must be 0 (not supported), got {float(K[0, 1])!r}")
    if K[1, 0] != 0.0 or not np.array_equal(K[2], [0.0, 0.0, 1.0]):
        raise RigError(f"{where}: K: expected the form [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {_fmt(K.tolist())}")

    if dist is None:
        dist = np.zeros(5)
    else:
        if isinstance(dist, (str, bytes, Mapping)):
            raise RigError(f"{where}: dist: expected 4 or 5 coefficients [k1, k2, p1, p2, k3], got {_fmt(dist)}")
        try:
            d = np.array(dist, dtype=np.float64)
        except (TypeError, ValueError):
            raise RigError(
                f"{where}: dist: expected 4 or 5 coefficients [k1, k2, p1, p2, k3], got {_fmt(dist)}"
            ) from None
        if d.ndim > 2 or (d.ndim == 2 and 1 not in d.shape):
            raise RigError(f"{where}: dist: expected 4 or 5 coefficients [k1, k2, p1, p2, k3], got shape {d.shape}")
        d = d.reshape(-1)
        if not np.all(np.isfinite(d)):
            raise RigError(f"{where}: dist: values must be finite, got {_fmt(d)}")
        if d.size > 5 and np.all(d[5:] == 0.0):
            d = d[:5]  # e.g. an 8/12/14-coefficient OpenCV model whose higher terms are unused
        if d.size not in (4, 5):
            raise RigError(
                f"{where}: dist: expected 4 or 5 coefficients [k1, k2, p1, p2, k3] "
                f"(higher-order models unsupported), got {d.size}"
            )
        dist = np.concatenate([d, np.zeros(5 - d.size)])

    R = _array(R, (3, 3), "a 3x3 world-to-camera rotation matrix", where, "R")
    _check_rotation(R, where)
    t = _array(t, (3,), "3 values [tx, ty, tz] in metres", where, "t")
    return name, width, height, K, dist, R, t


def _camera_where(source: str, index: int | None, name: Any) -> str:
    if index is None:
        return f"{source}: camera {_fmt(name)}"
    return f"{source}: cameras[{index}] {_fmt(name)}"


def _parse_volume(volume: Any, source: str) -> tuple[np.ndarray, np.ndarray]:
    where = source
    if isinstance(volume, Mapping) or not isinstance(volume, (tuple, list)) or len(volume) != 2:
        raise RigError(f"{where}: volume: expected (min_xyz, max_xyz) in metres, got {_fmt(volume)}")
    lo = _array(volume[0], (3,), "3 values [x, y, z] in metres", where, "volume: min")
    hi = _array(volume[1], (3,), "3 values [x, y, z] in metres", where, "volume: max")
    if not np.all(lo < hi):
        raise RigError(
            f"{where}: volume: min must be < max on every axis, got min {_fmt(lo.tolist())} max {_fmt(hi.tolist())}"
        )
    return _readonly(lo), _readonly(hi)
