"""AVI of PNG images (wptrack.io.avi.PngAviWriter, VideoWriter(codec="PNG")): exact round trips through OpenCV's
reader, the header's counts and rate, seeks, OpenDML files of several RIFFs (checked chunk by chunk and through
OpenCV), frames kept in order by several encoding threads, bounded frames in flight, abort and errors, and the
masks.avi of ``wptrack masks`` and of a resumed run."""

from __future__ import annotations

import struct
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from wptrack.core.errors import ConfigError, OutputError
from wptrack.io import avi
from wptrack.io.avi import PngAviWriter, png_workers
from wptrack.io.frames import open_source
from wptrack.io.video import BackgroundWriter, VideoWriter, continue_video
from wptrack.motion.masks import MaskConfig, open_masks
from wptrack.motion.writing import write_masks

# ------------------------------------------------------------------------------------------------ helpers


def _frames(rng: np.random.Generator, kind: str, size: tuple[int, int], count: int) -> list[np.ndarray]:
    w, h = size
    if kind == "bilevel":
        return [((rng.random((h, w)) < 0.3) * 255).astype(np.uint8) for _ in range(count)]
    if kind == "grey":
        return [rng.integers(0, 256, (h, w), dtype=np.uint8) for _ in range(count)]
    return [rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for _ in range(count)]


def _write(path: Path, frames: list[np.ndarray], fps: float = 25.0, **kw) -> PngAviWriter:
    h, w = frames[0].shape[:2]
    writer = PngAviWriter(path, fps, (w, h), **kw)
    for f in frames:
        writer.write(f)
    assert writer.close() == path
    return writer


