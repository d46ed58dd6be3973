"""Switchable hard conditions of the s3 plaza scenes (issue 10): each one alone, so that its effect can be measured.

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

The chosen conditions and their parameters are written to ``scene.json`` under ``conditions`` (absent when none).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError

__all__ = ["CONDITION_NAMES", "PlazaConditions", "TimeWarp", "ease_rate", "parse_conditions"]

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
