"""Device memory and particle counts checked before anything is allocated: a count that does not fit is refused with the
limit named (:func:`check_fits`), a count past the 32-bit index limit too (:func:`check_particles`)."""

from __future__ import annotations

import numpy as np
import warp as wp

from wptrack.core.errors import ConfigError
from wptrack.core.resampling import bytes_per_particle

POINT_STATE_BYTES = 2 * 12 + 2 * 4 + 4
"""Device bytes per particle of the point-particle state: positions (2 x vec3 ping-pong), log-weights (2 x
float32), ancestors (int32)."""


def resampler_bytes(scheme: str) -> int:
    """Device bytes per particle of a point filter's resampler (from log-weights): 0 for systematic (exact integer
    CDF, per-block totals only); float64 weights, CDF and scan scratch (+ residual buffers) for the others."""
    return bytes_per_particle(scheme, log_weights=True)


def available_bytes(device: str) -> int:
    """Free memory of a device: CUDA free memory, or the host's available physical memory for the CPU."""
    import os

    dev = wp.get_device(device)
    if dev.is_cuda:
        return int(dev.free_memory)
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 1 << 62


def check_fits(n: int, per_particle: int, fixed: int, device: str, what: str = "particles") -> None:
    """Raise ConfigError before allocating when ``n`` particles of ``per_particle`` bytes (plus ``fixed`` bytes)
    cannot fit in the device's free memory (a 10 % margin is kept for the runtime and scratch)."""
    need = n * per_particle + fixed
    free = available_bytes(device)
    usable = int(0.9 * free)
    if need > usable:
        limit = max(0, (usable - fixed) // per_particle)
        raise ConfigError(
            f"{what}: {n} particles need {need / 2**30:.2f} GiB on {device} ({per_particle} bytes each) but only "
            f"{free / 2**30:.2f} GiB is free; the limit here is about {limit} particles"
        )


def check_particles(n: int) -> int:
    """Validate a particle count (positive integer, below the 32-bit index limit)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n <= 0:
        raise ConfigError(f"particles: expected a positive integer, got {n!r}")
    if n >= 2**31 - 1:
        raise ConfigError(f"particles: {n} exceeds the limit of 2^31 - 2 particles")
    return int(n)
