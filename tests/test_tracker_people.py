"""The S2 people tracker end to end on a small in-memory scene, on every device: people appear, are tracked with
persistent ids, keep them while they pass each other, and leave; bad input; checkpoints; hulls."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wptrack.cameras.rig import Camera, Rig
from wptrack.core.errors import ConfigError, FrameError
from wptrack.trackers.people.config import OccupancyConfig, PeopleConfig
from wptrack.trackers.people.run import hull_points
from wptrack.trackers.people.tracker import PeopleTracker

W, H = 160, 120
COLOURS = ((40, 40, 200), (200, 80, 30))  # BGR: a red and a blue person


def rig3() -> Rig:
    target = (2.0, 2.0, 0.8)
    cams = (
        Camera.look_at("c0", W, H, (-0.5, -0.5, 2.6), target, 90.0),
        Camera.look_at("c1", W, H, (4.5, -0.5, 2.6), target, 90.0),
        Camera.look_at("c2", W, H, (2.0, 4.8, 2.6), target, 90.0),
    )
    return Rig(cams, volume=(np.array([0.0, 0.0, 0.0]), np.array([4.0, 4.0, 2.0])))


def _cylinder(xy, radius=0.22, height=1.7):
    a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    z = np.linspace(0.0, height, 12)
    ring = np.stack([xy[0] + radius * np.cos(a), xy[1] + radius * np.sin(a)], axis=1)
    return np.array([[x, y, zz] for zz in z for x, y in ring])


def render(rig: Rig, people: list[tuple[np.ndarray, tuple[int, int, int]]], rng) -> tuple[list, list]:
    """Images (grey noise + each person's silhouette in its colour, nearer drawn last) and perfect masks."""
    images, masks = [], []
    for cam in rig.cameras:
        img = rng.integers(95, 125, (H, W, 3)).astype(np.uint8)
        mask = np.zeros((H, W), np.uint8)
        depth_order = sorted(people, key=lambda p: -np.linalg.norm(cam.center[:2] - p[0]))
        for xy, colour in depth_order:
            uv, depth = cam.project(_cylinder(xy))
            if np.any(depth <= 0):
                continue
            hull = cv2.convexHull(np.round(uv).astype(np.int32))
            cv2.fillConvexPoly(img, hull, colour)
            cv2.fillConvexPoly(mask, hull, 255)
        images.append(img)
        masks.append(mask)
    return images, masks


def crossing(frames: int):
    """Two people walking towards each other along y = 2, passing 0.7 m apart, present from frame 3."""
    for t in range(frames):
        people = []
        if t >= 3:
            s = (t - 3) * 0.05
            people = [(np.array([0.6 + s, 1.65]), COLOURS[0]), (np.array([3.4 - s, 2.35]), COLOURS[1])]
        yield t, people


def _config(**kw):
    return PeopleConfig(particles=300, seed=3, **kw)


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(5)
    rig = rig3()
    frames = [(people, *render(rig, people, rng)) for _, people in crossing(60)]
    return rig, frames


def run(device, scene, **kw):
    rig, frames = scene
    tr = PeopleTracker(rig, _config(**kw), device=device, keep_particles=100)
    return tr, [tr.step(images, masks) for _, images, masks in frames]


def test_people_are_added_tracked_and_keep_ids(device, scene):
    _, frames = scene
    tr, ests = run(device, scene)
    assert ests[0].people == [] and ests[2].people == []  # nobody before frame 3
    assert sorted(tr.tracked_ids) == [0, 1]  # two people, two ids, no spurious ones
    by_id: dict[int, list] = {0: [], 1: []}
    for (people, _, _), est in zip(frames, ests, strict=True):
        for p in est.people:
            assert np.all(np.isfinite(p.mean)) and p.ess > 0
            truth = [xy for xy, _ in people]
            d = min(np.hypot(*(p.mean[:2] - xy)) for xy in truth)
            by_id[p.id].append((est.frame, d, int(np.argmin([np.hypot(*(p.mean[:2] - xy)) for xy in truth]))))
    for pid, rows in by_id.items():
        later = [r for r in rows if r[0] >= 15]
        assert later, f"person {pid} not tracked after frame 15"
        assert np.median([d for _, d, _ in later]) < 0.15  # metres on the ground
        assert len({k for _, _, k in later}) == 1, f"person {pid} switched identity"
        z = [p.mean[2] for e in ests[15:] for p in e.people if p.id == pid]
        assert 0.5 < np.median(z) < 1.2  # the particles fill the body, centroid at about half its height


def test_same_seed_same_output(device, scene):
    _, a = run(device, scene)
    _, b = run(device, scene)
    for ea, eb in zip(a, b, strict=True):
        assert [p.id for p in ea.people] == [p.id for p in eb.people]
        for pa, pb in zip(ea.people, eb.people, strict=True):
            np.testing.assert_array_equal(pa.mean, pb.mean)


def test_empty_scene_tracks_nobody(device):
    rng = np.random.default_rng(1)
    rig = rig3()
    tr = PeopleTracker(rig, _config(), device=device)
    for _ in range(6):
        est = tr.step(*render(rig, [], rng))
        assert est.people == [] and est.added == []


def test_person_leaving_is_removed(device, scene):
    rig, frames = scene
    rng = np.random.default_rng(2)
    tr = PeopleTracker(rig, _config(), device=device)
    for _, images, masks in frames[:20]:
        tr.step(images, masks)
    assert len(tr.tracked_ids) == 2
    removed = []
    for _ in range(10):  # everybody gone
        removed += tr.step(*render(rig, [], rng)).removed
    assert sorted(removed) == [0, 1] and tr.tracked_ids == []


def test_checkpoint_continues_identically(device, scene):
    rig, frames = scene
    tr, ests = run(device, scene)
    a = PeopleTracker(rig, _config(), device=device, keep_particles=100)
    for _, images, masks in frames[:25]:
        a.step(images, masks)
    b = PeopleTracker(rig, _config(), device=device, keep_particles=100)
    b.load_state_dict(a.state_dict())
    for (_, images, masks), ref in zip(frames[25:], ests[25:], strict=True):
        est = b.step(images, masks)
        assert [p.id for p in est.people] == [p.id for p in ref.people]
        for p, q in zip(est.people, ref.people, strict=True):
            np.testing.assert_array_equal(p.mean, q.mean)


def test_occupancy_integrates_to_one(device, scene):
    tr, _ = run(device, scene, occupancy=OccupancyConfig(extent=(2.0, 2.0, 3.0)))
    voxel = tr.config.occupancy.voxel
    _, images, masks = scene[1][-1]
    for _ in range(2):  # both particle buffers (the recorded launches are kept per buffer), the grid following
        pid = tr.tracked_ids[0]
        origin, grid = tr.occupancy(pid)
        assert grid.dtype == np.float32 and np.all(grid >= 0)
        assert abs(grid.sum() * voxel**3 - 1.0) < 0.05  # the 3 sigma cutoff and the grid edges lose a little
        centre = origin + voxel * (np.array(np.unravel_index(np.argmax(grid), grid.shape)) + 0.5)
        mean = next(p.mean for p in tr.step(images, masks).people if p.id == pid)
        assert np.hypot(*(centre[:2] - mean[:2])) < 0.3


def test_bad_input(device):
    rig = rig3()
    with pytest.raises(ConfigError, match="two or more"):
        PeopleTracker(Rig(rig.cameras[:1], volume=rig.volume), _config(), device=device)
    tr = PeopleTracker(rig, _config(), device=device)
    images, masks = render(rig, [], np.random.default_rng(0))
    with pytest.raises(FrameError, match="mask size"):
        tr.step(images, [m[:-1] for m in masks])
    with pytest.raises(FrameError, match="3 cameras"):
        tr.step(images[:2], masks[:2])


def test_hull_points_holds_the_weight():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(400, 3))
    w = np.exp(-0.5 * np.sum(pts**2, axis=1))
    hull = hull_points(pts, w, 0.95)
    order = np.argsort(-w)
    k = int(np.searchsorted(np.cumsum(w[order]), 0.95 * w.sum())) + 1
    kept = pts[order[:k]]
    assert len(hull) >= 4 and all(any(np.array_equal(v, q) for q in kept) for v in hull)
    from scipy.spatial import Delaunay

    inside = Delaunay(hull).find_simplex(kept) >= 0
    assert inside.all()  # the hull holds the whole 95 % set
    assert not (Delaunay(hull).find_simplex(pts[order[-20:]]) >= 0).all()  # but not the light tail