def _read(path: Path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    assert cap.isOpened()
    out = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        out.append(f)
    cap.release()
    return out


def _same(decoded: np.ndarray, frame: np.ndarray) -> bool:
    """An OpenCV BGR frame read back equals the frame written (a grey frame in all three channels)."""
    if frame.ndim == 2:
        return all(np.array_equal(decoded[..., c], frame) for c in range(3))
    return np.array_equal(decoded, frame)


def _chunks(data: bytes, start: int, end: int) -> list[tuple[bytes, int, int]]:
    """``(fourcc, body offset, body size)`` of the RIFF chunks that exactly fill ``data[start:end]``."""
    out = []
    pos = start
    while pos < end:
        fourcc = data[pos : pos + 4]
        size = struct.unpack_from("<I", data, pos + 4)[0]
        out.append((fourcc, pos + 8, size))
        pos += 8 + size + (size & 1)
    assert pos == end, "chunks overrun their parent"
    return out


def _parse(path: Path) -> dict:
    """Walk an AVI file written by PngAviWriter, checking its structure against the AVI / OpenDML layout; returns the
    header fields, the frames' PNG bytes per RIFF and the indexes."""
    data = path.read_bytes()
    riffs = _chunks(data, 0, len(data))
    assert all(fcc == b"RIFF" for fcc, _, _ in riffs)
    forms = [data[off : off + 4] for _, off, _ in riffs]
    assert forms[0] == b"AVI " and all(f == b"AVIX" for f in forms[1:])
    info: dict = {"riff_sizes": [8 + size for _, _, size in riffs], "segments": []}
    for k, (_, off, size) in enumerate(riffs):
        subs = _chunks(data, off + 4, off + size)
        lists = {data[o : o + 4]: (o, s) for fcc, o, s in subs if fcc == b"LIST"}
        if k == 0:
            assert subs[0][0] == b"LIST" and data[subs[0][1] : subs[0][1] + 4] == b"hdrl"
            hdrl = _chunks(data, subs[0][1] + 4, subs[0][1] + subs[0][2])
            assert [c[0] for c in hdrl[:2]] == [b"avih", b"LIST"] and hdrl[2][0] in (b"LIST", b"JUNK")
            info["avih"] = struct.unpack_from("<14I", data, hdrl[0][1])
            strl = _chunks(data, hdrl[1][1] + 4, hdrl[1][1] + hdrl[1][2])
            assert data[hdrl[1][1] : hdrl[1][1] + 4] == b"strl"
            assert [c[0] for c in strl[:2]] == [b"strh", b"strf"]
            info["strh"] = struct.unpack_from("<4s4sIHHIIIIIIIIhhhh", data, strl[0][1])
            info["strf"] = struct.unpack_from("<IiiHHIIiiII", data, strl[1][1])
            info["indx_tag"] = strl[2][0]
            n_super = struct.unpack_from("<I", data, strl[2][1] + 4)[0]
            info["super"] = [struct.unpack_from("<QII", data, strl[2][1] + 24 + 16 * j) for j in range(n_super)]
            info["odml_tag"] = hdrl[2][0]
            assert data[hdrl[2][1] : hdrl[2][1] + 8] == b"odmldmlh"
            info["dmlh_frames"] = struct.unpack_from("<I", data, hdrl[2][1] + 12)[0]
            idx1 = [c for c in subs if c[0] == b"idx1"]
            assert len(idx1) == 1
            n = idx1[0][2] // 16
            info["idx1"] = [struct.unpack_from("<4sIII", data, idx1[0][1] + 16 * j) for j in range(n)]
        else:
            assert [c[0] for c in subs] == [b"LIST"]  # an AVIX: its movi list only
        movi_at, movi_size = lists[b"movi"]
        movi = _chunks(data, movi_at + 4, movi_at + movi_size)
        frames = [(o, s) for fcc, o, s in movi if fcc == b"00dc"]
        ix = [(o, s) for fcc, o, s in movi if fcc == b"ix00"]
        assert all(fcc in (b"00dc", b"ix00") for fcc, _, _ in movi)
        seg = {"movi": movi_at, "frames": frames, "png": [data[o : o + s] for o, s in frames], "ix": None}
        if ix:
            (o, s), last = ix[0], movi[-1]
            assert len(ix) == 1 and last[0] == b"ix00", "the ix00 ends the movi list"
            longs, sub, kind, n, chunk_id, base = struct.unpack_from("<HBBI4sQ", data, o)
            assert (longs, sub, kind, chunk_id, base) == (2, 0, 1, b"00dc", movi_at)
            entries = [struct.unpack_from("<II", data, o + 24 + 8 * j) for j in range(n)]
            seg["ix"] = {"at": o - 8, "size": 8 + s, "entries": [(base + a, b) for a, b in entries]}
        info["segments"].append(seg)
    return info


def _check_layout(path: Path, frames: list[np.ndarray], fps: float, segment_bytes: int | None = None) -> dict:
    """Every field the AVI / OpenDML readers use, checked against the frames written."""
    info = _parse(path)
    segs = info["segments"]
    pngs = [p for s in segs for p in s["png"]]
    assert len(pngs) == len(frames)
    for png, frame in zip(pngs, frames, strict=True):  # the chunks hold the frames' PNG images, in order
        assert png[:8] == b"\x89PNG\r\n\x1a\n"
        assert np.array_equal(cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED), frame)
    h, w = frames[0].shape[:2]
    largest = max(len(p) for p in pngs)
    avih, strh, strf = info["avih"], info["strh"], info["strf"]
    first = len(segs[0]["frames"])
    assert avih[4] == first and avih[6] == 1 and avih[7] == largest and avih[8:10] == (w, h)
    assert avih[0] == round(1e6 / fps) and avih[3] & 0x10  # AVIF_HASINDEX
    assert strh[:2] == (b"vids", b"MPNG") and strh[9] == len(frames) and strh[10] == largest
    assert strh[7] / strh[6] == pytest.approx(fps, rel=1e-9)  # rate / scale
    assert strf[0] == 40 and strf[1:3] == (w, h) and struct.pack("<I", strf[5]) == b"MPNG"
    # idx1: the first RIFF's frames, chunk headers from the 'movi' FOURCC, keyframes
    movi0 = segs[0]["movi"]
    assert [(e[0], e[1], movi0 + e[2] + 8, e[3]) for e in info["idx1"]] == [
        (b"00dc", 0x10, o, s) for o, s in segs[0]["frames"]
    ]
    if len(segs) == 1:
        assert info["indx_tag"] == b"JUNK" and info["odml_tag"] == b"JUNK" and segs[0]["ix"] is None
    else:
        assert info["indx_tag"] == b"indx" and info["odml_tag"] == b"LIST"
        assert info["dmlh_frames"] == len(frames)
        assert info["super"] == [(s["ix"]["at"], s["ix"]["size"], len(s["frames"])) for s in segs]
        for s in segs:  # ix00: data offsets from the base, sizes, keyframes (bit 31 clear)
            assert s["ix"]["entries"] == s["frames"]
    if segment_bytes is not None:
        for size, s in zip(info["riff_sizes"], segs, strict=True):
            assert size <= segment_bytes or len(s["frames"]) == 1
    return info


