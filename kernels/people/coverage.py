"""S2 people tracker, ours beyond the paper: how much of a standing person's image rectangle the motion masks cover.

A person standing at ground point (x, y) is modelled, as in the Probabilistic Occupancy Map of Fleuret, Berclaz,
Lengagne and Fua (PAMI 2008, section 4.2: "a rectangle of the height and width of an average human"), by a vertical
box ``2 half_width`` wide (across the camera's viewing direction) and ``height`` tall on the floor z = 0; in each
camera it is the bounding rectangle of the projections of its four corners (:func:`person_box`). Its *coverage* is
the fraction of the rectangle's pixels (clipped to the image) that the motion mask marks, counted in O(1) with the
camera's integral image (``kernels.colour`` builds it from a 0/1 mask, ``Camera.integral_offset``). A camera
*sees* the box when it lies in front of it and at least ``min_visible`` of its area is inside the image (a person
cut by the border still counts); otherwise the camera says nothing (coverage -1).

POM infers occupancy probabilities by a mean-field approximation of its generative model; we use the rectangle
coverage directly, the cheaper variant: :func:`coverage_kernel` on a ground grid (the birth map), and
:func:`box_log_likelihood` as a person-level term of a particle's weight (the particle's ground position must be
where a whole person's rectangle is covered in every camera that sees it; the paper's per-point motion term alone
lets a particle cloud slide along one camera's viewing ray when the other camera's mask loses the person).
:func:`person_boxes_kernel` and :func:`explained_mask_kernel` clear the pixels of the tracked people's rectangles,
so that the birth map shows only motion nobody explains (the ghosts two people's silhouettes make where other
cameras' rays cross are inside tracked people's rectangles); :func:`left_mask_kernel` and
:func:`left_coverage_kernel` give the part of a candidate's rectangle they leave (POM's gain for births, optional).
:func:`exclusion_log_penalty` keeps two people's particles apart. :func:`gate_kernel` says whether a frame's masks
show a person, pooling the cameras or per camera (:func:`kth_camera_coverage`).

Units: metres (world, z up, floor z = 0), pixels. Rectangles are ``vec4(u0, v0, u1, v1)``: columns [u0, u1), rows
[v0, v1) of the image, integers stored as floats, clipped to the image; ``u1 <= u0`` means empty.

Length: one module for the person rectangle on purpose: its projection, its counts on the integral images (whole,
what the other people leave, per camera), the evidence map, the particle terms, the gate and the appearance
histograms all share :func:`person_box` and :func:`box_count`, and each kernel is tested against one NumPy
reference of that rectangle (tests/test_kernels_coverage.py).
"""

import warp as wp

from wptrack.kernels.core.camera import Camera, project
from wptrack.kernels.people.descriptor import rgb_to_hsv

wp.set_module_options({"enable_backward": False})


@wp.func
def camera_centre(cam: Camera):
    """The camera's centre in the world, metres: -R^T t."""
    return -(wp.transpose(cam.R) * cam.t)


