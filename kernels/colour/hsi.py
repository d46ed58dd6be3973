"""Colour classification (HSI target of Barrera et al., section II.B) and per-camera integral images.

Frames arrive as one flat ``uint8`` buffer of BGR pixels for all cameras (camera ``c`` starts at pixel
``cams[c].pixel_offset``). A pixel matches the target when its hue is within [H_min, H_max] degrees
(wrapping through 0 when H_min > H_max), its saturation within [S_min, S_max] and its intensity within
[I_min, I_max] (too dark or too bright pixels never match).

The test depends on the 24-bit colour only, so it is evaluated once per colour into a 2^24-bit table (2 MiB,
:func:`colour_table_kernel`, once per target) and a pixel costs one table read: on a CPU core the arithmetic
test measured ~18 ns per noisy pixel (branch-free rewrites did not help), the table read ~3 ns.
"""

import warp as wp

from wptrack.kernels.core.camera import Camera

wp.set_module_options({"enable_backward": False})


@wp.struct
class ColourTarget:
    """HSI target colour: hue in degrees [0, 360), saturation in [0, 1], intensity in [0, 255]."""

    h_min: float
    h_max: float
    s_min: float
    s_max: float
    i_min: float
    i_max: float
    lower: wp.vec4  # hue range on the half B <= G (hue = acos c) as two intervals of c = cos(hue): lo1 hi1 lo2 hi2
    upper: wp.vec4  # the same for the half B > G (hue = 360 - acos c)
    table: wp.array(dtype=wp.uint32)  # (2^19,) bit (r << 16 | g << 8 | b) set when that colour matches


@wp.func
def rgb_to_hsi(r: float, g: float, b: float):
    """RGB (0..255) to HSI: ``vec3(hue degrees [0, 360), saturation [0, 1], intensity [0, 255])``."""
    total = r + g + b
    i = total / 3.0
    s = float(0.0)
    if total > 0.0:
        s = 1.0 - 3.0 * wp.min(r, wp.min(g, b)) / total
    num = 0.5 * ((r - g) + (r - b))
    den = wp.sqrt((r - g) * (r - g) + (r - b) * (g - b))
    h = float(0.0)
    if den > 1.0e-6:
        h = wp.degrees(wp.acos(wp.clamp(num / den, -1.0, 1.0)))
        if b > g:
            h = 360.0 - h
    return wp.vec3(h, s, i)


@wp.func
def in_intervals(c: float, iv: wp.vec4):
    return (c >= iv[0] and c <= iv[1]) or (c >= iv[2] and c <= iv[3])


@wp.func
def matches(target: ColourTarget, r: float, g: float, b: float):
    """1 if the RGB pixel matches the HSI target, else 0.

    Same test as comparing :func:`rgb_to_hsi`'s hue with [H_min, H_max], without the arc cosine: the hue range is
    precomputed (host side) as intervals of cos(hue) on each half of the hue circle (B <= G: hue in [0, 180];
    B > G: hue in (180, 360)), where the cosine is monotonic.
    """
    total = r + g + b
    i = total / 3.0
    if i < target.i_min or i > target.i_max or total <= 0.0:
        return 0
    s = 1.0 - 3.0 * wp.min(r, wp.min(g, b)) / total
    if s < target.s_min or s > target.s_max:
        return 0
    num = 0.5 * ((r - g) + (r - b))
    den = wp.sqrt((r - g) * (r - g) + (r - b) * (g - b))
    c = float(1.0)  # grey: hue 0
    upper = False
    if den > 1.0e-6:
        c = wp.clamp(num / den, -1.0, 1.0)
        upper = b > g
    if upper:
        if in_intervals(c, target.upper):
            return 1
        return 0
    if in_intervals(c, target.lower):
        return 1
    return 0


TABLE_WORDS = wp.constant(1 << 19)
"""32-bit words of the colour table (2^24 colours, one bit each)."""


@wp.kernel
def colour_table_kernel(target: ColourTarget, table: wp.array(dtype=wp.uint32)):
    """Evaluate :func:`matches` for every 24-bit colour: launch ``dim=TABLE_WORDS``; word ``w`` holds colours
    ``32 w .. 32 w + 31`` (index ``r << 16 | g << 8 | b``), bit k for colour ``32 w + k``."""
    w = wp.tid()
    acc = wp.uint32(0)
    for k in range(32):
        idx = w * 32 + k
        if matches(target, float((idx >> 16) & 255), float((idx >> 8) & 255), float(idx & 255)) == 1:
            acc = acc | (wp.uint32(1) << wp.uint32(k))
    table[w] = acc


