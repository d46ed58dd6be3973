"""``reduce.increment_kernel`` on every device: the device frame counter that seeds the random streams advances by
one per launch (and only element 0), also when replayed from a captured CUDA graph, where a scalar argument would be
frozen."""

from __future__ import annotations

import numpy as np
import warp as wp

from wptrack.kernels import reduce as kreduce


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
