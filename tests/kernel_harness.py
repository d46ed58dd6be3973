"""Warp kernels that exist only to test the library's ``@wp.func`` functions from the host: each launches one
function over arrays so a test can compare it with its NumPy reference (the library launches these functions inside
its fused kernels, never alone)."""

from __future__ import annotations

import warp as wp

from wptrack.kernels.colour.blobs import candidate, keep_candidate, rank_candidate, select_blob
from wptrack.kernels.colour.hsi import HALF_WINDOW, ColourTarget
from wptrack.kernels.colour.proposal import (
    camera_centre,
    jump_sample,
    pixel_ray_direction,
    ray_pair_midpoint,
)
from wptrack.kernels.colour.scoring import colour_log_likelihood
from wptrack.kernels.colour.walk import STREAM_MOTION, gaussian_walk
from wptrack.kernels.core.camera import Camera, project
from wptrack.kernels.core.random import normal4
from wptrack.kernels.core.reduce import moments_push, moments_store, moments_zero
from wptrack.kernels.people.coverage import PersonTerms, person_log_terms
from wptrack.kernels.people.descriptor import (
    alpha_h,
    alpha_s,
    appearance_log_prob,
    rgb_to_hsv,
)
from wptrack.kernels.people.filter import motion_log_likelihood
from wptrack.kernels.people.occupancy import INV_SQRT_2PI_CUBED


@wp.kernel
def project_kernel(
    cams: wp.array(dtype=Camera),
    points: wp.array(dtype=wp.vec3),
    out: wp.array2d(dtype=wp.vec3),
):
    """Project ``points`` (N,) into every camera; ``out`` (M, N) holds (u, v, depth) as in ``project``."""
    c, i = wp.tid()
    out[c, i] = project(cams[c], points[i])


@wp.kernel
def block_partials_kernel(
    logw: wp.array(dtype=wp.float32),
    particles: wp.array(dtype=wp.vec3),
    n: int,
    chunk: int,
    part_max: wp.array(dtype=wp.float32),
    part_arg: wp.array(dtype=wp.int32),
    part: wp.array2d(dtype=wp.float64),
):
    """Per-block max, MAP index and weighted sums (see :func:`moments_store`) of existing particles, in one pass.

    The trackers fuse the same accumulation into their predict + score kernels. Launch with
    ``wp.launch_tiled(dim=[blocks], block_dim=B)``.
    """
    b, lane = wp.tid()
    start = b * chunk
    stop = wp.min(start + chunk, n)
    best, arg, sw, sw2, sx, sxx = moments_zero()
    for i in range(start + lane, stop, wp.block_dim()):
        best, arg, sw, sw2, sx, sxx = moments_push(best, arg, sw, sw2, sx, sxx, logw[i], i, particles[i])
    moments_store(b, lane, best, arg, sw, sw2, sx, sxx, part_max, part_arg, part)


@wp.kernel
def colour_score_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    points: wp.array(dtype=wp.vec3),
    loglik: wp.array(dtype=wp.float32),
):
    """Log-likelihood of every point (eqs. 5-7), without prediction."""
    i = wp.tid()
    loglik[i] = colour_log_likelihood(cams, target, bgr, integral, window, mode, points[i])


@wp.kernel
def gaussian_walk_kernel(
    particles: wp.array(dtype=wp.vec3),
    ancestors: wp.array(dtype=wp.int32),
    sigma: wp.array(dtype=wp.float32),
    seed: wp.vec2ui,
    frame: wp.array(dtype=wp.int32),
    out: wp.array(dtype=wp.vec3),
):
    """Resampled gather + gaussian walk: ``out[i] = particles[ancestors[i]] + N(0, sigma[0])``."""
    i = wp.tid()
    out[i] = gaussian_walk(particles[ancestors[i]], sigma[0], seed, i, frame[0])


