"""Per-object occlusion within a particle's scene, for the S3 template tracker's prediction (beyond Juza et al.).

The virtual scene of a particle is the union of its templates (eq. 4), so an object hidden behind nearer objects
of the same particle explains almost no pixel of the motion image: the likelihood (eq. 6) says nothing about it.
Under the paper's prediction such an object still gets the full velocity noise (eqs. 8-9) and the full deletion
probability T_del (eq. 13) every frame: it wanders, and deletion, which costs the particle nothing while the
object is hidden, removes it from a growing share of the particles until its slot is freed; when the person
reappears a new label is added for them (an identity switch). ``occlusion_kernel`` measures, for every object of
every particle, the fraction of its image that nearer objects of the same particle hide; the prediction
(``dynamics.template_predict_kernel``) lowers the deletion probability and the diffusion of hidden objects.

Off by default (``TemplateConfig.occlusion_del`` = ``occlusion_noise`` = 0, the kernel is then not launched): on
the tuning scene it did not lower the group identity switches (docs/notes.md); kept as an option.

The measure is on image boxes: each piece's hull (``raster.template_hulls_kernel``) is replaced by its bounding
box clipped to the image, and the occlusion of object ``s`` is

    occ(s) = min(1, sum_{t nearer than s} sum_{a in pieces(s), b in pieces(t)} |box_a & box_b| / sum_a |box_a|)

(pixels^2 / pixels^2; overlaps of two occluders are counted twice, hence the clamp). Objects with no piece in the
image have occlusion 0. "Nearer" compares the camera depth of the objects' ground points (``hull_depth``), ties
broken by the lower slot.
"""

import warp as wp

from wptrack.kernels.templates.raster import PIECES

wp.set_module_options({"enable_backward": False})


@wp.func
def piece_box(hull_pts: wp.array3d(dtype=wp.vec2), i: int, q: int, n: int, width: int, height: int):
    """Bounding box ``(x0, x1, y0, y1)`` of hull ``q`` of particle ``i`` (``n`` vertices), clipped to the image
    ``[0, width] x [0, height]`` (pixels; ``x1 <= x0`` or ``y1 <= y0``: empty)."""
    p = hull_pts[i, q, 0]
    x0 = p[0]
    x1 = p[0]
    y0 = p[1]
    y1 = p[1]
    for k in range(1, n):
        p = hull_pts[i, q, k]
        x0 = wp.min(x0, p[0])
        x1 = wp.max(x1, p[0])
        y0 = wp.min(y0, p[1])
        y1 = wp.max(y1, p[1])
    w = float(width)
    h = float(height)
    return wp.vec4(wp.clamp(x0, 0.0, w), wp.clamp(x1, 0.0, w), wp.clamp(y0, 0.0, h), wp.clamp(y1, 0.0, h))


@wp.func
def box_area(b: wp.vec4):
    """Area of a box ``(x0, x1, y0, y1)``, pixels^2 (0 when empty)."""
    return wp.max(b[1] - b[0], 0.0) * wp.max(b[3] - b[2], 0.0)


@wp.func
def box_overlap(a: wp.vec4, b: wp.vec4):
    """Area of the intersection of two boxes ``(x0, x1, y0, y1)``, pixels^2."""
    w = wp.min(a[1], b[1]) - wp.max(a[0], b[0])
    h = wp.min(a[3], b[3]) - wp.max(a[2], b[2])
    return wp.max(w, 0.0) * wp.max(h, 0.0)


@wp.kernel
def occlusion_kernel(
    hull_pts: wp.array3d(dtype=wp.vec2),
    hull_n: wp.array2d(dtype=wp.int32),
    hull_depth: wp.array2d(dtype=wp.float32),
    width: int,
    height: int,
    occlusion: wp.array2d(dtype=wp.float32),
):
    """Fraction of each object's image box hidden by nearer objects of the same particle (module docstring).

    Launch with ``dim=(N, R)``: one thread per particle and slot.

    Args:
        hull_pts, hull_n, hull_depth: the particles' piece hulls (N, R * PIECES, HULL_MAX) pixels, vertex counts
            (N, R * PIECES) (0: no piece) and the camera depth of each object's ground point (N, R * PIECES),
            metres, from ``raster.template_hulls_kernel``.
        width, height: image size, pixels.
        occlusion: (N, R) output, in [0, 1] (0 for empty slots and objects outside the image).
    """
    i, s = wp.tid()
    slots = occlusion.shape[1]
    area = float(0.0)
    for a in range(PIECES):
        qa = s * PIECES + a
        if hull_n[i, qa] > 0:
            area += box_area(piece_box(hull_pts, i, qa, hull_n[i, qa], width, height))
    occ = float(0.0)
    if area > 0.0:
        depth = hull_depth[i, s * PIECES]
        hidden = float(0.0)
        for t in range(slots):
            qt = t * PIECES
            dt = hull_depth[i, qt]
            nearer = dt < depth or (dt == depth and t < s)
            if t != s and nearer and (hull_n[i, qt] > 0 or hull_n[i, qt + 1] > 0):
                for a in range(PIECES):
                    qa = s * PIECES + a
                    if hull_n[i, qa] > 0:
                        ba = piece_box(hull_pts, i, qa, hull_n[i, qa], width, height)
                        for b in range(PIECES):
                            qb = qt + b
                            if hull_n[i, qb] > 0:
                                hidden += box_overlap(ba, piece_box(hull_pts, i, qb, hull_n[i, qb], width, height))
        occ = wp.min(hidden / area, 1.0)
    occlusion[i, s] = occ
