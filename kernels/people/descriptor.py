"""S2 colour observation (Lopez-Cifuentes et al., sections 3.1-3.3): HSV planes, image noise, the multi-view 3D
colour descriptor and the appearance probability.

Map to the paper:
- :func:`rgb_to_hsv`: eqs. 12-14 (hexcone HSV). Units: H in [0, 1) (fraction of the hue
  circle, 0 = red), S in [0, 1], V in [0, 1] (intensity / 255). Grey pixels (max = min) get H = 0.
- :func:`noise_partials_kernel` + :func:`noise_sigma_kernel`: sigma_n of eq. 18 from two consecutive frames.
- :func:`var_s`, :func:`var_h`, :func:`alpha_s`, :func:`alpha_h`: the noise propagation of eqs. 15-16 and the
  equalisation weights of eq. 17.
- :func:`descriptor_at`, :func:`descriptor_kernel`: D(P) of eqs. 19-21 for every particle (A_t, eq. 22).
- :func:`appearance_log_prob`: eqs. 23-26 (the test harness launches it per particle).

Choices where the paper is silent or ambiguous (all documented at the function):
- sigma_n (eq. 18): the sum runs over all 3 Npix channel values of the BGR frames of every camera (the paper's
  divisor is 3 Npix and it assumes the same noise in R, G, B), in V units (/255). The difference of two frames has
  variance 2 sigma^2, so for a static scene eq. 18 returns sqrt(2) sigma_n; kept as the paper writes it.
- Eq. 16 gives H_n and S_n for one ordering of R, G, B; var(S_n), var(H_n) are obtained by first-order (delta
  method) propagation with the channels sorted (max, mid, min). H_n is the within-sextant fraction; our hue is the
  fraction of the whole circle, H = (sextant + H_n) / 6, so var(H) = var(H_n) / 36.
- Eq. 17's extracted text reads alpha = (var(V_n) / var(X_n))^2: implemented literally (exponent ``ALPHA_POWER``).
  mu_R, mu_G, mu_B are the Gaussian-weighted mean colour of the particle's neighbourhood (section 3.1, "image
  patch"), accumulated by the descriptor kernel.
- Eq. 20: G is a normalised 2D Gaussian pdf with standard deviation r_i (the paper's "covariance I r_i" is read as
  sigma = r_i), so a camera that sees the whole disc contributes about the same total weight whatever the disc's
  size (the scale invariance the paper claims). The disc radius r_i = sqrt(A_p / pi) is approximated by the pinhole
  radius of the projected sphere r_i = f r_N / depth (f = (fx + fy) / 2; exact for a sphere on the optical axis,
  ignoring distortion), clamped to [``r_min``, ``r_max``] pixels (``r_max`` bounds the cost: one thread loops over
  ~pi r_max^2 pixels per camera). The disc is the set of pixels whose centre lies within r_i of the projected centre,
  clipped to the image; a camera where P is behind or "not seen" (:func:`camera.project`) contributes nothing.
- Linear interpolation into two bins (eq. 20, h(u_k)): bin k has centre (k + 1/2) / N_b; a value between two centres
  is split between them in proportion to its distance. Hue wraps (bin N_b - 1 and bin 0 are neighbours); S and V
  below the first centre or above the last go wholly to the end bin.
- A particle whose neighbourhood no camera sees gets an all-zero descriptor and mass 0; its appearance distance is
  taken as the maximum (M = 1 in eq. 26).
"""

import warp as wp

from wptrack.kernels.core.camera import Camera, project

wp.set_module_options({"enable_backward": False})

ALPHA_POWER = wp.constant(2.0)  # eq. 17 exponent as printed
SQRT_2 = wp.constant(1.4142135623730951)
LOG_SQRT_2PI = wp.constant(0.9189385332046727)  # log(sqrt(2 pi))
INV_2PI = wp.constant(0.15915494309189535)
VAR_FLOOR = wp.constant(1.0e-12)  # floor for variances and denominators (dimensionless, V units squared)


# ------------------------------------------------------------------------------------------------ HSV (eqs. 12-14)