@wp.kernel
def window_from_mask_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    window: wp.array(dtype=wp.uint8),
):
    """The 5x5 window-count map straight from the target mask (25 reads per pixel, all from cache on a GPU; no
    integral image). Launch (M, max H, max W); flat like the mask."""
    c, py, px = wp.tid()
    cam = cams[c]
    if py >= cam.height or px >= cam.width:
        return
    m = int(0)
    for dy in range(-HALF_WINDOW, HALF_WINDOW + 1):
        y = py + dy
        if y >= 0 and y < cam.height:
            row = cam.pixel_offset + y * cam.width
            for dx in range(-HALF_WINDOW, HALF_WINDOW + 1):
                x = px + dx
                if x >= 0 and x < cam.width:
                    m += int(mask[row + x])
    window[cam.pixel_offset + py * cam.width + px] = wp.uint8(m)


@wp.kernel
def ray_pair_kernel(
    cams: wp.array(dtype=Camera),
    cam_a: wp.array(dtype=wp.int32),
    cam_b: wp.array(dtype=wp.int32),
    uv_a: wp.array(dtype=wp.vec2),
    uv_b: wp.array(dtype=wp.vec2),
    out: wp.array(dtype=wp.vec4),
):
    """Triangulate pixel pairs (tests): ``out[i]`` = :func:`ray_pair_midpoint` of the rays through ``uv_a[i]`` in
    camera ``cam_a[i]`` and ``uv_b[i]`` in camera ``cam_b[i]``."""
    i = wp.tid()
    ca = cams[cam_a[i]]
    cb = cams[cam_b[i]]
    out[i] = ray_pair_midpoint(
        camera_centre(ca),
        pixel_ray_direction(ca, uv_a[i][0], uv_a[i][1]),
        camera_centre(cb),
        pixel_ray_direction(cb, uv_b[i][0], uv_b[i][1]),
    )


@wp.kernel
def jump_sample_kernel(
    parents: wp.array(dtype=wp.vec3),
    seed: wp.vec2ui,
    frame: int,
    sigma: float,
    threshold: float,
    uniform: int,
    lo: wp.vec3,
    hi: wp.vec3,
    det_pos: wp.array(dtype=wp.vec3),
    det_cum: wp.array(dtype=wp.float32),
    count: int,
    sigma_d: float,
    out: wp.array(dtype=wp.vec3),
):
    """:func:`jump_sample` per point, with the filter's own motion normals (tests)."""
    i = wp.tid()
    z = normal4(seed, i, frame, STREAM_MOTION)
    out[i] = jump_sample(
        parents[i], z, seed, i, frame, sigma, threshold, uniform, lo, hi, det_pos, det_cum, count, sigma_d
    )


@wp.kernel
def blob_select_kernel(
    part_score: wp.array3d(dtype=wp.float32),
    part_index: wp.array3d(dtype=wp.int32),
    part_uv: wp.array3d(dtype=wp.vec2),
    blobs: int,
    blob_score: wp.array2d(dtype=wp.float32),
    blob_uv: wp.array2d(dtype=wp.vec2),
):
    """The ``blobs`` best peaks of each camera, key descending, into ``blob_*[c, 0:blobs]``: blob score (the 3 x 3
    count; 0: empty slot) and centre. Launch (M, chunks, PEAK_KEEP): one thread per peak entry writes it to the slot
    of its rank (the number of its camera's entries with a higher key, or the same key and a lower sub-block index)
    when that is < ``blobs``; thread (c, 0, 0) empties the slots from the camera's number of peaks on (disjoint from
    the ranked ones)."""
    c, k, r = wp.tid()
    select_blob(c, k, r, part_score, part_index, part_uv, blobs, blob_score, blob_uv)


@wp.kernel
def candidates_kernel(
    cams: wp.array(dtype=Camera),
    target: ColourTarget,
    bgr: wp.array(dtype=wp.uint8),
    integral: wp.array(dtype=wp.int32),
    window: wp.array(dtype=wp.uint8),
    mode: int,
    blob_score: wp.array2d(dtype=wp.float32),
    blob_uv: wp.array2d(dtype=wp.vec2),
    pair_a: wp.array(dtype=wp.int32),
    pair_b: wp.array(dtype=wp.int32),
    gate_px: float,
    lo: wp.vec3,
    hi: wp.vec3,
    cand_pos: wp.array(dtype=wp.vec3),
    cand_score: wp.array(dtype=wp.float32),
):
    """One thread per (pair p, blob i of camera ``pair_a[p]``, blob j of camera ``pair_b[p]``), flat index
    ``(p B + i) B + j`` with ``B = blob_score.shape[1]``; launch ``len(cand_pos)`` threads (P B^2). Writes the
    triangulated point and its mode-test score (``proposal.mode_log_likelihood``), or score ``LOG_ZERO`` when a blob
    slot is empty, the rays do not meet in front of both cameras, the point lies outside [lo, hi] or reprojects more
    than ``gate_px`` from either blob centre."""
    t = wp.tid()
    candidate(
        t,
        cams,
        target,
        bgr,
        integral,
        window,
        mode,
        blob_score,
        blob_uv,
        pair_a,
        pair_b,
        gate_px,
        lo,
        hi,
        cand_pos,
        cand_score,
    )