@wp.func
def person_box(cam: Camera, x: float, y: float, half_width: float, height: float):
    """The image rectangle of a person standing at (x, y): the bounding box of the projections of the corners of a
    vertical box ``2 half_width`` wide across the viewing direction and ``height`` tall (metres).

    Returns ``(box, full)``: ``box`` = vec4(u0, v0, u1, v1) clipped to the image (integers, see the module
    docstring), ``full`` = the area of the unclipped rectangle, pixels^2; ``full`` = 0 when a corner is not projected
    (behind the camera, or where its distortion model is not valid)."""
    c = camera_centre(cam)
    dx = x - c[0]
    dy = y - c[1]
    n = wp.sqrt(dx * dx + dy * dy)
    px = float(0.0)
    py = float(1.0)
    if n > 1.0e-9:
        px = -dy / n
        py = dx / n
    umin = float(1.0e30)
    umax = float(-1.0e30)
    vmin = float(1.0e30)
    vmax = float(-1.0e30)
    ok = int(1)
    for k in range(4):
        s = float(2 * (k % 2) - 1)
        z = height * float(k // 2)
        q = project(cam, wp.vec3(x + s * half_width * px, y + s * half_width * py, z))
        if q[2] <= 0.0:
            ok = 0
        umin = wp.min(umin, q[0])
        umax = wp.max(umax, q[0])
        vmin = wp.min(vmin, q[1])
        vmax = wp.max(vmax, q[1])
    if ok == 0:
        return wp.vec4(0.0, 0.0, 0.0, 0.0), float(0.0)
    full = (umax - umin) * (vmax - vmin)
    w = float(cam.width)
    h = float(cam.height)
    u0 = wp.clamp(wp.floor(umin + 0.5), 0.0, w)
    u1 = wp.clamp(wp.floor(umax + 0.5), 0.0, w)
    v0 = wp.clamp(wp.floor(vmin + 0.5), 0.0, h)
    v1 = wp.clamp(wp.floor(vmax + 0.5), 0.0, h)
    return wp.vec4(u0, v0, u1, v1), full


@wp.func
def box_count(cam: Camera, integral: wp.array(dtype=wp.int32), box: wp.vec4):
    """Mask pixels inside ``box`` (clipped, integers as floats) from the camera's (H+1) x (W+1) integral image."""
    u0 = int(box[0])
    v0 = int(box[1])
    u1 = int(box[2])
    v1 = int(box[3])
    if u1 <= u0 or v1 <= v0:
        return int(0)
    w1 = cam.width + 1
    base = cam.integral_offset
    return (
        integral[base + v1 * w1 + u1]
        - integral[base + v0 * w1 + u1]
        - integral[base + v1 * w1 + u0]
        + integral[base + v0 * w1 + u0]
    )


@wp.func
def box_counts(
    cam: Camera,
    integral: wp.array(dtype=wp.int32),
    x: float,
    y: float,
    half_width: float,
    height: float,
    vis: float,
    unit: float,
):
    """``(on, area)``: mask pixels inside the rectangle of a person at (x, y) and the rectangle's area, both counted
    inside the image, or ``(0, -1)`` when the camera does not see it (a corner not projected, or less than ``vis``
    of the rectangle inside the image). ``unit``: pixels each of the integral's pixels stands for (the mask
    block-summed, see :func:`downsample_mask_kernel`; the area is multiplied by it, the counts already hold it)."""
    box, full = person_box(cam, x, y, half_width, height)
    area = (box[2] - box[0]) * (box[3] - box[1])
    if full <= 0.0 or area <= 0.0 or area < vis * full:
        return float(0.0), float(-1.0)
    return float(box_count(cam, integral, box)), area * unit


@wp.func
def box_coverage(
    cam: Camera,
    integral: wp.array(dtype=wp.int32),
    x: float,
    y: float,
    half_width: float,
    height: float,
    vis: float,
    unit: float,
):
    """Fraction of the rectangle of a person at (x, y) that the mask covers (its part inside the image), or -1 when
    the camera does not see it (:func:`box_counts`)."""
    on, area = box_counts(cam, integral, x, y, half_width, height, vis, unit)
    if area <= 0.0:
        return float(-1.0)
    return on / area


@wp.func
def cell_centre(origin: wp.vec2, cell: float, nx: int, t: int):
    """Centre (metres) of cell ``t`` = (ix, iy) = (t % nx, t / nx) of a ground grid: ``origin + cell (ix + 1/2,
    iy + 1/2)``."""
    return wp.vec2(origin[0] + cell * (float(t % nx) + 0.5), origin[1] + cell * (float(t / nx) + 0.5))


@wp.func
def in_boxes(boxes: wp.array2d(dtype=wp.vec4), n: int, skip: int, c: int, fu: float, fv: float):
    """Whether pixel (fu, fv) lies in one of the first ``n`` rectangles of ``boxes`` in camera ``c`` other than row
    ``skip`` (-1: none skipped)."""
    for k in range(n):
        if k != skip:
            b = boxes[k, c]
            if fu >= b[0] and fu < b[2] and fv >= b[1] and fv < b[3]:
                return True
    return False


@wp.kernel
def downsample_mask_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    scale: int,
    small_cams: wp.array(dtype=Camera),
    small: wp.array(dtype=wp.uint8),
):
    """Block sums of the 0/1 masks: ``small`` pixel (u, v) of camera c = the motion pixels of the ``scale`` x
    ``scale`` block of ``mask`` from (scale u, scale v) (0 .. scale^2 <= 255). ``small_cams``: the same cameras at
    the reduced size (``pixel_offset`` into ``small``; the rectangles are projected with them). A person's
    rectangle is tens of pixels wide, so its coverage counted on blocks is as good and ``scale^2`` times cheaper
    to integrate (POM, too, works on reduced images). Launch dim ``(cameras, small max height, small max
    width)``."""
    c, v, u = wp.tid()
    sc = small_cams[c]
    if v >= sc.height or u >= sc.width:
        return
    cam = cams[c]
    n = int(0)
    for dv in range(scale):
        row = cam.pixel_offset + (scale * v + dv) * cam.width + scale * u
        for du in range(scale):
            n += int(mask[row + du])
    small[sc.pixel_offset + v * sc.width + u] = wp.uint8(n)


