"""S2 person rectangles (kernels/people/coverage.py, ours after POM) against NumPy references on every device: the
rectangle of a standing person, its mask counts from the integral image, the coverage and area maps of a ground
grid, the tracked people's rectangles and the motion they leave, the rectangle term of a particle's weight (what
the other people's rectangles leave), the exclusion penalty, the gate, and the appearance histograms."""

from __future__ import annotations

import colorsys

import kernel_harness as harness
import numpy as np
import pytest
import warp as wp

from wptrack.cameras.rig import Camera, Rig
from wptrack.cameras.structs import DeviceRig
from wptrack.kernels.colour import hsi as kcolour
from wptrack.kernels.core import camera as kcam
from wptrack.kernels.people import coverage as kcov

HW, HEIGHT, VIS = 0.25, 1.75, 0.5


def make_rig() -> Rig:
    """Two 96x72 cameras 2.5 m high looking at a 4 x 4 m floor, one with lens distortion."""
    return Rig(
        (
            Camera.look_at("a", 96, 72, (-1.0, -1.0, 2.5), (2.0, 2.0, 0.7), 70.0),
            Camera.look_at("b", 96, 72, (5.0, -0.5, 2.4), (2.0, 2.0, 0.8), 75.0, dist=[-0.04, 0.01, 0, 0, 0]),
        )
    )


def blob_masks(rig: Rig, rng) -> np.ndarray:
    """Flat 0/1 masks with rectangular blobs (people-sized) and noise."""
    out = []
    for cam in rig.cameras:
        m = (rng.random((cam.height, cam.width)) < 0.03).astype(np.uint8)
        for _ in range(6):
            u, v = rng.integers(0, cam.width), rng.integers(0, cam.height)
            m[v : v + rng.integers(10, 40), u : u + rng.integers(4, 15)] = 1
        out.append(m.reshape(-1))
    return np.concatenate(out)


