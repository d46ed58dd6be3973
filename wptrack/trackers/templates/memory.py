"""Device memory of the S3 template tracker: bytes per particle and object slot, and the check made before anything
is allocated (``--max-objects`` or ``--particles`` beyond the device's free memory is one clear error that names the
limits)."""

from __future__ import annotations

from wptrack.core import memory as core_memory
from wptrack.core.errors import ConfigError
from wptrack.core.memory import check_fits
from wptrack.core.resampling import bytes_per_particle
from wptrack.kernels.templates import raster as kraster

SLOT_STATE_BYTES = (
    2 * (4 + 4 + 8 + 8 + 4 + 12 + 4) + int(kraster.PIECES) * (int(kraster.HULL_MAX) * 8 + 4 + 8 + 4) + 4  # + occlusion
)
"""Device bytes per object slot of a particle: two ping-pong state buffers and the piece hulls."""
PARTICLE_BYTES = 2 * 4 + 4 + 4 + 4 + 8 + 8
"""Device bytes per particle besides the slots: log-weights (2), penalty, complexity, ancestor, weight, XOR sums."""
PARTITION_SLOT_BYTES = 8 + 4 + 4 + 8 + 8
"""Device bytes per slot and particle of the partitioned filter (``TemplateConfig.partition``), besides the joint
filter's: a weight (float64), an ancestor, a log-factor and an exact CDF entry (int64) per group (a group per slot at
most), and the group sums (two int32)."""


def particle_bytes(max_objects: int, scheme: str, partition: bool = False) -> int:
    """Device memory per particle of the template tracker, bytes."""
    extra = max_objects * PARTITION_SLOT_BYTES if partition else 0
    return max_objects * SLOT_STATE_BYTES + PARTICLE_BYTES + extra + bytes_per_particle(scheme)  # float64 weights


def check_template_fits(n: int, r: int, scheme: str, partition: bool, fixed: int, device: str) -> None:
    """Raise ConfigError before any allocation when ``n`` particles of ``r`` object slots (``particle_bytes``) and
    ``fixed`` bytes of images do not fit in the device's free memory (``wptrack.core.memory.check_fits``: a 10 %
    margin); the message names ``max_objects`` and ``particles`` and gives the largest R_max that fits at ``n``
    particles and the most particles that fit at ``r`` slots."""
    try:
        check_fits(n, particle_bytes(r, scheme, partition), fixed, device, what="template tracker particles")
    except ConfigError:
        free = core_memory.available_bytes(device)  # the module's: tests pretend less memory
        usable = int(0.9 * free) - fixed
        fit_r = 0
        while fit_r < r and n * particle_bytes(fit_r + 1, scheme, partition) <= usable:
            fit_r += 1
        fit_n = max(usable, 0) // particle_bytes(r, scheme, partition)
        need = n * particle_bytes(r, scheme, partition) + fixed
        limit = (
            f"max_objects {fit_r} at {n} particles, or {fit_n} particles at max_objects {r}"
            if fit_r > 0  # else "max_objects 0" would be named as a limit: no object at all fits at n particles
            else f"{fit_n} particles at max_objects {r} (not even max_objects 1 fits at {n} particles)"
        )
        raise ConfigError(
            f"max_objects: {r} objects x {n} particles need {need / 2**30:.2f} GiB on {device} but only "
            f"{free / 2**30:.2f} GiB is free; the limit here is {limit}"
        ) from None
