"""Tsai camera calibrations (the format PETS 2009 and many older datasets publish) as wptrack cameras.

A Tsai calibration file is XML with one ``<Camera>`` element holding three children::

    <Geometry width= height= ncx= nfx= dx= dy= dpx= dpy=/>   sensor: pixels and millimetres per sensor element
    <Intrinsic focal= kappa1= cx= cy= sx=/>                 f (mm), radial distortion (1/mm^2), centre (px), scale
    <Extrinsic tx= ty= tz= rx= ry= rz=/>                    world-to-camera translation (world units), angles (rad)

Tsai's model (R. Y. Tsai, "A versatile camera calibration technique ...", IEEE J. Robotics and Automation 3(4),
1987; equations as implemented in R. Willson's reference code, numbered here T1-T5):

* (T1) ``[xc, yc, zc] = R [xw, yw, zw] + T`` with ``R = Rz(rz) Ry(ry) Rx(rx)``;
* (T2) undistorted sensor coordinates ``Xu = f xc / zc``, ``Yu = f yc / zc`` (mm);
* (T3) radial distortion ``Xu = Xd (1 + kappa1 rd^2)``, ``Yu = Yd (1 + kappa1 rd^2)``, ``rd^2 = Xd^2 + Yd^2``
  (the distorted radius is the root of the cubic ``kappa1 rd^3 + rd - ru = 0``);
* (T4) pixels ``u = Xd sx / dpx + Cx``, ``v = Yd / dpy + Cy``.

Tsai's distortion maps distorted to undistorted coordinates; OpenCV's (the model of
:class:`wptrack.cameras.rig.Camera` and of the projection kernel) maps undistorted to distorted. The conversion keeps
K, R and t exact (``fx = f sx / dpx``, ``fy = f / dpy``, ``cx = Cx``, ``cy = Cy``, ``t = T`` in metres) and fits
``(k1, k2, k3)`` (``p1 = p2 = 0``) by weighted least squares so that OpenCV's polynomial reproduces Tsai's
radial factor ``rd / ru`` over the whole image plus a 10 % margin in radius. For PETS 2009 View_001 the largest
residual over the image is 3.4e-4 pixel (``tsai_fit_residual`` reports it for any file; the test in
``tests/test_tsai.py`` checks < 0.01 px), far below the annotation noise.

An image scaled from the calibrated size (PETS ships 768x576 calibrations for 480x360 copies) is handled by
:meth:`wptrack.cameras.rig.Camera.scaled` (K scales, the normalised distortion is unchanged).
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wptrack.cameras.camera import Camera
from wptrack.cameras.checks import _camera_where, _fmt, _positive_int
from wptrack.core.errors import RigError

__all__ = ["TsaiCalibration", "read_tsai", "load_tsai_camera", "tsai_to_camera", "tsai_fit_residual", "UNITS"]

UNITS = {"mm": 1.0e-3, "m": 1.0}
"""Metres per world unit of the calibration file's translation (``units`` of a ``tsai:`` rig entry)."""

FIT_MARGIN = 1.1
"""The distortion fit covers distorted radii up to this multiple of the farthest image corner's."""

_FIELDS = {
    "Geometry": ("width", "height", "ncx", "nfx", "dx", "dy", "dpx", "dpy"),
    "Intrinsic": ("focal", "kappa1", "cx", "cy", "sx"),
    "Extrinsic": ("tx", "ty", "tz", "rx", "ry", "rz"),
}


def _rotation(rx: float, ry: float, rz: float) -> np.ndarray:
    """Tsai's world-to-camera rotation ``Rz(rz) Ry(ry) Rx(rx)`` (T1; Willson's r1..r9)."""
    sa, ca = math.sin(rx), math.cos(rx)
    sb, cb = math.sin(ry), math.cos(ry)
    sg, cg = math.sin(rz), math.cos(rz)
    return np.array(
        [
            [cb * cg, cg * sa * sb - ca * sg, sa * sg + ca * cg * sb],
            [cb * sg, sa * sb * sg + ca * cg, ca * sb * sg - cg * sa],
            [-sb, cb * sa, ca * cb],
        ]
    )