def integral(rig: Rig, drig: DeviceRig, mask: np.ndarray, device) -> wp.array:
    """The integral images of the flat 0/1 masks with kernels.colour.hsi's scans (tested in test_kernels_colour)."""
    m = wp.array(mask, dtype=wp.uint8, device=device)
    out = wp.zeros(drig.total_integral, dtype=wp.int32, device=device)
    cams = drig.cams
    maxw = max(c.width for c in rig.cameras)
    maxh = max(c.height for c in rig.cameras)
    seg = int(kcolour.SEGMENT)
    rows = (drig.num_cameras, maxh, -(-maxw // seg))
    cols = (drig.num_cameras, maxw + 1, -(-maxh // seg))
    rs = wp.zeros(rows, dtype=wp.int32, device=device)
    cs = wp.zeros(cols, dtype=wp.int32, device=device)
    wp.launch(kcolour.row_segment_sums_kernel, dim=rows, inputs=[cams, m], outputs=[rs], device=device)
    wp.launch(kcolour.row_scan_kernel, dim=rows, inputs=[cams, m, rs], outputs=[out], device=device)
    wp.launch(kcolour.col_segment_sums_kernel, dim=cols, inputs=[cams, out], outputs=[cs], device=device)
    wp.launch(kcolour.col_scan_kernel, dim=cols, inputs=[cams, cs], outputs=[out], device=device)
    return out


def project_ref(drig: DeviceRig, pts: np.ndarray, device) -> np.ndarray:
    """(M, N, 3) (u, v, depth) by kernel_harness.project_kernel (test_kernels_camera checks it against OpenCV)."""
    out = wp.zeros((drig.num_cameras, len(pts)), dtype=wp.vec3, device=device)
    wp.launch(
        harness.project_kernel,
        dim=(drig.num_cameras, len(pts)),
        inputs=[drig.cams, wp.array(pts, dtype=wp.vec3, device=device)],
        outputs=[out],
        device=device,
    )
    return out.numpy().astype(np.float64)


def box_ref(rig: Rig, drig: DeviceRig, xy: np.ndarray, device, hw=HW, h=HEIGHT):
    """(M, N, 4) clipped rectangles and (M, N) unclipped areas (0 where a corner is not projected)."""
    corners = []
    for cam in rig.cameras:
        d = xy - cam.center[:2]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        perp = np.column_stack([-d[:, 1], d[:, 0]])
        corners.append(perp)
    m, n = len(rig), len(xy)
    boxes = np.zeros((m, n, 4))
    full = np.zeros((m, n))
    for c, cam in enumerate(rig.cameras):
        pts = np.concatenate(
            [np.column_stack([xy + s * hw * corners[c], np.full(n, z)]) for s in (-1, 1) for z in (0.0, h)]
        ).astype(np.float32)
        uvz = project_ref(drig, pts, device)[c].reshape(4, n, 3)
        ok = np.all(uvz[..., 2] > 0, axis=0)
        umin, umax = uvz[..., 0].min(0), uvz[..., 0].max(0)
        vmin, vmax = uvz[..., 1].min(0), uvz[..., 1].max(0)
        box = np.stack(
            [
                np.clip(np.floor(umin + 0.5), 0, cam.width),
                np.clip(np.floor(vmin + 0.5), 0, cam.height),
                np.clip(np.floor(umax + 0.5), 0, cam.width),
                np.clip(np.floor(vmax + 0.5), 0, cam.height),
            ],
            axis=1,
        )
        boxes[c] = np.where(ok[:, None], box, 0.0)
        full[c] = np.where(ok, (umax - umin) * (vmax - vmin), 0.0)
    return boxes, full


def count_ref(mask2d: np.ndarray, box) -> int:
    u0, v0, u1, v1 = (int(v) for v in box)
    return int(mask2d[v0:v1, u0:u1].sum()) if u1 > u0 and v1 > v0 else 0


def masks_2d(rig: Rig, flat: np.ndarray) -> list[np.ndarray]:
    out, start = [], 0
    for cam in rig.cameras:
        out.append(flat[start : start + cam.width * cam.height].reshape(cam.height, cam.width))
        start += cam.width * cam.height
    return out


@wp.kernel
def _box_kernel(
    cams: wp.array(dtype=kcam.Camera),
    xy: wp.array(dtype=wp.vec2),
    hw: float,
    h: float,
    boxes: wp.array2d(dtype=wp.vec4),
    full: wp.array2d(dtype=wp.float32),
):
    c, i = wp.tid()
    b, f = kcov.person_box(cams[c], xy[i][0], xy[i][1], hw, h)
    boxes[c, i] = b
    full[c, i] = wp.float32(f)


def test_person_box_matches_numpy(device, rng):
    rig = make_rig()
    drig = DeviceRig(rig, device)
    xy = np.concatenate([rng.uniform(-0.5, 4.5, (200, 2)), [[-1.2, -1.2], [2.0, -3.0]]]).astype(np.float32)
    boxes = wp.zeros((2, len(xy)), dtype=wp.vec4, device=device)
    full = wp.zeros((2, len(xy)), dtype=wp.float32, device=device)
    wp.launch(
        _box_kernel,
        dim=(2, len(xy)),
        inputs=[drig.cams, wp.array(xy, dtype=wp.vec2, device=device), HW, HEIGHT],
        outputs=[boxes, full],
        device=device,
    )
    ref, ref_full = box_ref(rig, drig, xy.astype(np.float64), device)
    got = boxes.numpy()
    # the corners are the same float32 projections: equal but for a pixel where u + 0.5 lands on an integer
    assert np.mean(np.abs(got - ref) <= 1.0) == 1.0 and np.mean(got == ref) > 0.99
    np.testing.assert_allclose(full.numpy(), ref_full, rtol=1e-4, atol=1e-3)
    assert (ref_full == 0).any() and (ref_full > 0).sum() > 150  # some behind a camera, most seen
    assert np.all(got[..., 2] >= got[..., 0]) and np.all(got[..., 2] <= 96) and np.all(got[..., 3] <= 72)


def test_coverage_and_area_maps_match_numpy(device, rng):
    rig = make_rig()
    drig = DeviceRig(rig, device)
    flat = blob_masks(rig, rng)
    I = integral(rig, drig, flat, device)  # noqa: E741
    origin, cell, nx, ny = (-0.5, -0.5), 0.2, 25, 22
    cov = wp.zeros((2, nx * ny), dtype=wp.float32, device=device)
    area = wp.zeros((2, nx * ny), dtype=wp.float32, device=device)
    common = [wp.vec2(*origin), cell, nx, HW, HEIGHT, VIS, 1.0]
    wp.launch(kcov.coverage_kernel, dim=(2, nx * ny), inputs=[drig.cams, I, *common], outputs=[cov], device=device)
    wp.launch(kcov.box_area_kernel, dim=(2, nx * ny), inputs=[drig.cams, *common], outputs=[area], device=device)
    t = np.arange(nx * ny)
    xy = np.column_stack([origin[0] + cell * (t % nx + 0.5), origin[1] + cell * (t // nx + 0.5)])
    boxes, full = box_ref(rig, drig, xy.astype(np.float32).astype(np.float64), device)
    masks = masks_2d(rig, flat)
    for c in range(2):
        a = (boxes[c, :, 2] - boxes[c, :, 0]) * (boxes[c, :, 3] - boxes[c, :, 1])
        seen = (full[c] > 0) & (a > 0) & (a >= VIS * full[c])
        ref_area = np.where(seen, a, -1.0)
        ref_cov = np.array(
            [count_ref(masks[c], b) / aa if s else -1.0 for b, aa, s in zip(boxes[c], a, seen, strict=True)]
        )
        same = np.isclose(area.numpy()[c], ref_area)  # a rounding tie can move an edge by a pixel
        assert same.mean() > 0.98 and seen.sum() > 100 and (~seen).sum() > 10
        np.testing.assert_allclose(cov.numpy()[c][same], ref_cov[same], rtol=1e-6, atol=1e-6)


def test_person_boxes_and_explained_mask(device, rng):
    rig = make_rig()
    drig = DeviceRig(rig, device)
    flat = blob_masks(rig, rng)
    people = rng.uniform(0.5, 3.5, (5, 2)).astype(np.float32)
    alive = np.array([1, 0, 1, 1, 0], np.int32)
    boxes = wp.zeros((5, 2), dtype=wp.vec4, device=device)
    wp.launch(
        kcov.person_boxes_kernel,
        dim=(5, 2),
        inputs=[drig.cams, wp.array(people, dtype=wp.vec2, device=device), wp.array(alive, device=device), HW, HEIGHT],
        outputs=[boxes],
        device=device,
    )
    ref, _ = box_ref(rig, drig, people.astype(np.float64), device)
    got = boxes.numpy()
    assert np.all(got[alive == 0] == 0)
    assert np.all(np.abs(got[alive == 1] - ref.transpose(1, 0, 2)[alive == 1]) <= 1.0)
    free = wp.zeros(len(flat), dtype=wp.uint8, device=device)
    wp.launch(
        kcov.explained_mask_kernel,
        dim=(2, 72, 96),
        inputs=[drig.cams, wp.array(flat, dtype=wp.uint8, device=device), boxes, 5],
        outputs=[free],
        device=device,
    )
    expect = [m.copy() for m in masks_2d(rig, flat)]
    for c in range(2):
        for b in got[:, c]:
            u0, v0, u1, v1 = (int(v) for v in b)
            expect[c][v0:v1, u0:u1] = 0
    np.testing.assert_array_equal(free.numpy(), np.concatenate([e.reshape(-1) for e in expect]))
    assert free.numpy().sum() < flat.sum()


@wp.kernel
def _terms_kernel(
    cams: wp.array(dtype=kcam.Camera),
    integral: wp.array(dtype=wp.int32),
    others: wp.array(dtype=wp.vec2),
    alive: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    terms: kcov.PersonTerms,
    points: wp.array(dtype=wp.vec3),
    out: wp.array(dtype=wp.float32),
):
    i = wp.tid()
    out[i] = wp.float32(kcov.person_log_terms(cams, integral, others, alive, boxes, own, terms, points[i]))


@wp.kernel
def _counts_kernel(
    cams: wp.array(dtype=kcam.Camera),
    integral: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    points: wp.array(dtype=wp.vec3),
    out: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    on, area, full = kcov.box_counts_left(cams, integral, boxes, own, points[i], HW, HEIGHT, VIS, 1.0)
    out[i] = wp.vec3(on, area, full)


def make_terms(slope=0.02, offset=0.004, radius=0.4, weight=5.0) -> kcov.PersonTerms:
    t = kcov.PersonTerms()
    t.half_width, t.height, t.min_visible, t.unit = HW, HEIGHT, VIS, 1.0
    t.slope, t.offset = slope, offset
    t.exclusion_radius, t.exclusion_weight = radius, weight
    return t


@pytest.mark.parametrize(("slope", "weight"), [(0.02, 0.0), (0.0, 5.0), (0.02, 5.0)])
def test_person_log_terms_match_numpy(device, rng, slope, weight):
    """The rectangle term counts only what the other people's rectangles leave (their overlaps subtracted, floored
    at 0); the exclusion term penalises closeness to the other living people; each off when its weight is 0."""
    rig = make_rig()
    drig = DeviceRig(rig, device)
    flat = blob_masks(rig, rng)
    I = integral(rig, drig, flat, device)  # noqa: E741
    others = rng.uniform(0.5, 3.5, (4, 2)).astype(np.float32)
    alive = np.array([1, 1, 0, 1], np.int32)
    own = 1
    boxes = wp.zeros((4, 2), dtype=wp.vec4, device=device)
    wp.launch(
        kcov.person_boxes_kernel,
        dim=(4, 2),
        inputs=[drig.cams, wp.array(others, dtype=wp.vec2, device=device), wp.array(alive, device=device), HW, HEIGHT],
        outputs=[boxes],
        device=device,
    )
    pts = np.column_stack([rng.uniform(0.0, 4.0, (300, 2)), rng.uniform(0, 1.8, 300)]).astype(np.float32)
    pts[:20, :2] = others[rng.integers(0, 4, 20)] + rng.normal(0, 0.2, (20, 2))  # some near the others
    terms = make_terms(slope=slope, weight=weight)
    out = wp.zeros(len(pts), dtype=wp.float32, device=device)
    wp.launch(
        _terms_kernel,
        dim=len(pts),
        inputs=[drig.cams, I, wp.array(others, dtype=wp.vec2, device=device), wp.array(alive, device=device)]
        + [boxes, own, terms, wp.array(pts, dtype=wp.vec3, device=device)],
        outputs=[out],
        device=device,
    )
    counts = wp.zeros(len(pts), dtype=wp.vec3, device=device)
    wp.launch(
        _counts_kernel,
        dim=len(pts),
        inputs=[drig.cams, I, boxes, own, wp.array(pts, dtype=wp.vec3, device=device)],
        outputs=[counts],
        device=device,
    )
    mine, full = box_ref(rig, drig, pts[:, :2].astype(np.float64), device)
    obox = boxes.numpy()
    masks = masks_2d(rig, flat)
    ref = np.zeros(len(pts))
    ref_counts = np.zeros((len(pts), 3))
    for i in range(len(pts)):
        if slope:
            for c in range(2):
                b = mine[c, i]
                area = (b[2] - b[0]) * (b[3] - b[1])
                if not (full[c, i] > 0 and area > 0 and area >= VIS * full[c, i]):
                    continue
                ref_counts[i, 2] += area
                on = count_ref(masks[c], b)
                for k in range(4):
                    if k == own:
                        continue
                    s = np.array([max(b[0], obox[k, c, 0]), max(b[1], obox[k, c, 1])] + [0, 0], dtype=np.float64)
                    s[2], s[3] = min(b[2], obox[k, c, 2]), min(b[3], obox[k, c, 3])
                    if s[2] > s[0] and s[3] > s[1]:
                        on -= count_ref(masks[c], s)
                        area -= (s[2] - s[0]) * (s[3] - s[1])
                ref[i] += slope * max(on, 0) - 0.004 * max(area, 0)
                ref_counts[i, :2] += (max(on, 0), max(area, 0))
        if weight:
            for k in range(4):
                if k != own and alive[k]:
                    d2 = np.sum((pts[i, :2].astype(np.float64) - others[k]) ** 2)
                    if d2 < 0.16:
                        ref[i] -= weight * (1 - d2 / 0.16)
    got = out.numpy()
    ok = np.isclose(got, ref, rtol=1e-4, atol=1e-3)
    assert ok.mean() > 0.97  # a rectangle edge on a rounding tie moves a pixel column
    if slope:
        same = np.all(np.isclose(counts.numpy(), ref_counts), axis=1)
        assert same.mean() > 0.97 and (ref_counts[:, 1] < ref_counts[:, 2]).sum() >= 5  # some rectangles shared
    if weight:
        assert (ref < -0.5).sum() >= 5
    if slope:
        assert (ref > 0).sum() >= 5 and (ref < 0).sum() >= 5


@pytest.mark.parametrize("dt", [0.04, 0.32])
def test_gate_picks_the_best_point_within_reach_and_shifts(device, rng, dt):
    """The gate's support is the best coverage of what the others leave of the rectangle (where that is at least
    ``min_left`` of it) on the grid of ``spacing`` within ``reach + speed dt`` of the person's last position (a slower
    frame rate searches farther); observe[1] takes the old observe[0]. The same support bit for bit whether one lane
    or a block of 64 (fewer than the 169 points of the slower frame rate: lanes take several) shares the points."""
    rig = make_rig()
    drig = DeviceRig(rig, device)
    flat = blob_masks(rig, rng)
    I = integral(rig, drig, flat, device)  # noqa: E741
    people = rng.uniform(1.0, 3.0, (3, 2)).astype(np.float32)
    alive = wp.array(np.array([1, 1, 1], np.int32), device=device)
    pdev = wp.array(people, dtype=wp.vec2, device=device)
    boxes = wp.zeros((3, 2), dtype=wp.vec4, device=device)
    wp.launch(
        kcov.person_boxes_kernel,
        dim=(3, 2),
        inputs=[drig.cams, pdev, alive, HW, HEIGHT],
        outputs=[boxes],
        device=device,
    )
    terms = make_terms(weight=0.0)
    reach, speed, spacing, min_left = 0.25, 1.5, 0.125, 0.25
    m = int(np.ceil((reach + speed * np.float32(dt)) / spacing))
    grid = [(a, b) for a in range(-m, m + 1) for b in range(-m, m + 1)]
    assert len(grid) == (49 if dt < 0.1 else 169)
    pts = np.array([[people[0, 0] + spacing * a, people[0, 1] + spacing * b, 0.0] for a, b in grid], np.float32)
    counts = wp.zeros(len(pts), dtype=wp.vec3, device=device)
    wp.launch(
        _counts_kernel,
        dim=len(pts),
        inputs=[drig.cams, I, boxes, 0, wp.array(pts, dtype=wp.vec3, device=device)],
        outputs=[counts],
        device=device,
    )
    c = counts.numpy().astype(np.float64)
    ok = (c[:, 1] > 0) & (c[:, 1] >= min_left * c[:, 2])
    best = float(np.max(np.where(ok, c[:, 0] / np.maximum(c[:, 1], 1), 0.0)))
    assert 0 < best < 1
    dt_dev = wp.array([dt], dtype=wp.float32, device=device)
    supports = []
    for block in (1, 64):
        for threshold, expect in ((best - 0.01, 1), (best + 0.01, 0)):
            observe = wp.array(np.array([7, 5], np.int32), device=device)
            support = wp.zeros(1, dtype=wp.float32, device=device)
            wp.launch_tiled(
                kcov.gate_kernel,
                dim=[1],
                inputs=[drig.cams, I, boxes, pdev, 0, terms, reach, speed, dt_dev, spacing, threshold, min_left, 0, 0],
                outputs=[observe, support],
                block_dim=block,
                device=device,
            )
            np.testing.assert_array_equal(observe.numpy(), [expect, 7])  # [1] takes the old [0]
            assert support.numpy()[0] == pytest.approx(best, rel=1e-5, abs=1e-6)
            supports.append(support.numpy()[0])
        off = make_terms(slope=0.0)
        observe = wp.array(np.array([0, 0], np.int32), device=device)
        support = wp.full(1, 5.0, dtype=wp.float32, device=device)
        wp.launch_tiled(
            kcov.gate_kernel,
            dim=[1],
            inputs=[drig.cams, I, boxes, pdev, 0, off, reach, speed, dt_dev, spacing, 0.99, min_left, 0, 0],
            outputs=[observe, support],
            block_dim=block,
            device=device,
        )
        np.testing.assert_array_equal(observe.numpy(), [1, 0])  # the term off: always seen
        assert support.numpy()[0] == 0.0
    assert len(set(supports)) == 1  # a maximum: the lanes' split does not change it


def test_person_histograms_match_numpy(device, rng):
    rig = make_rig()
    drig = DeviceRig(rig, device)
    flat = blob_masks(rig, rng)
    bgr = np.concatenate([rng.integers(0, 256, (c.height * c.width * 3,), dtype=np.uint8) for c in rig.cameras])
    people = np.array([[1.5, 1.5], [2.6, 2.0], [2.0, 3.0]], np.float32)
    boxes = wp.zeros((3, 2), dtype=wp.vec4, device=device)
    wp.launch(
        kcov.person_boxes_kernel,
        dim=(3, 2),
        inputs=[
            drig.cams,
            wp.array(people, dtype=wp.vec2, device=device),
            wp.array(np.ones(3, np.int32), device=device),
        ]
        + [HW, HEIGHT],
        outputs=[boxes],
        device=device,
    )
    nb = int(kcov.HIST_BINS)
    hist = wp.zeros((3, 2, 2, nb + 1), dtype=wp.float32, device=device)
    wp.launch(
        kcov.person_histogram_kernel,
        dim=(3, 2, 2, 72),
        inputs=[drig.cams, wp.array(bgr, dtype=wp.uint8, device=device), wp.array(flat, dtype=wp.uint8, device=device)]
        + [boxes],
        outputs=[hist],
        device=device,
    )
    got = hist.numpy()
    b = boxes.numpy()
    masks = masks_2d(rig, flat)
    nh, ns = int(kcov.HIST_H), int(kcov.HIST_S)
    offs = [0, rig[0].width * rig[0].height]
    for i in range(3):
        for c, cam in enumerate(rig.cameras):
            u0, v0, u1, v1 = b[i, c]
            h = v1 - v0
            for part, (a, z) in enumerate(((v0 + 0.5 * h, v1 - 0.05 * h), (v0, v0 + 0.5 * h))):
                ref = np.zeros(nb + 1)
                for v in range(int(a), int(z)):
                    for u in range(int(u0), int(u1)):
                        if not masks[c][v, u]:
                            continue
                        if any(
                            k != i and b[k, c, 0] <= u < b[k, c, 2] and b[k, c, 1] <= v < b[k, c, 3] for k in range(3)
                        ):
                            continue
                        p = 3 * (offs[c] + v * cam.width + u)
                        hh, ss, vv = colorsys.rgb_to_hsv(bgr[p + 2] / 255, bgr[p + 1] / 255, bgr[p] / 255)
                        if ss >= 0.2 and vv >= 0.15:
                            ref[min(int(hh * nh), nh - 1)] += 1
                        ref[nh + min(int(ss * ns), ns - 1)] += 1
                        ref[nh + ns + min(int(vv * 4), 3)] += 1
                        ref[nb] += 1
                # a hue or a value on a bin edge may round the other way in float32
                assert np.abs(got[i, c, part] - ref).sum() <= 4, (i, c, part)
                assert got[i, c, part, nb] == ref[nb]
    assert got[..., nb].sum() > 50


@pytest.mark.parametrize("scale", [2, 3])
def test_reduced_masks_count_blocks_and_their_rectangles_scale(device, rng, scale):
    """The reduced masks hold the motion pixels of each scale x scale block (the remainder columns and rows left
    out), and a person's rectangle projected with the reduced camera is the full rectangle divided by the scale
    (to the pixel): the coverage counted on blocks matches the full-size coverage."""
    from wptrack.trackers.people.tracker import reduced_camera

    rig = make_rig()
    drig = DeviceRig(rig, device)
    small_rig = Rig(tuple(reduced_camera(c, scale) for c in rig.cameras))
    sdrig = DeviceRig(small_rig, device)
    flat = blob_masks(rig, rng)
    small = wp.zeros(sdrig.total_pixels, dtype=wp.uint8, device=device)
    dims = (2, max(c.height for c in small_rig.cameras), max(c.width for c in small_rig.cameras))
    wp.launch(
        kcov.downsample_mask_kernel,
        dim=dims,
        inputs=[drig.cams, wp.array(flat, dtype=wp.uint8, device=device), scale, sdrig.cams],
        outputs=[small],
        device=device,
    )
    got = small.numpy()
    for c, (full_m, scam) in enumerate(zip(masks_2d(rig, flat), small_rig.cameras, strict=True)):
        h, w = scam.height, scam.width
        ref = full_m[: h * scale, : w * scale].reshape(h, scale, w, scale).sum(axis=(1, 3))
        off = sdrig.pixel_offsets[c]
        np.testing.assert_array_equal(got[off : off + h * w].reshape(h, w), ref)
    xy = rng.uniform(0.5, 3.5, (60, 2))
    full_boxes, _ = box_ref(rig, drig, xy, device)
    small_boxes, small_full = box_ref(small_rig, sdrig, xy, device)
    seen = small_full > 0
    assert seen.sum() > 60
    err = np.abs(small_boxes * scale - full_boxes)[seen]
    assert np.median(err) <= scale and err.max() <= 2 * scale  # rounding to blocks, and the clipped remainder
    # coverage counted on blocks (unit = scale^2 pixels per block) against the full-size count
    I_full = integral(rig, drig, flat, device)
    I_small = integral(small_rig, sdrig, got, device)
    origin, cell, nx, ny = (0.5, 0.5), 0.25, 12, 12
    covs = []
    for cams, I, unit in ((drig.cams, I_full, 1.0), (sdrig.cams, I_small, float(scale * scale))):  # noqa: E741
        cov = wp.zeros((2, nx * ny), dtype=wp.float32, device=device)
        wp.launch(
            kcov.coverage_kernel,
            dim=(2, nx * ny),
            inputs=[cams, I, wp.vec2(*origin), cell, nx, HW, HEIGHT, VIS, unit],
            outputs=[cov],
            device=device,
        )
        covs.append(cov.numpy())
    both = (covs[0] >= 0) & (covs[1] >= 0)
    assert both.sum() > 100
    assert np.median(np.abs(covs[0] - covs[1])[both]) < 0.03


def test_left_mask_and_left_coverage_match_numpy(device, rng):
    """The part of a candidate's rectangle the tracked people's rectangles leave (left_mask_kernel's map, counted
    with its integral image) and the unexplained motion's coverage of that part (left_coverage_kernel), against
    NumPy, on blocks of 2 x 2 pixels (``unit`` 4: the free mask holds block counts, the left map one per block)."""
    rig = make_rig()
    drig = DeviceRig(rig, device)
    flat = blob_masks(rig, rng)
    people = rng.uniform(0.5, 3.5, (4, 2)).astype(np.float32)
    alive = np.array([1, 1, 0, 1], np.int32)
    boxes = wp.zeros((4, 2), dtype=wp.vec4, device=device)
    wp.launch(
        kcov.person_boxes_kernel,
        dim=(4, 2),
        inputs=[drig.cams, wp.array(people, dtype=wp.vec2, device=device), wp.array(alive, device=device), HW, HEIGHT],
        outputs=[boxes],
        device=device,
    )
    free = wp.zeros(len(flat), dtype=wp.uint8, device=device)
    wp.launch(
        kcov.explained_mask_kernel,
        dim=(2, 72, 96),
        inputs=[drig.cams, wp.array(flat, dtype=wp.uint8, device=device), boxes, 4],
        outputs=[free],
        device=device,
    )
    left = wp.zeros(len(flat), dtype=wp.uint8, device=device)
    wp.launch(kcov.left_mask_kernel, dim=(2, 72, 96), inputs=[drig.cams, boxes, 4], outputs=[left], device=device)
    got_boxes = boxes.numpy()
    expect_left = [np.ones((c.height, c.width), np.uint8) for c in rig.cameras]
    for c in range(2):
        for b in got_boxes[:, c]:
            u0, v0, u1, v1 = (int(v) for v in b)
            expect_left[c][v0:v1, u0:u1] = 0
    np.testing.assert_array_equal(left.numpy(), np.concatenate([e.reshape(-1) for e in expect_left]))
    assert 0 < left.numpy().sum() < len(flat)
    # pretend the masks were block sums of 2 x 2 pixels: the free mask's pixels hold up to 4, the areas count blocks
    free4 = wp.array(free.numpy() * 4, dtype=wp.uint8, device=device)
    If, Il = integral(rig, drig, free4.numpy(), device), integral(rig, drig, left.numpy(), device)
    origin, cell, nx, ny, unit = (-0.5, -0.5), 0.2, 25, 22, 4.0
    cov = wp.zeros((2, nx * ny), dtype=wp.float32, device=device)
    part = wp.zeros((2, nx * ny), dtype=wp.float32, device=device)
    wp.launch(
        kcov.left_coverage_kernel,
        dim=(2, nx * ny),
        inputs=[drig.cams, If, Il, wp.vec2(*origin), cell, nx, HW, HEIGHT, VIS, unit],
        outputs=[cov, part],
        device=device,
    )
    t = np.arange(nx * ny)
    xy = np.column_stack([origin[0] + cell * (t % nx + 0.5), origin[1] + cell * (t // nx + 0.5)])
    cboxes, full = box_ref(rig, drig, xy.astype(np.float32).astype(np.float64), device)
    fmask = masks_2d(rig, free4.numpy())
    checked = hidden = 0
    for c in range(2):
        a = (cboxes[c, :, 2] - cboxes[c, :, 0]) * (cboxes[c, :, 3] - cboxes[c, :, 1])
        seen = (full[c] > 0) & (a > 0) & (a >= VIS * full[c])
        rest = np.array([count_ref(expect_left[c], b) for b in cboxes[c]], np.float64)
        on = np.array([count_ref(fmask[c], b) for b in cboxes[c]], np.float64)
        ref_part = np.where(seen, rest / np.maximum(a, 1), -1.0)
        ref_cov = np.where(seen, np.where(rest > 0, on / np.maximum(rest * unit, 1), 0.0), -1.0)
        same = np.isclose(part.numpy()[c], ref_part, atol=1e-6)  # a rounding tie can move an edge by a pixel
        assert same.mean() > 0.97 and seen.sum() > 100
        np.testing.assert_allclose(cov.numpy()[c][same], ref_cov[same], rtol=1e-5, atol=1e-6)
        checked += int((same & seen).sum())
        hidden += int((same & seen & (ref_part < 0.5)).sum())
    assert checked > 200 and hidden > 5  # some candidates are half hidden by the tracked people


@wp.kernel
def _camera_counts_kernel(
    cams: wp.array(dtype=kcam.Camera),
    integral: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    points: wp.array(dtype=wp.vec3),
    out: wp.array2d(dtype=wp.vec4),
):
    i, c = wp.tid()
    seen, on, area, full = kcov.camera_counts_left(cams[c], c, integral, boxes, own, points[i], HW, HEIGHT, VIS)
    out[i, c] = wp.vec4(float(seen), on, area, full)


def _three_people(device, rng):
    """The two-camera rig with blob masks, their integral images and three people's rectangles (``person_boxes``)."""
    rig = make_rig()
    drig = DeviceRig(rig, device)
    flat = blob_masks(rig, rng)
    I = integral(rig, drig, flat, device)  # noqa: E741
    people = rng.uniform(1.0, 3.0, (3, 2)).astype(np.float32)
    pdev = wp.array(people, dtype=wp.vec2, device=device)
    boxes = wp.zeros((3, 2), dtype=wp.vec4, device=device)
    wp.launch(
        kcov.person_boxes_kernel,
        dim=(3, 2),
        inputs=[drig.cams, pdev, wp.array(np.ones(3, np.int32), device=device), HW, HEIGHT],
        outputs=[boxes],
        device=device,
    )
    return rig, drig, flat, I, people, pdev, boxes


@pytest.mark.parametrize("k", [1, 2, 3])
def test_gate_per_camera_takes_the_kth_camera(device, rng, k):
    """``cameras`` = k: the gate's support is the best, over its grid points, of the k-th largest coverage among the
    cameras that judge the point (what the others leave of the rectangle there is at least ``min_left`` of it), 0
    where fewer than k judge (k = 3 with two cameras: never seen); the per-camera counts add up to the pooled
    ones (``box_counts_left``)."""
    rig, drig, flat, I, people, pdev, boxes = _three_people(device, rng)  # noqa: E741
    reach, speed, spacing, min_left, dt = 0.25, 1.5, 0.125, 0.25, 0.04
    m = int(np.ceil((reach + speed * np.float32(dt)) / spacing))
    pts = np.array(
        [
            [people[0, 0] + spacing * a, people[0, 1] + spacing * b, 0.0]
            for a in range(-m, m + 1)
            for b in range(-m, m + 1)
        ],
        np.float32,
    )
    pts_dev = wp.array(pts, dtype=wp.vec3, device=device)
    per = wp.zeros((len(pts), 2), dtype=wp.vec4, device=device)
    wp.launch(
        _camera_counts_kernel, dim=(len(pts), 2), inputs=[drig.cams, I, boxes, 0, pts_dev], outputs=[per], device=device
    )
    pooled = wp.zeros(len(pts), dtype=wp.vec3, device=device)
    wp.launch(_counts_kernel, dim=len(pts), inputs=[drig.cams, I, boxes, 0, pts_dev], outputs=[pooled], device=device)
    p = per.numpy().astype(np.float64)  # (points, cameras, [seen, on, area, full])
    np.testing.assert_allclose(p[..., 1].sum(1), pooled.numpy()[:, 0], rtol=1e-6)
    np.testing.assert_allclose(p[..., 2].sum(1), pooled.numpy()[:, 1], rtol=1e-6)
    np.testing.assert_allclose(p[..., 3].sum(1), pooled.numpy()[:, 2], rtol=1e-6)
    judge = (p[..., 0] > 0) & (p[..., 2] > 0) & (p[..., 2] >= min_left * p[..., 3])
    cov = np.where(judge, p[..., 1] / np.maximum(p[..., 2], 1), -np.inf)
    ranked = -np.sort(-cov, axis=1)  # largest first
    kth = ranked[:, k - 1] if k <= 2 else np.full(len(pts), -np.inf)
    best = float(np.max(np.where(np.isfinite(kth), kth, 0.0)))
    assert (judge.sum(1) == 2).any() and (judge.sum(1) < 2).any() or k == 3
    if k < 3:
        assert 0 < best < 1
    terms = make_terms(weight=0.0)
    dt_dev = wp.array([dt], dtype=wp.float32, device=device)
    threshold = best - 0.01 if k < 3 else 0.01
    got = []
    for block in (1, 64):
        observe = wp.array(np.array([7, 5], np.int32), device=device)
        support = wp.zeros(1, dtype=wp.float32, device=device)
        wp.launch_tiled(
            kcov.gate_kernel,
            dim=[1],
            inputs=[drig.cams, I, boxes, pdev, 0, terms, reach, speed, dt_dev, spacing, threshold, min_left, k, 0],
            outputs=[observe, support],
            block_dim=block,
            device=device,
        )
        assert support.numpy()[0] == pytest.approx(best, rel=1e-5, abs=1e-6)
        assert observe.numpy()[0] == (1 if k < 3 else 0)
        got.append(support.numpy()[0])
    assert got[0] == got[1]
    if k == 2:  # the second camera's coverage is below the pooled one somewhere: the rule is stricter
        pooled_best = np.max(np.where(judge.any(1), pooled.numpy()[:, 0] / np.maximum(pooled.numpy()[:, 1], 1), 0))
        assert best < pooled_best


def test_balanced_rectangle_term_weights_each_camera_by_its_own_rectangle(device, rng):
    """``PersonTerms.balance``: each camera's rectangle term (what the others leave of the rectangle, as in the
    pooled term) is weighted by the mean area of the person's own rectangles over the cameras divided by its own in
    that camera (1 where its own is empty), against NumPy from the per-camera counts; off, the pooled term."""
    rig = make_rig()
    drig = DeviceRig(rig, device)
    flat = blob_masks(rig, rng)
    I = integral(rig, drig, flat, device)  # noqa: E741
    people = rng.uniform(0.5, 3.5, (4, 2)).astype(np.float32)
    own = 1
    people[own] = (1.0, 3.2)  # nearer camera a than camera b: its rectangles differ in size
    boxes = wp.zeros((4, 2), dtype=wp.vec4, device=device)
    alive = wp.array(np.ones(4, np.int32), device=device)
    pdev = wp.array(people, dtype=wp.vec2, device=device)
    wp.launch(
        kcov.person_boxes_kernel,
        dim=(4, 2),
        inputs=[drig.cams, pdev, alive, HW, HEIGHT],
        outputs=[boxes],
        device=device,
    )
    pts = np.column_stack([people[own] + rng.normal(0, 0.4, (200, 2)), np.zeros(200)]).astype(np.float32)
    pts_dev = wp.array(pts, dtype=wp.vec3, device=device)
    per = wp.zeros((len(pts), 2), dtype=wp.vec4, device=device)
    wp.launch(
        _camera_counts_kernel,
        dim=(len(pts), 2),
        inputs=[drig.cams, I, boxes, own, pts_dev],
        outputs=[per],
        device=device,
    )
    p = per.numpy().astype(np.float64)
    ob = boxes.numpy()[own].astype(np.float64)
    a_own = (ob[:, 2] - ob[:, 0]) * (ob[:, 3] - ob[:, 1])
    assert np.all(a_own > 0) and max(a_own) > 1.5 * min(a_own)
    w = a_own.mean() / a_own
    slope, offset = 0.02, 0.004
    ref = np.sum(np.where(p[..., 0] > 0, w * (slope * p[..., 1] - offset * p[..., 2]), 0.0), axis=1)
    pooled_ref = np.sum(np.where(p[..., 0] > 0, slope * p[..., 1] - offset * p[..., 2], 0.0), axis=1)
    for balance, expect in ((1, ref), (0, pooled_ref)):
        terms = make_terms(slope=slope, offset=offset, weight=0.0)
        terms.balance = balance
        out = wp.zeros(len(pts), dtype=wp.float32, device=device)
        wp.launch(
            _terms_kernel,
            dim=len(pts),
            inputs=[drig.cams, I, pdev, alive, boxes, own, terms, pts_dev],
            outputs=[out],
            device=device,
        )
        np.testing.assert_allclose(out.numpy(), expect, rtol=1e-4, atol=1e-3)
    assert np.abs(ref - pooled_ref).max() > 0.1  # the weights matter


def test_gate_per_camera_use_splits_weighting_and_removal(device, rng):
    """``use`` = 1: the support (removal) is the per-camera one, the weighting decision pooled; ``use`` = 2 the other
    way round (k = 2, two cameras)."""
    rig, drig, flat, I, people, pdev, boxes = _three_people(device, rng)  # noqa: E741
    terms = make_terms(weight=0.0)
    dt_dev = wp.array([0.04], dtype=wp.float32, device=device)
    args = [drig.cams, I, boxes, pdev, 0, terms, 0.25, 1.5, dt_dev, 0.125]

    def gate(threshold, k, use):
        observe = wp.array(np.array([7, 5], np.int32), device=device)
        support = wp.zeros(1, dtype=wp.float32, device=device)
        wp.launch_tiled(
            kcov.gate_kernel,
            dim=[1],
            inputs=[*args, threshold, 0.25, k, use],
            outputs=[observe, support],
            block_dim=1,
            device=device,
        )
        return int(observe.numpy()[0]), float(support.numpy()[0])

    _, pooled = gate(0.5, 0, 0)
    _, per_camera = gate(0.5, 2, 0)
    assert 0 < per_camera < pooled - 0.01  # the second camera's coverage is below the pooled one
    t = 0.5 * (per_camera + pooled)
    assert gate(t, 2, 0) == (0, pytest.approx(per_camera))
    assert gate(t, 2, 1) == (1, pytest.approx(per_camera))  # weighted (pooled), support per camera
    assert gate(t, 2, 2) == (0, pytest.approx(pooled))  # not weighted (per camera), support pooled
    assert gate(t, 0, 2) == (1, pytest.approx(pooled))  # k = 0: pooled whatever use says
