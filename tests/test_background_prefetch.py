"""The offline background model's prefetch worker (wptrack.motion.background.OfflineBackground): window ``i + 1``'s
samples read in one worker thread while the frames before it are processed. The masks and probabilities equal those of
reading every window in the calling thread, byte for byte, for every source type; restarts work; the sampler's warnings
and errors reach the calling thread as before; close() joins the worker."""

from __future__ import annotations

import logging
import threading

import cv2
import numpy as np
import pytest

from wptrack.core.errors import FrameError
from wptrack.io.frames import open_source
from wptrack.io.video import write_video
from wptrack.motion import background as B
from wptrack.motion import windows as Wn
from wptrack.motion.masks import MaskConfig, MotionMasks

H, W = 48, 64
WORKER = "wptrack-background"


def _scene(rng: np.random.Generator, frames: int) -> np.ndarray:
    """``(frames, H, W, 3)`` uint8: a texture whose left half dims and right half brightens over time (so the
    windows' backgrounds differ), two moving rectangles, noise."""
    base = cv2.resize(rng.uniform(60, 190, (H // 8, W // 8, 3)).astype(np.float32), (W, H))
    ramp = np.where(np.arange(W) < W // 2, -1.0, 1.0)[None, :, None]
    out = np.empty((frames, H, W, 3), np.uint8)
    for t in range(frames):
        img = base * (1.0 + 0.25 * ramp * t / frames) + rng.normal(0, 3, base.shape)
        x = (2 * t) % (W - 12)
        img[8:24, x : x + 12] = (30, 200, 90)
        img[30:44, W - 14 - x : W - 2 - x] = (200, 40, 160)
        out[t] = np.clip(img, 0, 255).astype(np.uint8)
    return out


def _spec(kind: str, video: np.ndarray, tmp_path) -> object:
    if kind == "array":
        return video
    if kind == "images":
        folder = tmp_path / "images"
        folder.mkdir()
        for t, f in enumerate(video):
            cv2.imwrite(str(folder / f"{t:04d}.png"), f)
        return folder
    path = tmp_path / "v.avi"
    write_video(path, video)
    return path


def _pass(masks: MotionMasks, prefetch: bool, reads: list | None = None) -> tuple[np.ndarray, np.ndarray]:
    """All masks and probabilities of one pass; ``reads`` collects ``(window, thread name)`` of every read (by the
    model or the share's builder, which reads and builds the windows after the first ahead of the frames)."""
    model = masks.model
    model._prefetch = prefetch
    original = B.OfflineBackground._read
    if reads is not None:

        def recording(self, i):
            reads.append((i, threading.current_thread().name))
            return original(self, i)

        B.OfflineBackground._read = recording
    try:
        out = list(masks.evidence())
    finally:
        B.OfflineBackground._read = original
    return np.stack([m for m, _ in out]), np.stack([p for _, p in out])


@pytest.mark.parametrize("kind", ["video", "images", "array"])
@pytest.mark.parametrize(("frames", "window", "samples"), [(40, 16, 8), (150, 80, 3)])  # grabs; seeks (gap 26+)
def test_prefetch_gives_the_same_masks(device, rng, tmp_path, kind, frames, window, samples, monkeypatch):
    """Byte-identical masks and probabilities with and without the worker, >= 3 windows, the reads after the
    first done by the worker, in window order; a second pass (restart at frame 0 after a full pass) equal too.
    One mask thread (on a CUDA host several are the default; their shared reads: tests/test_pipeline.py)."""
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "1")
    video = _scene(rng, frames)
    spec = _spec(kind, video, tmp_path)
    config = MaskConfig(window=window, samples=samples, device=device)
    plain = MotionMasks(open_source(spec), config)
    ref_masks, ref_probs = _pass(plain, prefetch=False)
    windows = len(plain.model.windows)
    assert windows >= 3
    if window == 80:
        assert min(np.diff(plain.model.windows[0].samples)) >= Wn.SEEK_GAP  # the sampler seeks between samples
    fetched = MotionMasks(open_source(spec), config)
    for _ in range(2):  # the second pass starts again at frame 0 after a full pass (and the model's close())
        reads: list = []
        kept = set(fetched.model._built)  # the last window stays built after a pass: not read again
        got_masks, got_probs = _pass(fetched, prefetch=True, reads=reads)
        np.testing.assert_array_equal(got_masks, ref_masks)
        np.testing.assert_array_equal(got_probs, ref_probs)
        assert [i for i, _ in reads] == [i for i in range(windows) if i not in kept]  # in order, once, none wasted
        assert all(name.startswith(WORKER) for _, name in reads[1:]), reads
    assert ref_masks.sum() > 0.01 * ref_masks.size  # the rectangles are found
    # the windows differ: the masks depend on reading the right window's samples
    one = MotionMasks(open_source(spec), MaskConfig(window=frames, samples=samples, device=device))
    assert not np.array_equal(_pass(one, prefetch=False)[1], ref_probs)


def test_restart_at_frame_zero_without_close(device, rng):
    """OfflineBackground used directly: evidence 0..T-1, then 0..T-1 again on the same model (windows dropped and
    rebuilt, the worker reading ahead) gives the first pass's results; random access (background) still works."""
    video = _scene(rng, 40)
    config = MaskConfig(window=16, samples=8, device=device)
    model = B.OfflineBackground(open_source(video), config, device)
    first = [model.evidence(t, video[t]) for t in range(len(video))]
    again = [model.evidence(t, video[t]) for t in range(len(video))]
    background = model.background(len(model.windows) - 1)
    model.close()
    for (m0, p0), (m1, p1) in zip(first, again, strict=True):
        np.testing.assert_array_equal(m0, m1)
        np.testing.assert_array_equal(p0, p1)
    plain = B.OfflineBackground(open_source(video), config, device)
    plain._prefetch = False
    ref = [plain.evidence(t, video[t]) for t in range(len(video))]
    np.testing.assert_array_equal(plain.background(len(model.windows) - 1), background)
    plain.close()
    for (m0, p0), (m1, p1) in zip(first, ref, strict=True):
        np.testing.assert_array_equal(m0, m1)
        np.testing.assert_array_equal(p0, p1)


def _truncated_pass(path, config: MaskConfig, prefetch: bool, caplog) -> tuple[list, np.ndarray]:
    source = open_source(path)
    source._count += 25  # the video reports 25 frames more than it has (as a truncated file's header does)
    masks = MotionMasks(source, config)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="wptrack.motion.background"):
        out, _ = _pass(masks, prefetch=prefetch)
    records = [(r.getMessage(), r.threadName) for r in caplog.records if r.name == "wptrack.motion.background"]
    return records, out


def test_unreadable_later_frames_warn_as_before(device, rng, tmp_path, caplog, monkeypatch):
    """A video that reports more frames than it has: the same masks, and the same background warnings in the same
    order, logged by the calling thread (the worker's are logged when its read is taken; the read of a window no
    frame needs, done ahead and dropped at close, logs nothing)."""
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "1")  # one model (a GPU host's default is three threads)
    video = _scene(rng, 40)
    path = tmp_path / "v.avi"
    write_video(path, video)
    config = MaskConfig(window=16, samples=8, device=device)
    before, ref = _truncated_pass(path, config, False, caplog)
    after, got = _truncated_pass(path, config, True, caplog)
    np.testing.assert_array_equal(got, ref)
    assert len(ref) == len(video)
    assert any("cannot read frame" in m for m, _ in before)  # the sampler met the end of the video
    assert after == before
    assert {name for _, name in after} == {threading.main_thread().name}


def test_worker_error_raised_in_the_calling_thread_when_needed(device, rng, caplog):
    """An error of a window's read (here a FrameError) is raised by evidence() at the frame that first needs that
    window, with its message, after the sampler's warnings of the same read - as without the worker."""
    video = _scene(rng, 40)
    config = MaskConfig(window=16, samples=8, device=device)

    def run(prefetch: bool) -> tuple[int, list]:
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="wptrack.motion.background"):
            t = first_error(prefetch)
        return t, [(r.getMessage(), r.threadName) for r in caplog.records]

    def first_error(prefetch: bool) -> int:
        model = B.OfflineBackground(open_source(video), config, device)
        model._prefetch = prefetch
        read = model._sampler.read
        bad = model.windows[2].samples

        def failing(idx, ahead=()):
            if idx == bad:
                model._sampler._warn("%s: a warning before the error", "array")
                raise FrameError("window 2 is broken")
            return read(idx, ahead)

        model._sampler.read = failing
        try:
            for t in range(len(video)):
                try:
                    model.evidence(t, video[t])
                except FrameError as e:
                    assert str(e) == "window 2 is broken"
                    assert threading.current_thread() is threading.main_thread()
                    return t
        finally:
            model.close()
        return -1

    with_worker, without = run(True), run(False)
    assert with_worker == without
    centres = [w.centre for w in Wn.plan_windows(40, 16, 8)]
    assert without[0] == min(t for t in range(40) if Wn.bracket(centres, t)[1] == 2)  # when window 2 is first needed
    assert without[1] == [("array: a warning before the error", threading.main_thread().name)]


