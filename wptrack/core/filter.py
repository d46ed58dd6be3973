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

import contextlib
import gc
import logging
import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
import warp as wp

from wptrack.core.device import block_partition, device_guard
from wptrack.core.errors import ConfigError
from wptrack.core.memory import POINT_STATE_BYTES, check_fits, check_particles, resampler_bytes
from wptrack.core.resampling import SCHEMES, Resampler
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


@runtime_checkable
class Tracker(Protocol):
    """The contract every tracker keeps (colour, people, templates), which the run loop, checkpoints, the report and
    the benchmarks use.

    ``step(observation)`` tracks one frame (colour: one BGR image per camera; people: ``(images, masks)``;
    templates: one motion mask) and returns the frame's estimate; ``track(observations, max_frames)`` iterates;
    ``state_dict()`` / ``load_state_dict()`` save and restore every array that carries the tracker to the next frame,
    by name, and refuse a state of another configuration. The rows a run writes from an estimate are the run job's
    (:class:`wptrack.runs.loop.TrackerRun`).
    """

    def step(self, observation: Any) -> Any: ...

    def track(self, observations: Iterable, max_frames: int | None = None) -> Iterator: ...

    def state_dict(self) -> dict[str, np.ndarray]: ...

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None: ...


def _seed_words(seed: int) -> wp.vec2ui:
    if not isinstance(seed, (int, np.integer)) or seed < 0 or seed >= 2**64:
        raise ConfigError(f"seed: expected an integer in [0, 2^64), got {seed!r}")
    seed = int(seed)
    return wp.vec2ui(seed & 0xFFFFFFFF, (seed >> 32) & 0xFFFFFFFF)


def _dtype_tail(arr: wp.array) -> tuple[int, ...]:
    """The trailing NumPy dimensions of a Warp array's dtype (3 for vec3, (3, 3) for mat33, none for scalars)."""
    return tuple(getattr(arr.dtype, "_shape_", ()))


def arrays_state(arrays: dict[str, wp.array]) -> dict[str, np.ndarray]:
    """Host copies of named device arrays (a tracker's :meth:`FrameChain.state_arrays`). Syncs with the device."""
    return {name: arr.numpy().copy() for name, arr in arrays.items()}


def check_state(arrays: dict[str, wp.array], state: dict[str, np.ndarray], host: tuple[str, ...] = ()) -> None:
    """Check that ``state`` holds exactly the named ``arrays`` (and the ``host`` keys), each with the array's shape
    and element type.

    Raises:
        ConfigError: a name missing or unexpected (a checkpoint of another configuration or version), or an array of
            another shape or type; the message names the arrays.
    """
    expected = set(arrays) | set(host)
    missing, unexpected = sorted(expected - set(state)), sorted(set(state) - expected)
    if missing or unexpected:
        parts = [f"missing {missing[:5]}" if missing else "", f"unexpected {unexpected[:5]}" if unexpected else ""]
        raise ConfigError(
            f"checkpoint: arrays {' and '.join(p for p in parts if p)} (a checkpoint of another configuration or "
            "version?)"
        )
    for name, arr in arrays.items():
        value = np.asarray(state[name])
        shape = tuple(arr.shape) + _dtype_tail(arr)
        kind = np.dtype(wp.dtype_to_numpy(getattr(arr.dtype, "_wp_scalar_type_", arr.dtype)))
        if value.shape != shape or value.dtype != kind:
            raise ConfigError(
                f"checkpoint: array {name} is {value.dtype} {value.shape}, the tracker's is {kind} {shape}"
            )


def load_arrays(arrays: dict[str, wp.array], state: dict[str, np.ndarray]) -> None:
    """Copy checked host arrays (:func:`check_state`) into the named device arrays."""
    for name, arr in arrays.items():
        arr.assign(np.asarray(state[name]))


@contextlib.contextmanager
def no_gc() -> Iterator[None]:
    """Python's garbage collector off for the block, after one collection: a CUDA graph capture must not record the
    frees of another run's Warp arrays or graphs that the collector finalises meanwhile (on any thread): such a free
    synchronises the stream ("Cannot synchronize stream while graph capture is active") or corrupts the graph. Seen
    in a batch worker that tracks run after run in one process (NVIDIA/warp#1714; Newton and mjlab suspend the
    collector the same way)."""
    enabled = gc.isenabled()
    gc.collect()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()