@wp.func
def rgb_to_hsv(r: float, g: float, b: float):
    """Hexcone HSV of an RGB colour in [0, 1]: ``vec3(H [0, 1), S [0, 1], V [0, 1])`` (eqs. 12-14).

    V = max (eq. 12); S = 1 - min / max, 0 when max = 0 (eq. 13); H = (sextant + fraction) / 6 with the standard
    hexcone sextants (eq. 14: for max = R, H = (G - B) / (6 (max - min)) mod 1); grey (max = min) gives H = 0.
    """
    mx = wp.max(r, wp.max(g, b))
    mn = wp.min(r, wp.min(g, b))
    s = float(0.0)
    if mx > 0.0:
        s = 1.0 - mn / mx  # eq. 13
    d = mx - mn
    h = float(0.0)
    if d > 0.0:
        if mx == r:
            h = (g - b) / d
            if h < 0.0:
                h += 6.0
        elif mx == g:
            h = 2.0 + (b - r) / d
        else:
            h = 4.0 + (r - g) / d
        h = h / 6.0  # eq. 14, as a fraction of the circle
        if h >= 1.0:
            h -= 1.0
    return wp.vec3(h, s, mx)  # eq. 12: V = max


# ----------------------------------------------------------------------------------------- noise (eqs. 15-18)


@wp.kernel
def noise_partials_kernel(
    prev: wp.array(dtype=wp.uint8),
    cur: wp.array(dtype=wp.uint8),
    n: int,
    stride: int,
    chunk: int,
    part: wp.array(dtype=wp.float64),
):
    """Eq. 18, pass 1: per-block sums of squared differences of two consecutive frames, in V units (/255).

    ``prev``, ``cur``: flat BGR buffers. The sum runs over the ``n`` channel values of every ``stride``-th pixel
    (value j is channel j % 3 of pixel stride (j / 3); stride 1: all 3 Npix values, the paper's sum; a larger
    stride estimates the same mean square from a pixel subsample, at 1 / stride of the cost). Launch
    ``wp.launch_tiled(dim=[blocks], block_dim=B)``; block ``b`` owns values ``[b chunk, (b+1) chunk)`` and writes
    ``part[b]`` once (no shared address between blocks)."""
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    acc = wp.float64(0.0)
    for j in range(start + lane, stop, wp.block_dim()):
        i = 3 * stride * (j / 3) + j % 3
        d = wp.float64(int(prev[i]) - int(cur[i])) * wp.float64(1.0 / 255.0)
        acc += d * d
    t = wp.tile_sum(wp.tile(acc))
    if lane == 0:
        part[b] = t[0]


@wp.kernel
def noise_sigma_kernel(
    part: wp.array(dtype=wp.float64),
    blocks: int,
    n: int,
    sigma_n: wp.array(dtype=wp.float32),
):
    """Eq. 18, pass 2 (launch one block): ``sigma_n[0] = sqrt(sum (I_{t-1} - I_t)^2 / n)`` with the sum over the
    n channel values of pass 1 (3 Npix with stride 1; V units). Stays on the device (no host sync)."""
    _b, lane = wp.tid()
    acc = wp.float64(0.0)
    for j in range(lane, blocks, wp.block_dim()):
        acc += part[j]
    t = wp.tile_sum(wp.tile(acc))
    if lane == 0:
        sigma_n[0] = wp.float32(wp.sqrt(t[0] / wp.float64(n)))


@wp.func
def var_s(mx: float, mn: float, sigma_n: float):
    """var(S_n) of eq. 16 by first-order propagation: S = 1 - min / max, so
    var S = sigma_n^2 (1 / max^2 + min^2 / max^4). Colour in [0, 1]."""
    m2 = wp.max(mx * mx, VAR_FLOOR)
    return sigma_n * sigma_n * (1.0 / m2 + mn * mn / (m2 * m2))