def _distorted_radius(ru: np.ndarray, kappa1: float) -> np.ndarray:
    """Root ``rd >= 0`` of ``kappa1 rd^3 + rd - ru = 0`` (T3), elementwise; ``ru`` in mm.

    For ``kappa1 > 0`` (barrel distortion) the cubic has one real root, given by Cardano's formula; for
    ``kappa1 < 0`` the smallest positive root is found by Newton's method from ``rd = ru`` (monotone there).
    Both are polished with two Newton steps (residual at machine precision).
    """
    ru = np.asarray(ru, dtype=np.float64)
    if kappa1 == 0.0:
        return ru.copy()
    if kappa1 > 0.0:
        p = 1.0 / (3.0 * kappa1)
        q = ru / (2.0 * kappa1)
        s = np.sqrt(q * q + p**3)
        rd = np.cbrt(q + s) + np.cbrt(q - s)
        iters = 2
    else:
        rd = ru.copy()
        iters = 60
    for _ in range(iters):
        rd = rd - (kappa1 * rd**3 + rd - ru) / (3.0 * kappa1 * rd**2 + 1.0)
    return rd


@dataclass(frozen=True)
class TsaiCalibration:
    """A parsed Tsai calibration (values as in the file: pixels, millimetres, radians, world units).

    Attributes:
        width, height: Calibrated image size, pixels.
        ncx, nfx, dx, dy, dpx, dpy: Sensor geometry (elements, pixels, mm per element / per pixel).
        focal: Effective focal length f, mm.  kappa1: Radial distortion, 1/mm^2.
        cx, cy: Image centre, pixels.  sx: Horizontal scale factor.
        T: (3,) world-to-camera translation, world units.  rx, ry, rz: Rotation angles, radians.
        source: File name used in messages.
    """

    width: int
    height: int
    ncx: float
    nfx: float
    dx: float
    dy: float
    dpx: float
    dpy: float
    focal: float
    kappa1: float
    cx: float
    cy: float
    sx: float
    T: np.ndarray
    rx: float
    ry: float
    rz: float
    source: str = "<memory>"

    @property
    def R(self) -> np.ndarray:
        """(3, 3) world-to-camera rotation (T1)."""
        return _rotation(self.rx, self.ry, self.rz)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tsai's forward projection (T1-T4), the reference for the conversion.

        Args:
            points: (N, 3) world points in the file's world units.

        Returns:
            ``(uv, zc)``: (N, 2) pixels in the calibrated image and (N,) camera depth in world units.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        xc = pts @ self.R.T + self.T  # (T1)
        xu = self.focal * xc[:, 0] / xc[:, 2]  # (T2)
        yu = self.focal * xc[:, 1] / xc[:, 2]
        ru = np.hypot(xu, yu)
        rd = _distorted_radius(ru, self.kappa1)  # (T3)
        ratio = np.divide(rd, ru, out=np.ones_like(ru), where=ru > 0)
        u = xu * ratio * self.sx / self.dpx + self.cx  # (T4)
        v = yu * ratio / self.dpy + self.cy
        return np.column_stack([u, v]), xc[:, 2]

    def back_project(self, uv: np.ndarray, z: float = 0.0) -> np.ndarray:
        """Tsai's inverse: pixels to world points on the plane ``z_world = z`` (T4, T3, T2, T1 inverted).

        Args:
            uv: (N, 2) pixels in the calibrated image.
            z: Height of the plane, world units.

        Returns:
            (N, 3) world points, world units (NaN where the ray is parallel to the plane).
        """
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        xd = self.dpx * (uv[:, 0] - self.cx) / self.sx  # (T4)
        yd = self.dpy * (uv[:, 1] - self.cy)
        factor = 1.0 + self.kappa1 * (xd * xd + yd * yd)  # (T3)
        ray_c = np.column_stack([xd * factor, yd * factor, np.full(len(uv), self.focal)])  # (T2)
        R = self.R
        centre = -R.T @ self.T  # (T1)
        ray_w = ray_c @ R
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (z - centre[2]) / ray_w[:, 2]
        s = np.where(np.isfinite(s), s, np.nan)
        return centre + s[:, None] * ray_w


def _float(elem: ET.Element, tag: str, field: str, where: str) -> float:
    raw = elem.get(field)
    if raw is None:
        raise RigError(f"{where}: <{tag}> is missing attribute '{field}'")
    try:
        value = float(raw)
    except ValueError:
        raise RigError(f"{where}: <{tag}> {field}: expected a number, got {raw!r}") from None
    if not math.isfinite(value):
        raise RigError(f"{where}: <{tag}> {field}: expected a finite number, got {raw!r}")
    return value


