"""Template rasterization for the S3 template tracker (Juza et al., section 3): 3D templates on a ground plane
projected through a calibrated camera (OpenCV distortion included) and filled in the image.

Every object is made of ``PIECES`` convex 3D pieces, each given by at most ``HULL_MAX`` vertices:

* human (``KIND_HUMAN``, dims = (height H, body radius r, head radius h) metres): piece 0 is the legs, a regular
  octagonal prism of radius ``LEG_RATIO r`` from the ground to the hips at ``HIP H``; piece 1 is the upper body and
  head, the convex hull of a hexagon of radius ``r`` at the hips, the same hexagon at the shoulders
  (``max(H - SHOULDER h, HIP H)``) and a square of half-diagonal ``h`` at the top of the head (``H``): 16
  vertices. The paper's Fig. 2 template is a body prism with a head; ours keeps its parameters (height, body and
  head radius) but gives it legs narrower than the torso and a shoulder-to-head taper, because the silhouette of a
  walking person is narrow below the hips and wide at the arms: with one prism wide enough for the torso the XOR
  penalty of a correctly placed person stayed at about 40 % of its mask area (docs/notes.md).
* vehicle (``KIND_VEHICLE``, dims = (length, width, height) metres, heading alpha radians): piece 0 the lower
  body box (full length and width, ``LOWER`` of the height), piece 1 the cabin box (``CABIN_LENGTH`` of the length,
  ``CABIN_WIDTH`` of the width, from the lower body to the full height).
* cyclist (``KIND_CYCLIST``, a person riding a bicycle, one object; dims = (length, width, height) metres, heading
  alpha radians; beyond the paper): the vehicle's two boxes in other proportions, piece 0 the bike with the rider's
  legs (full length and width, ``RIDER_LOWER`` of the height), piece 1 the rider's body and head
  (``RIDER_LENGTH`` of the length, ``RIDER_WIDTH`` of the width, up to the full height).

A piece's image is the convex hull of its projected vertices (gift wrapping, at most ``HULL_MAX`` vertices). A
pixel ``(u, v)`` (centre at integer coordinates, OpenCV convention) is covered by a piece when its centre lies in
the closed hull; a row's coverage is a span ``[ceil(x_left), floor(x_right)]`` found from the hull's edges. The
virtual scene ``v_i`` of a particle (eq. 4) is the union of its pieces' spans. Nothing here materialises an
image per particle: consumers (``kernels.templates.xor``, ``kernels.templates.uoh``) walk the spans row by row.
"""

import warp as wp

from wptrack.kernels.core.camera import Camera, project

wp.set_module_options({"enable_backward": False})

MAX_SLOTS = wp.constant(64)
"""Largest R_max (objects per particle) the kernels support (the length of their per-slot local vectors,
:data:`vec_slots` and :data:`vec_slots_i`; was 16 before issue 26)."""
PIECES = wp.constant(2)
"""Convex pieces per object."""
MAX_PIECES = wp.constant(128)
"""MAX_SLOTS * PIECES: the most pieces a particle can have (the length of :data:`vec_pieces`)."""
HULL_MAX = wp.constant(16)
"""Most vertices per piece (and per projected hull)."""

KIND_NONE = wp.constant(0)
KIND_HUMAN = wp.constant(1)
KIND_VEHICLE = wp.constant(2)
KIND_CYCLIST = wp.constant(3)

LOWER = wp.constant(0.55)  # vehicle: lower body height / total height
CABIN_LENGTH = wp.constant(0.6)  # vehicle: cabin length / total length
CABIN_WIDTH = wp.constant(0.9)  # vehicle: cabin width / total width
OCTAGON = wp.constant(0.7853981633974483)  # 2 pi / 8

HEXAGON = wp.constant(1.0471975511965976)  # 2 pi / 6
LEG_RATIO = wp.constant(0.65)  # human: leg prism radius / body radius (two legs side by side vs torso and arms)
HIP = wp.constant(0.5)  # human: hip height / height
SHOULDER = wp.constant(2.5)  # human: shoulders this many head radii below the top of the head
RIDER_LOWER = wp.constant(0.5)  # cyclist: bike and legs box height / total height (the saddle)
RIDER_LENGTH = wp.constant(0.35)  # cyclist: rider box length / total length (the bike's)
RIDER_WIDTH = wp.constant(0.8)  # cyclist: rider box width / total width (the handlebar's)

