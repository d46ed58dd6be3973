"""Configuration and results of the S3 template tracker (Juza et al.): the human and vehicle priors, the frozen
``TemplateConfig`` (validated, with units and the paper's symbols), and the per-frame ``TemplateEstimate`` with its
``TrackedObject`` list. The device driver is :mod:`wptrack.trackers.templates.tracker`, which re-exports these names.

Length: one dataclass holds every parameter of the tracker with its units, symbol, range and the measurements that
chose its default (the CLI and the batch manifests are derived from it); split up, a parameter's reasons would no
longer sit beside it."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from wptrack.core.config import check, param
from wptrack.core.errors import ConfigError
from wptrack.core.resampling import SCHEMES
from wptrack.kernels.templates import raster as kraster

CLASSES: tuple[str, ...] = ("human", "vehicle", "cyclist")
"""Object classes, in KIND order (KIND_HUMAN = 1, KIND_VEHICLE = 2, KIND_CYCLIST = 3)."""
DEFAULT_CLASSES: tuple[str, ...] = ("human", "vehicle")
"""The classes the tracker adds by default. The cyclist (issue 26) is opt-in: with it on by default, cyclist
hypotheses took people walking along the street (TownCentre, tracker seed 0: 10 cyclist tracks, 28 % of the
reported rows, MOTA 0.28 -> 0.21; PETS seed 1: MOTA 0.88 -> 0.82; docs/notes.md)."""


def _vec3(value: Any, name: str, positive: bool = True) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: expected 3 numbers, got {value!r}") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name}: expected 3 finite numbers, got {value!r}")
    if positive and np.any(arr < 0):
        raise ConfigError(f"{name}: expected values >= 0 (metres), got {arr.tolist()}")
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def _nonneg(value: Any, name: str, unit: str, upper: float | None = None, strict: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ConfigError(f"{name}: expected a number ({unit}), got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < 0 or (strict and v == 0) or (upper is not None and v > upper):
        rng = f"in [0, {upper}]" if upper is not None else ("> 0" if strict else ">= 0")
        raise ConfigError(f"{name}: expected a value {rng} ({unit}), got {value!r}")
    return v


@dataclass(frozen=True)
class HumanPrior:
    """Human template (leg prism + upper body with head, ``kernels.templates.raster``), its prior and its dynamics (eq.
    8).

    dims = (height, body radius, head radius), metres. Deviations are per frame.
    """

    dims_mean: tuple[float, float, float] = (1.72, 0.22, 0.10)
    """Prior mean of an added human (and the size of the addition candidates), m."""
    dims_sd: tuple[float, float, float] = (0.08, 0.03, 0.01)
    """Prior deviation of an added human's dims, m."""
    dims_min: tuple[float, float, float] = (1.2, 0.10, 0.07)
    dims_max: tuple[float, float, float] = (2.1, 0.32, 0.15)
    sigma_dims: tuple[float, float, float] = (0.01, 0.005, 0.002)
    """sigma_d of eq. 8, m per frame."""
    sigma_speed: float = 0.25
    """sigma_v of eq. 8 (each velocity component), m/s per frame."""
    init_speed_sd: float = 0.5
    """Velocity deviation of an added human, m/s."""
    speed_max: float = 3.0
    """Velocity magnitude limit, m/s."""
    cost_a: float = 20.0
    """a_r of eq. 5, pixels."""
    cost_b: float = 60.0
    """b_r of eq. 5, pixels."""

    def __post_init__(self) -> None:
        for name in ("dims_mean", "dims_sd", "dims_min", "dims_max", "sigma_dims"):
            object.__setattr__(self, name, _vec3(getattr(self, name), f"human.{name}"))
        for name, unit in (("sigma_speed", "m/s"), ("init_speed_sd", "m/s"), ("cost_a", "px"), ("cost_b", "px")):
            object.__setattr__(self, name, _nonneg(getattr(self, name), f"human.{name}", unit))
        object.__setattr__(self, "speed_max", _nonneg(self.speed_max, "human.speed_max", "m/s", strict=True))
        _check_dims("human", self.dims_mean, self.dims_min, self.dims_max)


