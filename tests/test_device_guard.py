"""The device guard keeps a tracker's CUDA graph capture apart from the motion masks' device work in other threads
(a mask thread's launch on the device's one current stream would land in the graph or fail the capture)."""

from __future__ import annotations

import threading

from wptrack.core.device import DeviceGuard, device_guard

WAIT = 5.0  # seconds a step that must happen may take (a loaded CI box)
BRIEF = 0.2  # seconds a step that must not happen is given


def _in_thread(fn) -> tuple[threading.Thread, threading.Event]:
    done = threading.Event()

    def run():
        fn()
        done.set()

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t, done


def test_shared_sections_run_together():
    guard = DeviceGuard()
    inside = threading.Barrier(2, timeout=WAIT)  # both threads inside at once, or the barrier breaks

    def work():
        with guard.shared():
            inside.wait()

    threads = [_in_thread(work) for _ in range(2)]
    for t, done in threads:
        assert done.wait(WAIT)
        t.join()


def test_a_capture_waits_for_the_shared_work_in_progress():
    guard = DeviceGuard()
    entered, release = threading.Event(), threading.Event()

    def mask_frame():
        with guard.shared():
            entered.set()
            release.wait(WAIT)

    t1, _ = _in_thread(mask_frame)
    assert entered.wait(WAIT)
    captured = threading.Event()

    def capture():
        with guard.exclusive():
            captured.set()

    t2, done = _in_thread(capture)
    assert not captured.wait(BRIEF)  # the mask frame is still on the device
    release.set()
    assert captured.wait(WAIT) and done.wait(WAIT)
    t1.join()
    t2.join()


def test_new_shared_work_waits_for_a_capture_in_progress_and_one_waiting():
    guard = DeviceGuard()
    order: list[str] = []
    holding, release = threading.Event(), threading.Event()

    def mask_frame():
        with guard.shared():
            holding.set()
            release.wait(WAIT)
            order.append("first frame")

    def capture():
        with guard.exclusive():
            order.append("capture")

    def later_frame():
        with guard.shared():
            order.append("later frame")

    t1, _ = _in_thread(mask_frame)
    assert holding.wait(WAIT)
    t2, captured = _in_thread(capture)
    while not guard._waiting:  # the capture is queued behind the first frame
        threading.Event().wait(0.005)
    t3, later = _in_thread(later_frame)
    assert not later.wait(BRIEF)  # held back: a waiting capture goes first
    release.set()
    assert captured.wait(WAIT) and later.wait(WAIT)
    for t in (t1, t2, t3):
        t.join()
    assert order == ["first frame", "capture", "later frame"]


def test_a_paused_shared_section_lets_a_waiting_capture_and_other_shared_work_through():
    """A mask thread waits (inside its shared section) for a window that the builder thread makes under the guard,
    and a capture asks for the device meanwhile: without pausing, the capture waits for the mask thread, the builder
    for the capture, the mask thread for the builder. Paused, the capture runs, then the builder, then the mask thread
    holds its section again (and a new capture waits for it)."""
    guard = DeviceGuard()
    built = threading.Event()
    order: list[str] = []
    mask_in = threading.Event()

    def mask_thread():
        with guard.shared():
            mask_in.set()
            with guard.paused():
                assert built.wait(WAIT)
            order.append("mask resumed")
            assert guard._shared == 1

    def capture():
        with guard.exclusive():
            order.append("capture")

    def builder():
        with guard.shared():
            order.append("build")
            built.set()

    mask, mask_done = _in_thread(mask_thread)
    assert mask_in.wait(WAIT)
    cap, cap_done = _in_thread(capture)
    assert cap_done.wait(WAIT)  # not held back by the paused section
    b, b_done = _in_thread(builder)
    assert b_done.wait(WAIT) and mask_done.wait(WAIT)
    for t in (mask, cap, b):
        t.join()
    assert order == ["capture", "build", "mask resumed"] and guard._shared == 0
    with guard.paused():  # outside a shared section: nothing to give up
        assert guard._shared == 0


def test_one_guard_per_device(device):
    """Every name of a device gives its one guard (the tracker may say ``cuda``, the masks ``cuda:0``)."""
    import warp as wp

    d = wp.get_device(device)
    assert device_guard(device) is device_guard(d) is device_guard(d.alias)
    if d.is_cuda and d.ordinal == wp.get_cuda_device().ordinal:
        assert device_guard("cuda") is device_guard(d.alias)
    if d.is_cuda:
        assert device_guard(d) is not device_guard("cpu")


