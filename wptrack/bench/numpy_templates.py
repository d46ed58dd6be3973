"""Plain NumPy reference of the S3 template tracker's per-frame measurement (Juza et al., eqs. 4-6 and 10): the
baseline "NumPy on CPU" of ``wptrack/bench/templates.py``.

Given the particle state (kind, ground position, heading, dims, age per slot; shapes (N, R, ...)), a calibrated
camera and the ground plane, it

1. builds every template piece's vertices (the list of ``kernels/templates/raster.py``, re-implemented here; vectorised
   over
   all particles and slots),
2. projects them with the OpenCV pinhole + (k1, k2, p1, p2, k3) distortion model in float64 (the formula of
   ``cv2.projectPoints``, in NumPy; a piece with a vertex behind the camera or beyond the distortion fold radius
   ``r2_max`` is not drawn, as on the device),
3. takes each piece's convex hull (``cv2.convexHull`` on the projected points),
4. finds each piece's covered columns per row (a pixel is covered when its centre, at integer coordinates, lies in
   the closed hull: one span ``[ceil(x_left), floor(x_right)]`` per row, from the hull's edges; vectorised over all
   edges of all pieces), then fills the spans of each particle into a boolean image of the particle's bounding box
   (one loop over the particles), the union of its pieces being its virtual scene v_i,
5. counts the XOR penalty m_i = |q XOR v_i| (eq. 4), the complexity c_i = sum_r a_r + b_r exp(-tau_r) (eq. 5), the
   log-weight log w_i = prior - (m_i + c_i) s / (W H) (eq. 6), and the Uncovered Object Histogram UOH = q (N -
   coverage) (eq. 10), coverage being the number of particles whose v_i covers the pixel.

Everything is float64 (the device uses float32), so a pixel whose centre lies within ~1e-4 px of a hull edge may be
counted differently; elsewhere the penalties are equal integers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KIND_NONE, KIND_HUMAN, KIND_VEHICLE = 0, 1, 2
PIECES = 2
"""Convex pieces per object (human: legs, upper body with head; vehicle: lower body, cabin)."""
HULL_MAX = 16
"""Most vertices per piece."""
LOWER, CABIN_LENGTH, CABIN_WIDTH = 0.55, 0.6, 0.9
"""Vehicle proportions (``kernels.templates.raster``): lower body height, cabin length and width, as fractions."""
MIN_DEPTH = 1.0e-6
"""Camera depth (metres) at or below which a point is not seen (``kernels.core.camera.MIN_DEPTH``)."""


LEG_RATIO, HIP, SHOULDER = 0.65, 0.5, 2.5
"""Human proportions (``kernels.templates.raster``): leg radius / body radius, hip height / height, shoulders in head
radii below the top."""

_OCTAGON = (np.arange(16) % 8) * (2.0 * np.pi / 8.0)
_LEGS = np.stack([np.cos(_OCTAGON), np.sin(_OCTAGON), (np.arange(16) >= 8).astype(np.float64)], axis=1)
"""(16, 3) leg prism on the unit cylinder: (cos a, sin a, 0 bottom / 1 top), the bottom octagon then the top."""
_HEXAGON = (np.arange(12) % 6) * (2.0 * np.pi / 6.0)
_SQUARE = np.arange(4) * (0.5 * np.pi)
_BOX = np.array([[1 - 2 * (k % 2), 1 - 2 * ((k // 2) % 2), float(k >= 4)] for k in range(8)], dtype=np.float64)
"""(8, 3) box corners: (+-1 along the length, +-1 along the width, bottom 0 / top 1)."""


@dataclass
class TemplateMeasurement:
    """The measurement of one frame for N particles."""

    penalty: np.ndarray
    """(N,) int64 XOR matching penalty m_i, pixels (eq. 4)."""
    complexity: np.ndarray
    """(N,) float64 complexity penalty c_i, pixels (eq. 5)."""
    logw: np.ndarray
    """(N,) float64 log-weights: prior - (m_i + c_i) s / (W H) (eq. 6)."""
    uoh: np.ndarray
    """(H, W) int64 Uncovered Object Histogram (eq. 10)."""
    foreground: int
    """|q|, foreground pixels of the mask."""


class NumpyTemplateScorer:
    """NumPy reference of eqs. 4-6 and 10 for one camera and a ground plane.

    Args:
        camera: ``wptrack.cameras.rig.Camera`` (K, dist, R, t, width, height).
        plane: ``wptrack.cameras.rig.GroundPlane`` (origin, x_axis, y_axis, normal).
        cost_a, cost_b: a_r and b_r of eq. 5 per kind, indexed by KIND_* (index 0 unused), pixels.
        scale: s of eq. 6 (the log-weight is ``-(m + c) s / (W H)``).
        r2_max: squared normalised radius beyond which a point is "not seen" (``warpcams.camera_struct``); inf to
            project everything in front of the camera.
        bg_weight: lambda of the weighted penalty ``|q AND NOT v| + lambda |v AND NOT q|`` in the log-weight.
        exclusion: cost of two objects' ground overlap, pixels per pair (``kernels.templates.xor.pair_overlap``).
    """

    def __init__(
        self,
        camera,
        plane,
        cost_a: tuple[float, float, float],
        cost_b: tuple[float, float, float],
        scale: float,
        r2_max: float = float("inf"),
        bg_weight: float = 1.0,
        exclusion: float = 0.0,
    ) -> None:
        self.bg_weight = float(bg_weight)
        self.exclusion = float(exclusion)
        self.width, self.height = int(camera.width), int(camera.height)
        self.R = np.asarray(camera.R, dtype=np.float64)
        self.t = np.asarray(camera.t, dtype=np.float64)
        self.fx, self.fy, self.cx, self.cy = float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy)
        self.k1, self.k2, self.p1, self.p2, self.k3 = (float(v) for v in np.asarray(camera.dist).reshape(-1)[:5])
        self.origin = np.asarray(plane.origin, dtype=np.float64)
        self.e1 = np.asarray(plane.x_axis, dtype=np.float64)
        self.e2 = np.asarray(plane.y_axis, dtype=np.float64)
        self.normal = np.asarray(plane.normal, dtype=np.float64)
        self.cost_a = np.asarray(cost_a, dtype=np.float64)
        self.cost_b = np.asarray(cost_b, dtype=np.float64)
        self.scale = float(scale)
        self.r2_max = float(r2_max)

    @classmethod
    def for_tracker(cls, tracker) -> NumpyTemplateScorer:
        """The reference for a ``TemplateTracker``'s camera, ground plane, eq. 5 costs, eq. 6 scale and fold radius."""
        cfg = tracker.config
        return cls(
            tracker.camera,
            tracker.plane,
            (0.0, cfg.human.cost_a, cfg.vehicle.cost_a),
            (0.0, cfg.human.cost_b, cfg.vehicle.cost_b),
            cfg.scale,
            r2_max=float(tracker.cam.r2_max),
            bg_weight=cfg.bg_weight,
            exclusion=cfg.exclusion,
        )

    # --- geometry ------------------------------------------------------------------------------------------
    @staticmethod
    def vertices(kind: np.ndarray, dims: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Piece vertices in each object's frame (along e1, along e2, height), metres.

        Args:
            kind: (...,) KIND_*. dims: (..., 3) metres. heading: (...,) radians.

        Returns:
            ``(verts, count)``: (..., PIECES, HULL_MAX, 3) float64 (unused rows zero) and (..., PIECES) int vertex
            counts (0 for empty slots).
        """
        kind = np.asarray(kind)
        dims = np.asarray(dims, dtype=np.float64)
        heading = np.asarray(heading, dtype=np.float64)
        shape = kind.shape
        verts = np.zeros((*shape, PIECES, HULL_MAX, 3))
        count = np.zeros((*shape, PIECES), dtype=np.int64)
        human = kind == KIND_HUMAN
        if np.any(human):
            d = dims[human]
            height, body_r, head_r = d[:, 0:1], d[:, 1:2], d[:, 2:3]
            hip = HIP * height
            legs = np.stack(
                [LEG_RATIO * body_r * _LEGS[:, 0], LEG_RATIO * body_r * _LEGS[:, 1], hip * _LEGS[:, 2]], axis=-1
            )
            shoulder = np.maximum(height - SHOULDER * head_r, hip)
            ring_z = np.where(np.arange(12) >= 6, shoulder, hip)
            upper = np.concatenate(
                [
                    np.stack([body_r * np.cos(_HEXAGON), body_r * np.sin(_HEXAGON), ring_z], axis=-1),
                    np.stack([head_r * np.cos(_SQUARE), head_r * np.sin(_SQUARE), np.repeat(height, 4, axis=1)], -1),
                ],
                axis=1,
            )
            v = np.zeros((len(d), PIECES, HULL_MAX, 3))
            v[:, 0, :16] = legs
            v[:, 1, :16] = upper
            verts[human] = v
            count[human] = (16, 16)
        vehicle = kind == KIND_VEHICLE
        if np.any(vehicle):
            d = dims[vehicle]
            a = heading[vehicle]
            hl, hw, hh = 0.5 * d[:, 0:1], 0.5 * d[:, 1:2], d[:, 2:3]
            v = np.zeros((len(d), PIECES, HULL_MAX, 3))
            for piece, (fl, fw, z0, z1) in enumerate(((1.0, 1.0, 0.0, LOWER), (CABIN_LENGTH, CABIN_WIDTH, LOWER, 1.0))):
                lx = fl * hl * _BOX[:, 0]
                ly = fw * hw * _BOX[:, 1]
                z = hh * (z0 + (z1 - z0) * _BOX[:, 2])
                ca, sa = np.cos(a)[:, None], np.sin(a)[:, None]
                v[:, piece, :8] = np.stack([ca * lx - sa * ly, sa * lx + ca * ly, z], axis=-1)
            verts[vehicle] = v
            count[vehicle] = 8
        return verts, count

    def project(self, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """OpenCV projection (k1, k2, p1, p2, k3) of world points (..., 3): ``(uv (..., 2), seen (...,))``.

        ``seen`` is False behind the camera (depth <= 1e-6 m) or beyond the fold radius ``r2_max``."""
        xc = world @ self.R.T + self.t
        z = xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            a = xc[..., 0] / z
            b = xc[..., 1] / z
        r2 = a * a + b * b
        seen = (z > MIN_DEPTH) & (r2 <= self.r2_max)
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        ad = a * radial + 2.0 * self.p1 * a * b + self.p2 * (r2 + 2.0 * a * a)
        bd = b * radial + self.p1 * (r2 + 2.0 * b * b) + 2.0 * self.p2 * a * b
        uv = np.stack([self.fx * ad + self.cx, self.fy * bd + self.cy], axis=-1)
        return np.where(seen[..., None], uv, 0.0), seen

    def hulls(
        self, kind: np.ndarray, pos: np.ndarray, heading: np.ndarray, dims: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Image hulls of every piece of every particle.

        Args:
            kind: (N, R). pos: (N, R, 2) ground coordinates, metres. heading: (N, R) radians. dims: (N, R, 3) m.

        Returns:
            ``(pts, n, rows)``: (N, R * PIECES, HULL_MAX, 2) float64 hull vertices padded with the first vertex,
            (N, R * PIECES) vertex counts (0: not drawn) and (N, R * PIECES, 2) first and last covered row
            (clipped to the image). Piece ``q = slot * PIECES + piece``.
        """
        import cv2

        kind = np.asarray(kind)
        n_p, n_r = kind.shape
        local, count = self.vertices(kind, dims, heading)
        pos = np.asarray(pos, dtype=np.float64)
        gx = pos[..., 0][:, :, None, None] + local[..., 0]
        gy = pos[..., 1][:, :, None, None] + local[..., 1]
        world = self.origin + gx[..., None] * self.e1 + gy[..., None] * self.e2 + local[..., 2][..., None] * self.normal
        uv, seen = self.project(world)
        valid = np.arange(HULL_MAX) < count[..., None]
        visible = (count > 0) & np.all(seen | ~valid, axis=-1)
        q = n_r * PIECES
        uv = uv.reshape(n_p, q, HULL_MAX, 2)
        visible = visible.reshape(n_p, q)
        count = count.reshape(n_p, q)
        pts = np.zeros((n_p, q, HULL_MAX, 2))
        hn = np.zeros((n_p, q), dtype=np.int64)
        for i, j in zip(*np.nonzero(visible), strict=True):
            p = uv[i, j, : count[i, j]]
            idx = cv2.convexHull(p.astype(np.float32), clockwise=False, returnPoints=False).reshape(-1)
            k = len(idx)
            pts[i, j, :k] = p[idx]
            pts[i, j, k:] = p[idx[0]]
            hn[i, j] = k
        # rows covered (clipped to the image); hulls that miss the image are not drawn (the padding repeats a
        # vertex, so it does not change the extremes)
        lo, hi = pts.min(axis=2), pts.max(axis=2)
        r0 = np.maximum(np.ceil(lo[..., 1]), 0).astype(np.int64)
        r1 = np.minimum(np.floor(hi[..., 1]), self.height - 1).astype(np.int64)
        hn[(r0 > r1) | (hi[..., 0] < 0.0) | (lo[..., 0] > self.width - 1)] = 0
        rows = np.stack([np.where(hn > 0, r0, 0), np.where(hn > 0, r1, -1)], axis=-1)
        return pts, hn, rows

    def spans(
        self, pts: np.ndarray, n: np.ndarray, rows: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Covered columns of every row of every drawn piece.

        A row y meets the closed hull in ``[x_left, x_right]``: the minimum and maximum, over the hull edges whose
        y-range contains y, of the edge's x at y (a horizontal edge contributes both ends). Vectorised over all
        edges: each edge emits its x at every integer row it spans, and the rows' extremes are gathered with
        ``np.minimum.at`` / ``np.maximum.at``.

        Args:
            pts, n, rows: (N, Q, HULL_MAX, 2), (N, Q), (N, Q, 2) from :meth:`hulls`.

        Returns:
            ``(particle, y, u0, u1)``: flat int64 arrays over (particle, piece, row) in that order, one entry per
            row of each drawn piece; the row's covered columns are ``[u0, u1]`` (``u1 < u0``: none).
        """
        part, piece = np.nonzero(n > 0)
        r0 = rows[part, piece, 0]
        r1 = rows[part, piece, 1]
        length = r1 - r0 + 1
        start = np.cumsum(length) - length
        total = int(length.sum())
        which = np.repeat(np.arange(len(part)), length)
        y = np.arange(total) - start[which] + r0[which]
        # edges (P, HULL_MAX): a -> b, only the first n of each hull
        a = pts[part, piece]
        b = np.roll(a, -1, axis=1)
        k = n[part, piece]
        b[np.arange(len(k)), k - 1] = a[:, 0]  # close each hull at its own last vertex
        e_ok = np.arange(HULL_MAX)[None, :] < k[:, None]
        lo = np.minimum(a[..., 1], b[..., 1])
        hi = np.maximum(a[..., 1], b[..., 1])
        first = np.maximum(np.ceil(lo), r0[:, None]).astype(np.int64)
        last = np.minimum(np.floor(hi), r1[:, None]).astype(np.int64)
        cnt = np.where(e_ok, np.maximum(last - first + 1, 0), 0).ravel()
        pe = np.repeat(np.arange(cnt.size), cnt)  # (pairs,) flat edge index
        ey = np.arange(pe.size) - np.repeat(np.cumsum(cnt) - cnt, cnt) + first.ravel()[pe]
        ax, ay = a[..., 0].ravel()[pe], a[..., 1].ravel()[pe]
        bx, by = b[..., 0].ravel()[pe], b[..., 1].ravel()[pe]
        flat = ay == by
        x = ax + (ey - ay) * (bx - ax) / np.where(flat, 1.0, by - ay)
        x_lo = np.where(flat, np.minimum(ax, bx), x)
        x_hi = np.where(flat, np.maximum(ax, bx), x)
        slot = start[pe // HULL_MAX] + ey - r0[pe // HULL_MAX]
        xl = np.full(total, np.inf)
        xr = np.full(total, -np.inf)
        np.minimum.at(xl, slot, x_lo)
        np.maximum.at(xr, slot, x_hi)
        ok = xl <= xr
        u0 = np.where(ok, np.maximum(np.ceil(np.where(ok, xl, 0.0)), 0.0), 0.0).astype(np.int64)
        u1 = np.where(ok, np.minimum(np.floor(np.where(ok, xr, -1.0)), self.width - 1), -1.0).astype(np.int64)
        return part[which], y, u0, u1

    @staticmethod
    def fill(y: np.ndarray, u0: np.ndarray, u1: np.ndarray) -> tuple[np.ndarray, int, int] | None:
        """Union of row spans (one particle's pieces) in their bounding box: ``(v (Y, X) bool, y0, x0)``, or None
        when no span covers a pixel."""
        good = u0 <= u1
        if not np.any(good):
            return None
        y, u0, u1 = y[good], u0[good], u1[good]
        y0, x0 = int(y.min()), int(u0.min())
        ny, bw = int(y.max()) - y0 + 1, int(u1.max()) - x0 + 2
        base = (y - y0) * bw - x0
        size = ny * bw
        diff = np.bincount(base + u0, minlength=size) - np.bincount(base + u1 + 1, minlength=size)
        # every span ends inside its row (u1 + 1 - x0 <= bw - 1), so one flat cumsum gives the per-row counts
        v = np.cumsum(diff).reshape(ny, bw)[:, :-1] > 0
        return v, y0, x0

    def virtual(self, kind, pos, heading, dims) -> np.ndarray:
        """Binary virtual scenes v_i (N, H, W) bool of the given particles (tests; allocates N images)."""
        pts, hn, rows = self.hulls(np.asarray(kind), pos, heading, dims)
        part, y, u0, u1 = self.spans(pts, hn, rows)
        out = np.zeros((len(hn), self.height, self.width), dtype=bool)
        for i in range(len(hn)):
            sel = part == i
            res = self.fill(y[sel], u0[sel], u1[sel])
            if res is not None:
                v, y0, x0 = res
                out[i, y0 : y0 + v.shape[0], x0 : x0 + v.shape[1]] = v
        return out

    # --- measurement ---------------------------------------------------------------------------------------
    def complexity(self, kind: np.ndarray, age: np.ndarray, pos=None, heading=None, dims=None) -> np.ndarray:
        """c_i of eq. 5: sum over the particle's objects of a_r + b_r exp(-tau_r), plus the exclusion prior (pairs'
        ground overlap x ``exclusion``, when the state is given); (N,) float64 pixels."""
        kind = np.asarray(kind)
        cost = self.cost_a[kind] + self.cost_b[kind] * np.exp(-np.asarray(age, dtype=np.float64))
        c = np.where(kind > 0, cost, 0.0).sum(axis=1)
        if self.exclusion > 0.0 and pos is not None:
            c = c + self.exclusion * self.overlap(kind, np.asarray(pos), np.asarray(heading), np.asarray(dims))
        return c

    @staticmethod
    def overlap(kind: np.ndarray, pos: np.ndarray, heading: np.ndarray, dims: np.ndarray) -> np.ndarray:
        """Summed ground overlap of every pair of objects of each particle (``kernels.templates.xor.pair_overlap``);
        (N,)."""
        pos = pos.astype(np.float64)
        heading = heading.astype(np.float64)
        dims = dims.astype(np.float64)

        def disc_in_box(c, r, centre, a, hl, hw):
            d = c - centre
            lx = np.abs(np.cos(a) * d[..., 0] + np.sin(a) * d[..., 1])
            ly = np.abs(-np.sin(a) * d[..., 0] + np.cos(a) * d[..., 1])
            return np.clip(np.minimum(hl + r - lx, hw + r - ly) / (2.0 * r), 0.0, 1.0)

        n, r = kind.shape
        total = np.zeros(n)
        for s in range(r):
            for t in range(s + 1, r):
                ka, kb = kind[:, s], kind[:, t]
                pa, pb, ha, hb, da, db = pos[:, s], pos[:, t], heading[:, s], heading[:, t], dims[:, s], dims[:, t]
                with np.errstate(divide="ignore", invalid="ignore"):
                    hh = np.clip(1.0 - np.linalg.norm(pa - pb, axis=-1) / (da[:, 1] + db[:, 1]), 0.0, 1.0)
                    hv = disc_in_box(pa, da[:, 1], pb, hb, 0.5 * db[:, 0], 0.5 * db[:, 1])
                    vh = disc_in_box(pb, db[:, 1], pa, ha, 0.5 * da[:, 0], 0.5 * da[:, 1])
                    rr = 0.5 * db[:, 1]
                    ax = np.maximum(0.5 * db[:, 0] - rr, 0.0)[:, None] * np.stack([np.cos(hb), np.sin(hb)], -1)
                    vv = np.max(
                        [disc_in_box(pb + f * ax, rr, pa, ha, 0.5 * da[:, 0], 0.5 * da[:, 1]) for f in (0, 1, -1)],
                        axis=0,
                    )
                o = np.where(
                    (ka == KIND_HUMAN) & (kb == KIND_HUMAN),
                    hh,
                    np.where(ka == KIND_HUMAN, hv, np.where(kb == KIND_HUMAN, vh, vv)),
                )
                total += np.where((ka > 0) & (kb > 0), np.nan_to_num(o), 0.0)
        return total

    def measure(
        self,
        mask: np.ndarray,
        kind: np.ndarray,
        pos: np.ndarray,
        heading: np.ndarray,
        dims: np.ndarray,
        age: np.ndarray,
        logw_prior: np.ndarray | None = None,
    ) -> TemplateMeasurement:
        """Penalties, complexity, log-weights and UOH of one frame.

        Args:
            mask: (H, W) motion mask q (nonzero = foreground).
            kind, pos, heading, dims, age: particle state, (N, R, ...) as in ``TemplateTracker.particles()``.
            logw_prior: (N,) log-weights before this frame's update (default 0, as after resampling).
        """
        q = np.asarray(mask) != 0
        if q.shape != (self.height, self.width):
            raise ValueError(f"mask: expected shape {(self.height, self.width)}, got {q.shape}")
        kind = np.asarray(kind)
        n_p = kind.shape[0]
        total = int(np.count_nonzero(q))
        pts, hn, rows = self.hulls(kind, pos, heading, dims)
        penalty = np.full(n_p, total, dtype=np.int64)
        weighted = np.full(n_p, float(total))
        cov = np.zeros((self.height, self.width), dtype=np.int64)
        part, y, u0, u1 = self.spans(pts, hn, rows)
        bounds = np.searchsorted(part, np.arange(n_p + 1))
        for i in range(n_p):
            lo, hi = bounds[i], bounds[i + 1]
            res = self.fill(y[lo:hi], u0[lo:hi], u1[lo:hi]) if hi > lo else None
            if res is None:
                continue
            v, y0, x0 = res
            win = q[y0 : y0 + v.shape[0], x0 : x0 + v.shape[1]]
            penalty[i] = total - int(np.count_nonzero(win)) + int(np.count_nonzero(win ^ v))  # eq. 4
            weighted[i] = total - int(np.count_nonzero(win & v)) + self.bg_weight * int(np.count_nonzero(v & ~win))
            cov[y0 : y0 + v.shape[0], x0 : x0 + v.shape[1]] += v
        complexity = self.complexity(kind, age, pos, heading, dims)
        prior = np.zeros(n_p) if logw_prior is None else np.asarray(logw_prior, dtype=np.float64)
        logw = prior - (weighted + complexity) * self.scale / float(self.width * self.height)  # eq. 6
        uoh = np.where(q, n_p - cov, 0)  # eq. 10
        return TemplateMeasurement(penalty, complexity, logw, uoh, total)
