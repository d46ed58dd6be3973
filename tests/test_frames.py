"""Frame sources: videos, image folders, globs, arrays; synchronisation and errors; video writing."""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np
import pytest

from wptrack.core.errors import ConfigError, FrameError
from wptrack.io.frames import ArraySource, ImageSequenceSource, SyncedFrames, VideoSource, open_frames, open_source
from wptrack.io.video import VideoWriter, write_video


def _frames(rng: np.random.Generator, n: int, w: int = 32, h: int = 24) -> np.ndarray:
    return rng.integers(0, 256, size=(n, h, w, 3), dtype=np.uint8)


def _write_avi(path: Path, frames: np.ndarray, codec: str = "FFV1") -> Path:
    h, w = frames.shape[1:3]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), 25, (w, h))
    if not writer.isOpened():
        pytest.skip(f"codec {codec} not available")
    for f in frames:
        writer.write(f)
    writer.release()
    return path


def _write_images(folder: Path, frames: np.ndarray, ext: str = ".png", prefix: str = "img") -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, f in enumerate(frames):
        p = folder / f"{prefix}{i}{ext}"
        assert cv2.imwrite(str(p), f)
        paths.append(p)
    return paths


def _patch_avi_count(path: Path, count: int) -> None:
    """Make an AVI report ``count`` frames in its headers (avih dwTotalFrames, strh dwLength)."""
    data = bytearray(path.read_bytes())
    i = data.find(b"avih")
    j = data.find(b"strh")
    assert i >= 0 and j >= 0
    struct.pack_into("<I", data, i + 8 + 16, count)
    struct.pack_into("<I", data, j + 8 + 32, count)
    path.write_bytes(bytes(data))


# ------------------------------------------------------------------------------------------------ sources


def test_video_source(tmp_path, rng):
    frames = _frames(rng, 7)
    path = _write_avi(tmp_path / "a.avi", frames)
    src = open_source(path)
    assert isinstance(src, VideoSource)
    assert (len(src), src.width, src.height) == (7, 32, 24)
    assert src.name == str(path)
    got = list(src)
    assert len(got) == 7
    assert all(g.shape == (24, 32, 3) and g.dtype == np.uint8 for g in got)
    np.testing.assert_array_equal(np.stack(got), frames)  # FFV1 is lossless
    assert len(list(src)) == 7  # iterating again restarts


def test_image_folder_natural_order_and_grayscale(tmp_path, rng):
    frames = _frames(rng, 12, w=20, h=10)
    _write_images(tmp_path / "imgs", frames)  # img0 .. img11: natural order must put img2 before img10
    gray = frames[0, :, :, 0]
    cv2.imwrite(str(tmp_path / "imgs" / "img12.png"), gray)
    (tmp_path / "imgs" / "notes.txt").write_text("not an image")
    src = open_source(tmp_path / "imgs")
    assert isinstance(src, ImageSequenceSource)
    assert (len(src), src.width, src.height) == (13, 20, 10)
    got = list(src)
    np.testing.assert_array_equal(np.stack(got[:12]), frames)
    assert got[12].shape == (10, 20, 3)
    np.testing.assert_array_equal(got[12], np.repeat(gray[:, :, None], 3, axis=2))


def test_glob_and_single_image(tmp_path, rng):
    frames = _frames(rng, 4)
    _write_images(tmp_path, frames, ext=".bmp", prefix="cam_")
    _write_images(tmp_path, frames[:1], ext=".bmp", prefix="other_")
    src = open_source(str(tmp_path / "cam_*.bmp"))
    assert len(src) == 4
    np.testing.assert_array_equal(np.stack(list(src)), frames)
    single = open_source(tmp_path / "other_0.bmp")
    assert len(single) == 1
    np.testing.assert_array_equal(next(iter(single)), frames[0])


def test_array_sources(rng):
    color = _frames(rng, 3)
    src = open_source(color, name="array[0]")
    assert isinstance(src, ArraySource)
    assert (len(src), src.size, src.name) == (3, (32, 24), "array[0]")
    np.testing.assert_array_equal(np.stack(list(src)), color)
    gray = color[..., 1]
    got = list(open_source(gray))
    assert got[0].shape == (24, 32, 3)
    np.testing.assert_array_equal(got[2][..., 2], gray[2])


# ------------------------------------------------------------------------------------------------ sync


