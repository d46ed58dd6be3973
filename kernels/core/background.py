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
pixel whose neighbours' mean normalised difference is far from 0, and not a cast shadow's darkening
(:func:`shadow_like`), becomes weak foreground too (a faint but coherent change, e.g. a car painted like the road).

Local illumination changes (issue 26): the frame is divided by a local light field and a pixel whose patch keeps
the background's texture is vetoed (:func:`local_gain`, :func:`illumination_change`); the patch statistics and the
field are made by the kernels of :mod:`wptrack.kernels.core.illumination` (driver:
:mod:`wptrack.motion.illumination`). :func:`mode_kernel` is the densest-cluster background of short recordings, its
samples weighed by how still they are (:func:`sample_change_kernel`, :func:`box_mean_kernel`, :func:`sample_weight`).

Length: one module for the offline model's per-pixel kernels, because they share its per-thread sample vectors, the
gain compensation of a sample (:func:`unlit`) and the bitwise selection (:func:`select_rank`); the light field's
kernels, which share none of them, have their own module (:mod:`wptrack.kernels.core.illumination`).
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

#: Most frames one background window may sample (the selection loops are unbounded, this bounds the cost).
MAX_SAMPLES = wp.constant(64)

#: 1 / Phi^-1(3/4): MAD -> standard deviation of a gaussian.
MAD_TO_SIGMA = wp.constant(1.4826)


#: Per-thread copy of one channel value's K samples (read once from the strided stack, then scanned 16 times).
samples_vec = wp.types.vector(length=MAX_SAMPLES, dtype=wp.int32)

