"""Independent partitions of the S3 template tracker's objects (beyond the paper): the slot boxes and their groups.

Each particle of the template tracker is a whole scene (Juza et al., section 2.2), so one weight per particle
(eq. 6) judges every object at once: with R objects a particle that fits one object well and another badly is
kept or dropped as a whole, and the particles' diversity per object falls like the R-th root of N (the joint
filter's curse of dimension; on the PETS clip, 4-8 people in view, 10,000 particles gave MOTA 0.50 where 1,000
gave 0.14 with the same masks, docs/notes.md).

The matching penalty is a sum over pixels, so it splits wherever the objects' pixels do. The *box* of slot ``s``
is the union over the particles of the image boxes of its drawn pieces (rows from the hulls, columns from their
vertices, clipped to the image), so every particle's template of that object lies inside it. Slots whose boxes
share a row and come within one column of each other are joined, transitively, into a *group*; the boxes of
different groups are then disjoint and at least one uncovered column apart on every row they share. Inside a group's
box only that group's objects draw pixels in any particle, so

    m'_i = sum_g m'_{i,g} + |q outside every box|,   c_i = sum_g c_{i,g}

(the weighted XOR of eq. 6 and the complexity of eq. 5 with the exclusion prior: two objects of different groups
have disjoint image boxes, so their ground footprints do not overlap either), and the weight of eq. 6 is a product
of one factor per group. Each group is then resampled on its own factor (Orton and Fitzgerald's independent
partition particle filter; MacCormick and Blake's partitioned sampling with one partition per group): particle
``j`` takes group ``g``'s objects from ancestor ``a_g(j)``, so combinations of well-placed objects from different
particles survive. The factorisation holds exactly for the boxes of the frame being scored; objects that interact
(overlapping boxes: a group of people, a person passing a car) share a group and are resampled jointly, as in
the paper. A slot held by some particle but drawn by none (its object out of view everywhere) is a group of its own
with an empty box (its factor is its complexity alone).

Kernels (launch order): :func:`slot_box_kernel` (per block of particles and slot, one atomic maximum per block),
then :func:`group_slots_kernel` (one thread). The groups' factors are
summed by ``kernels.templates.xor`` and weighed by ``kernels.templates.xor.group_logw_kernel``.
"""

import warp as wp

from wptrack.kernels.core.reduce import block_argmax
from wptrack.kernels.templates.raster import PIECES, vec_slots_i

wp.set_module_options({"enable_backward": False})

BOX_NONE = wp.constant(-1073741824)
"""Sentinel of the box maxima: ``-x0``, ``-y0``, ``x1``, ``y1`` are reduced by max, and an empty box is this in
all four (``x1 < x0``)."""


@wp.func
def piece_box(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    i: int,
    q: int,
    nv: int,
    width: int,
    height: int,
):
    """``(-x0, -y0, x1, y1)`` of piece ``q`` of particle ``i`` (``nv`` > 0 hull vertices): its rows and the columns
    ``[max(floor(min x), 0), min(ceil(max x), width - 1)]`` of its vertices, which hold every span
    ``raster.hull_chain_span`` draws (``ceil`` of the left crossing and ``floor`` of the right one)."""
    r = hull_rows[i, q]
    xl = float(3.0e38)
    xr = float(-3.0e38)
    for k in range(nv):
        x = hull_pts[i, q, k][0]
        xl = wp.min(xl, x)
        xr = wp.max(xr, x)
    x0 = wp.max(int(wp.floor(xl)), 0)
    x1 = wp.min(int(wp.ceil(xr)), width - 1)
    return wp.vec4i(-x0, -wp.max(r[0], 0), x1, wp.min(r[1], height - 1))


@wp.func
def max4(a: wp.vec4i, b: wp.vec4i):
    return wp.vec4i(wp.max(a[0], b[0]), wp.max(a[1], b[1]), wp.max(a[2], b[2]), wp.max(a[3], b[3]))


