"""Particle resampling on device: multinomial, stratified, systematic and residual schemes chosen by name.

A :class:`Resampler` owns every temporary for up to ``capacity`` particles, so a call allocates nothing on the
device, never synchronises with the host and can be captured in a CUDA graph: the frame number and the optional ESS
trigger are read from device arrays inside the kernels.

Two inputs:
- float64 weights (``__call__``): float64 prefix sums (``wp.utils.array_scan``; a float32 CDF loses whole particles
  at N ~ 1e6), then a search or scatter kernel per scheme.
- float32 log-weights (``from_log_weights``, the particle filters' path; build with ``log_weights=True``):
  systematic resampling runs on an exact integer CDF (weights quantised to ``floor(exp(logw - max) 2^k)``, int64
  prefix sums in 20-bit limbs) fused with the scatter, with no per-particle temporary; the other schemes write the
  float64 weights first.

Offspring ranges longer than ``long_range`` slots (systematic and residual schemes, GPU default :data:`LONG_RANGE`)
are written by a follow-up fill kernel with all its threads, so one heavy parent does not serialise the scatter.

Example::

    resampler = make_resampler("systematic", capacity=n, device="cuda:0")
    resampler(weights, wp.vec2ui(seed & 0xFFFFFFFF, seed >> 32), frame, ancestors, enabled=do_resample)
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wptrack.core.device import block_partition
from wptrack.core.errors import ConfigError
from wptrack.kernels.core import resample as kres

BLOCK = 256
"""Threads per block of the fused systematic kernels (the CPU backend runs one lane per block)."""
MAX_BLOCKS = 2048
"""Upper bound on their blocks: each block sums the totals of the blocks before it (O(blocks^2) reads in all)."""
PER_LANE_GPU = 4
"""Contiguous particles per lane and scan round of the fused systematic pass on a GPU. H200, 1e8 particles,
``Resampler.from_log_weights`` (2026-11-23): with the int64 shuffle scan 4 -> 1.49 ms, 8 -> 1.60 ms; with the
previous three 32-bit limb tile scans 4 -> 1.72-1.76 ms, 8 -> 1.69-1.70 ms (same ancestors)."""
PER_LANE_CPU = 1024
LONG_RANGE = 64
"""Longest offspring range a thread of the scatter kernels writes itself on a GPU; a parent with more children
writes its first slot and leaves the rest to :func:`kernels.core.resample.long_ranges_fill_kernel`, which spreads them
over a fixed grid (one parent owning ~1e6 of 1e8 slots serialised the scatter: 199 ms on an H200). The list costs
8 / (LONG_RANGE + 1) bytes per particle (0.12). On the CPU backend, which runs a launch on one thread, the default is
no list (a range costs the same wherever it is written; no fill launch)."""
FILL_BLOCKS_GPU = 512
"""Blocks of the long-range fill kernel on a GPU (on the CPU backend: one)."""

SCHEMES: tuple[str, ...] = ("multinomial", "stratified", "systematic", "residual")

_SEARCH_KERNELS = {
    "multinomial": kres.multinomial_kernel,
    "stratified": kres.stratified_kernel,
    "systematic": kres.systematic_kernel,
}


class Resampler:
    """Ancestor selection for one scheme and up to ``capacity`` particles on one device.

    Args:
        scheme: one of :data:`SCHEMES`.
        capacity: the largest particle count a call may use; all temporaries are allocated for it here.
        device: Warp device alias (``"cpu"``, ``"cuda:0"``, ...).
        log_weights: build for :meth:`from_log_weights` (float32 log-weights) instead of :meth:`__call__`.
        long_range: the longest offspring range one thread writes itself (systematic and residual schemes); longer
            ones are filled by the whole grid (:func:`kernels.core.resample.long_ranges_fill_kernel`). Any value >= 1
            gives the same ancestors. Default: :data:`LONG_RANGE` on a GPU, ``capacity`` (no list) on the CPU.

    Raises:
        ConfigError: unknown scheme (the message lists the valid names), a capacity below 1 or a long_range below 1.
    """

    def __init__(
        self, scheme: str, capacity: int, device: str, log_weights: bool = False, long_range: int | None = None
    ) -> None:
        if scheme not in SCHEMES:
            raise ConfigError(f"resampling scheme {scheme!r}: expected one of {', '.join(SCHEMES)}")
        if int(capacity) < 1:
            raise ConfigError(f"resampler capacity {capacity}: expected at least 1 particle")
        if long_range is None:
            long_range = int(capacity) if wp.get_device(device).is_cpu else LONG_RANGE
        if int(long_range) < 1:
            raise ConfigError(f"resampler long_range {long_range}: expected at least 1 slot")
        self.scheme = scheme
        self.capacity = int(capacity)
        self.device = wp.get_device(device)
        self.log_weights = bool(log_weights)
        cap = self.capacity
        self._always = wp.ones(1, dtype=wp.int32, device=self.device)
        # systematic from log-weights: exact integer CDF, no per-particle buffer (see kernels.core.resample)
        self.exact = self.log_weights and scheme == "systematic"
        self.sm_count = 0 if self.device.is_cpu else self.device.sm_count
        self.blocks, self.chunk = block_partition(cap, self.device.is_cpu, BLOCK, MAX_BLOCKS, self.sm_count)
        self.scale = float(2 ** quantisation_bits(cap))
        # particles per lane and scan round: a few on a GPU (ILP, fewer block-wide scans), a long run on the CPU
        # backend, where a block is one lane and the scans are sequential anyway
        self.per_lane = PER_LANE_CPU if self.device.is_cpu else PER_LANE_GPU
        # one lane per block on the CPU backend whatever wp.config.enable_cpu_blocks says: the block scans of the
        # exact systematic kernels are warp shuffles on CUDA and a one-lane identity on the CPU
        self.block_dim = 1 if self.device.is_cpu else BLOCK
        self.totals = wp.zeros(self.blocks, dtype=wp.int64, device=self.device) if self.exact else None
        self.weights = (
            wp.zeros(cap, dtype=wp.float64, device=self.device) if self.log_weights and not self.exact else None
        )
        # long offspring ranges (systematic, residual): per group of parents (the blocks above) a packed counter
        # and the first list entry; the list itself holds at most capacity // (long_range + 1) + groups entries
        self.long_range = int(long_range)
        self.fill_blocks = 1 if self.device.is_cpu else min(self.blocks, FILL_BLOCKS_GPU)
        self.long_meta: wp.array | None = None
        if scheme in ("systematic", "residual"):
            entries = cap // (self.long_range + 1) + self.blocks + 1
            self.long_meta = wp.zeros(self.blocks, dtype=wp.int64, device=self.device)
            self.long_base = wp.zeros(self.blocks, dtype=wp.int32, device=self.device)
            self.long_lo = wp.zeros(entries, dtype=wp.int32, device=self.device)
            self.long_off = wp.zeros(entries, dtype=wp.int32, device=self.device)
        self.cdf = None if self.exact else wp.zeros(cap, dtype=wp.float64, device=self.device)
        self.counts: wp.array | None = None
        self.positions: wp.array | None = None
        self.residuals: wp.array | None = None
        self.residual_cdf: wp.array | None = None
        if scheme == "residual":
            self.counts = wp.zeros(cap, dtype=wp.int32, device=self.device)
            self.positions = wp.zeros(cap, dtype=wp.int32, device=self.device)
            self.residuals = wp.zeros(cap, dtype=wp.float64, device=self.device)
            self.residual_cdf = wp.zeros(cap, dtype=wp.float64, device=self.device)
        self._views: dict[int, dict[str, wp.array]] = {}

    def _buffers(self, n: int) -> dict[str, wp.array]:
        """Views of the temporaries with length ``n`` (array headers only, cached; no device allocation)."""
        views = self._views.get(n)
        if views is None:
            names = ("cdf", "counts", "positions", "residuals", "residual_cdf")
            full = {name: getattr(self, name) for name in names if getattr(self, name) is not None}
            views = {name: (a if n == self.capacity else a[:n]) for name, a in full.items()}
            self._views[n] = views
        return views

    def __call__(
        self,
        weights: wp.array,
        seed: wp.vec2ui,
        frame: wp.array,
        ancestors: wp.array,
        enabled: wp.array | None = None,
        n: int | None = None,
    ) -> None:
        """Draw ``ancestors`` from ``weights`` (asynchronous: launches only, no host sync, no allocation).

        Args:
            weights: (N,) float64 unnormalised non-negative weights with a positive total.
            seed: the run's 64-bit seed as ``wp.vec2ui`` (constant for the run).
            frame: (1,) int32 device array holding the filter iteration; the random counter is
                ``(index, frame[0], STREAM_RESAMPLE or STREAM_RESIDUAL)``.
            ancestors: (N,) int32 output; ``ancestors[j]`` is the parent of output particle ``j``.
            enabled: optional (1,) int32 device array; when ``enabled[0] == 0`` the output is the identity
                ``ancestors[j] = j``.
            n: number of particles to resample (default ``weights.shape[0]``); at most ``capacity``.

        Raises:
            ValueError: ``n`` exceeds the capacity or the arrays are too short, of the wrong dtype or on another
                device.
        """
        if self.exact:
            raise ValueError("resampler built for log-weights (systematic, exact CDF): call from_log_weights()")
        if n is None:
            n = weights.shape[0]
        n = int(n)
        if not 1 <= n <= self.capacity:
            raise ValueError(f"resampler: n={n} outside [1, capacity={self.capacity}]")
        if weights.dtype != wp.float64 or ancestors.dtype != wp.int32:
            raise ValueError("resampler: weights must be float64 and ancestors int32")
        if weights.shape[0] < n or ancestors.shape[0] < n:
            raise ValueError(f"resampler: weights {weights.shape} / ancestors {ancestors.shape} shorter than n={n}")
        for a in (weights, frame, ancestors, enabled):
            if a is not None and a.device != self.device:
                raise ValueError(f"resampler on {self.device}: got an array on {a.device}")
        if enabled is None:
            enabled = self._always
        w = weights if weights.shape[0] == n else weights[:n]
        buf = self._buffers(n)
        wp.utils.array_scan(w, buf["cdf"], inclusive=True)
        groups, chunk = block_partition(n, self.device.is_cpu, BLOCK, MAX_BLOCKS, self.sm_count)
        if self.long_meta is not None and self.long_range < n:
            self.long_meta.zero_()  # the counters of the groups (the fused log-weight pass zeroes its own)
        if self.scheme in _SEARCH_KERNELS:
            long_args = [self.long_range, chunk] if self.scheme == "systematic" else []
            long_out = self._long_lists() if self.scheme == "systematic" else []
            wp.launch(
                _SEARCH_KERNELS[self.scheme],
                dim=n,
                inputs=[w, buf["cdf"], seed, frame, enabled, n, *long_args],
                outputs=[ancestors, *long_out],
                device=self.device,
            )
            if self.scheme == "systematic":
                self._fill_long(ancestors, groups, n)
            return
        wp.launch(
            kres.residual_split_kernel,
            dim=n,
            inputs=[w, buf["cdf"], n],
            outputs=[buf["counts"], buf["residuals"]],
            device=self.device,
        )
        wp.utils.array_scan(buf["counts"], buf["positions"], inclusive=True)
        wp.utils.array_scan(buf["residuals"], buf["residual_cdf"], inclusive=True)
        wp.launch(
            kres.residual_scatter_kernel,
            dim=n,
            inputs=[buf["counts"], buf["positions"], enabled, n, self.long_range, chunk],
            outputs=[ancestors, *self._long_lists()],
            device=self.device,
        )
        self._fill_long(ancestors, groups, n)  # before the draws, which may copy deterministic slots
        wp.launch(
            kres.residual_draw_kernel,
            dim=n,
            inputs=[buf["residuals"], buf["residual_cdf"], buf["positions"], seed, frame, enabled, n],
            outputs=[ancestors],
            device=self.device,
        )

    def from_log_weights(
        self,
        logw: wp.array,
        est: wp.array,
        max_slot: int,
        seed: wp.vec2ui,
        frame: wp.array,
        ancestors: wp.array,
        enabled: wp.array | None = None,
    ) -> None:
        """Draw ``ancestors`` from log-weights (asynchronous: launches only, no host sync, no allocation).

        Systematic resampling runs on an exact integer CDF without any per-particle temporary: the weights
        ``exp(logw - max)`` are quantised to integers ``floor(w 2^k)`` with ``k = 60 - bitlen(capacity)`` (at most
        52; k = 33 at 1e8 particles), summed per block, then scanned and scattered in one fused pass. A particle
        whose weight is below ``2^-k`` of the best one gets no offspring. The other schemes write the float64
        weights and run :meth:`__call__`.

        Args:
            logw: (capacity,) float32 log-weights.
            est: float64 device vector whose entry ``max_slot`` holds ``max(logw)`` (e.g.
            ``kernels.core.reduce.EST_*``). max_slot: index of the max log-weight in ``est``. seed, frame, ancestors,
            enabled: as :meth:`__call__`.

        Raises:
            ValueError: the resampler was not built with ``log_weights=True``, or wrong lengths/dtypes/devices.
        """
        if not self.log_weights:
            raise ValueError("resampler: build it with log_weights=True to call from_log_weights()")
        n = self.capacity
        if logw.dtype != wp.float32 or logw.shape[0] != n or ancestors.shape[0] != n or ancestors.dtype != wp.int32:
            raise ValueError(f"resampler: logw (float32) and ancestors (int32) must have {n} entries")
        for a in (logw, est, frame, ancestors, enabled):
            if a is not None and a.device != self.device:
                raise ValueError(f"resampler on {self.device}: got an array on {a.device}")
        if enabled is None:
            enabled = self._always
        if not self.exact:
            wp.launch(
                kres.weights_from_log_kernel,
                dim=n,
                inputs=[logw, est, int(max_slot)],
                outputs=[self.weights],
                device=self.device,
            )
            self(self.weights, seed, frame, ancestors, enabled=enabled)
            return
        wp.launch_tiled(
            kres.quantised_totals_kernel,
            dim=[self.blocks],
            inputs=[logw, est, int(max_slot), self.scale, n, self.chunk],
            outputs=[self.totals],
            block_dim=self.block_dim,
            device=self.device,
        )
        wp.launch_tiled(
            kres.systematic_logw_kernel,
            dim=[self.blocks],
            inputs=[
                logw,
                est,
                int(max_slot),
                self.scale,
                self.totals,
                self.blocks,
                seed,
                frame,
                enabled,
                n,
                self.chunk,
                self.per_lane,
                self.long_range,
            ],
            outputs=[ancestors, *self._long_lists()],
            block_dim=self.block_dim,
            device=self.device,
        )
        self._fill_long(ancestors, self.blocks, n)

    def _long_lists(self) -> list[wp.array]:
        """The long-range list arrays, in the kernels' argument order."""
        return [self.long_meta, self.long_base, self.long_lo, self.long_off]

    def _fill_long(self, ancestors: wp.array, groups: int, n: int) -> None:
        """Fill the long offspring ranges recorded by the scatter kernel (a fixed launch that returns at once when
        there are none; not launched when no range can be long)."""
        if self.long_range >= n:
            return
        wp.launch_tiled(
            kres.long_ranges_fill_kernel,
            dim=[self.fill_blocks],
            inputs=[self.long_meta, self.long_base, self.long_lo, self.long_off, groups, self.fill_blocks],
            outputs=[ancestors],
            block_dim=BLOCK,
            device=self.device,
        )


