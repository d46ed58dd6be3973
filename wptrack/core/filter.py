"""The particle-filter engine shared by the point trackers (S1 colour, and the 3D-observation filter of the
extended paper's section III.C): particle state, estimates, resampling, CUDA graphs.

A frame is a fixed chain of launches::

    predict+score (tracker kernel: gather parents, motion, likelihood, log-weights, and per block of particles
                   the max log-weight, MAP index and weighted sums, in the same pass)
    -> final moments  (one block: MMSE mean, spread, ESS, likelihood, resample decision)
    -> optional subsample for reports
    -> resample from the log-weights (scheme by name; systematic: exact integer CDF, two passes, no temporaries)
       -> ancestors for the next frame
    -> frame counter += 1 (on device: it keys the random streams)

Nothing in the chain reads back to the host or allocates; on CUDA the chain is captured once per ping-pong
parity as a CUDA graph and replayed. Per-frame parameters (frame number, sigma, ESS threshold) live in
small device arrays, so a replay sees their current values. The only device-to-host copy per frame is the
estimate vector (and, when asked for, a small subsample of particles for reports).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from wptrack.core.device import block_partition
from wptrack.core.errors import ConfigError
from wptrack.core.resampling import SCHEMES, Resampler, bytes_per_particle
from wptrack.kernels.colour import walk as kmotion
from wptrack.kernels.core import reduce as kreduce

log = logging.getLogger(__name__)

BLOCK = 256
"""Threads per block of the reduction kernels (CUDA; the CPU backend runs one thread per block)."""
MAX_BLOCKS = 2048
"""Upper bound on the blocks of a reduction: more blocks only lengthen the final one-block pass over the per-block
partials (at 1e8 particles, 390 625 blocks of 256 made it the slowest stage). On a GPU the cap is lower, a whole
number of waves per SM (``wptrack.core.device.GPU_BLOCKS_PER_SM``)."""


@dataclass
class Estimate:
    """The filter's output for one frame (host arrays; metres in the world frame)."""

    frame: int
    """0-based frame index."""
    mean: np.ndarray
    """(3,) weighted mean of the particles (MMSE estimate), metres."""
    std: np.ndarray
    """(3,) weighted standard deviation per axis (spread of the cloud), metres."""
    map: np.ndarray
    """(3,) the particle with the highest weight (MAP estimate), metres."""
    ess: float
    """Effective sample size (sum w)^2 / sum w^2, in particles."""
    loglik: float
    """log of the mean particle weight: the frame's log-likelihood estimate (when resampled every frame)."""
    resampled: bool
    """Whether the particles were resampled after this frame (ESS trigger)."""
    degenerate: bool = False
    """Every log-weight was -inf or NaN (every particle out of view or of zero likelihood): the frame's weights
    were taken as uniform, i.e. the predicted cloud was kept as it is ("keep the prior"); the estimate is then the
    prediction's mean, finite, and ``loglik`` is ``kernels.core.reduce.LOGW_FLOOR``."""
    particles: np.ndarray | None = None
    """(K, 3) float32 subsample of the weighted particle cloud (only when requested), metres."""
    weights: np.ndarray | None = None
    """(K,) float32 weights of that subsample relative to the best particle."""
    timings: dict[str, float] = field(default_factory=dict)
    """Seconds spent per stage for this frame (host wall clock; see ParticleFilter.step)."""
    detection: int = -1
    """Trackers with a detection-driven proposal: detection candidates found this frame (0 = no detection);
    -1 when the tracker has none."""
    jump: bool = False
    """Trackers with detection jumps: whether this frame moved particles to the detections (a mode test fired)."""


def _seed_words(seed: int) -> wp.vec2ui:
    if not isinstance(seed, (int, np.integer)) or seed < 0 or seed >= 2**64:
        raise ConfigError(f"seed: expected an integer in [0, 2^64), got {seed!r}")
    seed = int(seed)
    return wp.vec2ui(seed & 0xFFFFFFFF, (seed >> 32) & 0xFFFFFFFF)


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


def _dtype_tail(arr: wp.array) -> tuple[int, ...]:
    """The trailing NumPy dimensions of a Warp array's dtype (3 for vec3, (3, 3) for mat33, none for scalars)."""
    return tuple(getattr(arr.dtype, "_shape_", ()))


