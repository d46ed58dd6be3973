"""Local illumination changes (issue 26): the patch statistics, the local light field and the compensation of a
window's samples, for the offline background model (the driver: :mod:`wptrack.motion.illumination`).

A cloud's shadow drifting over the ground, a light switched on in part of the view, change the light of a region
smoothly and coherently: texture, gradient structure and hue stay, scaled. :func:`luma_kernel`,
:func:`patch_rows_kernel` and :func:`patch_kernel` compare every pixel's luminance patch with the background's
(normalised cross-correlation, gradient correlation, texture, the pixel's residual from the patch's linear fit);
:func:`tile_gain_kernel` takes per tile the median brightness ratio of the pixels whose patch keeps the background's
texture (selection on quantised log ratios, :data:`LOG_STEPS`), :func:`tile_smooth_kernel` smooths the tiles by a
weighted median; :func:`wptrack.kernels.core.background.foreground_kernel` divides the frame by that field
(:func:`~wptrack.kernels.core.background.local_gain`, bilinear between tile centres) and vetoes what
:func:`~wptrack.kernels.core.background.illumination_change` explains; :func:`compensate_kernel` divides a window's
samples by their own fields; :func:`patch_pixels_kernel` gives the patch statistics of listed pixels (the texture
test of a window's shadow votes).
"""

import warp as wp

from wptrack.kernels.core.background import (
    MAX_SAMPLES,
    ForegroundParams,
    background_at,
    local_gain,
    patch_at,
    patch_vec,
    rows_vec,
    samples_vec,
    select_rank,
    unlit,
)

wp.set_module_options({"enable_backward": False})

#: Quantisation of a log brightness ratio to 0..255: ``q = 128 + round(LOG_STEPS ln(ratio))`` (ratios 1/4 .. 4,
#: steps of 1.09 %), so a tile's median ratio is a selection on 8-bit values (:func:`select_rank`).
LOG_STEPS = wp.constant(92.33248261689366)

