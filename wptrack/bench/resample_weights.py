"""Resampling alone on synthetic log-weights (``wptrack bench --tracker color --weights ordinary|concentrated``).

Times the colour tracker's resampling pass (systematic from float32 log-weights: the totals pass, the fused exact
scan + scatter and the long-range fill) at N particles on log-weights drawn once from N(0, sigma^2):

- ``ordinary``: sigma = 1 (ESS ~ N / e, the largest parent a few hundred children at 1e8);
- ``concentrated``: sigma = 5, the pathology of BENCHMARKS.md (one parent owning ~1e6 of 1e8 slots).

The timed path uses the long-range list with the GPU's threshold ``LONG_RANGE`` on every device (the CPU backend's
default is no list). The same weights go through a resampler whose threshold no range reaches (every range written
by its own thread: the scatter before the long-range fill, and the CPU default): its time is reported as
``serial_ms`` and its ancestors must equal the timed path's bit for bit; up to ``numpy_max`` particles both are also
checked against the NumPy reference.
"""

from __future__ import annotations

import time

import numpy as np

WEIGHT_SIGMAS = {"ordinary": 1.0, "concentrated": 5.0}
"""Standard deviation of the synthetic log-weights of each ``--weights`` case."""
SERIAL_FRAMES = 5
"""Timed calls of the serial reference path on a GPU (slow by design on concentrated weights); on the CPU it
alternates with the timed path, ``frames`` calls each."""


def _time_calls(call, count: int, device) -> list[float]:
    """Seconds of ``count`` calls of ``call``: CUDA events around each on a GPU; on the CPU, whose launches run
    synchronously on the calling thread, that thread's CPU time (a shared machine's load changes the wall clock by
    several times; the CPU time much less)."""
    import warp as wp

    if device.is_cuda:
        ev = [wp.Event(device, enable_timing=True) for _ in range(count + 1)]
        wp.record_event(ev[0])
        for k in range(count):
            call()
            wp.record_event(ev[k + 1])
        wp.synchronize_device(device)
        return [wp.get_event_elapsed_time(ev[k], ev[k + 1]) / 1000.0 for k in range(count)]
    out = []
    for _ in range(count):
        t0 = time.thread_time()
        call()
        out.append(time.thread_time() - t0)
    return out