# ------------------------------------------------------------------------------------------------ round trips


@pytest.mark.parametrize("kind", ["bilevel", "grey", "bgr"])
@pytest.mark.parametrize("size", [(1, 1), (51, 37), (160, 9)])
def test_round_trip_is_exact(tmp_path, rng, kind, size):
    frames = _frames(rng, kind, size, 6)
    path = tmp_path / "v.avi"
    writer = _write(path, frames, bilevel=kind == "bilevel", workers=2)
    assert writer.frames == 6 and writer.segments == 1 and writer.close() == path  # close: idempotent
    back = _read(path)
    assert len(back) == 6
    assert all(_same(b, f) for b, f in zip(back, frames, strict=True))
    _check_layout(path, frames, 25.0)


def test_bilevel_images_are_one_bit_and_smaller(tmp_path, rng):
    frames = _frames(rng, "bilevel", (64, 48), 4)
    _write(tmp_path / "b.avi", frames, bilevel=True)
    _write(tmp_path / "g.avi", frames, bilevel=False)
    bits = [p[24] for p in _parse(tmp_path / "b.avi")["segments"][0]["png"]]  # IHDR bit depth
    assert bits == [1] * 4 and [p[24] for p in _parse(tmp_path / "g.avi")["segments"][0]["png"]] == [8] * 4
    assert (tmp_path / "b.avi").stat().st_size < (tmp_path / "g.avi").stat().st_size
    assert all(_same(b, f) for b, f in zip(_read(tmp_path / "b.avi"), frames, strict=True))


@pytest.mark.parametrize("fps", [25.0, 7.0, 29.97, 30000 / 1001, 12.5])
def test_frame_count_and_rate_read_back(tmp_path, rng, fps):
    frames = _frames(rng, "bilevel", (40, 30), 11)
    path = tmp_path / "v.avi"
    _write(path, frames, fps=fps, bilevel=True)
    cap = cv2.VideoCapture(str(path))
    assert cap.get(cv2.CAP_PROP_FRAME_COUNT) == 11
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(fps, rel=1e-6)
    assert int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little") == b"MPNG"
    assert (cap.get(cv2.CAP_PROP_FRAME_WIDTH), cap.get(cv2.CAP_PROP_FRAME_HEIGHT)) == (40, 30)
    cap.release()
    _check_layout(path, frames, fps)
    assert open_source(path).fps == pytest.approx(fps, rel=1e-6)


def test_seeks_land_on_the_frame_asked_for(tmp_path, rng):
    frames = _frames(rng, "grey", (33, 21), 20)
    path = tmp_path / "v.avi"
    _write(path, frames)
    cap = cv2.VideoCapture(str(path))
    for target in (13, 0, 19, 7, 8, 2):
        assert cap.set(cv2.CAP_PROP_POS_FRAMES, target)
        ok, f = cap.read()
        assert ok and _same(f, frames[target]), target
    cap.release()


def test_parallel_decoding_reads_the_frames_in_order(tmp_path, rng, monkeypatch):
    """A masks video read by several captures at once (wptrack.io.decode: seeks to each chunk) gives every frame."""
    frames = _frames(rng, "bilevel", (24, 16), 40)
    path = tmp_path / "m.avi"
    _write(path, frames, bilevel=True)
    monkeypatch.setenv("WPTRACK_DECODE_WORKERS", "3")
    back = list(open_source(path))
    assert len(back) == 40 and all(_same(b, f) for b, f in zip(back, frames, strict=True))


