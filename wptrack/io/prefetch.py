"""Frames decoded ahead by a background thread (:class:`prefetch`), so decoding overlaps tracking; bounded memory,
errors re-raised in the consumer."""

from __future__ import annotations


class prefetch:  # noqa: N801 - used like a function: ``for frame in prefetch(frames): ...``
    """Iterate over ``source`` with a background thread decoding up to ``depth`` items ahead.

    Video decoding (OpenCV releases the GIL) then overlaps with the tracker's device work. Items come out in
    order; an exception raised by the source is re-raised in the consumer at the position it occurred; leaving
    the loop early (``break``, an exception, Ctrl-C) stops the thread at its next item.

    Args:
        source: any iterable (e.g. :class:`SyncedFrames`).
        depth: queue length (frames decoded ahead); bounded so memory stays small.
    """

    _END = object()

    def __init__(self, source, depth: int = 4) -> None:
        import queue
        import threading

        if depth < 1:
            raise ValueError(f"prefetch depth must be >= 1, got {depth}")
        self._source = source
        self._queue: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="wptrack-prefetch", daemon=True)
        self._thread.start()

    def __len__(self) -> int:
        return len(self._source)

    def _put(self, item) -> bool:
        import queue

        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def _run(self) -> None:
        try:
            for item in self._source:
                if not self._put((item, None)):
                    return
        except BaseException as e:  # noqa: BLE001 - handed to the consumer
            self._put((None, e))
            return
        self._put((self._END, None))

    def __iter__(self):
        try:
            while True:
                item, error = self._queue.get()
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
