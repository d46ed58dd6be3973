"""S2 volumetric occupancy pdf (Lopez-Cifuentes et al., eqs. 2-3 and Figs. 6, 8): a 3D Gaussian kernel density of
the weighted particles on a voxel grid,

    p(x_v) = sum_i w_i N(x_v; P_i, sigma^2 I),   w_i = exp(logw_i - log sum_j exp(logw_j)),

truncated at ``cutoff`` sigma (terms with |x_v - P_i| > cutoff sigma are dropped; with cutoff 3 a lone particle keeps
P(chi^2_3 <= 9) = 97.1 % of its mass). The paper names the kernel but not its width; sigma is the caller's.

Grid: voxel (ix, iy, iz) has centre ``origin + (i + 1/2) * voxel`` (metres); the output is (nx, ny, nz) float32, in
1 / m^3. Layout choice: a gather, one thread per voxel looping over all particles, O(V N) work. It needs no atomics
and sums in particle order, so the result is bit-identical from run to run on every device. (A scatter, one thread
per particle adding into the ~(2 cutoff sigma / voxel)^3 voxels around it, does O(N k^3) work but its float32
atomic adds land in a scheduling-dependent order on CUDA, so the grid would change in the last bits between runs;
a hash-grid neighbour query per voxel would keep the gather deterministic at O(V k) if reports need large N.)
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

INV_SQRT_2PI_CUBED = wp.constant(0.06349363593424097)  # (2 pi)^(-3/2)


@wp.kernel
def occupancy_kernel(
    points: wp.array(dtype=wp.vec3),
    logw: wp.array(dtype=wp.float32),
    log_norm: wp.array(dtype=wp.float64),
    sigma: float,
    cutoff: float,
    origin: wp.vec3,
    voxel: float,
    grid: wp.array3d(dtype=wp.float32),
):
    """Occupancy density at every voxel centre (launch ``dim=(nx, ny, nz)``).

    Args:
        points: (N,) particle positions P_i, metres. logw: (N,) log-weights.
        log_norm: [0] = log sum_i exp(logw_i) (e.g. ``est[EST_LOGLIK] + log N`` from ``kernels.core.reduce``), so the
            weights sum to 1 and the grid integrates to ~1 (less the mass beyond the cutoff and outside the grid).
        sigma: kernel deviation, metres. cutoff: truncation radius in units of sigma.
        origin: corner of voxel (0, 0, 0), metres. voxel: edge length, metres.
        grid: (nx, ny, nz) out: density, 1 / m^3.
    """
    ix, iy, iz = wp.tid()
    xv = origin + voxel * wp.vec3(float(ix) + 0.5, float(iy) + 0.5, float(iz) + 0.5)
    r2max = cutoff * cutoff * sigma * sigma
    inv2s2 = 0.5 / (sigma * sigma)
    ln = log_norm[0]
    acc = float(0.0)
    for i in range(points.shape[0]):
        d = xv - points[i]
        d2 = wp.dot(d, d)
        if d2 <= r2max:
            acc += wp.float32(wp.exp(wp.float64(logw[i]) - ln)) * wp.exp(-d2 * inv2s2)
    grid[ix, iy, iz] = acc * INV_SQRT_2PI_CUBED / (sigma * sigma * sigma)


@wp.kernel
def log_norm_kernel(est: wp.array(dtype=wp.float64), loglik_slot: int, n: int, out: wp.array(dtype=wp.float64)):
    """``out[0] = est[loglik_slot] + log(n)``: log sum_i exp(logw_i) from a filter's estimate vector (its log mean
    weight, ``kernels.core.reduce.EST_LOGLIK``), for :func:`occupancy_kernel` without a host round trip. Launch dim
    1."""
    out[0] = est[loglik_slot] + wp.log(wp.float64(n))
