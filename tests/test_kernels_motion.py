"""Gaussian walk (eqs. 1-3) and initialisation kernels."""

from __future__ import annotations

import kernel_harness as harness
import numpy as np
import warp as wp

from wptrack.kernels.colour import walk as kmotion


def test_gaussian_walk_statistics_and_gather(device, rng):
    n = 40_000
    sigma = 0.03
    base = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    anc = rng.integers(0, n, n).astype(np.int32)
    out = wp.zeros(n, dtype=wp.vec3, device=device)
    args = [
        wp.array(base, dtype=wp.vec3, device=device),
        wp.array(anc, device=device),
        wp.array([sigma], dtype=wp.float32, device=device),
        wp.vec2ui(9, 0),
        wp.array([3], dtype=wp.int32, device=device),
    ]
    wp.launch(harness.gaussian_walk_kernel, dim=n, inputs=args, outputs=[out], device=device)
    step = out.numpy() - base[anc]
    # per axis: mean within 5 standard errors, std within 2 %
    assert np.all(np.abs(step.mean(0)) < 5 * sigma / np.sqrt(n))
    np.testing.assert_allclose(step.std(0), sigma, rtol=0.02)
    assert abs(np.corrcoef(step.T)[0, 1]) < 0.02
    # determinism and frame dependence
    out2 = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(harness.gaussian_walk_kernel, dim=n, inputs=args, outputs=[out2], device=device)
    np.testing.assert_array_equal(out.numpy(), out2.numpy())
    args[4] = wp.array([4], dtype=wp.int32, device=device)
    wp.launch(harness.gaussian_walk_kernel, dim=n, inputs=args, outputs=[out2], device=device)
    assert not np.any(np.all(out.numpy() == out2.numpy(), axis=1))


def test_init_kernels(device):
    n = 20_000
    out = wp.zeros(n, dtype=wp.vec3, device=device)
    wp.launch(kmotion.init_point_kernel, dim=n, inputs=[wp.vec3(0.4, 0.1, 0.2)], outputs=[out], device=device)
    np.testing.assert_allclose(out.numpy(), np.tile([0.4, 0.1, 0.2], (n, 1)), rtol=1e-7)
    lo, hi = np.array([-1.0, 0.0, 2.0]), np.array([1.0, 0.5, 2.1])
    wp.launch(
        kmotion.init_box_kernel,
        dim=n,
        inputs=[wp.vec3(*lo.tolist()), wp.vec3(*hi.tolist()), wp.vec2ui(1, 2)],
        outputs=[out],
        device=device,
    )
    p = out.numpy()
    assert np.all(p >= lo.astype(np.float32)) and np.all(p <= hi.astype(np.float32))
    # uniform: mean at the centre, variance (hi - lo)^2 / 12, within 3 %
    assert np.all(np.abs(p.mean(0) - (lo + hi) / 2) < 0.01 * (hi - lo))
    np.testing.assert_allclose(p.var(0), (hi - lo) ** 2 / 12, rtol=0.03)
