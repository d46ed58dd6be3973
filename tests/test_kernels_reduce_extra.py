"""Reduction kernels not compared with NumPy elsewhere, on every device: ``block_max_kernel`` + ``final_max_kernel``
and ``single_max_kernel``, the same in one block (the max log-weight and the lowest index attaining it, as the
template tracker launches them; test_kernels_templates only reads the max back through the normalised weights) at
sizes that are not multiples of the block, with ties across blocks; and ``increment_kernel``: the device frame counter
that seeds the random streams advances by one per launch (and only element 0), also when replayed from a captured CUDA
graph, where a scalar argument would be frozen."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from wptrack.kernels.core import reduce as kreduce


def test_increment_counts_launches(device):
    counter = wp.array([41, 7], dtype=wp.int32, device=device)
    for expected in (42, 43, 44):
        wp.launch(kreduce.increment_kernel, dim=1, inputs=[counter], device=device)
        np.testing.assert_array_equal(counter.numpy(), [expected, 7])
    if wp.get_device(device).is_cuda:
        with wp.ScopedCapture(device=device) as capture:
            wp.launch(kreduce.increment_kernel, dim=1, inputs=[counter], device=device)
        for _ in range(3):
            wp.capture_launch(capture.graph)
        np.testing.assert_array_equal(counter.numpy(), [47, 7])


BLOCK = 256  # as wptrack.core.filter / the template tracker


def run_max(device, logw: np.ndarray, chunk: int):
    n = len(logw)
    blocks = (n + chunk - 1) // chunk
    pm = wp.full(blocks, 7.0, dtype=wp.float32, device=device)
    pa = wp.full(blocks, -7, dtype=wp.int32, device=device)
    est = wp.full(int(kreduce.EST_SIZE), 7.0, dtype=wp.float64, device=device)
    best = wp.full(1, -7, dtype=wp.int32, device=device)
    lw = wp.array(logw.astype(np.float32), dtype=wp.float32, device=device)
    wp.launch_tiled(
        kreduce.block_max_kernel, dim=[blocks], inputs=[lw, n, chunk], outputs=[pm, pa], block_dim=BLOCK, device=device
    )
    wp.launch_tiled(
        kreduce.final_max_kernel, dim=[1], inputs=[pm, pa, blocks], outputs=[est, best], block_dim=BLOCK, device=device
    )
    return pm.numpy(), pa.numpy(), est.numpy(), int(best.numpy()[0])


@pytest.mark.parametrize(("n", "chunk"), [(1, 256), (300, 256), (5000, 256), (70_001, 64)])
def test_block_and_final_max_match_numpy(device, rng, n, chunk):
    logw = rng.normal(-50.0, 10.0, n).astype(np.float32)
    if n > 10:
        top = logw.max() + 1.0
        ties = np.sort(rng.choice(n, 3, replace=False))
        logw[ties] = top  # the maximum, three times (in different blocks when n is large): the lowest index wins
        logw[rng.integers(0, n, 5)] = -np.inf  # never the maximum
    pm, pa, est, best = run_max(device, logw, chunk)
    for b in range(len(pm)):
        blk = logw[b * chunk : (b + 1) * chunk]
        assert pm[b] == blk.max() and pa[b] == b * chunk + int(np.argmax(blk == blk.max()))
    assert est[kreduce.EST_MAXLOGW] == np.float64(logw.max())
    assert best == int(np.argmax(logw == logw.max()))
    assert np.all(np.delete(est, kreduce.EST_MAXLOGW) == 7.0)  # no other entry written


@pytest.mark.parametrize("n", [1, 300, 4096])
def test_single_max_matches_two_passes(device, rng, n):
    """single_max_kernel (the template tracker's argmax up to SINGLE_MAX values, one block of 1024 threads): the
    maximum and the lowest index attaining it (ties, -inf entries), nothing else of ``est`` written; the same as
    block_max_kernel + final_max_kernel."""
    logw = rng.normal(-50.0, 10.0, n).astype(np.float32)
    if n > 10:
        logw[np.sort(rng.choice(n, 3, replace=False))] = logw.max() + 1.0
        logw[rng.integers(0, n, 5)] = -np.inf
    est = wp.full(int(kreduce.EST_SIZE), 7.0, dtype=wp.float64, device=device)
    best = wp.full(1, -7, dtype=wp.int32, device=device)
    wp.launch_tiled(
        kreduce.single_max_kernel,
        dim=[1],
        inputs=[wp.array(logw, dtype=wp.float32, device=device), n],
        outputs=[est, best],
        block_dim=1024,
        device=device,
    )
    got = est.numpy()
    assert got[kreduce.EST_MAXLOGW] == np.float64(logw.max())
    assert int(best.numpy()[0]) == int(np.argmax(logw == logw.max()))
    assert np.all(np.delete(got, kreduce.EST_MAXLOGW) == 7.0)
    _, _, est2, best2 = run_max(device, logw, 256)
    assert est2[kreduce.EST_MAXLOGW] == got[kreduce.EST_MAXLOGW] and best2 == int(best.numpy()[0])