def read_tsai(path: str | os.PathLike[str], where: str | None = None) -> TsaiCalibration:
    """Parse a Tsai calibration XML file.

    Args:
        path: The file.
        where: Prefix of error messages (default: the path).

    Raises:
        RigError: missing/unreadable file, malformed XML, a missing element or attribute, a non-numeric,
            non-finite or out-of-range value (message names the file and the field).
    """
    path = Path(path)
    where = f"{where}: tsai: {path}" if where else str(path)
    if not path.is_file():
        raise RigError(f"{where}: file not found")
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as exc:
        raise RigError(f"{where}: cannot read as Tsai calibration XML: {exc}") from None
    if root.tag != "Camera":
        found = root.find("Camera")
        if found is None:
            raise RigError(f"{where}: expected a <Camera> element, got <{root.tag}>")
        root = found
    values: dict[str, float] = {}
    for tag, fields in _FIELDS.items():
        elem = root.find(tag)
        if elem is None:
            raise RigError(f"{where}: missing element <{tag}> (attributes {', '.join(fields)})")
        for field in fields:
            values[field] = _float(elem, tag, field, where)
    for field, tag in (("width", "Geometry"), ("height", "Geometry")):
        if values[field] <= 0 or values[field] != int(values[field]):
            raise RigError(f"{where}: <{tag}> {field}: expected a positive whole number of pixels, got {values[field]}")
    for field, tag in (("dpx", "Geometry"), ("dpy", "Geometry"), ("focal", "Intrinsic"), ("sx", "Intrinsic")):
        if values[field] <= 0:
            raise RigError(f"{where}: <{tag}> {field}: must be > 0, got {values[field]}")
    return TsaiCalibration(
        width=int(values["width"]),
        height=int(values["height"]),
        **{k: values[k] for k in ("ncx", "nfx", "dx", "dy", "dpx", "dpy", "focal", "kappa1", "cx", "cy", "sx")},
        T=np.array([values["tx"], values["ty"], values["tz"]]),
        rx=values["rx"],
        ry=values["ry"],
        rz=values["rz"],
        source=str(path),
    )


def _corner_radius_mm(calib: TsaiCalibration) -> float:
    """Largest distorted sensor radius (mm) over the corners of the calibrated image (T4 inverted)."""
    u = np.array([-0.5, calib.width - 0.5, -0.5, calib.width - 0.5])
    v = np.array([-0.5, -0.5, calib.height - 0.5, calib.height - 0.5])
    xd = calib.dpx * (u - calib.cx) / calib.sx
    yd = calib.dpy * (v - calib.cy)
    return float(np.max(np.hypot(xd, yd)))


def _fit_distortion(calib: TsaiCalibration) -> np.ndarray:
    """OpenCV ``(k1, k2, p1, p2, k3)`` approximating Tsai's radial factor ``rd / ru`` (``p1 = p2 = 0``).

    The factor is a function of the normalised undistorted radius ``r = ru / f``; OpenCV's is
    ``1 + k1 r^2 + k2 r^4 + k3 r^6``. Residuals are weighted by ``r`` so the fit minimises pixel error
    (a factor error e displaces a point by about ``fx r e`` pixels).
    """
    rd = np.linspace(0.0, FIT_MARGIN * _corner_radius_mm(calib), 2001)[1:]
    ru = rd * (1.0 + calib.kappa1 * rd * rd)  # (T3)
    r = ru / calib.focal
    target = rd / ru - 1.0
    r2 = r * r
    A = np.column_stack([r2, r2 * r2, r2 * r2 * r2]) * r[:, None]
    k, *_ = np.linalg.lstsq(A, target * r, rcond=None)
    return np.array([k[0], k[1], 0.0, 0.0, k[2]])


def tsai_to_camera(
    calib: TsaiCalibration,
    name: str,
    units: str = "mm",
    width: int | None = None,
    height: int | None = None,
):
    """The :class:`wptrack.cameras.rig.Camera` equivalent to a Tsai calibration.

    Args:
        calib: The parsed calibration.
        name: Camera name.
        units: World units of the file's translation: ``"mm"`` (PETS, Tsai's software) or ``"m"``.
        width, height: Image size to build the camera for (pixels); default the calibrated size. A different
            size scales K (:meth:`Camera.scaled`), e.g. 480x360 for PETS's 768x576 calibration.

    Returns:
        The camera (world in metres; ``X_cam = R X_world + t``).

    Raises:
        RigError: unknown ``units``.
    """
    if units not in UNITS:
        raise RigError(f"{calib.source}: units: expected one of {', '.join(UNITS)}, got {units!r}")
    fx = calib.focal * calib.sx / calib.dpx  # (T2, T4)
    fy = calib.focal / calib.dpy
    K = np.array([[fx, 0.0, calib.cx], [0.0, fy, calib.cy], [0.0, 0.0, 1.0]])
    cam = Camera(
        name=name,
        width=calib.width,
        height=calib.height,
        K=K,
        dist=_fit_distortion(calib),
        R=calib.R,
        t=calib.T * UNITS[units],
    )
    if width is not None or height is not None:
        cam = cam.scaled(calib.width if width is None else width, calib.height if height is None else height)
    return cam