@wp.func
def var_h(mx: float, mid: float, mn: float, sigma_n: float):
    """var(H) of eq. 16 by first-order propagation, H in fractions of the circle: H_n = (mid - min) / (max - min),
    var H_n = sigma_n^2 (1 / D^2 + ((mid - max)^2 + (mid - min)^2) / D^4) with D = max - min; var H = var H_n / 36."""
    d2 = wp.max((mx - mn) * (mx - mn), VAR_FLOOR)
    a = mid - mx
    c = mid - mn
    return sigma_n * sigma_n * (1.0 / d2 + (a * a + c * c) / (d2 * d2)) / 36.0


@wp.func
def sort3(c: wp.vec3):
    """(max, mid, min) of the three components."""
    mx = wp.max(c[0], wp.max(c[1], c[2]))
    mn = wp.min(c[0], wp.min(c[1], c[2]))
    return mx, c[0] + c[1] + c[2] - mx - mn, mn


@wp.func
def alpha_s(rgb: wp.vec3, sigma_n: float):
    """alpha_S = (var(V_n) / var(S_n))^ALPHA_POWER (eq. 17), var(V_n) = sigma_n^2; ``rgb`` mean colour in [0, 1]."""
    mx, mid, mn = sort3(rgb)
    vv = wp.max(sigma_n * sigma_n, VAR_FLOOR)
    return wp.pow(vv / wp.max(var_s(mx, mn, sigma_n), VAR_FLOOR), ALPHA_POWER)


@wp.func
def alpha_h(rgb: wp.vec3, sigma_n: float):
    """alpha_H = (var(V_n) / var(H_n))^ALPHA_POWER (eq. 17); grey colours (max = min) give alpha_H ~ 0."""
    mx, mid, mn = sort3(rgb)
    vv = wp.max(sigma_n * sigma_n, VAR_FLOOR)
    return wp.pow(vv / wp.max(var_h(mx, mid, mn, sigma_n), VAR_FLOOR), ALPHA_POWER)


# -------------------------------------------------------------------------------------- descriptor (eqs. 19-21)


@wp.func
def bin_split(x: float, nb: int, wrap: int):
    """Linear interpolation of value ``x`` in [0, 1] into two of ``nb`` bins (centres at (k + 1/2) / nb).

    Returns ``(k0, k1, w1)``: weight ``1 - w1`` to bin k0 and ``w1`` to bin k1. ``wrap`` = 1 for hue (bins N_b - 1
    and 0 are neighbours), else values beyond the end centres go wholly to the end bin."""
    t = x * float(nb) - 0.5
    f = wp.floor(t)
    k0 = int(f)
    w1 = t - f
    k1 = k0 + 1
    if wrap == 1:
        k0 = (k0 + nb) % nb
        k1 = k1 % nb
    else:
        if k0 < 0:
            k0 = 0
            w1 = 0.0
        if k1 > nb - 1:
            k1 = nb - 1
            w1 = 0.0
            if k0 > nb - 1:
                k0 = nb - 1
    return k0, k1, w1


@wp.func
def disc_radius(cam: Camera, depth: float, r_n: float, r_min: float, r_max: float):
    """r_i (pixels) of the projected neighbourhood sphere of radius r_N (metres) at ``depth`` (metres):
    f r_N / depth, the pinhole stand-in for sqrt(A_p / pi) (eq. 20), clamped to [r_min, r_max]."""
    f = 0.5 * (cam.f[0] + cam.f[1])
    return wp.clamp(f * r_n / depth, r_min, r_max)


@wp.func
def disc_window(cam: Camera, x: wp.vec3, r_n: float, r_min: float, r_max: float):
    """The disc of world point ``x`` in one camera (eqs. 19-20): ``(u, v, r, x0, x1, y0, y1)``, its centre and
    radius r_i (:func:`disc_radius`), pixels, and the pixel box around it clipped to the image (inclusive). The box is
    empty (``x1 < x0``) when the camera does not see ``x``."""
    uvz = project(cam, x)
    if uvz[2] <= 0.0:
        return 0.0, 0.0, 0.0, 0, -1, 0, -1
    r = disc_radius(cam, uvz[2], r_n, r_min, r_max)
    u = uvz[0]
    v = uvz[1]
    x0 = wp.max(int(wp.ceil(u - r)), 0)
    x1 = wp.min(int(wp.floor(u + r)), cam.width - 1)
    y0 = wp.max(int(wp.ceil(v - r)), 0)
    y1 = wp.min(int(wp.floor(v + r)), cam.height - 1)
    return u, v, r, x0, x1, y0, y1


