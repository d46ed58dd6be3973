"""Device selection: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``."""

from __future__ import annotations

import logging
import os
import sys
import tempfile

from .errors import DeviceError

log = logging.getLogger(__name__)

_NO_DRIVER = "Could not find or load the NVIDIA CUDA driver"
_driver_missing: bool | None = None  # set by init_warp when it saw Warp's "no CUDA driver" message
_said: set[str] = set()


def _say_once(message: str) -> None:
    """Log the device choice once per process (trackers resolve the already resolved alias again)."""
    if message not in _said:
        _said.add(message)
        log.info(message)


def quiet_warp(quiet: bool = True) -> None:
    """Silence Warp's start-up banner and kernel-cache messages (``quiet=False`` restores them)."""
    import warp as wp

    wp.config.quiet = quiet
    wp.config.log_level = wp.LOG_WARNING if quiet else wp.LOG_INFO


def init_warp() -> None:
    """Initialise Warp (idempotent), without its "no CUDA driver" noise on machines without a GPU.

    Warp's native library prints ``Warp CUDA warning: Could not find or load the NVIDIA CUDA driver`` from C
    straight to file descriptor 2 when ``libcuda`` cannot be loaded, whatever the device asked for. The first
    call captures descriptor 2 while Warp starts, drops that one line (it is logged at DEBUG level instead: a
    run says which device it used and why via :func:`resolve_device`) and writes everything else back to stderr.
    """
    global _driver_missing
    import warp as wp
    from warp._src import context

    if context.runtime is not None:
        return
    try:
        sys.stderr.flush()
        fd = sys.stderr.fileno() if hasattr(sys.stderr, "fileno") else 2
    except (OSError, ValueError):  # stderr replaced by an object without a descriptor (e.g. pytest capture)
        fd = 2
    with tempfile.TemporaryFile() as tmp:
        saved = os.dup(fd)
        try:
            os.dup2(tmp.fileno(), fd)
            try:
                wp.init()
            finally:
                os.dup2(saved, fd)
        finally:
            os.close(saved)
        tmp.seek(0)
        text = tmp.read().decode("utf-8", "replace")
    kept = []
    for line in text.splitlines(keepends=True):
        if _NO_DRIVER in line:
            _driver_missing = True
            log.debug("Warp: %s", line.strip())
        else:
            kept.append(line)
    if kept:
        sys.stderr.write("".join(kept))
        sys.stderr.flush()


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
        if cuda:
            _say_once(f"device {cuda[0]} (auto: first CUDA device)")
            return cuda[0]
        why = "no NVIDIA CUDA driver" if _driver_missing else "no CUDA device"
        _say_once(f"device cpu (auto: {why})")
        return "cpu"
    if spec == "cpu":
        _say_once("device cpu (asked for)")
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


CPU_CHUNK = 16384
"""Particles per block on the CPU backend, where a block is one lane running its chunk serially: few blocks keep
the per-block tile reductions and the final combination cheap (1e5 particles: 391 blocks of 256 made the fused
systematic pass 3.4 ms, 8 blocks 1.8 ms; measured on the CI box's CPU)."""


def block_partition(n: int, is_cpu: bool, block: int = 256, max_blocks: int = 2048) -> tuple[int, int]:
    """``(blocks, chunk)``: block ``b`` of a tiled launch owns particles ``[b chunk, (b+1) chunk)``. On a GPU one
    block per ``block`` particles, at most ``max_blocks`` (past ~2 blocks per SM more blocks only lengthen the final
    one-block passes); on the CPU one block per ``CPU_CHUNK`` particles."""
    per = CPU_CHUNK if is_cpu else block
    blocks = max(1, min((n + per - 1) // per, max_blocks))
    return blocks, (n + blocks - 1) // blocks