@wp.kernel
def slot_box_kernel(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_rows: wp.array2d(dtype=wp.vec2i),
    kind: wp.array2d(dtype=wp.int32),
    n: int,
    chunk: int,
    width: int,
    height: int,
    slot_acc: wp.array2d(dtype=wp.int32),
):
    """Per block of particles and slot: the union of the slot's drawn pieces' boxes and whether any particle of
    the block holds the slot, reduced by the block, then merged into ``slot_acc`` by one atomic maximum per block and
    component (no per-particle atomics). Launch ``wp.launch_tiled(dim=[blocks, R], block_dim=B)``; block ``b`` owns
    particles ``[b chunk, (b+1) chunk)`` (one lane on the CPU backend).

    Args:
        hull_pts, hull_n, hull_rows: the particles' piece hulls (``raster.template_hulls_kernel``), (N, R PIECES).
        kind: (N, R) KIND_* per slot.
        n, chunk: particles and particles per block.
        width, height: image size, pixels.
        slot_acc: (R, 5) ``(-x0, -y0, x1, y1, alive)`` pixels, maxima over the particles; on entry :data:`BOX_NONE` in
            the first four columns and 0 in the last (as :func:`group_slots_kernel` leaves it).
    """
    b, s, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    box = wp.vec4i(BOX_NONE, BOX_NONE, BOX_NONE, BOX_NONE)
    alive = int(0)
    for i in range(start + lane, stop, wp.block_dim()):
        if kind[i, s] > 0:
            alive = 1
            for p in range(PIECES):
                q = s * PIECES + p
                nv = hull_n[i, q]
                if nv > 0:
                    box = max4(box, piece_box(hull_pts, hull_rows, i, q, nv, width, height))
    # block maxima, one component at a time (float32 holds these integers exactly)
    m0, _a0 = block_argmax(float(box[0]), 0)
    m1, _a1 = block_argmax(float(box[1]), 0)
    m2, _a2 = block_argmax(float(box[2]), 0)
    m3, _a3 = block_argmax(float(box[3]), 0)
    ma, _a4 = block_argmax(float(alive), 0)
    if lane == 0 and int(ma) != 0:  # a block holding no particle of the slot changes nothing
        wp.atomic_max(slot_acc, s, 0, int(m0))
        wp.atomic_max(slot_acc, s, 1, int(m1))
        wp.atomic_max(slot_acc, s, 2, int(m2))
        wp.atomic_max(slot_acc, s, 3, int(m3))
        wp.atomic_max(slot_acc, s, 4, 1)


@wp.func
def boxes_touch(a: wp.vec4i, b: wp.vec4i):
    """Two non-empty boxes ``(x0, y0, x1, y1)`` share a row and come within one column of each other."""
    if a[2] < a[0] or b[2] < b[0]:
        return False
    return a[1] <= b[3] and b[1] <= a[3] and a[0] <= b[2] + 1 and b[0] <= a[2] + 1


@wp.func
def root_of(parent: vec_slots_i, s: int):
    r = s
    while parent[r] != r:
        r = parent[r]
    return r