vec16 = wp.types.vector(length=16, dtype=wp.float32)
"""HULL_MAX floats: a piece's projected vertices."""
vec_pieces = wp.types.vector(length=128, dtype=wp.int32)
"""MAX_PIECES int32: per-piece local arrays of a particle (rows, chain walks, spans)."""
vec_slots = wp.types.vector(length=64, dtype=wp.float32)
"""MAX_SLOTS float32: per-slot (or per-group: at most one group per slot) local arrays."""
vec_slots_i = wp.types.vector(length=64, dtype=wp.int32)
"""MAX_SLOTS int32: per-slot (or per-group) local arrays."""


@wp.struct
class GroundPlane:
    """The plane objects move on, as an orthonormal frame in world coordinates (metres).

    A ground position ``(x, y)`` and a height ``h`` above the plane map to ``origin + x e1 + y e2 + h normal``.
    """

    origin: wp.vec3
    e1: wp.vec3
    e2: wp.vec3
    normal: wp.vec3


@wp.func
def plane_point(plane: GroundPlane, x: float, y: float, h: float):
    """World point of ground coordinates (x, y) and height h above the plane, metres."""
    return plane.origin + x * plane.e1 + y * plane.e2 + h * plane.normal


@wp.func
def piece_vertices(kind: int, piece: int):
    """Number of vertices of ``piece`` of an object of ``kind`` (0 when the object has no such piece)."""
    if kind == KIND_HUMAN:
        return 16
    if kind == KIND_VEHICLE or kind == KIND_CYCLIST:
        return 8
    return 0


@wp.func
def piece_vertex(kind: int, piece: int, k: int, dims: wp.vec3, heading: float):
    """Vertex ``k`` of a piece in the object's frame: (along e1, along e2, height), metres, relative to the
    object's ground position (its ground-contact centre)."""
    if kind == KIND_HUMAN:
        height = dims[0]
        body_r = dims[1]
        head_r = dims[2]
        hip = HIP * height
        if piece == 0:  # legs: octagonal prism
            a = float(k % 8) * OCTAGON
            h = float(0.0)
            if k >= 8:
                h = hip
            return wp.vec3(LEG_RATIO * body_r * wp.cos(a), LEG_RATIO * body_r * wp.sin(a), h)
        if k < 12:  # upper body: hexagons at the hips and the shoulders
            a = float(k % 6) * HEXAGON
            h = hip
            if k >= 6:
                h = wp.max(height - SHOULDER * head_r, hip)
            return wp.vec3(body_r * wp.cos(a), body_r * wp.sin(a), h)
        a = float(k - 12) * (0.5 * wp.pi)  # top of the head: a square
        return wp.vec3(head_r * wp.cos(a), head_r * wp.sin(a), height)
    # vehicle (and cyclist) boxes, rotated by the heading about the plane normal
    length = dims[0]
    width = dims[1]
    height = dims[2]
    lower = LOWER
    top_length = CABIN_LENGTH
    top_width = CABIN_WIDTH
    if kind == KIND_CYCLIST:
        lower = RIDER_LOWER
        top_length = RIDER_LENGTH
        top_width = RIDER_WIDTH
    hl = 0.5 * length
    hw = 0.5 * width
    z0 = float(0.0)
    z1 = lower * height
    if piece == 1:
        hl = hl * top_length
        hw = hw * top_width
        z0 = z1
        z1 = height
    lx = hl * (1.0 - 2.0 * float(k % 2))
    ly = hw * (1.0 - 2.0 * float((k / 2) % 2))
    z = z0
    if k >= 4:
        z = z1
    ca = wp.cos(heading)
    sa = wp.sin(heading)
    return wp.vec3(ca * lx - sa * ly, sa * lx + ca * ly, z)


@wp.func
def convex_hull(xs: vec16, ys: vec16, n: int):
    """Gift wrapping of ``n`` <= HULL_MAX points: returns (hull_x, hull_y, count), vertices in order.

    Collinear points on an edge are skipped (the farthest one is kept); coincident points count once.
    """
    hx = vec16()
    hy = vec16()
    start = int(0)
    for j in range(1, n):
        if xs[j] < xs[start] or (xs[j] == xs[start] and ys[j] < ys[start]):
            start = j
    count = int(0)
    cur = start
    for _it in range(HULL_MAX):
        cx = xs[cur]
        cy = ys[cur]
        hx[count] = cx
        hy[count] = cy
        count += 1
        cand = cur
        ax = float(0.0)  # the candidate's offset from the current vertex
        ay = float(0.0)
        for j in range(n):
            if j != cur:
                bx = xs[j] - cx
                by = ys[j] - cy
                if cand == cur:
                    cand = j
                    ax = bx
                    ay = by
                else:
                    cross = ax * by - ay * bx
                    if cross < 0.0 or (cross == 0.0 and bx * bx + by * by > ax * ax + ay * ay):
                        cand = j
                        ax = bx
                        ay = by
        if cand == cur:
            break
        if xs[cand] == xs[cur] and ys[cand] == ys[cur]:
            break
        cur = cand
        if cur == start:
            break
    return hx, hy, count


