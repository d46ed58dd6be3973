"""Ground-footprint overlap of two objects of the S3 template tracker: the exclusion prior that
``kernels.templates.xor`` adds to eq. 5's complexity (beyond the paper: solid objects cannot stand on the same
ground), also the footprint tests of ``kernels.templates.dynamics`` (an added vehicle absorbs the humans on its
footprint) and ``kernels.templates.classify``. Humans are ground discs of their body radius; vehicles and cyclists
boxes of their length and width.
"""

import warp as wp

from wptrack.kernels.templates.raster import KIND_HUMAN

wp.set_module_options({"enable_backward": False})


@wp.func
def disc_in_box(c: wp.vec2, r: float, centre: wp.vec2, heading: float, half: wp.vec2):
    """Penetration of a ground disc (centre ``c``, radius ``r``, metres) into an oriented box (``centre``,
    ``heading`` radians, half length and half width ``half``, metres), as a fraction of the disc's diameter in
    [0, 1]: 0 when they do not overlap, 1 when the disc is pushed a whole diameter in."""
    d = c - centre
    ca = wp.cos(heading)
    sa = wp.sin(heading)
    lx = wp.abs(ca * d[0] + sa * d[1])
    ly = wp.abs(-sa * d[0] + ca * d[1])
    depth = wp.min(half[0] + r - lx, half[1] + r - ly)
    return wp.clamp(depth / (2.0 * r), 0.0, 1.0)


@wp.func
def footprint(k: int, dims: wp.vec3):
    """Radius of an object's ground disc (human: body radius; vehicle: half width, metres)."""
    if k == KIND_HUMAN:
        return dims[1]
    return 0.5 * dims[1]


@wp.func
def pair_overlap(ka: int, pa: wp.vec2, ha: float, da: wp.vec3, kb: int, pb: wp.vec2, hb: float, db: wp.vec3):
    """Ground-footprint overlap of two objects in [0, 1] (the exclusion prior of ``xor_score_kernel``).

    Humans are discs of their body radius, vehicles boxes of their length and width. Two humans: ``1 - d / (r_a +
    r_b)`` (d the distance of their centres). Human and vehicle: the disc's penetration into the box
    (``disc_in_box``). Two vehicles: the deepest penetration of three discs of half the width along b (its centre
    and both ends) into a's box.
    """
    if ka == KIND_HUMAN and kb == KIND_HUMAN:
        return wp.clamp(1.0 - wp.length(pa - pb) / (da[1] + db[1]), 0.0, 1.0)
    if ka == KIND_HUMAN:
        return disc_in_box(pa, da[1], pb, hb, wp.vec2(0.5 * db[0], 0.5 * db[1]))
    if kb == KIND_HUMAN:
        return disc_in_box(pb, db[1], pa, ha, wp.vec2(0.5 * da[0], 0.5 * da[1]))
    r = 0.5 * db[1]
    along = wp.max(0.5 * db[0] - r, 0.0) * wp.vec2(wp.cos(hb), wp.sin(hb))
    half = wp.vec2(0.5 * da[0], 0.5 * da[1])
    o = disc_in_box(pb, r, pa, ha, half)
    o = wp.max(o, disc_in_box(pb + along, r, pa, ha, half))
    return wp.max(o, disc_in_box(pb - along, r, pa, ha, half))
