"""Switchable hard conditions of the s3 plaza scenes (issue 10): each one alone, so that its effect can be measured.
The s2 office scenes take the two light conditions, ``clouds`` and ``exposure``, indoors (daylight from the south
windows, per-camera auto-exposure, lights in part of the room: :mod:`wptrack.synth.office`).

``wptrack synth s3-mixed --out DIR --conditions sun,dark-car`` (or ``--conditions all``) renders a plaza scene with
the chosen conditions; all are off by default and the scenes are then unchanged (the same frames, masks and ground
truth as without this module). The conditions:

- ``static-start``: the scene is frozen for :data:`HOLD_S` seconds at the moment of its default timeline when the
  most objects are in view (the first such frame), then plays on (easing in over :data:`EASE_S`): objects are in view
  at frame 0 and stand still for a while (a background model must not learn them, nor leave ghosts where they were).
- ``stop-and-go``: every person stops for :data:`STOP_S` seconds (easing out and in over :data:`EASE_S`) at 40 % of
  the frames on which they are in view, then walks on; people of a group stop together.
- ``sun``: a low, clear-sky sun (:data:`SUN_ELEVATION_DEG` above the horizon, same azimuth): long, hard-edged cast
  shadows (no blur) of the objects and the clutter, darkened by the ratio the scene's lighting model gives for a
  horizontal surface without direct sun, ``ambient / (ambient + diffuse sin(elevation))`` (about 0.38), the same for
  the three channels (chromaticity kept); the exposure is raised to keep the lit ground at its default brightness.
  Shadows are not objects: the perfect masks and the ground truth do not change.
- ``light-change``: a global illumination change (a cloud or an auto-exposure step): all channels fall by
  :data:`LIGHT_DROP` (a little less in blue) over :data:`LIGHT_RAMP_S` seconds from :data:`LIGHT_DOWN_S`, and come
  back over the same ramp from :data:`LIGHT_UP_S`.
- ``noise``: stronger, signal-dependent sensor noise, standard deviation ``sqrt(READ_NOISE^2 + SHOT_GAIN * I)`` DN
  for a pixel of ``I`` DN (about 6.5 DN at 100 DN instead of the default 3.5 DN everywhere); the same random draws.
- ``compression``: each frame is JPEG-encoded at quality :data:`JPEG_QUALITY` and decoded (cv2) after the noise
  (blocking, ringing and chroma subsampling around edges); the written video stays lossless.
- ``dark-car``: the first car of the scene (lowest id) is painted in the road's asphalt colour, so its roof shows the
  road's radiance and its sides are darker still; scenes without a car are unchanged (a warning says so).
- ``crowd``: 20-40 more people in view at once, singles, pairs side by side and groups of three walking along the
  street both ways, some crossing in from below, a few small and half hidden on the far sidewalk (issue 26;
  :mod:`wptrack.synth.plaza_crowd`).
- ``cyclists``: 2-4 people riding bicycles at 3.5-6 m/s along the road and across the plaza, each one object of
  class ``cyclist`` (issue 26; :mod:`wptrack.synth.plaza_crowd`).
- ``clouds`` (issue 26): soft-edged cloud shadows drifting across the scene with the wind (:func:`cloud_cover`): a
  train of :data:`CLOUD_COUNT` clouds (elliptical, edges blurred over :data:`CLOUD_EDGE_M` metres, opacity
  :data:`CLOUD_OPACITY` with a drifting internal texture) at :data:`CLOUD_WIND` m/s. A cloud removes that fraction of
  the direct sunlight, so a sunlit horizontal surface darkens by ``opacity * direct share`` (the share of direct
  light in its radiance, about 0.55 on the plaza: a road pixel goes e.g. 190 -> 145 under a thick cloud, -> 170
  under a thin one), surfaces in static shadow not at all, vertical surfaces and vegetation by
  ``opacity * CLOUD_SIDE_SHARE`` (less), the people and cars by their own direct share at their 3-D points; the sky
  light left is a little bluer (:data:`CLOUD_TINT`). Cloud shadows are not objects: the masks and ground truth do
  not change. :func:`cloud_darkening` gives the per-pixel darkening of the static scene (to measure false
  positives where the ground darkened).
- ``exposure`` (issue 26): the camera's auto-exposure jumps (global gain steps :data:`EXPOSURE_STEPS` over
  :data:`EXPOSURE_RAMP_S` seconds), auto-white-balance shifts (:data:`AWB_SHIFTS`, per channel, over
  :data:`AWB_RAMP_S`) and lights switching on in part of the view (:data:`LIGHT_POOLS`: a warm pool of light on the
  ground, brightening every surface and person in it with a gaussian fall-off, switched on over
  :data:`POOL_RAMP_S`). Masks and ground truth unchanged.
- ``short`` (issue 26): a clip of :data:`SHORT_S` seconds (shorter than the offline background window), starting at
  the moment of the scene's default timeline whose next :data:`SHORT_S` seconds hold the most objects in view, so
  objects are in view from the first frame and through most frames (the default length becomes that clip; the
  objects' motion is the default one, shifted in time).

The chosen conditions and their parameters are written to ``scene.json`` under ``conditions`` (absent when none).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError

__all__ = [
    "CONDITION_NAMES",
    "PlazaConditions",
    "TimeWarp",
    "cloud_cover",
    "cloud_darkening",
    "ease_rate",
    "exposure_gain",
    "light_pool_factor",
    "parse_conditions",
]

HOLD_S = 4.0
"""static-start: seconds the whole scene stands still at the start."""
EASE_S = 0.6
"""Seconds to go from standing to full speed (and back), with a smoothstep rate."""
STOP_S = 3.0
"""stop-and-go: seconds each person stands (not counting the easing)."""
STOP_AT = 0.4
"""stop-and-go: fraction of a person's frames in view at which they stop."""
SUN_ELEVATION_DEG = 35.0
"""sun: elevation of the sun, degrees (the default sun stands at about 54 degrees)."""
SUN_AMBIENT = 0.3
"""sun: ambient (sky) term of the lighting."""
SUN_DIFFUSE = 0.85
"""sun: direct (Lambert) term of the lighting at normal incidence."""
LIGHT_DROP = (0.38, 0.36, 0.32)
"""light-change: relative fall of R, G, B under the cloud."""
LIGHT_DOWN_S = 3.0
"""light-change: time the light starts falling, seconds."""
LIGHT_UP_S = 8.0
"""light-change: time the light starts coming back, seconds."""
LIGHT_RAMP_S = 1.0
"""light-change: duration of each ramp, seconds."""
READ_NOISE = 4.0
"""noise: signal-independent noise standard deviation, DN."""
SHOT_GAIN = 0.27
"""noise: variance per DN of signal (shot noise), DN."""
JPEG_QUALITY = 70
"""compression: JPEG quality (0-100) of cv2.imencode."""
CROWD_AT_ONCE = (20, 40)
"""crowd: range of the mean number of crowd people in the ground truth over the default length (one draw per scene)."""
GROUP_SIZES = ((1, 0.4), (2, 0.4), (3, 0.2))
"""crowd: group sizes and their shares."""
SIDE_BY_SIDE = (0.7, 0.9)
"""crowd: distance of neighbours walking side by side in a pair or a group of three, metres."""
WALK_SPEEDS = (0.9, 1.5)
"""crowd: walking speeds, m/s."""
CYCLISTS = (2, 4)
"""cyclists: range of their number."""
CYCLE_SPEEDS = (3.5, 6.0)
"""cyclists: their speeds, m/s."""
CYCLIST_CLASS = "cyclist"
"""cyclists: ground-truth class of a rider on a bicycle (one object)."""
CLOUD_WIND = (4.0, 25.0)
"""clouds: wind speed (m/s) and direction (degrees from world +x towards +y) the cloud shadows drift with."""
CLOUD_COUNT = 7
"""clouds: number of clouds in the train (drawn once from :data:`CLOUD_SEED`)."""
CLOUD_SEED = 2611
"""clouds: seed of the cloud train's sizes, gaps, lateral offsets and opacities (fixed: the same clouds on every
scene and scene seed)."""
CLOUD_LENGTH_M = (8.0, 16.0)
"""clouds: range of a cloud's length along the wind, metres."""
CLOUD_WIDTH_M = (16.0, 32.0)
"""clouds: range of a cloud's width across the wind, metres."""
CLOUD_GAP_M = (3.0, 10.0)
"""clouds: range of the clear gap between two clouds along the wind, metres."""
CLOUD_OPACITY = (0.2, 0.5)
"""clouds: range of the fraction of direct sunlight a cloud's core removes."""
CLOUD_EDGE_M = 4.0
"""clouds: width of a cloud shadow's soft edge on the ground, metres."""
CLOUD_TEXTURE = 0.3
"""clouds: relative amplitude of the drifting texture inside a cloud (its opacity varies by about +-15 %)."""
CLOUD_SIDE_SHARE = 0.3
"""clouds: share of direct sunlight in the radiance of static surfaces that do not face up (facades, vegetation,
the sides of the clutter): they darken less under a cloud than the sunlit ground."""
CLOUD_TINT = (1.0, 0.97, 0.92)
"""clouds: relative darkening of R, G, B under a cloud (the sky light that stays is bluish: red falls most)."""
EXPOSURE_STEPS = ((1.5, 1.3), (5.5, 0.8), (9.5, 1.15))
"""exposure: auto-exposure jumps ``(time s, factor)``: from that time on, the global gain is multiplied by factor."""
EXPOSURE_RAMP_S = 0.15
"""exposure: duration of each auto-exposure jump, seconds (about two frames at 15 fps)."""
AWB_SHIFTS = ((3.5, (1.08, 1.0, 0.9)), (8.5, (0.95, 1.0, 1.07)))
"""exposure: auto-white-balance shifts ``(time s, (R, G, B) factors)``, multiplying from that time on."""
AWB_RAMP_S = 0.5
"""exposure: duration of each white-balance shift, seconds."""
LIGHT_POOLS = (
    (2.5, (2.0, 8.0), 2.5, (1.45, 1.36, 1.22)),
    (7.0, (-6.0, 17.0), 3.0, (1.35, 1.3, 1.2)),
)
"""exposure: lights switching on ``(time s, ground centre (x, y) m, gaussian radius m, (R, G, B) peak factor)``:
a floodlight's pool on the ground (a warm light: red rises most)."""
POOL_RAMP_S = 0.2
"""exposure: seconds a light takes to switch on."""
SHORT_S = 5.0
"""short: clip length, seconds (75 frames at the plaza's 15 fps; the offline background window is 300 frames)."""

