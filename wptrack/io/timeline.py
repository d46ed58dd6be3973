"""The stage timeline of a run: wall time spent per stage in every thread of the pipeline (decode, masks, upload,
filter, writers) and the waits between them, so a run can say where its time went and how much of it overlapped.

A :class:`Timeline` is thread-safe. The run loop (:func:`wptrack.runs.loop.run_tracker`) makes one per run and
makes it the active one (:func:`active`) while the run goes; the pipeline's parts record into whatever timeline is
active (:func:`record`, a no-op when none is): the decode-ahead threads (:class:`wptrack.io.prefetch.prefetch`: the
time spent producing each item, the time blocked on a full queue, the time the consumer waited), the background
video writers (:class:`wptrack.io.video.BackgroundWriter`) and the loop itself. One run at a time per process
(the active timeline is global; ``wptrack batch`` runs each run in its own process).

run.json's ``timeline`` (:meth:`Timeline.summary`): per stage the total seconds, the count, the mean in ms and the
share of the run's wall time; ``wall_s`` (from the first frame asked for to the last frame written) and
``overlap``: the busy stages' total over the wall time (1: one stage at a time; 2: two threads busy on average);
``source``: the stage the run loop takes its items from (``wait_<source>``: the time the filter waited for them);
``first_item_s``: the start-up, from the first frame asked for to the first item the loop got (the first frames
decoded, an offline background's first window read and built, the first mask made), and ``after_first_per_s`` the
items per second after it (the steady rate a long recording approaches);
``cpu_s``: the CPU time of each of the pipeline's threads (``main``: the loop; ``decode``, ``masks``: the prefetch
threads; ``write_*``: the writers) and ``process`` (every thread of the process, OpenCV's and the background
model's workers included). On a shared machine the wall times of the stages include the time other processes had
the cores; the CPU times do not, so together they tell what a free machine would do: a run needs at least its
busiest thread's CPU time, and its process CPU time over the cores.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Iterator
from typing import Any

WAIT_PREFIX = "wait_"
"""Stages named ``wait_*`` (a consumer waiting for a producer) and ``*_blocked`` (a producer waiting for room in a
full queue) are idle time: left out of ``overlap``."""

BLOCKED_SUFFIX = "_blocked"


def is_wait(stage: str) -> bool:
    """Whether ``stage`` is idle time (a wait or a blocked producer), not work."""
    return stage.startswith(WAIT_PREFIX) or stage.endswith(BLOCKED_SUFFIX)


class Timeline:
    """Total wall time and count per stage, added to from any thread.

    Attributes:
        started: ``time.perf_counter()`` when the timeline was made (or :meth:`start` last called).
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._stages: dict[str, list[float]] = {}
        self._cpu: dict[str, float] = {}
        self.started = time.perf_counter()
        self.stopped: float | None = None
        self._process_cpu = time.process_time()
        self._process_cpu_end: float | None = None
        self.source: str | None = None  # the stage the run loop consumes (its wait is wait_<source>)
        self.first: float | None = None  # time.perf_counter() when the run loop got its first item (item())
        self.items = 0  # items the run loop got

    def start(self) -> None:
        """Start the wall clock now (the run's first frame is asked for)."""
        self.started = time.perf_counter()
        self.stopped = None
        self.first, self.items = None, 0
        self._process_cpu = time.process_time()
        self._process_cpu_end = None

    def stop(self) -> None:
        """Stop the wall clock now (the run's last frame is written)."""
        self.stopped = time.perf_counter()
        self._process_cpu_end = time.process_time()

    def item(self) -> None:
        """The run loop got an item (a frame's observation): the first one ends the pipeline's start-up (the first
        frames decoded, an offline background's first window read and built, the first mask made)."""
        now = time.perf_counter()
        with self._lock:
            if self.first is None:
                self.first = now
            self.items += 1

    def add_cpu(self, thread: str, seconds: float) -> None:
        """Add ``seconds`` of CPU time of the pipeline thread ``thread`` (``time.thread_time`` differences)."""
        with self._lock:
            self._cpu[thread] = self._cpu.get(thread, 0.0) + float(seconds)

    def add(self, stage: str, seconds: float, count: int = 1) -> None:
        """Add ``seconds`` of ``stage`` (``count`` items)."""
        with self._lock:
            entry = self._stages.get(stage)
            if entry is None:
                self._stages[stage] = [float(seconds), count]
            else:
                entry[0] += float(seconds)
                entry[1] += count

    def total(self, stage: str) -> float:
        """Total seconds of ``stage`` so far (0 when never recorded)."""
        with self._lock:
            entry = self._stages.get(stage)
            return entry[0] if entry else 0.0

    def summary(self) -> dict[str, Any]:
        """``{"wall_s", "overlap", "stages": {stage: {"total_s", "count", "mean_ms", "share"}}}`` (see the module)."""
        end = self.stopped if self.stopped is not None else time.perf_counter()
        wall = max(end - self.started, 1e-9)
        with self._lock:
            items = sorted(self._stages.items())
        stages = {
            name: {
                "total_s": round(total, 6),
                "count": int(count),
                "mean_ms": round(1000.0 * total / count, 4) if count else 0.0,
                "share": round(total / wall, 4),
            }
            for name, (total, count) in items
        }
        busy = sum(total for name, (total, _) in items if not is_wait(name))
        with self._lock:
            cpu = {name: round(seconds, 6) for name, seconds in sorted(self._cpu.items())}
        end_cpu = self._process_cpu_end if self._process_cpu_end is not None else time.process_time()
        cpu["process"] = round(end_cpu - self._process_cpu, 6)
        out = {"wall_s": round(wall, 6), "overlap": round(busy / wall, 3), "stages": stages, "cpu_s": cpu}
        if self.source is not None:
            out["source"] = self.source
        if self.first is not None:  # the start-up, and the rate of the frames after the first
            out["first_item_s"] = round(self.first - self.started, 6)
            if self.items > 1 and end > self.first:
                out["after_first_per_s"] = round((self.items - 1) / (end - self.first), 3)
        return out


_active: Timeline | None = None


def current() -> Timeline | None:
    """The active timeline, or None."""
    return _active


def record_cpu(thread: str, seconds: float) -> None:
    """Add to the active timeline's CPU time of ``thread`` (nothing when no timeline is active)."""
    timeline = _active
    if timeline is not None:
        timeline.add_cpu(thread, seconds)


@contextlib.contextmanager
def thread_cpu(thread: str) -> Iterator[None]:
    """Record the CPU time the calling thread spends inside the block as ``thread`` (:func:`record_cpu`)."""
    t0 = time.thread_time()
    try:
        yield
    finally:
        record_cpu(thread, time.thread_time() - t0)


def record(stage: str, seconds: float, count: int = 1) -> None:
    """Add to the active timeline's ``stage`` (nothing when no timeline is active)."""
    timeline = _active
    if timeline is not None:
        timeline.add(stage, seconds, count)


@contextlib.contextmanager
def active(timeline: Timeline) -> Iterator[Timeline]:
    """Make ``timeline`` the active one inside the block (the previous one again after it)."""
    global _active
    previous, _active = _active, timeline
    try:
        yield timeline
    finally:
        _active = previous
