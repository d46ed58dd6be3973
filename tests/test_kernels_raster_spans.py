"""``raster.hull_chain_span`` (a row's columns from the hull's two y-monotone chains, walks carried from row to row)
against ``raster.hull_span`` (every edge tested) on every device: identical columns, bit for bit, on the projected
hulls of random scenes and on hand-made hulls with vertices exactly on rows, horizontal top and bottom edges, both
orientations and degenerate one- and two-vertex hulls; rows visited upwards, downwards, in strided passes (the
lanes of a block) and at random (fresh walks at every row above the last). The NumPy reference for the columns
themselves is the float64 rasteriser of test_kernels_templates, through ``render_virtual_kernel`` (which uses the
chain walk)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp
from test_kernels_templates import PIECES, random_camera, random_scene, raster

from wptrack.cameras.rig import GroundPlane
from wptrack.kernels.templates import raster as kraster

HULL_MAX = int(kraster.HULL_MAX)


@wp.kernel
def chain_vs_full_kernel(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    order: wp.array(dtype=wp.int32),
    width: int,
    full: wp.array3d(dtype=wp.int32),
    chain: wp.array3d(dtype=wp.int32),
):
    """Per piece (i, q) and row y of ``order`` within its rows: ``full[i * Q + q, y] = (u0, u1)`` of
    ``hull_span`` and ``chain[...]`` of ``hull_chain_span``, its walks carried over ``order`` while the rows
    increase and started afresh when they do not."""
    i, q = wp.tid()
    m = hull_n[i, q]
    if m == 0:
        return
    r = hull_rows[i, q]
    p = i * hull_n.shape[1] + q
    down = int(0)  # noqa: UP018  (a mutable Warp loop variable)
    up = int(0)  # noqa: UP018
    last = int(-1)  # noqa: UP018
    for k in range(order.shape[0]):
        y = order[k]
        if y < last:  # a row above the last one: fresh walks
            down = 0
            up = 0
        last = y
        if y >= r[0] and y <= r[1]:
            a0, a1 = kraster.hull_span(hull_pts, i, q, m, float(y), width)
            b0, b1, down, up = kraster.hull_chain_span(hull_pts, i, q, m, float(y), width, down, up)
            full[p, y, 0] = a0
            full[p, y, 1] = a1
            chain[p, y, 0] = b0
            chain[p, y, 1] = b1


def orders(height: int, rng) -> dict[str, np.ndarray]:
    rows = np.arange(height, dtype=np.int32)
    return {
        "up": rows,
        "down": rows[::-1].copy(),
        "lanes3": np.concatenate([rows[k::3] for k in range(3)]),
        "lanes64": np.concatenate([rows[k::64] for k in range(64)]),
        "random": rng.permutation(rows).astype(np.int32),
    }


def compare(device, pts: np.ndarray, n: np.ndarray, rows: np.ndarray, width: int, height: int, rng) -> int:
    """Runs the kernel over every order; returns the number of (piece, row) pairs compared per order."""
    p, q = n.shape
    d_pts = wp.array(pts.astype(np.float32), dtype=wp.vec2, device=device)
    d_n = wp.array(n.astype(np.int32), dtype=wp.int32, device=device)
    d_rows = wp.array(rows.astype(np.int32), dtype=wp.vec2i, device=device)
    tested = 0
    for name, order in orders(height, rng).items():
        full = wp.full((p * q, height, 2), -9, dtype=wp.int32, device=device)
        chain = wp.full((p * q, height, 2), -9, dtype=wp.int32, device=device)
        wp.launch(
            chain_vs_full_kernel,
            dim=(p, q),
            inputs=[d_pts, d_n, d_rows, wp.array(order, dtype=wp.int32, device=device), width],
            outputs=[full, chain],
            device=device,
        )
        f, c = full.numpy(), chain.numpy()
        bad = np.argwhere(np.any(f != c, axis=2))
        assert len(bad) == 0, (
            f"order {name}: (piece, row) {bad[:5].tolist()} full {f[tuple(bad[0])]} chain {c[tuple(bad[0])]}"
        )
        tested = int(np.sum(f[..., 0] != -9))
    return tested


def test_chain_span_equals_full_span_on_projected_hulls(device, rng):
    """Hulls of random scenes on random distorted cameras: vertex 0 is the topmost, and the chain walk gives the
    columns of the edge scan on every row in every visiting order."""
    plane = GroundPlane()
    tested = 0
    for _ in range(3):
        cam = random_camera(rng)
        kind, pos, heading, dims = random_scene(rng, cam, plane, 24, 3)
        hulls = raster(device, cam, plane, kind, pos, heading, dims)
        pts, n, rows = hulls.pts.numpy(), hulls.n.numpy(), hulls.rows.numpy()
        for i, q in np.argwhere(n > 0):
            ys = pts[i, q, : n[i, q], 1]
            assert ys[0] == ys.min(), f"particle {i} piece {q}: vertex 0 is not the topmost"
        tested += compare(device, pts, n, rows, cam.width, cam.height, rng)
    assert tested > 2000


def polygon(xy, width: int, height: int, reverse: bool = False):
    """(pts (HULL_MAX, 2), n, rows) of a hand-made convex polygon started at its topmost vertex."""
    xy = np.asarray(xy, dtype=np.float64)
    if reverse:
        xy = xy[::-1]
    top = int(np.argmin(xy[:, 1]))
    xy = np.roll(xy, -top, axis=0)
    pts = np.zeros((HULL_MAX, 2))
    pts[: len(xy)] = xy
    row0 = max(int(np.ceil(xy[:, 1].min())), 0)
    row1 = min(int(np.floor(xy[:, 1].max())), height - 1)
    return pts, len(xy), (row0, row1)


def test_chain_span_equals_full_span_on_edge_cases(device, rng):
    """Vertices exactly on rows, horizontal top and bottom edges, thin slivers, both orientations, a 16-gon, and
    degenerate hulls of one and two vertices (a point, a segment, a horizontal segment)."""
    w, h = 64, 48
    shapes = [
        [(10, 5), (30, 5), (30, 20), (10, 20)],  # rectangle on rows: horizontal top and bottom
        [(20, 3), (35, 12), (28, 30), (8, 30), (4, 12)],  # flat bottom, vertices on rows
        [(20.5, 2.25), (40.75, 10.0), (22.0, 40.5), (3.5, 17.0)],
        [(5, 10), (60, 10.5), (6, 11)],  # sliver, top edge nearly horizontal
        [(32 + 20 * np.cos(a), 24 + 20 * np.sin(a)) for a in np.arange(16) * (2 * np.pi / 16)],
        [(1.5, 0.0), (62.5, 0.0), (62.5, 47.0), (1.5, 47.0)],  # touches the image borders
        [(-10.0, -3.0), (80.0, 10.0), (20.0, 60.0)],  # crosses every border
        [(12.0, 7.0)],  # a point on a row
        [(12.0, 7.0), (30.0, 25.0)],  # a segment
        [(12.0, 9.0), (30.0, 9.0)],  # a horizontal segment on a row
    ]
    polys = []
    for s in shapes:
        polys.append(polygon(s, w, h))
        polys.append(polygon(s, w, h, reverse=True))
        polys.append(polygon(np.asarray(s, dtype=np.float64) + rng.uniform(-0.5, 0.5, 2), w, h))
    pts = np.stack([p[0] for p in polys])[:, None]
    n = np.array([p[1] for p in polys])[:, None]
    rows = np.array([p[2] for p in polys])[:, None]
    assert compare(device, pts, n, rows, w, h, rng) > 500


@pytest.mark.parametrize("stride", [1, 5])
def test_row_intervals_walks_match_fresh_walks(device, rng, stride):
    """row_intervals with walks carried over a lane's rows (as xor_score_kernel calls it) returns the intervals of
    fresh walks on every row (as render_virtual_kernel calls it)."""
    plane = GroundPlane()
    cam = random_camera(rng)
    kind, pos, heading, dims = random_scene(rng, cam, plane, 16, 4)
    hulls = raster(device, cam, plane, kind, pos, heading, dims)
    out = wp.zeros((2, 16, cam.height, 2 * int(kraster.MAX_PIECES) + 1), dtype=wp.int32, device=device)
    wp.launch(
        intervals_kernel,
        dim=(16, stride),
        inputs=[hulls.pts, hulls.n, hulls.rows, 4 * PIECES, cam.width, stride],
        outputs=[out],
        device=device,
    )
    o = out.numpy()
    np.testing.assert_array_equal(o[0], o[1])
    assert o[0, :, :, 0].sum() > 200  # intervals were found


@wp.kernel
def intervals_kernel(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    pieces: int,
    width: int,
    stride: int,
    out: wp.array4d(dtype=wp.int32),
):
    i, lane = wp.tid()
    down = kraster.vec32i()
    up = kraster.vec32i()
    for y in range(lane, out.shape[2], stride):
        count, m0, m1, down, up = kraster.row_intervals(hull_pts, hull_n, hull_rows, i, pieces, y, width, down, up)
        c2, f0, f1, _d, _u = kraster.row_intervals(
            hull_pts, hull_n, hull_rows, i, pieces, y, width, kraster.vec32i(), kraster.vec32i()
        )
        out[0, i, y, 0] = count
        out[1, i, y, 0] = c2
        for k in range(count):
            out[0, i, y, 1 + 2 * k] = m0[k]
            out[0, i, y, 2 + 2 * k] = m1[k]
        for k in range(c2):
            out[1, i, y, 1 + 2 * k] = f0[k]
            out[1, i, y, 2 + 2 * k] = f1[k]
