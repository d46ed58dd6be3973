"""A tiny vectorised NumPy ray caster for synthetic camera images.

The static part of a scene (axis-aligned boxes, vertical cylinders, each with a procedural texture) is ray cast
once per camera; per frame only dynamic spheres are intersected, inside the pixel box around their projection,
and composited by ray distance (a z-buffer), then lit, shadowed and corrupted with sensor noise.

Conventions: world units are metres, z up; image units are pixels with pixel centres at integer coordinates (as in
:mod:`wptrack.cameras.rig`). Colours inside this module are linear RGB floats where 1.0 maps to 255 DN before the global
exposure; the images returned are uint8 BGR (OpenCV order). Rays are cast through ``cv2.undistortPoints`` of every
pixel centre, so rendered images carry the camera's lens distortion exactly as ``Camera.project`` models it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from wptrack.cameras.rig import Camera

__all__ = [
    "Box",
    "Cylinder",
    "Light",
    "Sphere",
    "StaticView",
    "camera_rays",
    "hsi",
    "solid",
    "value_noise",
    "wood",
    "noisy",
    "posters",
    "render_static",
    "shade_frame",
]

log = logging.getLogger(__name__)

Texture = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``texture(points (N, 3) metres, normals (N, 3)) -> albedo (N, 3)`` linear RGB in [0, 1]."""

_EPS = 1e-9


# ----------------------------------------------------------------------------------------------------- colour