@wp.func
def pixel_rgb(bgr: wp.array(dtype=wp.uint8), cam: Camera, px: int, py: int):
    """(R, G, B) in [0, 1] of pixel (px, py) of a camera's image in the flat interleaved BGR buffer."""
    o = 3 * (cam.pixel_offset + py * cam.width + px)
    return wp.vec3(float(bgr[o + 2]), float(bgr[o + 1]), float(bgr[o])) * (1.0 / 255.0)


@wp.func
def hist_add(out: wp.array2d(dtype=wp.float32), i: int, base: int, x: float, nb: int, wrap: int, w: float):
    k0, k1, w1 = bin_split(x, nb, wrap)
    out[i, base + k0] = out[i, base + k0] + w * (1.0 - w1)
    out[i, base + k1] = out[i, base + k1] + w * w1


@wp.func
def descriptor_at(
    cams: wp.array(dtype=Camera),
    bgr: wp.array(dtype=wp.uint8),
    x: wp.vec3,
    r_n: float,
    n_bins: int,
    r_min: float,
    r_max: float,
    step: int,
    desc: wp.array2d(dtype=wp.float32),
    i: int,
):
    """D(x) (eqs. 19-21) into row ``i`` of ``desc``; returns (mass, mean colour). See :func:`descriptor_kernel`."""
    nb = n_bins
    for k in range(3 * nb):
        desc[i, k] = 0.0
    total = float(0.0)
    crgb = wp.vec3()
    for c in range(cams.shape[0]):
        cam = cams[c]
        u, vv, r, x0, x1, y0, y1 = disc_window(cam, x, r_n, r_min, r_max)
        if x1 < x0 or y1 < y0:
            continue
        r2 = r * r
        norm = INV_2PI * float(step * step) / r2  # each sample stands for step x step pixels
        for py in range(y0, y1 + 1, step):
            dy = float(py) - vv
            for px in range(x0, x1 + 1, step):
                dx = float(px) - u
                d2 = dx * dx + dy * dy
                if d2 <= r2:
                    w = norm * wp.exp(-0.5 * d2 / r2)  # G of eq. 20, sigma = r_i
                    rgb = pixel_rgb(bgr, cam, px, py)
                    hsv = rgb_to_hsv(rgb[0], rgb[1], rgb[2])  # eqs. 12-14, only for the pixels the discs cover
                    hist_add(desc, i, 0, hsv[0], nb, 1, w)
                    hist_add(desc, i, nb, hsv[1], nb, 0, w)
                    hist_add(desc, i, 2 * nb, hsv[2], nb, 0, w)
                    total += w
                    crgb += w * rgb
    if total > 0.0:
        inv = 1.0 / total  # eq. 20's denominator
        for k in range(3 * nb):
            desc[i, k] = desc[i, k] * inv
        crgb = crgb * inv
    return total, crgb


