"""Colour classification (HSI target of Barrera et al., section II.B) and per-camera integral images.

Frames arrive as one flat ``uint8`` buffer of BGR pixels for all cameras (camera ``c`` starts at pixel
``cams[c].pixel_offset``). A pixel matches the target when its hue is within [H_min, H_max] degrees
(wrapping through 0 when H_min > H_max), its saturation within [S_min, S_max] and its intensity within
[I_min, I_max] (too dark or too bright pixels never match).
"""

import warp as wp

from .camera import Camera

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
def matches(target: ColourTarget, r: float, g: float, b: float):
    """1 if the RGB pixel matches the HSI target, else 0."""
    hsi = rgb_to_hsi(r, g, b)
    h = hsi[0]
    hue_ok = False
    if target.h_min <= target.h_max:
        hue_ok = h >= target.h_min and h <= target.h_max
    else:
        hue_ok = h >= target.h_min or h <= target.h_max
    if (
        hue_ok
        and hsi[1] >= target.s_min
        and hsi[1] <= target.s_max
        and hsi[2] >= target.i_min
        and hsi[2] <= target.i_max
    ):
        return 1
    return 0


@wp.func
def pixel_matches(target: ColourTarget, bgr: wp.array(dtype=wp.uint8), pixel: int):
    """Classify the pixel at flat index ``pixel`` of a BGR buffer."""
    o = 3 * pixel
    return matches(target, float(bgr[o + 2]), float(bgr[o + 1]), float(bgr[o]))


@wp.kernel
def target_mask_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    mask: wp.array(dtype=wp.uint8),
):
    """Target mask of every camera: launch (M, max W*H); ``mask`` is flat like the frames (1 byte/pixel)."""
    c, p = wp.tid()
    cam = cams[c]
    if p >= cam.width * cam.height:
        return
    q = cam.pixel_offset + p
    mask[q] = wp.uint8(pixel_matches(target, bgr, q))


@wp.kernel
def integral_rows_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
):
    """Row prefix sums: launch (M, max H). ``integral`` row y+1 col x+1 = sum of mask[y, 0..x]."""
    c, y = wp.tid()
    cam = cams[c]
    if y >= cam.height:
        return
    w1 = cam.width + 1
    base = cam.integral_offset + (y + 1) * w1
    src = cam.pixel_offset + y * cam.width
    acc = int(0)
    integral[base] = 0
    for x in range(cam.width):
        acc += int(mask[src + x])
        integral[base + x + 1] = acc
    if y == 0:
        for x in range(w1):
            integral[cam.integral_offset + x] = 0


@wp.kernel
def integral_cols_kernel(
    cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
):
    """Column prefix sums over the row sums: launch (M, max W + 1); completes the integral image."""
    c, x = wp.tid()
    cam = cams[c]
    if x > cam.width:
        return
    w1 = cam.width + 1
    acc = int(0)
    for y in range(1, cam.height + 1):
        k = cam.integral_offset + y * w1 + x
        acc += integral[k]
        integral[k] = acc