CONDITION_NAMES: dict[str, str] = {
    "static-start": "static_start",
    "stop-and-go": "stop_and_go",
    "sun": "sun_shadows",
    "light-change": "light_change",
    "noise": "sensor_noise",
    "compression": "compression",
    "dark-car": "dark_car",
    "crowd": "crowd",
    "cyclists": "cyclists",
    "clouds": "clouds",
    "exposure": "exposure",
    "short": "short_clip",
}
"""Command-line name -> :class:`PlazaConditions` field."""


@dataclass(frozen=True)
class PlazaConditions:
    """Which hard conditions a plaza scene renders (all off: the default scenes).

    Attributes:
        static_start: Objects in view at frame 0, standing still for :data:`HOLD_S` seconds.
        stop_and_go: People stop for :data:`STOP_S` seconds and walk on.
        sun_shadows: Low clear-sky sun: long hard cast shadows, chromaticity kept.
        light_change: Global illumination drop by about a third and back.
        sensor_noise: Stronger signal-dependent sensor noise.
        compression: JPEG quality :data:`JPEG_QUALITY` on every frame.
        dark_car: The first car painted in the asphalt's colour.
        crowd: 20-40 more people at once, in pairs and small groups (:mod:`wptrack.synth.plaza_crowd`).
        cyclists: 2-4 cyclists (:mod:`wptrack.synth.plaza_crowd`).
        clouds: Soft cloud shadows drifting across the scene.
        exposure: Auto-exposure jumps, white-balance shifts and lights switching on in part of the view.
        short_clip: A clip of :data:`SHORT_S` seconds with objects in view from the first frame.
    """

    static_start: bool = False
    stop_and_go: bool = False
    sun_shadows: bool = False
    light_change: bool = False
    sensor_noise: bool = False
    compression: bool = False
    dark_car: bool = False
    crowd: bool = False
    cyclists: bool = False
    clouds: bool = False
    exposure: bool = False
    short_clip: bool = False

    def __post_init__(self) -> None:
        for f in fields(self):
            if not isinstance(getattr(self, f.name), (bool, np.bool_)):
                raise ConfigError(f"PlazaConditions.{f.name}: expected True or False, got {getattr(self, f.name)!r}")

    @property
    def names(self) -> list[str]:
        """Command-line names of the conditions that are on, in :data:`CONDITION_NAMES` order."""
        return [name for name, attr in CONDITION_NAMES.items() if getattr(self, attr)]

    @property
    def any(self) -> bool:
        """True when at least one condition is on."""
        return bool(self.names)

    @classmethod
    def parse(cls, text: str | Sequence[str] | None) -> PlazaConditions:
        """Conditions from a comma-separated list of names (:data:`CONDITION_NAMES`), ``all`` or ``none``.

        Raises:
            ConfigError: an unknown name (the message lists the known ones).
        """
        return parse_conditions(text)

    def describe(self) -> dict[str, dict[str, Any]]:
        """Name -> parameters of each condition that is on (written to scene.json)."""
        params: dict[str, dict[str, Any]] = {
            "static-start": {"hold_s": HOLD_S, "ease_s": EASE_S},
            "stop-and-go": {"stop_s": STOP_S, "at_fraction_in_view": STOP_AT, "ease_s": EASE_S},
            "sun": {
                "elevation_deg": SUN_ELEVATION_DEG,
                "ambient": SUN_AMBIENT,
                "diffuse": SUN_DIFFUSE,
                "shadow_ratio": round(sun_shadow_ratio(), 4),
            },
            "light-change": {
                "drop_rgb": list(LIGHT_DROP),
                "down_s": LIGHT_DOWN_S,
                "up_s": LIGHT_UP_S,
                "ramp_s": LIGHT_RAMP_S,
            },
            "noise": {"read_dn": READ_NOISE, "shot_gain_dn": SHOT_GAIN},
            "compression": {"codec": "jpeg", "quality": JPEG_QUALITY},
            "dark-car": {"albedo": "asphalt"},
            "crowd": _crowd_params(),
            "cyclists": _cyclist_params(),
            "clouds": {
                "wind_m_s": CLOUD_WIND[0],
                "wind_direction_deg": CLOUD_WIND[1],
                "clouds": [
                    {k: round(float(v), 3) for k, v in zip(CLOUD_FIELDS, c, strict=True)} for c in cloud_train()
                ],
                "edge_m": CLOUD_EDGE_M,
                "texture": CLOUD_TEXTURE,
                "side_share": CLOUD_SIDE_SHARE,
                "tint_rgb": list(CLOUD_TINT),
            },
            "exposure": {
                "steps": [list(s) for s in EXPOSURE_STEPS],
                "ramp_s": EXPOSURE_RAMP_S,
                "awb_shifts": [[t, list(f)] for t, f in AWB_SHIFTS],
                "awb_ramp_s": AWB_RAMP_S,
                "light_pools": [
                    {"on_s": t, "centre_m": list(c), "radius_m": r, "peak_rgb": list(f)} for t, c, r, f in LIGHT_POOLS
                ],
                "pool_ramp_s": POOL_RAMP_S,
            },
            "short": {"seconds": SHORT_S},
        }
        return {name: params[name] for name in self.names}