@wp.kernel
def descriptor_kernel(
    cams: wp.array(dtype=Camera),
    bgr: wp.array(dtype=wp.uint8),
    points: wp.array(dtype=wp.vec3),
    r_n: float,
    n_bins: int,
    r_min: float,
    r_max: float,
    step: int,
    desc: wp.array2d(dtype=wp.float32),
    mass: wp.array(dtype=wp.float32),
    mean_rgb: wp.array(dtype=wp.vec3),
):
    """The 3D colour descriptor D(P) (eqs. 19-21) of every point, one thread per point.

    For every camera: project P (``camera.project``), r_i = :func:`disc_radius`, and for every pixel u_k of the
    disc |u_k - p_i| <= r_i (clipped to the image) add G(|p_i - u_k|) = exp(-d^2 / (2 r_i^2)) / (2 pi r_i^2) times
    h(u_k) (:func:`bin_split`) to the H, S and V histograms; all cameras accumulate together and each histogram is
    divided by the total weight (eq. 20's denominator), so each sums to 1.

    Args:
        cams: (M,) cameras; ``bgr``: (3 P,) frames (the HSV of each disc pixel is computed here, :func:`rgb_to_hsv`:
            the discs cover fewer pixels than the images have).
        points: (N,) positions P, metres. r_n: neighbourhood radius r_N, metres (eq. 19). n_bins: N_b.
        r_min, r_max: clamp of the disc radius, pixels.
        step: pixel stride of the disc's samples in x and y (1: every pixel, eq. 20 exactly; 2: a quarter of them,
            each weighted for step x step pixels, a quadrature of the same Gaussian-weighted histogram).
        desc: (N, 3 N_b) out: H bins, then S bins, then V bins (each normalised; all zero when unseen).
        mass: (N,) out: total Gaussian weight (eq. 20's denominator); 0 when no camera sees the neighbourhood.
        mean_rgb: (N,) out: Gaussian-weighted mean colour (R, G, B) in [0, 1] (the patch means of section 3.1).

    Cost: sum over cameras of ~pi r_i^2 / step^2 pixels per particle (r_max = 12 px, step 1: up to ~450 reads per
    camera), each doing 6 read-modify-writes of the thread's own histogram row.
    """
    i = wp.tid()
    m, rgb = descriptor_at(cams, bgr, points[i], r_n, n_bins, r_min, r_max, step, desc, i)
    mass[i] = m
    mean_rgb[i] = rgb


# ------------------------------------------------------------------------------- appearance (eqs. 23-26)


@wp.func
def hist_distance(a: wp.array2d(dtype=wp.float32), i: int, b: wp.array2d(dtype=wp.float32), j: int, base: int, nb: int):
    """Euclidean distance E between bins ``base .. base + nb - 1`` of rows ``a[i]`` and ``b[j]`` (eq. 23)."""
    acc = float(0.0)
    for k in range(base, base + nb):
        d = a[i, k] - b[j, k]
        acc += d * d
    return wp.sqrt(acc)


@wp.func
def appearance_log_prob(
    model: wp.array2d(dtype=wp.float32),
    i: int,
    desc: wp.array2d(dtype=wp.float32),
    j: int,
    mass: float,
    rgb: wp.vec3,
    n_bins: int,
    sigma_n: float,
    sigma_p: float,
):
    """log p(A_t | x_t) (eqs. 23-26) between the predicted appearance ``model[i]`` (C_t) and the observed descriptor
    ``desc[j]`` (A_t, mass ``mass``, mean colour ``rgb`` for alpha_S, alpha_H of eq. 17).

    d_H = E(C_H, D_H) alpha_H / sqrt 2, d_S = E(C_S, D_S) alpha_S / sqrt 2, d_V = E(C_V, D_V) / sqrt 2 (eq. 23);
    M = (d_H + d_S + beta_V d_V) / (alpha_H + alpha_S + beta_V) (eq. 24), beta_V = N(d_V; 0, sigma_n) (eq. 25);
    log p = -M^2 / (2 sigma_p^2) - log(sqrt(2 pi) sigma_p) (eq. 26). An unseen descriptor (mass 0) gets M = 1.
    ``sigma_n`` in V units (eq. 18), ``sigma_p`` dimensionless.
    """
    m = float(1.0)
    if mass > 0.0:
        nb = n_bins
        a_s = alpha_s(rgb, sigma_n)
        a_h = alpha_h(rgb, sigma_n)
        d_h = hist_distance(model, i, desc, j, 0, nb) * a_h / SQRT_2  # eq. 23
        d_s = hist_distance(model, i, desc, j, nb, nb) * a_s / SQRT_2
        d_v = hist_distance(model, i, desc, j, 2 * nb, nb) / SQRT_2
        sn = wp.max(sigma_n, 1.0e-6)
        beta = wp.exp(-d_v * d_v / (2.0 * sn * sn) - LOG_SQRT_2PI) / sn  # eq. 25
        m = (d_h + d_s + beta * d_v) / wp.max(a_h + a_s + beta, VAR_FLOOR)  # eq. 24
    return -m * m / (2.0 * sigma_p * sigma_p) - LOG_SQRT_2PI - wp.log(sigma_p)  # eq. 26