@dataclass(frozen=True)
class VehiclePrior:
    """Vehicle template (lower body + cabin boxes), its prior and its dynamics (eq. 9).

    dims = (length, width, height), metres. Deviations are per frame.
    """

    dims_mean: tuple[float, float, float] = (4.4, 1.8, 1.5)
    dims_sd: tuple[float, float, float] = (0.3, 0.08, 0.08)
    dims_min: tuple[float, float, float] = (3.0, 1.4, 1.1)
    dims_max: tuple[float, float, float] = (6.5, 2.5, 2.4)
    sigma_dims: tuple[float, float, float] = (0.03, 0.01, 0.01)
    sigma_speed: float = 0.6
    """sigma_v of eq. 9, m/s per frame."""
    sigma_turn: float = 0.3
    """sigma_theta of eq. 9, rad/s per frame. 0.3 lets the turn rate reach 1 rad/s within one second of turning in
    (15 frames, one deviation); was 0.15 (docs/notes.md, round six)."""
    init_speed_sd: float = 3.0
    init_heading_sd: float = 0.2
    """Heading deviation of an added vehicle around the candidate's orientation, rad."""
    speed_max: float = 20.0
    turn_max: float = 2.5
    """|theta| limit, rad/s. A car's yaw rate is its speed over its turning radius: 2.5 rad/s is a 1.6 m radius at
    4 m/s, beyond any road car; the U-turns of ``wptrack synth s3-cars`` reach 2.4 rad/s. The former limit, 1 rad/s,
    held every hypothesis of a U-turning car outside its turn, and humans were added on the part it left uncovered
    (docs/notes.md, round six)."""
    orientations: int = 4
    """Candidate orientations in [0, pi) (a box is symmetric under a half turn)."""
    cost_a: float = 40.0
    cost_b: float = 120.0

    def __post_init__(self) -> None:
        for name in ("dims_mean", "dims_sd", "dims_min", "dims_max", "sigma_dims"):
            object.__setattr__(self, name, _vec3(getattr(self, name), f"vehicle.{name}"))
        for name, unit in (
            ("sigma_speed", "m/s"),
            ("sigma_turn", "rad/s"),
            ("init_speed_sd", "m/s"),
            ("init_heading_sd", "rad"),
            ("cost_a", "px"),
            ("cost_b", "px"),
        ):
            object.__setattr__(self, name, _nonneg(getattr(self, name), f"vehicle.{name}", unit))
        object.__setattr__(self, "speed_max", _nonneg(self.speed_max, "vehicle.speed_max", "m/s", strict=True))
        object.__setattr__(self, "turn_max", _nonneg(self.turn_max, "vehicle.turn_max", "rad/s", strict=True))
        if isinstance(self.orientations, bool) or not isinstance(self.orientations, int) or self.orientations < 1:
            raise ConfigError(f"vehicle.orientations: expected an integer >= 1, got {self.orientations!r}")
        _check_dims("vehicle", self.dims_mean, self.dims_min, self.dims_max)


@dataclass(frozen=True)
class CyclistPrior:
    """Cyclist template (a person riding a bicycle, one object: the bike-and-legs box and the rider's box of
    ``kernels.templates.raster``), its prior and its dynamics (eq. 9, as a vehicle's). Beyond the paper.

    dims = (length, width, height), metres: the bike's length, the handlebar's width, the top of the rider's head.
    Deviations are per frame; the turn rate's deviation and limit and the heading deviation of an added cyclist are
    the vehicle's (``VehiclePrior.sigma_turn``, ``turn_max``, ``init_heading_sd``).
    """

    dims_mean: tuple[float, float, float] = (1.75, 0.6, 1.65)
    dims_sd: tuple[float, float, float] = (0.1, 0.05, 0.06)
    dims_min: tuple[float, float, float] = (1.4, 0.4, 1.3)
    dims_max: tuple[float, float, float] = (2.2, 0.9, 2.0)
    sigma_dims: tuple[float, float, float] = (0.01, 0.005, 0.005)
    sigma_speed: float = 0.4
    """sigma_v of eq. 9, m/s per frame."""
    init_speed_sd: float = 3.0
    """Speed deviation of an added cyclist (along its heading, either way), m/s."""
    speed_max: float = 12.0
    speed_min: float = 0.0
    """Slowest speed of a cyclist, m/s (beyond the paper: eq. 9's speed is kept at least this far from 0, either
    way; 0: no floor, eq. 9). People on bicycles ride at 3-8 m/s and walkers at 0.8-1.6 m/s, so a cyclist hypothesis
    put on a walker would outrun them and lose their pixels. Off by default: with the cyclist class and 2 m/s (the
    physical bound, not tuned), held-out s3-people + cyclists MOTA 0.748 -> 0.772 and s3-mixed + cyclists 0.879 ->
    0.891, PETS seeds 0 / 1 0.850 / 0.815 -> 0.855 / 0.842, but TownCentre seeds 0 / 1 0.209 / 0.313 -> 0.239 / 0.200
    (docs/notes.md, round eight): not a gain on the real street."""
    orientations: int = 4
    """Candidate orientations in [0, pi)."""
    cost_a: float = 20.0
    """a_r of eq. 5, pixels (at ``TemplateConfig.reference_area``), as a human's."""
    cost_b: float = 60.0

    def __post_init__(self) -> None:
        for name in ("dims_mean", "dims_sd", "dims_min", "dims_max", "sigma_dims"):
            object.__setattr__(self, name, _vec3(getattr(self, name), f"cyclist.{name}"))
        for name, unit in (("sigma_speed", "m/s"), ("init_speed_sd", "m/s"), ("cost_a", "px"), ("cost_b", "px")):
            object.__setattr__(self, name, _nonneg(getattr(self, name), f"cyclist.{name}", unit))
        object.__setattr__(self, "speed_max", _nonneg(self.speed_max, "cyclist.speed_max", "m/s", strict=True))
        object.__setattr__(self, "speed_min", _nonneg(self.speed_min, "cyclist.speed_min", "m/s", upper=self.speed_max))
        if isinstance(self.orientations, bool) or not isinstance(self.orientations, int) or self.orientations < 1:
            raise ConfigError(f"cyclist.orientations: expected an integer >= 1, got {self.orientations!r}")
        _check_dims("cyclist", self.dims_mean, self.dims_min, self.dims_max)