def _crowd_params() -> dict[str, Any]:
    return {"at_once": list(CROWD_AT_ONCE), "group_sizes": [list(g) for g in GROUP_SIZES],
            "side_by_side_m": list(SIDE_BY_SIDE), "speeds": list(WALK_SPEEDS)}  # fmt: skip


def _cyclist_params() -> dict[str, Any]:
    return {"count": list(CYCLISTS), "speeds": list(CYCLE_SPEEDS), "class": CYCLIST_CLASS}


def parse_conditions(text: str | Sequence[str] | None) -> PlazaConditions:
    """See :meth:`PlazaConditions.parse`."""
    if text is None:
        return PlazaConditions()
    items = text.split(",") if isinstance(text, str) else list(text)
    names = [s.strip().lower() for s in items if s.strip()]
    if names == ["all"]:
        return PlazaConditions(**{attr: True for attr in CONDITION_NAMES.values()})
    if names in ([], ["none"]):
        return PlazaConditions()
    unknown = [n for n in names if n not in CONDITION_NAMES]
    if unknown:
        raise ConfigError(
            f"conditions: unknown {', '.join(repr(n) for n in unknown)} "
            f"(expected a comma-separated list of {', '.join(CONDITION_NAMES)}, or all, or none)"
        )
    return PlazaConditions(**{CONDITION_NAMES[n]: True for n in names})