@wp.kernel
def candidate_keep_kernel(
    cand_pos: wp.array(dtype=wp.vec3),
    cand_score: wp.array(dtype=wp.float32),
    radius: float,
    keep: wp.array(dtype=wp.int32),
):
    """Non-maximum suppression: ``keep[t] = 1`` when candidate t is valid and no valid candidate ranking before it
    lies within ``radius`` metres. One thread per candidate."""
    keep_candidate(wp.tid(), cand_pos, cand_score, radius, keep)


@wp.kernel
def candidate_rank_kernel(
    cand_pos: wp.array(dtype=wp.vec3),
    cand_score: wp.array(dtype=wp.float32),
    keep: wp.array(dtype=wp.int32),
    det_pos: wp.array(dtype=wp.vec3),
    det_score: wp.array(dtype=wp.float32),
):
    """The ``K = len(det_pos)`` best kept candidates, score descending, into the detection slots; slots beyond the
    number kept get score ``LOG_ZERO``. One thread per candidate (at least K threads: thread t < K also checks
    whether slot t stays empty)."""
    rank_candidate(wp.tid(), cand_pos, cand_score, keep, det_pos, det_score)


@wp.kernel
def normal_kernel(
    seed: wp.vec2ui,
    frame: int,
    stream: int,
    out: wp.array2d(dtype=wp.float32),
):
    """N(0, 1) draws for indices ``0..N-1`` (tests). ``out``: (N, 4)."""
    i = wp.tid()
    z = normal4(seed, i, frame, stream)
    for k in range(4):
        out[i, k] = z[k]


@wp.kernel
def hsv_planes_kernel(
    bgr: wp.array(dtype=wp.uint8),
    h: wp.array(dtype=wp.float32),
    s: wp.array(dtype=wp.float32),
    v: wp.array(dtype=wp.float32),
):
    """H, S, V planes of flat BGR frames (all cameras back to back, ``Camera.pixel_offset``): launch one thread per
    pixel (total pixels of the rig). ``bgr`` (3 P,) uint8; outputs (P,) float32 in the units of :func:`rgb_to_hsv`."""
    p = wp.tid()
    o = 3 * p
    scale = 1.0 / 255.0
    hsv = rgb_to_hsv(float(bgr[o + 2]) * scale, float(bgr[o + 1]) * scale, float(bgr[o]) * scale)
    h[p] = hsv[0]
    s[p] = hsv[1]
    v[p] = hsv[2]


@wp.kernel
def alpha_kernel(rgb: wp.array(dtype=wp.vec3), sigma_n: float, out: wp.array(dtype=wp.vec2)):
    """(alpha_S, alpha_H) of each colour (tests and diagnostics)."""
    i = wp.tid()
    out[i] = wp.vec2(alpha_s(rgb[i], sigma_n), alpha_h(rgb[i], sigma_n))


@wp.kernel
def appearance_kernel(
    model: wp.array2d(dtype=wp.float32),
    desc: wp.array2d(dtype=wp.float32),
    mass: wp.array(dtype=wp.float32),
    mean_rgb: wp.array(dtype=wp.vec3),
    n_bins: int,
    sigma_n: wp.array(dtype=wp.float32),
    sigma_p: float,
    logp: wp.array(dtype=wp.float32),
):
    """log p(A_t | x_t) of every particle (eqs. 23-26): ``model`` (N, 3 N_b) predicted C_t, ``desc`` (N, 3 N_b)
    observed A_t with ``mass``, ``mean_rgb`` from :func:`descriptor_kernel`; ``sigma_n[0]`` from
    :func:`noise_sigma_kernel`. ``logp`` (N,) out."""
    i = wp.tid()
    logp[i] = appearance_log_prob(model, i, desc, i, mass[i], mean_rgb[i], n_bins, sigma_n[0], sigma_p)


