"""Motion-JPEG videos read as JPEG packets (wptrack.io.jpeg): the same images as a decoder gives, only the frames
retrieved decoded, bounded frames in flight, and FFmpeg's decoder where the packets do not decode alone."""

from __future__ import annotations

import threading
import time

import cv2
import numpy as np
import pytest

from wptrack.io import jpeg
from wptrack.io.frames import open_source
from wptrack.motion import windows as Wn


def _mjpg(path, frames):
    h, w = frames.shape[1:3]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25, (w, h))
    if not writer.isOpened():
        pytest.skip("no MJPG writer")
    for f in frames:
        writer.write(f)
    writer.release()
    return path


def _smooth(rng, n, h=48, w=64):
    """Frames of smooth colour fields (what a camera sees; JPEG decoders agree closely on them), each different."""
    base = cv2.resize(rng.uniform(40, 220, (6, 8, 3)).astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC)
    return np.stack([np.clip(base + 3 * k, 0, 255).astype(np.uint8) for k in range(n)])


def test_packets_decode_to_the_videos_images(tmp_path, rng, monkeypatch):
    """A Motion-JPEG video opens as JPEG packets; its frames are the JPEG images (``cv2.imdecode`` of each packet),
    as close to what was encoded as FFmpeg's decoder gives (closer here: FFmpeg converts its YUV output to BGR in a
    second step); WPTRACK_JPEG_DECODE=0 reads it with FFmpeg."""
    frames = _smooth(rng, 12)
    path = _mjpg(tmp_path / "v.avi", frames)
    src = open_source(path)
    assert src.jpeg and len(src) == 12 and (src.width, src.height) == (64, 48)
    got = np.stack(list(src))
    monkeypatch.setenv(jpeg.JPEG_DECODE_ENV, "0")
    ffmpeg = open_source(path)
    assert not ffmpeg.jpeg
    ref = np.stack(list(ffmpeg))
    err, err_ffmpeg = (np.abs(x.astype(int) - frames).mean() for x in (got, ref))
    assert err < 3 and err <= err_ffmpeg  # the encoded images
    assert not np.array_equal(got, ref)  # by another decoder (libjpeg-turbo): what the module's docstring says


def test_packets_that_do_not_decode_alone_fall_back_to_ffmpeg(tmp_path, rng, monkeypatch):
    path = _mjpg(tmp_path / "v.avi", _smooth(rng, 4))
    monkeypatch.setattr(jpeg, "decode_packet", lambda packet: None)  # e.g. an AVI1 stream without Huffman tables
    src = open_source(path)
    assert not src.jpeg and len(list(src)) == 4


def test_sampler_decodes_only_the_samples(tmp_path, rng, monkeypatch):
    """The background's sampler passes the frames between samples as packets: one decode per frame it keeps (the
    samples and the next window's frames on its way), the frames a full read gives."""
    n = 60
    path = _mjpg(tmp_path / "v.avi", _smooth(rng, n))
    source = open_source(path)
    full = np.stack(list(source))
    calls = []
    real = jpeg.decode_packet
    monkeypatch.setattr(jpeg, "decode_packet", lambda packet: calls.append(1) or real(packet))
    sampler = Wn._Sampler(source, readers=1)
    indices, ahead = (3, 13, 23, 33), (28, 38)
    got = sampler.read(indices, ahead)
    np.testing.assert_array_equal(np.stack(got), full[list(indices)])
    assert len(calls) == len(indices) + 1  # and frame 28, kept for the next window on the way
    assert sorted(sampler.kept) == [28]
    sampler.close()