def test_empty_file_is_a_valid_avi(tmp_path):
    path = tmp_path / "e.avi"
    PngAviWriter(path, 25.0, (8, 6)).close()
    info = _parse(path)
    assert info["avih"][4] == 0 and info["strh"][9] == 0 and info["idx1"] == []
    assert _read(path) == []


# ------------------------------------------------------------------------------------------------ OpenDML


@pytest.mark.parametrize("kind", ["bilevel", "bgr"])
def test_files_of_several_riffs_are_read_whole_and_exact(tmp_path, rng, kind):
    frames = _frames(rng, kind, (45, 31), 60)
    path = tmp_path / "v.avi"
    limit = 7000 if kind == "bilevel" else 20000
    writer = _write(path, frames, fps=29.97, bilevel=kind == "bilevel", workers=3, segment_bytes=limit)
    assert writer.segments >= 4
    info = _check_layout(path, frames, 29.97, segment_bytes=limit)
    assert len(info["segments"]) == writer.segments
    back = _read(path)
    assert len(back) == 60 and all(_same(b, f) for b, f in zip(back, frames, strict=True))
    cap = cv2.VideoCapture(str(path))
    assert cap.get(cv2.CAP_PROP_FRAME_COUNT) == 60
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(29.97)
    last_riff_first = 60 - len(info["segments"][-1]["frames"])
    for target in (last_riff_first, 59, 3, last_riff_first - 1, 31):  # into later RIFFs and back
        assert cap.set(cv2.CAP_PROP_POS_FRAMES, target)
        ok, f = cap.read()
        assert ok and _same(f, frames[target]), target
        assert cap.get(cv2.CAP_PROP_POS_FRAMES) == target + 1
    cap.release()


def test_opencv_reads_the_later_riffs_through_their_ix00_index(tmp_path, rng):
    """A damaged ix00 entry in a later RIFF breaks reading there: OpenCV (FFmpeg) follows the OpenDML index, so the
    index checked above is the one in use."""
    frames = _frames(rng, "grey", (30, 20), 30)
    path = tmp_path / "v.avi"
    _write(path, frames, segment_bytes=6000)
    info = _parse(path)
    assert len(info["segments"]) >= 3
    data = bytearray(path.read_bytes())
    at = info["segments"][1]["ix"]["at"] + 8 + 24  # the second RIFF's first entry: its data offset
    data[at : at + 4] = b"\0\0\0\0"
    broken = tmp_path / "broken.avi"
    broken.write_bytes(bytes(data))
    assert len(_read(path)) == 30 and len(_read(broken)) < 30


def test_super_index_full_is_an_output_error(tmp_path, rng, monkeypatch):
    monkeypatch.setattr(avi, "SUPER_INDEX_ENTRIES", 3)
    frames = _frames(rng, "grey", (30, 20), 10)
    writer = PngAviWriter(tmp_path / "v.avi", 25.0, (30, 20), segment_bytes=1, workers=1)
    with pytest.raises(OutputError, match="super index is full"):
        for f in frames:
            writer.write(f)
        writer.close()
    assert not (tmp_path / "v.avi").exists()


# ------------------------------------------------------------------------------------------------ threads


def _slow_encoder(delays: dict[int, float], log: list | None = None, writer_box: list | None = None):
    """An encoder sleeping ``delays[frame value]`` seconds first (frames are constant images of their index)."""
    real = avi.encode_png

    def encode(frame: np.ndarray, bilevel: bool, compression: int = 1) -> bytes:
        k = int(frame.flat[0])
        if log is not None and writer_box:
            log.append((k, writer_box[0].frames))
        time.sleep(delays.get(k, 0.0))
        return real(frame, bilevel, compression)

    return encode


def test_frames_stay_in_order_with_uneven_encoding_times(tmp_path, monkeypatch, rng):
    delays = {k: float(rng.choice([0.0, 0.002, 0.02])) for k in range(30)}
    delays[0] = 0.05  # the first frame finishes last of its batch
    monkeypatch.setattr(avi, "encode_png", _slow_encoder(delays))
    frames = [np.full((10, 12), k, np.uint8) for k in range(30)]
    path = tmp_path / "v.avi"
    _write(path, frames, workers=4)
    assert [int(f[0, 0, 0]) for f in _read(path)] == list(range(30))