@wp.kernel
def motion_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    p_b: float,
    log_outside: float,
    drop_worst: int,
    points: wp.array(dtype=wp.vec3),
    loglik: wp.array(dtype=wp.float32),
):
    """log p(M_t | x_t) of every point (eqs. 7-10); see :func:`motion_log_likelihood`. ``loglik`` (N,) out."""
    i = wp.tid()
    loglik[i] = motion_log_likelihood(cams, mask, p_b, log_outside, drop_worst, points[i])


@wp.kernel
def observation_kernel(
    cams: wp.array(dtype=Camera),
    mask: wp.array(dtype=wp.uint8),
    p_b: float,
    log_outside: float,
    drop_worst: int,
    points: wp.array(dtype=wp.vec3),
    model: wp.array2d(dtype=wp.float32),
    desc: wp.array2d(dtype=wp.float32),
    mass: wp.array(dtype=wp.float32),
    mean_rgb: wp.array(dtype=wp.vec3),
    n_bins: int,
    sigma_n: wp.array(dtype=wp.float32),
    sigma_p: float,
    box_cams: wp.array(dtype=Camera),
    integral: wp.array(dtype=wp.int32),
    others: wp.array(dtype=wp.vec2),
    alive: wp.array(dtype=wp.int32),
    boxes: wp.array2d(dtype=wp.vec4),
    own: int,
    terms: PersonTerms,
    loglik: wp.array(dtype=wp.float32),
):
    """log p(z_t | x_t) = log p(M_t | x_t) + log p(A_t | x_t) (eq. 11) of every particle, plus the person-level terms
    (ours: ``coverage.person_log_terms`` with the masks' integral images ``integral`` of the cameras ``box_cams``
    (the rig at the integral's reduced size, ``coverage.downsample_mask_kernel``), the other people's ground
    positions ``others``/``alive`` and this person's slot ``own``); the descriptor (``desc``, ``mass``,
    ``mean_rgb``) must have been computed at ``points`` by ``descriptor.descriptor_kernel``."""
    i = wp.tid()
    x = points[i]
    lm = motion_log_likelihood(cams, mask, p_b, log_outside, drop_worst, x)
    la = appearance_log_prob(model, i, desc, i, mass[i], mean_rgb[i], n_bins, sigma_n[0], sigma_p)
    loglik[i] = lm + la + person_log_terms(box_cams, integral, others, alive, boxes, own, terms, x)


@wp.kernel
def occupancy_hashgrid_kernel(
    hash_grid: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    logw: wp.array(dtype=wp.float32),
    log_norm: wp.array(dtype=wp.float64),
    sigma: float,
    cutoff: float,
    origin: wp.vec3,
    voxel: float,
    grid: wp.array3d(dtype=wp.float32),
):
    """:func:`occupancy_kernel` with the particles found by a ``wp.HashGrid`` query (``hash_grid``: the id of a
    grid built on ``points`` with radius >= cutoff sigma): O(V k) instead of O(V N) for k particles within the
    cutoff. Still a gather (no atomics): the query visits cells and the sorted points in a fixed order, so the result
    is reproducible for a given point set; it equals the brute-force kernel up to float32 summation order."""
    ix, iy, iz = wp.tid()
    xv = origin + voxel * wp.vec3(float(ix) + 0.5, float(iy) + 0.5, float(iz) + 0.5)
    rmax = cutoff * sigma
    r2max = rmax * rmax
    inv2s2 = 0.5 / (sigma * sigma)
    ln = log_norm[0]
    acc = float(0.0)
    query = wp.hash_grid_query(hash_grid, xv, rmax)
    i = int(0)
    while wp.hash_grid_query_next(query, i):
        d = xv - points[i]
        d2 = wp.dot(d, d)
        if d2 <= r2max:
            acc += wp.float32(wp.exp(wp.float64(logw[i]) - ln)) * wp.exp(-d2 * inv2s2)
    grid[ix, iy, iz] = acc * INV_SQRT_2PI_CUBED / (sigma * sigma * sigma)
