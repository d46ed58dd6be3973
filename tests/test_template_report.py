"""What the template tracker reports: objects whose image box is mostly outside the image are left out
(``TemplateConfig.min_in_image``), by the same rule as the synthetic ground truth's labels."""

from __future__ import annotations

import numpy as np
import pytest

from wptrack.cameras.rig import Camera, GroundPlane, Rig
from wptrack.core.errors import ConfigError
from wptrack.synth import SCENES
from wptrack.synth import plaza as P
from wptrack.synth.plaza_background import plaza_camera
from wptrack.trackers.templates.config import TemplateConfig, TrackedObject
from wptrack.trackers.templates.tracker import TemplateTracker, image_box_fraction


def _vehicle(plane: GroundPlane, ground, dims, heading: float) -> TrackedObject:
    g = np.asarray(ground, dtype=np.float64)
    dims = np.asarray(dims, dtype=np.float64)
    return TrackedObject(id=0, cls="vehicle", position=plane.to_world(g), ground=g, dims=dims, heading=heading, speed=0)


def test_image_box_fraction_matches_the_ground_truth_rule() -> None:
    """For a car's box, the tracker's fraction equals the one the synthetic ground truth labels by
    (``wptrack.synth.plaza.image_box_cover``, which builds the corners from the scene's own shapes in world
    coordinates; both project them with ``Camera.image_box_cover``), inside, across the edges of and outside the
    image."""
    cam, plane = plaza_camera(), GroundPlane()
    car = next(a.shape for a in SCENES["s3-cars"].build().actors if isinstance(a.shape, P.Car))
    rng = np.random.default_rng(7)
    pos = rng.uniform([-16.0, 3.0], [16.0, 32.0], (300, 2))
    heading = rng.uniform(-np.pi, np.pi, 300)
    ok, area, inside = P.image_box_cover(cam, car, pos, heading)
    expected = np.where(ok, inside / area, 0.0)
    got = image_box_fraction(cam, plane, [_vehicle(plane, p, car.dims, h) for p, h in zip(pos, heading, strict=True)])
    np.testing.assert_allclose(got, expected, atol=1e-9)
    # the draw covers the three cases
    assert (expected > 0.999).sum() > 20 and (expected == 0).sum() > 20
    assert ((expected > 0.05) & (expected < 0.95)).sum() > 20
    assert image_box_fraction(cam, plane, []).shape == (0,)


def test_image_box_fraction_of_a_human_uses_its_body_diameter() -> None:
    """A human (height, body radius, head radius) is boxed as a vehicle of length = width = 2 x body radius and its
    height would be; across the image's left edge the fraction is strictly between 0 and 1 and depends on the
    radius; in the middle of the view it is 1."""
    cam = Camera.look_at("cam", 320, 240, position=[0, -4, 10], target=[0, 9, 0], fx=250.0)
    plane = GroundPlane()
    xs = np.linspace(-20.0, 0.0, 20001)
    u = cam.project(np.c_[xs, np.full_like(xs, 9.0), np.zeros_like(xs)])[0][:, 0]
    x_edge = float(xs[np.argmin(np.abs(u))])  # the ground point at (x_edge, 9) projects onto column 0

    def human(x: float, radius: float) -> TrackedObject:
        g = np.array([x, 9.0])
        return TrackedObject(
            id=1, cls="human", position=plane.to_world(g), ground=g, dims=np.array([1.7, radius, 0.1]), heading=0.3,
            speed=0.0,
        )  # fmt: skip

    f = image_box_fraction(cam, plane, [human(x_edge, 0.25), human(x_edge, 0.4), human(0.0, 0.25)])
    as_boxes = image_box_fraction(
        cam, plane, [_vehicle(plane, (x_edge, 9.0), (2 * rad, 2 * rad, 1.7), 0.3) for rad in (0.25, 0.4)]
    )
    np.testing.assert_allclose(f[:2], as_boxes, rtol=0, atol=1e-12)
    assert 0.05 < f[0] < 0.95 and abs(f[0] - f[1]) > 0.01 and f[2] == 1.0


def test_min_in_image_is_validated() -> None:
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ConfigError, match="min_in_image"):
            TemplateConfig(min_in_image=bad)


@pytest.mark.parametrize("min_in_image", [0.25, 0.0])
def test_tracker_leaves_out_objects_outside_the_image(device, min_in_image: float) -> None:
    """Two vehicles held by every particle, one in the middle of the view and one 40 m to its side: the one outside
    is tracked (its slot is kept) but reported only with ``min_in_image`` 0."""
    cam = Camera.look_at("cam0", 320, 240, position=[0, -4, 10], target=[0, 9, 0], fx=250.0, dist=[-0.05, 0, 0, 0, 0])
    n, r = 64, 2
    config = TemplateConfig(particles=n, max_objects=r, seed=1, t_del=0.0, min_in_image=min_in_image)
    tr = TemplateTracker(Rig(cameras=(cam,)), config, device=device)
    tr.set_particles(
        kind=np.full((n, r), 2, np.int32),
        label=np.tile(np.array([5, 6], np.int32), (n, 1)),
        pos=np.tile(np.array([[0.0, 9.0], [40.0, 9.0]], np.float32), (n, 1, 1)),
        vel=np.zeros((n, r, 2), np.float32),
        heading=np.zeros((n, r), np.float32),
        dims=np.tile(np.array([4.4, 1.8, 1.5], np.float32), (n, r, 1)),
        age=np.ones((n, r), np.float32),
        logw=np.zeros(n, np.float32),
    )
    est = tr.step(np.zeros((240, 320), np.uint8))
    reported = {o.id: o for o in est.objects}
    assert reported[5].in_image == 1.0
    if min_in_image > 0:
        assert set(reported) == {5}
    else:
        assert set(reported) == {5, 6} and reported[6].in_image == 0.0
    assert {o.id for o in est.best} == {5, 6}  # the particles keep both