@wp.kernel
def template_hulls_kernel(
    cam: Camera,
    plane: GroundPlane,
    kind: wp.array2d(dtype=wp.int32),
    pos: wp.array2d(dtype=wp.vec2),
    heading: wp.array2d(dtype=wp.float32),
    dims: wp.array2d(dtype=wp.vec3),
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    hull_depth: wp.array2d(dtype=wp.float32),
):
    """Project every object of every particle and store its pieces' image hulls.

    Launch with ``dim=(N, R * PIECES)``: thread ``(i, q)`` is piece ``q % PIECES`` of slot ``q // PIECES`` of
    particle ``i`` (a thread per piece: twice the threads of one per object, for the latency of small N on the GPU).
    Inputs are (N, R) per slot: ``kind`` (KIND_*), ``pos`` ground position (metres),
    ``heading`` (radians), ``dims`` (metres, see the module docstring). Outputs per piece ``q = slot * PIECES +
    piece``: ``hull_pts`` (N, R * PIECES, HULL_MAX) hull vertices (pixels) in order around the hull, the first
    one topmost (smallest v; ``hull_chain_span`` relies on it), ``hull_n`` vertex count (0: the piece
    does not exist, is partly behind the camera or misses the image), ``hull_rows`` (first, last) image row the
    piece covers (clipped to the image), ``hull_depth`` camera depth of the object's ground point (metres; 0 for
    an empty slot, which is not projected).
    """
    i, q = wp.tid()
    s = q / PIECES
    piece = q - s * PIECES
    k = kind[i, s]
    if k == 0:  # an empty slot (most of R_max): no pieces; its depth is never read (hull_n = 0)
        hull_n[i, q] = 0
        hull_rows[i, q] = wp.vec2i(0, -1)
        hull_depth[i, q] = 0.0
        return
    p = pos[i, s]
    a = heading[i, s]
    d = dims[i, s]
    ground = plane_point(plane, p[0], p[1], 0.0)
    g = project(cam, ground)
    n = piece_vertices(k, piece)
    xs = vec16()
    ys = vec16()
    visible = n > 0
    for j in range(n):
        v = piece_vertex(k, piece, j, d, a)
        uvz = project(cam, plane_point(plane, p[0] + v[0], p[1] + v[1], v[2]))
        if uvz[2] <= 0.0:
            visible = False
        xs[j] = uvz[0]
        ys[j] = uvz[1]
    count = int(0)
    row0 = int(0)
    row1 = int(-1)
    if visible:
        hx, hy, count = convex_hull(xs, ys, n)
        top = int(0)  # stored from its topmost vertex (the first of smallest v): see hull_chain_span
        for j in range(1, count):
            if hy[j] < hy[top]:
                top = j
        xmin = hx[0]
        xmax = hx[0]
        ymin = hy[0]
        ymax = hy[0]
        for j in range(count):
            jt = j + top
            if jt >= count:
                jt -= count
            hull_pts[i, q, j] = wp.vec2(hx[jt], hy[jt])
            xmin = wp.min(xmin, hx[j])
            xmax = wp.max(xmax, hx[j])
            ymin = wp.min(ymin, hy[j])
            ymax = wp.max(ymax, hy[j])
        row0 = wp.max(int(wp.ceil(ymin)), 0)
        row1 = wp.min(int(wp.floor(ymax)), cam.height - 1)
        if row0 > row1 or xmax < 0.0 or xmin > float(cam.width - 1):
            count = 0
    if count == 0:
        row0 = 0
        row1 = -1
    hull_n[i, q] = count
    hull_rows[i, q] = wp.vec2i(row0, row1)
    hull_depth[i, q] = g[2]


