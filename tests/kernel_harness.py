"""Warp kernels that exist only to test the library's ``@wp.func`` functions from the host: each launches one
function over arrays so a test can compare it with its NumPy reference (the library launches these functions inside
its fused kernels, never alone)."""

from __future__ import annotations

import warp as wp

from wptrack.kernels.core.camera import Camera, project
from wptrack.kernels.core.reduce import moments_push, moments_store, moments_zero


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
