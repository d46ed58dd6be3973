"""Offline background model of a whole recording (``MaskConfig.method == "offline"``), on Warp kernels.

Offline processing may look at the whole recording before making any mask, so the background of frame ``t`` is
estimated from frames before *and after* it: an object standing still at the start is in the background only for
as long as it stands still, and leaves no ghost once it moves (an online model such as MOG2 has learnt it into
the background by then, and marks the uncovered road as foreground for a while). The condition: a pixel's
background is what it shows in most of its window's samples, so an object is left out of it when it stands on
that pixel for less than about half of the window (choose ``window`` longer than twice the longest stand that
must stay foreground).

Design (kernels and formulas: :mod:`wptrack.kernels.core.background`; the windows and their reader:
:mod:`wptrack.motion.windows`; the host statistics of the samples: :mod:`wptrack.motion.stats`; local illumination:
:mod:`wptrack.motion.illumination`):

* **Windows.** The recording of ``T`` frames is covered by windows of ``L = window`` frames whose starts are spaced
  evenly, about ``L / 2`` apart (half overlap), the first starting at frame 0 and the last ending at frame ``T``.
  Window ``i`` samples ``K = min(samples, L)`` frames evenly inside itself and its background is the per-pixel
  temporal median of those ``K`` frames, with the per-channel MAD as its noise estimate. Its centre is the mean
  of its sample indices. A recording shorter than ``L`` gets one window over all of it (a log warning says so);
  with fewer than 3 frames the median cannot reject anything that stands still (another warning).
* **Drift.** Frame ``t`` uses the background and MAD interpolated linearly between the two windows whose centres
  bracket it (before the first centre / after the last: that window alone), so slow illumination changes are
  followed with a lag of at most a window, without steps at window boundaries.
* **Passes.** Windows are built lazily while the frames are streamed (the mask pass): a second reader fetches the ``K``
  sampled frames of the next window when frame ``t`` first needs it, so only two windows' backgrounds are held. It seeks
  only across gaps of :data:`~wptrack.motion.windows.SEEK_GAP` frames or more (an OpenCV seek decodes about 16 frames
  before its target) and grabs the frames in between otherwise, keeping on its way the samples of the following window
  (which overlaps this one by half), so it reads forward and decodes each frame about once: with the defaults (a sample
  every 12 frames) a video costs at most one extra decoding pass (0.6 of the decoding time of a 600-frame 640x480 FFV1
  video on the CI machine, where seeking to every sample cost 2.9); an image sequence, or samples more than
  :data:`SEEK_GAP` apart, about ``K / (L / 2)`` extra decoded frames per frame. The exact frame a seek lands on does not
  matter: the median is robust to a sample being a frame off. That reading runs ahead in one worker thread: when the
  mask pass builds window ``i``, the worker starts reading (and preparing with NumPy) window ``i + 1``'s samples, so the
  extra decoding overlaps the per-frame work on another core (:class:`OfflineBackground`; the same reads in the same
  order, so the same masks). The windows after the first are also *built* by a worker ahead of the frames
  (:func:`wptrack.motion.parallel.build_ahead`), so the masks do not stall for a build. On a host with cores to spare
  (:func:`wptrack.motion.windows.sample_readers`) several captures read a window's samples of an intra-coded video at
  once, in contiguous groups (the same frames: such seeks are exact), so the first window, read before the first
  mask, comes sooner.
* **Gains.** Each window's samples and each frame get a global gain per channel (illumination changes), the median
  of their ratios to the background over a pixel subsample: every 13th pixel for the windows, thinned to at most
  :data:`~wptrack.motion.stats.GAIN_PIXELS` for a frame (the same pixels up to 425,984 pixels per frame, e.g.
  640x480; at 1920x1080 every 65th pixel).
* **Spread cap.** Each window also records the image-wide median of its per-pixel noise scales (on a pixel
  subsample); with ``MaskConfig.spread_cap`` the per-pixel scale is capped at that many times it, so an object
  standing in a large minority of a window's samples does not hide itself by inflating its pixels' MAD.
* **Local illumination** (issue 26; ``MaskConfig.illum_*``): a local light field the frame is divided by and a
  veto of what a patch's texture explains as a light change (cloud shadows, exposure, lights switched on in part of
  the view), and each window's samples divided by their own field before its statistics
  (:class:`wptrack.motion.illumination.LightField`).
* **Densest samples** (``MaskConfig.mode_band``; short recordings with people in most frames): the background of a
  window is, per pixel, the median of its densest cluster of samples (those within ``mode_band`` noise scales of
  the sample with the most such neighbours) instead of the median of all: moving people differ from sample to
  sample, the background does not, so a pixel covered in most samples keeps its background
  (:func:`~wptrack.kernels.core.background.mode_kernel`). People who *stand* for most of a short clip are one dense
  cluster too; but they move (sway, gestures), so a sample whose patch changed from both neighbouring samples by
  more than ``MaskConfig.mode_still`` noise scales counts 1/8 in the cluster (:meth:`OfflineBackground._sample_motion`):
  the few still samples of the uncovered ground outweigh them (a 100-frame PETS excerpt: two people standing by the
  sign for 85 of its frames were background, MOTA 0.70 -> 0.87; docs/notes.md).
* **Hysteresis.** With ``MaskConfig.fg_low``, the kernel marks weak foreground (``fg_low < z <= fg_threshold``)
  beside the strong; :func:`hysteresis` keeps the weak pixels 8-connected to a strong one (OpenCV connected
  components on the host, where the mask goes anyway).
* **Host work per frame** (the kernels are cheap; what costs is on the host): the frame's gain (bounded by
  :data:`GAIN_PIXELS`), the hysteresis (one labelling of the foreground, then work on the weak pixels only) and
  one copy of the probability for the caller. On CUDA the frame goes up and the mask and probability come down
  through pinned buffers allocated once (one wait per frame, for the results).

Length: one class on purpose: a window's life (read, build, share between threads, drop) and the per-frame test read
the same state (the windows' device arrays and host statistics, the share's locks); the kernels, the sampler, the
statistics and the light field are in their own modules already.
"""

