"""The static plaza of the S3 scenes: camera, textured ground and facades, clutter (parked cars, bushes, benches,
lamp posts), the sun's cast shadows, and the pre-rendered static view every frame starts from."""

from __future__ import annotations

import functools
import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from wptrack.cameras.rig import Camera
from wptrack.synth.actors import _Prim, _Rgb
from wptrack.synth.conditions import CLOUD_SIDE_SHARE
from wptrack.synth.render import Box, Cylinder, Light, StaticView, noisy, render_static, solid, value_noise, wood

log = logging.getLogger(__name__)

IMAGE_SIZE = (640, 480)
"""Image width and height, pixels."""
CAMERA_POSITION = (0.0, 0.0, 7.5)
"""Camera centre, metres."""
CAMERA_PITCH_DEG = 38.0
"""Downward tilt of the optical axis below the horizon, degrees (the camera looks along +y)."""
CAMERA_FOCAL = 580.0
"""Focal length fx = fy, pixels."""
CAMERA_DIST = (-0.08, 0.01, 0.0, 0.0, 0.0)
"""OpenCV distortion k1 k2 p1 p2 k3."""
FPS = 15.0
"""Frame rate, frames per second."""
FRAMES = 180
"""Default number of frames (12 s)."""
SUN = (-0.45, -0.35, 0.8)
"""Direction towards the sun (behind the camera, on its left: shadows fall away from it, to the right)."""
NOISE_SIGMA = 3.5
"""Sensor noise standard deviation, DN."""
SHADOW_STRENGTH = 0.55
"""Darkening of a fully shadowed up-facing surface (0..1)."""
SHADOW_TINT = (1.0, 0.92, 0.78)
"""Relative darkening of R, G, B in shadows (lit by the blue sky: red falls most), multiplies SHADOW_STRENGTH."""
IN_VIEW = 0.25
"""Fraction of the box holding an object (a person's arms' reach included) inside the image for it to count as in
view: the scenes' draws (``plaza_rules``), the conditions' timings (the short clip's start, the stops) and the hints
(most objects at once). The ground truth's rule until 2026-11-27; now :data:`MIN_IN_IMAGE`."""
MIN_IN_IMAGE = 0.9
"""Fraction of an object's image bounding box (the box of its labelled dimensions) that must lie inside the image for
it to be in the ground truth: people and vehicles nearly whole in view, as the real clips' annotators labelled them
(TownCentre: 97.5 % of the labelled bodies have >= 0.9 of their box inside the image; PETS S2.L1 View 001: every box
whole inside; docs/notes.md, 2026-11-27 afternoon). The template tracker reports by the same rule
(``TemplateConfig.min_in_image``). Was :data:`IN_VIEW` of the wider box until then: the scenes (actors, paths, timings)
are the same, their ground truth is labelled later at the borders."""
ROAD_LANES = (12.9, 16.1)
"""Lane centres, y metres: the near lane drives +x, the far lane -x."""

LABEL_BUSH = 40
"""Label of the flickering vegetation (bushes, tree crown) in the static label image."""


def plaza_camera() -> Camera:
    """The scene camera ``cam0`` (see the module docstring)."""
    pitch = math.radians(CAMERA_PITCH_DEG)
    pos = np.asarray(CAMERA_POSITION, dtype=np.float64)
    target = pos + 10.0 * np.array([0.0, math.cos(pitch), -math.sin(pitch)])
    return Camera.look_at("cam0", IMAGE_SIZE[0], IMAGE_SIZE[1], pos, target, fx=CAMERA_FOCAL, dist=CAMERA_DIST)


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _tiles(x: np.ndarray, y: np.ndarray, size: float, rgb: np.ndarray, seed: int) -> np.ndarray:
    """Paving: square tiles of ``size`` metres, per-tile brightness, darker joints, fine grain."""
    lattice = np.random.default_rng(seed).random((256, 256))
    u, v = x / size, y / size
    tu, tv = np.floor(u).astype(np.int64) % 256, np.floor(v).astype(np.int64) % 256
    fu, fv = u - np.floor(u), v - np.floor(v)
    edge = np.minimum(np.minimum(fu, 1 - fu), np.minimum(fv, 1 - fv)) * size
    joint = 0.72 + 0.28 * _smoothstep(0.005, 0.02, edge)
    grain = value_noise(x / 0.06, y / 0.06, seed + 1) - 0.5
    stain = value_noise(x / 1.7, y / 1.7, seed + 2) - 0.5
    factor = joint * (0.92 + 0.16 * lattice[tu, tv] + 0.12 * grain + 0.15 * stain)
    return rgb[None, :] * factor[:, None]


