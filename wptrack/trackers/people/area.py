"""The working area of the S2 people tracker: the part of the ground where people are looked for.

By default it is derived from the calibration alone: the ground points (z = 0) at which a standing person would be
seen by at least ``AreaConfig.min_cameras`` cameras (two: the tracker adds people where several views agree). A
camera *sees* a ground point when at least ``AreaConfig.min_visible`` of the person's vertical axis there (from the
floor to ``person_height``) projects inside its image, in front of it and within the range where its lens model
is valid (the projection kernels' fold-back guard), and when that person would be at least ``min_person_height``
pixels tall in its image (so the area stops where people become too small to track: the "sensible distance" of
a camera that sees the horizon; ``max_distance`` bounds it in any case). A rig's ``volume`` replaces the area by
its ground rectangle.

The area is a boolean mask on a ground grid of ``cell`` metres; the tracker's evidence map covers its bounding box,
people are added only inside it and removed when they leave it.

Errors (:class:`~wptrack.core.errors.RigError`, one line naming the cameras): cameras that see no common ground, and a
``volume`` that no camera sees, or that fewer than ``min_cameras`` cameras see anywhere.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from wptrack.cameras.rig import Camera, Rig
from wptrack.core.config import check, param
from wptrack.core.errors import RigError

log = logging.getLogger(__name__)

AXIS_SAMPLES = 9
"""Points sampled on a person's vertical axis to decide whether a camera sees it."""
MIN_DEPTH = 0.1
"""Points nearer than this to a camera's image plane (metres) are not seen."""


@dataclass(frozen=True)
class AreaConfig:
    """The working area when the rig has no ``volume`` (ours): the ground seen by
    ``min_cameras`` cameras, from the calibration.

    Attributes:
        min_cameras: cameras that must see a ground point for it to be in the area (at most the rig's cameras).
            Ours: 2 (people are added where two views agree).
        person_height: height of the standing person whose visibility decides, metres. Ours: 1.7.
        min_visible: fraction of the person's vertical axis that must project inside a camera's image for the
            camera to see the point (a person cut by the image border is still tracked). Ours: 0.5.
        min_person_height: a camera sees a point only where that person would be at least this tall in its image,
            as a fraction of the image height: the area ends where people become too small to track, and the same
            camera at another resolution (a resized copy of its video) has the same area. Ours: 0.1 (29 pixels of
            the EPFL terrace's 288 rows).
        max_distance: and only within this ground distance of the camera, metres. Ours: 50.
        cell: resolution of the area, metres. Ours: 0.25.
    """

    min_cameras: int = param(2, help="cameras that must see a ground point for it to be in the area", lo=1)
    person_height: float = param(
        1.7,
        help="height of the standing person whose visibility decides",
        units="m",
        lo=0.0,
        lo_open=True,
    )
    min_visible: float = param(
        0.5,
        help="fraction of that person's axis inside a camera's image for the camera to see the point",
        lo=0.0,
        hi=1.0,
        lo_open=True,
    )
    min_person_height: float = param(
        0.1,
        help="a camera sees a point only where that person is at least this tall in its image (of the image height)",
        lo=0.0,
        hi=1.0,
        lo_open=True,
    )
    max_distance: float = param(
        50.0,
        help="and only within this ground distance of the camera",
        units="m",
        lo=0.0,
        lo_open=True,
    )
    cell: float = param(0.25, help="resolution of the area", units="m", lo=0.0, lo_open=True)

    def __post_init__(self) -> None:
        check(self, "area.")