def _device_arrays(obj, prefix: str = "", seen: set[int] | None = None) -> Iterator[tuple[str, wp.array]]:
    """Every ``wp.array`` reachable from ``obj``'s attributes: directly, in lists/tuples/dicts, in ``@wp.struct``
    instances, and in wptrack helper objects (recursively), as ``(dotted.name, array)`` in a stable order.

    Buffers created lazily or cached views appear only once used, so a fresh filter lists a subset of the names of
    one that has run: :meth:`FrameChain.load_state_dict` restores the names the fresh filter has."""
    if isinstance(obj, wp.array):  # an array reachable by two names (a cached view) is listed under both
        yield prefix, obj
        return
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            yield from _device_arrays(v, f"{prefix}.{i}", seen)
    elif isinstance(obj, dict):
        for k in sorted(obj, key=str):
            yield from _device_arrays(obj[k], f"{prefix}.{k}", seen)
    elif hasattr(obj, "_cls") and hasattr(obj._cls, "vars"):  # a @wp.struct instance
        for k in obj._cls.vars:
            yield from _device_arrays(getattr(obj, k), f"{prefix}.{k}", seen)
    elif type(obj).__module__.startswith("wptrack") and hasattr(obj, "__dict__"):
        for k in sorted(vars(obj)):
            if not k.startswith("__"):
                yield from _device_arrays(getattr(obj, k), f"{prefix}.{k}" if prefix else k, seen)