@wp.kernel
def coverage_kernel(
    cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    origin: wp.vec2,
    cell: float,
    nx: int,
    half_width: float,
    height: float,
    min_visible: float,
    unit: float,
    coverage: wp.array2d(dtype=wp.float32),
):
    """Coverage of a person's rectangle at every cell of a ground grid in every camera (:func:`box_coverage`).

    Launch dim ``(cameras, nx * ny)``. Cell ``t`` = (ix, iy) = (t % nx, t / nx) has centre ``origin + cell (ix + 1/2,
    iy + 1/2)``, metres. ``coverage`` (cameras, nx * ny) out: fraction in [0, 1], -1 where the camera does not see
    the cell's person."""
    c, t = wp.tid()
    p = cell_centre(origin, cell, nx, t)
    coverage[c, t] = wp.float32(box_coverage(cams[c], integral, p[0], p[1], half_width, height, min_visible, unit))


@wp.kernel
def box_area_kernel(
    cams: wp.array(dtype=Camera),
    origin: wp.vec2,
    cell: float,
    nx: int,
    half_width: float,
    height: float,
    min_visible: float,
    unit: float,
    area: wp.array2d(dtype=wp.float32),
):
    """The area (pixels inside the image, times ``unit``: see :func:`box_counts`) of a person's rectangle at every
    cell of the grid of :func:`coverage_kernel` in every camera, -1 where the camera does not see it (the same
    rule). Launch dim ``(cameras, nx * ny)``."""
    c, t = wp.tid()
    cam = cams[c]
    p = cell_centre(origin, cell, nx, t)
    box, full = person_box(cam, p[0], p[1], half_width, height)
    a = (box[2] - box[0]) * (box[3] - box[1])
    if full <= 0.0 or a <= 0.0 or a < min_visible * full:
        area[c, t] = wp.float32(-1.0)
    else:
        area[c, t] = wp.float32(a * unit)


@wp.kernel
def person_boxes_kernel(
    cams: wp.array(dtype=Camera),
    people: wp.array(dtype=wp.vec2),
    alive: wp.array(dtype=wp.int32),
    half_width: float,
    height: float,
    boxes: wp.array2d(dtype=wp.vec4),
):
    """The image rectangles of the people standing at ``people`` (ground x, y, metres) whose ``alive`` flag is set,
    in every camera. Launch dim ``(people, cameras)``; ``boxes`` (people, cameras) out: clipped rectangles (module
    docstring), empty ones for people not alive and for corners not projected."""
    i, c = wp.tid()
    box = wp.vec4(0.0, 0.0, 0.0, 0.0)
    if alive[i] != 0:
        b, full = person_box(cams[c], people[i][0], people[i][1], half_width, height)
        if full > 0.0:
            box = b
    boxes[i, c] = box


@wp.kernel
def explained_mask_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    boxes: wp.array2d(dtype=wp.vec4),
    n: int,
    free: wp.array(dtype=wp.uint8),
):
    """``free`` = the mask (0/1) with the pixels inside the first ``n`` rectangles of ``boxes`` (from
    :func:`person_boxes_kernel`; empty rectangles clear nothing) cleared: the motion nobody tracked explains. Launch
    dim ``(cameras, max height, max width)``; flat per-frame pixel buffers (``Camera.pixel_offset``)."""
    c, v, u = wp.tid()
    cam = cams[c]
    if v >= cam.height or u >= cam.width:
        return
    i = cam.pixel_offset + v * cam.width + u
    m = mask[i]
    if m != wp.uint8(0) and in_boxes(boxes, n, -1, c, float(u), float(v)):
        m = wp.uint8(0)
    free[i] = m


