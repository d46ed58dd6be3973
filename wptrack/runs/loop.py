"""One run loop for every tracker: frame source -> ``tracker.step`` -> run writers -> summary.

A tracker plugs into :func:`run_tracker` through a :class:`TrackerRun`: the job validates every input when it
is built (rig, videos, sizes, parameters, device), and the loop then owns what all runs share:

* the output folder (checked writable only after the job validated, so a bad input writes nothing),
* :class:`wptrack.io.RunWriter` (``tracks.csv`` appended per frame, ``run.json`` and ``particles.npz`` replaced
  atomically), with the job's extra writers opened in :meth:`TrackerRun.start` and always closed in
  :meth:`TrackerRun.finish`,
* frames decoded ahead by a background thread (:class:`wptrack.frames.prefetch`), the time the tracker waited
  for them recorded as the ``decode_wait`` stage, and the tracker's own per-stage timings,
* a tqdm progress bar,
* interruption: Ctrl-C (SIGINT) and SIGTERM end the run with ``run.json`` status ``interrupted`` and the last
  frame written (``last_frame``); the outputs written so far stay valid.
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

log = logging.getLogger(__name__)


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by a signal (SIGINT or SIGTERM). ``exit_code`` is the shell convention 128 + signal."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"interrupted by signal {signum}")
        self.signum = int(signum)
        self.exit_code = 128 + int(signum)


@contextlib.contextmanager
def interruptible() -> Iterator[None]:
    """Turn SIGTERM into :class:`RunInterrupted` while the block runs (SIGINT already raises KeyboardInterrupt).

    Only the main thread can install signal handlers; elsewhere the block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, _frame: Any) -> None:
        raise RunInterrupted(signum)

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


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
    """

    name: str
    columns: Sequence[str]
    config: dict[str, Any]
    total: int | None = None
    particles_every: int = 0
    particles_max: int = 2000

    def info(self) -> dict[str, Any]:
        """Extra run.json fields (device, seed, ...)."""
        return {}

    def frames(self) -> Iterable[Any]:
        """The per-frame observations, in order (decoded lazily: the loop prefetches them)."""
        raise NotImplementedError

    def start(self, out_dir: Path) -> None:
        """Open the job's extra outputs in ``out_dir`` (called once the RunWriter exists)."""

    def step(self, item: Any) -> Any:
        """Run the tracker on one observation and return its estimate (with a ``timings`` dict)."""
        raise NotImplementedError

    def record(self, est: Any, out: Any) -> None:
        """Write one frame's estimate: ``out.add_rows``, ``out.add_particles``, the job's extra files."""
        raise NotImplementedError

    def finish(self) -> None:
        """Close the job's extra outputs (always called, also when the run is interrupted or fails)."""

    def summary(self) -> dict[str, Any]:
        """The run summary recorded in run.json and returned by :func:`run_tracker`."""
        return {}


def _progress(total: int | None, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc="tracking", unit="frame", disable=not enabled, leave=False, dynamic_ncols=True)


def run_tracker(
    job: TrackerRun,
    out_dir: str | Path,
    progress: bool = False,
    max_frames: int | None = None,
    prefetch_depth: int = 4,
) -> dict[str, Any]:
    """Run ``job`` over its frames and write the run folder as it goes.

    Args:
        job: a validated :class:`TrackerRun`.
        out_dir: output folder (created if needed).
        progress: show a progress bar.
        max_frames: stop after this many frames (None: the whole source).
        prefetch_depth: frames decoded ahead by a background thread.

    Returns:
        The job's summary (also in run.json).

    Raises:
        OutputError: the folder cannot be written (before anything is written).
        RunInterrupted / KeyboardInterrupt: SIGTERM / Ctrl-C; run.json then says ``interrupted``.
    """
    from ..frames import prefetch
    from ..io import RunWriter, ensure_writable_dir

    out_dir = ensure_writable_dir(out_dir)
    total = job.total if max_frames is None or job.total is None else min(job.total, max_frames)
    with (
        interruptible(),
        RunWriter(
            out_dir,
            job.name,
            job.columns,
            job.config,
            particles_every=job.particles_every,
            particles_max=job.particles_max,
        ) as out,
    ):
        out.set_info(**job.info())
        job.start(out.out_dir)
        bar = _progress(total, progress)
        try:
            t_wait = time.perf_counter()
            # "decode_wait": the time the tracker waited for the next decoded frame
            for k, item in enumerate(prefetch(job.frames(), depth=prefetch_depth)):
                if max_frames is not None and k >= max_frames:
                    break
                out.add_timing("decode_wait", time.perf_counter() - t_wait)
                est = job.step(item)
                job.record(est, out)
                out.frame_done(est.frame)
                for stage, seconds in est.timings.items():
                    out.add_timing(stage, seconds)
                bar.update(1)
                t_wait = time.perf_counter()
        finally:
            bar.close()
            job.finish()
        summary = job.summary()
        out.close("complete", summary)
    return summary