def run_weights_case(n: int, device: str, weights: str, frames: int = 50, numpy_max: int = 100_000, seed: int = 0):
    """Time systematic resampling from synthetic log-weights at ``n`` particles (see the module docstring).

    Returns:
        dict with ``resample_ms`` (median per call), ``fill_ms`` (the long-range fill kernel alone, median),
        ``serial_ms`` (median of the serial path), ``long_ranges`` / ``long_slots`` (what the fill wrote),
        ``max_offspring``, ``ess``, ``equivalent`` (bit-identical to the serial path and, up to ``numpy_max``, to
        the NumPy reference).
    """
    import warp as wp

    from wptrack.core.resampling import LONG_RANGE, Resampler, offspring_counts
    from wptrack.kernels.core import reduce as kreduce
    from wptrack.kernels.core import resample as kres

    if weights not in WEIGHT_SIGMAS:
        raise ValueError(f"weights {weights!r}: expected one of {', '.join(WEIGHT_SIGMAS)}")
    dev = wp.get_device(device)
    rng = np.random.default_rng(seed)
    logw_np = rng.standard_normal(n, dtype=np.float32) * np.float32(WEIGHT_SIGMAS[weights])
    est_np = np.zeros(kreduce.EST_MAXLOGW + 1)
    est_np[kreduce.EST_MAXLOGW] = float(logw_np.max())
    logw = wp.array(logw_np, dtype=wp.float32, device=dev)
    est = wp.array(est_np, dtype=wp.float64, device=dev)
    anc = wp.zeros(n, dtype=wp.int32, device=dev)
    frame = wp.zeros(1, dtype=wp.int32, device=dev)
    seed_v = wp.vec2ui(seed & 0xFFFFFFFF, (seed >> 32) & 0xFFFFFFFF)
    slot = int(kreduce.EST_MAXLOGW)
    r = Resampler("systematic", n, dev, log_weights=True, long_range=LONG_RANGE)  # the GPU default, on any device
    serial = Resampler("systematic", n, dev, log_weights=True, long_range=n)

    def resample(res=r, out=anc):
        res.from_log_weights(logw, est, slot, seed_v, frame, out)

    anc_serial = wp.zeros(n, dtype=wp.int32, device=dev)
    resample()  # module load outside the timings
    resample(serial, anc_serial)
    wp.synchronize_device(dev)
    if dev.is_cpu:  # the two paths alternate, so that both see the same load of a shared machine
        times, serial_times = [], []
        for _ in range(frames):
            times += _time_calls(resample, 1, dev)
            serial_times += _time_calls(lambda: resample(serial, anc_serial), 1, dev)
    else:
        times = _time_calls(resample, frames, dev)
        serial_times = _time_calls(lambda: resample(serial, anc_serial), min(frames, SERIAL_FRAMES), dev)
    fill = _time_calls(lambda: r._fill_long(anc, r.blocks, n), frames, dev)  # idempotent: rewrites the same slots
    result_anc = anc.numpy()
    meta = r.long_meta.numpy()
    equivalent = bool(np.array_equal(result_anc, anc_serial.numpy()))
    if n <= numpy_max:
        q_dev = wp.zeros(n, dtype=wp.int64, device=dev)
        wp.launch(kres.quantised_weights_kernel, dim=n, inputs=[logw, est, slot, r.scale], outputs=[q_dev], device=dev)
        equivalent &= bool(np.array_equal(result_anc, _systematic_reference(q_dev.numpy(), seed_v, dev)))
    w = np.exp(logw_np.astype(np.float64) - float(logw_np.max()))
    return {
        "tracker": "color",
        "weights": weights,
        "particles": n,
        "device": dev.alias,
        "frames": frames,
        "resample_ms": 1e3 * float(np.median(times)),
        "fill_ms": 1e3 * float(np.median(fill)),
        "serial_ms": 1e3 * float(np.median(serial_times)),
        "long_ranges": int((meta >> 32).sum()),
        "long_slots": int((meta & 0xFFFFFFFF).sum()),
        "max_offspring": int(offspring_counts(result_anc, n).max()),
        "ess": float(w.sum() ** 2 / (w * w).sum()),
        "equivalent": equivalent,
    }


def _systematic_reference(q: np.ndarray, seed, device) -> np.ndarray:
    """NumPy systematic resampling on the exact integer CDF of ``q`` with the kernels' uniform of frame 0."""
    import warp as wp

    from wptrack.kernels.core import random as wrand

    words = wp.zeros((1, 4), dtype=wp.uint32, device=device)
    wp.launch(wrand.philox_kernel, dim=1, inputs=[seed, 0, wrand.STREAM_RESAMPLE], outputs=[words], device=device)
    u = (float(words.numpy()[0, 0]) + 0.5) * 2.0**-32
    n = len(q)
    c = np.cumsum(q)
    bounds = np.clip(np.floor(c.astype(np.float64) * (n / float(c[-1])) + u), 0, n).astype(np.int64)
    bounds[-1] = n
    return np.repeat(np.arange(n), np.diff(np.concatenate([[0], bounds])))


WEIGHTS_HEADER = "resampling alone on synthetic log-weights (ms per call; serial scatter: the reference path)"
"""The line above the ``--weights`` rows (the colour suite's table header does not describe them)."""


def format_weights_row(r: dict) -> str:
    """One line of the ``--weights`` benchmark."""
    eq = "yes" if r["equivalent"] else "NO"
    return (
        f"resample {r['weights']:12s} N={r['particles']:<10d} {r['resample_ms']:9.3f} ms/call (fill "
        f"{r['fill_ms']:.3f} ms; serial scatter {r['serial_ms']:.3f} ms)  long ranges {r['long_ranges']} "
        f"({r['long_slots']} slots), max offspring {r['max_offspring']}, ESS {r['ess']:.3g}, equal: {eq}"
    )