@dataclass(frozen=True)
class WorkingArea:
    """Where people are looked for.

    Attributes:
        origin: (2,) ground (x, y) of the corner of cell (0, 0), metres.
        cell: cell edge, metres.
        mask: (ny, nx) bool: the cells in the area (row = y).
        cameras: (ny, nx) int: cameras seeing each cell's centre (0 where not computed: a rig volume).
        source: ``"calibration"`` or ``"volume"``.
        z_top: top of the working volume, metres (the rig volume's, else ``person_height`` + 0.2).
        visible: the ground seen by at least one camera (``"calibration"``: where tracked people are followed;
            people are added only in ``mask``), or None (a rig volume: the volume is both).
    """

    origin: np.ndarray
    cell: float
    mask: np.ndarray
    cameras: np.ndarray
    source: str
    z_top: float
    visible: WorkingArea | None = None

    @property
    def followed(self) -> WorkingArea:
        """Where tracked people are followed: :attr:`visible`, or the area itself."""
        return self.visible if self.visible is not None else self

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lo, hi)`` (2,) each: the bounding box of the area's cells, metres."""
        rows, cols = np.nonzero(self.mask)
        lo = self.origin + self.cell * np.array([cols.min(), rows.min()], dtype=np.float64)
        hi = self.origin + self.cell * np.array([cols.max() + 1, rows.max() + 1], dtype=np.float64)
        return lo, hi

    @property
    def square_metres(self) -> float:
        """The area's surface, m^2."""
        return float(self.mask.sum()) * self.cell**2

    def grown(self, margin: float) -> WorkingArea:
        """The area grown by ``margin`` metres (cell resolution; the grid gains a border to hold it)."""
        import cv2

        r = max(0, int(math.ceil(margin / self.cell)))
        if r == 0:
            return self
        padded = np.pad(self.mask.astype(np.uint8), r)
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
        mask = cv2.dilate(padded, kernel) > 0
        cams = np.pad(self.cameras, r)
        return WorkingArea(self.origin - r * self.cell, self.cell, mask, cams, self.source, self.z_top)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """Whether ground points ``xy`` (..., 2) lie in the area (the cell holding them is in it)."""
        xy = np.asarray(xy, dtype=np.float64)
        mask = self.mask
        ij = np.floor((xy - self.origin) / self.cell).astype(np.int64)
        ny, nx = mask.shape
        inside = (ij[..., 0] >= 0) & (ij[..., 0] < nx) & (ij[..., 1] >= 0) & (ij[..., 1] < ny)
        out = np.zeros(inside.shape, dtype=bool)
        out[inside] = mask[ij[..., 1][inside], ij[..., 0][inside]]
        return out

    def resample(self, origin: np.ndarray, cell: float, nx: int, ny: int) -> np.ndarray:
        """The area on another grid (cell centres looked up): (ny, nx) bool."""
        xs = origin[0] + cell * (np.arange(nx) + 0.5)
        ys = origin[1] + cell * (np.arange(ny) + 0.5)
        gx, gy = np.meshgrid(xs, ys)
        return self.contains(np.stack([gx, gy], axis=-1))

    def describe(self) -> str:
        """One line for the log: where the area comes from, its surface and bounding box."""
        lo, hi = self.bounds
        where = "the rig's volume" if self.source == "volume" else "the ground seen by two or more cameras"
        return (
            f"working area: {where}, {self.square_metres:.1f} m^2 within x {lo[0]:.2f}..{hi[0]:.2f} m, "
            f"y {lo[1]:.2f}..{hi[1]:.2f} m"
        )


def _r2_max(cam: Camera) -> float:
    from wptrack.cameras.structs import R2_FOLD_MARGIN, corner_radius2, fold_radius2

    return float(min(R2_FOLD_MARGIN * corner_radius2(cam), fold_radius2(cam.dist), 1.0e6))


def camera_sees(cam: Camera, points: np.ndarray) -> np.ndarray:
    """Whether each world point (N, 3) projects inside ``cam``'s image, in front of it and within the radius where
    its distortion model is valid (the rule of ``kernels.camera.project``): (N,) bool."""
    pts = np.asarray(points, dtype=np.float64)
    cam_pts = pts @ cam.R.T + cam.t
    depth = cam_pts[:, 2]
    with np.errstate(all="ignore"):
        a = cam_pts[:, 0] / depth
        b = cam_pts[:, 1] / depth
    ok = depth > MIN_DEPTH
    ok &= a * a + b * b <= _r2_max(cam)
    uv = np.full((len(pts), 2), -1.0)
    if np.any(ok):
        uv[ok], _ = cam.project(pts[ok])
    ok &= (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height - 1)
    return ok


def _person_px(cam: Camera, xy: np.ndarray, height: float) -> np.ndarray:
    """Projected height (pixels) of a vertical segment of ``height`` metres standing at ``xy`` (N, 2), from the
    pinhole model (distortion left out: a size, not a position); 0 behind the camera."""
    n = len(xy)
    foot = np.column_stack([xy, np.zeros(n)]) @ cam.R.T + cam.t
    head = np.column_stack([xy, np.full(n, height)]) @ cam.R.T + cam.t
    out = np.zeros(n)
    ok = (foot[:, 2] > MIN_DEPTH) & (head[:, 2] > MIN_DEPTH)
    du = cam.fx * (head[ok, 0] / head[ok, 2] - foot[ok, 0] / foot[ok, 2])
    dv = cam.fy * (head[ok, 1] / head[ok, 2] - foot[ok, 1] / foot[ok, 2])
    out[ok] = np.hypot(du, dv)
    return out


def camera_coverage(cam: Camera, xy: np.ndarray, config) -> np.ndarray:
    """Whether ``cam`` sees a standing person at each ground point ``xy`` (N, 2): (N,) bool (module docstring)."""
    xy = np.asarray(xy, dtype=np.float64)
    n = len(xy)
    heights = np.linspace(0.0, config.person_height, AXIS_SAMPLES)
    pts = np.concatenate([np.column_stack([xy, np.full(n, z)]) for z in heights])
    seen = camera_sees(cam, pts).reshape(AXIS_SAMPLES, n).mean(axis=0) >= config.min_visible
    near = np.hypot(xy[:, 0] - cam.center[0], xy[:, 1] - cam.center[1]) <= config.max_distance
    return seen & near & (_person_px(cam, xy, config.person_height) >= config.min_person_height * cam.height)


