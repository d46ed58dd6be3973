"""Device selection: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``."""

from __future__ import annotations

import logging
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

from wptrack.core.errors import DeviceError

if TYPE_CHECKING:
    import numpy as np

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


GPU_BLOCKS_PER_SM = (3, 8)
"""Block caps per SM of the reduction launches on a GPU, ``(up to GPU_FEW_BLOCKS_PARTICLES per thread, above)``:
3 blocks of 256 is what the fused predict + score kernel keeps resident per SM (72 registers on sm_90), so up to
~3e6 particles (H100) one full wave of blocks runs with no tail; above, 8 per SM balance the blocks' uneven finish
(colour tracker, 4 cameras, H100, graph frame by the cap of blocks: 1e6 0.099 ms at 3/SM, 0.132 at the old fixed
2048; 1e7 0.465 at 8/SM, 0.479 at 3/SM, 0.488 at 2048; 1e8 3.81 at 8/SM, 4.12 at 3/SM, 3.83 at 2048; a cap of 4
per SM, 1.33 waves, was slower than both; BENCHMARKS.md, issue 13, round six)."""
GPU_FEW_BLOCKS_PARTICLES = 32
"""Particles per thread up to which the reductions use the smaller cap of :data:`GPU_BLOCKS_PER_SM`."""