#: Background values below this (8-bit) are left out of the local gains (dark pixels carry no ratio).
MIN_LEVEL = wp.constant(16.0)


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
    b, s = background_at(bg0, mad0, bg1, mad1, w, params, p)
    f = float(0.0)
    bs = float(0.0)
    for c in range(3):
        f += float(frame[3 * p + c]) / gain[c]
        bs += b[c]
    luma[p] = wp.vec3(f / 3.0, bs / 3.0, s)


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
def luma_grad_kernel(
    luma: wp.array(dtype=wp.vec3),
    width: int,
    height: int,
    grads: wp.array(dtype=wp.vec4),
):
    """Per pixel, :func:`luma_grad` once, for :func:`patch_rows_kernel` (which reads each pixel's gradients in
    ``2 radius + 1`` row sums).

    Args:
        luma: ``(H W,)`` :func:`luma_kernel`'s output. width, height: Image size, pixels.
        grads: ``(H W,)`` output ``(df/dx, df/dy, db/dx, db/dy)``.
    """
    p = wp.tid()
    grads[p] = luma_grad(luma, p % width, p // width, width, height)


@wp.kernel
def patch_rows_kernel(
    luma: wp.array(dtype=wp.vec3),
    grads: wp.array(dtype=wp.vec4),
    width: int,
    height: int,
    radius: int,
    gradients: int,
    rows: wp.array(dtype=rows_vec),
):
    """First (horizontal) pass of :func:`patch_kernel`: per pixel, the sums over its row neighbours
    ``x - radius .. x + radius`` inside the image of ``f, b, f^2, b^2, f b`` (of ``f - 128`` and ``b - 128``),
    ``grad f . grad b``, ``|grad f|^2``, ``|grad b|^2`` (:func:`luma_grad`, from :func:`luma_grad_kernel`) and their
    count. One thread per pixel
    (each sum read afresh: no sliding sums, no float32 cancellation).

    Args:
        luma: ``(H W,)`` :func:`luma_kernel`'s output. grads: ``(H W,)`` :func:`luma_grad_kernel`'s output (read
            only with ``gradients``).
        width, height: Image size, pixels. radius: Patch radius.
        gradients: 1: the gradient sums too; 0: they stay 0 (so :func:`patch_kernel`'s gradient correlation is 0):
            only the gradient veto (``veto_grad > 0``, off by default) reads them, and they are 40 % of the sums.
        rows: ``(H W,)`` output row sums.
    """
    p = wp.tid()
    y = p // width
    x = p % width
    acc = rows_vec()
    for xx in range(wp.max(x - radius, 0), wp.min(x + radius + 1, width)):
        v = luma[y * width + xx]
        f = v[0] - 128.0  # centred: smaller float32 sums of squares (variances are differences of them)
        b = v[1] - 128.0
        acc[0] += f
        acc[1] += b
        acc[2] += f * f
        acc[3] += b * b
        acc[4] += f * b
        if gradients != 0:
            g = grads[y * width + xx]
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
    patch[p] = patch_at(rows, luma, width, height, radius, p)


#: Most subsample pixels of a tile in each direction (:func:`tile_gain_kernel`: every ``ceil(tile / 8)``-th pixel).
TILE_SAMPLES = wp.constant(8)


@wp.kernel
def patch_samples_kernel(
    rows: wp.array(dtype=rows_vec),
    luma: wp.array(dtype=wp.vec3),
    params: ForegroundParams,
    height: int,
    radius: int,
    patch: wp.array(dtype=patch_vec),
):
    """:func:`patch_kernel` at the pixels :func:`tile_gain_kernel` reads only (each tile's regular subsample of at
    most 8 x 8 pixels; the same values: :func:`~wptrack.kernels.core.background.patch_at`); other pixels are left
    as they were. One thread per tile and subsample slot (launch with ``dim = tiles_y tiles_x 64``).

    Args:
        rows, luma: ``(H W,)`` :func:`patch_rows_kernel`'s sums and :func:`luma_kernel`'s output.
        params: ``tile``, ``tiles_x``, ``width``. height: Image height, pixels. radius: Patch radius, pixels.
        patch: ``(H W,)`` output, written at the subsample.
    """
    t = wp.tid()
    k = t % (TILE_SAMPLES * TILE_SAMPLES)
    tile = t // (TILE_SAMPLES * TILE_SAMPLES)
    tx = tile % params.tiles_x
    ty = tile // params.tiles_x
    step = wp.max(1, (params.tile + 7) // 8)
    yy = ty * params.tile + (k // TILE_SAMPLES) * step
    xx = tx * params.tile + (k % TILE_SAMPLES) * step
    if yy < wp.min((ty + 1) * params.tile, height) and xx < wp.min((tx + 1) * params.tile, params.width):
        p = yy * params.width + xx
        patch[p] = patch_at(rows, luma, params.width, height, radius, p)


@wp.kernel
def patch_pixels_kernel(
    rows: wp.array(dtype=rows_vec),
    luma: wp.array(dtype=wp.vec3),
    pixels: wp.array(dtype=wp.int32),
    width: int,
    height: int,
    radius: int,
    patch: wp.array(dtype=patch_vec),
):
    """:func:`patch_kernel` at a list of pixels (the same values:
    :func:`~wptrack.kernels.core.background.patch_at`), packed: ``patch[i]`` is pixel ``pixels[i]``'s. For the
    texture test of a window's shadow votes (a pixel subsample of each sample). One thread per listed pixel.

    Args:
        rows, luma: ``(H W,)`` :func:`patch_rows_kernel`'s sums and :func:`luma_kernel`'s output.
        pixels: ``(P,)`` flat pixel indices ``y W + x``.
        width, height: Image size, pixels. radius: Patch radius, pixels.
        patch: ``(P,)`` output ``(ncc, gc, tex_b, tex_f, resid, gap)`` per listed pixel.
    """
    i = wp.tid()
    patch[i] = patch_at(rows, luma, width, height, radius, pixels[i])


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
    """The smallest of ``values[:count]`` of positive weight whose weight with that of the values below it reaches
    half the total (a lower weighted median; ties broken by the value).

    The values of positive weight are sorted (insertion) and their distinct values tried in ascending order: the
    weight below a value only grows with it, so the first that reaches half the total is the smallest. Each sum is
    taken over ``values`` in index order (the float32 sums, and so the medians, of the definition bit for bit)."""
    sv = neighbours_vec()
    n = int(0)
    for i in range(count):
        if weights[i] > 0.0:
            vi = values[i]
            j = n
            while j > 0 and sv[j - 1] > vi:
                sv[j] = sv[j - 1]
                j -= 1
            sv[j] = vi
            n += 1
    best = float(0.0)
    for k in range(n):
        v = sv[k]
        tried = False
        if k > 0:
            if sv[k - 1] == v:
                tried = True
        if not tried:
            below = float(0.0)
            for j in range(count):
                if values[j] <= v:
                    below += weights[j]
            if below >= 0.5 * total:
                best = v
                break
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