def _check_dims(kind: str, mean, lo, hi) -> None:
    if not all(0 < a <= b for a, b in zip(lo, hi, strict=True)):
        raise ConfigError(f"{kind}.dims_min/dims_max: expected 0 < min <= max per dimension, got {lo} and {hi}")
    if not all(a <= m <= b for a, m, b in zip(lo, mean, hi, strict=True)):
        raise ConfigError(f"{kind}.dims_mean: {mean} must lie within dims_min {lo} and dims_max {hi}")


@dataclass(frozen=True)
class TemplateConfig:
    """Configuration of the template tracker (defaults suit 640x480 surveillance video at 10-25 fps)."""

    particles: int = param(1000, help="number of particles, each a whole scene", symbol="N", lo=1, hi=2**31 - 2)
    max_objects: int = param(64, help="objects per particle", symbol="R_max", lo=1, hi=int(kraster.MAX_SLOTS))
    """R_max, objects per particle (at most ``kernels.templates.raster.MAX_SLOTS`` = 64; the device memory it needs is
    checked before allocation). 64 (was 8 before issue 26): a busy street holds 20-40 people and the hypotheses on
    their way in and out; a slot is free again only when no particle holds its object, so R_max just above the scene's
    count delays additions (on the PETS clip, 4-8 people, R_max 64 scored MOTA 0.866 where 8 scored 0.836, tracker
    seeds 0-5). Empty slots cost little: the partitioned filter keeps them out of every group, and the scoring walks
    only the pieces drawn on each row (CPU time per frame on the PETS clip, 1000 particles: 25 ms at 8, 35 ms at 64)."""
    camera: str = param("0", help="the rig camera that sees the scene: its name or index")
    fps: float | None = param(
        None,
        help="frame rate of the sequence (Delta t = 1 / fps in eqs. 8-9; default: the video's, else 15)",
        units="frames/s",
        lo=0.0,
        lo_open=True,
    )
    scale: float = param(5000.0, help="log w_i = -(m'_i + c_i) s / (W H)", symbol="s, eq. 6", lo=0.0, lo_open=True)
    bg_weight: float = param(
        0.6,
        help="weight of a template pixel on mask background in the matching penalty (1: the XOR of eq. 4)",
        symbol="lambda",
        lo=0.0,
        hi=1.0,
    )
    """lambda, weight of a template pixel on mask background in the matching penalty that enters eq. 6:
    m'_i = |q AND NOT v_i| + lambda |v_i AND NOT q| (1: the XOR of eq. 4 exactly). Beyond the paper: masks made by
    background subtraction miss parts of objects (clothes like the ground, the shadow test) far more often than
    they show motion where there is none, so a template pixel on background is weaker evidence against a
    hypothesis than a foreground pixel left uncovered (a per-pixel Bernoulli model with a miss rate above the
    false-alarm rate gives lambda < 1). 0.6 was chosen on the tuning scenes (scene seed 0, offline masks): 0.5 kept
    more of the people whose clothes the masks miss, 0.75 placed cars better (docs/notes.md)."""
    exclusion: float = param(
        300.0,
        help="cost of two objects of a particle on the same ground, per pair at full overlap (0: eq. 5 exactly)",
        units="px",
        lo=0.0,
    )
    """Cost of two objects of a particle sharing the same ground, pixels per pair at full overlap (added to eq. 5's
    c_i; 0: eq. 5 exactly). Beyond the paper: humans are discs of their body radius and vehicles boxes on the ground
    (``kernels.templates.xor.pair_overlap``); solid objects cannot overlap, which keeps two hypotheses off one person in
    a group and humans off a car that its template does not fit yet. 300 px is about a fifth of a person's silhouette
    at 15 m."""
    slot_margin: int = param(
        0, help="slots beyond the reported objects that additions may hold (0: every free slot of R_max)", lo=0
    )
    """Slots beyond the reported objects that additions may hold at once (with ``slot_margin_frac``: at most n +
    max(slot_margin, ceil(slot_margin_frac n)) slots in use for n objects reported; 0: every free slot of R_max).
    Beyond the paper: R_max bounds the hypotheses on their way in (not yet reported) as well as the objects; an R_max
    just above the scene's count kept spurious additions (a human on the edge of a car) few, a large one lets them
    all in (held-out s3-cars, offline masks: MOTA 0.908 at R_max 6, 0.860 at 64, from three of twelve runs). Off by
    default: on the tuning scenes (s3-cars, scene seeds 0-5) 4 changed nothing (MOTA 0.959 -> 0.960), which cannot
    justify it (docs/notes.md, round eight)."""
    slot_margin_frac: float = param(
        0.25, help="the slot margin as a fraction of the reported objects (the larger of the two)", lo=0.0
    )
    """See ``slot_margin``: the margin grows with the objects reported (a crowd takes several in at once)."""
    reference_area: int = param(
        640 * 480,
        help="image area at which the pixel costs are given (scaled with the image's area; 0: raw pixels)",
        units="px",
        lo=0,
    )
    """Image area, pixels, at which the pixel costs are given: eq. 5's a_r and b_r (``human.cost_a`` ...),
    ``exclusion`` and ``min_candidate_area`` are multiplied by the image's area over this (0: raw pixels, as before
    issue 26). Beyond the paper: the matching penalty enters eq. 6 as a fraction of the image (m / (W H)), but the
    costs were in pixels, so at 1920x1080 they weighed 6.75 times less against an object's evidence than at 640x480
    (the same scene at two sizes was tracked differently; TownCentre at 1080p: three hypotheses on a woman with a
    pushchair, duplicates beside people). A person's silhouette is 0.4-0.45 % of the image in the plaza scenes, the
    PETS clip and TownCentre alike (the median human addition candidate), so one reference serves them."""
    t_add: float = param(
        0.3,
        help="fraction of particles that receive the frame's proposed object",
        symbol="T_add, eq. 12",
        lo=0.0,
        hi=1.0,
    )
    additions: int = param(
        1, help="objects proposed per frame on disjoint candidate boxes (1: eq. 11's single o_new)", lo=1
    )
    """Objects proposed per frame (1: eq. 11's single o_new, the paper). Beyond the paper: after each choice the
    candidates whose image boxes share a pixel with it are set aside and the best of the rest is proposed too, up to
    this many, each to its own slot and added to each particle with its own draw (eq. 12). A crowd that is in view
    at the first frame, or enters at once, is otherwise found one object per frame (20 people: the better part of
    a second of misses for the last ones); disjoint boxes explain disjoint pixels, so each choice's gain (eq. 11) is
    what it gains beside the others."""
    t_del: float = param(
        0.02,
        help="per-frame deletion probability of each object in each particle",
        symbol="T_del, eq. 13",
        lo=0.0,
        hi=1.0,
    )
    sigma_pos: float = param(0.03, help="position diffusion added to eqs. 8-9, per frame", units="m", lo=0.0)
    dims_revert: float = param(
        0.02,
        help="per-frame pull of an object's dims towards its class's prior mean (0: the random walk of eqs. 8-9)",
        lo=0.0,
        hi=1.0,
    )
    """Per-frame pull of every object's dims towards its class's prior mean ``dims_mean``, in [0, 1]: eqs. 8-9's
    d_t = d + dims_revert (mean - d) + N(0, sigma_d^2) (0: the random walk of eqs. 8-9). Beyond the paper: a mean-
    reverting (Ornstein-Uhlenbeck) size, stationary deviation sigma_d / sqrt(2 dims_revert) per dimension (human
    height: 0.05 m). In a group the feet of the people behind are hidden, and a template placed too near the camera
    and grown tall (to dims_max) covers the same pixels as the right one: seen on s3-groups, where lagging hypotheses
    sat 0.7-1 m nearer than their person with heights of 2.0-2.1 m. 0.02 was chosen on scene seed 0 (s3-groups,
    perfect masks, tracker seeds 0-3: 8.0 ID switches per run instead of 10.0; docs/notes.md)."""
    occlusion_del: float = param(
        0.0, help="share of T_del that an object's occlusion removes (0: eq. 13 exactly)", lo=0.0, hi=1.0
    )
    """Share of T_del (eq. 13) that an object's occlusion removes, in [0, 1]: an object whose image box is hidden a
    fraction o by nearer objects of its particle (``kernels.templates.occlusion``) is deleted with probability T_del (1
    - occlusion_del o) (0: eq. 13 exactly). Beyond the paper: a hidden object explains no pixel, so deleting it costs
    the particle nothing, and under eq. 13 a person walking behind others in a group is removed from a growing share of
    the particles until the slot is freed and the person is re-added with a new label (an identity switch). Off by
    default: on the tuning scene it did not lower the group ID switches (1: 11.3 per run over tracker seeds 0-3 instead
    of 10.0; with ``dims_revert`` 17.5 instead of 8.0): hidden hypotheses that are kept also wander
    onto the wrong person (docs/notes.md)."""
    occlusion_noise: float = param(
        0.0, help="share of the motion noise that an object's occlusion removes (0: eqs. 8-9 exactly)", lo=0.0, hi=1.0
    )
    """Share of the velocity, turn and position noise (eqs. 8-9, ``sigma_pos``) that an object's occlusion removes,
    in [0, 1]: noise x (1 - occlusion_noise o) (0: eqs. 8-9 exactly). Beyond the paper: a hidden object gets no
    evidence that could correct a diffused velocity, so it keeps its motion while hidden. Off by default: 0.7 (with
    occlusion_del 1) gave 26 group ID switches instead of 10 on the one tracker seed tried."""
    unseen_del: float = param(
        0.0, help="per-frame deletion probability of an object none of whose pieces is in the image", lo=0.0, hi=1.0
    )
    """Per-frame deletion probability of an object none of whose pieces is in the image, in [0, 1] (0: eq. 13
    only). Beyond the paper: an object that has left the view explains no pixel and no pixel contradicts it, so
    under eq. 13 alone it stays (and is reported) for 1 / T_del = 50 frames on average after it left. Off by
    default: on scene seeds 0-2 (with ``vehicle_entry_px`` 64) 0.5 lowered the false positives of s3-people (13 -> 7
    per run) and s3-mixed (18 -> 13) but s3-cars lost accuracy (0.93 -> 0.85), a difference 9 runs per scene cannot
    separate from the seed spread (docs/notes.md)."""
    human: HumanPrior = param(
        default_factory=HumanPrior, help="the human template, its prior and dynamics (YAML, --config)", flag=""
    )
    vehicle: VehiclePrior = param(
        default_factory=VehiclePrior, help="the vehicle template, its prior and dynamics (YAML, --config)", flag=""
    )
    cyclist: CyclistPrior = param(
        default_factory=CyclistPrior, help="the cyclist template, its prior and dynamics (YAML, --config)", flag=""
    )
    classes: tuple[str, ...] = param(
        DEFAULT_CLASSES, help="object classes the tracker may add (cyclist: opt-in)", choices=CLASSES
    )
    """Object classes the tracker may add: any of ``human``, ``vehicle``, ``cyclist`` (default: human and vehicle;
    add ``cyclist`` for streets with bicycles, :data:`DEFAULT_CLASSES`)."""
    candidate_step_px: int = param(
        8, help="addition candidates: ground points under an image grid of this pitch", units="px", lo=1
    )
    candidate_step_width: float = param(
        0.0,
        help="candidate grid pitch per row as a fraction of a person's image width there (0: the fixed pitch)",
        lo=0.0,
    )
    """With a value > 0 the pitch of each row of the candidate grid is this fraction of the image width of a person
    standing on that row (the human prior's mean body diameter), between 2 pixels and ``candidate_step_px`` (0: a
    fixed pitch of ``candidate_step_px``). Beyond the paper: a far person 8-10 pixels wide on an 8-pixel grid has no
    candidate that fits them well enough for eq. 11's threshold."""
    max_range: float = param(
        60.0, help="addition candidates farther from the camera are dropped", units="m", lo=0.0, lo_open=True
    )
    add_min_gain: float = param(
        0.2, help="a candidate is proposed when its gain (eq. 11) is at least this fraction of its area", lo=0.0
    )
    add_beta: float = param(0.5, help="weight of uncovered background in the addition gain (0: eq. 11 exactly)", lo=0.0)
    add_cost: float = param(
        0.0,
        help="a candidate's gain must pay this multiple of its object's complexity cost (eq. 5 at age 0; 0: off)",
        lo=0.0,
    )
    """Multiple of a new object's complexity cost (eq. 5 at age 0: a_r + b_r of its class, scaled like the other pixel
    costs by ``reference_area``) that a candidate's gain (eq. 11) must reach to be proposed; the argmax then ranks the
    candidates by their gain less that cost (0: off, eq. 11's gain alone). Beyond the paper: a particle that receives
    an object pays its cost in eq. 6 at once, so a candidate whose uncovered pixels are fewer than its cost lowers
    every particle it is added to and dies within frames, while the single addition of the frame
    (``additions`` 1) was spent on it: on TownCentre (tracker seed 0) it went in 56 of the 64 frames 29-92 to
    candidates never reported, 53 of them partly masked blobs more than 35 m away. Off by default: 1 cost TownCentre
    (tracker seeds 0-5, MOTA 0.270 -> 0.261) and s3-mixed (held-out scene seed 10, seeds 0-2: 0.975 -> 0.959), and
    gained on PETS (0.869 -> 0.874), s3-people (0.845 -> 0.850) and s3-cars (0.624 -> 0.781; docs/notes.md)."""
    vehicle_fit: float = param(
        0.85,
        help="class-aware addition: a vehicle candidate this much on foreground replaces a chosen human (0: off)",
        lo=0.0,
        hi=1.0,
    )
    """Class-aware addition (``kernels.templates.classify``; 0: off, eq. 11 exactly): when eq. 11 picks a human
    candidate, the vehicle candidate within half a vehicle length (``vehicle.dims_mean``) whose silhouette is the
    largest fraction of foreground replaces it if that fraction is at least ``vehicle_fit`` (candidates on the footprint
    of a reported vehicle are skipped). Beyond the paper: the uncovered part of a partly explained car (entering the
    image, turning, a vehicle hypothesis lagging behind it) is human-sized, so eq. 11 adds humans on it; a car's blob
    fills a vehicle template, a person's does not. 0.85 was chosen on scene seed 0 over 0.7 (with 0.7 s3-mixed lost a
    person for up to 50 frames; docs/notes.md)."""
    absorb: bool = param(True, help="an added vehicle removes the particle's humans on its footprint (off: eq. 12)")
    """A vehicle added to a particle removes the particle's humans whose ground disc meets its footprint (one move
    that replaces the humans covering a car by the vehicle, drawn with the addition's own random number; the
    weights of eq. 6 judge it like every addition and deletion of eqs. 12-13). Beyond the paper; false: eq. 12."""
    vehicle_entry_px: int = param(
        64, help="vehicle candidates also this far beyond the image's left, right and bottom borders", units="px", lo=0
    )
    """Vehicle addition candidates also stand under the pixels up to this far beyond the image's left, right and
    bottom borders, pixels (0: under the image only, the paper's grid). Beyond the paper: a car entering the view
    shows only its front, no vehicle centred in the image fits that blob, and eq. 11 added humans on it (the short-
    lived false positives beside cars). 64 was chosen on scene seeds 0-2 (tracker seeds 0-2, offline masks): s3-mixed
    MOTA 0.566 -> 0.665 and false positives per run 55 -> 18, s3-cars MOTA 0.468 -> 0.609, s3-people and s3-groups
    unchanged within their spread; 128 gave the same (docs/notes.md)."""
    human_entry_px: int = param(
        64, help="human candidates also this far beyond the image's left, right and bottom borders", units="px", lo=0
    )
    """Human addition candidates also stand under the pixels up to this far beyond the image's left, right and bottom
    borders, pixels (0: under the image only, the paper's grid). Beyond the paper: a person walking in from below the
    image shows the head and shoulders first, whose ground point is below the image, so no human candidate fitted
    them until the feet came into view, 0.6-1 s later (docs/notes.md, round six). 64 as for vehicles; chosen on
    scene seeds 0-5 (perfect masks: 16 and 64 px helped, 128 px did not)."""
    min_track_frames: int = param(
        8,
        help="tracks reported in fewer frames are left out of a completed run's tracks.csv (1: keep all; "
        "tracks_all.csv keeps every track)",
        units="frames",
        lo=1,
    )
    """Tracks reported in fewer frames than this are left out of a completed run's ``tracks.csv``, unless still
    reported in its last frame (1: every track; all of them stay in ``tracks_all.csv``; ``wptrack.io.run.
    drop_short_tracks``). Offline confirmation: the whole run is known when it completes, so a track that lasts is
    kept from its first frame, and only hypotheses that die young go (an object added on a shadow, the edge of a car
    or a passing glitch, deleted again a few frames later; each new id is also an id switch). The tracker itself is
    unchanged. Beyond the paper. 8 was chosen on scene seeds 0-2 (tracker seeds 0-2, offline masks; 1, 4, 8, 12, 16
    compared): s3-cars MOTA 0.609 -> 0.704 and id switches 2.9 -> 1.4 per run with the same accuracy, s3-mixed MOTA
    0.665 -> 0.671, s3-groups id switches 10.9 -> 8.4, s3-people accuracy 0.667 -> 0.644 (one short true track); 12
    and 16 cost s3-mixed accuracy. Held out it costs accuracy where an object was only covered by short fragments
    (s3-cars 0.92 -> 0.86) and halves the id switches (docs/notes.md, round four)."""
    backfill_seconds: float = param(
        1.35,
        help="when the run completes, extend each lasting track back over up to this long before it was first "
        "reported, while in view (0: off)",
        units="s",
        lo=0.0,
    )
    """Offline backfill (``wptrack.trackers.templates.backfill``): a completed run's ``tracks.csv`` extends every track
    of at least ``backfill_min_frames`` rows back over up to this long before its first row (``round(backfill_seconds x
    fps)`` frames: 20 at 15 fps), at the velocity of its first 8 rows, while the object stays in view (``min_in_image``)
    and no other track stands on its footprint (0: off; ``tracks_all.csv`` keeps the tracker's own rows; the added rows
    have ``existence`` 0), seconds. Beyond the paper: the filter reports an object some frames after it came into view
    (eq. 11 needs enough uncovered pixels and the new object must win ``min_existence`` of the weight), late when it
    enters behind an occluder or in clothes the masks half miss; once the whole recording is tracked, those frames are
    known to have held it. 20 frames and 15 rows were chosen on scene seeds 0-5 (15 fps, tracker seeds 0-2, both mask
    kinds; 10, 20 and 30 frames, 0 and 15 rows compared): s3-people accuracy 0.60 -> 0.71 (offline masks) and 0.87 ->
    0.94 (perfect), no scene worse. The horizon is a time because the extrapolation's error grows with time
    (docs/notes.md, round seven). Extending forwards was tried and not kept (s3-cars MOTA fell: hypotheses that
    died on a confusion were prolonged)."""
    backfill_min_frames: int = param(15, help="backfill only tracks with at least this many rows", units="rows", lo=1)
    """Tracks with fewer rows than this in ``tracks.csv`` are not backfilled (``backfill_seconds``): short tracks
    are more often hypotheses added on the wrong thing (a human on the edge of a car) whose extension only adds
    false positives."""
    stitch_seconds: float = param(
        2.0,
        help="when the run completes, a track that starts up to this long after another ended, where that one was "
        "heading, takes its id (0: off)",
        units="s",
        lo=0.0,
    )
    """Offline stitching (``wptrack.trackers.templates.backfill.stitch_tracks_file``), after the backfill: a track that
    ends and one of the same class that starts at most this long later (``round(stitch_seconds x fps)`` frames: 30 at 15
    fps) within ``stitch_distance`` of where the first was heading (its last position moved on at the velocity of its
    last 8 rows) get the first one's id, nearest pairs first (0: off), seconds. Beyond the paper: the filter loses an
    object now and then (eq. 13 deletes it, or a neighbour's hypothesis takes its pixels) and adds it again under a new
    label, an identity switch that the completed run can see. Chosen on scene seeds 0-5 (tracker seeds 0-2, both mask
    kinds; 2 and 4 s, 1 and 2 m compared): s3-groups IDF1 0.793 -> 0.820 and id switches 5.2 -> 3.8 per run (offline
    masks), s3-mixed IDF1 0.844 -> 0.885, no scene worse (docs/notes.md, round seven)."""
    stitch_distance: float = param(
        2.0, help="largest distance from where the ended track was heading", units="m", lo=0.0
    )
    smooth_seconds: float = param(
        1.0,
        help="when the run completes, smooth each track's positions over +- this long (0: off)",
        units="s",
        lo=0.0,
    )
    """Offline smoothing (``wptrack.core.smoothing``), after the backfill and the stitching: each track's positions
    (``x, y, z, gx, gy``) become a weighted line's over +- this long at each row (LOESS of degree 1, tricube weights;
    ``round(smooth_seconds x fps)`` frames), so the jitter of a filtered estimate is averaged with the frames after
    it, which the online filter had not seen; a constant-velocity walk is kept as it is (0: off; ``tracks_all.csv``
    keeps the tracker's own rows), seconds. Beyond the paper. Measured on the outputs of existing runs (2026-11-27,
    tracker seeds 0-5 on the real clips, 0-2 on the held-out scenes), MOTA without / 1 s / 1.5 s: TownCentre 0.480 /
    0.506 / 0.520, PETS 0.873 / 0.882 / 0.885, ``s3-mixed`` 0.894 / 0.912 / 0.912, ``s3-groups`` 0.589 / 0.593 / 0.594,
    ``s3-people`` 0.845 throughout, ``s3-cars`` 0.782 / 0.781 / 0.781. A window longer than 1 s cuts the corners of
    turning objects: ``s3-cars`` HOTA 0.534 / 0.536 / 0.512 (localisation), the people tracker's office 0.714 / 0.736
    / 0.695; so 1 s, whatever the real clips' MOTA would gain beyond it (docs/notes.md)."""
    partition: bool = param(
        True,
        help="resample independent groups of objects apart (off: the paper's joint filter, one weight per particle)",
        negative="joint",
    )
    """Resample independent groups of objects apart (``kernels.templates.partition``; false: the paper's joint filter,
    one weight per particle). Objects whose image boxes (over all particles) are a column apart or more explain disjoint
    pixels, so the weight of eq. 6 is a product of one factor per group; each group of slots is resampled on its own
    factor, and particle j takes each group's objects from that group's ancestor (an independent partition particle
    filter). Beyond the paper: with one weight for a whole scene of R objects the particles' diversity per object
    collapses as R grows (on the PETS clip 10,000 joint particles scored MOTA 0.50 where 1,000 scored 0.14 on the same
    masks); objects that interact (overlapping boxes) stay in one group, resampled jointly. Needs ``ess_threshold`` 1
    (every group is resampled every frame)."""
    min_candidate_area: int = param(30, help="smallest candidate silhouette", units="px", lo=1)
    min_existence: float = param(
        0.5,
        help="objects are reported when the weight of the particles holding them reaches this fraction",
        lo=0.0,
        hi=1.0,
    )
    min_in_image: float = param(
        0.9,
        help="objects are reported with at least this fraction of their image box inside the image (0: all)",
        lo=0.0,
        hi=1.0,
    )
    """Objects are reported when at least this fraction of their image bounding box (the box around the image of
    their 3D bounding box: a vehicle's length x width x height, a human's body diameter square x height) lies inside
    the image (0: wherever they are). The particles hold an object that has left the view until eq. 13 deletes it
    (no pixel contradicts it there) and one that is entering from its first pixels; neither is in view in the sense
    of a labelled ground truth. 0.9 is how the real clips were labelled (people nearly whole in view: 97.5 % of
    TownCentre's labelled bodies have >= 0.9 of their box inside the image, every PETS S2.L1 box lies whole inside)
    and the convention of our synthetic ground truth (``wptrack.synth.plaza_background.MIN_IN_IMAGE``, the same box).
    Measured (2026-11-27, docs/notes.md): TownCentre tracker seeds 0-2 MOTA 0.547 / 0.560 / 0.583 / 0.608 / 0.625 /
    0.632 at 0.25 / 0.5 / 0.6 / 0.75 / 0.9 / 1.0 (the people at the far end whose heads the image's top edge cuts
    are not labelled), PETS 0.875 / 0.885 / 0.888 / 0.892 / 0.893 / 0.892 (people walking in from the borders are
    labelled once in view). Set 0 when your labels include objects mostly outside the image, 0.25 for labels from a
    quarter in view. Only the report (and the backfill's view test) changes: the particles keep every object."""
    resampling: str = param("systematic", help="resampling scheme", choices=SCHEMES)
    ess_threshold: float = param(
        1.0,
        help="resample when ESS <= this fraction of N (1: every frame, as in the paper)",
        lo=0.0,
        hi=1.0,
        lo_open=True,
    )
    seed: int = param(0, help="seed of the counter-based random streams", lo=0, hi=2**64 - 1)

    def __post_init__(self) -> None:
        if isinstance(self.camera, (int, np.integer)) and not isinstance(self.camera, bool):
            object.__setattr__(self, "camera", str(int(self.camera)))  # an index, as the command line gives it
        check(self)
        if not isinstance(self.human, HumanPrior):
            raise ConfigError("human: expected a HumanPrior")
        if not isinstance(self.vehicle, VehiclePrior):
            raise ConfigError("vehicle: expected a VehiclePrior")
        if not isinstance(self.cyclist, CyclistPrior):
            raise ConfigError("cyclist: expected a CyclistPrior")
        if not self.classes or len(set(self.classes)) != len(self.classes):
            raise ConfigError(f"classes: expected a non-empty subset of {list(CLASSES)}, got {list(self.classes)}")
        if self.partition and self.ess_threshold < 1.0:
            raise ConfigError(
                f"ess_threshold {self.ess_threshold}: the partitioned filter (partition: true) resamples every group "
                "every frame; use ess_threshold 1, or partition false for the joint filter with an ESS trigger"
            )

    @property
    def frame_rate(self) -> float:
        """``fps``, or 15 frames/s when it is not given (the tracker's Delta t = 1 / frame_rate)."""
        return 15.0 if self.fps is None else float(self.fps)

    @property
    def camera_key(self) -> int | str:
        """The rig camera: its index when ``camera`` is a number, else its name."""
        return int(self.camera) if self.camera.isdigit() else self.camera

    @property
    def backfill_frames(self) -> int:
        """``backfill_seconds`` in frames at ``fps``."""
        return int(round(self.backfill_seconds * self.frame_rate))

    @property
    def stitch_frames(self) -> int:
        """``stitch_seconds`` in frames at ``fps``."""
        return int(round(self.stitch_seconds * self.frame_rate))

    @property
    def smooth_frames(self) -> int:
        """``smooth_seconds`` in frames at ``fps``."""
        return int(round(self.smooth_seconds * self.frame_rate))

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python form (run.json)."""
        d = asdict(self)
        d["classes"] = list(self.classes)
        return d


@dataclass
class TrackedObject:
    """One object of the estimate (world frame and ground-plane coordinates; metres, radians, seconds)."""

    id: int
    """Persistent label."""
    cls: str
    """``"human"``, ``"vehicle"`` or ``"cyclist"``."""
    position: np.ndarray
    """(3,) ground-contact point in world coordinates, metres."""
    ground: np.ndarray
    """(2,) ground-plane coordinates, metres."""
    dims: np.ndarray
    """(3,) human (height, body radius, head radius) or vehicle and cyclist (length, width, height), metres."""
    heading: float
    """Direction of motion (vehicle: orientation towards its motion) in the ground plane, radians."""
    speed: float
    """m/s."""
    existence: float = 1.0
    """Weight of the particles that hold the object (1 for the best particle's objects)."""
    in_image: float = 1.0
    """Fraction of the object's image bounding box inside the image (``TemplateConfig.min_in_image``; not computed for
    the best particle's objects, which are not filtered: 1)."""
    std: np.ndarray = field(default_factory=lambda: np.zeros(2))
    """(2,) spread of the ground position over the particles, metres."""
    age: float = 0.0
    """Mean time the object has been tracked, seconds."""

    @property
    def size(self) -> tuple[float, float, float]:
        """(length, width, height) in metres (a human's length and width are the body diameter)."""
        if self.cls == "human":
            return (2 * float(self.dims[1]), 2 * float(self.dims[1]), float(self.dims[0]))
        return (float(self.dims[0]), float(self.dims[1]), float(self.dims[2]))


@dataclass
class TemplateEstimate:
    """The tracker's output for one frame."""

    frame: int
    objects: list[TrackedObject]
    """Objects whose existence >= min_existence and with >= min_in_image of their image box in the image, by id."""
    best: list[TrackedObject]
    """The objects of the best (MAP) particle."""
    penalty: int
    """XOR matching penalty m of the best particle, pixels (eq. 4)."""
    foreground: int
    """|q|: foreground pixels of the motion mask."""
    ess: float
    loglik: float
    added: tuple[int, str] | None
    """(label, class) of the object proposed to the particles after this frame, if any."""
    virtual: np.ndarray | None = None
    """(H, W) uint8 virtual scene of the best particle: 0 background, 1 + slot of the nearest object."""
    uoh: np.ndarray | None = None
    """(H, W) int32 Uncovered Object Histogram (eq. 10), when requested."""
    degenerate: bool = False
    """Every particle's log-weight was -inf or NaN (floored to ``kernels.core.reduce.LOGW_FLOOR``): the frame kept the
    predicted particles with uniform weights (the prior) and its estimate is the prior's; ``loglik`` is the floor."""
    groups: int = 1
    """Independent groups of objects resampled apart after this frame (``TemplateConfig.partition``; the joint
    filter of the paper: 1)."""
    timings: dict[str, float] = field(default_factory=dict)