#: Per-thread weights of one pixel's K samples (:func:`mode_kernel`).
weights_vec = wp.types.vector(length=MAX_SAMPLES, dtype=wp.float32)


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
    step: int,
    median: wp.array(dtype=wp.uint8),
    mad: wp.array(dtype=wp.uint8),
):
    """Per channel value ``j``: lower median of ``stack[:, j] / gains[:, j % 3]`` and its MAD (lower median of
    absolute deviations); with ``step > 1`` only at every ``step``-th pixel (launched over ``3 ceil(H W / step)``
    threads; the other pixels' values are left as they are).

    Args:
        stack: ``(K, 3 H W)`` sampled frames, ``1 <= K <= MAX_SAMPLES``.
        gains: ``(K,)`` global gain of each sample per channel (B, G, R) relative to the window (1: none): the
            samples are compensated for global illumination changes before the statistics.
        step: Pixels between two computed pixels (1: every pixel): the densest cluster's band needs the image-wide
            noise scale only, which reads every 7th pixel's MAD.
        median: ``(3 H W,)`` output background.
        mad: ``(3 H W,)`` output median absolute deviation (8-bit units).
    """
    j = wp.tid()
    c = j % 3
    if step > 1:
        j = 3 * (j // 3) * step + c
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


#: Per-pixel patch statistics of :func:`wptrack.kernels.core.illumination.patch_kernel`: NCC of the luminance
#: patches (frame vs background), correlation of their gradients, the background's and the frame's patch standard
#: deviations (luminance noise scales), the centre pixel's residual from the patch's linear fit (luminance noise
#: scales), and the fit's distance from a gain.
patch_vec = wp.types.vector(length=6, dtype=wp.float32)

#: Row sums of :func:`wptrack.kernels.core.illumination.patch_rows_kernel`: f, b, f^2, b^2, f b,
#: grad f . grad b, |grad f|^2, |grad b|^2, count.
rows_vec = wp.types.vector(length=9, dtype=wp.float32)


@wp.func
def patch_at(
    rows: wp.array(dtype=rows_vec), luma: wp.array(dtype=wp.vec3), width: int, height: int, radius: int, p: int
):
    """The patch statistics of pixel ``p`` (:func:`wptrack.kernels.core.illumination.patch_kernel`, which calls this:
    the same operations, so the same values) from the row sums ``rows`` and the luminance ``luma`` of
    :func:`wptrack.kernels.core.illumination.patch_rows_kernel` and ``luma_kernel``; for the kernels that need them
    at a few pixels only (the tiles' votes, the veto's candidates)."""
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
    return out


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
    no_prob: int  # 1: the probability is not asked for (foreground_kernel leaves ``prob`` as it is); 0: written


@wp.func
def local_gain(local: wp.array(dtype=wp.vec3), params: ForegroundParams, p: int):
    """The local illumination field at pixel ``p``: the exponential of the tiles' log gains interpolated bilinearly
    between the tile centres (clamped at the image border); exactly 1 where the four tiles' log gains are all 0
    (``exp(0) = 1``: the exponentials are skipped)."""
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
    q00 = local[j0 * params.tiles_x + i0]
    q01 = local[j0 * params.tiles_x + i1]
    q10 = local[j1 * params.tiles_x + i0]
    q11 = local[j1 * params.tiles_x + i1]
    zero = wp.vec3(0.0, 0.0, 0.0)
    if q00 == zero and q01 == zero and q10 == zero and q11 == zero:
        return wp.vec3(1.0, 1.0, 1.0)  # no local change around (the usual case): exp(0) = 1 without the exps
    top = (1.0 - fu) * q00 + fu * q01
    bottom = (1.0 - fu) * q10 + fu * q11
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


@wp.func
def background_at(
    bg0: wp.array(dtype=wp.uint8),
    mad0: wp.array(dtype=wp.uint8),
    bg1: wp.array(dtype=wp.uint8),
    mad1: wp.array(dtype=wp.uint8),
    w: float,
    params: ForegroundParams,
    p: int,
):
    """Pixel ``p``'s background (B, G, R) between the two windows and its noise scale ``s = max(s0, min(s_cap, 1.4826
    sqrt(sum_c MAD_c^2 / 3)))``, 8-bit units, as :func:`foreground_kernel` tests the frame against them."""
    b = wp.vec3(0.0, 0.0, 0.0)
    mm = float(0.0)
    for c in range(3):
        b[c] = float(bg0[3 * p + c])
        m = float(mad0[3 * p + c])
        if w > 0.0:  # between two windows (w = 0: one window, half the reads)
            b[c] = (1.0 - w) * b[c] + w * float(bg1[3 * p + c])
            m = (1.0 - w) * m + w * float(mad1[3 * p + c])
        mm += m * m
    spread = MAD_TO_SIGMA * wp.sqrt(mm / 3.0)
    if params.spread_cap > 0.0:
        spread = wp.min(spread, params.spread_cap)
    return b, wp.max(params.noise_floor, spread)


@wp.func
def shadow_like(m: wp.vec3, u: wp.vec3, params: ForegroundParams):
    """Whether a neighbourhood's mean normalised difference ``m`` darkens the background ``u = B / s`` as a cast shadow
    (the shadow test on the mean frame ``B + s m``): ratio ``a = 1 + m.u / u.u`` in ``[shadow_lo, shadow_hi]``,
    chromaticity distortion ``|m - (a - 1) u| / |u| <= chroma_max``. False with the shadow test off."""
    uu = wp.dot(u, u)
    if params.shadow == 0 or uu <= 0.0:
        return False
    a = 1.0 + wp.dot(m, u) / uu
    cd = wp.length(m - (a - 1.0) * u) / wp.sqrt(uu)
    return a >= params.shadow_lo and a <= params.shadow_hi and cd <= params.chroma_max


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
    rows: wp.array(dtype=rows_vec),
    luma: wp.array(dtype=wp.vec3),
    radius: int,
    height: int,
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
            of the frame over the background beyond the global gain
            (:func:`wptrack.kernels.core.illumination.tile_smooth_kernel`), interpolated bilinearly between the tile
            centres; the frame is divided by its exponential too. Read only when ``params.tile > 0``.
        rows, luma: ``(H W,)`` the row sums and luminance of :func:`wptrack.kernels.core.illumination.patch_rows_kernel`
            and ``luma_kernel``, for the illumination veto: the patch statistics (:func:`patch_at`) are computed
            from them at the pixels the veto tests only; read only when ``params.veto_ncc > 0`` or
            ``params.veto_grad > 0``. radius: The patch radius, pixels. height: Image height, pixels.
        patch: ``(H W,)`` output: the patch statistics (as :func:`wptrack.kernels.core.illumination.patch_kernel`'s)
            of the pixels the veto tested (foreground candidates, ``z > T_low`` and not a cast shadow); other pixels
            are left as they were.
        mask: ``(H W,)`` output ``level + 4 shadow``: level 2 = foreground, 1 = weak foreground
            (``T_low < z <= T``), 0 = background (and every cast shadow or illumination change); ``shadow`` as
            below (one array for the driver to copy).
        prob: ``(H W,)`` output foreground probability in ``[0, 1]`` (left as it is with ``params.no_prob``).
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
    back, s = background_at(bg0, mad0, bg1, mad1, w, params, p)
    d = wp.vec3(0.0, 0.0, 0.0)
    dd = float(0.0)
    ib = float(0.0)
    bb = float(0.0)
    ii = float(0.0)
    for c in range(3):
        b = back[c]
        x = float(frame[3 * p + c]) / lit[c]
        d[c] = x - b
        dd += (x - b) * (x - b)
        ib += x * b
        bb += b * b
        ii += x * x
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
        st = patch_at(rows, luma, params.width, height, radius, p)
        patch[p] = st
        if illumination_change(st, params, ib, bb, ii):
            is_shadow = 3
    fg = int(0)
    if is_shadow < 2:
        if z > params.threshold:
            fg = 2
        elif z > params.low_threshold:
            fg = 1
    mask[p] = wp.uint8(fg + 4 * is_shadow)
    if params.no_prob == 0:
        pr = float(0.0)
        if is_shadow < 2:
            pr = 1.0 / (1.0 + wp.exp(-(z - params.threshold) / params.soft_scale))
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
    bg0: wp.array(dtype=wp.uint8),
    mad0: wp.array(dtype=wp.uint8),
    bg1: wp.array(dtype=wp.uint8),
    mad1: wp.array(dtype=wp.uint8),
    w: float,
    params: ForegroundParams,
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
    ``scale < 1`` for spatially correlated noise, measured by the driver), unless that mean is a cast shadow's
    darkening (:func:`shadow_like`): a soft shadow's faint edge, under the per-pixel test's ``z > T_low``. Other
    pixels are copied.

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
        bg0, mad0, bg1, mad1, w, params: As :func:`foreground_kernel`'s (read where a pixel would be marked).
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
                b, s = background_at(bg0, mad0, bg1, mad1, w, params, p)
                if not shadow_like(wp.vec3(acc[0], acc[1], acc[2]) / n, b / s, params):
                    v = v + 1
        out[p] = wp.uint8(v)
        if y + radius + 1 < height:
            acc += rows[(y + radius + 1) * width + x]
        if y - radius >= 0:
            acc -= rows[(y - radius) * width + x]


#: Weight of a sample that moved (see :func:`mode_kernel`) in the densest-cluster count; a still sample weighs 1.
MOVING_WEIGHT = wp.constant(0.125)


@wp.kernel
def gather_columns_kernel(
    stack: wp.array2d(dtype=wp.uint8),
    columns: wp.array(dtype=wp.int32),
    out: wp.array2d(dtype=wp.uint8),
):
    """``out[r, j] = stack[r, columns[j]]``: the channel values of a pixel subsample of each of a window's samples
    (the host statistics' input: a few MB to download instead of the whole ``(K, 3 H W)`` stack). Launched with
    ``dim=(K, J)``.

    Args:
        stack: ``(K, 3 P)`` sampled frames. columns: ``(J,)`` flat channel-value indices into a row of ``stack``.
        out: ``(K, J)`` output.
    """
    r, j = wp.tid()
    out[r, j] = stack[r, columns[j]]


@wp.kernel
def sample_change_kernel(
    stack: wp.array2d(dtype=wp.uint8),
    gains: wp.array(dtype=wp.vec3),
    lag: int,
    change: wp.array2d(dtype=wp.uint8),
):
    """Per sample ``r >= lag`` and pixel ``p``: the change from sample ``r - lag`` of the window, the largest
    channel's ``|S_r - S_(r-lag)|`` after both are compensated by their gains (8-bit units). Launched with
    ``dim=(K - lag, P)``; rows ``0 .. lag - 1`` of ``change`` are not written.

    Args:
        stack: ``(K, 3 P)`` sampled frames (time order). gains: ``(K,)`` per-sample gains (B, G, R).
        lag: Samples between the two compared (>= 1).
        change: ``(K, P)`` output, row ``r`` the change from sample ``r - lag`` to ``r``.
    """
    i, p = wp.tid()
    r = i + lag
    d = int(0)
    for c in range(3):
        a = unlit(float(stack[r, 3 * p + c]), gains[r][c])
        b = unlit(float(stack[r - lag, 3 * p + c]), gains[r - lag][c])
        d = wp.max(d, wp.abs(a - b))
    change[r, p] = wp.uint8(d)


@wp.kernel
def box_mean_kernel(
    src: wp.array2d(dtype=wp.uint8),
    length: int,
    count: int,
    step: int,
    stride: int,
    radius: int,
    dst: wp.array2d(dtype=wp.uint8),
):
    """One pass of a separable box mean over the images in the rows of ``src`` (a running sum per line): line
    ``l`` of image row ``r`` holds the pixels ``l * stride + x * step``, ``x < length``; each gets the mean of the
    pixels within ``radius`` of it along the line (the window clipped at the image's border), rounded half up.
    Horizontal: ``length = W, step = 1, stride = W``; vertical: ``length = H, step = W, stride = 1``. Launched with
    ``dim=(K, count)``, ``count`` the lines per image (H or W).

    Args:
        src: ``(K, P)`` images. dst: ``(K, P)`` output (not ``src``).
    """
    r, line = wp.tid()
    base = line * stride
    acc = int(0)
    for x in range(wp.min(radius, length - 1) + 1):
        acc += int(src[r, base + x * step])
    for x in range(length):
        lo = wp.max(x - radius, 0)
        hi = wp.min(x + radius, length - 1)
        n = hi - lo + 1
        dst[r, base + x * step] = wp.uint8((acc + n // 2) // n)
        if x + radius + 1 < length:
            acc += int(src[r, base + (x + radius + 1) * step])
        if x - radius >= 0:
            acc -= int(src[r, base + (x - radius) * step])


@wp.func
def sample_weight(motion: wp.array2d(dtype=wp.uint8), count: int, lag: int, k: int, p: int, still: float):
    """Weight of sample ``k`` at pixel ``p`` in :func:`mode_kernel`'s count: 1 if it changed by at most ``still``
    (8-bit units) from the sample ``lag`` before it or the one ``lag`` after it (``motion``: the patch means of
    :func:`sample_change_kernel`; only the one that exists near the window's ends), else :data:`MOVING_WEIGHT`; 1 for
    every sample when ``still <= 0``, and for a sample with no other ``lag`` away (no evidence either way)."""
    if still <= 0.0 or (k < lag and k + lag >= count):
        return 1.0
    m = int(256)
    if k >= lag:
        m = int(motion[k, p])
    if k + lag < count:
        m = wp.min(m, int(motion[k + lag, p]))
    if float(m) <= still:
        return 1.0
    return MOVING_WEIGHT


@wp.kernel
def mode_kernel(
    stack: wp.array2d(dtype=wp.uint8),
    gains: wp.array(dtype=wp.vec3),
    band: float,
    motion: wp.array2d(dtype=wp.uint8),
    lag: int,
    still: float,
    median: wp.array(dtype=wp.uint8),
    mad: wp.array(dtype=wp.uint8),
):
    """Per pixel: the background as the densest cluster of its samples instead of their median (short recordings
    with objects in most frames: a pixel that objects cover in more than half of the samples keeps its background
    when the objects differ from sample to sample while the background does not).

    The samples are compensated by their gains as in :func:`median_mad_kernel`. The centre is the first sample with
    the largest weight of samples within ``band`` of it in every channel (Chebyshev distance, 8-bit units); the
    background is the per-channel lower median of those samples, and the MAD the lower median of all samples'
    absolute deviations from it (as :func:`median_mad_kernel`'s, so a pixel whose samples spread keeps its spread).

    A sample weighs 1 where it is still, :data:`MOVING_WEIGHT` where it changed from both samples ``lag`` before and
    after it (:func:`sample_weight`): people who stand for most of a short clip are one dense cluster of samples
    too, but they move (sway, gestures: a patch changes by tens of levels from one sample to the next) where the
    ground does not (noise: a level or two), so the few samples of the uncovered ground outweigh them (issue 26,
    short recordings).
    ``lag`` is 1 (neighbouring samples) unless the samples lie much closer than a fifth of a second (the driver's
    choice): a short clip sampled every frame or two would find a plain coat's inside unchanged.

    Args:
        stack: ``(K, 3 H W)`` sampled frames, ``1 <= K <= MAX_SAMPLES``.
        gains: ``(K,)`` per-sample gains (B, G, R).
        band: Cluster half-width, 8-bit units (> 0).
        motion: ``(K, H W)`` each sample's change from the one ``lag`` before, patch means
            (:func:`sample_change_kernel`, :func:`box_mean_kernel`; rows ``< lag`` unused); not read when
            ``still <= 0``.
        lag: Samples between the two compared (>= 1).
        still: Largest change of a still sample, 8-bit units (<= 0: every sample weighs 1).
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
    weight = weights_vec()
    for k in range(count):
        weight[k] = sample_weight(motion, count, lag, k, p, still)
    # each pair once (the distance is symmetric): n[k] is the weight of the samples within the band of sample k,
    # itself included; the weights are multiples of MOVING_WEIGHT = 1/8 summing to at most 64, exact in float32,
    # so the order of the sums changes nothing
    n = weights_vec()
    for k in range(count):
        n[k] = weight[k]
    for k in range(count):
        bk = vb[k]
        gk = vg[k]
        rk = vr[k]
        nk = n[k]
        wk = weight[k]
        for j in range(k + 1, count):
            dist = wp.max(wp.abs(vb[j] - bk), wp.max(wp.abs(vg[j] - gk), wp.abs(vr[j] - rk)))
            if float(dist) <= band:
                nk += weight[j]
                n[j] += wk
        n[k] = nk
    best = int(0)
    best_count = float(-1.0)
    for k in range(count):
        if n[k] > best_count:
            best_count = n[k]
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