from __future__ import annotations

import contextlib
import logging
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import wait as wait_futures
from typing import Any

import numpy as np

from wptrack.core.device import download
from wptrack.core.errors import FrameError
from wptrack.io.frames import FrameSource
from wptrack.motion.illumination import LightField
from wptrack.motion.levels import resolve_levels
from wptrack.motion.stats import (
    GAIN_PIXELS,
    SCALE_STEP,
    channel_gains,
    median_last,
    motion_radius,
    neighbourhood_picks,
    neighbourhood_scale,
    sample_gains_channels,
    shadow_ratio,
    spread_scale,
)
from wptrack.motion.windows import WindowShare, _Sampler, _WindowRead, bracket, plan_windows

STILL_FPS = 25.0
"""Frame rate assumed for :meth:`OfflineBackground._still_lag` when the source has none (arrays, image folders)."""

STILL_NOISE = 2.0
"""A still sample's change may reach this many times the window's median sample change (over every
:data:`~wptrack.motion.stats.SCALE_STEP`-th pixel, the noise scale's subsample; most pixels are background most of
the time, so that median is the noise's own change): in noisy video the ground's samples differ by their noise (the
largest channel's change of a gaussian noise of standard deviation s averages ~1.9 s, above ``mode_still`` noise
scales), and a noise-free object (a clipped black coat) must not count as stiller than the ground."""

log = logging.getLogger(__name__)