def tsai_fit_residual(calib: TsaiCalibration, step: float = 4.0) -> float:
    """Largest distance (pixels, calibrated image) between Tsai's and the converted camera's projection.

    Evaluated over a grid of image points every ``step`` pixels: each pixel is back-projected with Tsai's model
    onto a plane 1 world unit in front of the camera, then projected with both models.
    """
    cam = tsai_to_camera(calib, "fit", units="m")
    u, v = np.meshgrid(np.arange(0.0, calib.width, step), np.arange(0.0, calib.height, step))
    uv = np.column_stack([u.ravel(), v.ravel()])
    xd = calib.dpx * (uv[:, 0] - calib.cx) / calib.sx
    yd = calib.dpy * (uv[:, 1] - calib.cy)
    factor = 1.0 + calib.kappa1 * (xd * xd + yd * yd)
    xc = np.column_stack([xd * factor / calib.focal, yd * factor / calib.focal, np.ones(len(uv))])
    world = (xc - calib.T) @ calib.R  # R^T (xc - T)
    uv_tsai, _ = calib.project(world)
    uv_cv, _ = cam.project(world)
    return float(max(np.max(np.linalg.norm(uv_tsai - uv, axis=1)), np.max(np.linalg.norm(uv_cv - uv_tsai, axis=1))))


_ENTRY_KEYS = ("name", "tsai", "units", "width", "height")


def camera_from_entry(d, source: str, index: int, base_dir: Path | None):
    """A rig-file camera entry ``{tsai: file, name?, units?, width?, height?}`` as a camera.

    ``tsai`` is resolved against ``base_dir`` (the rig file's folder); ``width``/``height`` give the image size
    the camera is built for (the calibration is scaled to it); ``units`` is ``mm`` (default) or ``m``.

    Raises:
        RigError: an unknown key, a bad value, or any problem of the file (message names rig file, camera, field).
    """
    ref = d["tsai"]
    name = d.get("name")
    if not isinstance(ref, (str, os.PathLike)) or not str(ref):
        where = _camera_where(source, index, name if name is not None else f"cam{index}")
        raise RigError(f"{where}: tsai: expected a file path, got {_fmt(ref)}")
    path = Path(ref)
    if not path.is_absolute() and base_dir is not None:
        path = Path(base_dir) / path
    if name is None:
        name = path.stem
    where = _camera_where(source, index, name)
    unknown = [k for k in d if k not in _ENTRY_KEYS]
    if unknown:
        raise RigError(
            f"{where}: unknown field {_fmt(unknown[0])} beside tsai: (expected one of {', '.join(_ENTRY_KEYS)})"
        )
    units = d.get("units", "mm")
    if units not in UNITS:
        raise RigError(f"{where}: units: expected one of {', '.join(UNITS)}, got {_fmt(units)}")
    width = None if d.get("width") is None else _positive_int(d["width"], where, "width")
    height = None if d.get("height") is None else _positive_int(d["height"], where, "height")
    calib = read_tsai(path, where)
    return tsai_to_camera(calib, str(name), units=units, width=width, height=height)


def load_tsai_camera(
    path: str | os.PathLike[str],
    name: str | None = None,
    width: int | None = None,
    height: int | None = None,
    units: str = "mm",
):
    """Read a Tsai calibration file as a :class:`wptrack.cameras.rig.Camera`.

    Args:
        path: The XML file.
        name: Camera name (default: the file stem).
        width, height: Image size to build the camera for (default: the calibrated size).
        units: World units of the file: ``"mm"`` (default, PETS) or ``"m"``.

    Raises:
        RigError: as :func:`read_tsai` and :func:`tsai_to_camera`.
    """
    calib = read_tsai(path)
    return tsai_to_camera(calib, name or Path(path).stem, units=units, width=width, height=height)