def hsi(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """HSI of RGB pixels, as the S1 colour tracker classifies them (NumPy reference).

    ``I = (R + G + B) / 3``; ``S = 1 - 3 min(R, G, B) / (R + G + B)``;
    ``H = acos(0.5 ((R - G) + (R - B)) / sqrt((R - G)^2 + (R - B)(G - B)))`` in degrees, ``360 - H`` where ``B > G``.

    Args:
        rgb: (..., 3) array in R, G, B channel order, 0-255 scale (any numeric dtype).

    Returns:
        ``(h, s, i)``: hue in degrees [0, 360), saturation in [0, 1], intensity in [0, 255] (float64 arrays of
        shape ``rgb.shape[:-1]``). Grey pixels get hue 0 and black pixels saturation 0.
    """
    c = np.asarray(rgb, dtype=np.float64)
    r, g, b = c[..., 0], c[..., 1], c[..., 2]
    total = r + g + b
    i = total / 3.0
    s = np.where(total > 0, 1.0 - 3.0 * np.minimum(np.minimum(r, g), b) / np.maximum(total, _EPS), 0.0)
    num = 0.5 * ((r - g) + (r - b))
    den = np.sqrt((r - g) ** 2 + (r - b) * (g - b))
    h = np.degrees(np.arccos(np.clip(num / np.maximum(den, _EPS), -1.0, 1.0)))
    h = np.where(den > 0, h, 0.0)
    h = np.where(b > g, 360.0 - h, h) % 360.0
    return h, s, i


# ----------------------------------------------------------------------------------------------------- textures


def value_noise(u: np.ndarray, v: np.ndarray, seed: int, grid: int = 64) -> np.ndarray:
    """Smooth 2-D value noise in [0, 1], periodic with period ``grid`` in each coordinate.

    Args:
        u: Coordinates in lattice cells (any shape).
        v: Coordinates in lattice cells (same shape as ``u``).
        seed: Seed of the lattice values.
        grid: Lattice size (period).

    Returns:
        Noise values, same shape as ``u``.
    """
    lattice = np.random.default_rng(seed).random((grid, grid))
    u0 = np.floor(u)
    v0 = np.floor(v)
    fu = u - u0
    fv = v - v0
    fu = fu * fu * (3 - 2 * fu)
    fv = fv * fv * (3 - 2 * fv)
    i0 = u0.astype(np.int64) % grid
    j0 = v0.astype(np.int64) % grid
    i1 = (i0 + 1) % grid
    j1 = (j0 + 1) % grid
    a = lattice[i0, j0] * (1 - fu) + lattice[i1, j0] * fu
    b = lattice[i0, j1] * (1 - fu) + lattice[i1, j1] * fu
    return a * (1 - fv) + b * fv


def _plane_uv(points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two in-surface coordinates (metres) of hit points, chosen by the dominant normal axis."""
    axis = np.argmax(np.abs(normals), axis=1)
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    u = np.where(axis == 0, y, x)
    v = np.where(axis == 2, y, z)
    return u, v


def solid(rgb: Sequence[float]) -> Texture:
    """A uniform albedo (linear RGB in [0, 1])."""
    colour = np.asarray(rgb, dtype=np.float64)

    def texture(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        return np.broadcast_to(colour, points.shape).copy()

    return texture


def noisy(rgb: Sequence[float], amplitude: float = 0.08, scale_m: float = 0.05, seed: int = 1) -> Texture:
    """A uniform albedo modulated by smooth brightness noise (plaster, carpet, cardboard).

    Args:
        rgb: Mean albedo, linear RGB in [0, 1].
        amplitude: Relative brightness variation (0.08 = +-8 %).
        scale_m: Size of a noise cell, metres.
        seed: Noise seed.
    """
    colour = np.asarray(rgb, dtype=np.float64)

    def texture(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        u, v = _plane_uv(points, normals)
        n = value_noise(u / scale_m, v / scale_m, seed) + 0.5 * value_noise(
            u / (0.3 * scale_m), v / (0.3 * scale_m), seed + 1
        )
        factor = 1.0 + amplitude * (n / 0.75 - 1.0)
        return colour[None, :] * factor[:, None]

    return texture


def wood(rgb: Sequence[float] = (0.55, 0.36, 0.2), ring_m: float = 0.07, grain_axis: int = 0, seed: int = 7) -> Texture:
    """A wood-like texture: rings across ``grain_axis`` distorted by noise, plus fine streaks along it.

    Args:
        rgb: Mean albedo, linear RGB in [0, 1].
        ring_m: Ring spacing, metres.
        grain_axis: World axis (0 = x, 1 = y) the grain runs along.
        seed: Noise seed.
    """
    colour = np.asarray(rgb, dtype=np.float64)

    def texture(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        along = points[:, grain_axis]
        across = points[:, 1 - grain_axis]
        warp = value_noise(along / 0.25, across / 0.08, seed) * 2.5
        rings = 0.5 + 0.5 * np.sin(2 * np.pi * (across / ring_m + warp))
        streak = value_noise(along / 0.4, across / 0.012, seed + 3)
        factor = 0.82 + 0.22 * rings + 0.12 * (streak - 0.5)
        out = colour[None, :] * factor[:, None]
        out[:, 2] *= 0.9 + 0.1 * rings  # darker rings are also a little warmer
        return out

    return texture


@dataclass(frozen=True)
class _Poster:
    lo: tuple[float, float]
    hi: tuple[float, float]
    rgb: tuple[float, float, float]
    stripes: bool


def posters(
    base: Texture,
    rects: Sequence[tuple[tuple[float, float], tuple[float, float], tuple[float, float, float], bool]],
) -> Texture:
    """A wall texture with rectangular posters on it.

    Args:
        base: Texture of the bare wall.
        rects: ``((u0, v0), (u1, v1), rgb, striped)`` per poster, in the wall's in-plane coordinates (metres): for a
            wall facing +-x these are (y, z), facing +-y (x, z). Striped posters alternate ``rgb`` with white.
    """
    items = [_Poster(tuple(lo), tuple(hi), tuple(rgb), bool(st)) for lo, hi, rgb, st in rects]

    def texture(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        out = base(points, normals)
        u, v = _plane_uv(points, normals)
        for p in items:
            inside = (u >= p.lo[0]) & (u <= p.hi[0]) & (v >= p.lo[1]) & (v <= p.hi[1])
            if not np.any(inside):
                continue
            colour = np.broadcast_to(np.asarray(p.rgb), (int(inside.sum()), 3)).copy()
            if p.stripes:
                band = (np.floor((v[inside] - p.lo[1]) / 0.04) % 2) == 1
                colour[band] = (0.8, 0.8, 0.78)
            out[inside] = colour
        return out

    return texture


# ----------------------------------------------------------------------------------------------------- geometry


@dataclass(frozen=True)
class Box:
    """An axis-aligned box.

    Attributes:
        lo: (3,) minimum corner, metres.
        hi: (3,) maximum corner, metres.
        texture: Albedo of its surface.
        label: Object id written to the label image (0 is reserved for 'nothing').
    """

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    texture: Texture
    label: int = 1

    def intersect(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest positive hit distance (inf on a miss) and the outward normal, per ray.

        Args:
            origin: (3,) ray origin, metres.
            dirs: (N, 3) unit ray directions.

        Returns:
            ``(t (N,), normal (N, 3))``.
        """
        lo = np.asarray(self.lo) - origin
        hi = np.asarray(self.hi) - origin
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / dirs
            t0 = lo[None, :] * inv
            t1 = hi[None, :] * inv
        t0 = np.where(np.isnan(t0), -np.inf, t0)
        t1 = np.where(np.isnan(t1), np.inf, t1)
        tmin = np.minimum(t0, t1)
        tmax = np.maximum(t0, t1)
        axis = np.argmax(tmin, axis=1)
        t_near = tmin[np.arange(len(dirs)), axis]
        t_far = np.min(tmax, axis=1)
        hit = (t_near <= t_far) & (t_near > 1e-6)
        t = np.where(hit, t_near, np.inf)
        normal = np.zeros_like(dirs)
        normal[np.arange(len(dirs)), axis] = -np.sign(dirs[np.arange(len(dirs)), axis])
        return t, normal


@dataclass(frozen=True)
class Cylinder:
    """A vertical capped cylinder (mug, cup, stand).

    Attributes:
        center: (x, y) of the axis, metres.
        radius: Radius, metres.
        z0: Bottom height, metres.
        z1: Top height, metres.
        texture: Albedo of its surface.
        label: Object id written to the label image.
    """

    center: tuple[float, float]
    radius: float
    z0: float
    z1: float
    texture: Texture
    label: int = 1

    def intersect(self, origin: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest positive hit distance (inf on a miss) and the outward normal, per ray (see :meth:`Box.intersect`)."""
        ox, oy = origin[0] - self.center[0], origin[1] - self.center[1]
        dx, dy, dz = dirs[:, 0], dirs[:, 1], dirs[:, 2]
        a = dx * dx + dy * dy
        b = 2 * (ox * dx + oy * dy)
        c = ox * ox + oy * oy - self.radius**2
        disc = b * b - 4 * a * c
        ok = (disc >= 0) & (a > _EPS)
        sq = np.sqrt(np.where(ok, disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            t_side = np.where(ok, (-b - sq) / (2 * np.maximum(a, _EPS)), np.inf)
        z_side = origin[2] + t_side * dz
        t_side = np.where((t_side > 1e-6) & (z_side >= self.z0) & (z_side <= self.z1), t_side, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_top = (self.z1 - origin[2]) / dz
        px = ox + t_top * dx
        py = oy + t_top * dy
        top_ok = (origin[2] > self.z1) & (t_top > 1e-6) & (px * px + py * py <= self.radius**2)
        t_top = np.where(top_ok, t_top, np.inf)
        t = np.minimum(t_side, t_top)
        normal = np.zeros_like(dirs)
        side = t_side <= t_top
        hx = ox + t_side * dx
        hy = oy + t_side * dy
        normal[:, 0] = np.where(side, hx / self.radius, 0.0)
        normal[:, 1] = np.where(side, hy / self.radius, 0.0)
        normal[:, 2] = np.where(side, 0.0, 1.0)
        normal[~np.isfinite(t)] = 0.0
        return t, normal


@dataclass(frozen=True)
class Sphere:
    """A dynamic sphere (the tracked ball).

    Attributes:
        radius: Radius, metres.
        rgb: Albedo, linear RGB in [0, 1].
        specular: Strength of the white Blinn-Phong highlight (0..1).
        shininess: Blinn-Phong exponent.
        label: Object id written to the label image.
    """

    radius: float
    rgb: tuple[float, float, float]
    specular: float = 0.25
    shininess: float = 40.0
    label: int = 100


@dataclass(frozen=True)
class Light:
    """Scene lighting.

    Attributes:
        direction: (3,) direction towards the (distant) light; normalised internally.
        ambient: Ambient term (fraction of the albedo seen in full shadow).
        diffuse: Lambert term at normal incidence.
        exposure: Linear radiance -> DN factor (1.0 maps radiance 1 to 255 DN).
    """

    direction: tuple[float, float, float] = (0.35, -0.3, 1.0)
    ambient: float = 0.35
    diffuse: float = 0.75
    exposure: float = 0.75

    @property
    def unit(self) -> np.ndarray:
        """(3,) unit direction towards the light."""
        d = np.asarray(self.direction, dtype=np.float64)
        return d / np.linalg.norm(d)


# ----------------------------------------------------------------------------------------------------- casting


def camera_rays(camera: Camera) -> np.ndarray:
    """Unit world-frame ray directions through every pixel centre, with the camera's lens distortion.

    Args:
        camera: The camera.

    Returns:
        (height * width, 3) float64 unit directions, row-major over (v, u).
    """
    import cv2

    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    K = np.array(camera.K)
    dist = np.array(camera.dist)
    try:
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)
        norm = cv2.undistortPoints(pts, K, dist, criteria=criteria)
    except (cv2.error, TypeError):  # older bindings without the criteria overload
        norm = cv2.undistortPoints(pts, K, dist)
    norm = np.asarray(norm, dtype=np.float64).reshape(-1, 2)
    d_cam = np.concatenate([norm, np.ones((norm.shape[0], 1))], axis=1)
    d_world = d_cam @ np.array(camera.R)  # R^T @ d for each row
    return d_world / np.linalg.norm(d_world, axis=1, keepdims=True)


@dataclass
class StaticView:
    """The static scene as seen by one camera, ray cast once.

    Attributes:
        camera: The camera.
        origin: (3,) camera centre, metres.
        dirs: (H*W, 3) unit ray directions (world).
        radiance: (H, W, 3) float32 linear RGB radiance of the static scene (before exposure and noise).
        depth: (H, W) float32 distance along the ray to the nearest static surface, metres (inf on a miss).
        label: (H, W) int16 object id per pixel (0 = background colour / nothing hit).
        up_index: (M,) flat indices of pixels whose surface faces up (receives the ball's shadow blob).
        up_points: (M, 3) float32 world hit points of those pixels, metres.
    """

    camera: Camera
    origin: np.ndarray
    dirs: np.ndarray
    radiance: np.ndarray
    depth: np.ndarray
    label: np.ndarray
    up_index: np.ndarray
    up_points: np.ndarray
    extra: dict = field(default_factory=dict)


def render_static(
    camera: Camera,
    objects: Sequence[Box | Cylinder],
    light: Light,
    background: Sequence[float] = (0.5, 0.5, 0.5),
) -> StaticView:
    """Ray cast the static objects for one camera.

    Args:
        camera: The camera.
        objects: Boxes and cylinders.
        light: Lighting (shadows between static objects are not modelled).
        background: Radiance where no object is hit, linear RGB.

    Returns:
        The camera's :class:`StaticView`.
    """
    dirs = camera_rays(camera)
    origin = np.asarray(camera.center, dtype=np.float64)
    n = dirs.shape[0]
    best_t = np.full(n, np.inf)
    best_obj = np.full(n, -1, dtype=np.int64)
    best_normal = np.zeros((n, 3))
    for k, obj in enumerate(objects):
        t, normal = obj.intersect(origin, dirs)
        closer = t < best_t
        best_t[closer] = t[closer]
        best_obj[closer] = k
        best_normal[closer] = normal[closer]
    radiance = np.empty((n, 3))
    radiance[:] = np.asarray(background, dtype=np.float64)
    label = np.zeros(n, dtype=np.int16)
    points = origin[None, :] + dirs * np.where(np.isfinite(best_t), best_t, 0.0)[:, None]
    lit = np.clip(best_normal @ light.unit, 0.0, None)
    for k, obj in enumerate(objects):
        sel = best_obj == k
        if not np.any(sel):
            continue
        albedo = obj.texture(points[sel], best_normal[sel])
        radiance[sel] = albedo * (light.ambient + light.diffuse * lit[sel])[:, None]
        label[sel] = obj.label
    up_index = np.flatnonzero((best_normal[:, 2] > 0.9) & np.isfinite(best_t))
    h, w = camera.height, camera.width
    return StaticView(
        camera=camera,
        origin=origin,
        dirs=dirs,
        radiance=radiance.reshape(h, w, 3).astype(np.float32),
        depth=best_t.reshape(h, w).astype(np.float32),
        label=label.reshape(h, w),
        up_index=up_index,
        up_points=points[up_index].astype(np.float32),
    )


def _sphere_bbox(camera: Camera, center: np.ndarray, radius: float) -> tuple[int, int, int, int] | None:
    """Pixel box ``(u0, u1, v0, v1)`` (half-open) that contains the sphere's image, or None when it is not visible."""
    offs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    corners = center[None, :] + 1.05 * radius * offs
    uv, depth = camera.project(corners)
    if np.all(depth <= 0):
        return None
    if np.any(depth <= 0.01):  # straddles the camera plane: projection unreliable, use the whole image
        return 0, camera.width, 0, camera.height
    u0 = max(int(np.floor(uv[:, 0].min())) - 2, 0)
    u1 = min(int(np.ceil(uv[:, 0].max())) + 3, camera.width)
    v0 = max(int(np.floor(uv[:, 1].min())) - 2, 0)
    v1 = min(int(np.ceil(uv[:, 1].max())) + 3, camera.height)
    if u0 >= u1 or v0 >= v1:
        return None
    return u0, u1, v0, v1


def shade_frame(
    view: StaticView,
    sphere: Sphere,
    center: np.ndarray,
    light: Light,
    gain_rgb: np.ndarray,
    noise_sigma: float,
    rng: np.random.Generator,
    shadow_strength: float = 0.55,
) -> tuple[np.ndarray, int, int, np.ndarray | None]:
    """Render one frame: static scene + ball (z-buffered) + soft shadow blob + illumination + noise.

    Args:
        view: The camera's static view.
        sphere: The ball.
        center: (3,) ball centre, metres.
        light: Lighting.
        gain_rgb: (3,) per-channel illumination gain of this frame (brightness x colour temperature).
        noise_sigma: Standard deviation of the additive Gaussian pixel noise, DN.
        rng: Noise generator (consumed: one (H, W, 3) draw per call).
        shadow_strength: Darkening at the centre of the shadow blob (0..1).

    Returns:
        ``(bgr, visible, total, mask)``: the uint8 (H, W, 3) BGR image; the number of ball pixels visible and the
        number the ball would cover without occluders; and the (H, W) bool mask of visible ball pixels (None when
        the ball is not in the image).
    """
    cam = view.camera
    h, w = cam.height, cam.width
    img = view.radiance.copy()
    c = np.asarray(center, dtype=np.float64)
    lu = light.unit
    r = sphere.radius

    # soft shadow blob on upward surfaces below the ball, cast along the light direction
    if len(view.up_index):
        p = view.up_points
        height = c[2] - p[:, 2]
        near = (height > 0) & (np.abs(p[:, 0] - c[0]) < 1.0) & (np.abs(p[:, 1] - c[1]) < 1.0)
        if np.any(near):
            pn = p[near].astype(np.float64)
            hn = height[near].astype(np.float64)
            sx = c[0] - lu[0] * hn / lu[2]
            sy = c[1] - lu[1] * hn / lu[2]
            d2 = (pn[:, 0] - sx) ** 2 + (pn[:, 1] - sy) ** 2
            sigma = r * (0.55 + 1.5 * np.maximum(hn - r, 0.0) / r * 0.25)
            amount = shadow_strength * np.exp(-0.5 * d2 / sigma**2) / (1.0 + 2.0 * np.maximum(hn - r, 0.0) / r)
            flat = img.reshape(-1, 3)
            idx = view.up_index[near]
            flat[idx] *= (1.0 - amount)[:, None].astype(np.float32)

    visible = total = 0
    mask = None
    box = _sphere_bbox(cam, c, r)
    if box is not None:
        u0, u1, v0, v1 = box
        rows = np.arange(v0, v1)
        cols = np.arange(u0, u1)
        idx = (rows[:, None] * w + cols[None, :]).ravel()
        d = view.dirs[idx]
        oc = view.origin - c
        b = d @ oc
        disc = b * b - (oc @ oc - r * r)
        hit = disc > 0
        t = np.where(hit, -b - np.sqrt(np.where(hit, disc, 0.0)), np.inf)
        hit &= t > 0
        total = int(hit.sum())
        front = hit & (t < view.depth.reshape(-1)[idx])
        visible = int(front.sum())
        if visible:
            tf = t[front]
            pts = view.origin[None, :] + d[front] * tf[:, None]
            n = (pts - c[None, :]) / r
            lam = np.clip(n @ lu, 0.0, None)
            half = lu[None, :] - d[front]
            half /= np.linalg.norm(half, axis=1, keepdims=True)
            spec = sphere.specular * np.clip(np.sum(n * half, axis=1), 0.0, None) ** sphere.shininess
            col = np.asarray(sphere.rgb)[None, :] * (light.ambient + light.diffuse * lam)[:, None] + spec[:, None]
            img.reshape(-1, 3)[idx[front]] = col.astype(np.float32)
            mask = np.zeros(h * w, dtype=bool)
            mask[idx[front]] = True
            mask = mask.reshape(h, w)

    scale = (255.0 * light.exposure * np.asarray(gain_rgb, dtype=np.float64)).astype(np.float32)
    out = img * scale[None, None, :]
    if noise_sigma > 0:
        out += rng.standard_normal((h, w, 3), dtype=np.float32) * np.float32(noise_sigma)
    rgb = np.clip(np.rint(out), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(rgb[:, :, ::-1]), visible, total, mask
