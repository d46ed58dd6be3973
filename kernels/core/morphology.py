"""Binary morphology and hysteresis of motion masks on the device (issue 27: the clean-up without a host round trip).

Images are ``wp.array2d(dtype=wp.uint8)`` of shape ``(H, W)``, values 0/1 unless said otherwise.

* :func:`morph_kernel`: erosion or dilation by a structuring element given as row runs ``(dy, dx0, dx1)`` (an
  ellipse is one run per row), a thread per pixel. As OpenCV's default border: pixels outside the image are left out
  (for the erosion they count as foreground, for the dilation as background), so ``open = dilate(erode(q))`` and
  ``close = erode(dilate(q))`` give ``cv2.morphologyEx``'s values.
* :func:`unpack_kernel`, :func:`penumbra_kernel`: the offline model's packed output ``level + 4 shadow``
  (``kernels.core.background.foreground_kernel``) split into levels (0 background, 1 weak, 2 strong) and the cast
  shadow's core (shadow 2); penumbra candidates (shadow 1) near a core (the core dilated) become background.
* :func:`label_init_kernel`, :func:`label_merge_kernel`, :func:`label_flatten_kernel`, :func:`strong_roots_kernel`,
  :func:`hysteresis_kernel`: the hysteresis, the weak pixels 8-connected to a strong one joining the mask, as a
  connected-components labelling of ``level > 0`` by union-find (Playne and Hawick, "A new algorithm for parallel
  connected-component labelling on GPUs", IEEE TPDS 2018): every pixel starts as its own tree, joins its
  neighbours' trees by atomic minima (the root of a component is its smallest pixel index, whatever the order of the
  joins), points at its root; the roots of components with a strong pixel are marked and the mask read off them. A
  fixed chain of five launches, no read-back (an earlier version swept rows and columns until nothing changed,
  reading a flag back every two sweeps: ~3 waits for the device a 1080p frame, slower than the host).
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


@wp.func
def root_of(labels: wp.array(dtype=wp.int32), a: int) -> int:
    """The root of pixel ``a``'s tree (a label that points to itself). Labels only ever decrease towards their
    root, so a chain read while other threads link trees (a stale value included) still ends at a root."""
    b = labels[a]
    while b != a:
        a = b
        b = labels[a]
    return a


@wp.func
def link(labels: wp.array(dtype=wp.int32), a: int, b: int):
    """Join the trees of pixels ``a`` and ``b``: the larger root is linked under the smaller one by an atomic
    minimum; when another thread linked that root meanwhile (the minimum returns another value than the root), the
    join is retried from there (Playne and Hawick, IEEE TPDS 2018, union-find labelling)."""
    done = int(0)
    while done == 0:
        a = root_of(labels, a)
        b = root_of(labels, b)
        if a < b:
            old = wp.atomic_min(labels, b, a)
            if old == b:
                done = 1
            else:
                b = old
        elif b < a:
            old = wp.atomic_min(labels, a, b)
            if old == a:
                done = 1
            else:
                a = old
        else:
            done = 1


@wp.kernel
def label_init_kernel(levels: wp.array2d(dtype=wp.uint8), labels: wp.array(dtype=wp.int32)):
    """Each pixel of ``levels > 0`` its own tree: ``labels[y W + x] = y W + x``, -1 elsewhere. Launch ``dim=(H,
    W)``."""
    y, x = wp.tid()
    p = y * levels.shape[1] + x
    if levels[y, x] != wp.uint8(0):
        labels[p] = p
    else:
        labels[p] = -1


@wp.kernel
def label_merge_kernel(levels: wp.array2d(dtype=wp.uint8), labels: wp.array(dtype=wp.int32)):
    """Join each pixel of ``levels > 0`` with its 8-neighbours of ``levels > 0`` to its left and in the row above
    (the other four join it from their side): afterwards each tree is one 8-connected component. Launch ``dim=(H,
    W)``."""
    y, x = wp.tid()
    w = levels.shape[1]
    if levels[y, x] == wp.uint8(0):
        return
    p = y * w + x
    if x > 0 and levels[y, x - 1] != wp.uint8(0):
        link(labels, p, p - 1)
    if y > 0:
        if x > 0 and levels[y - 1, x - 1] != wp.uint8(0):
            link(labels, p, p - w - 1)
        if levels[y - 1, x] != wp.uint8(0):
            link(labels, p, p - w)
        if x < w - 1 and levels[y - 1, x + 1] != wp.uint8(0):
            link(labels, p, p - w + 1)


@wp.kernel
def label_flatten_kernel(levels: wp.array2d(dtype=wp.uint8), labels: wp.array(dtype=wp.int32)):
    """Point every labelled pixel at its root (the smallest pixel index of its component). Launch ``dim=(H, W)``."""
    y, x = wp.tid()
    if levels[y, x] != wp.uint8(0):
        p = y * levels.shape[1] + x
        labels[p] = root_of(labels, p)


@wp.kernel
def strong_roots_kernel(
    levels: wp.array2d(dtype=wp.uint8), labels: wp.array(dtype=wp.int32), strong: wp.array(dtype=wp.uint8)
):
    """``strong[root] = 1`` for the components that hold a strong pixel (level 2); ``strong`` must hold zeros
    (every writer writes 1: the order does not matter). Launch ``dim=(H, W)`` after :func:`label_flatten_kernel`."""
    y, x = wp.tid()
    if levels[y, x] == wp.uint8(2):
        strong[labels[y * levels.shape[1] + x]] = wp.uint8(1)


@wp.kernel
def hysteresis_kernel(
    levels: wp.array2d(dtype=wp.uint8),
    labels: wp.array(dtype=wp.int32),
    strong: wp.array(dtype=wp.uint8),
    mask: wp.array2d(dtype=wp.uint8),
):
    """``mask = 1`` on the components of ``levels > 0`` that hold a strong pixel, 0 elsewhere (the host's
    ``wptrack.motion.levels.hysteresis``). Launch ``dim=(H, W)`` after :func:`strong_roots_kernel`."""
    y, x = wp.tid()
    m = wp.uint8(0)
    if levels[y, x] != wp.uint8(0):
        m = strong[labels[y * levels.shape[1] + x]]
    mask[y, x] = m
