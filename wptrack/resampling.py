"""Particle resampling on device: multinomial, stratified, systematic and residual schemes chosen by name.

A :class:`Resampler` owns every temporary (the float64 CDF and, for the residual scheme, the count and residual
buffers) for up to ``capacity`` particles, so a call allocates nothing on the device, never synchronises with the
host and can be captured in a CUDA graph: the frame number and the optional ESS trigger are read from device
arrays inside the kernels. Prefix sums are float64 (``wp.utils.array_scan``); a float32 CDF loses whole particles
at N ~ 1e6.

Example::

    resampler = make_resampler("systematic", capacity=n, device="cuda:0")
    resampler(weights, wp.vec2ui(seed & 0xFFFFFFFF, seed >> 32), frame, ancestors, enabled=do_resample)
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wptrack.kernels import resample as kres

from .errors import ConfigError

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

    Raises:
        ConfigError: unknown scheme (the message lists the valid names) or a capacity below 1.
    """

    def __init__(self, scheme: str, capacity: int, device: str) -> None:
        if scheme not in SCHEMES:
            raise ConfigError(f"resampling scheme {scheme!r}: expected one of {', '.join(SCHEMES)}")
        if int(capacity) < 1:
            raise ConfigError(f"resampler capacity {capacity}: expected at least 1 particle")
        self.scheme = scheme
        self.capacity = int(capacity)
        self.device = wp.get_device(device)
        cap = self.capacity
        self.cdf = wp.zeros(cap, dtype=wp.float64, device=self.device)
        self._always = wp.ones(1, dtype=wp.int32, device=self.device)
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
        if self.scheme in _SEARCH_KERNELS:
            wp.launch(
                _SEARCH_KERNELS[self.scheme],
                dim=n,
                inputs=[w, buf["cdf"], seed, frame, enabled, n],
                outputs=[ancestors],
                device=self.device,
            )
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
            inputs=[buf["counts"], buf["positions"], enabled, n],
            outputs=[ancestors],
            device=self.device,
        )
        wp.launch(
            kres.residual_draw_kernel,
            dim=n,
            inputs=[buf["residuals"], buf["residual_cdf"], buf["positions"], seed, frame, enabled, n],
            outputs=[ancestors],
            device=self.device,
        )


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