def test_sync_two_cameras_different_sizes(tmp_path, rng):
    a = _frames(rng, 5, w=32, h=24)
    b = _frames(rng, 5, w=16, h=8)
    path_a = _write_avi(tmp_path / "a.avi", a)
    _write_images(tmp_path / "b", b, ext=".png")
    synced = open_frames([path_a, tmp_path / "b"])
    assert isinstance(synced, SyncedFrames)
    assert len(synced) == 5
    assert synced.sizes == [(32, 24), (16, 8)]
    steps = list(synced)
    assert len(steps) == 5
    for i, (fa, fb) in enumerate(steps):
        np.testing.assert_array_equal(fa, a[i])
        np.testing.assert_array_equal(fb, b[i])


def test_different_counts_error_and_stop_at_shortest(tmp_path, rng):
    pa = _write_avi(tmp_path / "a.avi", _frames(rng, 6))
    pb = _write_avi(tmp_path / "b.avi", _frames(rng, 4))
    with pytest.raises(FrameError) as err:
        open_frames([pa, pb])
    msg = str(err.value)
    assert f"{pa} 6" in msg and f"{pb} 4" in msg and "--stop-at-shortest" in msg and "\n" not in msg
    synced = open_frames([pa, pb], stop_at_shortest=True)
    assert len(synced) == 4 and len(list(synced)) == 4
    # max_frames within the common part needs no --stop-at-shortest
    assert len(list(open_frames([pa, pb], max_frames=3))) == 3


def test_max_frames(rng):
    arrays = [_frames(rng, 5), _frames(rng, 5, w=8, h=8)]
    assert len(open_frames(arrays, max_frames=2)) == 2
    assert len(list(open_frames(arrays, max_frames=2))) == 2
    assert len(open_frames(arrays, max_frames=50)) == 5
    assert list(open_frames(arrays, max_frames=0)) == []
    with pytest.raises(ConfigError):
        open_frames(arrays, max_frames=-1)
    assert open_frames(arrays).names == ["array[0]", "array[1]"]


def test_video_shorter_than_reported(tmp_path, rng):
    short = _write_avi(tmp_path / "short.avi", _frames(rng, 5))
    _patch_avi_count(short, 8)
    src = open_source(short)
    if len(src) != 8:
        pytest.skip("this OpenCV build does not report the patched frame count")
    assert len(list(src)) == 5
    other = _write_avi(tmp_path / "other.avi", _frames(rng, 8))
    synced = open_frames([other, short])
    got = []
    with pytest.raises(FrameError) as err:
        for step in synced:
            got.append(step)
    assert len(got) == 5
    assert str(short) in str(err.value) and "ended after 5" in str(err.value)
    assert len(list(open_frames([other, short], stop_at_shortest=True))) == 5
    assert len(list(open_frames([short]))) == 5  # alone: stops early with a warning in the log


# ------------------------------------------------------------------------------------------------ errors


def test_missing_file(tmp_path):
    path = tmp_path / "nope.avi"
    with pytest.raises(FrameError, match="not found") as err:
        open_source(path)
    assert str(path) in str(err.value)


def test_unreadable_video(tmp_path):
    path = tmp_path / "junk.avi"
    path.write_bytes(b"this is not a video" * 10)
    with pytest.raises(FrameError) as err:
        open_source(path)
    assert str(path) in str(err.value)