class FrameChain:
    """A filter whose frame is a fixed chain of device launches over ping-pong buffers (parity 0/1).

    Subclasses call ``FrameChain.__init__`` first, implement :meth:`stages` (the chain), :meth:`state_arrays` (the
    device arrays a frame hands to the next) and ``step``. This base runs the chain (CUDA graph capture per parity
    after a warm-up run), times it, saves and restores the state, and iterates over observations.

    Attributes:
        device: the Warp device, e.g. ``cpu`` or ``cuda:0``.
        is_cuda: whether it is a CUDA device.
        use_graph: the chain is captured as a CUDA graph per parity (CUDA only).
        parity: which of the ping-pong buffers holds the current particles (0 or 1).
        frames_done: frames tracked so far.
    """

    def __init__(self, device: str, use_graph: bool | None = None) -> None:
        dev = wp.get_device(device)
        self.device = str(dev)
        self.is_cuda = dev.is_cuda
        self.use_graph = self.is_cuda if use_graph is None else (bool(use_graph) and self.is_cuda)
        self.parity = 0
        self.frames_done = 0
        self._graphs: list = [None, None]
        self._warm = [False, False]

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
            with device_guard(self.device).exclusive(), no_gc():  # no other thread's device work in the graph
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
    def state_arrays(self) -> dict[str, wp.array]:  # pragma: no cover - implemented by each tracker
        """The device arrays that carry the filter from one frame to the next, by name (both ping-pong buffers where a
        frame reads the one it did not write). Scratch written before it is read in every frame is left out. This is
        what a checkpoint saves: a name added here is a new checkpoint key."""
        raise NotImplementedError

    def host_state(self) -> dict[str, np.ndarray]:
        """The host-side counters that go with :meth:`state_arrays` (``__parity__``, ``__frames_done__``)."""
        return {"__parity__": np.int64(self.parity), "__frames_done__": np.int64(self.frames_done)}

    def load_host_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore :meth:`host_state`."""
        self.parity = int(state["__parity__"])
        self.frames_done = int(state["__frames_done__"])

    def state_dict(self) -> dict[str, np.ndarray]:
        """A copy of the filter's state after the last frame (:meth:`state_arrays` and :meth:`host_state`), for
        :meth:`load_state_dict`: restoring it into a filter built with the same configuration continues exactly as the
        original would have (the random streams are counter-based, keyed by the frame). Syncs with the device: not for
        the frame loop."""
        return {**arrays_state(self.state_arrays()), **self.host_state()}

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restore a :meth:`state_dict` into this filter (built with the same configuration).

        Raises:
            ConfigError: the state does not match this filter (names missing or unexpected, other shapes or types).
        """
        arrays = self.state_arrays()
        check_state(arrays, state, tuple(self.host_state()))
        load_arrays(arrays, state)
        self.load_host_state(state)
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
        super().__init__(device, use_graph)
        self.n = n
        self.seed = _seed_words(seed)
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

    def state_arrays(self) -> dict[str, wp.array]:
        """The point filter's state: both position and log-weight buffers, the ancestors and the resample flag the
        next prediction reads, the frame counter (it keys the random streams), and the per-frame parameters sigma and
        the ESS threshold (they may be changed between frames). The per-block partials, the estimate vector, the
        resampler's scratch and the subsample are written before they are read in every frame."""
        return {
            "x.0": self.x[0],
            "x.1": self.x[1],
            "logw.0": self.logw[0],
            "logw.1": self.logw[1],
            "ancestors": self.ancestors,
            "resampled": self.resampled,
            "frame": self.frame,
            "sigma": self.sigma,
            "ess_threshold": self.ess_threshold,
        }

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

    def launch_frame(self) -> None:
        """Launch one frame of the chain on the already uploaded observation without waiting for the device: the
        estimate reaches the host buffers once the device is synchronised (for trackers that run several filters per
        frame and synchronise once, :class:`wptrack.trackers.people.tracker.PeopleTracker`)."""
        src, dst = self.parity, 1 - self.parity
        self._run_chain(src, dst)
        self.parity = dst
        self.frames_done += 1

    def advance(self) -> Estimate:
        """Run one frame of the chain on the already uploaded observation and return the estimate."""
        t0 = time.perf_counter()
        frame = self.frames_done
        self.launch_frame()
        wp.synchronize_device(self.device)
        e = self.est_host.numpy()
        est = Estimate(
            frame=frame,
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
        return est