class OfflineBackground:
    """Windowed median/MAD background of one source and the per-frame foreground evidence.

    Args:
        source: The camera's frames.
        config: A ``MaskConfig`` (fields ``window``, ``samples``, ``fg_threshold``, ``fg_low``, ``spread_cap``,
            ``soft_scale``, ``noise_floor``, ``detect_shadows``, ``shadow_lo``, ``shadow_hi``, ``shadow_chroma``).
        device: Warp device alias.

    Attributes:
        windows: The background windows (:func:`plan_windows`).
        centres: Their centres, frames.

    Use :meth:`evidence` frame by frame in time order (a restart at frame 0 is allowed); windows are built when
    first needed and dropped when no later frame needs them.

    Prefetch: when :meth:`evidence` builds window ``i``, one worker thread (created on first use, joined by
    :meth:`close`) starts reading window ``i + 1``'s samples (decoding: OpenCV releases the GIL) and preparing
    them with NumPy (subsample, gains, medians), while the frames before it are processed; building ``i + 1``
    then takes that read. The worker touches only the sampler and NumPy: every Warp launch, allocation and copy
    stays in the calling thread (trackers capture CUDA graphs there). The sampler is used by one thread at a time
    and reads the same frames in the same order as without the worker, so the masks are the same; its warnings
    are logged, and its errors raised, by the calling thread when it takes the read. A request for another window
    first waits for (or cancels) the pending read and drops it. :meth:`background` and :meth:`spread` do not
    prefetch. Several models in threads (:class:`~wptrack.motion.windows.WindowShare`, ``share``) share the windows,
    the sampler and the worker; there a build worker builds each window after the first from the reader's read (a
    builder model of the share, its device work in the device guard's shared section like the mask threads').
    """

    def __init__(self, source: FrameSource, config: Any, device: str, share: WindowShare | None = None) -> None:
        import warp as wp

        from wptrack.kernels.core import background as kbg

        self.source = source
        self.config = config
        self.device = device
        # the windows' plan, shared with the other models of the source (its warnings are said once, by the first)
        self._share = WindowShare(source) if share is None else share
        plan = (len(source), int(config.window), int(config.samples))
        if self._share.windows is None:
            self._share.windows = plan_windows(*plan, source.name)
            self._share.plan = plan
        elif self._share.plan != plan:  # an internal misuse: models sharing windows must plan them alike
            raise ValueError(f"a WindowShare planned for {self._share.plan} (frames, window, samples), not {plan}")
        self.windows = self._share.windows
        self.centres = [w.centre for w in self.windows]
        self.pixels = source.width * source.height
        n3 = 3 * self.pixels
        on_cpu = wp.get_device(device).is_cpu
        # CUDA: the frame goes up and the results come down through pinned host buffers (allocated once, copied
        # asynchronously, one wait per frame); CPU: the kernel reads the caller's frame and writes arrays that
        # NumPy views share
        self._frame = None if on_cpu else wp.zeros(n3, dtype=wp.uint8, device=device)
        self._stage_in = None if on_cpu else wp.empty(n3, dtype=wp.uint8, device="cpu", pinned=True)
        self._stage_mask = None if on_cpu else wp.empty(self.pixels, dtype=wp.uint8, device="cpu", pinned=True)
        self._stage_prob = None if on_cpu else wp.empty(self.pixels, dtype=wp.float32, device="cpu", pinned=True)
        staged = (self._stage_in, self._stage_mask, self._stage_prob)
        self._stage_views = None if on_cpu else [a.numpy() for a in staged]  # NumPy views of the pinned buffers
        self._mask = wp.zeros(self.pixels, dtype=wp.uint8, device=device)
        self._prob = wp.zeros(self.pixels, dtype=wp.float32, device=device)
        self._shadow = wp.zeros(self.pixels, dtype=wp.uint8, device=device)
        self._diff = wp.zeros(self.pixels, dtype=wp.vec3, device=device)
        self._packed = wp.zeros(self.pixels, dtype=wp.uint8, device=device) if config.neighbourhood else None
        self._rows = wp.zeros(self.pixels, dtype=wp.vec4, device=device) if config.neighbourhood else None
        # the built windows and their statistics (self._share, above): this model's own, or shared with the other
        # models of the source (WindowShare: each window built once)
        self._built = self._share.built
        self._scale = self._share.scale  # image-wide median noise scale of each built window
        self._nb_scale = self._share.nb_scale  # neighbourhood_scale of each built window
        self._ratio = self._share.ratio  # learnt shadow ratio of each built window (None: not learnt)
        # channel values of a pixel subsample (every 13th pixel) for the windows' gains (illumination changes) and
        # shadow ratios: flat indices pixel-major (3 P',) and channel-major (3, P')
        pixels = np.arange(0, self.pixels, 13)
        self._sub = (3 * pixels[:, None] + np.arange(3)[None, :]).reshape(-1)
        self._sub_channels = np.ascontiguousarray(self._sub.reshape(-1, 3).T)
        # a frame's gain: every m-th pixel of that subsample, at most GAIN_PIXELS pixels
        self._gain_step = max(1, math.ceil(len(pixels) / GAIN_PIXELS))
        self._gain_index = np.ascontiguousarray(self._sub_channels[:, :: self._gain_step])
        self._bg_sub = self._share.bg_sub  # each window's (3, P') compensated median at the subsample
        self._bg_gain = self._share.bg_gain  # ... at the frame gain's pixels
        self.last_gain = np.ones(3)  # the global gain of the last frame given to evidence() (B, G, R)
        self._stacks: dict[int, Any] = {}
        self._motion: dict[int, tuple] = {}  # two (K, P) uint8 buffers per window size: the samples' patch changes
        self._no_motion: Any = None  # (1, 1) stand-in when mode_still is off
        self._prefetch = True  # False: every window read in the calling thread (tests compare the two)
        # issue 27 (opt-in, wptrack.motion.masks.MotionMasks.attach_cleanup): a DeviceCleanup makes evidence() resolve
        # and clean the mask on the device and download it instead of the levels
        self.cleanup: Any = None
        self.want_prob = True
        """False: evidence() neither computes the foreground probability (the logistic per pixel) nor downloads it,
        and returns None for it (iterating MotionMasks, as the trackers do, asks for the mask only)."""
        self.on_build: Callable[[int, float, np.ndarray], None] | None = None
        """Called as ``on_build(window, centre, background)`` when a window is built (in the thread that asked
        for it), with its ``(H, W, 3)`` uint8 BGR background: e.g. a run saving the backgrounds for its report."""
        p = kbg.ForegroundParams()
        p.threshold = float(config.fg_threshold)
        p.low_threshold = float(config.fg_low) if config.fg_low > 0 else float(config.fg_threshold)
        p.spread_cap = 0.0
        p.soft_scale = float(config.soft_scale)
        p.noise_floor = float(config.noise_floor)
        p.shadow = int(bool(config.detect_shadows))
        p.shadow_lo = float(config.shadow_lo)
        p.shadow_hi = float(config.shadow_hi)
        p.shadow_edge_hi = float(config.shadow_hi)
        p.chroma_max = float(config.shadow_chroma)
        self.params = p
        self.light = LightField(config, source.width, source.height, p, device)
        # the shadow votes' pixels (the subsample above) on the device, for their texture test
        self._sub_pixels = (
            wp.array(pixels.astype(np.int32), dtype=wp.int32, device=device) if self.light.textured_votes else None
        )
        # CUDA: the subsample's channel values gathered on the device (a build downloads those, not its whole stack)
        self._sub_columns = (
            None if on_cpu else wp.array(self._sub_channels.reshape(-1).astype(np.int32), dtype=wp.int32, device=device)
        )
        self._sub_stacks: dict[int, Any] = {}  # (K, 3 P') uint8 device buffers by window size

    @property
    def _sampler(self) -> _Sampler:
        return self._share.sampler

    @property
    def _executor(self) -> ThreadPoolExecutor | None:
        return self._share.executor

    @_executor.setter
    def _executor(self, value: ThreadPoolExecutor | None) -> None:
        self._share.executor = value

    @property
    def _pending(self) -> tuple[int, Future] | None:
        return self._share.pending

    @_pending.setter
    def _pending(self, value: tuple[int, Future] | None) -> None:
        self._share.pending = value

    def _read(self, i: int) -> _WindowRead:
        """Read window ``i``'s samples and prepare them on the host (any thread; no Warp call: see the class)."""
        with self._share.read_lock:
            return self._read_unlocked(i)

    def _read_unlocked(self, i: int) -> _WindowRead:
        ahead = self.windows[i + 1].samples if i + 1 < len(self.windows) else ()
        notes: list[tuple[Any, ...]] = []
        self._sampler.notes = notes
        try:
            frames = [np.ascontiguousarray(f) for f in self._sampler.read(self.windows[i].samples, ahead)]
            if not frames:
                return _WindowRead(frames, notes=notes)
            sub = np.empty((len(frames), *self._sub_channels.shape), dtype=np.uint8)
            for r, f in enumerate(frames):
                sub[r] = f.reshape(-1)[self._sub_channels]
            gains, bg_sub = sample_gains_channels(sub)
            bg_gain = np.ascontiguousarray(bg_sub[:, :: self._gain_step])
            return _WindowRead(frames, sub, gains, bg_sub, bg_gain, notes)
        except Exception as e:  # noqa: BLE001 - raised by the thread that takes the read, after its warnings
            return _WindowRead([], notes=notes, error=e)
        finally:
            self._sampler.notes = None

    def _take(self, i: int) -> _WindowRead:
        """Window ``i``'s read: the worker's when it was prefetched, else read now (a pending read of another
        window is cancelled, or waited for and dropped, first: the sampler serves one thread at a time)."""
        if self._share.ahead is not None:  # the pending task (if any) is the builder's, for another window
            got = self._read(i)
        else:
            with self._share.lock:
                pending, self._pending = self._pending, None
            if pending is not None and pending[0] == i:
                got = pending[1].result()
            else:
                if pending is not None and not pending[1].cancel():
                    wait_futures([pending[1]])
                got = self._read(i)
        for note in got.notes:
            log.warning(*note)
        if got.error is not None:
            raise got.error
        return got

    def _submit(self, i: int) -> None:
        """Start reading window ``i``'s samples in the worker (unless built, pending or past the last); with a
        builder (:attr:`WindowShare.ahead`) the worker also builds it (:meth:`_build_ahead`), at most two windows
        beyond the frames' (device memory stays bounded on long recordings)."""
        share = self._share
        with share.lock:
            if not self._prefetch or i >= len(self.windows) or i in share.built or i in share.building:
                return
            if share.ahead is not None and i > max(share.positions.values(), default=0) + 2:
                return
            if share.pending is not None:
                if share.pending[0] not in share.built:
                    return  # a read still to be taken
                share.pending[1].cancel()  # its window was built without it (read again): drop it
            if share.executor is None:
                share.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wptrack-background")
            if share.ahead is not None:
                share.building[i] = threading.Event()  # claimed by the builder: the models wait for it
                share.failed.pop(i, None)
                if share.build_executor is None:
                    share.build_executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wptrack-build")
                read = share.executor.submit(share.ahead._read, i)  # the reader reads on while a window is built
                share.pending = (i, share.build_executor.submit(share.ahead._build_ahead, i, read))
            else:
                share.pending = (i, share.executor.submit(self._read, i))

    def _build_ahead(self, i: int, read: Future) -> None:
        """The build worker's task: build window ``i`` from its ``read`` (the reader's; this model is the share's
        builder, its device work inside the device guard's shared section as the mask threads' is), then release the
        models waiting for it. The next window's read starts when this build starts."""
        share = self._share
        with share.lock:
            if share.pending is not None and share.pending[0] == i:
                share.pending = None  # taken by this task: the build's prefetch may submit the next window
        try:
            got = read.result()
            with share.guard.shared():
                self._build(i, prefetch=True, got=got)
        except BaseException as e:  # noqa: BLE001 - raised by the models that wait for the window
            with share.lock:
                share.failed[i] = e
        finally:
            with share.lock:
                share.building.pop(i).set()

    def _window(self, i: int, prefetch: bool = False) -> tuple[Any, Any]:
        """``(median, mad)`` device arrays of window ``i`` (built on first use; with ``prefetch``, building it
        starts the worker's read of window ``i + 1``). With a shared :class:`WindowShare` the first model that needs
        a window builds it and the others wait for it."""
        share = self._share
        with share.lock:
            done = share.built.get(i)
            waiting = share.building.get(i) if done is None else None
            if done is None and waiting is None:
                share.building[i] = threading.Event()
                share.failed.pop(i, None)
        if done is not None:
            self._log_notes(i)
            if prefetch:  # built by another call (e.g. background(0) for a report): the next read still starts here
                self._submit(i + 1)
            return done
        if waiting is not None:  # another model builds it: wait, then use it
            if share.guard is not None:
                with share.guard.paused():  # the builder's device work may wait for a capture that waits for us
                    waiting.wait()
            else:
                waiting.wait()
            self._log_notes(i)
            with share.lock:
                if i in share.failed:
                    raise share.failed[i]
                if i in share.built:
                    return share.built[i]
            return self._window(i, prefetch)  # built and already dropped (a restart): build it again
        try:
            return self._build(i, prefetch)
        except BaseException as e:
            with share.lock:
                share.failed[i] = e
            raise
        finally:
            with share.lock:
                share.building.pop(i).set()

    def _log_notes(self, i: int) -> None:
        """Log, in the calling thread, the warnings of window ``i``'s build ahead (by the share's builder), once: the
        model that takes the window first logs them, as it would have logged its own build's."""
        with self._share.lock:
            notes = self._share.notes.pop(i, ())
        for note in notes:
            log.warning(*note)

    def _build(self, i: int, prefetch: bool, got: _WindowRead | None = None) -> tuple[Any, Any]:
        """Build window ``i`` (this model claimed it in its :class:`WindowShare`) from its read ``got`` (None: take
        it); ``(median, mad)``. A build ahead (``got`` given, by the share's builder) keeps its warnings for the model
        that takes the window (:meth:`_log_notes`): a window built ahead that no frame needs logs nothing."""
        import warp as wp

        ahead = got is not None
        notes: list[tuple] = []
        if got is None:
            with self._host_part():
                got = self._take(i)
        else:
            notes.extend(got.notes)
            with self._share.lock:
                self._share.notes[i] = notes  # read by the models after this build (they wait for it)
            if got.error is not None:
                raise got.error
        frames = got.frames
        if not frames:
            if self._built:
                note = ("%s: no frame of background window %d could be read; reusing another", self.source.name, i)
                if ahead:
                    notes.append(note)
                else:
                    log.warning(*note)
                m = max(self._built)
                for stats in (self._bg_sub, self._bg_gain, self._scale, self._nb_scale, self._ratio):
                    if m in stats:
                        stats[i] = stats[m]
                return self._built[m]
            raise FrameError(f"{self.source.name}: no frame of background window {i} could be read")
        if prefetch:
            self._submit(i + 1)  # the worker reads on while this window is built and its frames processed
        k = len(frames)
        n3 = 3 * self.pixels
        stack = self._stacks.get(k)
        if stack is None:
            stack = self._stacks[k] = wp.zeros((k, n3), dtype=wp.uint8, device=self.device)
        for r, f in enumerate(frames):
            flat = f.reshape(-1)
            wp.copy(stack, wp.array(flat, dtype=wp.uint8, device="cpu", copy=False), dest_offset=r * n3, count=n3)
        sub, gains = got.sub, got.gains
        self._bg_sub[i], self._bg_gain[i] = got.bg_sub, got.bg_gain
        median = wp.zeros(3 * self.pixels, dtype=wp.uint8, device=self.device)
        mad = wp.zeros(3 * self.pixels, dtype=wp.uint8, device=self.device)
        g = wp.array(gains, dtype=wp.vec3, device=self.device)
        c = self.config
        compensate = bool(self.light.tiles and c.illum_windows)
        # the last median/MAD pass before the densest cluster's serves only the image-wide noise scale of its band
        # (spread_scale: every SCALE_STEP-th pixel's MAD), so it computes those pixels only
        self._median_mad(stack, g, median, mad, SCALE_STEP if c.mode_band > 0 and not compensate else 1)
        if compensate:
            # each sample under its own light: divide it by its global gain and local field against this first
            # median, then the statistics again (unit gains) on what now differs only by what moved
            cap = float(c.spread_cap * spread_scale(download(mad))) if c.spread_cap > 0 else 0.0
            self.light.compensate(stack, gains, median, mad, cap)
            ones = wp.array(np.ones((k, 3), dtype=np.float32), dtype=wp.vec3, device=self.device)
            self._median_mad(stack, ones, median, mad, SCALE_STEP if c.mode_band > 0 else 1)
            if c.mode_band > 0:
                self._mode(i, stack, ones, mad, median)
            frames, sub = self._compensated_samples(stack, neighbourhood_picks(k) if c.neighbourhood > 0 else [])
            with self._host_part():
                gains = np.ones((k, 3), dtype=np.float32)
                bg_sub = median_last(np.moveaxis(sub, 0, -1).astype(np.float64))
                self._bg_sub[i], self._bg_gain[i] = bg_sub, np.ascontiguousarray(bg_sub[:, :: self._gain_step])
        elif c.mode_band > 0:
            self._mode(i, stack, g, mad, median)
        if c.spread_cap > 0 or c.shadow_band > 0 or c.neighbourhood > 0:
            mad_host = download(mad)
            median_host = download(median) if c.neighbourhood > 0 else None
            with self._host_part():
                self._scale[i] = spread_scale(mad_host)
            nb_scale: Future | None = None
            if c.neighbourhood > 0:  # host work only: in a thread of its own, beside the shadow votes' device work
                shape = (self.source.height, self.source.width, 3)
                pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wptrack-nbscale")
                nb_scale = pool.submit(
                    neighbourhood_scale,
                    [None if f is None else f.reshape(shape) for f in frames], gains, median_host.reshape(shape),
                    mad_host.reshape(shape), c.neighbourhood, c.noise_floor,
                )  # fmt: skip
                pool.shutdown(wait=False)
            try:
                self._learn_shadows(i, stack, gains, median, mad, sub, mad_host)
            except BaseException:
                if nb_scale is not None:
                    wait_futures([nb_scale])  # the thread ends before the error leaves the build
                raise
            if nb_scale is not None:
                with self._host_part():
                    self._nb_scale[i] = nb_scale.result()
                log.info(
                    "%s: background window %d: neighbourhood noise scale %.2f", self.source.name, i, self._nb_scale[i]
                )
        log.debug("%s: background window %d from %d frames", self.source.name, i, k)
        with self._share.lock:  # last: another model takes a built window's statistics without waiting
            self._built[i] = (median, mad)
        if self.on_build is not None:
            image = download(median).reshape(self.source.height, self.source.width, 3).copy()
            with self._host_part():
                self.on_build(i, float(self.centres[i]), image)
        return median, mad

    def _learn_shadows(
        self, i: int, stack: Any, gains: np.ndarray, median: Any, mad: Any, sub: np.ndarray, mad_host: np.ndarray
    ) -> None:
        """Window ``i``'s learnt shadow ratio (``shadow_band`` with ``detect_shadows``; :func:`shadow_ratio` of the
        subsample ``sub`` ``(K, 3, P')``, its votes kept by the light field's texture test where that is on)."""
        c = self.config
        if not (c.shadow_band > 0 and c.detect_shadows):
            return
        keep = None
        if self.light.textured_votes:  # only votes that keep the ground's texture (not dark clothes)
            cap = float(c.spread_cap * self._scale[i]) if c.spread_cap > 0 else 0.0
            keep = self.light.sample_patches(stack, gains, median, mad, self._sub_pixels, cap)
        with self._host_part():
            ratio = shadow_ratio(
                sub.transpose(0, 2, 1), gains, self._bg_sub[i].T, mad_host[self._sub].reshape(-1, 3),
                c.fg_threshold, c.noise_floor, c.shadow_chroma, keep=keep, sharp=c.shadow_peak,
            )  # fmt: skip
        self._ratio[i] = ratio
        log.info("%s: background window %d: learnt shadow ratio %s", self.source.name, i, ratio)

    def _compensated_samples(self, stack: Any, picks: list[int]) -> tuple[list[np.ndarray | None], np.ndarray]:
        """The host data a window's statistics need of its compensated samples ``stack`` (``(K, 3 H W)`` uint8):
        ``(frames, sub)``, the samples ``picks`` as flat ``(3 H W,)`` arrays (None for the others) and the
        subsample's channel values ``(K, 3, P')``. On CUDA only those are downloaded (the subsample gathered on the
        device, :func:`~wptrack.kernels.core.background.gather_columns_kernel`): at 1920x1080 the whole stack is 155
        MB, whose download and indexing took ~0.25 s of each window build on an H100 host (issue 27: the first
        window's build is the start-up of every run)."""
        import warp as wp

        from wptrack.kernels.core import background as kbg

        k = stack.shape[0]
        if self._sub_columns is None:  # the CPU: the stack is host memory already
            host = download(stack)
            with self._host_part():
                sub = np.ascontiguousarray(
                    host[:, self._sub_channels.reshape(-1)].reshape(k, *self._sub_channels.shape)
                )
            return [host[r] if r in picks else None for r in range(k)], sub
        buf = self._sub_stacks.get(k)
        if buf is None:
            buf = self._sub_stacks[k] = wp.empty((k, self._sub_columns.shape[0]), dtype=wp.uint8, device=self.device)
        wp.launch(kbg.gather_columns_kernel, dim=buf.shape, inputs=[stack, self._sub_columns], outputs=[buf],
                  device=self.device)  # fmt: skip
        sub = download(buf).reshape(k, *self._sub_channels.shape)
        frames: list[np.ndarray | None] = [download(stack[r]) if r in picks else None for r in range(k)]
        return frames, sub

    def _median_mad(self, stack: Any, gains: Any, median: Any, mad: Any, step: int) -> None:
        """Per-channel median and MAD of a window's samples (:func:`~wptrack.kernels.core.background.
        median_mad_kernel`) into ``median`` and ``mad``, at every ``step``-th pixel (the others left as they are)."""
        import warp as wp

        from wptrack.kernels.core import background as kbg

        dim = 3 * ((self.pixels + step - 1) // step)
        wp.launch(kbg.median_mad_kernel, dim=dim, inputs=[stack, gains, step], outputs=[median, mad],
                  device=self.device)  # fmt: skip

    def _host_part(self) -> Any:
        """Context of a build's host-only work (reading samples, NumPy statistics, writing images), entered with no
        device work of this thread in flight: it gives up the thread's shared section of the device guard
        (:meth:`wptrack.core.device.DeviceGuard.paused`) so that a tracker's graph capture waiting for it does not
        hold every mask thread back for a window build's host seconds (issue 27: in a 1080p profile the tracker's two
        captures waited 3.2 s in all)."""
        guard = self._share.guard
        return guard.paused() if guard is not None else contextlib.nullcontext()

    def _mode(self, i: int, stack: Any, gains: Any, mad: Any, median: Any) -> None:
        """Rebuild a window's ``median`` and ``mad`` (device arrays, in place) as the densest cluster of each pixel's
        samples (:func:`wptrack.kernels.core.background.mode_kernel`), the band ``mode_band`` times the image-wide noise
        scale of the window's first ``mad`` (at least the noise floor), the samples that moved weighing 1/8 (a still
        sample changed by at most ``mode_still`` times that scale, or :data:`STILL_NOISE` times the window's median
        change if that is more, from the sample :meth:`_still_lag` before or after it)."""
        import warp as wp

        from wptrack.kernels.core import background as kbg

        c = self.config
        scale = max(c.noise_floor, spread_scale(download(mad)))
        band = float(c.mode_band * scale)
        k = stack.shape[0]
        lag = self._still_lag(i)
        still = float(c.mode_still * scale) if c.mode_still > 0 and k > lag else 0.0
        motion = self._sample_motion(stack, gains, lag) if still > 0 else self._dummy_motion()
        if still > 0:  # above the noise's own change: the median change of the window's pixels (mostly background)
            changes = download(motion)[lag:, ::SCALE_STEP]
            with self._host_part():
                still = max(still, STILL_NOISE * float(np.median(changes)))
            log.info(
                "%s: background window %d: densest cluster of samples; one that changed by more than %.1f levels from "
                "both samples %d away counts 1/8", self.source.name, i, still, lag,
            )  # fmt: skip
        wp.launch(kbg.mode_kernel, dim=self.pixels, inputs=[stack, gains, band, motion, lag, still],
                  outputs=[median, mad], device=self.device)  # fmt: skip

    def _still_lag(self, i: int) -> int:
        """Samples between the two that :meth:`_sample_motion` compares in window ``i``: ``MaskConfig.mode_lag``
        seconds (at the source's frame rate, :data:`STILL_FPS` when it has none) over the window's mean sample gap,
        rounded, at least 1 and at most half the window's samples (so that every sample has another ``lag`` away):
        neighbouring samples (1) for every window of 100 frames or more at 25 frames/s; a 40-frame clip sampled every
        1.6 frames compares samples 3 apart (a plain coat's inside does not change in 1.6 frames; the ground between
        two passers is seen for no longer)."""
        samples = self.windows[i].samples
        gap = (samples[-1] - samples[0]) / (len(samples) - 1) if len(samples) > 1 else 1.0
        fps = self.source.fps or STILL_FPS
        lag = round(self.config.mode_lag * fps / max(gap, 1.0))
        return max(1, min(lag, len(samples) // 2))  # at most half the samples: every sample has one lag away

    def _dummy_motion(self) -> Any:
        """A ``(1, 1)`` stand-in for :func:`mode_kernel`'s ``motion`` when it is not read (``still`` 0)."""
        import warp as wp

        if self._no_motion is None:
            self._no_motion = wp.zeros((1, 1), dtype=wp.uint8, device=self.device)
        return self._no_motion

    def _sample_motion(self, stack: Any, gains: Any, lag: int) -> Any:
        """Each window sample's change from the sample ``lag`` before it (:func:`~wptrack.kernels.core.background.
        sample_change_kernel`), averaged over a square patch of radius :func:`~wptrack.motion.stats.motion_radius`
        (two box passes): a ``(K, P)`` uint8 device array, rows ``< lag`` unused. The patch mean reaches a little way
        into a plain coat, whose inside changes little from one sample to the next while its outline does."""
        import warp as wp

        from wptrack.kernels.core import background as kbg

        k = stack.shape[0]
        h, w = self.source.height, self.source.width
        bufs = self._motion.get(k)
        if bufs is None:
            bufs = self._motion[k] = tuple(wp.zeros((k, self.pixels), dtype=wp.uint8, device=self.device) for _ in "ab")
        a, b = bufs
        rad = motion_radius(w, h)
        wp.launch(kbg.sample_change_kernel, dim=(k - lag, self.pixels), inputs=[stack, gains, lag], outputs=[a],
                  device=self.device)  # fmt: skip
        wp.launch(kbg.box_mean_kernel, dim=(k, h), inputs=[a, w, h, 1, w, rad], outputs=[b], device=self.device)
        wp.launch(kbg.box_mean_kernel, dim=(k, w), inputs=[b, h, w, w, 1, rad], outputs=[a], device=self.device)
        return a

    def shadow_bounds(self, i: int, j: int, w: float) -> tuple[float, float]:
        """Brightness-ratio bounds of the cast-shadow (umbra) test between windows ``i`` and ``j`` (weight ``w`` of
        ``j``): the learnt ratio ``r`` (interpolated; a window that learnt none uses the other's) gives
        ``[max(r - band, 0.05), min(r + band, shadow_hi)]``: one sky and one sun darken every cast shadow of the
        scene by about ``r``, so nothing darker than ``r - band`` is one of them, whatever ``shadow_lo`` says (deep
        sun shadows below it are removed; under an overcast sky, ``r`` near 0.9 as on the PETS clip, dark neutral
        clothes at 0.6-0.7, which the fixed bounds took for shadow, stay foreground). Ratios above the band, up to
        ``shadow_hi``, are penumbra candidates (shadow only where attached to an umbra, :func:`resolve_levels`).
        No learnt ratio: the configured ``[shadow_lo, shadow_hi]``.

        The ratio is learnt from the votes that keep the ground's texture (``MaskConfig.shadow_texture``,
        :meth:`wptrack.motion.illumination.LightField.sample_patches`) where there are enough of them: dark neutral
        clothes on a grey floor vote too, and where they outnumber the shadows (the EPFL terrace and Oxford
        TownCentre: learnt 0.33-0.47, the band then ate trousers and coats) they taught the band their own ratio; a
        cast shadow darkens the ground's texture, clothes replace it (TownCentre at 1080p: 0.87 from the textured
        votes). A floor too flat for the test at the sampled pixels keeps every vote (the terrace at 360x288, PETS).

        Until 2026-11-24 the learnt ratio could lower ``shadow_lo`` but not raise it, because raising it on the
        PETS clip made the darker shadows at the people's feet foreground and the joint template filter then lost
        MOTA (0.24 -> 0.05); with the partitioned filter (``TemplateConfig.partition``) the fuller legs are worth
        more than the feet's shadow costs (docs/notes.md, round five)."""
        c = self.config
        ri, rj = self._ratio.get(i), self._ratio.get(j)
        if ri is None and rj is None:
            return float(c.shadow_lo), float(c.shadow_hi)
        r = (1.0 - w) * (ri if ri is not None else rj) + w * (rj if rj is not None else ri)
        lo = max(r - c.shadow_band, 0.05)
        return float(lo), float(max(min(r + c.shadow_band, c.shadow_hi), lo))

    def background(self, i: int = 0) -> np.ndarray:
        """``(H, W, 3)`` uint8 BGR background of window ``i`` (builds it if needed)."""
        median, _ = self._window(i)
        return download(median).reshape(self.source.height, self.source.width, 3).copy()

    def spread(self, i: int = 0) -> np.ndarray:
        """``(H, W, 3)`` uint8 per-channel MAD of window ``i`` (8-bit units)."""
        _, mad = self._window(i)
        return download(mad).reshape(self.source.height, self.source.width, 3).copy()

    def evidence(self, t: int, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Foreground of frame ``t``.

        Args:
            t: Frame index.
            frame: ``(H, W, 3)`` uint8 BGR.

        Returns:
            ``(mask, prob)``: ``(H, W)`` uint8 mask (1 = foreground, shadows excluded, after the hysteresis, not
            cleaned) and ``(H, W)`` float32 foreground probability (None with :attr:`want_prob` False: not
            computed).
        """
        import warp as wp

        from wptrack.kernels.core import background as kbg

        i, j, w = bracket(self.centres, t)
        self._share.drop_before(self, i)
        b0, m0 = self._window(i, prefetch=True)
        b1, m1 = self._window(j, prefetch=True)
        flat = np.ascontiguousarray(frame, dtype=np.uint8).reshape(-1)
        if flat.size != 3 * self.pixels:  # the kernel reads 3 H W values where the frame is
            raise FrameError(
                f"{self.source.name}: frame {t} has shape {np.shape(frame)}, expected "
                f"({self.source.height}, {self.source.width}, 3) uint8"
            )
        if self._stage_in is None:
            frame_in = wp.array(flat, dtype=wp.uint8, device="cpu", copy=False)
        else:  # the upload runs while the host computes the gain
            self._stage_views[0][:] = flat
            wp.copy(self._frame, self._stage_in)
            frame_in = self._frame
        bg = self._bg_gain[i] if w == 0.0 else (1.0 - w) * self._bg_gain[i] + w * self._bg_gain[j]
        gain = channel_gains(flat[self._gain_index][None], bg)[0]
        self.last_gain = gain
        if self.config.spread_cap > 0:
            self.params.spread_cap = float(self.config.spread_cap * ((1.0 - w) * self._scale[i] + w * self._scale[j]))
        if self.config.shadow_band > 0:
            self.params.shadow_lo, self.params.shadow_hi = self.shadow_bounds(i, j, w)
        if self.light.active:
            self.light.measure(frame_in, wp.vec3(*gain), b0, m0, b1, m1, w)
        light = self.light  # the veto computes its candidates' patch statistics from the frame's rows and luma
        self.params.no_prob = int(not self.want_prob)  # not asked for: no logistic per pixel, no download
        inputs = [frame_in, b0, m0, b1, m1, w, wp.vec3(*gain), self.params, light.local, light.rows, light.luma]
        outputs = [light.patch, self._mask, self._prob, self._shadow, self._diff]
        wp.launch(kbg.foreground_kernel, dim=self.pixels, inputs=[*inputs, int(self.config.illum_patch),
                  self.source.height], outputs=outputs, device=self.device)  # fmt: skip
        packed = self._mask
        if self._packed is not None:
            r = int(self.config.neighbourhood)
            width, height = self.source.width, self.source.height
            run = int(kbg.RUN)
            wp.launch(
                kbg.neighbourhood_rows_kernel,
                dim=height * ((width + run - 1) // run),
                inputs=[self._mask, self._diff, width, height, r],
                outputs=[self._rows],
                device=self.device,
            )
            scale = float((1.0 - w) * self._nb_scale[i] + w * self._nb_scale[j])
            backs = [b0, m0, b1, m1, w, self.params]  # the neighbourhood's shadow-like test (kernel docstring)
            wp.launch(
                kbg.neighbourhood_kernel,
                dim=width * ((height + run - 1) // run),
                inputs=[self._mask, self._rows, width, height, r, self.params.low_threshold, scale, *backs],
                outputs=[self._packed],
                device=self.device,
            )
            packed = self._packed
        shape = (self.source.height, self.source.width)
        if self.cleanup is not None:  # the clean-up on the device: one mask (and the probability if asked) down
            mask_dev = self.cleanup(packed.reshape(shape), self._prob.reshape(shape) if self.want_prob else None)
            if self._stage_mask is None:
                mask_host, prob = mask_dev.numpy().reshape(-1), self._prob.numpy()
            else:
                wp.copy(self._stage_mask, mask_dev.reshape(-1))
                if self.want_prob:
                    wp.copy(self._stage_prob, self._prob)
                wp.synchronize_stream(wp.get_stream(self.device))
                mask_host, prob = self._stage_views[1], self._stage_views[2]
            prob = prob.reshape(shape).copy() if self.want_prob else None
            return mask_host.reshape(shape).copy(), prob
        if self._stage_mask is None:
            levels = packed.numpy()
            prob = self._prob.numpy() if self.want_prob else None
        else:
            wp.copy(self._stage_mask, packed)
            if self.want_prob:
                wp.copy(self._stage_prob, self._prob)
            wp.synchronize_stream(wp.get_stream(self.device))
            levels, prob = self._stage_views[1], self._stage_views[2] if self.want_prob else None
        if prob is not None:
            prob = prob.reshape(shape).copy()  # the caller's own (the buffers are overwritten by the next frame)
        return resolve_levels(levels.reshape(shape), prob), prob

    def close(self) -> None:
        """Stop and join the prefetch worker (a read in progress stops at its next frame and is dropped) and
        release the sampler's video reader. The model stays usable: a later call reads again (a new worker)."""
        pending, self._pending = self._pending, None
        if pending is not None and pending[1].cancel() and self._share.ahead is not None:
            with self._share.lock:  # a build that will not run: release its claim
                event = self._share.building.pop(pending[0], None)
            if event is not None:
                event.set()
        if self._executor is not None or self._share.build_executor is not None:
            self._sampler.stop.set()
            try:
                for executor in (self._share.build_executor, self._executor):
                    if executor is not None:
                        executor.shutdown(wait=True, cancel_futures=True)
            finally:
                self._executor = self._share.build_executor = None
                self._sampler.stop.clear()
        self._sampler.close()
