"""Offline background model: per-pixel temporal median and MAD over sampled frames, and per-frame foreground.

Frames are flat ``uint8`` buffers of interleaved BGR pixels (``3 * H * W`` bytes, channel ``c`` of pixel ``p`` at
``3 p + c``). A background window holds ``K`` sampled frames as a ``(K, 3 H W)`` ``uint8`` array.

Background statistics (:func:`median_mad_kernel`, one thread per channel value): the lower median
``B = x_(m)``, ``m = (K - 1) // 2`` (0-based order statistic) and the median absolute deviation
``MAD = median_k |x_k - B|`` (same order statistic). Both are found by bitwise selection on the 8-bit values:
the answer is built from the most significant bit down, each of the 8 steps counting the ``K`` values below a
candidate, so the cost is at most ``8 K`` compares per selection (fewer: bits common to the smallest and largest
value are skipped), on a per-thread copy of the ``K`` values, with no histogram (a 256-bin histogram per thread
does not fit GPU registers) and no sort (an insertion sort costs ``K^2 / 4`` compares, more from K ~ 32).

Per frame (:func:`foreground_kernel`, one thread per pixel), with the background ``B`` and the per-channel MADs
linearly interpolated between the two nearest windows (weight ``w`` of the second):

* global illumination: every frame (and every sample of a window) is first divided by its global gain per
  channel, the median over a pixel subsample of its ratio to the background (computed by the driver), so a light
  dimming or a camera's auto-exposure neither hides people in the MAD nor floods the masks,
* noise scale ``s = max(s0, min(1.4826 sqrt(sum_c MAD_c^2 / 3), s_cap))`` (8-bit units; ``1.4826 MAD`` estimates a
  gaussian standard deviation, ``s0`` is the noise floor: the smallest scale allowed, for compressed or clipped
  pixels whose samples barely vary; ``s_cap`` the largest, a multiple of the image-wide median of the per-pixel
  scales computed by the driver, or none when 0: an object standing on a pixel in a large minority of a window's
  samples inflates that pixel's MAD, and without the cap hides itself while it stands); for gaussian noise ``3 z^2``
  is chi-square with 3 degrees of freedom, so ``T = 4`` marks a static pixel as foreground with probability about
  2e-10 (``T = 3``: 6e-6, ``T = 2``: 7e-3),
* robust distance ``z = sqrt(sum_c (I_c - B_c)^2 / 3) / s`` (RMS colour difference in robust standard deviations),
* shadow test (cast shadows keep the background's chromaticity and darken it by a bounded ratio): brightness
  ratio ``a = (I . B) / (B . B)`` (Horprasert et al.'s brightness distortion) and chromaticity distortion
  ``cd = |I - a B| / |B|``; a pixel is shadow when ``lo <= a <= hi`` and ``cd <= chroma_max``, and a penumbra
  candidate when ``hi < a <= edge_hi`` and ``cd <= chroma_max`` (only where
  ``|B| >= 1``, and only when the test is enabled; tested where ``z > T_low``),
* soft foreground probability ``P = 1 / (1 + exp(-(z - T) / k))`` (``T`` the threshold, ``k`` the soft scale, both
  in robust standard deviations); shadow pixels get ``P = 0``; penumbra candidates are left to the driver (kept as
  shadow where 8-connected to a shadow pixel, the brighter rim of a cast shadow; else foreground by their ``z``),
* mask level ``M = 2`` (strong) iff ``z > T`` and not shadow (equivalently ``P > 1/2``), ``M = 1`` (weak) iff
  ``T_low < z <= T`` and not shadow, else 0. The driver keeps the weak pixels 8-connected to a strong one
  (hysteresis, as Canny's edge linking: a low-contrast part of an object, e.g. legs in trousers of the paving's
  colour, is accepted where it hangs on the object's contrasted parts; isolated noise above ``T_low`` is not).

Then, with a neighbourhood radius (:func:`neighbourhood_rows_kernel`, :func:`neighbourhood_kernel`), a background
pixel whose neighbours' mean normalised difference is far from 0 becomes weak foreground too (a faint but coherent
change, e.g. a car painted like the road).

Local illumination changes (issue 26; the driver: :mod:`wptrack.background`): :func:`luma_kernel`,
:func:`patch_rows_kernel` and :func:`patch_kernel` compare every pixel's luminance patch with the background's (NCC,
gradient correlation, texture, the pixel's residual from the patch's linear fit); :func:`tile_gain_kernel` takes
per tile the median brightness ratio of the pixels whose patch keeps the background's texture (selection on
quantised log ratios, :data:`LOG_STEPS`), :func:`tile_smooth_kernel` smooths the tiles by a weighted median, and
:func:`foreground_kernel` divides the frame by that field (:func:`local_gain`, bilinear between tile centres) and
vetoes what :func:`illumination_change` explains; :func:`compensate_kernel` divides a window's samples by their own
fields. :func:`mode_kernel` is the densest-cluster background of short recordings.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

#: Most frames one background window may sample (the selection loops are unbounded, this bounds the cost).
MAX_SAMPLES = wp.constant(64)

#: 1 / Phi^-1(3/4): MAD -> standard deviation of a gaussian.
MAD_TO_SIGMA = wp.constant(1.4826)


#: Per-thread copy of one channel value's K samples (read once from the strided stack, then scanned 16 times).
samples_vec = wp.types.vector(length=MAX_SAMPLES, dtype=wp.int32)


@wp.func
def select_rank(values: samples_vec, count: int, rank: int, lo: int, hi: int):
    """The ``rank``-th smallest (0-based) of ``values[:count]``, all in ``[lo, hi]`` (within 0..255).

    Bitwise selection from the most significant bit down, one counting pass per bit; the bits above the highest
    bit where ``lo`` and ``hi`` differ are common to all values and skipped (noisy backgrounds span a few tens of
    levels: about 5 passes instead of 8).
    """
    spread = lo ^ hi
    bits = int(0)
    while spread > 0:
        spread = spread >> 1
        bits += 1
    answer = lo & ~((1 << bits) - 1)
    for step in range(bits):
        candidate = answer | (1 << (bits - 1 - step))
        below = int(0)  # values < candidate
        for k in range(count):
            if values[k] < candidate:
                below += 1
        if below <= rank:  # the rank-th value is >= candidate: set the bit
            answer = candidate
    return answer


@wp.func
def unlit(x: float, g: float):
    """An 8-bit value divided by a global gain (illumination compensation), rounded and clamped to 0..255."""
    return wp.clamp(int(wp.floor(x / g + 0.5)), 0, 255)


@wp.kernel
def median_mad_kernel(
    stack: wp.array2d(dtype=wp.uint8),
    gains: wp.array(dtype=wp.vec3),
    median: wp.array(dtype=wp.uint8),
    mad: wp.array(dtype=wp.uint8),
):
    """Per channel value ``j``: lower median of ``stack[:, j] / gains[:, j % 3]`` and its MAD (lower median of
    absolute deviations).

    Args:
        stack: ``(K, 3 H W)`` sampled frames, ``1 <= K <= MAX_SAMPLES``.
        gains: ``(K,)`` global gain of each sample per channel (B, G, R) relative to the window (1: none): the
            samples are compensated for global illumination changes before the statistics.
        median: ``(3 H W,)`` output background.
        mad: ``(3 H W,)`` output median absolute deviation (8-bit units).
    """
    j = wp.tid()
    c = j % 3
    count = wp.min(stack.shape[0], MAX_SAMPLES)
    rank = (count - 1) // 2
    values = samples_vec()
    lo = int(255)
    hi = int(0)
    for k in range(count):
        v = unlit(float(stack[k, j]), gains[k][c])
        values[k] = v
        lo = wp.min(lo, v)
        hi = wp.max(hi, v)
    b = select_rank(values, count, rank, lo, hi)
    hi = wp.max(hi - b, b - lo)  # the deviations lie in [0, max deviation]
    for k in range(count):
        values[k] = wp.abs(values[k] - b)
    median[j] = wp.uint8(b)
    mad[j] = wp.uint8(select_rank(values, count, rank, 0, hi))


#: Per-pixel patch statistics of :func:`patch_kernel`: NCC of the luminance patches (frame vs background),
#: correlation of their gradients, the background's and the frame's patch standard deviations (luminance noise
#: scales), the
#: centre pixel's residual from the patch's linear fit (luminance noise scales), and the fit's distance from a gain.
patch_vec = wp.types.vector(length=6, dtype=wp.float32)

#: Row sums of :func:`patch_rows_kernel`: f, b, f^2, b^2, f b, grad f . grad b, |grad f|^2, |grad b|^2, count.
rows_vec = wp.types.vector(length=9, dtype=wp.float32)

#: Quantisation of a log brightness ratio to 0..255: ``q = 128 + round(LOG_STEPS ln(ratio))`` (ratios 1/4 .. 4,
#: steps of 1.09 %), so a tile's median ratio is a selection on 8-bit values (:func:`select_rank`).
LOG_STEPS = wp.constant(92.33248261689366)

#: Background values below this (8-bit) are left out of the local gains (dark pixels carry no ratio).
MIN_LEVEL = wp.constant(16.0)


@wp.struct
class ForegroundParams:
    """Per-frame test parameters (units: robust standard deviations unless stated)."""

    threshold: float  # T: foreground when z > T
    low_threshold: float  # T_low <= T: weak foreground when T_low < z <= T (hysteresis)
    spread_cap: float  # s_cap, 8-bit units: largest noise scale (0: no cap)
    soft_scale: float  # k of the logistic P = 1 / (1 + exp(-(z - T) / k))
    noise_floor: float  # s0, 8-bit units
    shadow: int  # 1: shadow test on
    shadow_lo: float  # brightness ratio bounds (dimensionless)
    shadow_hi: float
    shadow_edge_hi: float  # penumbra candidates: shadow_hi < a <= shadow_edge_hi (= shadow_hi: none)
    chroma_max: float  # chromaticity distortion bound (dimensionless, |I - a B| / |B|)
    tile: int  # local illumination field: tile size, pixels (0: no field, the global gain only)
    tiles_x: int  # tiles per image row
    tiles_y: int  # tiles per image column
    width: int  # image width, pixels
    verify_ncc: float  # local field: smallest patch NCC of a pixel that votes for its tile's gain
    veto_ncc: float  # illumination veto: smallest patch NCC (0: no NCC veto)
    veto_grad: float  # illumination veto: smallest patch gradient correlation (0: no gradient veto)
    veto_texture: float  # smallest background patch standard deviation, noise scales
    veto_resid: float  # largest centre residual of the patch's linear fit, luminance noise scales
    gain_gap: float  # largest |ln(slope / ratio of the means)| of a patch's fit (a pure gain: 0)
    illum_chroma: float  # largest chromaticity distortion of a local illumination change
    illum_lo: float  # brightness ratio range of a local illumination change
    illum_hi: float


@wp.func
def local_gain(local: wp.array(dtype=wp.vec3), params: ForegroundParams, p: int):
    """The local illumination field at pixel ``p``: the exponential of the tiles' log gains interpolated bilinearly
    between the tile centres (clamped at the image border)."""
    px = p % params.width
    py = p // params.width
    u = (float(px) + 0.5) / float(params.tile) - 0.5
    v = (float(py) + 0.5) / float(params.tile) - 0.5
    i0 = wp.clamp(int(wp.floor(u)), 0, params.tiles_x - 1)
    j0 = wp.clamp(int(wp.floor(v)), 0, params.tiles_y - 1)
    i1 = wp.min(i0 + 1, params.tiles_x - 1)
    j1 = wp.min(j0 + 1, params.tiles_y - 1)
    fu = wp.clamp(u - float(i0), 0.0, 1.0)
    fv = wp.clamp(v - float(j0), 0.0, 1.0)
    top = (1.0 - fu) * local[j0 * params.tiles_x + i0] + fu * local[j0 * params.tiles_x + i1]
    bottom = (1.0 - fu) * local[j1 * params.tiles_x + i0] + fu * local[j1 * params.tiles_x + i1]
    g = (1.0 - fv) * top + fv * bottom
    return wp.vec3(wp.exp(g[0]), wp.exp(g[1]), wp.exp(g[2]))


@wp.func
def illumination_change(st: patch_vec, params: ForegroundParams, ib: float, bb: float, ii: float):
    """Whether a pixel's change is a local illumination change: its background patch is textured
    (``st[2] >= veto_texture``) and the frame's patch keeps texture (``st[3] >= veto_texture / 2``), the patches
    correlate (NCC ``st[0] >= veto_ncc`` or gradient correlation ``st[1] >= veto_grad``, each where > 0), the
    centre pixel follows the patch's linear fit (``st[4] <= veto_resid``), which is a gain (``st[5] <= gain_gap``),
    and its colour is the background's
    scaled (brightness ratio ``a = I.B / B.B`` in ``[illum_lo, illum_hi]``, chromaticity distortion
    ``<= illum_chroma``)."""
    if st[2] < params.veto_texture or st[3] < 0.5 * params.veto_texture or st[4] > params.veto_resid:
        return False
    if st[5] > params.gain_gap:
        return False
    ncc_ok = params.veto_ncc > 0.0 and st[0] >= params.veto_ncc
    corr = ncc_ok or (params.veto_grad > 0.0 and st[1] >= params.veto_grad)
    if not corr or bb < 1.0:
        return False
    a = ib / bb
    cd = wp.sqrt(wp.max(ii - a * ib, 0.0) / bb)
    return a >= params.illum_lo and a <= params.illum_hi and cd <= params.illum_chroma


@wp.kernel
def foreground_kernel(
    frame: wp.array(dtype=wp.uint8),
    bg0: wp.array(dtype=wp.uint8),
    mad0: wp.array(dtype=wp.uint8),
    bg1: wp.array(dtype=wp.uint8),
    mad1: wp.array(dtype=wp.uint8),
    w: float,
    gain: wp.vec3,
    params: ForegroundParams,
    local: wp.array(dtype=wp.vec3),
    patch: wp.array(dtype=patch_vec),
    mask: wp.array(dtype=wp.uint8),
    prob: wp.array(dtype=wp.float32),
    shadow: wp.array(dtype=wp.uint8),
    diff: wp.array(dtype=wp.vec3),
):
    """Foreground mask, probability and shadow flag of one frame (see the module docstring for the formulas).

    Args:
        frame: ``(3 H W,)`` BGR frame.
        bg0, mad0: ``(3 H W,)`` background and MAD of the earlier window; ``bg1``, ``mad1`` of the later one.
        w: Interpolation weight of the later window in ``[0, 1]``.
        gain: The frame's global gain per channel (B, G, R) relative to the background (illumination change):
            the frame is divided by it before the tests (1: none).
        params: Thresholds.
        local: ``(tiles_y tiles_x,)`` the local illumination field: per tile, the log gain per channel (B, G, R)
            of the frame over the background beyond the global gain (:func:`tile_smooth_kernel`), interpolated
            bilinearly between the tile centres; the frame is divided by its exponential too. Read only when
            ``params.tile > 0``.
        patch: ``(H W,)`` :func:`patch_kernel`'s patch statistics, for the illumination veto; read only when
            ``params.veto_ncc > 0`` or ``params.veto_grad > 0``.
        mask: ``(H W,)`` output ``level + 4 shadow``: level 2 = foreground, 1 = weak foreground
            (``T_low < z <= T``), 0 = background (and every cast shadow or illumination change); ``shadow`` as
            below (one array for the driver to copy).
        prob: ``(H W,)`` output foreground probability in ``[0, 1]``.
        diff: ``(H W,)`` output normalised difference ``(I - B) / s`` per channel (B, G, R; robust standard
            deviations), for :func:`neighbourhood_kernel`.
        shadow: ``(H W,)`` output, 2 = cast shadow (counted as background), 1 = penumbra candidate (its ``mask``
            and ``prob`` as if not a shadow), 3 = local illumination change (the veto; counted as background), 0 =
            none of them.
    """
    p = wp.tid()
    lit = gain
    if params.tile > 0:
        lit = wp.cw_mul(gain, local_gain(local, params, p))
    d = wp.vec3(0.0, 0.0, 0.0)
    dd = float(0.0)
    mm = float(0.0)
    ib = float(0.0)
    bb = float(0.0)
    ii = float(0.0)
    for c in range(3):
        j = 3 * p + c
        b = float(bg0[j])
        m = float(mad0[j])
        if w > 0.0:  # between two windows (w = 0: one window, half the reads)
            b = (1.0 - w) * b + w * float(bg1[j])
            m = (1.0 - w) * m + w * float(mad1[j])
        x = float(frame[j]) / lit[c]
        d[c] = x - b
        dd += (x - b) * (x - b)
        mm += m * m
        ib += x * b
        bb += b * b
        ii += x * x
    spread = MAD_TO_SIGMA * wp.sqrt(mm / 3.0)
    if params.spread_cap > 0.0:
        spread = wp.min(spread, params.spread_cap)
    s = wp.max(params.noise_floor, spread)
    z = wp.sqrt(dd / 3.0) / s
    is_shadow = int(0)
    if params.shadow != 0 and bb >= 1.0 and z > params.low_threshold:
        a = ib / bb
        # |I - a B|^2 = I.I - 2 a I.B + a^2 B.B = I.I - a I.B  (a = I.B / B.B)
        cd = wp.sqrt(wp.max(ii - a * ib, 0.0) / bb)
        if a >= params.shadow_lo and cd <= params.chroma_max:
            if a <= params.shadow_hi:
                is_shadow = 2
            elif a <= params.shadow_edge_hi:
                is_shadow = 1
    if is_shadow < 2 and (params.veto_ncc > 0.0 or params.veto_grad > 0.0) and z > params.low_threshold:
        if illumination_change(patch[p], params, ib, bb, ii):
            is_shadow = 3
    fg = int(0)
    pr = float(0.0)
    if is_shadow < 2:
        pr = 1.0 / (1.0 + wp.exp(-(z - params.threshold) / params.soft_scale))
        if z > params.threshold:
            fg = 2
        elif z > params.low_threshold:
            fg = 1
    mask[p] = wp.uint8(fg + 4 * is_shadow)
    prob[p] = pr
    shadow[p] = wp.uint8(is_shadow)
    diff[p] = d / s


#: Pixels one thread of the neighbourhood kernels slides its box sum over (a run of a row or a column).
RUN = wp.constant(32)


@wp.func
def usable_diff(packed: wp.array(dtype=wp.uint8), diff: wp.array(dtype=wp.vec3), q: int):
    """``(d, 1)`` for a pixel that enters a neighbourhood mean (neither strong foreground, cast shadow nor penumbra
    candidate), else 0."""
    u = int(packed[q])
    out = wp.vec4(0.0, 0.0, 0.0, 0.0)
    if (u & 3) < 2 and (u >> 2) == 0:
        d = diff[q]
        out = wp.vec4(d[0], d[1], d[2], 1.0)
    return out


@wp.kernel
def neighbourhood_rows_kernel(
    packed: wp.array(dtype=wp.uint8),
    diff: wp.array(dtype=wp.vec3),
    width: int,
    height: int,
    radius: int,
    rows: wp.array(dtype=wp.vec4),
):
    """First (horizontal) pass of :func:`neighbourhood_kernel`: per pixel, the sum of the normalised differences
    (x, y, z) and the count (w) of the usable pixels (:func:`usable_diff`) among its row neighbours
    ``x - radius .. x + radius``. One thread per row and run of :data:`RUN` pixels, sliding the sum along the run
    (launch with ``dim = height * ceil(width / RUN)``).

    Args:
        packed: ``(H W,)`` :func:`foreground_kernel`'s ``mask``. diff: ``(H W,)`` its normalised differences.
        width, height: Image size, pixels. radius: Neighbourhood radius, pixels.
        rows: ``(H W,)`` output partial sums.
    """
    t = wp.tid()
    y = t % height
    x0 = (t // height) * RUN
    x1 = wp.min(x0 + RUN, width)
    base = y * width
    acc = wp.vec4(0.0, 0.0, 0.0, 0.0)
    for xx in range(wp.max(x0 - radius, 0), wp.min(x0 + radius + 1, width)):
        acc += usable_diff(packed, diff, base + xx)
    for x in range(x0, x1):
        rows[base + x] = acc
        if x + radius + 1 < width:
            acc += usable_diff(packed, diff, base + x + radius + 1)
        if x - radius >= 0:
            acc -= usable_diff(packed, diff, base + x - radius)


@wp.kernel
def neighbourhood_kernel(
    packed: wp.array(dtype=wp.uint8),
    rows: wp.array(dtype=wp.vec4),
    width: int,
    height: int,
    radius: int,
    low_threshold: float,
    scale: float,
    out: wp.array(dtype=wp.uint8),
):
    """Weak foreground from the mean difference of a neighbourhood (a faint but coherent change).

    A background pixel (level 0, not a cast shadow) becomes weak foreground (level 1) when the mean normalised
    difference over its ``(2 radius + 1)^2`` neighbours that are neither strong foreground nor cast shadow nor
    penumbra candidate (edges of contrasted objects and shadows would leak in) is far from 0:
    ``z_n = c sqrt(n) sqrt(sum_c m_c^2 / 3) > T_low``, with ``m_c`` the mean of channel ``c`` over the ``n``
    neighbours counted and ``c`` the ``scale`` (under independent
    gaussian noise ``m_c`` has standard deviation ``1 / sqrt(n)``, so with ``scale`` 1 ``z_n`` has the distribution
    of ``z``; a region darker by 1.5 robust standard deviations gives ``z_n`` about 4.5 over 3 x 3 pixels;
    ``scale < 1`` for spatially correlated noise, measured by the driver). Other pixels are copied.

    Args:
        packed: ``(H W,)`` :func:`foreground_kernel`'s ``mask`` (``level + 4 shadow``).
        rows: ``(H W,)`` :func:`neighbourhood_rows_kernel`'s row sums (separable box sum: 2 (2 radius + 1) reads
            per pixel instead of (2 radius + 1)^2).

    One thread per column and run of :data:`RUN` rows, sliding the column sum down the run (launch with
    ``dim = width * ceil(height / RUN)``; few threads, so the per-thread overhead of a CPU launch stays small).
        width, height: Image size, pixels.
        radius: Neighbourhood radius, pixels (>= 1).
        low_threshold: ``T_low``.
        scale: Noise correction ``c`` (1: independent pixels).
        out: ``(H W,)`` output, packed like ``packed``.
    """
    t = wp.tid()
    x = t % width
    y0 = (t // width) * RUN
    y1 = wp.min(y0 + RUN, height)
    acc = wp.vec4(0.0, 0.0, 0.0, 0.0)
    for yy in range(wp.max(y0 - radius, 0), wp.min(y0 + radius + 1, height)):
        acc += rows[yy * width + x]
    for y in range(y0, y1):
        p = y * width + x
        v = int(packed[p])
        n = acc[3]
        if (v & 3) == 0 and (v >> 2) < 2 and n > 0.5:
            if scale * scale * (acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]) / (3.0 * n) > (
                low_threshold * low_threshold
            ):
                v = v + 1
        out[p] = wp.uint8(v)
        if y + radius + 1 < height:
            acc += rows[(y + radius + 1) * width + x]
        if y - radius >= 0:
            acc -= rows[(y - radius) * width + x]


# ------------------------------------------------------------------------------------- local illumination changes


@wp.kernel
def luma_kernel(
    frame: wp.array(dtype=wp.uint8),
    gain: wp.vec3,
    bg0: wp.array(dtype=wp.uint8),
    mad0: wp.array(dtype=wp.uint8),
    bg1: wp.array(dtype=wp.uint8),
    mad1: wp.array(dtype=wp.uint8),
    w: float,
    params: ForegroundParams,
    luma: wp.array(dtype=wp.vec3),
):
    """Per pixel: the frame's luminance after the global gain ``f = mean_c I_c / g_c``, the background's
    ``b = mean_c B_c`` (interpolated between the windows as in :func:`foreground_kernel`) and the noise scale ``s``
    of :func:`foreground_kernel` (8-bit units), for :func:`patch_rows_kernel` and :func:`tile_gain_kernel`.

    Args:
        frame: ``(3 H W,)`` BGR frame. gain: its global gain per channel.
        bg0, mad0, bg1, mad1, w: The windows' backgrounds and MADs and the weight of the later one.
        params: ``spread_cap`` and ``noise_floor``.
        luma: ``(H W,)`` output ``(f, b, s)``.
    """
    p = wp.tid()
    f = float(0.0)
    bs = float(0.0)
    mm = float(0.0)
    for c in range(3):
        j = 3 * p + c
        b = float(bg0[j])
        m = float(mad0[j])
        if w > 0.0:
            b = (1.0 - w) * b + w * float(bg1[j])
            m = (1.0 - w) * m + w * float(mad1[j])
        f += float(frame[j]) / gain[c]
        bs += b
        mm += m * m
    spread = MAD_TO_SIGMA * wp.sqrt(mm / 3.0)
    if params.spread_cap > 0.0:
        spread = wp.min(spread, params.spread_cap)
    luma[p] = wp.vec3(f / 3.0, bs / 3.0, wp.max(params.noise_floor, spread))


@wp.func
def luma_grad(luma: wp.array(dtype=wp.vec3), x: int, y: int, width: int, height: int):
    """Central-difference gradients of the frame's and the background's luminance at ``(x, y)`` (one-sided at the
    border): ``(df/dx, df/dy, db/dx, db/dy)``, 8-bit units per pixel."""
    xl = wp.max(x - 1, 0)
    xr = wp.min(x + 1, width - 1)
    yu = wp.max(y - 1, 0)
    yd = wp.min(y + 1, height - 1)
    left = luma[y * width + xl]
    right = luma[y * width + xr]
    up = luma[yu * width + x]
    down = luma[yd * width + x]
    sx = 1.0 / float(wp.max(xr - xl, 1))
    sy = 1.0 / float(wp.max(yd - yu, 1))
    return wp.vec4((right[0] - left[0]) * sx, (down[0] - up[0]) * sy, (right[1] - left[1]) * sx, (down[1] - up[1]) * sy)


@wp.kernel
def patch_rows_kernel(
    luma: wp.array(dtype=wp.vec3),
    width: int,
    height: int,
    radius: int,
    rows: wp.array(dtype=rows_vec),
):
    """First (horizontal) pass of :func:`patch_kernel`: per pixel, the sums over its row neighbours
    ``x - radius .. x + radius`` inside the image of ``f, b, f^2, b^2, f b`` (of ``f - 128`` and ``b - 128``),
    ``grad f . grad b``, ``|grad f|^2``, ``|grad b|^2`` (:func:`luma_grad`) and their count. One thread per pixel
    (each sum read afresh: no sliding sums, no float32 cancellation).

    Args:
        luma: ``(H W,)`` :func:`luma_kernel`'s output. width, height: Image size, pixels. radius: Patch radius.
        rows: ``(H W,)`` output row sums.
    """
    p = wp.tid()
    y = p // width
    x = p % width
    acc = rows_vec()
    for xx in range(wp.max(x - radius, 0), wp.min(x + radius + 1, width)):
        v = luma[y * width + xx]
        g = luma_grad(luma, xx, y, width, height)
        f = v[0] - 128.0  # centred: smaller float32 sums of squares (variances are differences of them)
        b = v[1] - 128.0
        acc[0] += f
        acc[1] += b
        acc[2] += f * f
        acc[3] += b * b
        acc[4] += f * b
        acc[5] += g[0] * g[2] + g[1] * g[3]
        acc[6] += g[0] * g[0] + g[1] * g[1]
        acc[7] += g[2] * g[2] + g[3] * g[3]
        acc[8] += 1.0
    rows[p] = acc


@wp.kernel
def patch_kernel(
    rows: wp.array(dtype=rows_vec),
    luma: wp.array(dtype=wp.vec3),
    width: int,
    height: int,
    radius: int,
    patch: wp.array(dtype=patch_vec),
):
    """Per pixel, how its ``(2 radius + 1)^2`` patch (the part inside the image) of the frame's luminance ``f``
    relates to the background's ``b`` (an illumination change keeps the texture: ``f`` is about ``alpha b + beta``
    over the patch; an object that entered is not):

    * ``ncc = cov(f, b) / sqrt(var f var b)``, the normalised cross-correlation (invariant to gain and offset),
    * ``gc = sum grad f . grad b / sqrt(sum |grad f|^2 sum |grad b|^2)``, the gradient correlation (orientation
      agreement weighted by magnitude),
    * ``tex_b = sqrt(3 var b) / s``, ``tex_f = sqrt(3 var f) / s``: the patches' standard deviations in units of
      the centre pixel's luminance noise ``s / sqrt(3)`` (a flat patch says nothing about texture),
    * ``resid = sqrt(3) |f - alpha b - beta| / s`` at the centre, ``alpha = cov / var b``,
      ``beta = mean f - alpha mean b``: how far the pixel itself is from the patch's fit (luminance noise scales:
      ``s / sqrt(3)`` for independent channels), so a thin object on a textured patch is not explained away,
    * ``gap = |ln(alpha (mean b) / (mean f))|``: how far the fit is from a pure gain (light multiplies radiance:
      under a cloud or a lamp ``f = k b`` over the patch, so the slope equals the ratio of the means; an object's
      edge that happens to lie along a background edge correlates too, with a slope unrelated to that ratio), at
      most 9, and 9 where the slope or a mean is not positive.

    Variances are population variances over the patch; ``ncc``, ``gc`` are 0 where a variance is 0.

    Args:
        rows: ``(H W,)`` :func:`patch_rows_kernel`'s sums. luma: ``(H W,)`` :func:`luma_kernel`'s output.
        width, height: Image size, pixels. radius: Patch radius, pixels.
        patch: ``(H W,)`` output ``(ncc, gc, tex_b, tex_f, resid, gap)``.
    """
    p = wp.tid()
    y = p // width
    x = p % width
    acc = rows_vec()
    for yy in range(wp.max(y - radius, 0), wp.min(y + radius + 1, height)):
        acc += rows[yy * width + x]
    n = acc[8]
    mf = acc[0] / n
    mb = acc[1] / n
    vf = wp.max(acc[2] / n - mf * mf, 0.0)
    vb = wp.max(acc[3] / n - mb * mb, 0.0)
    cov = acc[4] / n - mf * mb
    ncc = float(0.0)
    if vf * vb > 0.0:
        ncc = cov / wp.sqrt(vf * vb)
    gc = float(0.0)
    if acc[6] * acc[7] > 0.0:
        gc = acc[5] / wp.sqrt(acc[6] * acc[7])
    alpha = float(0.0)
    if vb > 0.0:
        alpha = cov / vb
    beta = mf - alpha * mb
    c = luma[p]
    s = c[2]
    resid = wp.sqrt(3.0) * wp.abs((c[0] - 128.0) - alpha * (c[1] - 128.0) - beta) / s
    out = patch_vec()
    out[0] = ncc
    out[1] = gc
    out[2] = wp.sqrt(3.0 * vb) / s
    out[3] = wp.sqrt(3.0 * vf) / s
    out[4] = resid
    gap = float(9.0)
    if alpha > 0.0 and mf + 128.0 > 0.0 and mb + 128.0 > 0.0:
        gap = wp.min(wp.abs(wp.log(alpha * (mb + 128.0) / (mf + 128.0))), 9.0)
    out[5] = gap
    patch[p] = out


@wp.func
def log_code(x: float, b: float):
    """A brightness ratio ``x / b`` quantised to 0..255 (:data:`LOG_STEPS`, 128 = ratio 1)."""
    return wp.clamp(int(wp.floor(LOG_STEPS * wp.log(x / b) + 128.5)), 0, 255)


@wp.kernel
def tile_gain_kernel(
    frame: wp.array(dtype=wp.uint8),
    gain: wp.vec3,
    bg0: wp.array(dtype=wp.uint8),
    bg1: wp.array(dtype=wp.uint8),
    w: float,
    patch: wp.array(dtype=patch_vec),
    params: ForegroundParams,
    height: int,
    shadows: int,
    tiles: wp.array(dtype=wp.vec4),
):
    """Per tile of ``tile x tile`` pixels: the frame's local gain per channel over the background, from the pixels
    whose patch says "same texture, other light" (the votes): background level >= :data:`MIN_LEVEL` and frame
    values in 1..254 in every channel, textured patches (``tex_b >= veto_texture``, ``tex_f >= veto_texture / 2``)
    that correlate (``ncc >= verify_ncc``) with a fit that is a gain (``gap <= gain_gap``) the pixel follows
    (``resid <= veto_resid``), and a colour that is the background's scaled (chromaticity distortion
    ``<= illum_chroma``). Objects that entered, and flat patches that cannot tell, do not vote;
    with ``shadows`` (and ``params.shadow``) neither do cast shadows (brightness ratio ``a`` in
    ``[shadow_lo, shadow_hi]``, chromaticity distortion ``<= chroma_max``, as :func:`foreground_kernel` tests them):
    the shadow test explains them, and a tile half in a person's shadow would otherwise move the field and push the
    shadow out of its band. A regular subsample of at most 8 x 8 pixels of the tile (every ``ceil(tile / 8)``-th
    pixel in x and y) is used.

    The gain of channel ``c`` is the lower median of the votes' quantised log ratios ``I_c / (g_c B_c)``
    (:func:`log_code`), as a log gain ``(q - 128) / LOG_STEPS``; the tile's weight is the fraction of its subsample
    that voted (0 with fewer than 4 votes).

    Args:
        frame: ``(3 H W,)`` BGR frame. gain: its global gain.
        bg0, bg1, w: The windows' backgrounds and the weight of the later one.
        patch: ``(H W,)`` :func:`patch_kernel`'s output.
        params: ``tile``, ``tiles_x``, ``tiles_y``, ``width``, ``veto_texture``, ``verify_ncc``, ``veto_resid``,
            ``gain_gap``, ``illum_chroma`` (and the shadow test's fields).
        height: Image height, pixels.
        shadows: 1: cast shadows do not vote (a frame); 0: they do (a window's sample, before any ratio is learnt).
        tiles: ``(tiles_y tiles_x,)`` output ``(log gain B, G, R, weight)``.
    """
    t = wp.tid()
    tx = t % params.tiles_x
    ty = t // params.tiles_x
    step = wp.max(1, (params.tile + 7) // 8)
    qb = samples_vec()
    qg = samples_vec()
    qr = samples_vec()
    count = int(0)
    seen = int(0)
    lo = wp.vec3i(255, 255, 255)
    hi = wp.vec3i(0, 0, 0)
    for yy in range(ty * params.tile, wp.min((ty + 1) * params.tile, height), step):
        for xx in range(tx * params.tile, wp.min((tx + 1) * params.tile, params.width), step):
            p = yy * params.width + xx
            seen += 1
            st = patch[p]
            if st[2] < params.veto_texture or st[3] < 0.5 * params.veto_texture or st[0] < params.verify_ncc:
                continue
            if st[4] > params.veto_resid or st[5] > params.gain_gap:
                continue
            ok = int(1)
            q = wp.vec3i(0, 0, 0)
            ib = float(0.0)
            bb = float(0.0)
            ii = float(0.0)
            for c in range(3):
                j = 3 * p + c
                b = float(bg0[j])
                if w > 0.0:
                    b = (1.0 - w) * b + w * float(bg1[j])
                f = float(frame[j])
                x = f / gain[c]
                ib += x * b
                bb += b * b
                ii += x * x
                if b < MIN_LEVEL or f < 1.0 or f > 254.0:
                    ok = 0
                else:
                    q[c] = log_code(x, b)
            if ok == 1:
                a = ib / bb
                cd = wp.sqrt(wp.max(ii - a * ib, 0.0) / bb)
                if cd > params.illum_chroma:  # light keeps the hue: a colour change is no vote
                    ok = 0
                elif shadows != 0 and params.shadow != 0:
                    if a >= params.shadow_lo and a <= params.shadow_hi and cd <= params.chroma_max:
                        ok = 0
            if ok == 1 and count < MAX_SAMPLES:
                qb[count] = q[0]
                qg[count] = q[1]
                qr[count] = q[2]
                for c in range(3):
                    lo[c] = wp.min(lo[c], q[c])
                    hi[c] = wp.max(hi[c], q[c])
                count += 1
    out = wp.vec4(0.0, 0.0, 0.0, 0.0)
    if count >= 4:
        rank = (count - 1) // 2
        out[0] = (float(select_rank(qb, count, rank, lo[0], hi[0])) - 128.0) / LOG_STEPS
        out[1] = (float(select_rank(qg, count, rank, lo[1], hi[1])) - 128.0) / LOG_STEPS
        out[2] = (float(select_rank(qr, count, rank, lo[2], hi[2])) - 128.0) / LOG_STEPS
        out[3] = float(count) / float(wp.max(seen, 1))
    tiles[t] = out


#: Most tiles of a :func:`tile_smooth_kernel` neighbourhood (radius <= 4).
MAX_NEIGHBOURS = wp.constant(81)

neighbours_vec = wp.types.vector(length=MAX_NEIGHBOURS, dtype=wp.float32)

#: Smallest weight (fraction of its subsample that voted) of a tile that may keep its own gains in
#: :func:`tile_smooth_kernel` (a median of fewer votes is too noisy to stand against its neighbours').
KEEP_WEIGHT = wp.constant(0.25)


@wp.func
def weighted_median(values: neighbours_vec, weights: neighbours_vec, count: int, total: float):
    """The smallest of ``values[:count]`` whose weight with that of the values below it reaches half the total
    (a lower weighted median; ties broken by the value)."""
    best = float(0.0)
    found = int(0)
    for i in range(count):
        if weights[i] > 0.0:
            below = float(0.0)
            for j in range(count):
                if values[j] <= values[i]:
                    below += weights[j]
            if below >= 0.5 * total and (found == 0 or values[i] < best):
                best = values[i]
                found = 1
    return best


@wp.kernel
def tile_smooth_kernel(
    tiles: wp.array(dtype=wp.vec4),
    tiles_x: int,
    tiles_y: int,
    radius: int,
    widen: int,
    min_weight: float,
    keep: float,
    dead: float,
    local: wp.array(dtype=wp.vec3),
):
    """The local illumination field per tile: per channel, the weighted median of the log gains of the tiles within
    ``radius`` tiles (a ``(2 radius + 1)^2`` square, inside the grid), weighted by their weights. Where their total
    weight is below ``min_weight`` (flat ground, e.g. asphalt, has no votes) the square is widened, up to ``widen``
    times, to radius ``2 r + 1`` (every ``ceil((2 r + 1) / 9)``-th tile in each direction, at most 81 tiles); still
    below it, 0 (no local change). The median keeps a change's edge and ignores a minority of wrong tiles. A tile of
    weight >= :data:`KEEP_WEIGHT` keeps its own gains where their mean differs from the median's by at most ``keep``
    (log units; 0: never): its votes are verified light changes, and the median flattens the peak of a pool of
    light and the inside of a static shadow that a cloud leaves as it is.

    Args:
        tiles: ``(tiles_y tiles_x,)`` :func:`tile_gain_kernel`'s output. tiles_x, tiles_y: Grid size.
        radius: Neighbourhood radius in tiles (0 to 4). widen: Widenings allowed (0: none).
        min_weight: Smallest total weight.
        keep: Largest difference (mean over channels, log gain) for a tile to keep its own gains.
        dead: A field whose log gains are all within ``dead`` of 0 is 0 (no local change: the few percent a tile's
            median of votes is off by do not move the tests where the light did not change).
        local: ``(tiles_y tiles_x,)`` output log gains (B, G, R).
    """
    t = wp.tid()
    tx = t % tiles_x
    ty = t // tiles_x
    wts = neighbours_vec()
    vb = neighbours_vec()
    vg = neighbours_vec()
    vr = neighbours_vec()
    count = int(0)
    total = float(0.0)
    r = radius
    for _k in range(widen + 1):
        step = wp.max(1, (2 * r + 9) // 9)
        count = int(0)
        total = float(0.0)
        for dy in range(-(r // step), r // step + 1):
            yy = ty + dy * step
            if yy >= 0 and yy < tiles_y:
                for dx in range(-(r // step), r // step + 1):
                    xx = tx + dx * step
                    if xx >= 0 and xx < tiles_x and count < MAX_NEIGHBOURS:
                        v = tiles[yy * tiles_x + xx]
                        vb[count] = v[0]
                        vg[count] = v[1]
                        vr[count] = v[2]
                        wts[count] = v[3]
                        total += v[3]
                        count += 1
        if total >= min_weight:
            break
        r = 2 * r + 1
    out = wp.vec3(0.0, 0.0, 0.0)
    if total >= min_weight and total > 0.0:
        out = wp.vec3(
            weighted_median(vb, wts, count, total),
            weighted_median(vg, wts, count, total),
            weighted_median(vr, wts, count, total),
        )
        own = tiles[t]
        moved = wp.abs((own[0] + own[1] + own[2]) - (out[0] + out[1] + out[2]))
        if keep > 0.0 and own[3] >= KEEP_WEIGHT and moved <= 3.0 * keep:
            out = wp.vec3(own[0], own[1], own[2])
        if wp.max(wp.abs(out[0]), wp.max(wp.abs(out[1]), wp.abs(out[2]))) <= dead:
            out = wp.vec3(0.0, 0.0, 0.0)
    local[t] = out


@wp.kernel
def compensate_kernel(
    stack: wp.array2d(dtype=wp.uint8),
    k: int,
    gain: wp.vec3,
    local: wp.array(dtype=wp.vec3),
    params: ForegroundParams,
):
    """Divide sample ``k`` of a window's stack, in place, by its global gain and its local illumination field
    (:func:`local_gain`), rounded and clamped (:func:`unlit`): the samples then differ from each other only by
    what moved (the window's statistics follow with unit gains).

    Args:
        stack: ``(K, 3 H W)`` the window's samples (changed in place, row ``k`` only).
        k: The sample. gain: Its global gain per channel.
        local: ``(tiles_y tiles_x,)`` its field (:func:`tile_smooth_kernel`). params: The tile geometry.
    """
    p = wp.tid()
    g = wp.cw_mul(gain, local_gain(local, params, p))
    for c in range(3):
        j = 3 * p + c
        stack[k, j] = wp.uint8(unlit(float(stack[k, j]), g[c]))


@wp.kernel
def mode_kernel(
    stack: wp.array2d(dtype=wp.uint8),
    gains: wp.array(dtype=wp.vec3),
    band: float,
    median: wp.array(dtype=wp.uint8),
    mad: wp.array(dtype=wp.uint8),
):
    """Per pixel: the background as the densest cluster of its samples instead of their median (short recordings
    with objects in most frames: a pixel that objects cover in more than half of the samples keeps its background
    when the objects differ from sample to sample while the background does not).

    The samples are compensated by their gains as in :func:`median_mad_kernel`. The centre is the first sample with
    the most samples within ``band`` of it in every channel (Chebyshev distance, 8-bit units); the background is
    the per-channel lower median of those samples, and the MAD the lower median of all samples' absolute deviations
    from it (as :func:`median_mad_kernel`'s, so a pixel whose samples spread keeps its spread).

    Args:
        stack: ``(K, 3 H W)`` sampled frames, ``1 <= K <= MAX_SAMPLES``.
        gains: ``(K,)`` per-sample gains (B, G, R).
        band: Cluster half-width, 8-bit units (> 0).
        median: ``(3 H W,)`` output background. mad: ``(3 H W,)`` output MAD.
    """
    p = wp.tid()
    count = wp.min(stack.shape[0], MAX_SAMPLES)
    vb = samples_vec()
    vg = samples_vec()
    vr = samples_vec()
    for k in range(count):
        vb[k] = unlit(float(stack[k, 3 * p]), gains[k][0])
        vg[k] = unlit(float(stack[k, 3 * p + 1]), gains[k][1])
        vr[k] = unlit(float(stack[k, 3 * p + 2]), gains[k][2])
    best = int(0)
    best_count = int(-1)
    for k in range(count):
        n = int(0)
        for j in range(count):
            dist = wp.max(wp.abs(vb[j] - vb[k]), wp.max(wp.abs(vg[j] - vg[k]), wp.abs(vr[j] - vr[k])))
            if float(dist) <= band:
                n += 1
        if n > best_count:
            best_count = n
            best = k
    for c in range(3):
        values = samples_vec()
        kept = samples_vec()
        m = int(0)
        lo = int(255)
        hi = int(0)
        for j in range(count):
            v = vb[j]
            if c == 1:
                v = vg[j]
            elif c == 2:
                v = vr[j]
            values[j] = v
            dist = wp.max(wp.abs(vb[j] - vb[best]), wp.max(wp.abs(vg[j] - vg[best]), wp.abs(vr[j] - vr[best])))
            if float(dist) <= band:
                kept[m] = v
                m += 1
                lo = wp.min(lo, v)
                hi = wp.max(hi, v)
        b = select_rank(kept, m, (m - 1) // 2, lo, hi)
        dev_hi = int(0)
        for j in range(count):
            values[j] = wp.abs(values[j] - b)
            dev_hi = wp.max(dev_hi, values[j])
        median[3 * p + c] = wp.uint8(b)
        mad[3 * p + c] = wp.uint8(select_rank(values, count, (count - 1) // 2, 0, dev_hi))
