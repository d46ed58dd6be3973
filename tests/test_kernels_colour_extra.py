"""``colour.colour_table_kernel`` against NumPy on every device: the 2^24-bit HSI colour table (one bit per 24-bit
colour, built once per target) agrees with the float64 HSI classification of test_kernels_colour on 2^18 random
colours per target plus the grey axis and the saturated edges of the RGB cube. Colours whose hue or saturation
lies within 1e-5 (relative to the range) of a threshold are excluded as float32 ties, except the saturations 0 and 1
and all intensities, which both sides compute exactly (an exact tie must be inside: the ranges
are closed). test_kernels_colour reads the table only through the ~5000 colours of its random frames."""

from __future__ import annotations

import numpy as np
import pytest
from test_kernels_colour import TARGETS, hsi_ref, match_ref


def table_bits(table: np.ndarray, rgb: np.ndarray) -> np.ndarray:
    """Bit of colour (r, g, b) (rows of ``rgb``, uint8) in the table: index r << 16 | g << 8 | b."""
    idx = (rgb[:, 0].astype(np.int64) << 16) | (rgb[:, 1].astype(np.int64) << 8) | rgb[:, 2].astype(np.int64)
    return ((table[idx >> 5] >> (idx & 31).astype(np.uint32)) & 1).astype(bool)


def sample_colours(rng) -> np.ndarray:
    """(K, 3) RGB: random colours, the grey axis, and every colour with one channel 0 and another 255."""
    v = np.arange(256)
    grey = np.repeat(v[:, None], 3, axis=1)
    edges = []
    for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1), (0, 2, 1), (1, 0, 2), (2, 1, 0)):
        e = np.zeros((256, 3), int)
        e[:, a], e[:, b], e[:, c] = 0, 255, v
        edges.append(e)
    return np.concatenate([rng.integers(0, 256, (1 << 18, 3)), grey, *edges]).astype(np.uint8)


@pytest.mark.parametrize("target", TARGETS)
def test_colour_table_matches_hsi_reference(device, rng, target):
    table = target.to_struct(device).table.numpy()
    rgb = sample_colours(rng)
    got = table_bits(table, rgb)
    bgr = rgb[:, ::-1]
    ref, _ = match_ref(bgr, target)
    h, sat, _ = hsi_ref(bgr)
    near = np.zeros(len(rgb), bool)
    for lim in target.hue:
        near |= np.abs(h - lim) < 360e-5
    for lim in target.sat:
        near |= (np.abs(sat - lim) < 1e-5) & (sat != 0) & (sat != 1)
    assert near.mean() < 0.01
    assert 0.005 < ref[~near].mean() < 0.995  # both classes present
    bad = np.flatnonzero((got != ref) & ~near)
    assert len(bad) == 0, f"{len(bad)} colours differ, e.g. RGB {rgb[bad[:5]].tolist()} table {got[bad[:5]].tolist()}"
    # grey (hue 0 by convention, saturation 0) never matches a target that needs saturation > 0
    grey = table_bits(table, np.repeat(np.arange(256, dtype=np.uint8)[:, None], 3, axis=1))
    assert not grey.any() or target.sat[0] <= 0.0