def test_the_frame_chain_captures_under_the_exclusive_guard(monkeypatch):
    import contextlib

    import warp as wp

    from wptrack.core.filter import FrameChain

    guard = device_guard("cpu")
    seen = []

    class Chain(FrameChain):
        def stages(self, src, dst):
            return [("record", lambda: seen.append(guard._exclusive))]

    @contextlib.contextmanager
    def fake_capture(device):
        yield type("Capture", (), {"graph": "graph"})()

    monkeypatch.setattr(wp, "ScopedCapture", fake_capture)
    monkeypatch.setattr(wp, "capture_launch", lambda graph: None)
    chain = Chain("cpu")
    chain.use_graph, chain._warm = True, [True, True]  # as on CUDA after the warm-up frame
    chain._run_chain(0, 1)  # captures (guarded), then replays
    chain._run_chain(0, 1)
    assert seen == [True] and not guard._exclusive


def test_the_masks_model_works_under_the_shared_guard(monkeypatch):
    """Every frame's device work of the offline model runs inside a shared section (one and two mask threads)."""
    import numpy as np

    from wptrack.motion.background import OfflineBackground
    from wptrack.motion.masks import MaskConfig, open_masks

    guard = device_guard("cpu")
    seen = []
    evidence = OfflineBackground.evidence

    def spy(self, t, frame):
        seen.append(guard._shared > 0)
        return evidence(self, t, frame)

    monkeypatch.setattr(OfflineBackground, "evidence", spy)
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, size=(12, 24, 32, 3), dtype=np.uint8)
    for workers in (1, 2):
        monkeypatch.setenv("WPTRACK_MASK_WORKERS", str(workers))
        masks = open_masks(frames, config=MaskConfig(method="offline", window=6, samples=3, device="cpu"))
        assert len(list(masks)) == 12
    assert len(seen) == 24 and all(seen)


def test_download_copies_without_switching_the_current_stream(device):
    import numpy as np
    import warp as wp

    from wptrack.core.device import download

    values = np.arange(24, dtype=np.float32).reshape(4, 6) - 3.5
    a = wp.array(values, dtype=wp.float32, device=device)
    d = wp.get_device(device)
    before = d.stream if d.is_cuda else None
    got = download(a)
    assert isinstance(got, np.ndarray) and got.shape == (4, 6) and got.dtype == np.float32
    np.testing.assert_array_equal(got, values)
    if d.is_cuda:
        assert d.stream is before
    v = wp.array(np.arange(9, dtype=np.uint8), dtype=wp.uint8, device=device)
    np.testing.assert_array_equal(download(v), np.arange(9, dtype=np.uint8))


def test_mask_threads_default_to_three_on_a_gpu_host_only(monkeypatch):
    import wptrack.core.config as config
    from wptrack.motion.parallel import GPU_MASK_WORKERS, mask_workers

    monkeypatch.delenv("WPTRACK_MASK_WORKERS", raising=False)
    monkeypatch.setattr(config, "host_cores", lambda: 16)  # the cores this process may use (its CPU affinity)
    assert mask_workers("cuda:0") == GPU_MASK_WORKERS == 3
    assert mask_workers("cpu") == mask_workers(None) == 1
    monkeypatch.setattr(config, "host_cores", lambda: 4)
    assert mask_workers("cuda:0") == 1  # few cores: the threads would take the decoder's
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "2")
    assert mask_workers("cpu") == mask_workers("cuda:0") == 2
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "0")
    assert mask_workers("cuda:0") == 1


def test_a_window_builds_host_work_lets_a_waiting_capture_through():
    """A window build runs inside its thread's shared section (a mask thread's frame, or the builder's), and a build
    at 1080p spends seconds in host work (reading its samples, NumPy statistics, writing the background image). A
    tracker's capture asking for the device meanwhile must not wait for that host work (and hold every other mask
    thread back with it): the build gives the section up there (``OfflineBackground._host_part``)."""
    import numpy as np

    from wptrack.io.frames import ArraySource
    from wptrack.motion.background import OfflineBackground
    from wptrack.motion.masks import MaskConfig

    guard = DeviceGuard()
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, size=(12, 24, 32, 3), dtype=np.uint8)
    config = MaskConfig(method="offline", window=6, samples=3, device="cpu")
    model = OfflineBackground(ArraySource(frames), config, "cpu")
    model._share.guard = guard
    captured = []

    def capture():
        with guard.exclusive():
            captured.append(True)

    def on_build(i, centre, image):
        assert guard._shared == 0  # given up for the host work
        _, cap_done = _in_thread(capture)
        assert cap_done.wait(WAIT)  # the capture got the device while this build's thread is in its section

    model.on_build = on_build
    with guard.shared():
        image = model.background(0)
        assert guard._shared == 1  # held again after the host work
    assert image.shape == (24, 32, 3) and captured == [True] and guard._shared == 0
    model.close()