def test_empty_folder_and_unmatched_glob(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(FrameError) as err:
        open_source(tmp_path / "empty")
    assert str(tmp_path / "empty") in str(err.value)
    pattern = str(tmp_path / "x_*.png")
    with pytest.raises(FrameError) as err:
        open_source(pattern)
    assert pattern in str(err.value)


def test_unreadable_image(tmp_path, rng):
    paths = _write_images(tmp_path / "imgs", _frames(rng, 3))
    paths[1].write_bytes(b"garbage")
    src = open_source(tmp_path / "imgs")
    with pytest.raises(FrameError) as err:
        list(src)
    assert str(paths[1]) in str(err.value)
    paths[0].write_bytes(b"")
    with pytest.raises(FrameError) as err:
        open_source(tmp_path / "imgs")
    assert str(paths[0]) in str(err.value)


@pytest.mark.parametrize(
    "array, what",
    [
        (np.zeros((2, 4, 4, 3), np.float32), "uint8"),
        (np.zeros((4, 4), np.uint8), "shape"),
        (np.zeros((2, 4, 4, 2), np.uint8), "shape"),
        (np.zeros((0, 4, 4, 3), np.uint8), "empty"),
    ],
)
def test_bad_arrays(array, what):
    with pytest.raises(FrameError, match=what) as err:
        open_frames([np.zeros((2, 4, 4, 3), np.uint8), array])
    assert "array[1]" in str(err.value)


def test_frame_size_change(tmp_path, rng):
    paths = _write_images(tmp_path / "imgs", _frames(rng, 3))
    cv2.imwrite(str(paths[2]), _frames(rng, 1, w=16, h=16)[0])
    with pytest.raises(FrameError, match="size") as err:
        list(open_source(tmp_path / "imgs"))
    assert str(paths[2]) in str(err.value)


def test_no_sources():
    with pytest.raises(FrameError):
        SyncedFrames([])


# ------------------------------------------------------------------------------------------------ writing


def test_write_video_ffv1_lossless(tmp_path, rng):
    frames = _frames(rng, 6)
    path = write_video(tmp_path / "out.avi", frames, fps=10)
    assert path == tmp_path / "out.avi"
    assert [p.name for p in tmp_path.iterdir()] == ["out.avi"]  # the temporary file was renamed
    src = open_source(path)
    assert len(src) == 6
    np.testing.assert_array_equal(np.stack(list(src)), frames)


def test_video_writer_mjpg_fallback(tmp_path, rng, monkeypatch):
    import wptrack.io.video as frames_mod

    monkeypatch.setitem(frames_mod.VIDEO_CODECS, ".avi", ("XXXX", "MJPG"))
    frames = _frames(rng, 5)
    with VideoWriter(tmp_path / "m.avi", fps=25, size=(32, 24)) as writer:
        assert writer.codec == "MJPG"
        for f in frames:
            writer.write(f)
    got = list(open_source(tmp_path / "m.avi"))
    assert len(got) == 5 and got[0].shape == (24, 32, 3)


def test_video_writer_interrupted_leaves_nothing(tmp_path, rng):
    with pytest.raises(KeyboardInterrupt):
        with VideoWriter(tmp_path / "x.avi", fps=25) as writer:
            writer.write(_frames(rng, 1)[0])
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    assert write_video(tmp_path / "empty.avi", []) is None
    assert list(tmp_path.iterdir()) == []


def test_video_writer_mp4_and_size_check(tmp_path, rng):
    frames = _frames(rng, 3)
    with VideoWriter(tmp_path / "v.mp4", fps=25) as writer:
        for f in frames:
            writer.write(f)
        with pytest.raises(ValueError):
            writer.write(_frames(rng, 1, w=8, h=8)[0])
    assert writer.codec in ("mp4v", "avc1")
    assert len(list(open_source(tmp_path / "v.mp4"))) == 3


def test_prefetch_order_errors_and_early_stop():
    import threading
    import time

    from wptrack.io.prefetch import prefetch

    assert list(prefetch(range(50), depth=3)) == list(range(50))

    def failing():
        yield 1
        yield 2
        raise FrameError("broken.avi: unreadable frame 2")

    got = []
    with pytest.raises(FrameError, match="broken.avi"):
        for x in prefetch(failing()):
            got.append(x)
    assert got == [1, 2]

    produced = []

    def slow():
        for k in range(1000):
            produced.append(k)
            yield k

    p = prefetch(slow(), depth=2)
    for x in p:
        if x == 3:
            break
    time.sleep(0.3)
    assert len(produced) < 10, "the thread must stop after the consumer leaves"
    assert not any(t.name == "wptrack-prefetch" and t.is_alive() for t in threading.enumerate())


@pytest.mark.parametrize("suffix", [".avi", ".mp4"])
def test_video_reader_gives_the_frames_of_a_sequential_read_in_any_order(tmp_path, suffix):
    """Random access (seeks over long gaps, backwards, collected frames on the way) gives the same frames as
    decoding the file from the start (lossless FFV1 and lossy MPEG-4 with keyframes far apart)."""
    from wptrack.io.frames import VideoReader, VideoSource
    from wptrack.io.video import write_video

    rng = np.random.default_rng(4)
    frames = [np.full((24, 32, 3), 7 * k % 256, np.uint8) + rng.integers(0, 20, (24, 32, 3), dtype=np.uint8)
              for k in range(60)]  # fmt: skip
    path = write_video(tmp_path / f"v{suffix}", frames, fps=10)
    src = VideoSource(path)
    truth = list(src)
    reader = VideoReader(src, seek_gap=5)
    for i in [3, 40, 41, 12, 59, 0, 30]:
        np.testing.assert_array_equal(reader.read(i), truth[i])
    assert reader.read(len(truth) + 3) is None
    reader.close()
    through = VideoReader(src, seek_gap=100)  # decodes through the gap: the collected frames come along
    np.testing.assert_array_equal(through.read(10, collect={4, 7, 12}), truth[10])
    assert sorted(through.passed) == [4, 7]
    for i, frame in through.passed.items():
        np.testing.assert_array_equal(frame, truth[i])
    through.close()
