"""One run loop for every tracker: frame source -> ``tracker.step`` -> run writers -> summary.

A tracker plugs into :func:`run_tracker` through a :class:`TrackerRun`: the job validates every input when it
is built (rig, videos, sizes, parameters, device), and the loop then owns what all runs share:

* the output folder (checked writable only after the job validated, so a bad input writes nothing),
* :class:`wptrack.io.run.RunWriter` (``tracks.csv`` appended per frame, ``run.json`` and ``particles.npz`` replaced
  atomically), with the job's extra writers opened in :meth:`TrackerRun.start` and always closed in
  :meth:`TrackerRun.finish`,
* frames decoded ahead by a background thread (:class:`wptrack.io.prefetch.prefetch`), the time the tracker waited
  for them recorded as the ``decode_wait`` stage, and the tracker's own per-stage timings; run.json's ``phases``:
  the kernel modules' load time before the first frame (``module_load_s``, compilation included when the cache
  missed them), the frame loop's wall time (``frame_loop_s``) and its start (``loop_start``, seconds since the
  epoch),
* the stage timeline (:mod:`wptrack.io.timeline`, run.json's ``timeline``): the wall time of every stage in every
  thread (``decode``, ``masks`` in the prefetch threads; ``upload``, ``filter``, ``record`` in the loop;
  ``write_*`` in the video writer threads), the waits between them (``wait_masks``: the filter waited for its
  masks; ``wait_decode``: the masks waited for decoding; ``*_blocked``: a producer held by a full queue) and how
  much of it overlapped,
* a tqdm progress bar,
* interruption: Ctrl-C (SIGINT) and SIGTERM stop the run after the frame in progress, with ``run.json`` status
  ``interrupted`` and the last frame written (``last_frame``); the outputs written so far stay valid,
* a source that ends before its announced length (a video truncated mid-stream): the frames up to the break are
  tracked and run.json's ``stopped_early`` says where (``{camera, frame, expected, reason}``; None otherwise),
* checkpoints: ``checkpoint.npz`` (the tracker's whole state after a frame and the job's summary inputs) every
  ``checkpoint_seconds`` and when interrupted, so ``resume=True`` (``--resume``) continues an interrupted or
  crashed run and gives the same outputs as an uninterrupted run (the random streams are counter-based, keyed by
  the frame).
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import time
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wptrack.io.rundir import clear_run_outputs, run_lock

log = logging.getLogger(__name__)

CHECKPOINT_FILE = "checkpoint.npz"
"""The state to resume an interrupted run from (``--resume``), in the run folder."""


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by a signal (SIGINT or SIGTERM). ``exit_code`` is the shell convention 128 + signal."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"interrupted by signal {signum}")
        self.signum = int(signum)
        self.exit_code = 128 + int(signum)


class _Stop:
    """The signal that asked the run to stop (0: none); set by the handlers of :func:`interruptible`."""

    signum = 0


@contextlib.contextmanager
def interruptible() -> Iterator[_Stop]:
    """Stop runs between frames on SIGINT (Ctrl-C) and SIGTERM.

    The first signal only sets the returned flag: the run loop finishes the frame in progress, writes a checkpoint
    and raises :class:`RunInterrupted`, so the outputs and the checkpoint describe the same last frame. A second
    signal raises :class:`RunInterrupted` at once. Only the main thread can install signal handlers; elsewhere the
    flag is never set and Ctrl-C raises KeyboardInterrupt wherever it lands.
    """
    stop = _Stop()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum: int, _frame: Any) -> None:
        if stop.signum:
            raise RunInterrupted(signum)
        stop.signum = signum
        log.warning("signal %d: stopping after the current frame (again to stop at once)", signum)

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for sig, h in previous.items():
            signal.signal(sig, h)


class TrackerRun:
    """What a tracker gives the run loop. Subclasses set the attributes and implement :meth:`frames`,
    :meth:`step` and :meth:`record`; the other hooks have defaults.

    Attributes:
        name: tracker name recorded in run.json (``color``, ``templates``, ``people``).
        columns: tracks.csv header, starting with ``frame, id, x, y, z``.
        config: the resolved run configuration recorded in run.json (inputs and tracker config).
        total: number of frames the source will give (None when unknown), for the progress bar.
        particles_every: keep the particle subsample of every this many frames in particles.npz (0: none).
        particles_max: at most this many particles per kept frame.
        particles_frames: at most this many frames of particles kept (evenly spaced over the run, see
            :class:`wptrack.io.run.ParticleStore`), so memory stays bounded however long the run.
    """

    name: str
    columns: Sequence[str]
    config: dict[str, Any]
    total: int | None = None
    source_stage: str | None = None
    """The timeline stage of producing one item of :meth:`frames` (``masks``, ``decode``; None: the source's own
    ``stage`` attribute, else ``source``)."""
    particles_every: int = 0
    particles_max: int = 2000
    particles_frames: int = 500

    def info(self) -> dict[str, Any]:
        """Extra run.json fields (device, seed, ...)."""
        return {}

    def frames(self) -> Iterable[Any]:
        """The per-frame observations, in order (decoded lazily: the loop prefetches them)."""
        raise NotImplementedError

    def start(self, out_dir: Path, resume_after: int | None = None) -> None:
        """Open the job's extra outputs in ``out_dir`` (called once the RunWriter exists). When resuming, keep
        what they hold up to frame ``resume_after`` and append to it."""

    def step(self, item: Any) -> Any:
        """Run the tracker on one observation and return its estimate (with a ``timings`` dict)."""
        raise NotImplementedError

    def record(self, est: Any, out: Any) -> None:
        """Write one frame's estimate: ``out.add_rows``, ``out.add_particles``, the job's extra files."""
        raise NotImplementedError

    def flush(self) -> None:
        """Make the job's extra outputs durable up to the last recorded frame (before a checkpoint)."""

    def finish(self) -> None:
        """Close the job's extra outputs (always called, also when the run is interrupted or fails)."""

    def summary(self) -> dict[str, Any]:
        """The run summary recorded in run.json and returned by :func:`run_tracker`."""
        return {}

    def stopped_early(self) -> dict[str, Any] | None:
        """Where the frame source ended before its reported length (a truncated video), or None: the
        ``stopped_early`` of the job's frame source (``self._frames``) or of its mask stream(s) (``self._masks``,
        ``self._stream``; a mask stream's ``source``). Recorded in run.json."""
        candidates = [getattr(self, "_frames", None), getattr(self, "_stream", None), *getattr(self, "_masks", [])]
        for obj in candidates:
            for src in (obj, getattr(obj, "source", None)):
                info = getattr(src, "stopped_early", None)
                if isinstance(info, dict):
                    return info
        return None

    def variable_rate(self) -> dict[str, Any] | None:
        """Where a video of the run first showed a variable frame rate (``VideoSource.variable_rate``, with its
        ``camera``), or None. Recorded in run.json (``variable_frame_rate``)."""
        candidates = [getattr(self, "_frames", None), getattr(self, "_stream", None), *getattr(self, "_masks", [])]
        for obj in candidates:
            for src in (obj, getattr(obj, "source", None), *getattr(obj, "sources", [])):
                info = getattr(src, "variable_rate", None)
                if isinstance(info, dict):
                    return {"camera": getattr(src, "name", "?"), **info}
        return None

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue after the last frame: the tracker's state (``self.tracker.state_dict()``)
        and the job's own accumulators (summary inputs) as NumPy arrays, keys prefixed ``job.``."""
        return self.tracker.state_dict()

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict` (into a job built with the same inputs and configuration)."""
        self.tracker.load_state_dict({k: v for k, v in state.items() if not k.startswith("job.")})


def _progress(total: int | None, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc="tracking", unit="frame", disable=not enabled, leave=False, dynamic_ncols=True)


def _flat(d: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(d, dict):
        return {prefix.rstrip("."): d}
    out: dict[str, Any] = {}
    for k, v in d.items():
        out.update(_flat(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v})
    return out


def describe_changes(tracker: str, before: dict[str, Any], now: dict[str, Any]) -> list[str]:
    """What differs between two run configurations, by command-line option where there is one:
    ``["--particles was 400, now 300", ...]`` (config paths such as ``tracker.occupancy.p_h`` otherwise)."""
    from wptrack.core.errors import ConfigError
    from wptrack.runs.spec import command, option_names

    def show(v: Any) -> str:
        text = "unset" if v is None else str(v)
        return text if len(text) <= 80 else text[:77] + "..."

    try:
        options = option_names(command(tracker))
    except ConfigError:  # a job that is no track command
        options = {}
    a, b = _flat(before), _flat(now)
    out: dict[str, str] = {}
    for key in sorted(set(a) | set(b)):
        if a.get(key) == b.get(key):
            continue
        name = options.get(key, key)
        out.setdefault(name, f"{name} was {show(a.get(key))}, now {show(b.get(key))}")
    return list(out.values())


def _check_resumable(job: TrackerRun, out_dir: Path) -> tuple[int | None, dict[str, Any]]:
    """The last frame and the state of the checkpoint in ``out_dir``, if ``job`` may resume that run; ``(None,
    {})`` when that run stopped before its first frame (nothing to continue: the run starts from the beginning)."""
    import json
    import zipfile

    from wptrack.core.errors import ConfigError
    from wptrack.io.atomic import jsonable
    from wptrack.io.run import RUN_FILE

    run_path = out_dir / RUN_FILE
    try:
        previous = json.loads(run_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise ConfigError(f"--resume: {run_path} is missing or unreadable: nothing to resume") from None
    if previous.get("status") == "complete":
        raise ConfigError(f"--resume: the run in {out_dir} is already complete")
    if previous.get("tracker") != job.name:
        raise ConfigError(f"--resume: {run_path} is a {previous.get('tracker')!r} run, not {job.name!r}")
    changed = describe_changes(job.name, previous.get("config", {}), jsonable(job.config))
    if changed:
        raise ConfigError(
            f"--resume: the configuration differs from the interrupted run in {out_dir}: {'; '.join(changed)}; "
            "resume with the same inputs and options (or start again with --overwrite)"
        )
    ckpt = out_dir / CHECKPOINT_FILE
    if not ckpt.exists():
        if previous.get("last_frame") is None:  # stopped before its first frame: start it from the beginning
            return None, {}
        raise ConfigError(
            f"--resume: {ckpt} not found (the run stopped before its first checkpoint); start again with --overwrite"
        )
    try:
        with open(ckpt, "rb") as fh, np.load(fh) as z:  # our handle: closed also when the archive is unreadable
            state = {k: z[k] for k in z.files}
        frame = int(state.pop("__run_frame__"))
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError) as e:
        raise ConfigError(
            f"--resume: the checkpoint {ckpt} is damaged ({type(e).__name__}: {e}; a full disk or a killed copy?) "
            "and cannot be continued from: run the command again without --resume, with --overwrite"
        ) from None
    return frame, state


def _write_checkpoint(job: TrackerRun, out: Any, frame: int) -> None:
    """Flush the outputs up to ``frame`` and save the state to continue after it (atomically)."""
    from wptrack.io.atomic import atomic_save_npz

    out.flush()
    job.flush()
    atomic_save_npz(out.out_dir / CHECKPOINT_FILE, __run_frame__=np.int64(frame), **job.state_dict())
    log.info("checkpoint after frame %d", frame)


def run_tracker(
    job: TrackerRun,
    out_dir: str | Path,
    progress: bool = False,
    max_frames: int | None = None,
    prefetch_depth: int = 4,
    resume: bool = False,
    checkpoint_seconds: float = 60.0,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Run ``job`` over its frames and write the run folder as it goes.

    Args:
        job: a validated :class:`TrackerRun`.
        out_dir: output folder (created if needed).
        progress: show a progress bar.
        max_frames: stop after this many frames (None: the whole source).
        prefetch_depth: frames decoded ahead by a background thread.
        resume: continue the interrupted run in ``out_dir`` from its checkpoint (same inputs and configuration):
            the frames up to the checkpoint are skipped, its later rows dropped, and the result is the same as
            an uninterrupted run's.
        checkpoint_seconds: write ``checkpoint.npz`` (the tracker's whole state, see ``FrameChain.state_dict``)
            at most this often while running, and always when interrupted; 0 only when interrupted. It is
            removed when the run completes.
        overwrite: ``out_dir`` may hold a previous run (its ``run.json``): remove what that run wrote
            (:data:`wptrack.io.rundir.RUN_OUTPUTS`) first. Without it such a folder is refused (unless ``resume``).

        The folder is locked while the run writes into it (:func:`run_lock`).

    Returns:
        The job's summary (also in run.json).

    Raises:
        OutputError: the folder cannot be written (before anything is written).
        RunInterrupted: SIGINT / SIGTERM (after a checkpoint); run.json then says ``interrupted``.
        ConfigError: ``resume`` without a resumable run of the same configuration in ``out_dir``; ``out_dir``
            holds a previous run and neither ``overwrite`` nor ``resume`` is given; another run holds the folder.
    """
    import math

    from wptrack.core.errors import ConfigError
    from wptrack.io.atomic import ensure_writable_dir
    from wptrack.io.run import RUN_FILE

    if (
        not (isinstance(checkpoint_seconds, (int, float)) and math.isfinite(checkpoint_seconds))
        or checkpoint_seconds < 0
    ):
        raise ConfigError(
            f"checkpoint interval: expected seconds >= 0 (0: only when interrupted), got {checkpoint_seconds!r}"
        )

    if resume and overwrite:
        raise ConfigError("--resume continues the run in --out, --overwrite replaces it: give one of them")
    if resume and not (Path(out_dir) / RUN_FILE).is_file():  # said before the folder is created (nothing left)
        raise ConfigError(f"--resume: {Path(out_dir) / RUN_FILE} is missing or unreadable: nothing to resume")
    created = not Path(out_dir).exists()
    out_dir = ensure_writable_dir(out_dir)
    try:
        with run_lock(out_dir):
            try:
                return _run_locked(
                    job, out_dir, progress, max_frames, prefetch_depth, resume, checkpoint_seconds, overwrite
                )
            except KeyboardInterrupt as e:  # what the CLI tells the user; a run stopped before its first frame
                e.run_dir = out_dir  # leaves nothing behind
                e.resumable = (out_dir / CHECKPOINT_FILE).exists()
                e.nothing_written = not e.resumable and _nothing_tracked(out_dir)
                if e.nothing_written:
                    clear_run_outputs(out_dir)
                raise
            except Exception as e:  # a bug: the CLI's message names the run (its run.json says 'failed')
                with contextlib.suppress(AttributeError, TypeError):
                    e.run_dir = out_dir
                raise
    except KeyboardInterrupt as e:
        if getattr(e, "nothing_written", False) and created:
            with contextlib.suppress(OSError):
                out_dir.rmdir()  # only if empty
        raise


def _nothing_tracked(out_dir: Path) -> bool:
    """Whether the run in ``out_dir`` stopped before it tracked a frame (run.json's ``last_frame`` is null)."""
    import json

    from wptrack.io.run import RUN_FILE

    try:
        return json.loads((out_dir / RUN_FILE).read_text(encoding="utf-8")).get("last_frame") is None
    except (OSError, ValueError):
        return True


def _run_locked(
    job: TrackerRun,
    out_dir: Path,
    progress: bool,
    max_frames: int | None,
    prefetch_depth: int,
    resume: bool,
    checkpoint_seconds: float,
    overwrite: bool,
) -> dict[str, Any]:
    """:func:`run_tracker` once the run folder is locked."""
    from wptrack.core.errors import ConfigError, WptrackError
    from wptrack.io import timeline
    from wptrack.io.run import RUN_FILE, RunWriter

    if not resume and (out_dir / RUN_FILE).exists():
        if not overwrite:
            raise ConfigError(
                f"{out_dir} holds a previous run ({RUN_FILE}); --overwrite replaces it, --resume continues an "
                "interrupted one, or choose another --out"
            )
        removed = clear_run_outputs(out_dir)
        log.info("--overwrite: removed %s from %s", ", ".join(removed), out_dir)
    after = None
    if resume:
        after, state = _check_resumable(job, out_dir)
        if after is None:
            log.warning(
                "--resume: the run in %s stopped before its first frame; starting it from the beginning", out_dir
            )
            clear_run_outputs(out_dir)
            resume = False
        else:
            try:
                job.load_state_dict(state)
            except (KeyError, ValueError, TypeError, IndexError, WptrackError) as e:
                why = str(e) if isinstance(e, WptrackError) else f"{type(e).__name__}: {e}"
                raise ConfigError(
                    f"--resume: the checkpoint {out_dir / CHECKPOINT_FILE} is damaged or of another version "
                    f"({why}) and cannot be continued from: run the command again without --resume, with --overwrite"
                ) from None
            log.info("resuming %s after frame %d", out_dir, after)
    start = 0 if after is None else after + 1
    total = job.total if max_frames is None or job.total is None else min(job.total, max_frames)
    with (
        interruptible() as stop,
        RunWriter(
            out_dir,
            job.name,
            job.columns,
            job.config,
            particles_every=job.particles_every,
            particles_max=job.particles_max,
            particles_frames=job.particles_frames,
            resume_from=after,
        ) as out,
    ):
        info = job.info()
        out.set_info(**info)
        job.start(out.out_dir, after)
        tracker = getattr(job, "tracker", None)
        t_load = time.perf_counter()
        if tracker is not None:  # compile the kernels missing from the cache now, not in the first frame's time
            import sys

            from wptrack.core.device import warm_up

            say = (lambda m: print(m, file=sys.stderr)) if progress else None
            warm_up(getattr(tracker, "kernel_modules", None), tracker.device, say=say)
        bar = _progress(total, progress)
        bar.update(start)
        # run.json "phases": what a run costs besides its frames (a batch's stage times, wptrack.batch)
        phases = {"module_load_s": time.perf_counter() - t_load, "loop_start": time.time()}
        t_loop = time.perf_counter()
        clock = timeline.Timeline()
        try:
            with timeline.active(clock):
                try:
                    _frame_loop(job, out, bar, stop, clock, start, max_frames, prefetch_depth, checkpoint_seconds)
                finally:
                    bar.close()
                    job.finish()  # the writer threads finish their queues here: on the timeline, in the wall time
                    clock.stop()
        finally:
            out.set_info(timeline=clock.summary(), variable_frame_rate=job.variable_rate())
            stopped = job.stopped_early()
            out.set_info(stopped_early=stopped)  # None: the source gave every frame it announced
            if stopped:
                log.warning(
                    "the frames ended early: %s at frame %d (%s)",
                    stopped["camera"],
                    stopped["frame"],
                    stopped["reason"],
                )
        out.set_info(phases={**phases, "frame_loop_s": time.perf_counter() - t_loop})
        summary = job.summary()
        out.close(
            "complete",
            summary,
            min_track_frames=getattr(job, "min_track_frames", 1),
            finish_tracks=getattr(job, "finish_tracks", None),
        )
    (out_dir / CHECKPOINT_FILE).unlink(missing_ok=True)
    return summary


def _frame_loop(
    job: TrackerRun,
    out: Any,
    bar: Any,
    stop: _Stop,
    clock: Any,
    start: int,
    max_frames: int | None,
    prefetch_depth: int,
    checkpoint_seconds: float,
) -> None:
    """The frames of :func:`run_tracker`: source (decoded ahead) -> ``job.step`` -> ``job.record``, with the
    timings, the progress bar, checkpoints and the stop signal."""

    from wptrack.io import timeline

    with timeline.thread_cpu("main"):
        _frames(job, out, bar, stop, clock, start, max_frames, prefetch_depth, checkpoint_seconds)


def _frames(
    job: TrackerRun,
    out: Any,
    bar: Any,
    stop: _Stop,
    clock: Any,
    start: int,
    max_frames: int | None,
    prefetch_depth: int,
    checkpoint_seconds: float,
) -> None:
    import itertools

    from wptrack.io.prefetch import prefetch

    last_checkpoint = time.monotonic()
    source = job.frames()
    stage = job.source_stage or getattr(source, "stage", None) or "source"
    frames = itertools.islice(source, start, max_frames)  # decoded and skipped when resuming
    clock.source = stage
    clock.start()
    t_wait = time.perf_counter()
    # "decode_wait": the time the tracker waited for the next decoded frame (the timeline's wait_<stage>)
    for item in prefetch(frames, depth=prefetch_depth, name=stage):
        t_step = time.perf_counter()
        clock.item()
        out.add_timing("decode_wait", t_step - t_wait)
        est = job.step(item)
        t_record = time.perf_counter()
        job.record(est, out)
        out.frame_done(est.frame)
        t_done = time.perf_counter()
        for name, seconds in est.timings.items():
            out.add_timing(name, seconds)
        step_s = t_record - t_step
        filter_s = min(est.timings.get("filter", step_s), step_s)
        upload_s = min(est.timings.get("upload", step_s - filter_s), step_s - filter_s)
        clock.add("filter", filter_s)
        clock.add("upload", upload_s)  # the observation's host work and copy to the device
        if step_s - filter_s - upload_s > 1e-4:
            clock.add("step_other", step_s - filter_s - upload_s)  # e.g. the people tracker's population update
        clock.add("record", t_done - t_record)
        bar.update(1)
        if stop.signum:
            _write_checkpoint(job, out, est.frame)
            raise RunInterrupted(stop.signum)
        if checkpoint_seconds > 0 and time.monotonic() - last_checkpoint >= checkpoint_seconds:
            _write_checkpoint(job, out, est.frame)
            last_checkpoint = time.monotonic()
        t_wait = time.perf_counter()
