"""Offline motion masks made by several threads at once, in frame order (issue 27: the mask step is the slowest
stage of a GPU run at 1080p, mostly host work per frame in one thread).

:func:`parallel_evidence` gives the frames of a :class:`wptrack.motion.masks.MotionMasks` round robin to ``W``
worker threads, each with an :class:`wptrack.motion.background.OfflineBackground` of its own (the first is the
stream's ``model``, so its ``on_build`` callback and its windows serve the caller as before), and yields the masks in
frame order. A frame's evidence depends on that frame and the windows around it only, and the models share their
windows (:class:`wptrack.motion.background.WindowShare`: each built once, by the first model that needs it, from the
samples one shared reader reads in the same order as for one model; the windows after the first are read by that
reader's worker thread and built by a build worker, ahead of the frames that need them), so the masks are those of
one model, frame for frame (tested). The cost: ``W`` times a model's per-frame device buffers. Queues of 2 per
worker bound the memory. Errors (the source's, a model's) are raised in the caller at the frame they concern; leaving
the iteration early stops the threads.

Opt-in (``WPTRACK_MASK_WORKERS=N``, :func:`mask_workers`): measured on the CPU only, where the mask step is not the
slowest stage of a run (the filter is) and extra models cost the two cores more than they save.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterable, Iterator
from typing import Any

import numpy as np

from wptrack.core.errors import FrameError
from wptrack.io import timeline
from wptrack.io.prefetch import get_until, put_until

MASK_WORKERS_ENV = "WPTRACK_MASK_WORKERS"
"""Environment variable: threads making the offline masks of one video (default: :func:`mask_workers`)."""

GPU_MASK_WORKERS = 3
"""Mask threads by default when the masks are made on a CUDA device and the host has >= 8 cores. H100 host (16
cores), ``wptrack bench --tracker pipeline`` 1080p MJPG, 600 frames: ``track templates --video`` 47.3 frames/s with
one thread, 64.1 with three (the masks thread was the limit: 19 ms of CPU per frame); the masks command alone 39.8 and
41.3 (it is limited by writing masks.avi). On the CPU device they cost more than they save (BENCHMARKS.md)."""

_END = object()


def mask_workers(device: str | None = None) -> int:
    """Threads making one video's offline masks: :data:`MASK_WORKERS_ENV` when set, else
    :data:`GPU_MASK_WORKERS` on a CUDA ``device`` of a host with >= 8 cores, else 1."""
    from wptrack.core.config import env_count, host_cores

    gpu_host = device is not None and device.startswith("cuda") and host_cores() >= 8
    return env_count(MASK_WORKERS_ENV, GPU_MASK_WORKERS if gpu_host else 1)


def build_ahead(model: Any, guard: Any) -> Any:
    """Make the windows of ``model``'s :class:`~wptrack.motion.background.WindowShare` after the first read by its
    reader and built by a build worker, ahead of the frames that need them: a second model of the same source (the
    builder; its ``on_build`` is the model's) becomes the share's ``ahead``. Without it a model builds a window when
    its first frame needs it, and the masks wait for the build (~1 s of CPU per 480x360 window with the defaults; at
    1080p ~1 s on an H100 host): the frames after it stall while one core builds. The same windows, so the same
    masks. The cost: the builder's buffers (its light field's above all: ``wptrack masks`` on the 1080p TownCentre
    clip peaks at 1.36 GB of resident memory instead of 1.11). Undo with :func:`stop_building_ahead`.

    Args:
        model: The stream's :class:`~wptrack.motion.background.OfflineBackground`.
        guard: Its device guard (a tracker's graph capture waits for the builder's device work).

    Returns:
        The builder.
    """
    from wptrack.motion.background import OfflineBackground

    share = model._share
    with guard.shared():
        builder = OfflineBackground(model.source, model.config, model.device, share=share)
    builder.on_build = model.on_build  # whichever model builds a window reports it
    share.guard, share.ahead = guard, builder
    return builder


def stop_building_ahead(model: Any, builder: Any) -> None:
    """Close the ``builder`` of :func:`build_ahead` (a read or build in progress ends first) and leave ``model`` to
    build its windows alone again."""
    try:
        builder.close()
    finally:
        model._share.ahead = model._share.guard = None


def parallel_evidence(
    masks: Any, frames: Iterable[np.ndarray], workers: int, clean: Any, probability: bool = True
) -> Iterator[tuple[np.ndarray, np.ndarray | None]]:
    """``(mask, prob)`` per frame of ``frames`` (the decoded frames of ``masks.source``, in order), as
    :meth:`wptrack.motion.masks.MotionMasks.evidence` yields them, made by ``workers`` threads (see the module).

    Args:
        masks: The :class:`~wptrack.motion.masks.MotionMasks` (offline method); its ``model`` is the first worker's.
        frames: Its frames, in order.
        workers: Threads (>= 2).
        clean: The clean-up of a model's raw mask (``clean_mask`` with the stream's config).
        probability: Yield the probability image (else None).
    """
    from wptrack.core.device import device_guard
    from wptrack.motion.background import OfflineBackground

    c = masks.config
    width, height = masks.size
    guard = device_guard(masks.model.device)  # a tracker's graph capture waits for the workers' device work
    with guard.shared():
        share = masks.model._share  # each window built once, by the first model that needs it (WindowShare)
        models = [masks.model] + [
            OfflineBackground(masks.source, c, masks.model.device, share=share) for _ in range(workers - 1)
        ]
    for model in models[1:]:  # the first model's clean-up and probability settings for every model
        masks.attach_cleanup(model)
        model.want_prob = masks.model.want_prob
        model.on_build = masks.model.on_build  # whichever model builds a window reports it
    # the windows after the first are read by the reader and built by a build worker, ahead of their frames (a build
    # in a mask thread held the others back: at 1080p ~1 s per window on an H100 host)
    builder = build_ahead(masks.model, guard)
    stop = threading.Event()
    inbox = [queue.Queue(maxsize=2) for _ in range(workers)]
    outbox = [queue.Queue(maxsize=2) for _ in range(workers)]

    def put(q: queue.Queue, item: Any) -> bool:
        return put_until(q, item, stop)

    def get(q: queue.Queue) -> Any:
        return get_until(q, stop, _END)

    def feed() -> None:
        count = 0  # frames handed out; an error concerns frame `count`
        try:
            for index, frame in enumerate(frames):
                if frame.shape[:2] != (height, width):
                    raise FrameError(
                        f"{masks.name}: frame {index} is {frame.shape[1]}x{frame.shape[0]} pixels, but the sequence "
                        f"started with {width}x{height} (the frame size must not change)"
                    )
                if not put(inbox[index % workers], (index, frame)):
                    return
                count = index + 1
            for k in range(workers):  # the worker of the next index first: its END ends the collection
                put(inbox[(count + k) % workers], _END)
        except BaseException as e:  # noqa: BLE001 - raised by the collector at its frame
            put(inbox[count % workers], e)

    def work(k: int) -> None:
        with timeline.thread_cpu("mask_workers"):  # the run's timeline: these threads' CPU time
            _work(k)

    def _work(k: int) -> None:
        model = models[k]
        while True:
            item = get(inbox[k])
            if item is _END or isinstance(item, BaseException):
                put(outbox[k], item)
                return
            index, frame = item
            try:
                with guard.shared():
                    raw, prob = model.evidence(index, frame)
                result = (raw if model.cleanup is not None else clean(raw), prob if probability else None)
            except BaseException as e:  # noqa: BLE001 - raised by the collector at its frame
                put(outbox[k], e)
                return
            if not put(outbox[k], result):
                return

    threads = [threading.Thread(target=feed, name="wptrack-masks-feed", daemon=True)]
    threads += [
        threading.Thread(target=work, args=(k,), name=f"wptrack-masks-{k}", daemon=True) for k in range(workers)
    ]
    for t in threads:
        t.start()
    try:
        index = 0
        while True:
            item = get(outbox[index % workers])
            if item is _END:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
            index += 1
    finally:
        stop.set()
        for t in threads:
            t.join(timeout=30.0)
        try:
            for model in models[1:]:
                model.close()
        finally:
            stop_building_ahead(masks.model, builder)  # the stream's model alone again
