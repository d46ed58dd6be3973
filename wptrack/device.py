"""Device selection: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``."""

from __future__ import annotations

import logging

from .errors import DeviceError

log = logging.getLogger(__name__)


def quiet_warp(quiet: bool = True) -> None:
    """Silence Warp's start-up banner and kernel-cache messages (``quiet=False`` restores them)."""
    import warp as wp

    wp.config.quiet = quiet
    wp.config.log_level = wp.LOG_WARNING if quiet else wp.LOG_INFO


def init_warp() -> None:
    """Initialise Warp (idempotent)."""
    import warp as wp

    wp.init()


def resolve_device(spec: str | None = "auto") -> str:
    """Resolve a user's device string into a Warp device alias.

    Args:
        spec: ``"auto"`` (CUDA when available, else CPU), ``"cpu"``, ``"cuda"`` (the default CUDA device) or
            ``"cuda:N"``. ``None`` means ``"auto"``.

    Returns:
        A Warp device alias such as ``"cpu"`` or ``"cuda:0"``.

    Raises:
        DeviceError: CUDA was asked for but is not available, or the string is not a device.
    """
    import warp as wp

    init_warp()
    spec = (spec or "auto").strip().lower()
    cuda = [d.alias for d in wp.get_cuda_devices()]
    if spec == "auto":
        return cuda[0] if cuda else "cpu"
    if spec == "cpu":
        return "cpu"
    if spec == "cuda" or spec.startswith("cuda:"):
        if not cuda:
            raise DeviceError(f"device '{spec}': CUDA is not available on this machine (use --device cpu or auto)")
        if spec == "cuda":
            return cuda[0]
        if spec not in cuda:
            raise DeviceError(f"device '{spec}': no such CUDA device (available: {', '.join(cuda)})")
        return spec
    raise DeviceError(f"device '{spec}': expected auto, cpu, cuda or cuda:N")