def sun_elevation_direction(azimuth_from: Sequence[float]) -> tuple[float, float, float]:
    """Unit direction towards a sun at :data:`SUN_ELEVATION_DEG` with the horizontal azimuth of ``azimuth_from``."""
    d = np.asarray(azimuth_from, dtype=np.float64)
    horiz = d[:2] / np.linalg.norm(d[:2])
    el = math.radians(SUN_ELEVATION_DEG)
    return (float(horiz[0] * math.cos(el)), float(horiz[1] * math.cos(el)), float(math.sin(el)))


def sun_shadow_ratio() -> float:
    """Brightness ratio shadow / lit of a horizontal surface under the ``sun`` lighting (same for R, G, B).

    The lighting model shades ``albedo * (ambient + diffuse * max(n . s, 0))``; a horizontal surface (n = +z) out of
    the direct sun keeps the ambient term only.
    """
    lam = math.sin(math.radians(SUN_ELEVATION_DEG))
    return SUN_AMBIENT / (SUN_AMBIENT + SUN_DIFFUSE * lam)


def light_change_factor(t: float) -> np.ndarray:
    """(3,) R, G, B multiplier of the ``light-change`` condition at time ``t`` seconds (1 outside the change)."""

    def ramp(x: float) -> float:
        y = min(max(x / LIGHT_RAMP_S, 0.0), 1.0)
        return y * y * (3 - 2 * y)

    c = ramp(t - LIGHT_DOWN_S) - ramp(t - LIGHT_UP_S)
    return 1.0 - c * np.asarray(LIGHT_DROP, dtype=np.float64)