@wp.func
def edge_x(a: wp.vec2, b: wp.vec2, y: float, xl: float, xr: float):
    """``(xl, xr)`` widened by the crossing of row ``y`` with the closed hull edge ``a -> b`` (both ends when the
    edge is horizontal on the row); unchanged when the edge misses the row. The one place the crossing is computed:
    ``hull_span`` and ``hull_chain_span`` agree bit for bit."""
    lo = wp.min(a[1], b[1])
    hi = wp.max(a[1], b[1])
    if y >= lo and y <= hi:
        if a[1] == b[1]:
            xl = wp.min(xl, wp.min(a[0], b[0]))
            xr = wp.max(xr, wp.max(a[0], b[0]))
        else:
            x = a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            xl = wp.min(xl, x)
            xr = wp.max(xr, x)
    return xl, xr


@wp.func
def span_columns(xl: float, xr: float, width: int):
    """Pixel columns ``(u0, u1)`` whose centres lie in ``[xl, xr]``, clipped to ``[0, width - 1]`` (``u1 < u0``:
    none)."""
    u0 = int(0)
    u1 = int(-1)
    if xl <= xr:
        u0 = wp.max(int(wp.ceil(xl)), 0)
        u1 = wp.min(int(wp.floor(xr)), width - 1)
    return u0, u1


@wp.func
def hull_span(hull_pts: wp.array3d(dtype=wp.vec2), i: int, q: int, n: int, y: float, width: int):
    """Columns ``(u0, u1)`` of image row ``y`` covered by hull ``q`` of particle ``i`` (``u1 < u0``: none).

    The row's intersection with the closed convex hull is ``[x_left, x_right]``; covered pixels are those whose
    centres lie in it, clipped to ``[0, width - 1]``. Tests every edge (O(n)); ``hull_chain_span`` gives the same
    columns in O(1) amortised over increasing rows.
    """
    xl = float(3.0e38)
    xr = float(-3.0e38)
    a = hull_pts[i, q, n - 1]
    for k in range(n):
        b = hull_pts[i, q, k]
        xl, xr = edge_x(a, b, y, xl, xr)
        a = b
    return span_columns(xl, xr, width)


@wp.func
def hull_chain_span(
    hull_pts: wp.array3d(dtype=wp.vec2), i: int, q: int, n: int, y: float, width: int, down: int, up: int
):
    """``hull_span`` by walking the hull's two y-monotone chains: returns ``(u0, u1, down, up)``.

    The hull's vertex 0 is its topmost (``template_hulls_kernel``), so v grows along edges 0, 1, ... (the down
    chain) to the bottom vertex and shrinks again to vertex 0 (the up chain, walked backwards from edge n - 1).
    ``down`` is the first down-chain edge to test and ``up`` counts up-chain edges already passed; both start at 0
    and only move forward, so ``y`` must not decrease between calls that pass a walk on (start a row above the
    last one from zeros). A row costs the edges it crosses plus those passed since the last row. On each chain the
    edges crossing a row are contiguous (the hull is convex), and every edge tested goes through ``edge_x`` with
    the same ends in the same order as in ``hull_span``, so the columns are identical.
    """
    xl = float(3.0e38)
    xr = float(-3.0e38)
    # down chain, edge k = (k, k + 1): skip the edges ending above the row (none of them crosses it), then test
    # edges while they cross it; an edge ending below the row ends the run (the next one starts below it)
    while down < n - 1 and hull_pts[i, q, down + 1][1] < y:
        down += 1
    k = down
    a = hull_pts[i, q, k]
    while k < n:
        kb = k + 1
        if kb == n:
            kb = 0
        b = hull_pts[i, q, kb]
        if k > down and (y < wp.min(a[1], b[1]) or y > wp.max(a[1], b[1])):
            break
        xl, xr = edge_x(a, b, y, xl, xr)
        if b[1] > y:
            break
        a = b
        k += 1
    # up chain, edge j = (j, j + 1) for j = n - 1 - up, n - 2 - up, ...: skip the edges whose lower end (j) is
    # above the row, then test edges while they cross it; a lower end below the row ends the run
    while up < n - 1 and hull_pts[i, q, n - 1 - up][1] < y:
        up += 1
    j = n - 1 - up
    b = hull_pts[i, q, 0]
    if j < n - 1:
        b = hull_pts[i, q, j + 1]
    while j >= 0:
        a = hull_pts[i, q, j]
        if j < n - 1 - up and (y < wp.min(a[1], b[1]) or y > wp.max(a[1], b[1])):
            break
        xl, xr = edge_x(a, b, y, xl, xr)
        if a[1] > y:
            break
        b = a
        j -= 1
    u0, u1 = span_columns(xl, xr, width)
    return u0, u1, down, up