def _reach(cam: Camera, config) -> float:
    """Ground distance beyond which ``cam`` cannot see a person ``min_person_height`` tall (pinhole bound), metres."""
    height_px = max(cam.fx, cam.fy) * config.person_height / (config.min_person_height * cam.height)
    return float(min(config.max_distance, height_px + abs(cam.center[2])))


def _footprint(cam: Camera, config) -> str:
    """``name x a..b y c..d m`` of what one camera sees (or ``name sees no ground``) for error messages."""
    r = _reach(cam, config)
    step = max(config.cell, r / 200.0)
    xs = np.arange(cam.center[0] - r, cam.center[0] + r + step, step)
    ys = np.arange(cam.center[1] - r, cam.center[1] + r + step, step)
    gx, gy = np.meshgrid(xs, ys)
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    seen = camera_coverage(cam, xy, config)
    if not seen.any():
        return f"'{cam.name}' sees no ground"
    p = xy[seen]
    return f"'{cam.name}' x {p[:, 0].min():.1f}..{p[:, 0].max():.1f} y {p[:, 1].min():.1f}..{p[:, 1].max():.1f} m"


def working_area(rig: Rig, config) -> WorkingArea:
    """The tracker's working area (module docstring) for ``rig`` with an :class:`AreaConfig`.

    Raises:
        RigError: no ground seen by ``min_cameras`` cameras (naming them and what each sees); a ``volume`` that no
            camera, or fewer than ``min_cameras`` cameras, see.
    """
    need = min(config.min_cameras, len(rig))
    cams = list(rig.cameras)
    if rig.volume is not None:
        lo, hi = (np.asarray(v, dtype=np.float64) for v in rig.volume)
        cell = config.cell
        nx = max(1, int(math.ceil((hi[0] - lo[0]) / cell - 1e-9)))
        ny = max(1, int(math.ceil((hi[1] - lo[1]) / cell - 1e-9)))
        xs = lo[0] + cell * (np.arange(nx) + 0.5)
        ys = lo[1] + cell * (np.arange(ny) + 0.5)
        gx, gy = np.meshgrid(xs, ys)
        xy = np.column_stack([gx.ravel(), gy.ravel()])
        count = sum(camera_coverage(c, xy, config).astype(np.int64) for c in cams).reshape(ny, nx)
        box = f"{rig.source}: volume x {lo[0]:g}..{hi[0]:g} y {lo[1]:g}..{hi[1]:g} m"
        if not count.any():
            raise RigError(
                f"{box} is outside every camera's view ({'; '.join(_footprint(c, config) for c in cams)}): "
                "check the volume and the cameras' poses"
            )
        if count.max() < need:
            raise RigError(
                f"{box}: no point of it is seen by {need} cameras ({'; '.join(_footprint(c, config) for c in cams)});"
                " people are added where two views agree: check the volume and the cameras' poses"
            )
        area = WorkingArea(lo[:2].copy(), cell, np.ones((ny, nx), dtype=bool), count, "volume", float(hi[2]))
    else:
        reach = [_reach(c, config) for c in cams]
        lo = np.min([c.center[:2] - r for c, r in zip(cams, reach, strict=True)], axis=0)
        hi = np.max([c.center[:2] + r for c, r in zip(cams, reach, strict=True)], axis=0)
        cell = max(config.cell, float(np.max(hi - lo)) / 2000.0)  # at most 2000 x 2000 cells
        nx = int(math.ceil((hi[0] - lo[0]) / cell))
        ny = int(math.ceil((hi[1] - lo[1]) / cell))
        xs = lo[0] + cell * (np.arange(nx) + 0.5)
        ys = lo[1] + cell * (np.arange(ny) + 0.5)
        gx, gy = np.meshgrid(xs, ys)
        xy = np.column_stack([gx.ravel(), gy.ravel()])
        seen = [camera_coverage(c, xy, config) for c in cams]
        count = np.sum(seen, axis=0).reshape(ny, nx)
        mask = count >= need
        if not mask.any():
            raise RigError(
                f"{rig.source}: the cameras {', '.join(repr(c.name) for c in cams)} see no common ground (no point "
                f"of the floor z = 0 is seen by {need} of them: {'; '.join(_footprint(c, config) for c in cams)}); "
                "the people tracker needs overlapping views: check the cameras' poses, or give the rig a volume"
            )
        for c, s in zip(cams, seen, strict=True):
            shared = s & (count.ravel() >= 2)
            if len(cams) > 2 and not shared.any():
                log.warning("%s: camera '%s' shares no ground with the other cameras", rig.source, c.name)
        z_top = config.person_height + 0.2

        def cropped(m: np.ndarray, visible: WorkingArea | None = None) -> WorkingArea:
            rows, cols = np.nonzero(m)  # crop to the mask's bounding box
            r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
            origin = lo + cell * np.array([c0, r0], dtype=np.float64)
            crop = (slice(r0, r1), slice(c0, c1))
            return WorkingArea(origin, cell, m[crop].copy(), count[crop].copy(), "calibration", z_top, visible)

        area = cropped(mask, visible=cropped(count >= 1))
    return area
