"""The block partition of the reduction launches (``wptrack.core.device.block_partition``)."""

from __future__ import annotations

import pytest

from wptrack.core.device import CPU_CHUNK, GPU_BLOCKS_PER_SM, GPU_FEW_BLOCKS_PARTICLES, block_partition


@pytest.mark.parametrize("sms", [0, 46, 132])
@pytest.mark.parametrize("n", [1, 255, 256, 257, 10**3, 10**5, 10**6, 3 * 10**6, 4 * 10**6, 10**7, 10**8])
def test_partition_covers_every_particle_once(n, sms):
    for is_cpu in (False, True):
        blocks, chunk = block_partition(n, is_cpu, 256, 2048, sms)
        assert 1 <= blocks <= 2048
        assert chunk == -(-n // blocks)  # blocks own [b chunk, (b + 1) chunk): all n covered, the last may be short
        if is_cpu:
            assert blocks == -(-n // CPU_CHUNK) or blocks == 2048


def test_gpu_caps_are_whole_waves():
    few, many = GPU_BLOCKS_PER_SM
    sms = 132
    edge = few * sms * 256 * GPU_FEW_BLOCKS_PARTICLES
    assert block_partition(1000, False, 256, 2048, sms) == (4, 250)
    assert block_partition(10**6, False, 256, 2048, sms)[0] == few * sms
    assert block_partition(edge, False, 256, 2048, sms)[0] == few * sms
    assert block_partition(edge + 1, False, 256, 2048, sms)[0] == many * sms
    assert block_partition(10**8, False, 256, 2048, sms)[0] == many * sms
    assert block_partition(10**8, False, 256, 2048, 0)[0] == 2048  # no SM count: the fixed cap
    assert block_partition(10**8, False, 256, 2048, 400)[0] == 2048  # never past max_blocks
    counts = [block_partition(n, False, 256, 2048, sms)[0] for n in range(1, 5 * 10**6, 9973)]
    assert counts == sorted(counts)  # monotone in n: a resampler sized for a capacity covers smaller calls
