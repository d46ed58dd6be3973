"""NumPy reference of the offline background model's kernels (:mod:`wptrack.kernels.core.background`), for the tests
and the ``masks`` benchmark: same formulas, float64 instead of float32."""

from __future__ import annotations

import numpy as np

MAD_TO_SIGMA = 1.4826


def median_mad(stack: np.ndarray, gains: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Lower median and MAD over axis 0 of a ``(K, 3 P)`` uint8 stack (0-based order statistic ``(K - 1) // 2``),
    each sample first divided by its ``(K, 3)`` channel gains (rounded half up, clamped to 0..255)."""
    rank = (stack.shape[0] - 1) // 2
    if gains is not None:
        k = stack.shape[0]
        g = np.asarray(gains, dtype=np.float64)[:, None, :]
        stack = np.clip(np.floor(stack.reshape(k, -1, 3) / g + 0.5), 0, 255).astype(np.uint8).reshape(k, -1)
    median = np.partition(stack, rank, axis=0)[rank]
    dev = np.abs(stack.astype(np.int16) - median.astype(np.int16)).astype(np.uint8)
    return median, np.partition(dev, rank, axis=0)[rank]


def neighbourhood(
    packed: np.ndarray,
    diff: np.ndarray,
    radius: int,
    low_threshold: float,
    scale: float = 1.0,
    u: np.ndarray | None = None,
    shadow: tuple[float, float, float] | None = None,
) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.core.background.neighbourhood_kernel` on ``(H, W)`` packed levels and
    ``(H, W, 3)`` normalised differences (box sums over the usable neighbours, zero outside the image); with
    ``shadow`` = ``(shadow_lo, shadow_hi, chroma_max)`` and ``u`` the ``(H, W, 3)`` background over its noise scale
    ``B / s``, a neighbourhood whose mean difference is a cast shadow's darkening of ``u`` is not marked
    (:func:`wptrack.kernels.core.background.shadow_like`)."""
    import cv2

    usable = (((packed & 3) < 2) & ((packed >> 2) == 0)).astype(np.float64)
    k = (2 * radius + 1, 2 * radius + 1)

    def box(a: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(a, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)

    n = box(usable)
    acc = np.stack([box(diff[..., c].astype(np.float64) * usable) for c in range(3)], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        z2 = np.where(n > 0, scale**2 * (acc * acc).sum(axis=-1) / (3.0 * np.maximum(n, 1.0)), 0.0)
    target = ((packed & 3) == 0) & ((packed >> 2) < 2) & (n > 0) & (z2 > low_threshold**2)
    if shadow is not None and u is not None:
        lo, hi, chroma = shadow
        mean = acc / np.maximum(n, 1.0)[..., None]
        uu = (u * u).sum(-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            a = 1.0 + (mean * u).sum(-1) / uu
            cd = np.linalg.norm(mean - (a - 1.0)[..., None] * u, axis=-1) / np.sqrt(uu)
        target &= ~((uu > 0) & (a >= lo) & (a <= hi) & (cd <= chroma))
    return (packed + target).astype(np.uint8)


def foreground(
    frame: np.ndarray,
    bg0: np.ndarray,
    mad0: np.ndarray,
    bg1: np.ndarray,
    mad1: np.ndarray,
    w: float,
    threshold: float,
    soft_scale: float,
    noise_floor: float,
    shadow: bool,
    shadow_lo: float,
    shadow_hi: float,
    chroma_max: float,
    gain: np.ndarray | None = None,
    low_threshold: float | None = None,
    spread_cap: float = 0.0,
    shadow_edge_hi: float | None = None,
    radius: int = 0,
    nb_scale: float = 1.0,
    field: np.ndarray | None = None,
    veto: dict | None = None,
) -> dict[str, np.ndarray]:
    """Per-pixel ``z``, shadow flag, probability, level (0/1/2) and mask of ``(H, W, 3)`` uint8 images (module
    formulas), the frame divided by its ``(3,)`` channel ``gain`` first; ``low_threshold`` (default: ``threshold``)
    is the hysteresis threshold, ``spread_cap`` the largest noise scale (8-bit units, 0: none), ``shadow_edge_hi``
    (default ``shadow_hi``) the penumbra candidates' upper ratio. ``packed`` is the kernel's ``level + 4 shadow``;
    ``mask`` is :func:`wptrack.motion.levels.resolve_levels` of it (after :func:`neighbourhood` with ``radius`` and
    ``nb_scale`` when ``radius > 0``) for 2-D images, ``level == 2`` otherwise. ``field``: the ``(..., 3)`` local
    illumination gains the frame is divided by too (:func:`local_field`); ``veto``: the keyword arguments of
    :func:`illumination_change` but ``x`` and ``b`` (its pixels, tested where ``z > low_threshold`` and not a cast
    shadow, get shadow code 3: background)."""
    from wptrack.motion.levels import resolve_levels

    edge_hi = shadow_hi if shadow_edge_hi is None else shadow_edge_hi
    low = threshold if low_threshold is None else low_threshold
    b = (1.0 - w) * bg0.astype(np.float64) + w * bg1.astype(np.float64)
    m = (1.0 - w) * mad0.astype(np.float64) + w * mad1.astype(np.float64)
    x = frame.astype(np.float64) / (1.0 if gain is None else np.asarray(gain, dtype=np.float64))
    if field is not None:
        x = x / field
    spread = MAD_TO_SIGMA * np.sqrt((m * m).sum(-1) / 3.0)
    if spread_cap > 0:
        spread = np.minimum(spread, spread_cap)
    s = np.maximum(noise_floor, spread)
    z = np.sqrt(((x - b) ** 2).sum(-1) / 3.0) / s
    bb = (b * b).sum(-1)
    ib = (x * b).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(bb >= 1.0, ib / np.maximum(bb, 1.0), 0.0)
        cd = np.linalg.norm(x - a[..., None] * b, axis=-1) / np.sqrt(np.maximum(bb, 1.0))
    candidate = shadow & (bb >= 1.0) & (z > low) & (a >= shadow_lo) & (cd <= chroma_max)
    is_shadow = candidate & (a <= shadow_hi)
    penumbra = candidate & (a > shadow_hi) & (a <= edge_hi)
    illum = np.zeros_like(is_shadow)
    if veto is not None:
        illum = ~is_shadow & (z > low) & illumination_change(x=x, b=b, **veto)
        penumbra &= ~illum
    background = is_shadow | illum
    prob = np.where(background, 0.0, 1.0 / (1.0 + np.exp(-(z - threshold) / soft_scale)))
    level = np.where(background, 0, np.where(z > threshold, 2, np.where(z > low, 1, 0))).astype(np.uint8)
    packed = (level + 4 * (2 * is_shadow + penumbra + 3 * illum)).astype(np.uint8)
    diff = (x - b) / s[..., None]
    if level.ndim == 2:
        prob = prob.astype(np.float32)
        cast = (shadow_lo, shadow_hi, chroma_max) if shadow else None
        final = neighbourhood(packed, diff, radius, low, nb_scale, b / s[..., None], cast) if radius > 0 else packed
        mask = resolve_levels(final.copy(), prob).astype(bool)
    else:
        mask = level == 2
    return {
        "diff": diff, "z": z, "a": a, "cd": cd, "shadow": is_shadow, "penumbra": penumbra, "prob": prob, "level": level,
        "packed": packed, "mask": mask, "illum": illum,
    }  # fmt: skip


# ------------------------------------------------------------------------------------- local illumination changes

LOG_STEPS = 128.0 / np.log(4.0)
MIN_LEVEL = 16.0
KEEP_WEIGHT = 0.25


def luma(
    frame: np.ndarray,
    gain: np.ndarray,
    bg0: np.ndarray,
    mad0: np.ndarray,
    bg1: np.ndarray,
    mad1: np.ndarray,
    w: float,
    noise_floor: float,
    spread_cap: float = 0.0,
) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.background.luma_kernel` on ``(H, W, 3)`` images: ``(H, W, 3)`` float64
    ``(f, b, s)``."""
    b = (1.0 - w) * bg0.astype(np.float64) + w * bg1.astype(np.float64)
    m = (1.0 - w) * mad0.astype(np.float64) + w * mad1.astype(np.float64)
    spread = MAD_TO_SIGMA * np.sqrt((m * m).sum(-1) / 3.0)
    if spread_cap > 0:
        spread = np.minimum(spread, spread_cap)
    f = (frame.astype(np.float64) / np.asarray(gain, dtype=np.float64)).mean(-1)
    return np.stack([f, b.mean(-1), np.maximum(noise_floor, spread)], axis=-1)


def patch(lum: np.ndarray, radius: int) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.background.patch_rows_kernel` and :func:`patch_kernel` on an ``(H, W, 3)``
    :func:`luma` image: ``(H, W, 6)`` ``(ncc, gc, tex_b, tex_f, resid, gap)`` (patches clipped to the image)."""
    import cv2

    f, b, s = lum[..., 0], lum[..., 1], lum[..., 2]

    def grad(a: np.ndarray, axis: int) -> np.ndarray:
        n = a.shape[axis]
        lo, hi = np.clip(np.arange(n) - 1, 0, n - 1), np.clip(np.arange(n) + 1, 0, n - 1)
        step = np.maximum(hi - lo, 1).reshape((-1, 1) if axis == 0 else (1, -1))
        return (np.take(a, hi, axis=axis) - np.take(a, lo, axis=axis)) / step

    fx, fy, bx, by = grad(f, 1), grad(f, 0), grad(b, 1), grad(b, 0)
    k = (2 * radius + 1, 2 * radius + 1)

    def box(a: np.ndarray) -> np.ndarray:
        return cv2.boxFilter(a, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)

    n = box(np.ones_like(f))
    mf, mb = box(f) / n, box(b) / n
    vf = np.maximum(box(f * f) / n - mf * mf, 0.0)
    vb = np.maximum(box(b * b) / n - mb * mb, 0.0)
    cov = box(f * b) / n - mf * mb
    gdot, gff, gbb = box(fx * bx + fy * by), box(fx * fx + fy * fy), box(bx * bx + by * by)
    with np.errstate(divide="ignore", invalid="ignore"):
        ncc = np.where(vf * vb > 0, cov / np.sqrt(vf * vb), 0.0)
        gc = np.where(gff * gbb > 0, gdot / np.sqrt(gff * gbb), 0.0)
        alpha = np.where(vb > 0, cov / vb, 0.0)
    beta = mf - alpha * mb
    resid = np.sqrt(3.0) * np.abs(f - alpha * b - beta) / s
    with np.errstate(divide="ignore", invalid="ignore"):
        ok = (alpha > 0) & (mf > 0) & (mb > 0)
        gap = np.where(ok, np.minimum(np.abs(np.log(np.where(ok, alpha * mb / np.where(ok, mf, 1.0), 1.0))), 9.0), 9.0)
    return np.stack([ncc, gc, np.sqrt(3.0 * vb) / s, np.sqrt(3.0 * vf) / s, resid, gap], axis=-1)


def tile_gains(
    frame: np.ndarray,
    gain: np.ndarray,
    bg0: np.ndarray,
    bg1: np.ndarray,
    w: float,
    st: np.ndarray,
    tile: int,
    texture: float,
    verify_ncc: float,
    shadow: tuple[float, float, float] | None = None,
    resid: float = np.inf,
    gap: float = np.inf,
    chroma: float = np.inf,
) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.background.tile_gain_kernel`: ``(ty, tx, 4)`` float64 (log gains B, G, R,
    weight) of ``(H, W, 3)`` images and the ``(H, W, 6)`` :func:`patch` statistics ``st``; ``shadow``: the cast
    shadows' ``(lo, hi, chroma_max)``, whose pixels do not vote (None: they do); ``resid``, ``gap``, ``chroma``: the
    votes' bounds (``veto_resid``, ``gain_gap``, ``illum_chroma``)."""
    h, w_px = frame.shape[:2]
    ty, tx = -(-h // tile), -(-w_px // tile)
    step = max(1, (tile + 7) // 8)
    b = (1.0 - w) * bg0.astype(np.float64) + w * bg1.astype(np.float64)
    f = frame.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.clip(np.floor(LOG_STEPS * np.log(f / np.asarray(gain) / b) + 128.5), 0, 255)
    ok = (
        (st[..., 2] >= texture) & (st[..., 3] >= 0.5 * texture) & (st[..., 0] >= verify_ncc)
        & (st[..., 4] <= resid) & (st[..., 5] <= gap)
        & (b >= MIN_LEVEL).all(-1) & (f >= 1.0).all(-1) & (f <= 254.0).all(-1)
    )  # fmt: skip
    x = f / np.asarray(gain, dtype=np.float64)
    bb, ib = (b * b).sum(-1), (x * b).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = ib / bb
        cd = np.sqrt(np.maximum((x * x).sum(-1) - a * ib, 0.0) / bb)
    ok &= cd <= chroma
    if shadow is not None:
        ok &= ~((a >= shadow[0]) & (a <= shadow[1]) & (cd <= shadow[2]))
    out = np.zeros((ty, tx, 4))
    for i in range(ty):
        for j in range(tx):
            sl = (slice(i * tile, min((i + 1) * tile, h), step), slice(j * tile, min((j + 1) * tile, w_px), step))
            sel = ok[sl].reshape(-1)
            votes = q[sl].reshape(-1, 3)[sel][:64]
            if len(votes) >= 4:
                rank = (len(votes) - 1) // 2
                out[i, j, :3] = (np.sort(votes, axis=0)[rank] - 128.0) / LOG_STEPS
                out[i, j, 3] = len(votes) / sel.size
    return out


def tile_smooth(
    tiles: np.ndarray, radius: int, min_weight: float, keep: float = 0.0, dead: float = 0.0, widen: int = 0
) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.background.tile_smooth_kernel` on ``(ty, tx, 4)`` tiles: ``(ty, tx, 3)``
    lower weighted medians over the ``(2 radius + 1)^2`` neighbourhoods, widened up to ``widen`` times where the
    weight is below ``min_weight`` (0 where it stays below), or a voting tile's own gains within ``keep`` of them;
    0 where all within ``dead`` of 0."""
    ty, tx, _ = tiles.shape
    out = np.zeros((ty, tx, 3))
    for i in range(ty):
        for j in range(tx):
            r = radius
            for _ in range(widen + 1):
                step = max(1, (2 * r + 9) // 9)
                offs = np.arange(-(r // step), r // step + 1) * step
                ii, jj = i + offs, j + offs
                nb = tiles[np.ix_(ii[(ii >= 0) & (ii < ty)], jj[(jj >= 0) & (jj < tx)])].reshape(-1, 4)
                total = nb[:, 3].sum()
                if total >= min_weight:
                    break
                r = 2 * r + 1
            wts = nb[:, 3]
            if total < min_weight or total <= 0:
                continue
            for c in range(3):
                v = nb[:, c]
                below = np.array([wts[v <= x].sum() for x in v])
                cand = (wts > 0) & (below >= 0.5 * total)
                out[i, j, c] = v[cand].min()
            own = tiles[i, j]
            if keep > 0 and own[3] >= KEEP_WEIGHT and abs(own[:3].sum() - out[i, j].sum()) <= 3.0 * keep:
                out[i, j] = own[:3]
            if np.abs(out[i, j]).max() <= dead:
                out[i, j] = 0.0
    return out


def local_field(local: np.ndarray, tile: int, h: int, w: int) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.background.local_gain`: ``(H, W, 3)`` gains, the ``(ty, tx, 3)`` log gains
    interpolated bilinearly between the tile centres."""
    ty, tx, _ = local.shape
    v = (np.arange(h) + 0.5) / tile - 0.5
    u = (np.arange(w) + 0.5) / tile - 0.5
    j0 = np.clip(np.floor(v).astype(int), 0, ty - 1)
    i0 = np.clip(np.floor(u).astype(int), 0, tx - 1)
    j1, i1 = np.minimum(j0 + 1, ty - 1), np.minimum(i0 + 1, tx - 1)
    fv = np.clip(v - j0, 0.0, 1.0)[:, None, None]
    fu = np.clip(u - i0, 0.0, 1.0)[None, :, None]
    top = (1 - fu) * local[j0][:, i0] + fu * local[j0][:, i1]
    bottom = (1 - fu) * local[j1][:, i0] + fu * local[j1][:, i1]
    return np.exp((1 - fv) * top + fv * bottom)


def illumination_change(
    st: np.ndarray,
    x: np.ndarray,
    b: np.ndarray,
    texture: float,
    veto_ncc: float,
    veto_grad: float,
    resid: float,
    illum_lo: float,
    illum_hi: float,
    illum_chroma: float,
    gap: float = np.inf,
) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.background.illumination_change` (``x`` the compensated frame, ``b`` the
    background, ``(H, W, 3)`` float)."""
    corr = ((veto_ncc > 0) & (st[..., 0] >= veto_ncc)) | ((veto_grad > 0) & (st[..., 1] >= veto_grad))
    bb = (b * b).sum(-1)
    ib = (x * b).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(bb >= 1.0, ib / np.maximum(bb, 1.0), 0.0)
        cd = np.sqrt(np.maximum((x * x).sum(-1) - a * ib, 0.0) / np.maximum(bb, 1.0))
    return (
        (st[..., 2] >= texture) & (st[..., 3] >= 0.5 * texture) & (st[..., 4] <= resid) & (st[..., 5] <= gap)
        & corr & (bb >= 1.0)
        & (a >= illum_lo) & (a <= illum_hi) & (cd <= illum_chroma)
    )  # fmt: skip


def compensate(sample: np.ndarray, gain: np.ndarray, field: np.ndarray) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.background.compensate_kernel`: an ``(H, W, 3)`` uint8 sample divided by
    its global gain and its ``(H, W, 3)`` local field, rounded half up and clamped."""
    g = np.asarray(gain, dtype=np.float64) * field
    return np.clip(np.floor(sample.astype(np.float64) / g + 0.5), 0, 255).astype(np.uint8)


def sample_motion(
    stack: np.ndarray, gains: np.ndarray, width: int, height: int, radius: int, lag: int = 1
) -> np.ndarray:
    """Reference of :func:`wptrack.kernels.background.sample_change_kernel` then :func:`box_mean_kernel` along the
    rows and the columns: a ``(K, P)`` uint8 array, row ``r >= lag`` each pixel's patch mean of the largest channel
    change from sample ``r - lag`` to ``r`` (rows before zeros)."""
    k = stack.shape[0]
    g = np.asarray(gains, dtype=np.float64)[:, None, :]
    v = np.clip(np.floor(stack.reshape(k, -1, 3) / g + 0.5), 0, 255).astype(np.int64)  # (K, P, 3)
    change = np.zeros((k, height, width), dtype=np.int64)
    change[lag:] = np.abs(v[lag:] - v[:-lag]).max(axis=-1).reshape(k - lag, height, width)

    def box(a: np.ndarray, axis: int) -> np.ndarray:  # running mean along one axis, clipped window, half up
        n = a.shape[axis]
        c = np.cumsum(np.moveaxis(a, axis, -1), axis=-1)
        c = np.concatenate([np.zeros(c.shape[:-1] + (1,), dtype=np.int64), c], axis=-1)
        x = np.arange(n)
        lo, hi = np.maximum(x - radius, 0), np.minimum(x + radius, n - 1)
        total, count = c[..., hi + 1] - c[..., lo], hi - lo + 1
        return np.moveaxis((total + count // 2) // count, -1, axis)

    return box(box(change, 2), 1).reshape(k, -1).astype(np.uint8)


def mode(
    stack: np.ndarray,
    gains: np.ndarray,
    band: float,
    motion: np.ndarray | None = None,
    still: float = 0.0,
    lag: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Reference of :func:`wptrack.kernels.background.mode_kernel` on a ``(K, 3 P)`` uint8 stack (``motion``: the
    ``(K, P)`` of :func:`sample_motion` with the same ``lag``, read when ``still > 0``)."""
    k = stack.shape[0]
    g = np.asarray(gains, dtype=np.float64)[:, None, :]
    v = np.clip(np.floor(stack.reshape(k, -1, 3) / g + 0.5), 0, 255).astype(np.int64)  # (K, P, 3)
    weight = np.ones((k, v.shape[1]))
    if still > 0 and k > lag:
        m = np.full((k + lag, v.shape[1]), 256, dtype=np.int64)  # m[r]: change into sample r from r - lag (if any)
        m[lag:k] = motion[lag:k]
        weight = np.where(np.minimum(m[:k], m[lag:]) <= still, 1.0, 0.125)
        r = np.arange(k)
        weight[(r < lag) & (r + lag >= k)] = 1.0  # no sample lag away: no evidence either way
    dist = np.abs(v[:, None] - v[None, :]).max(axis=-1)  # (K, K, P): dist[j, k]
    counts = ((dist <= band) * weight[:, None, :]).sum(axis=0)  # (K, P) weight of the samples near sample k
    best = np.argmax(counts, axis=0)  # first of the largest
    near = np.take_along_axis(dist, best[None, None, :], axis=1)[:, 0, :] <= band  # (K, P)
    median = np.zeros(v.shape[1:], dtype=np.int64)
    for p in range(v.shape[1]):
        kept = np.sort(v[near[:, p], p], axis=0)
        median[p] = kept[(len(kept) - 1) // 2]
    dev = np.sort(np.abs(v - median[None]), axis=0)[(k - 1) // 2]
    return median.reshape(-1).astype(np.uint8), dev.reshape(-1).astype(np.uint8)
