"""Configuration of the S2 multi-camera people tracker (Lopez-Cifuentes et al., "multi-camera 3D particle filters
with motion and colour"): frozen dataclasses, validated on construction, with the paper's symbols and units.

The paper fixes few numbers: N_S = 500 particles per target, P_H = 0.95, alpha "close to zero", p_B "a positive
value close to 0". Every other default here is this project's choice (marked "ours"), not the paper's.
The kernels these parameters feed are in ``kernels/people/filter.py``, ``kernels/people/descriptor.py`` and
``kernels/people/occupancy.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wptrack.core.config import param
from wptrack.core.errors import ConfigError

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
    """Particle dynamics (section 2.1).

    Attributes:
        sigma_pos: deviation of the position noise n_P per axis (eq. 5), metres per frame. Ours: 0.03.
        sigma_vel: deviation of the velocity noise n_V per axis (eq. 5), metres per frame per frame. Ours: 0.01.
        alpha: forgetting factor of the appearance update C_t = alpha A_{t-1} + (1 - alpha) C_{t-1} (eq. 6);
            the paper asks for a value close to zero. Ours: 0.05. Must lie in [0, 1).
    """

    sigma_pos: float = param(
        0.03,
        help="deviation of the position noise n_P per axis (eq. 5), per frame",
        units="m",
        lo=0.0,
        lo_open=True,
        flag="sigma-pos",
    )
    sigma_vel: float = param(
        0.01,
        help="deviation of the velocity noise n_V per axis (eq. 5), per frame",
        units="m/frame",
        lo=0.0,
        flag="sigma-vel",
    )
    alpha: float = param(
        0.05,
        help="forgetting factor of the appearance update (eq. 6), close to zero",
        symbol="alpha",
        lo=0.0,
        hi=1.0,
        hi_open=True,
        flag="alpha",
    )

    def __post_init__(self) -> None:
        _positive(self.sigma_pos, "dynamics.sigma_pos", "a position noise deviation in metres")
        _non_negative(self.sigma_vel, "dynamics.sigma_vel", "a velocity noise deviation in metres/frame")
        a = _number(self.alpha, "dynamics.alpha")
        if not (0.0 <= a < 1.0):
            raise ConfigError(f"dynamics.alpha: expected a forgetting factor in [0, 1), got {self.alpha!r}")


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

    p_b: float = param(
        0.05,
        help="background probability: the likelihood factor of a camera whose mask shows no motion at the projection "
        "(eq. 10)",
        symbol="p_B",
        lo=0.0,
        hi=0.5,
        lo_open=True,
        hi_open=True,
        flag="p-b",
    )
    outside: str = param(
        "background",
        help="what a camera that does not see the particle contributes: background (p_B, eq. 10) or neutral (1)",
        choices=OUTSIDE_MODES,
    )
    drop_worst: bool = param(
        True,
        help="with three or more cameras, leave out the least supporting camera's factor (off: eq. 9 as printed)",
    )

    def __post_init__(self) -> None:
        v = _number(self.p_b, "motion.p_b")
        if not (0.0 < v < 0.5):
            raise ConfigError(f"motion.p_b: expected a background probability in (0, 0.5), got {self.p_b!r}")
        if self.outside not in OUTSIDE_MODES:
            raise ConfigError(f"motion.outside: expected one of {', '.join(OUTSIDE_MODES)}, got {self.outside!r}")

    @property
    def log_outside(self) -> float:
        """The ``log_outside`` argument of ``kernels.people.filter.motion_kernel``."""
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

    r_n: float = param(
        0.1,
        help="radius of the spherical neighbourhood N_P (eq. 19)",
        units="m",
        symbol="r_N",
        lo=0.0,
        lo_open=True,
        flag="r-n",
    )
    n_bins: int = param(
        8,
        help="bins of each of the H, S and V histograms (eq. 20)",
        symbol="N_b",
        lo=2,
        hi=16,
        flag="bins",
    )
    r_min: float = param(1.0, help="smallest projected disc radius", units="px", lo=0.0, lo_open=True)
    r_max: float = param(12.0, help="largest projected disc radius (bounds the cost)", units="px", lo=0.0, lo_open=True)
    sigma_p: float = param(
        0.2,
        help="deviation of the appearance probability (eq. 26)",
        symbol="sigma_p",
        lo=0.0,
        lo_open=True,
    )
    step: int = param(2, help="pixel stride of the disc's samples (1: eq. 20 exactly)", units="px", lo=1)

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

    sigma: float = param(0.10, help="deviation of the 3D Gaussian kernel per particle", units="m", lo=0.0, lo_open=True)
    cutoff: float = param(3.0, help="truncation radius of the kernel, in kernel deviations", lo=0.0, lo_open=True)
    voxel: float = param(0.1, help="edge of the output voxels", units="m", lo=0.0, lo_open=True)
    extent: tuple[float, float, float] = param(
        (1.2, 1.2, 2.2),
        help="size of the grid around each person (x, y, z)",
        units="m",
        lo=0.0,
        lo_open=True,
        metavar=("X", "Y", "Z"),
    )
    p_h: float = param(
        0.95,
        help="probability the bounding volume must contain (section 4)",
        symbol="P_H",
        lo=0.0,
        hi=1.0,
        lo_open=True,
        hi_open=True,
    )

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

    A person is added where the motion masks of several cameras agree on a column over the ground that no tracked
    person explains, for several frames in a row (in the spirit of S3's uncovered-object histogram); a person whose
    column loses that multi-view support for several frames, or who leaves the working volume, is removed. Ids are
    never reused.

    Attributes:
        cell: ground grid pitch of the evidence map, metres. Ours: 0.1.
        heights: heights of the points tested over each cell, metres (a person's legs to head). Ours: 0.3 .. 1.5.
        min_fraction: fraction of a camera's visible points that must be on its motion mask for its vote. Ours: 0.6.
        min_cameras: cameras that must vote (at least 2, and at most the rig's cameras). Ours: 2.
        exclusion: no birth within this distance of a tracked person (ground plane), metres. Ours: 0.7.
        min_area: connected cells with enough votes needed for a birth, cells. Ours: 4.
        frames_to_add: consecutive frames of unexplained evidence near the same place before adding. Ours: 3.
        frames_to_remove: consecutive frames without evidence within ``support_radius`` before removing. Ours: 5.
        support_radius: radius around a person's ground position searched for its evidence, metres. Ours: 0.4.
        init_radius: radius of the cylinder a new person's particles start in, metres. Ours: 0.25.
        init_z: heights of that cylinder, metres. Ours: (0.3, 1.6).
        merge_distance: two people whose ground positions stay closer than this for ``frames_to_remove`` frames
            follow one person: the younger is removed, metres. Ours: 0.3 (people shaking hands stand ~0.6 m apart).
        person_radius: motion whose viewing ray passes within this distance of a tracked person's vertical axis
            is explained by that person (no birth from it), metres. Ours: 0.4.
        person_height: height of that axis, metres. Ours: 2.0.
        max_people: people tracked at once (a pool of filters allocated once). Ours: 8.

    At most one person is added per frame (the strongest unexplained region): the motion the new person explains
    is discounted from the next frame on, so the ghosts that two real people's silhouettes make where other
    cameras' rays cross are not added as people.
    """

    cell: float = param(0.1, help="ground grid pitch of the evidence map", units="m", lo=0.0, lo_open=True)
    heights: tuple[float, ...] = param(
        (0.3, 0.6, 0.9, 1.2, 1.5),
        help="heights of the points tested over each cell",
        units="m",
        lo=0.0,
    )
    min_fraction: float = param(
        0.6,
        help="fraction of a camera's visible points that must be on its motion mask for its vote",
        lo=0.0,
        hi=1.0,
        lo_open=True,
        hi_open=True,
    )
    min_cameras: int = param(2, help="cameras that must vote", lo=1)
    exclusion: float = param(
        0.7,
        help="no birth within this distance of a tracked person",
        units="m",
        lo=0.0,
        lo_open=True,
    )
    min_area: int = param(4, help="connected cells with enough votes needed for a birth", units="cells", lo=1)
    frames_to_add: int = param(3, help="consecutive frames of unexplained evidence before adding", units="frames", lo=1)
    frames_to_remove: int = param(5, help="consecutive frames without evidence before removing", units="frames", lo=1)
    support_radius: float = param(
        0.4,
        help="radius around a person searched for its evidence",
        units="m",
        lo=0.0,
        lo_open=True,
    )
    init_radius: float = param(
        0.25,
        help="radius of the cylinder a new person's particles start in",
        units="m",
        lo=0.0,
        lo_open=True,
    )
    init_z: tuple[float, float] = param(
        (0.3, 1.6),
        help="heights of that cylinder (low, high)",
        units="m",
        lo=0.0,
        metavar=("LOW", "HIGH"),
    )
    merge_distance: float = param(
        0.3,
        help="two people closer than this for frames_to_remove frames follow one person",
        units="m",
        lo=0.0,
    )
    person_radius: float = param(
        0.4,
        help="motion within this distance of a tracked person's axis is explained by that person",
        units="m",
        lo=0.0,
        lo_open=True,
    )
    person_height: float = param(2.0, help="height of that axis", units="m", lo=0.0, lo_open=True)
    max_people: int = param(
        8,
        help="people tracked at once (a pool of filters allocated once)",
        lo=1,
        flag="max-people",
    )

    def __post_init__(self) -> None:
        _positive(self.cell, "birth.cell", "a grid pitch in metres")
        if not self.heights or any(_number(h, "birth.heights") < 0 for h in self.heights):
            raise ConfigError(f"birth.heights: expected heights >= 0 metres, got {self.heights!r}")
        _open_fraction(self.min_fraction, "birth.min_fraction", "a fraction")
        _int_at_least(self.min_cameras, "birth.min_cameras", 1, "a camera count")
        _positive(self.exclusion, "birth.exclusion", "a distance in metres")
        _int_at_least(self.min_area, "birth.min_area", 1, "a cell count")
        _int_at_least(self.frames_to_add, "birth.frames_to_add", 1, "a frame count")
        _int_at_least(self.frames_to_remove, "birth.frames_to_remove", 1, "a frame count")
        _positive(self.support_radius, "birth.support_radius", "a distance in metres")
        _positive(self.init_radius, "birth.init_radius", "a radius in metres")
        if len(self.init_z) != 2 or not (
            0 <= _number(self.init_z[0], "birth.init_z") < _number(self.init_z[1], "birth.init_z")
        ):
            raise ConfigError(f"birth.init_z: expected (low, high) heights in metres, low < high, got {self.init_z!r}")
        _non_negative(self.merge_distance, "birth.merge_distance", "a distance in metres")
        _positive(self.person_radius, "birth.person_radius", "a radius in metres")
        _positive(self.person_height, "birth.person_height", "a height in metres")
        _int_at_least(self.max_people, "birth.max_people", 1, "a number of people")


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

    centroid: str = param(
        "standing",
        help="the 3D centroid: standing (ground position and a standing-person height) or particles (the paper's mean)",
        choices=CENTROID_MODES,
    )
    ratio: float = param(0.55, help="centre-of-mass height / stature", lo=0.0, hi=1.0, lo_open=True, hi_open=True)
    step: float = param(0.02, help="vertical step of the column search", units="m", lo=0.0, lo_open=True)
    max_gap: float = param(0.1, help="holes in the masks bridged on the way up", units="m", lo=0.0)
    min_cameras: int = param(2, help="cameras that must see a column point moving", lo=1)
    search: float = param(
        0.08,
        help="the column is also searched this far around the ground position",
        units="m",
        lo=0.0,
    )

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
        dynamics, motion, descriptor, occupancy, birth, body: the sections above.

    Resampling runs every frame (section 2.1: "particle resampling should be performed at each time step").
    """

    particles: int = param(500, help="particles per tracked person", symbol="N_S", lo=1)
    seed: int = param(0, help="seed of the counter-based random streams", lo=0, hi=2**64 - 1)
    dynamics: DynamicsConfig = param(default_factory=DynamicsConfig, help="particle dynamics (section 2.1)")
    motion: MotionConfig = param(default_factory=MotionConfig, help="motion observation (section 2.2)")
    descriptor: DescriptorConfig = param(default_factory=DescriptorConfig, help="3D colour descriptor (section 3.2)")
    occupancy: OccupancyConfig = param(default_factory=OccupancyConfig, help="volumetric occupancy (eqs. 2-3)")
    birth: BirthConfig = param(default_factory=BirthConfig, help="how people appear and leave")
    body: BodyConfig = param(default_factory=BodyConfig, help="the person's 3D centroid")

    def __post_init__(self) -> None:
        _int_at_least(self.particles, "particles", 1, "a particle count")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not (0 <= self.seed < 2**64):
            raise ConfigError(f"seed: expected an integer in [0, 2^64), got {self.seed!r}")
        for name, cls in (
            ("dynamics", DynamicsConfig),
            ("motion", MotionConfig),
            ("descriptor", DescriptorConfig),
            ("occupancy", OccupancyConfig),
            ("birth", BirthConfig),
            ("body", BodyConfig),
        ):
            if not isinstance(getattr(self, name), cls):
                raise ConfigError(f"{name}: expected a {cls.__name__}, got {type(getattr(self, name)).__name__}")