def sensor_sigma(radiance_dn: np.ndarray) -> np.ndarray:
    """Per-pixel noise standard deviation (DN) of the ``noise`` condition for a signal of ``radiance_dn`` DN."""
    return np.sqrt(np.float32(READ_NOISE**2) + np.float32(SHOT_GAIN) * np.clip(radiance_dn, 0.0, None))


def jpeg_roundtrip(bgr: np.ndarray, quality: int = JPEG_QUALITY) -> np.ndarray:
    """``(H, W, 3)`` uint8 BGR image encoded as JPEG at ``quality`` and decoded again (cv2)."""
    import cv2

    ok, buf = cv2.imencode(".jpg", bgr, [int(cv2.IMWRITE_JPEG_QUALITY), int(quality)])
    if not ok:  # pragma: no cover - cv2 always encodes a valid uint8 image
        raise RuntimeError("cv2.imencode failed to encode a JPEG frame")
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)


def _smooth(x: np.ndarray | float) -> np.ndarray:
    """Smoothstep of ``x`` clipped to [0, 1]."""
    y = np.clip(x, 0.0, 1.0)
    return y * y * (3 - 2 * y)


CLOUD_FIELDS = ("u0_m", "w_m", "length_m", "width_m", "opacity")
"""Names of the columns of :func:`cloud_train` (scene.json)."""