@wp.kernel
def left_mask_kernel(
    cams: wp.array(dtype=Camera),
    boxes: wp.array2d(dtype=wp.vec4),
    n: int,
    left: wp.array(dtype=wp.uint8),
):
    """``left`` = 1 at the pixels outside the first ``n`` rectangles of ``boxes`` (from :func:`person_boxes_kernel`),
    0 inside one: the part of the image no tracked person explains, whose integral image gives the part of a
    candidate's rectangle the tracked people leave (:func:`left_coverage_kernel`). Launch dim ``(cameras, max
    height, max width)``; flat per-frame pixel buffers (``Camera.pixel_offset``)."""
    c, v, u = wp.tid()
    cam = cams[c]
    if v >= cam.height or u >= cam.width:
        return
    m = wp.uint8(1)
    if in_boxes(boxes, n, -1, c, float(u), float(v)):
        m = wp.uint8(0)
    left[cam.pixel_offset + v * cam.width + u] = m


@wp.kernel
def left_coverage_kernel(
    cams: wp.array(dtype=Camera),
    free_integral: wp.array(dtype=wp.int32),
    left_integral: wp.array(dtype=wp.int32),
    origin: wp.vec2,
    cell: float,
    nx: int,
    half_width: float,
    height: float,
    min_visible: float,
    unit: float,
    coverage: wp.array2d(dtype=wp.float32),
    left: wp.array2d(dtype=wp.float32),
):
    """The evidence map of POM's gain (Fleuret et al., PAMI 2008, section 4: the masks as the union of the people's
    rectangles): at every cell of the grid of :func:`coverage_kernel` and in every camera, the part of a person's
    rectangle that the tracked people's rectangles leave (``left``, a fraction of the rectangle inside the image,
    from ``left_integral``, the integral image of :func:`left_mask_kernel`'s map) and the fraction of that part the
    unexplained motion covers (``coverage``, from ``free_integral``, the integral image of
    :func:`explained_mask_kernel`'s mask; 0 where nothing is left): pixels another person explains are neither
    evidence for a newcomer nor against it, as in the rectangle term of a particle (:func:`box_counts_left`).
    Both -1 where the camera does not see the cell's person (:func:`box_counts`). Launch dim ``(cameras, nx *
    ny)``; ``unit`` as in :func:`box_counts` (the free integral counts mask pixels, the left one blocks)."""
    c, t = wp.tid()
    cam = cams[c]
    p = cell_centre(origin, cell, nx, t)
    box, full = person_box(cam, p[0], p[1], half_width, height)
    area = (box[2] - box[0]) * (box[3] - box[1])
    if full <= 0.0 or area <= 0.0 or area < min_visible * full:
        coverage[c, t] = wp.float32(-1.0)
        left[c, t] = wp.float32(-1.0)
        return
    rest = float(box_count(cam, left_integral, box))
    cov = float(0.0)
    if rest > 0.0:
        cov = float(box_count(cam, free_integral, box)) / (rest * unit)
    coverage[c, t] = wp.float32(cov)
    left[c, t] = wp.float32(rest / area)


@wp.struct
class PersonTerms:
    """Parameters of the person-level terms of a particle's log-weight (:func:`person_log_terms`)."""

    half_width: float  # half the person's width, metres
    height: float  # the person's height, metres
    min_visible: float  # fraction of a rectangle inside the image for the camera to see it
    unit: float  # pixels each pixel of the masks' integral images stands for (box_counts)
    slope: float  # rectangle term: slope * on - offset * area per camera (box_log_likelihood)
    offset: float
    exclusion_radius: float  # metres (exclusion_log_penalty)
    exclusion_weight: float  # nats at distance 0
    balance: int  # 1: each camera's rectangle term weighted by the mean own-rectangle area / its own (0: off)


@wp.func
def overlap(a: wp.vec4, b: wp.vec4):
    """The intersection of two rectangles (possibly empty: u1 <= u0 or v1 <= v0)."""
    return wp.vec4(wp.max(a[0], b[0]), wp.max(a[1], b[1]), wp.min(a[2], b[2]), wp.min(a[3], b[3]))


