"""Motion models (prediction step).

S1 colour PF (Barrera et al., eqs. 1-3): a gaussian random walk with the same deviation sigma_m on x, y, z.
Noise comes from the counter-based stream ``(seed, particle, frame, STREAM_MOTION)`` so that a run is
reproducible on every device and under CUDA graph replay.
"""

import warp as wp

from wptrack.kernels.core.random import STREAM_INIT, STREAM_MOTION, normal4, uniform4

wp.set_module_options({"enable_backward": False})


@wp.func
def gaussian_walk(x: wp.vec3, sigma: float, seed: wp.vec2ui, index: int, frame: int):
    """x(t) = x(t-1) + N(0, sigma_m) per axis (eqs. 1-3); ``sigma`` in metres."""
    z = normal4(seed, index, frame, STREAM_MOTION)
    return x + sigma * wp.vec3(z[0], z[1], z[2])


@wp.kernel
def init_point_kernel(point: wp.vec3, out: wp.array(dtype=wp.vec3)):
    """All particles at one point (the paper's initialisation; the first prediction spreads them)."""
    out[wp.tid()] = point


@wp.kernel
def init_box_kernel(lo: wp.vec3, hi: wp.vec3, seed: wp.vec2ui, out: wp.array(dtype=wp.vec3)):
    """Particles uniform in the axis-aligned box [lo, hi] (metres)."""
    i = wp.tid()
    u = uniform4(seed, i, 0, STREAM_INIT)
    out[i] = wp.vec3(lo[0] + (hi[0] - lo[0]) * u[0], lo[1] + (hi[1] - lo[1]) * u[1], lo[2] + (hi[2] - lo[2]) * u[2])
