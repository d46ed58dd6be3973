"""The run pipeline's threads (issue 27): decode-ahead with its timeline, background video writers (bounded, atomic,
errors raised in the caller), grey mask videos, the virtual.avi rule, and bad input (a decoder slower than real
time, a consumer that stops early, a writer that fails or is slower than the run): no deadlock, bounded queues."""

from __future__ import annotations

import threading
import time

import cv2
import numpy as np
import pytest
import warp as wp

from wptrack.io import timeline
from wptrack.io.prefetch import prefetch
from wptrack.io.video import BackgroundWriter, VideoWriter, continue_video


def _read_all(path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    out = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        out.append(frame)
    cap.release()
    return out


# ------------------------------------------------------------------------------------------------ timeline


def test_timeline_summary_overlap_and_waits():
    t = timeline.Timeline()
    t.add("filter", 0.5)
    t.add("decode", 0.25, count=2)
    t.add("wait_masks", 10.0)
    t.add("decode_blocked", 10.0)
    t.started, t.stopped = 0.0, 0.5
    s = t.summary()
    assert s["wall_s"] == pytest.approx(0.5)
    assert s["overlap"] == pytest.approx(1.5)  # waits and blocked producers are idle, not work
    assert s["stages"]["decode"] == {"total_s": 0.25, "count": 2, "mean_ms": 125.0, "share": 0.5}
    assert timeline.is_wait("wait_decode") and timeline.is_wait("masks_blocked") and not timeline.is_wait("masks")
    assert "first_item_s" not in s  # the loop got no item


def test_timeline_start_up_and_the_rate_after_it():
    """The start-up (first frame asked for -> first item the loop got) and the items per second after it."""
    t = timeline.Timeline()
    t.start()
    t.started -= 2.0  # asked for the first frame 2 s ago
    t.item()
    t.first -= 1.0  # ... and got it 1 s ago (1 s of start-up)
    for _ in range(4):
        t.item()
    t.stop()
    s = t.summary()
    assert s["first_item_s"] == pytest.approx(1.0, abs=0.05)
    assert s["after_first_per_s"] == pytest.approx(4 / (t.stopped - t.first), rel=1e-3)
    assert 3.5 < s["after_first_per_s"] <= 4.0
    t.start()  # a new run: no item yet
    assert t.first is None and t.items == 0 and "first_item_s" not in t.summary()


def test_record_goes_to_the_active_timeline_only():
    timeline.record("decode", 1.0)  # none active: dropped
    t = timeline.Timeline()
    with timeline.active(t):
        timeline.record("decode", 0.25)
        assert timeline.current() is t
    timeline.record("decode", 1.0)
    assert timeline.current() is None
    assert t.total("decode") == 0.25


# ------------------------------------------------------------------------------------------------ prefetch


def test_prefetch_records_producer_consumer_and_blocked_time():
    def slow_source():
        for i in range(6):
            time.sleep(0.01)  # a decoder slower than the consumer
            yield i

    t = timeline.Timeline()
    with timeline.active(t):
        got = list(prefetch(slow_source(), depth=2, name="decode"))
    assert got == list(range(6))
    s = t.summary()["stages"]
    assert s["decode"]["count"] == 6 and s["decode"]["total_s"] >= 0.05
    assert s["wait_decode"]["count"] == 7  # six items and the end
    assert s["wait_decode"]["total_s"] >= 0.03  # the consumer waited for the slow producer

    t = timeline.Timeline()
    with timeline.active(t):
        for _ in prefetch(iter(range(5)), depth=1, name="masks"):
            time.sleep(0.01)  # a consumer slower than the producer: the producer is blocked
    assert t.total("masks_blocked") >= 0.02


def test_prefetch_bounded_and_stops_its_source_when_the_consumer_leaves():
    produced = []
    closed = threading.Event()

    def endless():
        try:
            i = 0
            while True:
                produced.append(i)
                yield np.zeros(1000, dtype=np.uint8)
                i += 1
        finally:
            closed.set()

    it = prefetch(endless(), depth=3)
    for k, _ in enumerate(it):
        time.sleep(0.02)
        assert len(produced) <= k + 1 + 3 + 1  # consumed + queued + one in the producer's hands
        if k == 5:
            break
    assert closed.wait(2.0)  # the source generator was closed (its file released) when the loop was left
    assert not it._thread.is_alive()


def test_prefetch_reraises_the_source_error_in_order():
    def failing():
        yield 1
        yield 2
        raise ValueError("corrupt frame 2")

    got = []
    with pytest.raises(ValueError, match="corrupt frame 2"):
        for item in prefetch(failing(), depth=4):
            got.append(item)
    assert got == [1, 2]


# ------------------------------------------------------------------------------------------------ writers


def test_grey_writer_round_trip(tmp_path, rng):
    masks = [(rng.random((24, 32)) > 0.5).astype(np.uint8) * 255 for _ in range(4)]
    with VideoWriter(tmp_path / "m.avi", fps=10, grey=True) as w:
        for m in masks[:3]:
            w.write(m)
        w.write(np.repeat(masks[3][..., None], 3, axis=2))  # a BGR frame is converted
    if w.codec != "FFV1":
        pytest.skip("FFV1 not available (grey round trip is exact only with a lossless codec)")
    back = _read_all(tmp_path / "m.avi")
    assert len(back) == 4
    for m, b in zip(masks, back, strict=True):
        assert b.shape == (24, 32, 3)
        for c in range(3):
            np.testing.assert_array_equal(b[..., c], m)


def test_background_writer_writes_what_the_plain_writer_writes(tmp_path, rng):
    frames = [rng.integers(0, 256, (24, 32), dtype=np.uint8) for _ in range(9)]
    t = timeline.Timeline()
    with timeline.active(t):
        bw = BackgroundWriter(VideoWriter(tmp_path / "b.avi", fps=10), depth=2, stage="write_test")
        for f in frames:
            bw.write(f, lambda g: cv2.merge([g, 255 - g, g // 2]))  # prepared in the writer thread
        bw.flush()
        assert bw.frames_written == 9
        assert not (tmp_path / "b.avi").exists()  # atomic: only once closed
        assert bw.close() == tmp_path / "b.avi"
    with VideoWriter(tmp_path / "a.avi", fps=10) as w:
        for f in frames:
            w.write(cv2.merge([f, 255 - f, f // 2]))
    if w.codec != "FFV1":
        pytest.skip("FFV1 not available")
    for a, b in zip(_read_all(tmp_path / "a.avi"), _read_all(tmp_path / "b.avi"), strict=True):
        np.testing.assert_array_equal(a, b)
    assert t.summary()["stages"]["write_test"]["count"] == 9
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.avi", "b.avi"]  # no temporary file left


class _SlowWriter:
    """A stand-in encoder slower than the run, failing at frame ``fail_at``."""

    def __init__(self, delay: float, fail_at: int = -1) -> None:
        self.delay, self.fail_at = delay, fail_at
        self.frames_written = 0
        self.closed = self.aborted = False

    def write(self, frame) -> None:
        time.sleep(self.delay)
        if self.frames_written == self.fail_at:
            raise OSError("disk full")
        self.frames_written += 1

    def close(self):
        self.closed = True

    def abort(self) -> None:
        self.aborted = True


def test_background_writer_is_bounded_when_the_encoder_is_slow():
    slow = _SlowWriter(0.01)
    bw = BackgroundWriter(slow, depth=3)
    t = timeline.Timeline()
    with timeline.active(t):
        for k in range(15):
            bw.write(np.zeros(10, dtype=np.uint8))
            assert bw._queue.qsize() <= 3  # memory bounded: the caller waits instead
            assert k + 1 - slow.frames_written <= 3 + 1
    bw.close()
    assert slow.frames_written == 15 and slow.closed
    assert t.total("wait_write_video") > 0.05  # the caller waited for the encoder


def test_background_writer_error_is_raised_by_the_caller_and_aborts():
    slow = _SlowWriter(0.0, fail_at=2)
    bw = BackgroundWriter(slow, depth=8)
    with pytest.raises(OSError, match="disk full"):
        for _ in range(50):
            bw.write(np.zeros(10, dtype=np.uint8))
            time.sleep(0.002)
        bw.close()
    assert bw.close() is None  # the run's finish() after the error: the file deleted, the error not raised again
    assert slow.aborted and not slow.closed

    failing = _SlowWriter(0.0, fail_at=1)
    bw = BackgroundWriter(failing, depth=8)
    bw.write(np.zeros(10, dtype=np.uint8))
    bw.write(np.zeros(10, dtype=np.uint8))
    with pytest.raises(OSError, match="disk full"):  # the error surfaces at close when no write saw it
        bw.close()
    assert failing.aborted and not failing.closed


def test_background_writer_abort_leaves_nothing(tmp_path):
    bw = BackgroundWriter(VideoWriter(tmp_path / "x.avi", fps=10), depth=2)
    for _ in range(5):
        bw.write(np.zeros((8, 8), dtype=np.uint8))
    bw.abort()
    assert list(tmp_path.iterdir()) == []


def test_continue_video_grey_keeps_the_frames_before_the_resume_point(tmp_path, rng):
    masks = [(rng.random((16, 16)) > 0.5).astype(np.uint8) * 255 for _ in range(5)]
    with VideoWriter(tmp_path / "m.avi", fps=10, grey=True) as w:
        for m in masks[:3]:
            w.write(m)
    if w.codec != "FFV1":
        pytest.skip("FFV1 not available")
    w = continue_video(tmp_path / "m.avi", 2, fps=10, grey=True)
    for m in masks[2:]:
        w.write(m)
    w.close()
    back = _read_all(tmp_path / "m.avi")
    assert len(back) == 5
    for m, b in zip(masks, back, strict=True):
        np.testing.assert_array_equal(b[..., 0], m)


# ------------------------------------------------------------------------------------------------ template outputs


def test_colour_virtual_equals_the_table_lookup(rng):
    from wptrack.trackers.templates.run import colour_virtual, label_colours

    labels = np.array([3, -1, 7, 12], dtype=np.int32)
    virtual = rng.integers(0, 6, (20, 30), dtype=np.uint8)
    lut = np.zeros((256, 3), dtype=np.uint8)
    lut[1:5] = label_colours(np.maximum(labels, 0))
    np.testing.assert_array_equal(colour_virtual(virtual, labels), lut[virtual])


def test_virtual_video_default_by_frame_size():
    from wptrack.trackers.templates.run import VIRTUAL_AUTO_PIXELS, virtual_default

    assert virtual_default(480, 360) and virtual_default(640, 480)
    assert not virtual_default(1440, 1080) and not virtual_default(1920, 1080)
    assert virtual_default(VIRTUAL_AUTO_PIXELS, 1) and not virtual_default(VIRTUAL_AUTO_PIXELS + 1, 1)


# ------------------------------------------------------------------------------------------------ the pipeline bench


def test_bench_pipeline_tiny(tmp_path, capsys):
    """``wptrack bench --tracker pipeline``: its own video, the three commands as the CLI runs them, the decode rate,
    the ratios and the run's own stage timeline (decode, masks, upload, filter, record, writer, waits, CPU)."""
    import json

    from wptrack.cli import main

    out = tmp_path / "pipe.json"
    argv = ["bench", "--tracker", "pipeline", "--device", "cpu", "--size", "96x72", "--frames", "6", "-q"]
    assert main([*argv, "--variant", "WPTRACK_MASK_WORKERS=2,WPTRACK_CPU_THREADS=1", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "decode only (cv2.VideoCapture, one thread)" in printed and "target track_fps >= 30" in printed
    assert "WPTRACK_MASK_WORKERS=2,WPTRACK_CPU_THREADS=1: track templates --video" in printed
    (r,) = json.loads(out.read_text())["results"]
    (v,) = r["variants"]
    assert v["env"] == {"WPTRACK_MASK_WORKERS": "2", "WPTRACK_CPU_THREADS": "1"} and v["track"]["fps"] > 0
    assert "mask_workers" in v["track"]["timeline"]["cpu_s"]  # the variant's run made its masks in two threads
    assert "WPTRACK_MASK_WORKERS" not in __import__("os").environ  # restored
    assert (r["width"], r["height"], r["frames"]) == (96, 72, 6)
    assert r["decode_fps"] > 0 and len(r["decode_s"]) == 2
    for key in ("masks", "track", "track_from_masks"):
        assert r[key]["fps"] > 0 and r[key]["ratio"] == pytest.approx(r[key]["fps"] / r["decode_fps"])
    tl = r["track"]["timeline"]
    for stage in ("decode", "masks", "upload", "filter", "record", "write_virtual", "wait_masks"):
        assert tl["stages"][stage]["count"] >= 6, stage  # every frame went through every stage
    assert tl["stages"]["masks"]["count"] == tl["stages"]["filter"]["count"] == 6
    assert set(tl["cpu_s"]) >= {"main", "masks", "decode", "write_virtual", "process"}
    assert tl["overlap"] > 0 and r["track"]["summary"]["virtual"] is True
    assert 0 < tl["first_item_s"] < tl["wall_s"] and tl["after_first_per_s"] > 0  # the start-up apart
    assert "start-up: the first frame's observation after" in printed
    assert "masks" not in r["track_from_masks"]["timeline"]["stages"]  # decoded masks, not made


def test_bench_pipeline_options(tmp_path, capsys):
    from wptrack.bench.pipeline import parse_size, parse_variant, scene_rig, write_scene
    from wptrack.cli import main
    from wptrack.core.errors import ConfigError

    assert parse_variant("WPTRACK_MASK_WORKERS=2, WPTRACK_DECODE_WORKERS=4") == (
        ("WPTRACK_MASK_WORKERS", "2"), ("WPTRACK_DECODE_WORKERS", "4"))  # fmt: skip
    for bad in ("PATH=/bin", "WPTRACK_MASK_WORKERS", "WPTRACK_MASK_WORKERS=two"):
        with pytest.raises(ConfigError, match="--variant"):
            parse_variant(bad)
    assert parse_size("1920x1080") == (1920, 1080)
    for bad in ("1920", "axb", "8x8"):
        with pytest.raises(ConfigError, match="--size"):
            parse_size(bad)
    base = ["bench", "--device", "cpu", "-q"]
    assert main([*base, "--tracker", "templates", "--size", "64x48"]) == 2  # the pipeline suite's option
    assert "only the 'pipeline' suite" in capsys.readouterr().err
    assert main([*base, "--tracker", "pipeline", "--particles", "10"]) == 2
    video = write_scene(tmp_path / "v.avi", 80, 64, 3)
    assert main([*base, "--tracker", "pipeline", "--video", str(video), "--size", "64x48"]) == 2
    rig = scene_rig(80, 64, tmp_path / "rig.yaml")
    assert main([*base, "--tracker", "pipeline", "--rig", str(rig)]) == 2  # a rig without --video
    capsys.readouterr()


def test_given_mask_equals_any_channel_above_the_threshold(rng):
    from wptrack.motion.masks import given_mask

    image = rng.integers(0, 256, (17, 23, 3), dtype=np.uint8)
    for threshold in (0, 127, 254):
        np.testing.assert_array_equal(given_mask(image, threshold), np.any(image > threshold, axis=2))
        np.testing.assert_array_equal(given_mask(image[..., 1], threshold), image[..., 1] > threshold)
    assert given_mask(image, 127).dtype == np.uint8


def test_iterating_masks_makes_no_probability(rng):
    from wptrack.motion.masks import open_masks

    frames = (rng.random((4, 12, 16)) > 0.5).astype(np.uint8) * 255
    masks = open_masks(masks=frames)
    assert all(p is None for _, p in masks.evidence(probability=False))
    pairs = list(masks.evidence())
    assert all(p.dtype == np.float32 and np.array_equal(p, m) for m, p in pairs)
    assert [m.tolist() for m in masks] == [m.tolist() for m, _ in pairs]


# ------------------------------------------------------------------------------------------------ multi-core CPU


def test_cpu_split_ranges_and_errors():
    from wptrack.core.device import CPU_SPLIT_MIN, CpuSplit, cpu_split_threads

    split = CpuSplit(10, 3)
    assert split.ranges == [(0, 3), (3, 6), (6, 10)]
    seen = []
    split(lambda k, lo, hi: seen.append((k, lo, hi, threading.current_thread() is threading.main_thread())))
    assert sorted(s[:3] for s in seen) == [(0, 0, 3), (1, 3, 6), (2, 6, 10)]
    assert [s[3] for s in seen if s[0] == 0] == [True]  # the calling thread runs the first range

    def fail(k, lo, hi):
        if k == 2:
            raise ValueError("range 2")

    with pytest.raises(ValueError, match="range 2"):
        split(fail)
    split.close()
    assert CpuSplit(1, 4).ranges == [(0, 1)]
    assert cpu_split_threads(CPU_SPLIT_MIN - 1) == 1


def test_cpu_split_threads_follow_the_environment(monkeypatch):
    from wptrack.core.device import CPU_SPLIT_MIN, cpu_split_threads

    monkeypatch.delenv("WPTRACK_DECODE_THREADS", raising=False)
    monkeypatch.setenv("WPTRACK_CPU_THREADS", "3")
    assert cpu_split_threads(100 * CPU_SPLIT_MIN) == 3
    monkeypatch.setenv("WPTRACK_CPU_THREADS", "1")
    assert cpu_split_threads(100 * CPU_SPLIT_MIN) == 1
    monkeypatch.delenv("WPTRACK_CPU_THREADS")
    monkeypatch.setenv("WPTRACK_DECODE_THREADS", "1")  # a batch worker holding one core: no split
    assert cpu_split_threads(100 * CPU_SPLIT_MIN) == 1


def test_split_hulls_equal_one_launch(monkeypatch):
    """The template tracker's hull projection over particle ranges in threads (CPU backend) writes the same hulls."""
    from wptrack.bench.templates import bench_objects, bench_particles, bench_rig
    from wptrack.core.device import CpuSplit
    from wptrack.trackers.templates.tracker import TemplateConfig, TemplateTracker

    truth = bench_objects(5, seed=3)
    tr = TemplateTracker(bench_rig(), TemplateConfig(particles=700, max_objects=5, seed=1), device="cpu")
    tr.set_particles(**bench_particles(truth, 700, seed=3))
    s = tr.state[tr.parity]
    hulls = (tr.hulls.pts, tr.hulls.n, tr.hulls.rows, tr.hulls.depth)
    out = []
    for split in (None, CpuSplit(700, 3), CpuSplit(700, 2)):
        for a in hulls:
            a.zero_()
        tr.hulls.launch(tr.cam, tr.plane_struct, s.kind, s.pos, s.heading, s.dims, tr.device, split)
        out.append([a.numpy().copy() for a in hulls])
    assert out[0][1].sum() > 0  # pieces were projected
    for got in out[1:]:
        for a, b in zip(out[0], got, strict=True):
            np.testing.assert_array_equal(a, b)


# ------------------------------------------------------------------------------------------------ bad input


def _vfr_mkv(path, timecodes_ms, codec="FFV1"):
    """A Matroska video (``codec``) whose frames carry ``timecodes_ms`` (a variable frame rate): written at 25
    frames/s by OpenCV, then each SimpleBlock's 16-bit relative timecode patched in place."""
    import struct

    n = len(timecodes_ms)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), 25, (32, 24))
    if not writer.isOpened():
        pytest.skip(f"no {codec} Matroska writer in this OpenCV")
    for i in range(n):
        writer.write(np.full((24, 32, 3), 10 * i, np.uint8))
    writer.release()
    data = bytearray(path.read_bytes())
    blocks, i = [], 0
    while len(blocks) < n:  # SimpleBlock: ID 0xA3, its size (an EBML number), track 0x81, int16 timecode
        i = data.find(b"\xa3", i)
        if i < 0:
            pytest.skip("unexpected Matroska layout")
        width = next((k + 1 for k in range(4) if data[i + 1] & (0x80 >> k)), 0)  # the size's bytes
        at = i + 1 + width
        if width and data[at] == 0x81 and struct.unpack(">h", data[at + 1 : at + 3])[0] == 40 * len(blocks):
            blocks.append(at + 1)
        i += 1
    for at, ms in zip(blocks, timecodes_ms, strict=True):
        struct.pack_into(">h", data, at, ms)
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("codec", ["FFV1", "MJPG"])  # MJPG: read as JPEG packets (wptrack.io.jpeg), in threads
def test_variable_frame_rate_video_is_read_whole_with_one_warning(tmp_path, caplog, monkeypatch, codec):
    from wptrack.io.frames import open_source

    monkeypatch.setenv("WPTRACK_JPEG_WORKERS", "2")
    path = _vfr_mkv(tmp_path / "vfr.mkv", [0, 40, 80, 120, 160, 200, 320, 440, 560, 680], codec)
    src = open_source(path)
    assert src.jpeg == (codec == "MJPG")
    with caplog.at_level("WARNING"):
        frames = list(src)
        again = list(src)
    values = [int(f[0, 0, 0]) for f in frames]
    assert len(frames) == len(again) == 10 and np.allclose(values, [10 * i for i in range(10)], atol=2)
    info = src.variable_rate
    if info is None:
        pytest.skip("this OpenCV build gives no timestamps for Matroska")
    assert info["frame"] == 6 and info["interval_ms"] == pytest.approx(120) and info["expected_ms"] == 40
    warnings = [r.getMessage() for r in caplog.records if "variable frame rate" in r.getMessage()]
    assert len(warnings) == 2 and "frame 6 comes 120 ms after frame 5" in warnings[0]  # once per pass

    steady = _vfr_mkv(tmp_path / "cfr.mkv", [40 * i for i in range(10)], codec)
    src = open_source(steady)
    assert len(list(src)) == 10 and src.variable_rate is None


class _FakeRun:
    """A run-loop job: frames of ``size`` bytes made ``delay`` seconds apart (a decoder slower than real time), or
    as fast as asked while the filter takes ``step_s`` (a consumer slower than the decoder)."""

    name = "fake"
    columns = ["frame", "id", "x", "y", "z"]
    config: dict = {}
    total = None
    source_stage = "decode"
    particles_every = particles_max = particles_frames = 1

    def __init__(self, frames: int, size: int, delay: float = 0.0, step_s: float = 0.0) -> None:
        self.n, self.size, self.delay, self.step_s = frames, size, delay, step_s
        self.made = 0

    def info(self):
        return {}

    def frames(self):
        for _ in range(self.n):
            time.sleep(self.delay)
            self.made += 1
            yield np.ones(self.size, dtype=np.uint8)

    def start(self, out_dir, resume_after=None):
        pass

    def step(self, item):
        from types import SimpleNamespace

        time.sleep(self.step_s)
        return SimpleNamespace(frame=self.made, timings={"filter": self.step_s})

    def record(self, est, out):
        pass

    def flush(self):
        pass

    def finish(self):
        pass

    def summary(self):
        return {}

    def stopped_early(self):
        return None

    def variable_rate(self):
        return None


def test_slow_decoder_and_slow_consumer_keep_memory_bounded(tmp_path):
    """Issue 27, bad input: a decoder slower than real time only makes the filter wait (no deadlock); a consumer
    slower than the decoder holds at most the prefetch depth of frames (peak memory measured), never the video."""
    import json
    import tracemalloc

    from wptrack.runs import run_tracker

    run_tracker(_FakeRun(8, 1000, delay=0.02), tmp_path / "slow-decoder", prefetch_depth=2)
    tl = json.loads((tmp_path / "slow-decoder" / "run.json").read_text())["timeline"]["stages"]
    assert tl["wait_decode"]["total_s"] >= 0.1 and tl["decode"]["count"] == 8

    frame = 1 << 20  # 1 MiB frames: 40 MiB if the queue held the whole video
    tracemalloc.start()
    try:
        job = _FakeRun(40, frame, step_s=0.005)
        run_tracker(job, tmp_path / "slow-consumer", prefetch_depth=3)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert job.made == 40
    assert peak < 8 * frame, f"peak {peak / frame:.1f} MiB"  # depth 3 + one in each thread's hands + slack
    tl = json.loads((tmp_path / "slow-consumer" / "run.json").read_text())["timeline"]["stages"]
    assert tl["decode_blocked"]["total_s"] > 0.05  # the decoder waited for room


def test_a_failed_run_leaves_no_pipeline_thread_behind(tmp_path):
    import json

    from wptrack.runs import run_tracker

    class Failing(_FakeRun):
        steps = 0

        def step(self, item):
            self.steps += 1
            if self.steps > 3:
                raise RuntimeError("device lost")
            return super().step(item)

    before = {t.name for t in threading.enumerate()}
    with pytest.raises(RuntimeError, match="device lost"):
        run_tracker(Failing(100, 1000), tmp_path / "fail", prefetch_depth=2)
    time.sleep(0.3)
    left = [t.name for t in threading.enumerate() if t.name not in before and t.name.startswith("wptrack")]
    assert not left, left
    run = json.loads((tmp_path / "fail" / "run.json").read_text())
    assert run["status"] == "failed" and run["timeline"]["stages"]["filter"]["count"] >= 2


def test_bench_pipeline_people_from_several_videos(tmp_path, capsys):
    """Several --video with their --rig: the people tracker's command against decoding the cameras in turn."""
    import json

    from wptrack.bench.pipeline import scene_cameras, scene_rig, write_scene
    from wptrack.cli import main

    cams = scene_cameras(96, 72, 2)
    videos = [str(write_scene(tmp_path / f"cam{k}.avi", 96, 72, 5, camera=c)) for k, c in enumerate(cams)]
    rig = scene_rig(96, 72, tmp_path / "rig.yaml", cameras=2)
    out = tmp_path / "people.json"
    argv = ["bench", "--tracker", "pipeline", "--device", "cpu", "-q", "--video", *videos, "--rig", str(rig)]
    assert main([*argv, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "wptrack track people --video (2 cameras, defaults)" in printed and "target people_ratio" in printed
    (r,) = json.loads(out.read_text())["results"]
    assert r["cameras"] == 2 and r["frames"] == 5 and r["people"]["fps"] > 0
    stages = r["people"]["timeline"]["stages"]
    assert stages["masks"]["count"] >= 2 * 5 and stages["decode"]["count"] >= 5 and stages["filter"]["count"] == 5
    assert main(["bench", "--tracker", "pipeline", "--device", "cpu", "-q", "--video", *videos]) == 2  # no --rig


def test_track_prints_where_the_time_went(tmp_path, capsys):
    """``wptrack track templates`` ends with one line from the run's timeline: frames/s, each stage's ms per frame
    and the filter's wait for its masks."""
    import json

    from wptrack.bench.pipeline import scene_rig, write_scene
    from wptrack.cli import main

    video = write_scene(tmp_path / "v.avi", 96, 72, 4)
    rig = scene_rig(96, 72, tmp_path / "rig.yaml")
    out = tmp_path / "run"
    argv = ["track", "templates", "-q", "--rig", str(rig), "--video", str(video), "--device", "cpu", "--out", str(out)]
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    speed = next(line for line in lines if line.startswith("speed: "))
    assert "frames/s" in speed and "filter " in speed and "masks " in speed and "waited for masks" in speed
    tl = json.loads((out / "run.json").read_text())["timeline"]
    assert tl["source"] == "masks" and tl["stages"]["wait_masks"]["count"] >= 4


@pytest.mark.parametrize(
    ("codec", "jpeg", "env", "prefix"),
    [
        ("MJPG", "1", "WPTRACK_JPEG_WORKERS", "wptrack-jpeg"),  # JPEG packets decoded by threads (wptrack.io.jpeg)
        ("MJPG", "0", "WPTRACK_DECODE_WORKERS", "wptrack-decode"),  # FFmpeg's decoder, captures on chunks
        ("FFV1", "1", "WPTRACK_DECODE_WORKERS", "wptrack-decode"),
    ],
)
def test_parallel_decode_gives_the_sequential_frames(tmp_path, rng, monkeypatch, codec, jpeg, env, prefix):
    """Decoding in worker threads (WPTRACK_DECODE_WORKERS: several captures on chunks of an intra-only video;
    WPTRACK_JPEG_WORKERS: a Motion-JPEG video's packets decoded by several threads) gives the frames of one
    sequential read, in order; a truncated video stops at the same frame; a consumer that stops early leaves no
    decoding thread behind."""
    from wptrack.io.frames import open_source

    monkeypatch.setenv("WPTRACK_JPEG_DECODE", jpeg)
    n = 45  # chunks of 8: the last one partial
    path = tmp_path / f"v_{codec}.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), 25, (40, 32))
    if not writer.isOpened():
        pytest.skip(f"no {codec} writer")
    for _ in range(n):
        writer.write(rng.integers(0, 256, (32, 40, 3), dtype=np.uint8))
    writer.release()
    src = open_source(path)
    assert src.jpeg == (codec == "MJPG" and jpeg == "1")
    monkeypatch.setenv(env, "1")
    one = list(src)
    assert len(one) == n
    for workers in ("2", "3"):
        monkeypatch.setenv(env, workers)
        many = list(src)
        assert len(many) == n and src.stopped_early is None
        for a, b in zip(one, many, strict=True):
            np.testing.assert_array_equal(a, b)
    before = {t.name for t in threading.enumerate()}
    it = iter(src)
    for _ in range(11):
        next(it)
    # the workers decode (both codecs are intra-only: OpenCV reports FFV1's FOURCC in lower case)
    assert [t.name for t in threading.enumerate() if t.name.startswith(prefix) and t.name not in before]
    it.close()
    time.sleep(0.3)
    assert not [t.name for t in threading.enumerate() if t.name.startswith(prefix) and t.name not in before]

    cut = tmp_path / f"cut_{codec}.avi"  # cut short: no index at the end of the AVI
    data = path.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    monkeypatch.setenv(env, "1")
    src = open_source(cut)
    seq = list(src)
    seq_stop = src.stopped_early
    monkeypatch.setenv(env, "3")
    par = list(src)
    assert 0 < len(par) == len(seq) < n and src.stopped_early == seq_stop
    for a, b in zip(seq, par, strict=True):
        np.testing.assert_array_equal(a, b)


def test_parallel_decode_reads_forward_where_seeking_is_inexact(monkeypatch):
    """A capture whose seeks land elsewhere (reported position != the frame asked for) makes the worker read forward
    from the start: still the sequential frames."""
    from wptrack.io.decode import parallel_frames

    class Fake:  # frame i is the number i; seeks are reported as landing one frame early
        def __init__(self):
            self.pos = 0

        def set(self, prop, value):
            self.pos = int(value) - 1

        def get(self, prop):
            return float(self.pos) if prop == cv2.CAP_PROP_POS_FRAMES else 40.0 * self.pos

        def grab(self):
            self.pos += 1
            return self.pos <= 30

        def read(self):
            if self.pos >= 30:
                return False, None
            self.pos += 1
            return True, np.full((2, 2), self.pos - 1, np.uint8)

        def release(self):
            pass

    got = [int(f[0, 0]) for _, ok, f, _ in parallel_frames(Fake, 30, 3) if ok]
    assert got == list(range(30))


# ------------------------------------------------------------------------------------------------ masks in threads


def _moving_boxes(rng, frames: int = 48, h: int = 48, w: int = 64) -> np.ndarray:
    base = cv2.resize(rng.uniform(60, 200, (h // 8, w // 8, 3)).astype(np.float32), (w, h))
    video = np.clip(base + rng.normal(0, 3, (frames, h, w, 3)), 0, 255).astype(np.uint8)
    for t in range(frames):
        x = (4 + 2 * t) % (w - 10)
        video[t, 10:30, x : x + 8] = (40, 200, 40)
        video[t, 30:44, w - 12 - x // 2 : w - 4 - x // 2] = (200, 40, 90)
    return video


@pytest.mark.parametrize("workers", ["2", "3"])
def test_masks_in_several_threads_equal_one_model(tmp_path, rng, monkeypatch, workers):
    """WPTRACK_MASK_WORKERS: the offline masks made by several models in threads (frames round robin) equal one
    model's, mask and probability, frame for frame, over several background windows; the models share their windows
    (WindowShare): each window is built once (the stream's on_build called once per window, whichever model built
    it) and the sampler reads the same frames in the same order as for one model."""
    from wptrack.io.video import write_video
    from wptrack.motion import windows as W
    from wptrack.motion.masks import MaskConfig, open_masks

    path = tmp_path / "v.avi"
    write_video(path, _moving_boxes(rng))
    config = MaskConfig(window=16, samples=5, device="cpu")  # 5 windows over 48 frames
    reads: list[tuple[int, ...]] = []
    sampler_read = W._Sampler.read

    def read(self, indices, ahead=()):
        reads.append(tuple(indices))
        return sampler_read(self, indices, ahead)

    monkeypatch.setattr(W._Sampler, "read", read)
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "1")
    one = list(open_masks(video=path, config=config).evidence())
    one_reads, reads[:] = list(reads), []
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", workers)
    stream = open_masks(video=path, config=config)
    assert stream.workers == int(workers)
    built = []
    stream.model.on_build = lambda window, centre, image: built.append((window, threading.current_thread().name))
    many = list(stream.evidence())
    assert len(many) == len(one) == 48 and len(stream.model.windows) >= 4
    assert sorted(w for w, _ in built) == list(range(len(stream.model.windows)))  # each window built once
    # the first by a mask thread, the later ones ahead of their frames by the build worker
    assert [name.startswith("wptrack-build") for _, name in sorted(built)] == [False] + [True] * (len(built) - 1)
    assert stream.model._share.ahead is None  # the stream's model alone again after the pass
    assert reads == one_reads and len(one_reads) == len(stream.model.windows)
    assert sum(int(m.sum()) for m, _ in one) > 0
    for (m1, p1), (m2, p2) in zip(one, many, strict=True):
        np.testing.assert_array_equal(m1, m2)
        np.testing.assert_array_equal(p1, p2)
    assert [m.tolist() for m in stream] == [m.tolist() for m, _ in one]  # iterating: the same masks, no probability


def test_masks_in_threads_raise_at_the_failing_frame_and_stop(tmp_path, rng, monkeypatch):
    from wptrack.io.video import write_video
    from wptrack.motion.background import OfflineBackground
    from wptrack.motion.masks import MaskConfig, open_masks

    path = tmp_path / "v.avi"
    write_video(path, _moving_boxes(rng, frames=30))
    config = MaskConfig(window=16, samples=5, device="cpu")
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "2")
    evidence = OfflineBackground.evidence

    def failing(self, t, frame):
        if t == 7:
            raise RuntimeError("device lost at frame 7")
        return evidence(self, t, frame)

    monkeypatch.setattr(OfflineBackground, "evidence", failing)
    got = []
    with pytest.raises(RuntimeError, match="frame 7"):
        for mask in open_masks(video=path, config=config):
            got.append(mask)
    assert len(got) == 7  # every mask before the failing frame, in order
    monkeypatch.setattr(OfflineBackground, "evidence", evidence)

    before = {t.name for t in threading.enumerate()}
    it = iter(open_masks(video=path, config=config))
    for _ in range(5):
        next(it)
    it.close()  # the consumer leaves early: the feeder, the workers and the extra model stop

    def left() -> list[str]:
        return [t.name for t in threading.enumerate() if t.name.startswith("wptrack-masks") and t.name not in before]

    deadline = time.monotonic() + 10.0  # a worker finishes the frame it is on (a window build on a loaded box)
    while left() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not left()


def test_device_cleanup_in_the_offline_model_gives_the_host_masks(tmp_path, rng, monkeypatch):
    """WPTRACK_DEVICE_CLEANUP=1: the offline model resolves and cleans its masks with the device kernels
    (wptrack.motion.cleanup) and downloads the mask: the same masks and probabilities as the host path, also with
    the masks made in two threads, and no probability (the same masks) when none is asked for."""
    from wptrack.io.video import write_video
    from wptrack.motion.masks import MaskConfig, open_masks

    path = tmp_path / "v.avi"
    write_video(path, _moving_boxes(rng, frames=40))
    config = MaskConfig(window=16, samples=5, device="cpu")
    monkeypatch.delenv("WPTRACK_DEVICE_CLEANUP", raising=False)
    monkeypatch.setenv("WPTRACK_MASK_WORKERS", "1")
    host = list(open_masks(video=path, config=config).evidence())
    # asked for the masks only (as the trackers iterate), the kernel skips the probability: the same masks
    masks_only = list(open_masks(video=path, config=config).evidence(probability=False))
    assert all(p is None for _, p in masks_only)
    for (m1, _), (m2, _) in zip(host, masks_only, strict=True):
        np.testing.assert_array_equal(m1, m2)
    monkeypatch.setenv("WPTRACK_DEVICE_CLEANUP", "1")
    for workers in ("1", "2"):
        monkeypatch.setenv("WPTRACK_MASK_WORKERS", workers)
        stream = open_masks(video=path, config=config)
        assert stream.model.cleanup is not None
        got = list(stream.evidence())
        assert len(got) == len(host) == 40 and sum(int(m.sum()) for m, _ in host) > 0
        for (m1, p1), (m2, p2) in zip(host, got, strict=True):
            np.testing.assert_array_equal(m1, m2)
            np.testing.assert_array_equal(p1, p2)
        masks_only = list(stream.evidence(probability=False))
        assert all(p is None for _, p in masks_only)
        for (m1, _), (m2, _) in zip(host, masks_only, strict=True):
            np.testing.assert_array_equal(m1, m2)
    with_area = open_masks(video=path, config=MaskConfig(window=16, samples=5, min_area=20, device="cpu"))
    assert with_area.model.cleanup is None  # min_area is a host filter: the host path


def test_device_cleanup_default_by_device_and_override(monkeypatch, device):
    """The masks are cleaned on the device by default on CUDA, on the host on the CPU; WPTRACK_DEVICE_CLEANUP=0/1
    overrides either way and any other value is a clear error."""
    from wptrack.core.errors import ConfigError
    from wptrack.motion.masks import DEVICE_CLEANUP_ENV, device_cleanup

    monkeypatch.delenv(DEVICE_CLEANUP_ENV, raising=False)
    assert device_cleanup(device) == wp.get_device(device).is_cuda
    monkeypatch.setenv(DEVICE_CLEANUP_ENV, "0")
    assert device_cleanup(device) is False
    monkeypatch.setenv(DEVICE_CLEANUP_ENV, " 1 ")
    assert device_cleanup(device) is True
    monkeypatch.setenv(DEVICE_CLEANUP_ENV, "yes")
    with pytest.raises(ConfigError, match="WPTRACK_DEVICE_CLEANUP: expected 0 or 1"):
        device_cleanup(device)