@wp.func
def camera_counts_left(
    cam: Camera,
    c: int,
    integral: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    x: wp.vec3,
    half_width: float,
    height: float,
    min_visible: float,
):
    """``(seen, on, area, full)`` of camera ``c`` for the rectangle of a person standing at (x[0], x[1]): whether the
    camera sees it (:func:`box_counts`' rule), its mask pixels and its pixels inside the image without the parts
    inside the other tracked people's rectangles (``boxes`` row ``c`` of every person but ``own``; overlapping ones
    are subtracted each, floored at 0), and its pixels inside the image before that; areas in the integral's pixels
    (:func:`box_counts_left` multiplies them by ``unit``). Zeros when the camera does not see it."""
    box, full = person_box(cam, x[0], x[1], half_width, height)
    area = (box[2] - box[0]) * (box[3] - box[1])
    if full > 0.0 and area > 0.0 and area >= min_visible * full:
        whole = area
        on = float(box_count(cam, integral, box))
        for k in range(boxes.shape[0]):
            if k != own:
                shared = overlap(box, boxes[k, c])
                if shared[2] > shared[0] and shared[3] > shared[1]:
                    on -= float(box_count(cam, integral, shared))
                    area -= (shared[2] - shared[0]) * (shared[3] - shared[1])
        return int(1), wp.max(on, 0.0), wp.max(area, 0.0), whole
    return int(0), float(0.0), float(0.0), float(0.0)


@wp.func
def box_counts_left(
    cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    x: wp.vec3,
    half_width: float,
    height: float,
    min_visible: float,
    unit: float,
):
    """``(on, area, full)`` summed over the cameras that see the rectangle of a person standing at (x[0], x[1]): its
    mask pixels and its pixels inside the image, both without the parts inside the other tracked people's
    rectangles (``boxes`` from :func:`person_boxes_kernel`, all rows but ``own``; overlapping ones are subtracted
    each, floored at 0 per camera), and its pixels inside the image before that (:func:`box_log_likelihood`); areas
    times ``unit`` (:func:`box_counts`). Per camera: :func:`camera_counts_left`."""
    on_sum = float(0.0)
    area_sum = float(0.0)
    full_sum = float(0.0)
    for c in range(cams.shape[0]):
        seen, on, area, full = camera_counts_left(cams[c], c, integral, boxes, own, x, half_width, height, min_visible)
        if seen != 0:
            full_sum += full
            on_sum += on
            area_sum += area
    return on_sum, area_sum * unit, full_sum * unit


@wp.func
def camera_coverage_left(
    cams: wp.array(dtype=Camera),
    c: int,
    integral: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    x: wp.vec3,
    half_width: float,
    height: float,
    min_visible: float,
    unit: float,
    min_left: float,
):
    """Camera ``c``'s coverage of what the other people's rectangles leave of the rectangle of a person at (x[0],
    x[1]) (:func:`camera_counts_left`), or -1 when the camera does not judge it (does not see it, or the others leave
    less than ``min_left`` of it)."""
    seen, on, area, full = camera_counts_left(cams[c], c, integral, boxes, own, x, half_width, height, min_visible)
    if seen != 0 and area > 0.0 and area >= min_left * full:
        return on / (area * unit)
    return float(-1.0)


@wp.func
def kth_camera_coverage(
    cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    x: wp.vec3,
    half_width: float,
    height: float,
    min_visible: float,
    unit: float,
    min_left: float,
    k: int,
):
    """The ``k``-th largest (1 = the largest) of the judging cameras' coverages (:func:`camera_coverage_left`) of the
    rectangle of a person at (x[0], x[1]), 0 when fewer than ``k`` cameras judge it: "at least ``k`` cameras each see
    this much of the person". Ties are ranked by camera index; cost: cameras^2 rectangle counts."""
    out = float(0.0)
    for i in range(cams.shape[0]):
        ci = camera_coverage_left(cams, i, integral, boxes, own, x, half_width, height, min_visible, unit, min_left)
        if ci >= 0.0:
            rank = int(0)
            for j in range(cams.shape[0]):
                if j != i:
                    cj = camera_coverage_left(
                        cams, j, integral, boxes, own, x, half_width, height, min_visible, unit, min_left
                    )
                    if cj > ci or (cj == ci and j < i):
                        rank += 1
            if rank == k - 1:
                out = ci
    return out