def test_write_copies_the_frame(tmp_path, monkeypatch):
    """The caller may reuse its buffer as soon as write returns (the frame is encoded later, in the pool)."""
    monkeypatch.setattr(avi, "encode_png", _slow_encoder(dict.fromkeys(range(12), 0.01)))
    buffer = np.zeros((10, 12), np.uint8)
    path = tmp_path / "v.avi"
    writer = PngAviWriter(path, 25.0, (12, 10), workers=2)
    for k in range(12):
        buffer[:] = k
        writer.write(buffer)
    buffer[:] = 99
    writer.close()
    assert [int(f[0, 0, 0]) for f in _read(path)] == list(range(12))


def test_frames_in_flight_are_bounded(tmp_path, monkeypatch):
    starts: list[tuple[int, int]] = []
    box: list[PngAviWriter] = []
    monkeypatch.setattr(avi, "encode_png", _slow_encoder(dict.fromkeys(range(24), 0.005), starts, box))
    writer = PngAviWriter(tmp_path / "v.avi", 25.0, (12, 10), workers=2, in_flight=3)
    box.append(writer)
    peak = 0
    for k in range(24):
        writer.write(np.full((10, 12), k, np.uint8))
        peak = max(peak, writer.pending)
    assert peak == 3  # the writer waits for the oldest frame when 3 are in flight
    writer.close()
    assert writer.frames == 24 and len(starts) == 24
    # frame k is handed to the pool only once frame k - 3 is in the file
    assert all(written >= k - 2 for k, written in starts)


