"""Motion kernels draw by draw against a NumPy Philox (test_kernels_motion checks only their statistics), on every
device: ``gaussian_walk_kernel`` (eqs. 1-3: the resampled parent plus sigma times the first three Box-Muller normals
of the (seed, i, frame, STREAM_MOTION) block) and ``init_box_kernel`` (uniform in [lo, hi] from the
(seed, i, 0, STREAM_INIT) block)."""

from __future__ import annotations

import kernel_harness as harness
import numpy as np
import warp as wp
from kernel_refs import normal4_ref, uniform4_ref

from wptrack.kernels.colour import walk as kmotion
from wptrack.kernels.core import random as krand


def test_gaussian_walk_matches_numpy_philox(device, rng):
    n, sigma, seed, frame = 3000, 0.07, (9, 4), 12
    base = rng.uniform(-2, 2, (n, 3)).astype(np.float32)
    anc = rng.integers(0, n, n).astype(np.int32)
    out = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(
        harness.gaussian_walk_kernel,
        dim=n,
        inputs=[
            wp.array(base, dtype=wp.vec3, device=device),
            wp.array(anc, dtype=wp.int32, device=device),
            wp.array([sigma], dtype=wp.float32, device=device),
            wp.vec2ui(*seed),
            wp.array([frame], dtype=wp.int32, device=device),
        ],
        outputs=[out],
        device=device,
    )
    z = normal4_ref(seed, n, frame, int(krand.STREAM_MOTION))
    ref = base.astype(np.float64)[anc] + np.float32(sigma) * z[:, :3]
    np.testing.assert_allclose(out.numpy(), ref, rtol=0, atol=3e-6)


def test_init_box_matches_numpy_philox(device):
    n, seed = 3000, (1, 2)
    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([1.0, 0.5, 2.1])
    out = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(
        kmotion.init_box_kernel,
        dim=n,
        inputs=[wp.vec3(*lo.tolist()), wp.vec3(*hi.tolist()), wp.vec2ui(*seed)],
        outputs=[out],
        device=device,
    )
    u = uniform4_ref(seed, n, 0, int(krand.STREAM_INIT))[:, :3]
    np.testing.assert_allclose(out.numpy(), lo + (hi - lo) * u, rtol=0, atol=1e-6)
