"""S2 configuration dataclasses: defaults valid, bad values rejected with the field named."""

from __future__ import annotations

import math

import pytest

from wptrack.core.errors import ConfigError
from wptrack.trackers.people.config import DescriptorConfig, DynamicsConfig, MotionConfig, OccupancyConfig, PeopleConfig


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
        (lambda: PeopleConfig(motion=0.1), "motion"),
    ],
)
def test_bad_values_name_the_field(make, field):
    with pytest.raises(ConfigError, match=f"^{field}: expected"):
        make()
