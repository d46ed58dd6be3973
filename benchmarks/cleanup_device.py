"""Issue 27: the motion masks' clean-up on the device (wptrack.motion.cleanup.DeviceCleanup) against the host
functions (resolve_levels + clean_mask: OpenCV morphology and connected components) on one synthetic 1920x1080 frame
of packed levels, per frame: the host path with the download of the packed levels and the upload of the mask it
costs, the device path (a fixed chain of launches, its hysteresis a union-find labelling). Same mask checked.

Run: ``python benchmarks/cleanup_device.py [--device cuda] [--size 1920x1080] [--repeats 50]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def main() -> None:
    import warp as wp
    from test_kernels_morphology import _packed  # the tests' structured levels (blobs, fringes, a serpentine)

    from wptrack.motion.cleanup import DeviceCleanup
    from wptrack.motion.levels import resolve_levels
    from wptrack.motion.masks import MaskConfig, clean_mask

    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--repeats", type=int, default=50)
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    wp.init()
    rng = np.random.default_rng(0)
    packed = _packed(rng, h, w)
    config = MaskConfig()
    d_packed = wp.array(packed, dtype=wp.uint8, device=a.device)
    d_mask = wp.zeros((h, w), dtype=wp.uint8, device=a.device)
    host = wp.zeros((h, w), dtype=wp.uint8, device="cpu", pinned=wp.get_device(a.device).is_cuda)
    clean = DeviceCleanup(w, h, config.open_px, config.close_px, a.device)
    got = clean(d_packed)  # compile, warm up
    expected = clean_mask(resolve_levels(packed.copy()), config)
    assert np.array_equal(got.numpy(), expected), "device and host masks differ"

    t0 = time.perf_counter()
    for _ in range(a.repeats):
        wp.copy(host, d_packed)  # download the packed levels
        wp.synchronize_device(a.device)
        m = clean_mask(resolve_levels(host.numpy().copy()), config)
        wp.copy(d_mask, wp.array(m, dtype=wp.uint8, device="cpu"))  # upload the mask for the tracker
    wp.synchronize_device(a.device)
    host_ms = 1000 * (time.perf_counter() - t0) / a.repeats
    t0 = time.perf_counter()
    for _ in range(a.repeats):
        clean(d_packed)
    wp.synchronize_device(a.device)
    dev_ms = 1000 * (time.perf_counter() - t0) / a.repeats
    print(f"{w}x{h} on {a.device}: host path {host_ms:.2f} ms/frame, device path {dev_ms:.2f} ms/frame; masks equal")


if __name__ == "__main__":
    main()