@wp.func
def pixel_matches(target: ColourTarget, bgr: wp.array(dtype=wp.uint8), pixel: int):
    """Classify the pixel at flat index ``pixel`` of a BGR buffer (one read of the target's colour table)."""
    o = 3 * pixel
    idx = (int(bgr[o + 2]) << 16) | (int(bgr[o + 1]) << 8) | int(bgr[o])
    return int((target.table[idx >> 5] >> wp.uint32(idx & 31)) & wp.uint32(1))


MASK_PIXELS_PER_THREAD = wp.constant(4)
"""Consecutive pixels classified by one thread of :func:`target_mask_kernel`."""


@wp.kernel
def target_mask_kernel(
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    total: int,
    mask: wp.array(dtype=wp.uint8),
):
    """Target mask of every camera at once: the cameras' frames lie back to back in ``bgr`` (3 bytes per pixel) and
    the mask is flat like them (1 byte per pixel), so the classification needs no camera: ``total`` pixels in all,
    :data:`MASK_PIXELS_PER_THREAD` consecutive ones per thread (a thread per pixel of a (cameras, pixels) launch,
    each loading its camera, took 15 us for 4 x 640 x 480 on an H100). Launch ceil(total / MASK_PIXELS_PER_THREAD).
    """
    t = wp.tid()
    first = t * MASK_PIXELS_PER_THREAD
    for q in range(first, wp.min(first + MASK_PIXELS_PER_THREAD, total)):
        mask[q] = wp.uint8(pixel_matches(target, bgr, q))


HALF_WINDOW = wp.constant(2)
"""The paper's 5x5 window: 2 pixels each side of the projected pixel."""


@wp.func
def window_count_integral(cam: Camera, integral: wp.array(dtype=wp.int32), px: int, py: int):
    """m from the integral image: the 5x5 window clipped to the image, 4 reads."""
    x0 = wp.max(px - HALF_WINDOW, 0)
    x1 = wp.min(px + HALF_WINDOW, cam.width - 1) + 1
    y0 = wp.max(py - HALF_WINDOW, 0)
    y1 = wp.min(py + HALF_WINDOW, cam.height - 1) + 1
    w1 = cam.width + 1
    base = cam.integral_offset
    return (
        integral[base + y1 * w1 + x1]
        - integral[base + y0 * w1 + x1]
        - integral[base + y1 * w1 + x0]
        + integral[base + y0 * w1 + x0]
    )


SEGMENT = wp.constant(32)
"""Pixels per thread in the segmented scans of the integral image."""


@wp.kernel
def row_segment_sums_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    seg: wp.array3d(dtype=wp.int32),
):
    """Integral image, pass 1 of 4: sum of each 32-pixel segment of every mask row. Launch (M, max H, segments);
    ``seg`` (M, max H, ceil(max W / 32))."""
    c, y, s = wp.tid()
    cam = cams[c]
    if y >= cam.height:
        return
    x0 = s * SEGMENT
    x1 = wp.min(x0 + SEGMENT, cam.width)
    src = cam.pixel_offset + y * cam.width
    acc = int(0)
    for x in range(x0, x1):
        acc += int(mask[src + x])
    seg[c, y, s] = acc


@wp.kernel
def row_scan_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    seg: wp.array3d(dtype=wp.int32),
    integral: wp.array(dtype=wp.int32),
):
    """Integral image, pass 2 of 4: row prefix sums (earlier segments' sums + a scan of this segment) into rows
    1..H of the (H+1) x (W+1) integral image; row 0 and column 0 are zero."""
    c, y, s = wp.tid()
    cam = cams[c]
    if y >= cam.height:
        return
    w1 = cam.width + 1
    x0 = s * SEGMENT
    if x0 >= cam.width:
        return
    x1 = wp.min(x0 + SEGMENT, cam.width)
    acc = int(0)
    for k in range(s):
        acc += seg[c, y, k]
    base = cam.integral_offset + (y + 1) * w1
    src = cam.pixel_offset + y * cam.width
    if s == 0:
        integral[base] = 0
    for x in range(x0, x1):
        acc += int(mask[src + x])
        integral[base + x + 1] = acc
    if y == 0:
        for x in range(x0, x1):
            integral[cam.integral_offset + x + 1] = 0
        if s == 0:
            integral[cam.integral_offset] = 0