class FrameChain:
    """A filter whose frame is a fixed chain of device launches over ping-pong buffers (parity 0/1).

    Subclasses set ``device``, ``is_cuda``, ``use_graph``, ``parity``, ``frames_done``, ``_graphs = [None, None]``
    and ``_warm = [False, False]``, and implement :meth:`stages` and ``step``. This base runs the chain (CUDA graph
    capture per parity after a warm-up run), times it and iterates over observations.
    """

    device: str
    is_cuda: bool
    use_graph: bool
    parity: int
    frames_done: int
    _graphs: list
    _warm: list[bool]

    def stages(self, src: int, dst: int) -> list[tuple[str, Callable[[], None]]]:  # pragma: no cover - abstract
        """The frame chain as named stages; running them in order is one filter iteration."""
        raise NotImplementedError

    def step(self, observation):  # pragma: no cover - implemented by each tracker
        """Upload one frame's observation and run one iteration."""
        raise NotImplementedError

    def _chain(self, src: int, dst: int) -> None:
        for _name, stage in self.stages(src, dst):
            stage()

    def _run_chain(self, src: int, dst: int) -> None:
        """Run the chain; on CUDA the first run of each parity loads the modules, the second captures a
        graph (launch arguments, buffers and device-side parameters are fixed), later ones replay it."""
        if not self.use_graph or not self._warm[src]:
            self._chain(src, dst)
            self._warm[src] = True
            return
        if self._graphs[src] is None:
            with wp.ScopedCapture(device=self.device) as capture:
                self._chain(src, dst)
            self._graphs[src] = capture.graph
        wp.capture_launch(self._graphs[src])

    def time_frames(self, count: int) -> list[float]:
        """Run ``count`` frames of the device chain on the uploaded observation (graph replay on CUDA) and return
        the device time of each, seconds (CUDA events; wall clock on the CPU). No estimate is read back."""
        times = []
        if self.is_cuda:
            ev = [wp.Event(self.device, enable_timing=True) for _ in range(count + 1)]
            wp.record_event(ev[0])
            for k in range(count):
                src, dst = self.parity, 1 - self.parity
                self._run_chain(src, dst)
                self.parity = dst
                wp.record_event(ev[k + 1])
            wp.synchronize_device(self.device)
            times = [wp.get_event_elapsed_time(ev[k], ev[k + 1]) / 1000.0 for k in range(count)]
        else:
            for _ in range(count):
                t0 = time.perf_counter()
                src, dst = self.parity, 1 - self.parity
                self._run_chain(src, dst)
                self.parity = dst
                times.append(time.perf_counter() - t0)
        self.frames_done += count
        return times

    def profile(self) -> dict[str, float]:
        """Run one frame stage by stage without a graph and return seconds per stage (CUDA events on GPUs,
        wall clock on the CPU, whose launches are synchronous). The observation must already be uploaded.
        The filter advances by one frame, as with :meth:`advance`."""
        src, dst = self.parity, 1 - self.parity
        times: dict[str, float] = {}
        if self.is_cuda:
            stages = self.stages(src, dst)
            events = [wp.Event(self.device, enable_timing=True) for _ in range(len(stages) + 1)]
            wp.record_event(events[0])
            names = []
            for k, (name, stage) in enumerate(stages):
                stage()
                wp.record_event(events[k + 1])
                names.append(name)
            wp.synchronize_device(self.device)
            for k, name in enumerate(names):
                times[name] = wp.get_event_elapsed_time(events[k], events[k + 1]) / 1000.0
        else:
            for name, stage in self.stages(src, dst):
                t0 = time.perf_counter()
                stage()
                times[name] = time.perf_counter() - t0
        self.parity = dst
        self.frames_done += 1
        return times

    # --- checkpoints -------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, np.ndarray]:
        """A copy of the filter's whole state after the last frame, for :meth:`load_state_dict`.

        Every Warp array the filter holds (directly, in lists/dicts, in ``@wp.struct`` instances or in its helper
        objects such as the resampler) is copied to the host, with ``parity`` and ``frames_done``: restoring it
        into a filter built with the same configuration continues exactly as the original would have (the random
        streams are counter-based, keyed by the frame). Scratch buffers are included (they are overwritten each
        frame anyway), so the size is the filter's device memory. Syncs with the device: not for the frame loop.
        """
        state = {name: arr.numpy().copy() for name, arr in _device_arrays(self)}
        state["__parity__"] = np.array(self.parity, dtype=np.int64)
        state["__frames_done__"] = np.array(self.frames_done, dtype=np.int64)
        return state

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restore a :meth:`state_dict` into this filter (built with the same configuration).

        Raises:
            ConfigError: the state does not match this filter (missing arrays, other shapes or types).
        """
        arrays = dict(_device_arrays(self))
        missing = sorted(set(arrays) - set(state))
        if missing:
            raise ConfigError(f"checkpoint: arrays {missing[:5]} missing (a checkpoint of another configuration?)")
        for name, arr in arrays.items():
            value = np.asarray(state[name])
            if value.shape != tuple(arr.shape) + _dtype_tail(arr):
                raise ConfigError(f"checkpoint: array {name} has shape {value.shape}, the filter's is {arr.shape}")
        for name, arr in arrays.items():
            arr.assign(np.asarray(state[name]))
        self.parity = int(state["__parity__"])
        self.frames_done = int(state["__frames_done__"])
        wp.synchronize_device(self.device)

    def track(self, observations: Iterable, max_frames: int | None = None) -> Iterator:
        """Iterate over observations (e.g. ``wptrack.io.frames.open_frames`` for image trackers), yielding one
        estimate each, for at most ``max_frames`` frames."""
        for k, obs in enumerate(observations):
            if max_frames is not None and k >= max_frames:
                return
            yield self.step(obs)


class ParticleFilter(FrameChain):
    """Particle state and the shared per-frame chain for trackers whose particles are 3D points.

    Subclasses implement :meth:`_launch_predict_score` (their motion + observation kernel) and upload their
    observation in :meth:`_upload` before the chain runs.

    Device state (allocated once, N = ``particles``):
        x: two (N,) ``wp.vec3`` ping-pong buffers of particle positions, metres.
        logw: two (N,) float32 ping-pong buffers of log-weights (unnormalised).
        ancestors: (N,) int32 parent of each particle for the next prediction (identity after init).
        resampled: (1,) int32, 1 when the last frame resampled (next log-weights restart from 0).
        part_max, part_arg, part: per block of particles (``blocks``,): max log-weight, its lowest index, and the
            weighted sums (``blocks``, ``kernels.core.reduce.N_SUMS``) relative to the block max, written by the
            tracker's predict + score kernel.
        est: (16,) float64 estimate vector (layout ``kernels.core.reduce.EST_*``).
        frame: (1,) int32 filter iteration, keys the random streams.
    """

    kernel_modules: tuple[str, ...] = (
        "wptrack.kernels.colour.walk",
        "wptrack.kernels.core.reduce",
        "wptrack.kernels.core.resample",
    )
    """Warp modules the frame chain launches (loaded before the first frame by :func:`wptrack.core.device.warm_up`)."""

    def __init__(
        self,
        particles: int,
        sigma: float,
        device: str,
        seed: int = 0,
        resampling: str = "systematic",
        ess_threshold: float = 1.0,
        keep_particles: int = 0,
        use_graph: bool | None = None,
    ) -> None:
        n = check_particles(particles)
        if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma > 0):
            raise ConfigError(f"sigma: expected a motion deviation > 0 metres, got {sigma!r}")
        if resampling not in SCHEMES:
            raise ConfigError(f"resampling: unknown scheme {resampling!r}; expected one of {', '.join(SCHEMES)}")
        if not (0.0 < ess_threshold <= 1.0):
            raise ConfigError(f"ess_threshold: expected a fraction in (0, 1], got {ess_threshold!r}")
        check_fits(n, POINT_STATE_BYTES + resampler_bytes(resampling), 0, device)
        self.n = n
        self.device = str(wp.get_device(device))
        self.is_cuda = wp.get_device(device).is_cuda
        self.seed = _seed_words(seed)
        self.use_graph = self.is_cuda if use_graph is None else (bool(use_graph) and self.is_cuda)
        sms = wp.get_device(self.device).sm_count if self.is_cuda else 0
        self.blocks, self.chunk = block_partition(n, not self.is_cuda, BLOCK, MAX_BLOCKS, sms)
        d = self.device
        self.x = [wp.zeros(n, dtype=wp.vec3, device=d), wp.zeros(n, dtype=wp.vec3, device=d)]
        self.logw = [wp.zeros(n, dtype=wp.float32, device=d), wp.zeros(n, dtype=wp.float32, device=d)]
        self.ancestors = wp.array(np.arange(n, dtype=np.int32), device=d)
        self.resampled = wp.ones(1, dtype=wp.int32, device=d)
        self.est = wp.zeros(kreduce.EST_SIZE, dtype=wp.float64, device=d)
        self.best_index = wp.zeros(1, dtype=wp.int32, device=d)
        self.part_max = wp.zeros(self.blocks, dtype=wp.float32, device=d)
        self.part_arg = wp.zeros(self.blocks, dtype=wp.int32, device=d)
        self.part = wp.zeros((self.blocks, kreduce.N_SUMS), dtype=wp.float64, device=d)
        self.frame = wp.zeros(1, dtype=wp.int32, device=d)
        self.sigma = wp.array([sigma], dtype=wp.float32, device=d)
        self.ess_threshold = wp.array([ess_threshold], dtype=wp.float32, device=d)
        self.resampler = Resampler(resampling, n, d, log_weights=True)
        self.keep = min(int(keep_particles), n)
        self.stride = max(1, n // self.keep) if self.keep else 1
        if self.keep:
            self.sub_x = wp.zeros(self.keep, dtype=wp.vec3, device=d)
            self.sub_w = wp.zeros(self.keep, dtype=wp.float32, device=d)
        pinned = self.is_cuda
        self.est_host = wp.zeros(kreduce.EST_SIZE, dtype=wp.float64, device="cpu", pinned=pinned)
        if self.keep:
            self.sub_x_host = wp.zeros(self.keep, dtype=wp.vec3, device="cpu", pinned=pinned)
            self.sub_w_host = wp.zeros(self.keep, dtype=wp.float32, device="cpu", pinned=pinned)
        self.parity = 0
        self.frames_done = 0
        self._graphs: list = [None, None]
        self._warm = [False, False]

    # --- initialisation ---------------------------------------------------------------------------
    def init_point(self, point) -> None:
        """Put every particle at ``point`` (3,) metres (Barrera et al.: the first prediction spreads them)."""
        p = np.asarray(point, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ConfigError(f"init: expected 3 finite coordinates in metres, got {point!r}")
        wp.launch(
            kmotion.init_point_kernel,
            dim=self.n,
            inputs=[wp.vec3(*p)],
            outputs=[self.x[self.parity]],
            device=self.device,
        )
        self._reset_weights()

    def init_box(self, lo, hi) -> None:
        """Particles uniform in the box [lo, hi] (metres)."""
        lo = np.asarray(lo, dtype=np.float64).reshape(-1)
        hi = np.asarray(hi, dtype=np.float64).reshape(-1)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ConfigError("init box: expected two finite 3-vectors (min, max) in metres")
        if np.any(lo > hi):
            raise ConfigError(f"init box: min {lo.tolist()} must not exceed max {hi.tolist()}")
        wp.launch(
            kmotion.init_box_kernel,
            dim=self.n,
            inputs=[wp.vec3(*lo), wp.vec3(*hi), self.seed],
            outputs=[self.x[self.parity]],
            device=self.device,
        )
        self._reset_weights()

    def _reset_weights(self) -> None:
        self.ancestors.assign(np.arange(self.n, dtype=np.int32))
        self.resampled.fill_(1)
        self.logw[self.parity].zero_()

    def set_sigma(self, sigma: float) -> None:
        """Change sigma_m (metres) between frames; a graph replay picks the new value up."""
        if not (math.isfinite(sigma) and sigma > 0):
            raise ConfigError(f"sigma: expected a motion deviation > 0 metres, got {sigma!r}")
        self.sigma.fill_(float(sigma))

    @property
    def particles(self) -> wp.array:
        """(N,) wp.vec3 current particle positions (after the last prediction), metres."""
        return self.x[self.parity]

    @property
    def log_weights(self) -> wp.array:
        """(N,) float32 current log-weights (unnormalised)."""
        return self.logw[self.parity]

    # --- the per-frame chain -----------------------------------------------------------------------
    def _launch_predict_score(self, src: int, dst: int) -> None:  # pragma: no cover - abstract
        """Launch the tracker's fused kernel (usually through :meth:`_launch_fused`)."""
        raise NotImplementedError

    def _launch_fused(self, kernel, observation: list, src: int, dst: int) -> None:
        """Launch a fused predict + score kernel whose arguments are the tracker's ``observation`` inputs followed by
        the shared particle state: ``(particles, ancestors, logw_prev, resampled, sigma, seed, frame, n, chunk)`` in,
        ``(particles_out, logw_out, part_max, part_arg, part)`` out (``kernels.core.reduce.moments_push``/
        ``moments_store``), one block per ``chunk`` particles."""
        wp.launch_tiled(
            kernel,
            dim=[self.blocks],
            inputs=[
                *observation,
                self.x[src],
                self.ancestors,
                self.logw[src],
                self.resampled,
                self.sigma,
                self.seed,
                self.frame,
                self.n,
                self.chunk,
            ],
            outputs=[self.x[dst], self.logw[dst], self.part_max, self.part_arg, self.part],
            block_dim=BLOCK,
            device=self.device,
        )

    def _launch_observation(self) -> None:
        """Per-frame observation preparation on the device (e.g. colour mask + integral image)."""

    def _estimate(self, dst: int) -> None:
        d = self.device
        x, logw = self.x[dst], self.logw[dst]
        wp.launch_tiled(
            kreduce.final_moments_kernel,
            dim=[1],
            inputs=[self.part_max, self.part_arg, self.part, self.blocks, self.n, x, self.ess_threshold],
            outputs=[self.est, self.best_index, self.resampled],
            block_dim=BLOCK,
            device=d,
        )
        if self.keep:
            wp.launch(
                kreduce.subsample_kernel,
                dim=self.keep,
                inputs=[x, logw, self.est, self.stride],
                outputs=[self.sub_x, self.sub_w],
                device=d,
            )

    def _resample(self, dst: int) -> None:
        self.resampler.from_log_weights(
            self.logw[dst],
            self.est,
            int(kreduce.EST_MAXLOGW),
            self.seed,
            self.frame,
            self.ancestors,
            enabled=self.resampled,
        )
        wp.launch(kreduce.increment_kernel, dim=1, inputs=[self.frame], device=self.device)

    def _readback(self) -> None:
        wp.copy(self.est_host, self.est)
        if self.keep:
            wp.copy(self.sub_x_host, self.sub_x)
            wp.copy(self.sub_w_host, self.sub_w)

    def stages(self, src: int, dst: int) -> list[tuple[str, Callable[[], None]]]:
        """The frame chain as named stages (for profiling): observe, predict_score, estimate, resample,
        readback. Running them in order is one filter iteration."""
        return [
            ("observe", self._launch_observation),
            ("predict_score", lambda: self._launch_predict_score(src, dst)),
            ("estimate", lambda: self._estimate(dst)),
            ("resample", lambda: self._resample(dst)),
            ("readback", self._readback),
        ]

    def step(self, observation) -> Estimate:  # pragma: no cover - implemented by each tracker
        """Upload one frame's observation and run one iteration."""
        raise NotImplementedError

    def advance(self) -> Estimate:
        """Run one frame of the chain on the already uploaded observation and return the estimate."""
        t0 = time.perf_counter()
        src, dst = self.parity, 1 - self.parity
        self._run_chain(src, dst)
        wp.synchronize_device(self.device)
        self.parity = dst
        e = self.est_host.numpy()
        est = Estimate(
            frame=self.frames_done,
            mean=e[kreduce.EST_MEAN : kreduce.EST_MEAN + 3].copy(),
            std=e[kreduce.EST_STD : kreduce.EST_STD + 3].copy(),
            map=e[kreduce.EST_MAP : kreduce.EST_MAP + 3].copy(),
            ess=float(e[kreduce.EST_ESS]),
            loglik=float(e[kreduce.EST_LOGLIK]),
            resampled=bool(e[kreduce.EST_RESAMPLED]),
            degenerate=bool(e[kreduce.EST_DEGENERATE]),
        )
        if self.keep:
            est.particles = self.sub_x_host.numpy().copy()
            w = self.sub_w_host.numpy().copy()
            est.weights = w
        est.timings["filter"] = time.perf_counter() - t0
        self.frames_done += 1
        return est