def test_threads_keep_a_bounded_number_of_frames_in_flight(tmp_path, rng, monkeypatch):
    """Several threads decode a Motion-JPEG video's frames, in order; a slow consumer holds at most 2 x workers
    decoded or pending frames; closing the iteration early leaves no decoding thread behind."""
    n = 40
    path = _mjpg(tmp_path / "v.avi", _smooth(rng, n))
    source = open_source(path)
    monkeypatch.setenv(jpeg.JPEG_WORKERS_ENV, "1")
    one = list(source)
    calls = []
    real = jpeg.decode_packet
    monkeypatch.setattr(jpeg, "decode_packet", lambda packet: calls.append(1) or real(packet))
    before = {t.name for t in threading.enumerate()}
    items = jpeg.jpeg_frames(source._open(), n, 3)
    consumed = []
    for i, ok, frame, _ in items:
        assert ok
        consumed.append(frame)
        time.sleep(0.002)
        assert len(calls) <= i + 1 + 2 * 3  # never more than 2 x workers ahead of the consumer
        if i == 9:
            break
    assert [t.name for t in threading.enumerate() if t.name.startswith("wptrack-jpeg") and t.name not in before]
    items.close()
    time.sleep(0.2)
    assert not [t.name for t in threading.enumerate() if t.name.startswith("wptrack-jpeg") and t.name not in before]
    for a, b in zip(consumed, one[:10], strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("kind", ["bilevel", "grey", "bgr"])
def test_png_videos_are_read_as_packets_exactly(tmp_path, rng, monkeypatch, kind):
    """wptrack's own PNG videos (masks.avi: wptrack.io.avi) are read as packets too: the frames exact (lossless), in
    order through the decoding threads, seeks included; FFmpeg's decoder gives the same frames."""
    from wptrack.io.avi import PngAviWriter

    h, w = 36, 50
    if kind == "bgr":
        frames = rng.integers(0, 256, (9, h, w, 3), dtype=np.uint8)
    else:
        frames = rng.integers(0, 256, (9, h, w), dtype=np.uint8)
        if kind == "bilevel":
            frames = np.where(frames > 200, 255, 0).astype(np.uint8)
    path = tmp_path / "m.avi"
    with PngAviWriter(path, 25.0, (w, h), bilevel=kind == "bilevel", workers=2) as writer:
        for f in frames:
            writer.write(f)
    expect = frames if kind == "bgr" else np.repeat(frames[..., None], 3, axis=3)
    monkeypatch.setenv(jpeg.JPEG_WORKERS_ENV, "3")  # several decoding threads: frames still in order
    src = open_source(path)
    assert src.jpeg and len(src) == 9
    np.testing.assert_array_equal(np.stack(list(src)), expect)
    from wptrack.io.frames import VideoReader

    reader = VideoReader(src, seek_gap=1)  # random access (a seek to each frame)
    for k in (6, 2, 8):
        np.testing.assert_array_equal(reader.read(k), expect[k])
    reader.close()
    monkeypatch.setenv(jpeg.JPEG_DECODE_ENV, "0")
    ffmpeg = open_source(path)
    assert not ffmpeg.jpeg
    np.testing.assert_array_equal(np.stack(list(ffmpeg)), expect)


def test_png_packets_decode_to_bgr_whatever_their_channels(rng):
    """decode_packet gives (H, W, 3) BGR for 1-bit, 8-bit grey, BGR and BGRA PNG images alike (and JPEG as before)."""
    grey = rng.integers(0, 256, (7, 11), dtype=np.uint8)
    bgr = rng.integers(0, 256, (7, 11, 3), dtype=np.uint8)
    bgra = np.concatenate([bgr, rng.integers(0, 256, (7, 11, 1), dtype=np.uint8)], axis=2)
    mask = np.where(grey > 100, 255, 0).astype(np.uint8)
    cases = [
        (cv2.imencode(".png", mask, [cv2.IMWRITE_PNG_BILEVEL, 1])[1], np.repeat(mask[..., None], 3, axis=2)),
        (cv2.imencode(".png", grey)[1], np.repeat(grey[..., None], 3, axis=2)),
        (cv2.imencode(".png", bgr)[1], bgr),
        (cv2.imencode(".png", bgra)[1], bgr),
    ]
    for packet, expect in cases:
        got = jpeg.decode_packet(packet)
        assert got.shape == (7, 11, 3) and got.dtype == np.uint8
        np.testing.assert_array_equal(got, expect)
    jpg = cv2.imencode(".jpg", bgr)[1]
    np.testing.assert_array_equal(jpeg.decode_packet(jpg), cv2.imdecode(jpg, cv2.IMREAD_COLOR))