def quantisation_bits(capacity: int) -> int:
    """Bits k of the integer weights ``floor(w 2^k)`` of the exact systematic CDF: the largest k <= 52 with
    ``capacity x 2^k <= 2^60`` (so every sum fits the three 20-bit limbs of the block scans)."""
    return min(52, 60 - int(capacity).bit_length())


def bytes_per_particle(scheme: str, log_weights: bool = False) -> int:
    """Device bytes per particle of a :class:`Resampler`: the float64 CDF, up to 8 bytes of prefix-sum scratch,
    the residual scheme's counts, positions, residuals and their CDF, and (from log-weights) the float64 weights.
    Systematic resampling from log-weights needs none (an int64 per block of particles). Not counted (under one
    byte): the long-range list of the systematic and residual schemes, 8 / (long_range + 1) bytes per particle
    (0.12 at the default :data:`LONG_RANGE`) plus 12 bytes per block."""
    if log_weights and scheme == "systematic":
        return 0
    extra = 4 + 4 + 8 + 8 if scheme == "residual" else 0
    return 8 + 8 + extra + (8 if log_weights else 0)


def make_resampler(scheme: str, capacity: int, device: str) -> Resampler:
    """Build a :class:`Resampler` (same as the constructor).

    Raises:
        ConfigError: unknown scheme or capacity below 1.
    """
    return Resampler(scheme, capacity, device)


def offspring_counts(ancestors: np.ndarray | wp.array, n: int) -> np.ndarray:
    """Number of children of each parent (host helper for diagnostics and tests).

    Args:
        ancestors: (N,) parent indices (numpy or Warp array; a Warp array is copied to the host).
        n: number of parents.

    Returns:
        (n,) int64 offspring counts, ``np.bincount(ancestors, minlength=n)``.
    """
    if isinstance(ancestors, wp.array):
        ancestors = ancestors.numpy()
    return np.bincount(np.asarray(ancestors, dtype=np.int64).ravel(), minlength=n)