@wp.kernel
def col_segment_sums_kernel(
    cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    seg: wp.array3d(dtype=wp.int32),
):
    """Integral image, pass 3 of 4: sum of each 32-row segment of every column of the row sums. Launch
    (M, max W + 1, segments); ``seg`` (M, max W + 1, ceil(max H / 32))."""
    c, x, s = wp.tid()
    cam = cams[c]
    if x > cam.width:
        return
    w1 = cam.width + 1
    y0 = 1 + s * SEGMENT
    y1 = wp.min(y0 + SEGMENT, cam.height + 1)
    acc = int(0)
    for y in range(y0, y1):
        acc += integral[cam.integral_offset + y * w1 + x]
    seg[c, x, s] = acc


@wp.kernel
def col_scan_kernel(
    cams: wp.array(dtype=Camera),
    seg: wp.array3d(dtype=wp.int32),
    integral: wp.array(dtype=wp.int32),
):
    """Integral image, pass 4 of 4: column prefix sums in place (earlier segments' sums + a scan of this one)."""
    c, x, s = wp.tid()
    cam = cams[c]
    if x > cam.width:
        return
    w1 = cam.width + 1
    y0 = 1 + s * SEGMENT
    if y0 > cam.height:
        return
    y1 = wp.min(y0 + SEGMENT, cam.height + 1)
    acc = int(0)
    for k in range(s):
        acc += seg[c, x, k]
    for y in range(y0, y1):
        i = cam.integral_offset + y * w1 + x
        acc += integral[i]
        integral[i] = acc


WINDOW_STRIP = wp.constant(8)
"""Output rows per thread of :func:`observe_map_kernel`."""
STRIP_ROWS = wp.constant(12)
"""Rows a lane of :func:`observe_map_kernel` classifies: its strip and two above and below (WINDOW_STRIP + 4; at most
``wp.config.max_unroll`` = 16 so the loops over them unroll)."""
strip_rows = wp.types.vector(length=12, dtype=wp.int32)
"""Per-row values of one lane of :func:`observe_map_kernel` (registers: indexed only in unrolled loops)."""
WARP_COLUMNS = wp.constant(28)
"""Output columns per warp of :func:`observe_map_kernel`: 32 lanes, 2 halo lanes each side."""


@wp.func_native("""
#if defined(__CUDA_ARCH__)
    const int l = threadIdx.x & 31;
    const int a1 = __shfl_up_sync(0xffffffffu, v, 1);
    const int a2 = __shfl_up_sync(0xffffffffu, v, 2);
    const int b1 = __shfl_down_sync(0xffffffffu, v, 1);
    const int b2 = __shfl_down_sync(0xffffffffu, v, 2);
    int s = v;
    if (l >= 1) s += a1;
    if (l >= 2) s += a2;
    if (l <= 30) s += b1;
    if (l <= 29) s += b2;
    return s;
#else
    return v;
#endif
""")
def warp_sum5(v: int) -> int:
    """Sum of ``v`` over lanes l-2 .. l+2 of the calling warp (those that exist). CUDA only: every lane of the warp
    calls it; the CPU branch (no warps) returns ``v``."""
    ...


@wp.func
def strip_pixel(cam: Camera, target: ColourTarget, bgr: wp.array(dtype=wp.uint8), x: int, y: int):
    """The target class of pixel (x, y) of camera ``cam``, 0 outside the image."""
    m = int(0)
    if x >= 0 and x < cam.width and y >= 0 and y < cam.height:
        m = pixel_matches(target, bgr, cam.pixel_offset + y * cam.width + x)
    return m


