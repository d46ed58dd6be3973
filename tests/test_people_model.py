"""S2 configuration dataclasses: defaults valid, bad values rejected with the field named."""

from __future__ import annotations

import math

import pytest

from wptrack.core.errors import ConfigError
from wptrack.trackers.people.config import (
    BirthConfig,
    DescriptorConfig,
    DynamicsConfig,
    MotionConfig,
    OccupancyConfig,
    PeopleConfig,
)


def test_defaults_are_valid_and_frozen():
    cfg = PeopleConfig()
    assert cfg.particles == 500 and cfg.occupancy.p_h == 0.95
    assert cfg.motion.log_outside == pytest.approx(math.log(0.05))
    assert MotionConfig(outside="neutral").log_outside == 0.0
    with pytest.raises(AttributeError):
        cfg.particles = 3  # type: ignore[misc]


@pytest.mark.parametrize(
    "make,field",
    [
        (lambda: DynamicsConfig(sigma_pos=0), "dynamics.sigma_pos"),
        (lambda: DynamicsConfig(sigma_vel=-1), "dynamics.sigma_vel"),
        (lambda: DynamicsConfig(alpha=1.0), "dynamics.alpha"),
        (lambda: DynamicsConfig(alpha=float("nan")), "dynamics.alpha"),
        (lambda: MotionConfig(p_b=0.0), "motion.p_b"),
        (lambda: MotionConfig(p_b=0.7), "motion.p_b"),
        (lambda: MotionConfig(outside="ignore"), "motion.outside"),
        (lambda: DescriptorConfig(r_n=-0.1), "descriptor.r_n"),
        (lambda: DescriptorConfig(n_bins=1), "descriptor.n_bins"),
        (lambda: DescriptorConfig(n_bins=8.0), "descriptor.n_bins"),
        (lambda: DescriptorConfig(r_min=5, r_max=4), "descriptor.r_max"),
        (lambda: DescriptorConfig(sigma_p=0), "descriptor.sigma_p"),
        (lambda: OccupancyConfig(sigma=0), "occupancy.sigma"),
        (lambda: OccupancyConfig(voxel="a"), "occupancy.voxel"),
        (lambda: OccupancyConfig(p_h=1.0), "occupancy.p_h"),
        (lambda: PeopleConfig(particles=0), "particles"),
        (lambda: PeopleConfig(seed=-1), "seed"),
        (lambda: PeopleConfig(fps=0), "fps"),
        (lambda: DynamicsConfig(alpha_interval=0), "dynamics.alpha_interval"),
        (lambda: DynamicsConfig(sigma_vel_z=-1), "dynamics.sigma_vel_z"),
        (lambda: BirthConfig(add_seconds=-1), "birth.add_seconds"),
        (lambda: BirthConfig(remove_seconds=float("inf")), "birth.remove_seconds"),
        (lambda: PeopleConfig(motion=0.1), "motion"),
    ],
)
def test_bad_values_name_the_field(make, field):
    with pytest.raises(ConfigError, match=f"^{field}: expected"):
        make()


def test_dynamics_per_frame_is_the_office_value_at_25_fps_and_scales_with_time():
    """The values in seconds are the per-frame values the office was built with at 25 frames/s (0.03 m, 0.01 m
    per frame per frame = 0.25 m/s, alpha 0.05); at another rate the noise is a random walk (variance in proportion
    to dt) and the appearance keeps the same memory in seconds."""
    d = DynamicsConfig()
    sp, (sv, svz), al = d.per_frame(0.04)
    assert sp == pytest.approx(0.03) and svz == pytest.approx(0.25) and al == pytest.approx(0.05)
    assert sv == pytest.approx(0.1)  # 0.5 m/s per sqrt(s) horizontally (ours)
    sp8, (sv8, svz8), al8 = d.per_frame(0.32)  # every 8th frame
    assert sp8**2 == pytest.approx(8 * sp**2) and sv8**2 == pytest.approx(8 * sv**2)
    assert svz8**2 == pytest.approx(8 * svz**2)
    assert 1 - al8 == pytest.approx((1 - al) ** 8)  # eight frames of forgetting in one