def test_png_workers_default_and_environment(tmp_path, monkeypatch):
    from wptrack.core.config import host_cores

    monkeypatch.delenv(avi.PNG_WORKERS_ENV, raising=False)
    assert png_workers() == max(1, min(4, host_cores() // 2))
    monkeypatch.setenv(avi.PNG_WORKERS_ENV, "7")
    assert png_workers() == 7
    writer = PngAviWriter(tmp_path / "v.avi", 25.0, (4, 4))  # the writer's default
    assert writer.workers == 7 and writer.in_flight == 14
    writer.abort()


# ------------------------------------------------------------------------------------------------ abort, errors


def test_abort_leaves_no_file(tmp_path, monkeypatch):
    monkeypatch.setattr(avi, "encode_png", _slow_encoder(dict.fromkeys(range(10), 0.02)))
    path = tmp_path / "v.avi"
    writer = PngAviWriter(path, 25.0, (12, 10), workers=2)
    for k in range(6):
        writer.write(np.full((10, 12), k, np.uint8))
    assert path.exists() and writer.pending > 0
    writer.abort()
    writer.abort()  # idempotent
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(RuntimeError, match="closed"):
        writer.write(np.zeros((10, 12), np.uint8))
    with pytest.raises(RuntimeError, match="closed"):
        writer.close()


def test_with_block_left_by_an_exception_removes_the_file(tmp_path, rng):
    path = tmp_path / "v.avi"
    with pytest.raises(KeyError), PngAviWriter(path, 25.0, (8, 6)) as writer:
        writer.write(np.zeros((6, 8), np.uint8))
        raise KeyError("stop")
    assert not path.exists()


def test_an_encoding_error_is_raised_by_a_later_write_or_close(tmp_path, monkeypatch):
    real = avi.encode_png

    def failing(frame, bilevel, compression=1):
        if int(frame.flat[0]) == 3:
            time.sleep(0.05)  # the error comes after the write that handed the frame over
            raise RuntimeError("encoder broke on frame 3")
        return real(frame, bilevel, compression)

    monkeypatch.setattr(avi, "encode_png", failing)
    path = tmp_path / "v.avi"
    writer = PngAviWriter(path, 25.0, (12, 10), workers=2)
    with pytest.raises(RuntimeError, match="frame 3"):
        for k in range(40):
            writer.write(np.full((10, 12), k, np.uint8))
            time.sleep(0.002)
    assert k < 40 and not path.exists()
    with pytest.raises(OutputError, match="frame 3"):  # the writer stays failed
        writer.write(np.zeros((10, 12), np.uint8))
    with pytest.raises(OutputError):
        writer.close()
    writer.abort()
    # an error in the last frames is raised by close
    writer = PngAviWriter(path, 25.0, (12, 10), workers=2)
    writer.write(np.full((10, 12), 3, np.uint8))
    with pytest.raises(RuntimeError, match="frame 3"):
        writer.close()
    assert not path.exists()


def test_bilevel_frames_must_be_grey_and_zero_or_255(tmp_path):
    writer = PngAviWriter(tmp_path / "v.avi", 25.0, (8, 6), bilevel=True)
    with pytest.raises(ValueError, match="grey"):
        writer.write(np.zeros((6, 8, 3), np.uint8))
    with pytest.raises(ValueError, match="8x6"):
        writer.write(np.zeros((8, 6), np.uint8))
    frame = np.zeros((6, 8), np.uint8)
    frame[2, 3] = 128
    with pytest.raises(ValueError, match="0 and 255"):  # by this write (encoded already) or by close
        writer.write(frame)
        writer.close()
    assert not (tmp_path / "v.avi").exists()


def test_bad_arguments(tmp_path):
    for kw in ({"fps": 0.0}, {"fps": float("nan")}, {"size": (0, 5)}, {"segment_bytes": 0}, {"compression": 10}):
        args = {"fps": 25.0, "size": (4, 4), **kw}
        with pytest.raises(ConfigError):
            PngAviWriter(tmp_path / "v.avi", args.pop("fps"), args.pop("size"), **args)
    with pytest.raises(OutputError):
        PngAviWriter(tmp_path / "missing" / "v.avi", 25.0, (4, 4))


# ------------------------------------------------------------------------------------------------ VideoWriter


def test_video_writer_png_is_atomic(tmp_path, rng):
    frames = _frames(rng, "bilevel", (20, 14), 5)
    path = tmp_path / "m.avi"
    writer = VideoWriter(path, fps=10, grey=True, codec="PNG", bilevel=True)
    for f in frames[:4]:
        writer.write(f)
    writer.write(cv2.merge([frames[4]] * 3))  # a BGR frame is made grey
    assert writer.codec == "MPNG" and writer.frames_written == 5
    assert not path.exists() and len(list(tmp_path.iterdir())) == 1  # only the hidden temporary file
    assert writer.close() == path
    assert [p.name for p in tmp_path.iterdir()] == ["m.avi"]
    back = _read(path)
    assert len(back) == 5 and all(_same(b, f) for b, f in zip(back, frames, strict=True))
    # abort and an exception in the with block leave nothing
    other = tmp_path / "o.avi"
    with pytest.raises(KeyError), VideoWriter(other, fps=10, grey=True, codec="png") as w:
        w.write(frames[0])
        raise KeyError("stop")
    w = VideoWriter(other, fps=10, size=(20, 14), codec="PNG")
    w.write(frames[0])
    w.abort()
    assert [p.name for p in tmp_path.iterdir()] == ["m.avi"]


def test_video_writer_png_options_are_checked(tmp_path):
    with pytest.raises(ConfigError, match=r"\.avi"):
        VideoWriter(tmp_path / "m.mkv", codec="PNG")
    with pytest.raises(ConfigError, match="codec"):
        VideoWriter(tmp_path / "m.avi", codec="H264")
    with pytest.raises(ConfigError, match="bilevel"):
        VideoWriter(tmp_path / "m.avi", codec="PNG", bilevel=True)  # not grey
    with pytest.raises(ConfigError, match="bilevel"):
        VideoWriter(tmp_path / "m.avi", grey=True, bilevel=True)  # not PNG
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("end", ["close", "flush"])
def test_video_writer_png_encoding_error_leaves_no_file(tmp_path, end):
    """A frame breaking the bilevel contract fails the background writer (raised by its flush or close); nothing is
    left behind."""
    bad = np.full((6, 8), 7, np.uint8)
    bw = BackgroundWriter(VideoWriter(tmp_path / "m.avi", fps=10, grey=True, codec="PNG", bilevel=True), depth=2)
    bw.write(bad)
    with pytest.raises(ValueError, match="0 and 255"):
        getattr(bw, end)()
    if end == "flush":
        assert bw.close() is None
    assert list(tmp_path.iterdir()) == []


def test_continue_video_keeps_the_first_frames_of_a_png_masks_video(tmp_path, rng):
    masks = _frames(rng, "bilevel", (31, 17), 7)
    path = tmp_path / "masks.avi"
    with VideoWriter(path, fps=10, grey=True, codec="PNG", bilevel=True) as w:
        for m in masks[:5]:
            w.write(m)
    w = continue_video(path, 3, fps=10, grey=True, codec="PNG", bilevel=True)
    assert w.frames_written == 3 and w.codec == "MPNG"
    for m in masks[5:]:
        w.write(m)
    w.close()
    back = _read(path)
    expected = masks[:3] + masks[5:]
    assert len(back) == 5 and all(_same(b, m) for b, m in zip(back, expected, strict=True))
    cap = cv2.VideoCapture(str(path))
    assert int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little") == b"MPNG"
    cap.release()
    # fewer frames than the resume point: the gap is black, frame i stays frame i
    w = continue_video(path, 7, fps=10, grey=True, codec="PNG", bilevel=True)
    w.write(masks[0])
    w.close()
    back = _read(path)
    assert len(back) == 8 and all(_same(b, m) for b, m in zip(back[:5], expected, strict=True))
    assert not back[5].any() and not back[6].any() and _same(back[7], masks[0])


# ------------------------------------------------------------------------------------------------ wptrack masks


def test_write_masks_writes_an_mpng_masks_video_read_back_exactly(tmp_path, rng):
    h, w, frames = 48, 64, 30
    base = cv2.resize(rng.uniform(60, 200, (h // 8, w // 8, 3)).astype(np.float32), (w, h))
    video = np.clip(base + rng.normal(0, 3, (frames, h, w, 3)), 0, 255).astype(np.uint8)
    for t in range(frames):
        x = 4 + 2 * t
        video[t, 16:34, x : x + 10] = (40, 200, 40)
    config = MaskConfig(window=frames, device="cpu")
    summary = write_masks(video, tmp_path / "out", config=config, probability=True)
    assert summary["codec"] == "MPNG" and summary["frames"] == frames
    expected = np.stack(list(open_masks(video=video, config=config)))
    assert expected.any() and not expected.all()
    path = tmp_path / "out" / "masks.avi"
    cap = cv2.VideoCapture(str(path))
    assert int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little") == b"MPNG"
    cap.release()
    info = _parse(path)
    assert {p[24] for s in info["segments"] for p in s["png"]} == {1}  # 1-bit images
    given = np.stack(list(open_masks(masks=path)))  # the given-masks path of `wptrack track --masks`
    np.testing.assert_array_equal(given, expected)
    raw = np.stack(list(open_source(path)))  # wptrack.io.frames
    np.testing.assert_array_equal(raw, np.repeat(expected[..., None] * np.uint8(255), 3, axis=3))
    prob = list(open_source(tmp_path / "out" / "probability.avi"))
    assert len(prob) == frames and len({int(v) for v in np.unique(np.stack(prob))}) > 2  # 8-bit grey, not 1-bit
    assert sorted(p.name for p in (tmp_path / "out").iterdir() if p.name.startswith(".")) == []


def test_background_writer_feeds_png_writer_from_another_thread(tmp_path, rng, monkeypatch):
    """BackgroundWriter's thread writes, the pool encodes: frames in order; flush waits for the pool's frames too
    (a checkpoint describes them as written); the file is renamed into place at close."""
    monkeypatch.setattr(avi, "encode_png", _slow_encoder(dict.fromkeys(range(256), 0.01)))
    masks = _frames(rng, "bilevel", (40, 24), 25)
    bw = BackgroundWriter(VideoWriter(tmp_path / "m.avi", fps=25, grey=True, codec="PNG", bilevel=True), depth=3)
    for m in masks:
        bw.write(m)
    bw.flush()
    png = bw.writer._writer
    assert png.pending == 0 and png.frames == 25
    assert bw.close() == tmp_path / "m.avi"
    back = _read(tmp_path / "m.avi")
    assert len(back) == 25 and all(_same(b, m) for b, m in zip(back, masks, strict=True))