@wp.func
def row_intervals(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    i: int,
    pieces: int,
    y: int,
    width: int,
    down: vec_pieces,
    up: vec_pieces,
):
    """The covered columns of row ``y`` of particle ``i``'s virtual scene as disjoint sorted intervals.

    ``down``, ``up``: per piece, the chain walks of ``hull_chain_span`` (zeros to start; pass back what the
    previous row returned only when ``y`` is below that row). Returns ``(count, starts, ends, down, up)``: ``count``
    merged intervals ``[starts[k], ends[k]]`` (inclusive columns), sorted, separated by at least one uncovered
    pixel, and the walks after this row.
    """
    s0 = vec_pieces()
    s1 = vec_pieces()
    n = int(0)
    yf = float(y)
    for q in range(pieces):
        m = hull_n[i, q]
        if m > 0:
            r = hull_rows[i, q]
            if y >= r[0] and y <= r[1]:
                u0, u1, dq, uq = hull_chain_span(hull_pts, i, q, m, yf, width, down[q], up[q])
                down[q] = dq
                up[q] = uq
                if u0 <= u1:
                    j = n
                    while j > 0 and s0[j - 1] > u0:
                        s0[j] = s0[j - 1]
                        s1[j] = s1[j - 1]
                        j -= 1
                    s0[j] = u0
                    s1[j] = u1
                    n += 1
    # merge in place: interval ``count`` is written at or before the input ``k`` it comes from
    count = int(0)
    for k in range(n):
        if count > 0 and s0[k] <= s1[count - 1] + 1:
            s1[count - 1] = wp.max(s1[count - 1], s1[k])
        else:
            s0[count] = s0[k]
            s1[count] = s1[k]
            count += 1
    return count, s0, s1, down, up


@wp.kernel
def render_virtual_kernel(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    pieces: int,
    particles: wp.array(dtype=wp.int32),
    out: wp.array3d(dtype=wp.uint8),
):
    """Materialise the binary virtual scenes ``v_i`` (eq. 4) of selected particles (reports and tests).

    Launch with ``dim=(K, H)``; ``particles`` (K,) indices; ``out`` (K, H, W) is 1 on covered pixels, else 0.
    """
    k, y = wp.tid()
    i = particles[k]
    width = out.shape[2]
    for x in range(width):
        out[k, y, x] = wp.uint8(0)
    count, m0, m1, _down, _up = row_intervals(
        hull_pts, hull_n, hull_rows, i, pieces, y, width, vec_pieces(), vec_pieces()
    )
    for c in range(count):
        for x in range(m0[c], m1[c] + 1):
            out[k, y, x] = wp.uint8(1)


@wp.kernel
def render_labels_kernel(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    hull_depth: wp.array2d(dtype=wp.float32),
    pieces: int,
    best: wp.array(dtype=wp.int32),
    out: wp.array2d(dtype=wp.uint8),
):
    """The virtual scene of particle ``best[0]`` with each pixel set to 1 + the slot of the nearest object
    covering it (0: background); nearer objects hide farther ones (painter's order by ground-point depth; equal
    depths in piece order).

    Launch with ``dim=H``; ``out`` (H, W) uint8. A row sorts only the pieces whose rows include it (a pixel row
    costs the pieces it meets, not ``R_max^2``).
    """
    y = wp.tid()
    i = best[0]
    width = out.shape[1]
    for x in range(width):
        out[y, x] = wp.uint8(0)
    yf = float(y)
    # the pieces drawn on this row, in piece order
    row = vec_pieces()
    m = int(0)
    for q in range(pieces):
        if hull_n[i, q] > 0:
            r = hull_rows[i, q]
            if y >= r[0] and y <= r[1]:
                row[m] = q
                m += 1
    drawn = vec_pieces()
    for _pass in range(m):
        # the farthest piece not drawn yet (the first of equal depths)
        far = int(-1)
        far_d = float(-3.0e38)
        for k in range(m):
            q = row[k]
            if drawn[k] == 0 and hull_depth[i, q] > far_d:
                far_d = hull_depth[i, q]
                far = k
        if far < 0:
            break
        drawn[far] = 1
        q = row[far]
        u0, u1 = hull_span(hull_pts, i, q, hull_n[i, q], yf, width)
        for x in range(u0, u1 + 1):
            out[y, x] = wp.uint8(q / PIECES + 1)
