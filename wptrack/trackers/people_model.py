"""Configuration of the S2 multi-camera people tracker (Lopez-Cifuentes et al., "multi-camera 3D particle filters
with motion and colour"): frozen dataclasses, validated on construction, with the paper's symbols and units.

The paper fixes few numbers: N_S = 500 particles per target, P_H = 0.95, alpha "close to zero", p_B "a positive
value close to 0". Every other default here is this project's choice (marked "ours"), not the paper's.
The kernels these parameters feed are in ``kernels/people.py``, ``kernels/descriptor.py`` and ``kernels/occupancy.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..errors import ConfigError

OUTSIDE_MODES = ("background", "neutral")


def _number(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{name}: expected a finite number, got {value!r}")
    return float(value)


def _positive(value: object, name: str, what: str) -> None:
    if _number(value, name) <= 0:
        raise ConfigError(f"{name}: expected {what} > 0, got {value!r}")


def _non_negative(value: object, name: str, what: str) -> None:
    if _number(value, name) < 0:
        raise ConfigError(f"{name}: expected {what} >= 0, got {value!r}")


def _open_fraction(value: object, name: str, what: str) -> None:
    v = _number(value, name)
    if not (0.0 < v < 1.0):
        raise ConfigError(f"{name}: expected {what} in (0, 1), got {value!r}")


def _int_at_least(value: object, name: str, lo: int, what: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ConfigError(f"{name}: expected {what}, an integer >= {lo}, got {value!r}")


@dataclass(frozen=True)
class DynamicsConfig:
    """Particle dynamics (section 2.1) in metres and seconds, so that one configuration works at any frame rate.

    Eq. 5 with the frame interval dt (seconds) made explicit: P_t = P_{t-1} + dt Pdot_{t-1} + n_P, Pdot_t = Pdot_{t-1}
    + n_V, velocity in metres per second. The noises are random walks: their per-frame deviations grow with sqrt(dt),
    so the spread they add over one second is the same at 3 and at 25 frames/s.

    Attributes:
        sigma_pos: position noise n_P per axis, metres per sqrt(second) (per frame: sigma_pos sqrt(dt)). Ours: 0.15
            (0.03 m per frame at 25 frames/s, the value the synthetic office was built with).
        sigma_vel: horizontal velocity noise n_V per axis, metres per second per sqrt(second) (per frame: sigma_vel
            sqrt(dt)). Ours: 0.5 (a walker's velocity changes by about 0.5 m/s in a second; the office was built
            with 1.25, 0.01 m per frame per frame at 25 frames/s, which lets the filters of people on real footage
            wander: terrace MOTA 0.05 against 0.24, seed 0).
        sigma_vel_z: vertical velocity noise, same units. Ours: 1.25 (the office's value: a person does not move up
            or down, but its particles must keep mixing over the body's height; with 0.5 their mean sat 0.3 m
            higher).
        alpha: forgetting factor of the appearance update C_t = alpha A_{t-1} + (1 - alpha) C_{t-1} (eq. 6) per
            ``alpha_interval`` seconds; the paper asks for a value close to zero. At a frame interval dt the factor
            is 1 - (1 - alpha)^(dt / alpha_interval), so the appearance's memory is the same time at any frame rate.
            Ours: 0.05. Must lie in [0, 1).
        alpha_interval: the interval ``alpha`` is given for, seconds. Ours: 0.04 (one frame at 25 frames/s).
    """

    sigma_pos: float = 0.15
    sigma_vel: float = 0.5
    sigma_vel_z: float = 1.25
    alpha: float = 0.05
    alpha_interval: float = 0.04

    def __post_init__(self) -> None:
        _positive(self.sigma_pos, "dynamics.sigma_pos", "a position noise in metres per sqrt(second)")
        _non_negative(self.sigma_vel, "dynamics.sigma_vel", "a velocity noise in metres/second per sqrt(second)")
        _non_negative(self.sigma_vel_z, "dynamics.sigma_vel_z", "a velocity noise in metres/second per sqrt(second)")
        a = _number(self.alpha, "dynamics.alpha")
        if not (0.0 <= a < 1.0):
            raise ConfigError(f"dynamics.alpha: expected a forgetting factor in [0, 1), got {self.alpha!r}")
        _positive(self.alpha_interval, "dynamics.alpha_interval", "an interval in seconds")

    def per_frame(self, dt: float) -> tuple[float, tuple[float, float], float]:
        """``(sigma_pos, (sigma_vel, sigma_vel_z), alpha)`` of one frame interval ``dt`` (seconds): metres,
        metres/second and the factor of eq. 6."""
        root = math.sqrt(dt)
        alpha = 1.0 - (1.0 - self.alpha) ** (dt / self.alpha_interval)
        return self.sigma_pos * root, (self.sigma_vel * root, self.sigma_vel_z * root), alpha


@dataclass(frozen=True)
class MotionConfig:
    """Motion-segmentation observation (section 2.2).

    Attributes:
        p_b: background probability p_B (eq. 10): the likelihood factor of a camera whose mask shows no motion at the
            projection (1 - p_B where it does). Ours: 0.05.
        outside: what a camera that does not see the particle contributes: ``background`` = p_B (eq. 10 literally:
            no motion was observed there), ``neutral`` = 1 (the camera says nothing).
        drop_worst: with three or more cameras, leave out the least supporting camera's factor (ours, beyond eq. 9:
            a person's legs hidden by furniture in one camera keep the other cameras' support, so the particles fill
            the whole person and the centroid is not pushed up to what every camera sees). False: eq. 9 as printed.
    """

    p_b: float = 0.05
    outside: str = "background"
    drop_worst: bool = True

    def __post_init__(self) -> None:
        v = _number(self.p_b, "motion.p_b")
        if not (0.0 < v < 0.5):
            raise ConfigError(f"motion.p_b: expected a background probability in (0, 0.5), got {self.p_b!r}")
        if self.outside not in OUTSIDE_MODES:
            raise ConfigError(f"motion.outside: expected one of {', '.join(OUTSIDE_MODES)}, got {self.outside!r}")

    @property
    def log_outside(self) -> float:
        """The ``log_outside`` argument of ``kernels.people.motion_kernel``."""
        return math.log(self.p_b) if self.outside == "background" else 0.0


@dataclass(frozen=True)
class DescriptorConfig:
    """3D colour descriptor (section 3.2) and appearance probability (section 3.3).

    Attributes:
        r_n: radius r_N of the spherical neighbourhood N_P (eq. 19), metres. Ours: 0.10.
        n_bins: bins N_b of each of the H, S and V histograms (eq. 20). Ours: 8.
        r_min: smallest projected disc radius r_i, pixels (a far sphere still covers the nearest pixels). Ours: 1.
        r_max: largest projected disc radius r_i, pixels (bounds the cost: ~pi r_max^2 pixels per camera and
            particle). Ours: 12.
        sigma_p: deviation sigma_p of the appearance probability (eq. 26), dimensionless (M lies in [0, 1]).
            Ours: 0.2.
        step: pixel stride of the disc's samples (1: every pixel of the disc, eq. 20 exactly; 2: one pixel in
            four, each weighted for four: the same Gaussian-weighted histogram by quadrature, a quarter of the
            cost). Ours: 2.
    """

    r_n: float = 0.10
    n_bins: int = 8
    r_min: float = 1.0
    r_max: float = 12.0
    sigma_p: float = 0.2
    step: int = 2

    def __post_init__(self) -> None:
        _positive(self.r_n, "descriptor.r_n", "a neighbourhood radius in metres")
        _int_at_least(self.n_bins, "descriptor.n_bins", 2, "a bin count")
        if self.n_bins > 16:
            raise ConfigError(f"descriptor.n_bins: at most 16 bins per histogram, got {self.n_bins}")
        _positive(self.r_min, "descriptor.r_min", "a disc radius in pixels")
        _positive(self.r_max, "descriptor.r_max", "a disc radius in pixels")
        if self.r_max < self.r_min:
            raise ConfigError(f"descriptor.r_max: expected >= r_min ({self.r_min!r}), got {self.r_max!r}")
        _positive(self.sigma_p, "descriptor.sigma_p", "an appearance deviation")
        _int_at_least(self.step, "descriptor.step", 1, "a pixel stride")


@dataclass(frozen=True)
class OccupancyConfig:
    """Volumetric occupancy pdf (eqs. 2-3; the 3D Gaussian kernel of Figs. 6 and 8) and the bounding volume.

    Attributes:
        sigma: deviation of the 3D Gaussian kernel per particle, metres. Ours: 0.10.
        cutoff: truncation radius of the kernel, in units of sigma. Ours: 3.
        voxel: edge of the output voxels, metres. Ours: 0.1 (people are ~0.5 m wide: 5 voxels).
        extent: size of the grid around each person (x, y, z), metres. Ours: 1.2 x 1.2 x 2.2.
        p_h: probability P_H that the bounding volume V_k must contain (section 4: 0.95).
    """

    sigma: float = 0.10
    cutoff: float = 3.0
    voxel: float = 0.1
    extent: tuple[float, float, float] = (1.2, 1.2, 2.2)
    p_h: float = 0.95

    def __post_init__(self) -> None:
        _positive(self.sigma, "occupancy.sigma", "a kernel deviation in metres")
        _positive(self.cutoff, "occupancy.cutoff", "a cutoff in kernel deviations")
        _positive(self.voxel, "occupancy.voxel", "a voxel edge in metres")
        if len(self.extent) != 3:
            raise ConfigError(f"occupancy.extent: expected (x, y, z) metres, got {self.extent!r}")
        for v in self.extent:
            _positive(v, "occupancy.extent", "a size in metres")
        _open_fraction(self.p_h, "occupancy.p_h", "a probability")


@dataclass(frozen=True)
class BirthConfig:
    """How people appear and leave (ours: the paper tracks a known set of people and does not say).

    The evidence map is a ground grid over the working area where each cell holds, per camera, the coverage of the
    rectangle of a person standing there by the motion nobody tracked explains (the masks less the tracked people's
    rectangles: ``kernels.coverage``, in the spirit of POM, Fleuret et al. PAMI 2008). A person is added where every
    camera that sees a cell (at least ``min_cameras`` of them) finds more of that motion than an empty rectangle
    would hold (its term of :class:`PersonConfig` is positive), for ``add_seconds``; a person the masks do not show
    (``PersonEstimate.support`` not above ``PersonConfig.gate``) for ``remove_seconds``, or who leaves the ground the
    cameras see, is removed. A person removed for lack of support may come back with its id (``reid_seconds``).

    Attributes:
        cell: ground grid pitch of the evidence map, metres. Ours: 0.1.
        min_cameras: cameras that must see a cell for a birth there (at least 2, and at most the rig's cameras).
            Ours: 2.
        exclusion: no birth within this distance of a tracked person (ground plane), metres. Ours: 0.7.
        min_area: connected cells of evidence needed for a birth, cells. Ours: 4.
        add_seconds: unexplained evidence near the same place for this long before adding, seconds. Ours: 0.12 (3
            frames at 25 frames/s; at least one frame at any rate).
        remove_seconds: not seen for this long before removing, seconds. Ours: 1 (a filter that no longer sees its
            person soon holds somebody else's place; the person comes back with its id, ``reid_seconds``).
        hold_seconds: the same for a person the masks lost while it stood still (slower than 0.3 m/s over the last
            second): a person standing and talking fades from the background model's masks, it has not left, and
            its filter holds its place (the gate stops the weighting), seconds. Ours: 10.
        init_radius: radius of the cylinder a new person's particles start in, metres. Ours: 0.25.
        init_z: heights of that cylinder, metres. Ours: (0.3, 1.6).
        init_speed: deviation of its particles' horizontal velocities per axis, metres per second (where a newcomer
            walks is unknown; the first frames' weights pick it). Ours: 0, at rest: 1 follows a newcomer at 5
            frames/s from its first second, but on the terrace (25 and 3 frames/s) the spread-out newcomers lost
            their people more often (MOTA 0.04 / -0.32 against 0.18 / -0.15, seeds 0-1).
        merge_distance: two people whose ground positions stay closer than this for ``remove_seconds``
            follow one person: the younger is removed, metres. Ours: 0.3 (people shaking hands stand ~0.6 m apart).
        max_people: people tracked at once (a pool of filters allocated once). Ours: 8.
        reid_seconds: a person removed for lack of support is remembered this long: a person added later within
            reach of where it was lost (1 m + 1.5 m/s of the time since) whose appearance is similar enough takes its
            id again (re-identification after an occlusion), seconds (0: never). Ours: 10.
        reid_similarity: the smallest appearance similarity for that (the mean Bhattacharyya coefficient of the
            hue, saturation and value histograms of the legs and the torso, ``kernels.coverage``), in (0, 1]. Ours:
            0.8.
        appearance_seconds: memory of a person's appearance histograms (an exponential average over the frames
            where enough of its pixels are its own), seconds. Ours: 3.

    At most one person is added per frame (the strongest unexplained region): the motion the new person explains
    is discounted from the next frame on, so the ghosts that two real people's silhouettes make where other
    cameras' rays cross are not added as people.
    """

    cell: float = 0.1
    min_cameras: int = 2
    exclusion: float = 0.7
    min_area: int = 4
    add_seconds: float = 0.12
    remove_seconds: float = 1.0
    hold_seconds: float = 10.0
    init_radius: float = 0.25
    init_z: tuple[float, float] = (0.3, 1.6)
    init_speed: float = 0.0
    merge_distance: float = 0.3
    max_people: int = 8
    reid_seconds: float = 10.0
    reid_similarity: float = 0.8
    appearance_seconds: float = 3.0

    def __post_init__(self) -> None:
        _positive(self.cell, "birth.cell", "a grid pitch in metres")
        _int_at_least(self.min_cameras, "birth.min_cameras", 1, "a camera count")
        _positive(self.exclusion, "birth.exclusion", "a distance in metres")
        _int_at_least(self.min_area, "birth.min_area", 1, "a cell count")
        _non_negative(self.add_seconds, "birth.add_seconds", "a time in seconds")
        _non_negative(self.remove_seconds, "birth.remove_seconds", "a time in seconds")
        _non_negative(self.hold_seconds, "birth.hold_seconds", "a time in seconds")
        _positive(self.init_radius, "birth.init_radius", "a radius in metres")
        if len(self.init_z) != 2 or not (
            0 <= _number(self.init_z[0], "birth.init_z") < _number(self.init_z[1], "birth.init_z")
        ):
            raise ConfigError(f"birth.init_z: expected (low, high) heights in metres, low < high, got {self.init_z!r}")
        _non_negative(self.init_speed, "birth.init_speed", "a speed deviation in metres/second")
        _non_negative(self.merge_distance, "birth.merge_distance", "a distance in metres")
        _int_at_least(self.max_people, "birth.max_people", 1, "a number of people")
        _non_negative(self.reid_seconds, "birth.reid_seconds", "a time in seconds")
        v = _number(self.reid_similarity, "birth.reid_similarity")
        if not (0.0 < v <= 1.0):
            raise ConfigError(f"birth.reid_similarity: expected a similarity in (0, 1], got {self.reid_similarity!r}")
        _positive(self.appearance_seconds, "birth.appearance_seconds", "a time in seconds")


@dataclass(frozen=True)
class PersonConfig:
    """The whole person beyond its particles (ours; ``kernels/coverage.py``): the image rectangle of a standing
    person, as in the Probabilistic Occupancy Map of Fleuret, Berclaz, Lengagne and Fua (PAMI 2008, section 4.2), and
    how it enters each particle's weight.

    A particle's log-weight gets, per camera that sees the rectangle of a person standing at the particle's ground
    position, the log-likelihood ratio of "a person here" (each rectangle pixel on the motion mask with probability
    ``p_person``) against "nobody" (``p_empty``) summed over the rectangle's pixels and divided by ``pixels`` (one
    independent sample per ``pixels`` pixels: mask pixels come in blobs), and a penalty when it lies within
    ``exclusion_radius`` of another tracked person.

    Attributes:
        half_width: half the rectangle's width across the viewing direction, metres. Ours: 0.25 (POM: 0.5 m wide).
        height: the rectangle's height, metres. Ours: 1.75 (POM's average human).
        min_visible: a camera sees a rectangle when this fraction of it is inside its image. Ours: 0.5.
        p_person: fraction of a person's rectangle that the motion masks cover. Ours: 0.35 (a person fills about
            half of the rectangle and the masks of real footage find part of that).
        p_empty: fraction of an empty rectangle that the masks cover. Ours: 0.05.
        pixels: pixels per independent sample of the rectangle term (0: the term is off, the paper's per-point
            likelihood alone). Ours: 100 (a person's rectangle at 5-10 m in a 360 x 288 image holds 2000-6000 pixels:
            20-60 samples).
        exclusion_radius: two people's ground positions closer than this repel, metres. Ours: 0.4.
        exclusion_weight: the penalty at distance 0, nats (0: off). Ours: 5.
        gate: a frame's masks show a person when they cover more than this fraction of its rectangle (of what the
            other people's rectangles leave of it, the cameras that see it together) somewhere near its last position
            (within ``gate_reach`` plus a walk of one frame interval at 1.5 m/s); otherwise the filter predicts
            without weighting (a person the background model absorbed while standing, or hidden, is not pulled onto
            the nearest other silhouette) and, after ``BirthConfig.remove_seconds``, is removed. Ours: 0.2 (the
            rectangle term is positive above 0.16 with the default ``p_person`` and ``p_empty``; the terrace's masks
            cover a walking person's rectangle 0.28-0.35 in the median).
        gate_reach: see ``gate``, metres. Ours: 0.25.
        gate_left: and only where the others leave at least this fraction of the rectangle (a person hidden behind
            others is not judged on a sliver). Ours: 0.25.
        stop_seconds: an unseen person's velocity decays with this time constant, seconds (people stop more
            often than they walk on unseen). Ours: 1.
    """

    half_width: float = 0.25
    height: float = 1.75
    min_visible: float = 0.5
    p_person: float = 0.35
    p_empty: float = 0.05
    pixels: float = 100.0
    exclusion_radius: float = 0.4
    exclusion_weight: float = 5.0
    gate: float = 0.2
    gate_reach: float = 0.25
    gate_left: float = 0.25
    stop_seconds: float = 1.0

    def __post_init__(self) -> None:
        _positive(self.half_width, "person.half_width", "a half width in metres")
        _positive(self.height, "person.height", "a height in metres")
        v = _number(self.min_visible, "person.min_visible")
        if not (0.0 < v <= 1.0):
            raise ConfigError(f"person.min_visible: expected a fraction in (0, 1], got {self.min_visible!r}")
        _open_fraction(self.p_person, "person.p_person", "a probability")
        _open_fraction(self.p_empty, "person.p_empty", "a probability")
        if self.p_empty >= self.p_person:
            raise ConfigError(f"person.p_empty: expected < p_person ({self.p_person!r}), got {self.p_empty!r}")
        _non_negative(self.pixels, "person.pixels", "a weight in pixels")
        _positive(self.exclusion_radius, "person.exclusion_radius", "a distance in metres")
        _non_negative(self.exclusion_weight, "person.exclusion_weight", "a penalty in nats")
        _open_fraction(self.gate, "person.gate", "a coverage fraction")
        _open_fraction(self.gate_left, "person.gate_left", "a fraction of the rectangle")
        _non_negative(self.gate_reach, "person.gate_reach", "a distance in metres")
        _positive(self.stop_seconds, "person.stop_seconds", "a time in seconds")

    @property
    def slope_offset(self) -> tuple[float, float]:
        """``(slope, offset)`` of ``kernels.coverage.box_log_likelihood``: log(p1 (1 - p0) / (p0 (1 - p1))) /
        ``pixels`` and -log((1 - p1) / (1 - p0)) / ``pixels`` (both 0 when ``pixels`` is 0: the term is off)."""
        p1, p0, k = self.p_person, self.p_empty, self.pixels
        if k == 0:
            return 0.0, 0.0
        return math.log(p1 * (1 - p0) / (p0 * (1 - p1))) / k, -math.log((1 - p1) / (1 - p0)) / k


@dataclass(frozen=True)
class AreaConfig:
    """The working area when the rig has no ``volume`` (ours; ``wptrack.trackers.people_area``): the ground seen by
    ``min_cameras`` cameras, from the calibration.

    Attributes:
        min_cameras: cameras that must see a ground point for it to be in the area (at most the rig's cameras).
            Ours: 2 (people are added where two views agree).
        person_height: height of the standing person whose visibility decides, metres. Ours: 1.7.
        min_visible: fraction of the person's vertical axis that must project inside a camera's image for the
            camera to see the point (a person cut by the image border is still tracked). Ours: 0.5.
        min_person_px: a camera sees a point only where that person would be at least this tall in its image,
            pixels: the area ends where people become too small to track. Ours: 30.
        max_distance: and only within this ground distance of the camera, metres. Ours: 50.
        cell: resolution of the area, metres. Ours: 0.25.
    """

    min_cameras: int = 2
    person_height: float = 1.7
    min_visible: float = 0.5
    min_person_px: float = 30.0
    max_distance: float = 50.0
    cell: float = 0.25

    def __post_init__(self) -> None:
        _int_at_least(self.min_cameras, "area.min_cameras", 1, "a camera count")
        _positive(self.person_height, "area.person_height", "a height in metres")
        v = _number(self.min_visible, "area.min_visible")
        if not (0.0 < v <= 1.0):
            raise ConfigError(f"area.min_visible: expected a fraction in (0, 1], got {self.min_visible!r}")
        _positive(self.min_person_px, "area.min_person_px", "a height in pixels")
        _positive(self.max_distance, "area.max_distance", "a distance in metres")
        _positive(self.cell, "area.cell", "a cell size in metres")


CENTROID_MODES = ("standing", "particles")


@dataclass(frozen=True)
class BodyConfig:
    """The person's 3D centroid (ours, beyond the paper).

    The paper's estimate is the mean of the particles, which fill the part of the person that the cameras see
    moving: when furniture hides the legs in every camera, that mean rises towards the chest. With ``standing``, the
    centroid keeps the particles' ground position (x, y) and takes its height from a standing-person model: the top
    of the person's silhouette column (the highest point on the person's axis seen moving by ``min_cameras``
    cameras, from the masks) times ``ratio``, the height of the centre of mass of a standing adult as a fraction of
    stature (about 0.55: D. A. Winter, *Biomechanics and Motor Control of Human Movement*, anthropometric tables).
    ``particles`` is the paper's estimate. tracks.csv carries both (``z`` and ``cloud_z``) and the top (``top``).

    Attributes:
        centroid: ``standing`` or ``particles``.
        ratio: centre-of-mass height / stature. Ours: 0.55 (Winter).
        step: vertical step of the column search, metres. Ours: 0.02.
        max_gap: holes in the masks bridged on the way up, metres. Ours: 0.1.
        min_cameras: cameras that must see a column point moving (at most the rig's cameras). Ours: 2.
        search: the column is also searched this far around the estimated ground position (a 3 x 3 grid of axes,
            the highest top wins), metres. Ours: 0.08.
    """

    centroid: str = "standing"
    ratio: float = 0.55
    step: float = 0.02
    max_gap: float = 0.1
    min_cameras: int = 2
    search: float = 0.08

    def __post_init__(self) -> None:
        if self.centroid not in CENTROID_MODES:
            raise ConfigError(f"body.centroid: expected one of {', '.join(CENTROID_MODES)}, got {self.centroid!r}")
        _open_fraction(self.ratio, "body.ratio", "a fraction of the stature")
        _positive(self.step, "body.step", "a step in metres")
        _non_negative(self.max_gap, "body.max_gap", "a gap in metres")
        _int_at_least(self.min_cameras, "body.min_cameras", 1, "a camera count")
        _non_negative(self.search, "body.search", "a distance in metres")


@dataclass(frozen=True)
class PeopleConfig:
    """The S2 tracker's parameters.

    Attributes:
        particles: particles per tracked person [N_S] (section 4: 500).
        seed: seed of the counter-based random streams (same seed + device -> identical output).
        fps: frame rate of the recording, frames per second (the frame interval dt = 1 / fps of the dynamics and of
            every time in seconds). None: the recording's own (the videos' frame rate in a run; ``--fps`` for image
            folders); a :class:`~wptrack.trackers.people.PeopleTracker` built without one assumes 25 frames/s.
            ``PeopleTracker.step(..., timestamp=...)`` takes dt from the frames' timestamps instead.
        dynamics, motion, descriptor, occupancy, birth, body, person, area: the sections above.

    Resampling runs every frame (section 2.1: "particle resampling should be performed at each time step").
    """

    particles: int = 500
    seed: int = 0
    fps: float | None = None
    dynamics: DynamicsConfig = field(default_factory=DynamicsConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    descriptor: DescriptorConfig = field(default_factory=DescriptorConfig)
    occupancy: OccupancyConfig = field(default_factory=OccupancyConfig)
    birth: BirthConfig = field(default_factory=BirthConfig)
    body: BodyConfig = field(default_factory=BodyConfig)
    person: PersonConfig = field(default_factory=PersonConfig)
    area: AreaConfig = field(default_factory=AreaConfig)

    def __post_init__(self) -> None:
        _int_at_least(self.particles, "particles", 1, "a particle count")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not (0 <= self.seed < 2**64):
            raise ConfigError(f"seed: expected an integer in [0, 2^64), got {self.seed!r}")
        if self.fps is not None:
            _positive(self.fps, "fps", "a frame rate in frames per second")
        for name, cls in (
            ("dynamics", DynamicsConfig),
            ("motion", MotionConfig),
            ("descriptor", DescriptorConfig),
            ("occupancy", OccupancyConfig),
            ("birth", BirthConfig),
            ("body", BodyConfig),
            ("person", PersonConfig),
            ("area", AreaConfig),
        ):
            if not isinstance(getattr(self, name), cls):
                raise ConfigError(f"{name}: expected a {cls.__name__}, got {type(getattr(self, name)).__name__}")