def test_close_joins_the_worker(device, rng, tmp_path):
    """The worker exists while a pass runs and is joined by close(): after a full pass, after an early break with a
    read pending (which stops at its next frame), and after a direct close; the model is usable again after."""
    video = _scene(rng, 120)
    path = tmp_path / "v.avi"
    write_video(path, video)
    config = MaskConfig(window=48, samples=24, device=device)
    start = threading.active_count()
    masks = MotionMasks(open_source(path), config, prefetch_depth=0)
    seen = []
    passing = masks.evidence()
    for t, _ in enumerate(passing):
        seen.append(any(th.name.startswith(WORKER) for th in threading.enumerate()))
        if t == 2:
            break  # window 1's read is pending or under way: the generator's close() stops and joins it
    passing.close()
    assert seen[0]  # the worker was running
    assert threading.active_count() == start
    assert not any(th.name.startswith(WORKER) for th in threading.enumerate())
    assert len(list(masks)) == len(video)  # a new worker for the next pass, joined again at its end
    assert threading.active_count() == start
    model = B.OfflineBackground(open_source(path), config, device)
    model.evidence(0, video[0])
    assert model._pending is not None and threading.active_count() == start + 1
    model.close()
    model.close()  # idempotent
    assert threading.active_count() == start and model._pending is None
    model.evidence(0, video[0])  # usable after close
    model.close()
    assert threading.active_count() == start