@wp.func
def box_log_likelihood(
    cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    x: wp.vec3,
    half_width: float,
    height: float,
    min_visible: float,
    unit: float,
    slope: float,
    offset: float,
):
    """The person-level term of a particle's log-weight (ours): ``slope * on - offset * area`` with ``on`` the mask
    pixels and ``area`` the pixels of the rectangle of a person standing at the particle's ground position (x[0],
    x[1]), over the cameras that see it, both without the parts inside the other tracked people's rectangles
    (:func:`box_counts_left`).

    It is the gain of POM's generative model (the masks as the union of the people's rectangles) when this person is
    added to the others: pixels another person already explains are neither evidence for this one nor against it,
    so a filter cannot take over another person's silhouette, and a person standing behind another in one view is
    judged by what the others leave of it. With ``slope = log(p1 (1 - p0) / (p0 (1 - p1))) / s`` and ``offset =
    -log((1 - p1) / (1 - p0)) / s`` it is the log-likelihood ratio of "a person here" (each pixel on the mask with
    probability p1) against "nobody" (p0), summed over the pixels and tempered by ``s`` (neighbouring mask pixels
    are not independent: one sample per ``s`` pixels). Summed, not averaged: a rectangle too small (a person placed
    too far, inside another silhouette) leaves the legs unexplained, one too large (too near) takes in floor, so the
    sum peaks where the person stands."""
    on, area, _full = box_counts_left(cams, integral, boxes, own, x, half_width, height, min_visible, unit)
    return slope * on - offset * area


@wp.func
def balanced_box_log_likelihood(
    cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    x: wp.vec3,
    half_width: float,
    height: float,
    min_visible: float,
    unit: float,
    slope: float,
    offset: float,
):
    """:func:`box_log_likelihood` with every camera's term ``slope * on_c - offset * area_c`` weighted by ``w_c = A /
    A_c``: ``A_c`` the area of the person's own rectangle in camera c at its last position (``boxes[own, c]``, the
    same for all its particles, so each camera's term keeps its sum over the rectangle and its peak where the person
    stands), ``A`` the mean of ``A_c`` over the cameras where it is not empty (w_c = 1 where it is). Each camera
    then holds the same number of samples of the person whatever its distance: a camera near the person no longer
    outweighs a far one whose parallax fixes the depth along the near one's rays (the mask pixels of a large
    silhouette are not more independent than those of a small one)."""
    total_area = float(0.0)
    n = float(0.0)
    for c in range(cams.shape[0]):
        b = boxes[own, c]
        a = (b[2] - b[0]) * (b[3] - b[1])
        if b[2] > b[0] and b[3] > b[1]:
            total_area += a
            n += 1.0
    out = float(0.0)
    for c in range(cams.shape[0]):
        seen, on, area, full = camera_counts_left(cams[c], c, integral, boxes, own, x, half_width, height, min_visible)
        if seen != 0:
            w = float(1.0)
            b = boxes[own, c]
            if b[2] > b[0] and b[3] > b[1]:
                w = (total_area / n) / ((b[2] - b[0]) * (b[3] - b[1]))
            out += w * (slope * on - offset * area * unit)
    return out


@wp.func
def exclusion_log_penalty(
    others: wp.array(dtype=wp.vec2), alive: wp.array(dtype=wp.int32), own: int, x: wp.vec3, radius: float, weight: float
):
    """``-weight (1 - d^2 / radius^2)`` for each other tracked person (``alive[k] != 0``, ``k != own``) whose ground
    position ``others[k]`` is within ``radius`` of the particle's (x[0], x[1]) (d their distance, metres), summed: two
    people's filters cannot both hold the same body (ours, beyond the paper)."""
    total = float(0.0)
    r2 = radius * radius
    for k in range(others.shape[0]):
        if k != own and alive[k] != 0:
            dx = x[0] - others[k][0]
            dy = x[1] - others[k][1]
            d2 = dx * dx + dy * dy
            if d2 < r2:
                total -= weight * (1.0 - d2 / r2)
    return total


