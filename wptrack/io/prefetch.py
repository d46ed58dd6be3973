"""Frames decoded ahead by a background thread (:class:`prefetch`), so decoding overlaps tracking; bounded memory,
errors re-raised in the consumer; the time each side spent working and waiting goes to the run's timeline
(:mod:`wptrack.io.timeline`)."""

from __future__ import annotations

import queue
import threading
import time
from typing import Any

from wptrack.io import timeline

POLL_S = 0.1
"""Seconds a blocked queue operation waits before it looks at its stop event again."""


def put_until(q: queue.Queue, item: Any, stop: threading.Event) -> bool:
    """Put ``item`` into ``q``, waiting while it is full; False (not put) once ``stop`` is set."""
    while not stop.is_set():
        try:
            q.put(item, timeout=POLL_S)
            return True
        except queue.Full:
            continue
    return False


def get_until(q: queue.Queue, stop: threading.Event, default: Any = None) -> Any:
    """The next item of ``q``, waiting while it is empty; ``default`` once ``stop`` is set."""
    while not stop.is_set():
        try:
            return q.get(timeout=POLL_S)
        except queue.Empty:
            continue
    return default


class prefetch:  # noqa: N801 - used like a function: ``for frame in prefetch(frames): ...``
    """Iterate over ``source`` with a background thread decoding up to ``depth`` items ahead.

    Video decoding (OpenCV releases the GIL) then overlaps with the tracker's device work. Items come out in
    order; an exception raised by the source is re-raised in the consumer at the position it occurred; leaving
    the loop early (``break``, an exception, Ctrl-C) stops the thread at its next item.

    Args:
        source: any iterable (e.g. :class:`SyncedFrames`).
        depth: queue length (frames decoded ahead); bounded so memory stays small: at most ``depth`` items in
            the queue and one in the producer's hands.
        name: the stage recorded in the active timeline (:mod:`wptrack.io.timeline`): ``name`` the time spent
            producing each item (in ``source``'s ``__next__``), ``name_blocked`` the time the producer waited for
            room in a full queue, ``wait_name`` the time the consumer waited for an item. Default: the source's
            ``stage`` attribute (``decode`` for frame sources), else ``source``.
    """

    _END = object()

    def __init__(self, source, depth: int = 4, name: str | None = None) -> None:
        import queue
        import threading

        if depth < 1:
            raise ValueError(f"prefetch depth must be >= 1, got {depth}")
        self._source = source
        self.name = name or getattr(source, "stage", None) or "source"
        self.depth = int(depth)
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="wptrack-prefetch", daemon=True)
        self._thread.start()

    def __len__(self) -> int:
        return len(self._source)

    def _put(self, item) -> bool:
        import queue

        try:
            self._queue.put_nowait(item)
            return True
        except queue.Full:
            pass
        t0 = time.perf_counter()
        try:
            return put_until(self._queue, item, self._stop)
        finally:
            timeline.record(self.name + timeline.BLOCKED_SUFFIX, time.perf_counter() - t0)

    def _run(self) -> None:
        with timeline.thread_cpu(self.name):
            self._produce()

    def _produce(self) -> None:
        stage = self.name
        try:
            it = iter(self._source)
            while True:
                t0 = time.perf_counter()
                try:
                    item = next(it)
                except StopIteration:
                    break
                timeline.record(stage, time.perf_counter() - t0)
                if not self._put((item, None)):
                    close = getattr(it, "close", None)
                    if close is not None:
                        close()
                    return
        except BaseException as e:  # noqa: BLE001 - handed to the consumer
            self._put((None, e))
            return
        self._put((self._END, None))

    def __iter__(self):
        wait = timeline.WAIT_PREFIX + self.name
        try:
            while True:
                t0 = time.perf_counter()
                item, error = self._queue.get()
                timeline.record(wait, time.perf_counter() - t0)
                if error is not None:
                    raise error
                if item is self._END:
                    return
                yield item
        finally:
            self.close()

    def close(self) -> None:
        """Stop the background thread (idempotent)."""
        self._stop.set()
        self._thread.join(timeout=5.0)