def test_prefetch_starts_after_a_window_built_for_a_report(device, rng, tmp_path, monkeypatch):
    """A run builds window 0 for its report (background(0), no prefetch) before the mask pass: the pass still reads
    every later window in the worker, in order and once (it read window 1 in the mask thread, while the other mask
    threads waited for it)."""
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "1")
    video = _scene(rng, 40)
    config = MaskConfig(window=16, samples=8, device=device)
    masks = MotionMasks(open_source(_spec("video", video, tmp_path)), config)
    reads: list = []
    model = masks.model
    original = B.OfflineBackground._read

    def recording(self, i):
        reads.append((i, threading.current_thread().name))
        return original(self, i)

    monkeypatch.setattr(B.OfflineBackground, "_read", recording)  # the model's reads and its builder's
    masks.background(0)
    assert reads == [(0, threading.current_thread().name)]
    list(masks.evidence())
    windows = len(model.windows)
    assert windows >= 3
    assert [i for i, _ in reads] == list(range(windows))
    assert all(name.startswith(WORKER) for _, name in reads[1:]), reads


@pytest.mark.parametrize("truncated", [False, True])
def test_sample_readers_give_the_same_masks(device, rng, tmp_path, monkeypatch, caplog, truncated):
    """WPTRACK_SAMPLE_READERS=3: a window's samples of an intra-coded video read by three captures at once, in
    contiguous groups (the others sought to their first frame): byte-identical masks and probabilities to one
    capture, the groups read in threads of their own; a video that reports more frames than it has gives the same
    warnings (logged by the calling thread) and masks."""
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "1")
    video = _scene(rng, 300)
    path = tmp_path / "v.avi"
    write_video(path, video)
    config = MaskConfig(window=200, samples=25, device=device)
    threads: set[str] = set()
    forward = Wn._read_forward

    def recording(*args, **kwargs):
        threads.add(threading.current_thread().name)
        return forward(*args, **kwargs)

    monkeypatch.setattr(Wn, "_read_forward", recording)
    got = {}
    for readers in ("1", "3"):
        monkeypatch.setenv(Wn.SAMPLE_READERS_ENV, readers)
        source = open_source(path)
        if truncated:
            source._count += 120  # the header promises 120 frames more: the last windows' reads fail part way
        masks = MotionMasks(source, config)
        assert masks.model._sampler.readers == int(readers)
        threads.clear()
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="wptrack.motion.background"):
            out = _pass(masks, prefetch=True)
        records = [(r.getMessage(), r.threadName) for r in caplog.records if r.name == "wptrack.motion.background"]
        got[readers] = (out, records, set(threads))
    (m1, p1), warn1, threads1 = got["1"]
    (m3, p3), warn3, threads3 = got["3"]
    np.testing.assert_array_equal(m3, m1)
    np.testing.assert_array_equal(p3, p1)
    assert m1.sum() > 0.01 * m1.size
    assert warn3 == warn1
    assert any("cannot read frame" in m for m, _ in warn1) == truncated
    assert not any(name.startswith("wptrack-samples") for name in threads1)
    assert any(name.startswith("wptrack-samples") for name in threads3), threads3