def block_partition(
    n: int, is_cpu: bool, block: int = 256, max_blocks: int = 2048, sm_count: int = 0
) -> tuple[int, int]:
    """``(blocks, chunk)``: block ``b`` of a tiled launch owns particles ``[b chunk, (b+1) chunk)``. On a GPU one
    block per ``block`` particles, at most ``max_blocks`` (more blocks only lengthen the final one-block passes) and,
    given the device's ``sm_count``, at most a whole number of waves (:data:`GPU_BLOCKS_PER_SM`); on the CPU one
    block per ``CPU_CHUNK`` particles."""
    per = CPU_CHUNK if is_cpu else block
    cap = max_blocks
    if not is_cpu and sm_count > 0:
        few, many = (k * sm_count for k in GPU_BLOCKS_PER_SM)
        cap = min(max_blocks, few if n <= few * block * GPU_FEW_BLOCKS_PARTICLES else many)
    blocks = max(1, min((n + per - 1) // per, cap))
    return blocks, (n + blocks - 1) // blocks


CPU_SPLIT_MIN = 256
"""Fewest particles per thread of a launch split over threads on the CPU backend (:class:`CpuSplit`)."""

CPU_SPLIT_MAX = 4
"""Most threads a split launch uses (the CI box has 2 cores; more rarely pays beside the run's other threads)."""


def cpu_split_threads(n: int) -> int:
    """Threads over which :class:`CpuSplit` runs a per-particle launch of ``n`` particles on the CPU backend: the
    environment variable ``WPTRACK_CPU_THREADS`` (1 turns the split off), else the cores this process may use
    (its CPU affinity), no more than a batch worker holds (``WPTRACK_DECODE_THREADS``, set by ``wptrack batch``);
    at most :data:`CPU_SPLIT_MAX`, with at least :data:`CPU_SPLIT_MIN` particles each."""
    import os

    from wptrack.io.decode import thread_budget

    env = os.environ.get("WPTRACK_CPU_THREADS", "").strip()
    cores = int(env) if env.isdigit() and int(env) > 0 else thread_budget()
    return max(1, min(cores, CPU_SPLIT_MAX, n // CPU_SPLIT_MIN))


class CpuSplit:
    """Run a launch over contiguous ranges of ``n`` items in several threads at once (the CPU backend runs a launch
    on one core; a launch is a ctypes call, which releases the GIL, so launches from several threads overlap).

    Only for plain ``wp.launch`` kernels whose outputs at item ``i`` depend on the inputs at ``i`` alone (launched on
    views ``a[lo:hi]``): the same results bit for bit. Not for ``wp.launch_tiled`` kernels: Warp's CPU tiles share one
    module-global shared-memory pointer (``wptrack.bench.cpu_threads``), so two tiled launches at once crash.

    Args:
        n: Items (particles).
        threads: Ranges run at once (the calling thread runs the first; :func:`cpu_split_threads`).

    ``split(fn)`` calls ``fn(k, lo, hi)`` for each range ``k`` and returns when all are done (an error of any is
    raised). ``ranges`` lists them.
    """

    def __init__(self, n: int, threads: int) -> None:
        from concurrent.futures import ThreadPoolExecutor

        threads = max(1, min(int(threads), int(n)))
        bounds = [(k * n) // threads for k in range(threads + 1)]
        self.ranges = [(bounds[k], bounds[k + 1]) for k in range(threads)]
        self._pool = ThreadPoolExecutor(threads - 1, thread_name_prefix="wptrack-split") if threads > 1 else None

    def __len__(self) -> int:
        return len(self.ranges)

    def __call__(self, fn) -> None:
        if self._pool is None:
            fn(0, *self.ranges[0])
            return
        futures = [self._pool.submit(fn, k, lo, hi) for k, (lo, hi) in enumerate(self.ranges) if k > 0]
        try:
            fn(0, *self.ranges[0])
        finally:
            for f in futures:
                f.result()

    def close(self) -> None:
        """Stop the threads (idempotent)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


def kernel_cache_dir() -> str:
    """Warp's kernel cache folder (``$WARP_CACHE_PATH`` when set, else ``~/.cache/warp/<version>``)."""
    import warp as wp

    init_warp()
    return str(wp.config.kernel_cache_dir)


def _module_cached(module, device, block_dim: int) -> bool:
    """Whether Warp's cache holds ``module``'s binary for ``device`` (private Warp API; False when unknown)."""
    import warp as wp
    from warp._src import context as ctx

    try:
        dim = ctx._resolve_launch_block_dim(device, block_dim)
        ident = module.get_module_identifier(dim)
        name = module._get_compile_output_name(device, block_dim=dim)
        return os.path.exists(os.path.join(wp.config.kernel_cache_dir, ident, name))
    except Exception:  # noqa: BLE001 - another Warp version: treat as not cached (we only say more)
        return False


def warm_up(
    modules: Sequence | None = None,
    device: str = "cpu",
    block_dim: int = 256,
    say: Callable[[str], None] | None = None,
) -> list[str]:
    """Load the Warp kernel modules before the first frame, compiling those missing from the kernel cache.

    Warp compiles a module on its first launch (seconds per module on the CPU), which would otherwise land in the
    first frame's time and make a progress bar show seconds per frame. When a module is not in the cache this says
    ``compiling kernels (first run only; cache: DIR) ...`` through ``say`` (default: ``log.info``) before compiling.
    The cache folder is ``$WARP_CACHE_PATH`` when set.

    Args:
        modules: Python modules (or names) holding Warp kernels; None: every ``wptrack.kernels.*`` module
            imported so far (those a tracker built by then uses).
        device: Warp device alias.
        block_dim: the launches' block size (``wp.launch_tiled`` uses 256 on CUDA; the CPU resolves to 1).
        say: called once with the message when something must be compiled.

    Returns:
        The names of the modules that were not in the cache (compiled now).
    """
    import warp as wp
    from warp._src import context as ctx

    init_warp()
    if modules is None:
        modules = sorted(m for m in sys.modules if m.startswith("wptrack.kernels."))  # every tracker kernel module
    names = [m if isinstance(m, str) else m.__name__ for m in modules]
    mods = [ctx.get_module(n) for n in names]
    d = wp.get_device(device)
    missing = [n for n, m in zip(names, mods, strict=True) if not _module_cached(m, d, block_dim)]
    if missing:
        (say or log.info)(f"compiling kernels (first run only; cache: {wp.config.kernel_cache_dir}) ...")
    t0 = time.perf_counter()
    for m in mods:
        wp.load_module(m, device=d, block_dim=block_dim)
    log.debug("kernels loaded on %s in %.2f s (compiled: %s)", d, time.perf_counter() - t0, ", ".join(missing) or "-")
    return missing


class DeviceGuard:
    """Keeps a CUDA graph capture apart from other threads' work on the same device.

    Warp's current stream is one per device, shared by every thread: a kernel, copy or allocation that another thread
    issues while a tracker captures its frame chain lands in the capture (silently part of the graph) or fails it
    ("Cannot synchronize stream while graph capture is active"). The motion masks run in threads beside the tracker
    (``wptrack track ... --video``, ``WPTRACK_MASK_WORKERS``), so their device work is *shared* (many threads at once)
    and a capture is *exclusive*: it waits for the shared sections in progress and holds new ones back until it ends
    (a capture waiting goes first, so steady mask work cannot starve it). Captures happen once per parity of a run.
    """

    def __init__(self) -> None:
        self._cond = threading.Condition()
        self._shared = 0
        self._exclusive = False
        self._waiting = 0
        self._local = threading.local()  # .depth: this thread's shared sections in progress

    @contextmanager
    def shared(self) -> Iterator[None]:
        """Device work that may run beside other shared work but never inside a capture."""
        with self._cond:
            self._cond.wait_for(lambda: not self._exclusive and not self._waiting)
            self._shared += 1
        self._local.depth = getattr(self._local, "depth", 0) + 1
        try:
            yield
        finally:
            self._local.depth -= 1
            with self._cond:
                self._shared -= 1
                self._cond.notify_all()

    @contextmanager
    def paused(self) -> Iterator[None]:
        """Inside this thread's shared sections, give them up while waiting for another thread's shared work (with
        no device work of this thread in flight): a capture waiting meanwhile must not hold that work back, or the
        two would wait for each other. Outside a shared section it does nothing."""
        depth = getattr(self._local, "depth", 0)
        if depth == 0:
            yield
            return
        with self._cond:
            self._shared -= depth
            self._cond.notify_all()
        self._local.depth = 0
        try:
            yield
        finally:
            with self._cond:
                self._cond.wait_for(lambda: not self._exclusive and not self._waiting)
                self._shared += depth
            self._local.depth = depth

    @contextmanager
    def exclusive(self) -> Iterator[None]:
        """A graph capture: no shared work runs on the device meanwhile (re-entrant use is not supported)."""
        with self._cond:
            self._waiting += 1
            try:
                self._cond.wait_for(lambda: not self._exclusive and not self._shared)
            finally:
                self._waiting -= 1
            self._exclusive = True
        try:
            yield
        finally:
            with self._cond:
                self._exclusive = False
                self._cond.notify_all()


_guards: dict[str, DeviceGuard] = {}
_guards_lock = threading.Lock()


def device_guard(device: object) -> DeviceGuard:
    """The process's :class:`DeviceGuard` of ``device`` (a Warp device or any name of it: ``cuda`` and ``cuda:0``
    are one device, one guard)."""
    import warp as wp

    key = wp.get_device(device).alias
    with _guards_lock:
        guard = _guards.get(key)
        if guard is None:
            guard = _guards[key] = DeviceGuard()
        return guard


def download(array: Any) -> np.ndarray:
    """A host copy of a Warp array that leaves the device's current stream alone (for threads beside a tracker).

    ``wp.array.numpy()`` of a CUDA array switches the device's one current stream to the null stream and back
    (``wp.ScopedStream``): two threads doing so at once can leave the device on the null stream, and the tracker's
    next graph capture then fails ("Warp error: unknown stream", H100, three mask threads). This copies on the stream
    current at the call and waits for that stream only.
    """
    import warp as wp

    if array.device.is_cpu:
        return array.numpy()
    stream = wp.get_stream(array.device)
    host = wp.empty(array.shape, dtype=array.dtype, device="cpu")
    wp.copy(host, array, stream=stream)
    wp.synchronize_stream(stream)
    return host.numpy()