@wp.kernel
def observe_map_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    mask: wp.array(dtype=wp.uint8),
    window: wp.array(dtype=wp.uint8),
):
    """Target mask and 5x5 window-count map in one pass (the GPU form of the observation; CUDA only, the CPU backend
    builds the map by rows: :func:`mask_rows_kernel`, :func:`window_cols_kernel`). Same values as
    :func:`target_mask_kernel` + :func:`window_from_mask_kernel`.

    A warp covers :data:`WARP_COLUMNS` columns and a strip of :data:`WINDOW_STRIP` rows: each lane classifies its
    column on the strip's rows and two more above and below (lanes 0-1 and 30-31 are the neighbouring columns, the
    halo), the horizontal 5-sums come from the neighbouring lanes by warp shuffles (:func:`warp_sum5`) and are
    summed vertically in registers. No mask is read back: the two launches it replaces (mask, then 25
    mask reads per pixel) took 15 + 37 us for 4 x 640 x 480 on an H100 (BENCHMARKS.md, issue 13, round six).
    Launch (M, ceil(max H / WINDOW_STRIP), 32 ceil(max W / WARP_COLUMNS)) with a block size that is a multiple of
    32; flat like the frames.
    """
    c, strip, t = wp.tid()
    cam = cams[c]
    lane = t % 32
    x = (t / 32) * WARP_COLUMNS + lane - 2
    y0 = strip * WINDOW_STRIP
    if y0 >= cam.height or x - lane + 2 >= cam.width:
        return  # the whole warp (same camera, strip and first column) leaves together
    owner = lane >= 2 and lane < 2 + WARP_COLUMNS and x < cam.width
    # constant trip counts: the loops unroll and the per-row values stay in registers (a row-by-row loop rotating
    # five registers ran the same: 22.4 vs 22.7 us on an H100)
    m = strip_rows()
    for k in range(STRIP_ROWS):
        m[k] = strip_pixel(cam, target, bgr, x, y0 - 2 + k)
    h = strip_rows()
    for k in range(STRIP_ROWS):
        h[k] = warp_sum5(m[k])
    for k in range(WINDOW_STRIP):
        y = y0 + k
        if owner and y < cam.height:
            out = cam.pixel_offset + y * cam.width + x
            mask[out] = wp.uint8(m[k + 2])
            window[out] = wp.uint8(h[k] + h[k + 1] + h[k + 2] + h[k + 3] + h[k + 4])


@wp.kernel
def mask_rows_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    mask: wp.array(dtype=wp.uint8),
    hsum: wp.array(dtype=wp.uint8),
):
    """Target mask and horizontal 5-pixel sums of the mask, one image row per thread (the CPU form of the window
    map: a sliding sum per row, then :func:`window_cols_kernel`). Launch (M, max H); ``hsum`` flat like the mask."""
    c, y = wp.tid()
    cam = cams[c]
    if y >= cam.height:
        return
    row = cam.pixel_offset + y * cam.width
    for x in range(cam.width):
        mask[row + x] = wp.uint8(pixel_matches(target, bgr, row + x))
    acc = int(0)
    for x in range(wp.min(HALF_WINDOW, cam.width)):
        acc += int(mask[row + x])
    for x in range(cam.width):
        if x + HALF_WINDOW < cam.width:
            acc += int(mask[row + x + HALF_WINDOW])
        if x - HALF_WINDOW - 1 >= 0:
            acc -= int(mask[row + x - HALF_WINDOW - 1])
        hsum[row + x] = wp.uint8(acc)


@wp.kernel
def window_cols_kernel(
    cams: wp.array(dtype=Camera),
    hsum: wp.array(dtype=wp.uint8),
    window: wp.array(dtype=wp.uint8),
):
    """The 5x5 window-count map from the horizontal sums: a sliding vertical sum, one image column per thread
    (2 reads per pixel; neighbouring columns share cache lines). Launch (M, max W). Same values as
    :func:`window_from_mask_kernel`."""
    c, x = wp.tid()
    cam = cams[c]
    if x >= cam.width:
        return
    w = cam.width
    col = cam.pixel_offset + x
    acc = int(0)
    for y in range(wp.min(HALF_WINDOW, cam.height)):
        acc += int(hsum[col + y * w])
    for y in range(cam.height):
        if y + HALF_WINDOW < cam.height:
            acc += int(hsum[col + (y + HALF_WINDOW) * w])
        if y - HALF_WINDOW - 1 >= 0:
            acc -= int(hsum[col + (y - HALF_WINDOW - 1) * w])
        window[col + y * w] = wp.uint8(acc)