# ------------------------------------------------------------------------- descriptor, one block per particle

MAX_BINS = wp.constant(16)
"""Largest N_b of :func:`descriptor_block_kernel` (its per-lane histograms are fixed-size vectors)."""

#: Per-lane partial sums of one particle's descriptor: 3 N_b histogram bins (N_b <= MAX_BINS), then the total
#: weight and the weighted R, G, B.
desc_acc = wp.types.vector(length=3 * 16 + 4, dtype=wp.float32)


@wp.func
def acc_add(acc: desc_acc, base: int, x: float, nb: int, wrap: int, w: float):
    k0, k1, w1 = bin_split(x, nb, wrap)
    acc[base + k0] = acc[base + k0] + w * (1.0 - w1)
    acc[base + k1] = acc[base + k1] + w * w1
    return acc


@wp.kernel
def descriptor_block_kernel(
    cams: wp.array(dtype=Camera),
    bgr: wp.array(dtype=wp.uint8),
    points: wp.array(dtype=wp.vec3),
    r_n: float,
    n_bins: int,
    r_min: float,
    r_max: float,
    step: int,
    desc: wp.array2d(dtype=wp.float32),
    mass: wp.array(dtype=wp.float32),
    mean_rgb: wp.array(dtype=wp.vec3),
):
    """:func:`descriptor_kernel` with one block per particle (``wp.launch_tiled(dim=[N], block_dim=B)``, N_b <=
    ``MAX_BINS``): the lanes share the disc pixels of every camera, each accumulates a partial histogram, and one
    block-wide sum (``wp.tile_sum``) combines them; lane 0 normalises and writes. The same sums as the one-thread
    kernel (eqs. 19-21) in another order (float32 rounding differs); on a GPU the thread-per-particle kernel leaves
    most of the device idle for a few thousand particles, this one does not. On the CPU a block is one lane."""
    i, lane = wp.tid()
    nb = n_bins
    x = points[i]
    acc = desc_acc()
    for c in range(cams.shape[0]):
        cam = cams[c]
        u, vv, r, x0, x1, y0, y1 = disc_window(cam, x, r_n, r_min, r_max)
        if x1 < x0 or y1 < y0:
            continue
        nx = (x1 - x0) / step + 1
        ny = (y1 - y0) / step + 1
        r2 = r * r
        norm = INV_2PI * float(step * step) / r2
        for k in range(lane, nx * ny, wp.block_dim()):
            py = y0 + (k / nx) * step
            px = x0 + (k % nx) * step
            dy = float(py) - vv
            dx = float(px) - u
            d2 = dx * dx + dy * dy
            if d2 <= r2:
                w = norm * wp.exp(-0.5 * d2 / r2)  # G of eq. 20, sigma = r_i
                rgb = pixel_rgb(bgr, cam, px, py)
                hsv = rgb_to_hsv(rgb[0], rgb[1], rgb[2])
                acc = acc_add(acc, 0, hsv[0], nb, 1, w)
                acc = acc_add(acc, nb, hsv[1], nb, 0, w)
                acc = acc_add(acc, 2 * nb, hsv[2], nb, 0, w)
                t = 3 * nb
                acc[t] = acc[t] + w
                acc[t + 1] = acc[t + 1] + w * rgb[0]
                acc[t + 2] = acc[t + 2] + w * rgb[1]
                acc[t + 3] = acc[t + 3] + w * rgb[2]
    s = wp.tile_sum(wp.tile(acc), axis=1)  # (3 N_b + 4,): the block's sums
    if lane == 0:
        t = 3 * nb
        total = s[t]
        inv = float(0.0)
        if total > 0.0:
            inv = 1.0 / total  # eq. 20's denominator
        for k in range(3 * nb):
            desc[i, k] = s[k] * inv
        mass[i] = total
        mean_rgb[i] = wp.vec3(s[t + 1], s[t + 2], s[t + 3]) * inv
