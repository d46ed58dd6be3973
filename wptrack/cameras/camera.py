"""Calibrated cameras and the ground plane: the geometry every tracker shares.

A :class:`Camera` is a calibrated pinhole camera (OpenCV conventions: camera axes x right, y down, z forward;
``X_cam = R @ X_world + t``; world units are metres, image units pixels, and pixel centres lie at integer
coordinates; OpenCV's distortion model). A :class:`GroundPlane` is the plane objects move on (default z = 0, the
plane the S3 template tracker's objects stand on; ``x_axis`` defaults to world x projected onto the plane). A set of
cameras is a :class:`wptrack.cameras.rig.Rig`; rig files are read and written by :mod:`wptrack.cameras.files`
(``camera_from_dict`` builds a camera from a rig-file entry).

Every problem raises :class:`~wptrack.core.errors.RigError` with a one-line message naming the file, the camera (index
and name) and the field.
"""

from __future__ import annotations

import functools
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wptrack.cameras.checks import _array, _camera_where, _fmt, _positive_int, _readonly, _validated_fields
from wptrack.core.errors import RigError

__all__ = ["Camera", "GroundPlane"]

log = logging.getLogger(__name__)


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

    @functools.cached_property
    def rvec(self) -> np.ndarray:
        """(3,) Rodrigues rotation vector of ``R``, radians (read-only; computed once: :meth:`project` runs every frame
        for the template tracker's report rule, and ``cv2.Rodrigues`` was 5 % of a 1080p run's main thread)."""
        import cv2

        rvec, _ = cv2.Rodrigues(np.array(self.R))
        return _readonly(np.asarray(rvec, dtype=np.float64).reshape(3))

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

    def image_box_cover(self, corners: np.ndarray, min_depth: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """How much of each object's image bounding box lies inside the image.

        Args:
            corners: (N, K, 3) world points per object (e.g. the 8 corners of its 3D box), metres.
            min_depth: a corner at this depth or nearer (metres) makes the object not ``ok``.

        Returns:
            ``(ok, area, inside)``: (N,) bool, every corner deeper than ``min_depth``; (N,) area of the bounding box
            of the projected corners and (N,) the part of it inside the ``width`` x ``height`` image, square pixels.
        """
        pts = np.asarray(corners, dtype=np.float64)
        n, k = pts.shape[:2]
        uv, depth = self.project(pts.reshape(-1, 3))
        uv = uv.reshape(n, k, 2)
        lo, hi = uv.min(axis=1), uv.max(axis=1)
        area = np.prod(np.maximum(hi - lo, 1e-6), axis=1)
        inside = np.prod(np.clip(np.minimum(hi, [self.width, self.height]) - np.maximum(lo, 0.0), 0.0, None), axis=1)
        return np.all(depth.reshape(n, k) > min_depth, axis=1), area, inside

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

    def for_size(self, width: int, height: int, source: str, rig_source: str = "the rig") -> Camera:
        """This camera for frames of ``width`` x ``height`` pixels from ``source``: itself when the sizes agree, the
        camera :meth:`scaled` to them when the frames are a resized copy (the same aspect ratio within 1 %).

        Raises:
            RigError: another aspect ratio (the message names the source, the camera and both sizes).
        """
        width, height = int(width), int(height)
        if (width, height) == (self.width, self.height):
            return self
        if abs(width / height - self.width / self.height) <= 0.01 * self.width / self.height:
            log.info("scaling camera %s from %dx%d to %dx%d (%s)", self.name, self.width, self.height, width, height,
                     source)  # fmt: skip
            return self.scaled(width, height)
        raise RigError(
            f"{source}: frame size {width}x{height} differs from camera '{self.name}' calibration "
            f"{self.width}x{self.height} in {rig_source} (and is not a resized copy of the same aspect ratio)"
        )

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
        # computed once: the trackers map every reported object with it each frame (np.cross costs ~30 us a call)
        object.__setattr__(self, "_y_axis", _readonly(np.cross(self.normal, self.x_axis)))

    @property
    def y_axis(self) -> np.ndarray:
        """(3,) unit in-plane direction of the ground y coordinate (``normal x x_axis``; read-only)."""
        return self._y_axis

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
