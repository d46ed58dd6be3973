"""The S2 tracker's working area from the calibration (wptrack.trackers.people.area): the ground seen by two
cameras, a rig volume overriding it, and the rigs it refuses with one clear line."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from wptrack.cameras.rig import Camera, Rig
from wptrack.core.errors import RigError
from wptrack.trackers.people.area import camera_coverage, working_area
from wptrack.trackers.people.config import AreaConfig, PeopleConfig

W, H = 160, 120


def facing_pair(gap: float = 8.0) -> Rig:
    """Two cameras 2 m high, ``gap`` metres apart on the x axis, looking at each other's feet area."""
    return Rig(
        (
            Camera.look_at("west", W, H, (0.0, 0.0, 2.0), (gap / 2, 0.0, 0.8), 140.0),
            Camera.look_at("east", W, H, (gap, 0.0, 2.0), (gap / 2, 0.0, 0.8), 140.0),
        )
    )


def test_area_is_the_ground_both_cameras_see():
    rig = facing_pair()
    cfg = AreaConfig()
    area = working_area(rig, cfg)
    assert area.source == "calibration"
    lo, hi = area.bounds
    assert lo[0] < 4.0 < hi[0] and lo[1] < 0.0 < hi[1]
    # brute force on random ground points: in the area <=> both cameras see a standing person there
    rng = np.random.default_rng(0)
    xy = rng.uniform([-2, -6], [10, 6], (4000, 2))
    both = camera_coverage(rig[0], xy, cfg) & camera_coverage(rig[1], xy, cfg)
    inside = area.contains(xy)
    assert both.sum() > 200 and (~both).sum() > 200
    agree = np.mean(inside == both)
    assert agree > 0.97  # cell resolution at the edges
    assert area.contains(np.array([[4.0, 0.0]]))[0] and not area.contains(np.array([[4.0, 20.0]]))[0]
    assert "two or more cameras" in area.describe() and "m^2" in area.describe()


def test_area_ends_where_people_become_too_small():
    rig = facing_pair(gap=40.0)  # the middle is 20 m from both cameras
    small = working_area(rig, AreaConfig(min_person_height=5.0 / H))
    assert small.contains(np.array([[20.0, 0.0]]))[0]
    with pytest.raises(RigError, match="see no common ground"):
        working_area(rig, AreaConfig(min_person_height=30.0 / H))  # a 1.7 m person is ~9 px tall there
    with pytest.raises(RigError, match="see no common ground"):
        working_area(rig, AreaConfig(min_person_height=5.0 / H, max_distance=15.0))  # each sees 15 m of the 40 m


def test_area_does_not_depend_on_the_resolution():
    """The same cameras at half and twice the resolution (resized copies of their videos, which a run accepts)
    see the same ground: the smallest person is a fraction of the image height."""
    rig = facing_pair(gap=24.0)  # far enough that the smallest-person bound ends the area
    cfg = AreaConfig()
    ref = working_area(rig, cfg)
    xy = np.column_stack([np.linspace(-2.0, 26.0, 113), np.zeros(113)])
    assert 0 < ref.contains(xy).sum() < len(xy) - 20  # the bound cuts the middle of the gap
    for w, h in ((W // 2, H // 2), (2 * W, 2 * H)):
        other = working_area(Rig(tuple(c.scaled(w, h) for c in rig.cameras)), cfg)
        assert np.mean(other.contains(xy) == ref.contains(xy)) > 0.97  # cell resolution at the edges


def test_cameras_without_common_ground_are_named():
    rig = Rig(
        (
            Camera.look_at("north", W, H, (0.0, 0.0, 2.0), (0.0, 5.0, 0.8), 140.0),
            Camera.look_at("south", W, H, (0.0, -1.0, 2.0), (0.0, -6.0, 0.8), 140.0),
        ),
        source="rig.yaml",
    )
    with pytest.raises(RigError) as e:
        working_area(rig, AreaConfig())
    text = str(e.value)
    assert "rig.yaml" in text and "'north'" in text and "'south'" in text and "common ground" in text
    assert "\n" not in text


def test_volume_overrides_and_bad_volumes_are_refused():
    rig = facing_pair()
    box = (np.array([2.0, -1.0, 0.0]), np.array([6.0, 1.0, 2.2]))
    area = working_area(Rig(rig.cameras, volume=box), AreaConfig())
    assert area.source == "volume" and area.z_top == pytest.approx(2.2)
    lo, hi = area.bounds
    np.testing.assert_allclose(lo, [2.0, -1.0])
    np.testing.assert_allclose(hi, [6.0, 1.0])
    assert area.square_metres == pytest.approx(8.0)
    away = (np.array([2.0, 30.0, 0.0]), np.array([6.0, 32.0, 2.0]))  # behind both cameras' views
    with pytest.raises(RigError, match="outside every camera's view"):
        working_area(Rig(rig.cameras, volume=away), AreaConfig())
    one = Rig(
        (rig[0], Camera.look_at("elsewhere", W, H, (0.0, 0.0, 2.0), (-5.0, 0.0, 0.8), 140.0)),
        volume=(np.array([3.0, -1.0, 0.0]), np.array([5.0, 1.0, 2.0])),
    )
    with pytest.raises(RigError, match="seen by 2 cameras"):
        working_area(one, AreaConfig())


def test_tracker_logs_the_area_and_adds_nobody_outside(caplog):
    from wptrack.trackers.people.tracker import PeopleTracker

    rig = facing_pair()
    with caplog.at_level(logging.INFO, logger="wptrack.trackers.people"):
        tr = PeopleTracker(rig, PeopleConfig(particles=64), device="cpu", keep_particles=0)
    assert any("working area: the ground seen by two or more cameras" in r.message for r in caplog.records)
    gx, gy = tr._cell_centres()
    inside = tr.area.contains(np.stack([gx, gy], axis=-1))
    np.testing.assert_array_equal(tr.area_map, inside)
    assert tr.area_map.any() and not tr.area_map.all()