def _ground_texture(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Plaza paving, kerb, asphalt with markings, parking bays, sidewalk (by world y, metres)."""
    x, y = points[:, 0], points[:, 1]
    out = _tiles(x, y, 0.5, np.array([0.55, 0.52, 0.47]), seed=21)
    kerb = (y >= 10.5) & (y < 10.8)
    out[kerb] = np.array([0.68, 0.67, 0.64]) * (0.95 + 0.1 * value_noise(x[kerb] / 0.1, y[kerb] / 0.1, 5))[:, None]
    road = (y >= 10.8) & (y < 23.5)
    xr, yr = x[road], y[road]
    n = value_noise(xr / 0.08, yr / 0.08, 31) - 0.5
    patch = value_noise(xr / 2.5, yr / 2.5, 32) - 0.5
    asphalt = np.array([0.21, 0.21, 0.22])[None, :] * (1.0 + 0.22 * n + 0.25 * patch)[:, None]
    paint = np.array([0.72, 0.72, 0.68])
    centre_line = (np.abs(yr - 14.5) < 0.07) & (np.mod(xr, 6.0) < 3.0)
    edge_line = np.abs(yr - 19.5) < 0.06
    bays = (yr > 19.5) & (yr < 23.4) & (np.mod(xr + 0.05, 2.6) < 0.1)
    asphalt[centre_line | edge_line | bays] = paint
    out[road] = asphalt
    walk = y >= 23.5
    out[walk] = _tiles(x[walk], y[walk], 0.3, np.array([0.6, 0.58, 0.55]), seed=41)
    return out


def _facade_texture(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """A building facade (wall facing -y): plaster with rows of windows and shop windows."""
    x, z = points[:, 0], points[:, 2]
    base = noisy((0.62, 0.55, 0.46), amplitude=0.06, scale_m=0.5, seed=51)(points, normals)
    win = (np.mod(x, 3.2) > 0.6) & (np.mod(x, 3.2) < 2.3) & (np.mod(z, 3.3) > 1.0) & (np.mod(z, 3.3) < 2.4) & (z > 3)
    shop = (np.mod(x, 6.0) > 0.5) & (np.mod(x, 6.0) < 5.0) & (z > 0.3) & (z < 2.6)
    base[win] = (0.12, 0.15, 0.2)
    base[shop] = (0.09, 0.1, 0.12)
    return base


def _parked_car(x: float, y: float, rgb: _Rgb, label: int) -> list[Box | Cylinder]:
    """A static parked car, nose along +-y (axis-aligned boxes)."""
    return [
        Box((x - 0.9, y - 2.2, 0.2), (x + 0.9, y + 2.2, 0.88), solid(rgb), label=label),
        Box((x - 0.8, y - 1.2, 0.88), (x + 0.8, y + 0.9, 1.45), solid((0.07, 0.08, 0.1)), label=label),
    ]


def _static_objects() -> list[Box | Cylinder]:
    """The plaza's ground, facade and clutter (fixed layout)."""
    concrete = noisy((0.6, 0.59, 0.56), amplitude=0.08, scale_m=0.08, seed=61)
    metal = solid((0.16, 0.17, 0.18))
    leaves = noisy((0.14, 0.26, 0.09), amplitude=0.35, scale_m=0.09, seed=62)
    objects: list[Box | Cylinder] = [
        Box((-80.0, -10.0, -0.5), (80.0, 25.0, 0.0), _ground_texture, label=1),
        Box((-80.0, 25.0, 0.0), (80.0, 25.5, 14.0), _facade_texture, label=2),
    ]
    # lamp posts (pole + lamp head)
    for i, (x, y) in enumerate(((-4.2, 7.4), (5.8, 10.0), (-9.5, 24.0), (6.0, 24.0))):
        objects.append(Cylinder((x, y), 0.07, 0.0, 4.6, metal, label=10 + i))
        objects.append(Box((x - 0.25, y - 0.15, 4.6), (x + 0.25, y + 0.15, 4.75), metal, label=10 + i))
    # bollards along the kerb
    for i, x in enumerate((-9.0, -6.0, -3.0, 3.0, 6.0, 9.0)):
        objects.append(Cylinder((x, 10.3), 0.09, 0.0, 0.9, solid((0.25, 0.25, 0.27)), label=20 + i))
    # benches (seat, back, two legs)
    for i, (x0, y0) in enumerate(((1.2, 5.0), (-7.8, 7.4))):
        bench = wood((0.5, 0.33, 0.18), ring_m=0.05, grain_axis=0, seed=70 + i)
        objects += [
            Box((x0, y0, 0.42), (x0 + 1.8, y0 + 0.45, 0.47), bench, label=30 + i),
            Box((x0, y0 + 0.4, 0.47), (x0 + 1.8, y0 + 0.46, 0.85), bench, label=30 + i),
            Box((x0 + 0.1, y0 + 0.05, 0.0), (x0 + 0.2, y0 + 0.4, 0.42), metal, label=30 + i),
            Box((x0 + 1.6, y0 + 0.05, 0.0), (x0 + 1.7, y0 + 0.4, 0.42), metal, label=30 + i),
        ]
    # planters with bushes (the bushes flicker), a tree, a litter bin
    for x0, y0 in ((4.2, 4.6), (6.4, 7.8)):
        objects.append(Box((x0 - 0.7, y0 - 0.5, 0.0), (x0 + 0.7, y0 + 0.5, 0.5), concrete, label=35))
        objects.append(Cylinder((x0, y0), 0.55, 0.5, 1.25, leaves, label=LABEL_BUSH))
    objects.append(Cylinder((-7.4, 10.0), 0.16, 0.0, 2.6, solid((0.3, 0.22, 0.15)), label=36))
    objects.append(Cylinder((-7.4, 10.0), 1.5, 2.6, 4.8, leaves, label=LABEL_BUSH))
    objects.append(Cylinder((2.6, 9.7), 0.28, 0.0, 0.95, solid((0.12, 0.25, 0.15)), label=37))
    # parked cars in the bays
    for i, (x, rgb) in enumerate(
        (
            (-10.35, (0.7, 0.7, 0.68)),
            (-7.75, (0.1, 0.14, 0.3)),
            (-2.55, (0.5, 0.51, 0.53)),
            (5.25, (0.55, 0.1, 0.07)),
            (10.45, (0.24, 0.24, 0.25)),
        )
    ):
        objects += _parked_car(x, 21.5, rgb, label=50 + i)
    return objects


def _shadow_hits(obj: Box | Cylinder, points: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """Whether rays from ``points`` (N, 3) towards the sun hit a static box or vertical cylinder."""
    if isinstance(obj, Box):
        prim = _Prim(
            "box",
            0.5 * (np.asarray(obj.lo) + np.asarray(obj.hi)),
            np.eye(3),
            0.5 * (np.asarray(obj.hi) - np.asarray(obj.lo)),
            np.zeros(3),
        )
        return np.isfinite(prim.intersect(points, sun))
    ox = points[:, 0] - obj.center[0]
    oy = points[:, 1] - obj.center[1]
    a = sun[0] ** 2 + sun[1] ** 2
    b = 2 * (ox * sun[0] + oy * sun[1])
    c = ox * ox + oy * oy - obj.radius**2
    disc = b * b - 4 * a * c
    ok = disc >= 0
    sq = np.sqrt(np.where(ok, disc, 0.0))
    t_in = (-b - sq) / (2 * a)
    t_out = (-b + sq) / (2 * a)
    z_in = points[:, 2] + np.maximum(t_in, 0.0) * sun[2]
    z_out = points[:, 2] + t_out * sun[2]
    return ok & (t_out > 1e-6) & (z_out >= obj.z0) & (z_in <= obj.z1)


@dataclass(frozen=True)
class PlazaBackground:
    """The static plaza as seen by ``cam0``, ray cast once.

    Attributes:
        view: The static view (radiance includes the static shadows).
        ground: (H, W, 3) float64 world points of up-facing static surfaces (shadow receivers), NaN elsewhere, metres.
        sunlit: (H, W) float32 fraction of direct sun on each pixel's surface (0 in static shadow).
        bush_index: (K,) flat indices of flickering vegetation pixels.
        bush_uv: (K, 2) float64 pixel coordinates of those pixels.
        light: The lighting.
        shadow_strength: Darkening of a fully shadowed up-facing surface (0..1), times ``shadow_tint``.
        shadow_tint: Relative darkening of R, G, B in shadows.
        soft_shadows: Cast shadows blurred into a penumbra (5x5 Gaussian, sigma 1 pixel); False: hard edges.
    """

    view: StaticView
    ground: np.ndarray
    sunlit: np.ndarray
    bush_index: np.ndarray
    bush_uv: np.ndarray
    light: Light
    shadow_strength: float = SHADOW_STRENGTH
    shadow_tint: tuple[float, float, float] = SHADOW_TINT
    soft_shadows: bool = True


DEFAULT_LIGHT = Light(direction=SUN, ambient=0.4, diffuse=0.65, exposure=1.0)
"""The scenes' default lighting: a hazy sun at about 54 degrees."""


def sun_light() -> tuple[Light, float]:
    """Lighting of the ``sun`` condition (:mod:`wptrack.synth.conditions`) and its shadow strength.

    A sun at ``SUN_ELEVATION_DEG`` with the default azimuth, less sky light and more direct light; the exposure keeps
    a lit horizontal surface at its default brightness. Returns ``(light, 1 - shadow ratio)``.
    """
    from wptrack.synth import conditions as C

    direction = C.sun_elevation_direction(SUN)
    d = DEFAULT_LIGHT
    lit_default = d.ambient + d.diffuse * float(d.unit[2])
    lit_sun = C.SUN_AMBIENT + C.SUN_DIFFUSE * direction[2]
    light = Light(direction=direction, ambient=C.SUN_AMBIENT, diffuse=C.SUN_DIFFUSE, exposure=lit_default / lit_sun)
    return light, 1.0 - C.sun_shadow_ratio()


@functools.lru_cache(maxsize=2)
def plaza_background(sun: bool = False) -> PlazaBackground:
    """Ray cast the static plaza once per process (cached; the arrays are read-only).

    Args:
        sun: The ``sun`` condition's lighting (:func:`sun_light`): low sun, hard neutral shadows; default: the
            scenes' own lighting (:data:`DEFAULT_LIGHT`, soft bluish shadows).
    """
    import cv2

    start = time.perf_counter()
    cam = plaza_camera()
    if sun:
        light, strength = sun_light()
        tint_rgb, soft_shadows = (1.0, 1.0, 1.0), False
    else:
        light, strength, tint_rgb, soft_shadows = DEFAULT_LIGHT, SHADOW_STRENGTH, SHADOW_TINT, True
    objects = _static_objects()
    view = render_static(cam, objects, light, background=(0.55, 0.62, 0.72))
    h, w = cam.height, cam.width
    ground = np.full((h * w, 3), np.nan)
    ground[view.up_index] = view.up_points
    # static shadows of the clutter on up-facing surfaces (culled by each object's shadow footprint)
    sun = light.unit
    pts = ground[view.up_index]
    shadow = np.zeros(len(pts), dtype=bool)
    for obj in objects[2:]:
        if isinstance(obj, Box):
            lo, hi = np.asarray(obj.lo), np.asarray(obj.hi)
        else:
            lo = np.array([obj.center[0] - obj.radius, obj.center[1] - obj.radius, obj.z0])
            hi = np.array([obj.center[0] + obj.radius, obj.center[1] + obj.radius, obj.z1])
        reach = hi[2] / sun[2] * np.abs(sun[:2])
        sel = (
            (pts[:, 2] < hi[2])
            & (pts[:, 0] >= lo[0] - reach[0] - 0.01)
            & (pts[:, 0] <= hi[0] + reach[0] + 0.01)
            & (pts[:, 1] >= lo[1] - reach[1] - 0.01)
            & (pts[:, 1] <= hi[1] + reach[1] + 0.01)
        )
        if np.any(sel):
            idx = np.flatnonzero(sel)
            shadow[idx] |= _shadow_hits(obj, pts[idx] + np.array([0.0, 0.0, 1e-4]), sun)
    hard = np.zeros(h * w, dtype=np.float32)
    hard[view.up_index] = shadow
    soft = cv2.GaussianBlur(hard.reshape(h, w), (5, 5), 1.0) if soft_shadows else hard.reshape(h, w)
    up = np.zeros(h * w, dtype=np.float32)
    up[view.up_index] = 1.0
    soft *= up.reshape(h, w)
    sunlit = (1.0 - soft).astype(np.float32)
    tint = np.asarray(tint_rgb, dtype=np.float32)
    radiance = view.radiance * (1.0 - strength * soft[..., None] * tint[None, None, :])
    view.radiance = radiance.astype(np.float32)
    bush_index = np.flatnonzero(view.label.reshape(-1) == LABEL_BUSH)
    bush_uv = np.stack([bush_index % w, bush_index // w], axis=1).astype(np.float64)
    for arr in (view.radiance, view.depth, view.label, view.dirs, ground, sunlit, bush_index, bush_uv):
        arr.setflags(write=False)
    log.debug("plaza background ray cast in %.2f s", time.perf_counter() - start)
    return PlazaBackground(
        view=view,
        ground=ground.reshape(h, w, 3),
        sunlit=sunlit,
        bush_index=bush_index,
        bush_uv=bush_uv,
        light=light,
        shadow_strength=strength,
        shadow_tint=tint_rgb,
        soft_shadows=soft_shadows,
    )


# ----------------------------------------------------------------------------------------------------- rendering


@functools.lru_cache(maxsize=2)
def static_points(sun: bool) -> np.ndarray:
    """(H, W, 3) float64 world points of the static plaza seen by each pixel (inf where a ray hits nothing)."""
    view = plaza_background(sun=sun).view
    h, w = view.camera.height, view.camera.width
    depth = view.depth.reshape(-1).astype(np.float64)
    out = view.origin[None, :] + np.where(np.isfinite(depth), depth, np.inf)[:, None] * view.dirs
    out = out.reshape(h, w, 3)
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=2)
def static_share(sun: bool) -> np.ndarray:
    """(H, W) float32 share of direct sunlight in the static plaza's radiance: the shadow strength where the surface
    faces up (times the part of the sun it sees), :data:`~wptrack.synth.conditions.CLOUD_SIDE_SHARE` on other
    surfaces, 0 on the sky."""
    bg = plaza_background(sun=sun)
    view = bg.view
    h, w = view.camera.height, view.camera.width
    out = np.where(np.isfinite(view.depth), np.float32(CLOUD_SIDE_SHARE), np.float32(0.0)).reshape(-1)
    out[view.up_index] = bg.shadow_strength * bg.sunlit.reshape(-1)[view.up_index]
    out = out.reshape(h, w).astype(np.float32)
    out.setflags(write=False)
    return out