@functools.lru_cache(maxsize=1)
def cloud_train() -> np.ndarray:
    """``(CLOUD_COUNT, 5)`` clouds of the ``clouds`` condition: along-wind centre at time 0 ``u0``, across-wind
    centre ``w``, length, width (metres) and core opacity; the first cloud's centre is at ``u0 = 10`` m (its rear
    half over the view at time 0), the others follow it upwind (they drift over the view later)."""
    rng = np.random.default_rng(CLOUD_SEED)
    out = []
    u = 10.0
    for k in range(CLOUD_COUNT):
        length = rng.uniform(*CLOUD_LENGTH_M)
        if k:
            u -= 0.5 * length + rng.uniform(*CLOUD_GAP_M)
        out.append((u, rng.uniform(2.0, 28.0), length, rng.uniform(*CLOUD_WIDTH_M), rng.uniform(*CLOUD_OPACITY)))
        u -= 0.5 * length
    return np.asarray(out)


def cloud_cover(xy: np.ndarray, t: float) -> np.ndarray:
    """Fraction of direct sunlight the clouds remove at ground points ``xy`` (..., 2) metres at time ``t`` seconds.

    Each cloud is an ellipse (length along the wind, width across) drifting at :data:`CLOUD_WIND`; its cover is its
    opacity (times a drifting texture, :data:`CLOUD_TEXTURE`) inside, falling smoothly to 0 over
    :data:`CLOUD_EDGE_M` metres across its rim; overlapping clouds combine as ``1 - prod(1 - cover)``.

    Returns:
        (...,) cover in [0, 1) (0 where a point is not finite).
    """
    from wptrack.synth.render import value_noise

    xy = np.asarray(xy, dtype=np.float64)
    speed, direction = CLOUD_WIND
    c, s = math.cos(math.radians(direction)), math.sin(math.radians(direction))
    ok = np.isfinite(xy[..., 0]) & np.isfinite(xy[..., 1])
    x, y = np.where(ok, xy[..., 0], 0.0), np.where(ok, xy[..., 1], 0.0)
    u = x * c + y * s - speed * t  # along the wind, in the clouds' frame
    w = -x * s + y * c
    texture = 1.0 + CLOUD_TEXTURE * (value_noise(u / 6.0 + 17.0, w / 6.0 + 5.0, CLOUD_SEED) - 0.5)
    clear = np.ones_like(u)
    for u0, w0, length, width, opacity in cloud_train():
        a, b = 0.5 * length, 0.5 * width
        rho = np.sqrt(((u - u0) / a) ** 2 + ((w - w0) / b) ** 2)
        inside = (1.0 - rho) * min(a, b)  # about the distance inside the rim, metres
        cover = opacity * _smooth(inside / CLOUD_EDGE_M + 0.5)
        clear *= 1.0 - np.clip(cover * texture, 0.0, 0.95)
    return np.where(ok, 1.0 - clear, 0.0)