@wp.func
def person_log_terms(
    cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    others: wp.array(dtype=wp.vec2),
    alive: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    terms: PersonTerms,
    x: wp.vec3,
):
    """:func:`box_log_likelihood` + :func:`exclusion_log_penalty` of a particle at ``x`` of the person in slot ``own``
    (each skipped when its weight, ``terms.slope`` or ``terms.exclusion_weight``, is 0)."""
    total = float(0.0)
    if terms.slope != 0.0 and terms.balance != 0:
        total += balanced_box_log_likelihood(
            cams,
            integral,
            boxes,
            own,
            x,
            terms.half_width,
            terms.height,
            terms.min_visible,
            terms.unit,
            terms.slope,
            terms.offset,
        )
    elif terms.slope != 0.0:
        total += box_log_likelihood(
            cams,
            integral,
            boxes,
            own,
            x,
            terms.half_width,
            terms.height,
            terms.min_visible,
            terms.unit,
            terms.slope,
            terms.offset,
        )
    if terms.exclusion_weight != 0.0:
        total += exclusion_log_penalty(others, alive, own, x, terms.exclusion_radius, terms.exclusion_weight)
    return total


@wp.kernel
def gate_kernel(
    cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    people: wp.array(dtype=wp.vec2),
    own: int,
    terms: PersonTerms,
    reach: float,
    speed: float,
    dt: wp.array(dtype=wp.float32),
    spacing: float,
    min_coverage: float,
    min_left: float,
    cameras: int,
    use: int,
    observe: wp.array(dtype=wp.int32),
    support: wp.array(dtype=wp.float32),
):
    """Whether this frame's masks show the person of slot ``own`` (ours). ``observe[1]`` takes the previous frame's
    ``observe[0]``; ``observe[0]`` = 1 when, somewhere on the grid of ``spacing`` metres within ``reach + speed dt[0]``
    metres (a square, per axis) of its last ground position ``people[own]`` (where the person may have walked in
    one frame interval), the rectangle of a person standing there is covered by the masks over more than
    ``min_coverage`` of what the other people's rectangles leave of it (:func:`box_counts_left`, all cameras that
    see it together), that part being at least ``min_left`` of the rectangle; else 0 (a person standing still whom
    the background model has absorbed, or hidden: the filter then predicts without weighting, instead of following
    the nearest other silhouette). A fraction, so the rule does not depend on the images' resolution. With
    ``cameras`` = k > 0 the coverage at a point is instead the k-th largest of the cameras' own coverages
    (:func:`kth_camera_coverage`: each camera judges what the others leave of its rectangle, where that is at least
    ``min_left`` of it): k cameras must each see the person (a position is fixed by two views; one camera's
    silhouette alone is a ray, where a filter can slide in depth onto another person's silhouette); ``use`` says for
    what: 0 both outputs, 1 only ``support`` (removal; ``observe`` pooled), 2 only ``observe`` (weighting; ``support``
    pooled). Always 1 when
    the rectangle term is off (``terms.slope == 0``). ``support[0]`` = the best such coverage (0 when off). Launch
    ``wp.launch_tiled(dim=[1], block_dim=B)``: the block's lanes share the (2 m + 1)^2 grid points (point j is
    (j // (2 m + 1) - m, j % (2 m + 1) - m) spacings away), their best coverages reduced with ``wp.tile_max`` (a
    maximum: the same for any B; one lane on the CPU); lane 0 writes."""
    _block, lane = wp.tid()
    if terms.slope == 0.0:
        if lane == 0:
            observe[1] = observe[0]
            observe[0] = 1
            support[0] = 0.0
        return
    best = float(0.0)
    best_k = float(0.0)
    p = people[own]
    m = int(wp.ceil((reach + speed * dt[0]) / spacing))
    side = 2 * m + 1
    for j in range(lane, side * side, wp.block_dim()):
        a = j / side - m
        b = j % side - m
        x = wp.vec3(p[0] + spacing * float(a), p[1] + spacing * float(b), 0.0)
        if cameras > 0:
            cov = kth_camera_coverage(
                cams,
                integral,
                boxes,
                own,
                x,
                terms.half_width,
                terms.height,
                terms.min_visible,
                terms.unit,
                min_left,
                cameras,
            )
            best_k = wp.max(best_k, cov)
        if cameras == 0 or use != 0:
            on, area, full = box_counts_left(
                cams, integral, boxes, own, x, terms.half_width, terms.height, terms.min_visible, terms.unit
            )
            if area > 0.0 and area >= min_left * full:
                best = wp.max(best, on / area)
    top = wp.tile_max(wp.tile(best))
    top_k = wp.tile_max(wp.tile(best_k))
    if lane == 0:
        seen = top[0]  # observe (weighting) and support (removal): pooled
        shown = top[0]
        if cameras > 0 and use != 1:
            seen = top_k[0]
        if cameras > 0 and use != 2:
            shown = top_k[0]
        observe[1] = observe[0]
        observe[0] = wp.where(seen > min_coverage, 1, 0)
        support[0] = wp.float32(shown)


