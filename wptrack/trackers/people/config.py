"""Configuration of the S2 multi-camera people tracker (Lopez-Cifuentes et al., "multi-camera 3D particle filters
with motion and colour"): frozen dataclasses, validated on construction, with the paper's symbols and units.

The paper fixes few numbers: N_S = 500 particles per target, P_H = 0.95, alpha "close to zero", p_B "a positive
value close to 0". Every other default here is this project's choice (marked "ours"), not the paper's.
The kernels these parameters feed are in ``kernels/people/filter.py``, ``kernels/people/coverage.py``,
``kernels/people/descriptor.py`` and ``kernels/people/occupancy.py``. Each field is declared once with
:func:`wptrack.core.config.param` (the command line and the batch manifests derive from it); each section checks its
fields with :func:`wptrack.core.config.check` and adds the checks that relate two fields.

Length: one module for the tracker's whole configuration on purpose: each section documents its fields with the
measurements that chose their defaults, and the sections are read together (the gate and the births share the
rectangle's probabilities).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wptrack.core.config import check, param
from wptrack.core.errors import ConfigError
from wptrack.trackers.people.area import AreaConfig

__all__ = [
    "AreaConfig",
    "BirthConfig",
    "BodyConfig",
    "DescriptorConfig",
    "DynamicsConfig",
    "MotionConfig",
    "OccupancyConfig",
    "PeopleConfig",
    "PersonConfig",
]

OUTSIDE_MODES = ("background", "neutral")
EXPLAINED_MODES = ("empty", "neutral")
GATE_USES = ("both", "removal", "weighting")


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

    sigma_pos: float = param(
        0.15,
        help="position noise n_P per axis (eq. 5), a random walk: sigma_pos sqrt(dt) per frame",
        units="m/sqrt(s)",
        lo=0.0,
        lo_open=True,
        flag="sigma-pos",
    )
    sigma_vel: float = param(
        0.5,
        help="horizontal velocity noise n_V per axis (eq. 5), a random walk: sigma_vel sqrt(dt) per frame",
        units="m/s/sqrt(s)",
        lo=0.0,
        flag="sigma-vel",
    )
    sigma_vel_z: float = param(
        1.25,
        help="vertical velocity noise (the particles keep filling the body's height)",
        units="m/s/sqrt(s)",
        lo=0.0,
    )
    alpha: float = param(
        0.05,
        help="forgetting factor of the appearance update (eq. 6) per alpha_interval, close to zero",
        symbol="alpha",
        lo=0.0,
        hi=1.0,
        hi_open=True,
        flag="alpha",
    )
    alpha_interval: float = param(0.04, help="the interval alpha is given for", units="s", lo=0.0, lo_open=True)
    jump: float = param(
        0.04, help="ours: share of each filter's particles moved along a camera's ray through them a frame (0: off)",
        lo=0.0, hi=1.0,
    )  # fmt: skip
    """Every frame a particle jumps with this probability (``kernels.people.filter.ray_jump``): a filter one view has
    locked on someone else's silhouette (a multi-view ghost) sits 1-2 m off along the other view's ray, a local
    optimum of the weights its Gaussian walk does not leave; the jumped particles try the positions along the rays
    and the weights decide. A share of each frame's particles, not a rate in time: it is the proposal's exploration,
    paid per frame at any frame rate. Measured on the EPFL terrace (docs/notes.md): 25 frames/s MOTA 0.343 -> 0.537
    (tracker seeds 0-3), 3.125 frames/s 0.176 -> 0.196 (seeds 0-7)."""
    jump_span: float = param(2.0, help="ours: the longest of those jumps", units="m", lo=0.0)
    jump_clear: float = param(
        1.0, help="ours: a jump never lands this close to another tracked person (it is not made)", units="m", lo=0.0
    )
    """Without it a jumped particle that lands on another person's body scores as well as on its own person, and the
    filter follows it (3.125 frames/s: 0.207 -> 0.06-0.13)."""

    def __post_init__(self) -> None:
        check(self, "dynamics.")

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
        check(self, "motion.")

    @property
    def log_outside(self) -> float:
        """The ``log_outside`` argument of ``kernels.people.filter.motion_log_likelihood``."""
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
        check(self, "descriptor.")
        if self.r_max < self.r_min:
            raise ConfigError(f"descriptor.r_max: expected >= r_min ({self.r_min!r}), got {self.r_max!r}")


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
        check(self, "occupancy.")


@dataclass(frozen=True)
class BirthConfig:
    """How people appear and leave (ours: the paper tracks a known set of people and does not say).

    The evidence map is a ground grid over the working area where each cell holds, per camera, the coverage of the
    rectangle of a person standing there by the motion nobody tracked explains (the masks less the tracked people's
    rectangles: ``kernels.people.coverage``, in the spirit of POM, Fleuret et al. PAMI 2008). A person is added where
    every camera that sees a cell (at least ``min_cameras`` of them) finds more of that motion than an empty rectangle
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
            hue, saturation and value histograms of the legs and the torso, ``kernels.people.coverage``), in (0, 1].
            Ours: 0.8.
        appearance_seconds: memory of a person's appearance histograms (an exponential average over the frames
            where enough of its pixels are its own), seconds. Ours: 3.
        explained: what the pixels inside the tracked people's rectangles count as in the evidence map:
            ``empty`` (cleared from the masks but still part of a candidate's rectangle: a newcomer standing beside a
            tracked person, whose rectangle the other's overlaps in one camera, looks like an empty rectangle there
            and that camera vetoes the birth) or ``neutral`` (POM's gain of adding a person, Fleuret et al. PAMI
            2008, section 4, as in the particles' rectangle term: a candidate is judged on the part of its rectangle
            the tracked people leave; a camera judges only where that part is at least ``PersonConfig.gate_left`` of
            the rectangle, and ``min_cameras`` cameras must judge). Ours: empty.

    At most one person is added per frame (the strongest unexplained region): the motion the new person explains
    is discounted from the next frame on, so the ghosts that two real people's silhouettes make where other
    cameras' rays cross are not added as people.
    """

    cell: float = param(0.1, help="ground grid pitch of the evidence map", units="m", lo=0.0, lo_open=True)
    min_cameras: int = param(2, help="cameras that must see a cell for a birth there", lo=1)
    exclusion: float = param(
        0.7,
        help="no birth within this distance of a tracked person",
        units="m",
        lo=0.0,
        lo_open=True,
    )
    min_area: int = param(4, help="connected cells of evidence needed for a birth", units="cells", lo=1)
    add_seconds: float = param(0.12, help="unexplained evidence for this long before adding", units="s", lo=0.0)
    remove_seconds: float = param(1.0, help="not seen for this long before removing", units="s", lo=0.0)
    hold_seconds: float = param(
        10.0,
        help="the same for a person the masks lost while it stood still (slower than 0.3 m/s)",
        units="s",
        lo=0.0,
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
    init_speed: float = param(
        0.0,
        help="deviation of a new person's particles' horizontal velocities per axis",
        units="m/s",
        lo=0.0,
    )
    merge_distance: float = param(
        0.3,
        help="two people closer than this for remove_seconds follow one person",
        units="m",
        lo=0.0,
    )
    max_people: int = param(
        8,
        help="people tracked at once (a pool of filters allocated once)",
        lo=1,
        flag="max-people",
    )
    reid_seconds: float = param(
        10.0,
        help="a person removed unseen is remembered this long for re-identification (0: never)",
        units="s",
        lo=0.0,
    )
    reid_similarity: float = param(
        0.8,
        help="smallest appearance similarity (mean Bhattacharyya coefficient) to take a remembered id again",
        lo=0.0,
        hi=1.0,
        lo_open=True,
    )
    appearance_seconds: float = param(
        3.0,
        help="memory of a person's appearance histograms",
        units="s",
        lo=0.0,
        lo_open=True,
    )

    explained: str = param(
        "empty",
        help="what the pixels inside the tracked people's rectangles count as in the evidence map: empty, or neutral "
        "(POM's gain: a candidate is judged on what the tracked people leave of its rectangle)",
        choices=EXPLAINED_MODES,
    )

    def __post_init__(self) -> None:
        check(self, "birth.")
        if not self.init_z[0] < self.init_z[1]:
            raise ConfigError(f"birth.init_z: expected (low, high) heights in metres, low < high, got {self.init_z!r}")


@dataclass(frozen=True)
class PersonConfig:
    """The whole person beyond its particles (ours; ``kernels/people/coverage.py``): the image rectangle of a standing
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
        gate_cameras: 0: the gate pools the cameras that see the rectangle (one camera's coverage can carry
            another's empty view); k >= 1: k cameras must each cover more than ``gate`` of what the others leave of
            their rectangle (where that is at least ``gate_left`` of it; a camera where the person is hidden does not
            judge), so one camera's silhouette alone, a ray along which a filter slides in depth, does not keep a
            person seen (``kernels.people.coverage.kth_camera_coverage``). Ours: 2, for the removal only (below).
        gate_cameras_use: what that per-camera rule decides (with ``gate_cameras`` > 0): ``both``, ``removal``
            (whether the person is seen for ``remove_seconds``; the weighting stays pooled) or ``weighting``
            (whether the filter is weighted; removal stays pooled). Ours: removal. Same commands, tracker seeds 0-3
            (issue 31): terrace at 3.125 frames/s MOTA -0.304 -> +0.041 (better on every seed; false positives 102
            -> 42), at 25 frames/s 0.234 -> 0.250 (false positives 449 -> 340, misses 516 -> 606); the offices
            unchanged (scene 1 0.950 / 0.946, scene 0 0.974, s2-office-lowfps both scenes). ``both``: 3.125
            frames/s -0.063 but 25 frames/s 0.211 and the office's exit 0.950 -> 0.929 (the unweighted filter
            stops inside the room); ``weighting``: 3.125 frames/s -0.49.
        balance_cameras: weight each camera's rectangle term of a particle by the mean area of the person's own
            rectangles over the cameras divided by its area in that camera (at its last position): every camera holds
            the same evidence about a person whatever its distance, so a near camera's large silhouette does not
            outweigh the far camera that fixes the depth along its rays
            (``kernels.people.coverage.balanced_box_log_likelihood``). Ours: off.
        stop_seconds: an unseen person's velocity decays with this time constant, seconds (people stop more
            often than they walk on unseen). Ours: 1.
    """

    half_width: float = param(0.25, help="half the person rectangle's width", units="m", lo=0.0, lo_open=True)
    height: float = param(1.75, help="the person rectangle's height", units="m", lo=0.0, lo_open=True)
    min_visible: float = param(
        0.5,
        help="a camera sees a rectangle when this fraction of it is inside its image",
        lo=0.0,
        hi=1.0,
        lo_open=True,
    )
    p_person: float = param(
        0.35,
        help="fraction of a person's rectangle the motion masks cover",
        lo=0.0,
        hi=1.0,
        lo_open=True,
        hi_open=True,
    )
    p_empty: float = param(
        0.05,
        help="fraction of an empty rectangle the motion masks cover",
        lo=0.0,
        hi=1.0,
        lo_open=True,
        hi_open=True,
    )
    pixels: float = param(
        100.0,
        help="pixels per independent sample of the rectangle term (0: off)",
        units="px",
        lo=0.0,
    )
    exclusion_radius: float = param(
        0.4,
        help="two people's ground positions closer than this repel",
        units="m",
        lo=0.0,
        lo_open=True,
    )
    exclusion_weight: float = param(5.0, help="the repulsion at distance 0 (0: off)", units="nats", lo=0.0)
    gate: float = param(
        0.2,
        help="the masks show a person when they cover more than this fraction of its rectangle near it",
        lo=0.0,
        hi=1.0,
        lo_open=True,
        hi_open=True,
    )
    gate_reach: float = param(0.25, help="how far the gate looks, plus a 1.5 m/s walk", units="m", lo=0.0)
    gate_left: float = param(
        0.25,
        help="the gate judges only where the other people leave this fraction of the rectangle",
        lo=0.0,
        hi=1.0,
        lo_open=True,
        hi_open=True,
    )
    gate_cameras: int = param(
        2,
        help="0: the gate pools the cameras; k: k cameras must each show the person (where not hidden by others)",
        lo=0,
    )
    gate_cameras_use: str = param(
        "removal",
        help="what the per-camera gate decides: both, removal (weighting pooled) or weighting (removal pooled)",
        choices=GATE_USES,
    )
    balance_cameras: bool = param(
        False,
        help="weight each camera's rectangle term by the mean own-rectangle area over its own (cameras hold equal "
        "evidence whatever their distance)",
    )
    stop_seconds: float = param(
        1.0,
        help="an unseen person's velocity decays with this time constant",
        units="s",
        lo=0.0,
        lo_open=True,
    )

    def __post_init__(self) -> None:
        check(self, "person.")
        if self.p_empty >= self.p_person:
            raise ConfigError(f"person.p_empty: expected < p_person ({self.p_person!r}), got {self.p_empty!r}")

    @property
    def slope_offset(self) -> tuple[float, float]:
        """``(slope, offset)`` of ``kernels.people.coverage.box_log_likelihood``: log(p1 (1 - p0) / (p0 (1 - p1))) /
        ``pixels`` and -log((1 - p1) / (1 - p0)) / ``pixels`` (both 0 when ``pixels`` is 0: the term is off)."""
        p1, p0, k = self.p_person, self.p_empty, self.pixels
        if k == 0:
            return 0.0, 0.0
        return math.log(p1 * (1 - p0) / (p0 * (1 - p1))) / k, -math.log((1 - p1) / (1 - p0)) / k


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
        check(self, "body.")


@dataclass(frozen=True)
class PeopleConfig:
    """The S2 tracker's parameters.

    Attributes:
        particles: particles per tracked person [N_S] (section 4: 500).
        seed: seed of the counter-based random streams (same seed + device -> identical output).
        fps: frame rate of the recording, frames per second (the frame interval dt = 1 / fps of the dynamics and of
            every time in seconds). None: the recording's own (the videos' frame rate in a run; ``--fps`` for image
            folders); a :class:`~wptrack.trackers.people.tracker.PeopleTracker` built without one assumes 25 frames/s.
            ``PeopleTracker.step(..., timestamp=...)`` takes dt from the frames' timestamps instead.
        smooth_seconds: offline smoothing of a completed run's ``tracks.csv`` (ours, beyond the paper;
            ``wptrack.core.smoothing``): each person's ``x, y, z`` become a weighted line's over +- this long at each
            row (LOESS of degree 1, tricube weights), seconds (0: off). The hulls, occupancy grids and MAP columns
            stay the filter's own. Measured on existing runs' outputs (MOTA without / 1 s / 1.5 s): terrace 25
            frames/s (seeds 0-3) 0.559 / 0.573 / 0.572, 3.125 frames/s (seeds 0-7) 0.184 / 0.221 / 0.219, the office
            0.954 throughout (its HOTA 0.714 / 0.736 / 0.695: a longer window cuts the corners of people turning);
            the same 1 s as the template tracker's ``TemplateConfig.smooth_seconds``.
        dynamics, motion, descriptor, occupancy, birth, body, person: the sections above; area:
            :class:`~wptrack.trackers.people.area.AreaConfig`.

    Resampling runs every frame (section 2.1: "particle resampling should be performed at each time step").
    """

    particles: int = param(500, help="particles per tracked person", symbol="N_S", lo=1)
    seed: int = param(0, help="seed of the counter-based random streams", lo=0, hi=2**64 - 1)
    fps: float | None = param(
        None,
        help="frame rate of the recording (default: the videos'; needed for image folders)",
        units="frames/s",
        lo=0.0,
        lo_open=True,
        flag="fps",
    )
    smooth_seconds: float = param(
        1.0,
        help="when the run completes, smooth each person's positions over +- this long (0: off)",
        units="s",
        lo=0.0,
    )
    dynamics: DynamicsConfig = param(default_factory=DynamicsConfig, help="particle dynamics (section 2.1)")
    motion: MotionConfig = param(default_factory=MotionConfig, help="motion observation (section 2.2)")
    descriptor: DescriptorConfig = param(default_factory=DescriptorConfig, help="3D colour descriptor (section 3.2)")
    occupancy: OccupancyConfig = param(default_factory=OccupancyConfig, help="volumetric occupancy (eqs. 2-3)")
    birth: BirthConfig = param(default_factory=BirthConfig, help="how people appear and leave")
    body: BodyConfig = param(default_factory=BodyConfig, help="the person's 3D centroid")
    person: PersonConfig = param(default_factory=PersonConfig, help="the person rectangle (after POM)")
    area: AreaConfig = param(default_factory=AreaConfig, help="the working area from the calibration")

    def __post_init__(self) -> None:
        check(self)
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
