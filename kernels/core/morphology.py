"""Binary morphology and hysteresis of motion masks on the device (issue 27: the clean-up without a host round trip).

Images are ``wp.array2d(dtype=wp.uint8)`` of shape ``(H, W)``, values 0/1 unless said otherwise.

* :func:`morph_kernel`: erosion or dilation by a structuring element given as row runs ``(dy, dx0, dx1)`` (an
  ellipse is one run per row), a thread per pixel. As OpenCV's default border: pixels outside the image are left out
  (for the erosion they count as foreground, for the dilation as background), so ``open = dilate(erode(q))`` and
  ``close = erode(dilate(q))`` give ``cv2.morphologyEx``'s values.
* :func:`unpack_kernel`, :func:`penumbra_kernel`: the offline model's packed output ``level + 4 shadow``
  (``kernels.core.background.foreground_kernel``) split into levels (0 background, 1 weak, 2 strong) and the cast
  shadow's core (shadow 2); penumbra candidates (shadow 1) near a core (the core dilated) become background.
* :func:`hysteresis_seed_kernel`, :func:`hysteresis_rows_kernel`, :func:`hysteresis_cols_kernel`: the weak pixels
  8-connected to a strong one join the mask. Seeded with the strong pixels, each sweep walks a row (or a column)
  forth and back and lets a weak pixel join when one of its 8 neighbours has joined, in place; the sweeps alternate
  until one changes nothing (``changed`` stays 0). Joining only ever adds pixels, so the order of the writes does
  not matter: the fixpoint is the union of the 8-connected components of ``level > 0`` that hold a strong pixel, the
  host's connected-components result (``wptrack.motion.levels.hysteresis``), in a few sweeps for blob-shaped
  components (a path that turns back on itself costs a sweep per turn).
"""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.kernel
def morph_kernel(
    src: wp.array2d(dtype=wp.uint8),
    runs: wp.array(dtype=wp.vec3i),
    count: int,
    erode: int,
    dst: wp.array2d(dtype=wp.uint8),
):
    """``dst = erode ? min : max`` of ``src`` over the element's pixels ``(y + dy, x + dx)``, ``dx0 <= dx <= dx1`` for
    each run ``(dy, dx0, dx1)`` of ``runs[:count]``; pixels outside the image are left out. Launch ``dim=(H, W)``."""
    y, x = wp.tid()
    h = src.shape[0]
    w = src.shape[1]
    want = wp.uint8(0)
    if erode == 0:
        want = wp.uint8(1)
    for k in range(count):
        r = runs[k]
        yy = y + r[0]
        if yy >= 0 and yy < h:
            for dx in range(r[1], r[2] + 1):
                xx = x + dx
                if xx >= 0 and xx < w:
                    if src[yy, xx] == want:  # erosion: a background pixel; dilation: a foreground one
                        dst[y, x] = want
                        return
    dst[y, x] = wp.uint8(1) - want


@wp.kernel
def unpack_kernel(
    packed: wp.array2d(dtype=wp.uint8),
    levels: wp.array2d(dtype=wp.uint8),
    core: wp.array2d(dtype=wp.uint8),
):
    """``levels = packed & 3`` and ``core = (packed >> 2) == 2`` (the cast shadow's core). Launch ``dim=(H, W)``."""
    y, x = wp.tid()
    v = int(packed[y, x])
    levels[y, x] = wp.uint8(v & 3)
    core[y, x] = wp.uint8(0)
    if (v >> 2) == 2:
        core[y, x] = wp.uint8(1)


@wp.kernel
def penumbra_kernel(
    packed: wp.array2d(dtype=wp.uint8),
    near: wp.array2d(dtype=wp.uint8),
    levels: wp.array2d(dtype=wp.uint8),
    prob: wp.array2d(dtype=wp.float32),
    has_prob: int,
):
    """A penumbra candidate (``packed >> 2 == 1``) where ``near`` (the core dilated) is set becomes background:
    level 0 and, with ``has_prob``, probability 0. Launch ``dim=(H, W)``."""
    y, x = wp.tid()
    if (int(packed[y, x]) >> 2) == 1 and near[y, x] != wp.uint8(0):
        levels[y, x] = wp.uint8(0)
        if has_prob != 0:
            prob[y, x] = 0.0


@wp.kernel
def hysteresis_seed_kernel(levels: wp.array2d(dtype=wp.uint8), mask: wp.array2d(dtype=wp.uint8)):
    """``mask = levels == 2`` (the strong pixels). Launch ``dim=(H, W)``."""
    y, x = wp.tid()
    mask[y, x] = wp.uint8(0)
    if levels[y, x] == wp.uint8(2):
        mask[y, x] = wp.uint8(1)


@wp.func
def joins(levels: wp.array2d(dtype=wp.uint8), mask: wp.array2d(dtype=wp.uint8), y: int, x: int, h: int, w: int):
    """Whether pixel ``(y, x)`` is weak, not yet in ``mask``, and has an 8-neighbour in ``mask``."""
    if levels[y, x] == wp.uint8(0) or mask[y, x] != wp.uint8(0):
        return False
    for dy in range(-1, 2):
        yy = y + dy
        if yy >= 0 and yy < h:
            for dx in range(-1, 2):
                xx = x + dx
                if xx >= 0 and xx < w:
                    if mask[yy, xx] != wp.uint8(0):
                        return True
    return False


@wp.kernel
def hysteresis_rows_kernel(
    levels: wp.array2d(dtype=wp.uint8),
    mask: wp.array2d(dtype=wp.uint8),
    changed: wp.array(dtype=wp.int32),
):
    """One row per thread, left to right then right to left: weak pixels next to the mask join it (in place);
    ``changed[0] = 1`` when any did. Launch ``dim=H``."""
    y = wp.tid()
    h = levels.shape[0]
    w = levels.shape[1]
    grew = int(0)
    for x in range(w):
        if joins(levels, mask, y, x, h, w):
            mask[y, x] = wp.uint8(1)
            grew = 1
    for k in range(w):
        x = w - 1 - k
        if joins(levels, mask, y, x, h, w):
            mask[y, x] = wp.uint8(1)
            grew = 1
    if grew != 0:
        changed[0] = 1


@wp.kernel
def hysteresis_cols_kernel(
    levels: wp.array2d(dtype=wp.uint8),
    mask: wp.array2d(dtype=wp.uint8),
    changed: wp.array(dtype=wp.int32),
):
    """:func:`hysteresis_rows_kernel` along the columns, top to bottom then bottom to top. Launch ``dim=W``."""
    x = wp.tid()
    h = levels.shape[0]
    w = levels.shape[1]
    grew = int(0)
    for y in range(h):
        if joins(levels, mask, y, x, h, w):
            mask[y, x] = wp.uint8(1)
            grew = 1
    for k in range(h):
        y = h - 1 - k
        if joins(levels, mask, y, x, h, w):
            mask[y, x] = wp.uint8(1)
            grew = 1
    if grew != 0:
        changed[0] = 1