HIST_H = wp.constant(8)
"""Hue bins of a person's appearance histogram (:func:`person_histogram_kernel`)."""
HIST_S = wp.constant(4)
"""Saturation bins."""
HIST_V = wp.constant(4)
"""Value bins."""
HIST_BINS = wp.constant(16)
"""Bins per body part: HIST_H + HIST_S + HIST_V."""
HIST_PARTS = wp.constant(2)
"""Body parts: 0 = legs (5 % to 50 % of the rectangle's height), 1 = torso and head (50 % to 100 %)."""
hist_bins = wp.types.vector(length=16, dtype=wp.float32)


@wp.func
def in_any_other(boxes: wp.array2d(dtype=wp.vec4), own: int, c: int, fu: float, fv: float):
    """Whether pixel (fu, fv) lies in the rectangle of another person than ``own`` in camera ``c``."""
    return in_boxes(boxes, boxes.shape[0], own, c, fu, fv)


@wp.kernel
def person_histogram_kernel(
    cams: wp.array(dtype=Camera),
    bgr: wp.array(dtype=wp.uint8),
    mask: wp.array(dtype=wp.uint8),
    boxes: wp.array2d(dtype=wp.vec4),
    hist: wp.array4d(dtype=wp.float32),
):
    """A person's appearance (ours, for re-identification; the S2 paper's appearance is per particle and short-lived):
    HSV histograms of the motion-mask pixels inside the person's rectangle that no other person's rectangle
    claims (crowds do not mix people), per camera and body part (:data:`HIST_PARTS`): ``HIST_H`` hue bins (pixels
    with S >= 0.2 and V >= 0.15: the hue of a grey is noise), ``HIST_S`` saturation and ``HIST_V`` value bins,
    unnormalised pixel counts.

    Launch dim ``(people, cameras, HIST_PARTS, max image height)``: one thread per image row of a rectangle part,
    adding its counts with ``wp.atomic_add`` (whole numbers in float32: exact, so the result does not depend on the
    order). ``hist`` (people, cameras, HIST_PARTS, HIST_BINS + 1) must be zero before the launch: the counts, and in
    the last slot the number of pixels counted. ``boxes`` (people, cameras) from :func:`person_boxes_kernel` (empty
    rectangles count nothing)."""
    i, c, part, v = wp.tid()
    cam = cams[c]
    b = boxes[i, c]
    if b[2] <= b[0] or b[3] <= b[1]:
        return
    h = b[3] - b[1]
    v0 = int(b[1])
    v1 = int(b[1] + 0.5 * h)
    if part == 0:
        v0 = int(b[1] + 0.5 * h)
        v1 = int(b[3] - 0.05 * h)
    if v < v0 or v >= v1:
        return
    acc = hist_bins()
    n = float(0.0)
    for u in range(int(b[0]), int(b[2])):
        p = cam.pixel_offset + v * cam.width + u
        if mask[p] != wp.uint8(0):
            if not in_any_other(boxes, i, c, float(u), float(v)):
                q = 3 * p
                hsv = rgb_to_hsv(float(bgr[q + 2]) / 255.0, float(bgr[q + 1]) / 255.0, float(bgr[q]) / 255.0)
                if hsv[1] >= 0.2 and hsv[2] >= 0.15:
                    k = wp.min(int(hsv[0] * float(HIST_H)), HIST_H - 1)
                    acc[k] = acc[k] + 1.0
                ks = wp.min(int(hsv[1] * float(HIST_S)), HIST_S - 1)
                kv = wp.min(int(hsv[2] * float(HIST_V)), HIST_V - 1)
                acc[HIST_H + ks] = acc[HIST_H + ks] + 1.0
                acc[HIST_H + HIST_S + kv] = acc[HIST_H + HIST_S + kv] + 1.0
                n += 1.0
    if n > 0.0:
        for k in range(HIST_BINS):
            if acc[k] > 0.0:
                wp.atomic_add(hist, i, c, part, k, acc[k])
        wp.atomic_add(hist, i, c, part, HIST_BINS, n)