def cloud_shadow_foot(points: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """Ground points ``(..., 2)`` whose cloud cover shades 3-D ``points`` (..., 3): the points moved along the
    sun direction ``sun`` (unit, towards the sun) down to z = 0 (the clouds are far above: their shadow on a point
    at height z is the ground shadow shifted towards the sun's azimuth)."""
    p = np.asarray(points, dtype=np.float64)
    sun = np.asarray(sun, dtype=np.float64)
    return p[..., :2] - (p[..., 2:3] / sun[2]) * sun[:2]


def cloud_darkening(cover: np.ndarray, share: np.ndarray) -> np.ndarray:
    """``(..., 3)`` R, G, B radiance factors of surfaces with direct-light ``share`` (...,) under cloud ``cover``
    (...,): ``1 - cover * share * CLOUD_TINT``."""
    return 1.0 - (np.asarray(cover) * np.asarray(share))[..., None] * np.asarray(CLOUD_TINT)


def exposure_gain(t: float) -> np.ndarray:
    """(3,) R, G, B global gain of the ``exposure`` condition at time ``t`` seconds: the auto-exposure jumps and the
    white-balance shifts so far (1 before the first)."""
    out = np.ones(3)
    for at, factor in EXPOSURE_STEPS:
        out = out * (1.0 + (factor - 1.0) * _smooth((t - at) / EXPOSURE_RAMP_S))
    for at, rgb in AWB_SHIFTS:
        out = out * (1.0 + (np.asarray(rgb) - 1.0) * _smooth((t - at) / AWB_RAMP_S))
    return out


def light_pool_factor(points: np.ndarray, t: float, pools: Sequence[tuple] = LIGHT_POOLS) -> np.ndarray:
    """``(..., 3)`` R, G, B factors of the ``exposure`` condition's lights at 3-D ``points`` (..., 3) at time ``t``:
    ``1 + on(t) (peak - 1) exp(-r^2 / (2 radius^2))`` per light, ``r`` the horizontal distance to its centre (1 where
    a point is not finite). ``pools``: the lights, as :data:`LIGHT_POOLS` (the plaza's; the office has its own)."""
    p = np.asarray(points, dtype=np.float64)
    out = np.ones((*p.shape[:-1], 3))
    ok = np.isfinite(p[..., 0]) & np.isfinite(p[..., 1])
    x, y = np.where(ok, p[..., 0], 1e9), np.where(ok, p[..., 1], 1e9)
    for at, (cx, cy), radius, peak in pools:
        on = float(_smooth((t - at) / POOL_RAMP_S))
        if on <= 0.0:
            continue
        fall = np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2.0 * radius**2))
        out = out * (1.0 + on * (np.asarray(peak) - 1.0) * fall[..., None])
    return out


# ----------------------------------------------------------------------------------------------------- retiming


def ease_rate(t: np.ndarray, stops: Sequence[tuple[float, float]]) -> np.ndarray:
    """Motion rate in [0, 1] at times ``t``: 0 inside each ``(start, end)`` stop, 1 away from the stops.

    The rate falls from 1 to 0 over :data:`EASE_S` seconds before ``start`` and rises back over :data:`EASE_S`
    after ``end`` (smoothstep), so that speeds change continuously. ``start = -inf`` stands still from the start.
    """
    t = np.asarray(t, dtype=np.float64)
    rate = np.ones_like(t)
    for start, end in stops:
        x_in = np.clip((start - t) / EASE_S, 0.0, 1.0) if math.isfinite(start) else np.zeros_like(t)
        x_out = np.clip((t - end) / EASE_S, 0.0, 1.0)
        x = np.maximum(x_in, x_out)
        rate = np.minimum(rate, x * x * (3 - 2 * x))
    return rate


@dataclass(frozen=True)
class TimeWarp:
    """A monotone map from scene time to an actor's own path time: ``w(t) = origin + integral of rate``.

    Attributes:
        knots: (K,) scene times, seconds (increasing, step ``dt``).
        values: (K,) path times at the knots; beyond the knots the map continues with slope 1.
    """

    knots: np.ndarray
    values: np.ndarray

    @classmethod
    def build(
        cls, stops: Sequence[tuple[float, float]], origin: float, span: tuple[float, float], dt: float = 0.005
    ) -> TimeWarp:
        """The warp with rate :func:`ease_rate` of ``stops``, mapping ``span[0]`` to ``origin`` (trapezoid rule)."""
        t = np.arange(span[0], span[1] + dt, dt)
        r = ease_rate(t, stops)
        w = origin + np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * dt)])
        return cls(t, w)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=np.float64)
        out = np.interp(t, self.knots, self.values)
        lo, hi = t < self.knots[0], t > self.knots[-1]
        out[lo] = self.values[0] + (t[lo] - self.knots[0])
        out[hi] = self.values[-1] + (t[hi] - self.knots[-1])
        return out


@dataclass(frozen=True)
class Retimed:
    """A track (path or formation member) followed with a :class:`TimeWarp` (stops, a frozen start)."""

    inner: Any
    warp: TimeWarp

    def positions(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and activity at scene ``times`` (seconds): those of ``inner`` at the warped times."""
        return self.inner.positions(self.warp(np.asarray(times, dtype=np.float64)))