@wp.kernel
def group_slots_kernel(
    slot_acc: wp.array2d(dtype=wp.int32),
    partition: int,
    slot_box: wp.array(dtype=wp.vec4i),
    slot_alive: wp.array(dtype=wp.int32),
    slot_group: wp.array(dtype=wp.int32),
    group_box: wp.array(dtype=wp.vec4i),
    group_first: wp.array(dtype=wp.int32),
    group_active: wp.array(dtype=wp.int32),
    n_groups: wp.array(dtype=wp.int32),
    slot_hi: wp.array(dtype=wp.int32),
):
    """The slot boxes from :func:`slot_box_kernel`'s maxima, which it resets for the next frame, then the slots'
    groups (see the module docstring) and the bound of the slots in use. One thread (``dim=1``); R <=
    ``raster.MAX_SLOTS`` slots.

    Groups are numbered by their lowest slot, in slot order. With ``partition`` 0 every alive slot is put in group
    0 (the joint filter of the paper: one factor, one resampling).

    Args:
        slot_acc: (R, 5) from :func:`slot_box_kernel`; left as it expects it (:data:`BOX_NONE`, 0).
        partition: 1 to split the slots into independent groups, 0 for one group.
        slot_box: (R,) ``(x0, y0, x1, y1)`` pixels per slot (``(0, 0, -1, -1)``: drawn by no particle).
        slot_alive: (R,) 1 where some particle holds the slot.
        slot_group: (R,) group of each slot, -1 for a slot no particle holds.
        group_box: (R,) box of each group (the union of its slots' boxes; empty for a group of undrawn slots).
        group_first: (R,) lowest slot of each group (-1 past the last group).
        group_active: (R,) 1 for the groups in use (``g < n_groups[0]``), else 0.
        n_groups: (1,) number of groups.
        slot_hi: (1,) one past the highest slot some particle holds (0: none): the slots from it on are empty in
            every particle, so their pieces are not drawn (``kernels.templates.xor`` scans the pieces below it only;
            an R_max well above the scene's count costs the scoring little).
    """
    r = slot_group.shape[0]
    parent = vec_slots_i()
    x0 = vec_slots_i()
    y0 = vec_slots_i()
    x1 = vec_slots_i()
    y1 = vec_slots_i()
    alive = vec_slots_i()
    for s in range(r):
        box = wp.vec4i(0, 0, -1, -1)
        if slot_acc[s, 2] != BOX_NONE:
            box = wp.vec4i(-slot_acc[s, 0], -slot_acc[s, 1], slot_acc[s, 2], slot_acc[s, 3])
        slot_box[s] = box
        slot_alive[s] = slot_acc[s, 4]
        parent[s] = s
        x0[s] = box[0]
        y0[s] = box[1]
        x1[s] = box[2]
        y1[s] = box[3]
        alive[s] = slot_acc[s, 4]
        for c in range(4):
            slot_acc[s, c] = BOX_NONE
        slot_acc[s, 4] = 0
    if partition != 0:
        changed = int(1)
        while changed != 0:
            changed = int(0)
            for s in range(r):
                if alive[s] != 0 and parent[s] == s:
                    for t in range(s + 1, r):
                        if alive[t] != 0 and parent[t] == t:
                            ba = wp.vec4i(x0[s], y0[s], x1[s], y1[s])
                            bb = wp.vec4i(x0[t], y0[t], x1[t], y1[t])
                            if boxes_touch(ba, bb):
                                parent[t] = s
                                x0[s] = wp.min(x0[s], x0[t])
                                y0[s] = wp.min(y0[s], y0[t])
                                x1[s] = wp.max(x1[s], x1[t])
                                y1[s] = wp.max(y1[s], y1[t])
                                changed = int(1)
    else:
        first = int(-1)
        for s in range(r):
            if alive[s] != 0:
                if first < 0:
                    first = s
                else:
                    parent[s] = first
                    if x1[s] >= x0[s]:
                        if x1[first] < x0[first]:
                            x0[first] = x0[s]
                            y0[first] = y0[s]
                            x1[first] = x1[s]
                            y1[first] = y1[s]
                        else:
                            x0[first] = wp.min(x0[first], x0[s])
                            y0[first] = wp.min(y0[first], y0[s])
                            x1[first] = wp.max(x1[first], x1[s])
                            y1[first] = wp.max(y1[first], y1[s])
    ids = vec_slots_i()
    for s in range(r):
        ids[s] = -1
    count = int(0)
    for s in range(r):
        slot_group[s] = -1
        if alive[s] != 0:
            root = root_of(parent, s)
            if ids[root] < 0:
                ids[root] = count
                group_first[count] = s
                group_box[count] = wp.vec4i(x0[root], y0[root], x1[root], y1[root])
                count += 1
            slot_group[s] = ids[root]
    for g in range(r):
        group_active[g] = 0
        if g < count:
            group_active[g] = 1
        else:
            group_first[g] = -1
            group_box[g] = wp.vec4i(0, 0, -1, -1)
    n_groups[0] = count
    top = int(0)
    for s in range(r):
        if alive[s] != 0:
            top = s + 1
    slot_hi[0] = top


@wp.func
def group_at(group_box: wp.array(dtype=wp.vec4i), groups: int, x: int, y: int):
    """The group whose box holds pixel ``(x, y)`` (-1 if none): the boxes of different groups are disjoint."""
    found = int(-1)
    for g in range(groups):
        bx = group_box[g]
        if x >= bx[0] and x <= bx[2] and y >= bx[1] and y <= bx[3]:
            found = g
    return found
