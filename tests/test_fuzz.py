"""Fuzzing (hypothesis) of the rig parser and the frame-source layer: whatever the input, the only exception is
the documented one (:class:`wptrack.core.errors.WptrackError`: RigError / FrameError / ConfigError).

Case counts (derandomized, so CI runs the same cases every time) with ``WPTRACK_FUZZ_FULL=1``: rig dicts 4000 +
mutated camera entries 4000 + rig file texts 2000 = 10^4 rig cases, opencv files 300, frame sources 300 generated
files/folders + 300 arrays (about 1 CPU minute). By default (CI) a quarter of each (about 15 CPU seconds).
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.test_rig import _cam_entry
from wptrack.cameras.rig import Rig
from wptrack.core.errors import WptrackError
from wptrack.io.frames import open_frames, open_source

FULL = os.environ.get("WPTRACK_FUZZ_FULL", "") not in ("", "0")


def fuzz(n: int) -> settings:
    """Settings for ``n`` cases in a full run (``WPTRACK_FUZZ_FULL=1``), n/4 by default."""
    return settings(
        max_examples=n if FULL else max(25, n // 4),
        deadline=None,
        derandomize=True,
        suppress_health_check=list(HealthCheck),
        database=None,
    )


logging.getLogger("wptrack.cameras.rig").setLevel(logging.ERROR)  # blind-camera warnings are expected here

floats = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1e3, 1e3),
    st.sampled_from([0.0, -0.0, 1.0, -1.0, 1e308, -1e308, 5e-324]),
)
scalars = st.one_of(st.none(), st.booleans(), st.integers(-(2**70), 2**70), floats, st.text(max_size=8))
vectors = st.lists(floats, min_size=0, max_size=6)
matrices = st.lists(st.lists(floats, min_size=0, max_size=4), min_size=0, max_size=4)
values = st.one_of(scalars, vectors, matrices, st.dictionaries(st.text(max_size=4), scalars, max_size=3))
KEYS = ["name", "width", "height", "K", "dist", "R", "rvec", "t", "opencv", "bogus"]


def _ok_or_documented(fn, *args, **kwargs) -> None:
    try:
        fn(*args, **kwargs)
    except WptrackError as e:
        assert str(e) and "\n" not in str(e)


@fuzz(4000)
@given(
    st.one_of(
        values,
        st.fixed_dictionaries(
            {"cameras": st.one_of(values, st.lists(st.dictionaries(st.sampled_from(KEYS), values), max_size=3))},
            optional={
                "volume": st.one_of(values, st.fixed_dictionaries({"min": vectors, "max": vectors})),
                "x": values,
            },
        ),
    )
)
def test_fuzz_rig_dict(d: Any) -> None:
    _ok_or_documented(Rig.from_dict, d, source="fuzz.yaml")


@fuzz(4000)
@given(st.dictionaries(st.sampled_from(KEYS), values, max_size=4), st.sets(st.sampled_from(KEYS), max_size=3))
def test_fuzz_mutated_camera_entry(changes: dict[str, Any], removed: set[str]) -> None:
    """A valid entry with fields replaced by arbitrary values or removed (the near-miss inputs users write)."""
    entry = _cam_entry("cam1")
    entry.update(changes)
    for k in removed:
        entry.pop(k, None)
    entry.pop("opencv", None)  # file references are fuzzed through the files below
    vol = {"min": [-1, -1, 0], "max": [1, 1, 2]}
    _ok_or_documented(Rig.from_dict, {"cameras": [_cam_entry("cam0"), entry], "volume": vol}, source="fuzz.yaml")


_TMP = Path(tempfile.mkdtemp(prefix="wptrack-fuzz-"))


@fuzz(2000)
@given(
    st.one_of(
        st.binary(max_size=200),
        st.text(max_size=200).map(str.encode),
        st.builds(lambda d: json.dumps(d, allow_nan=True).encode(), values),
        st.builds(lambda e: json.dumps({"cameras": [e]}).encode(), st.dictionaries(st.sampled_from(KEYS), values)),
    ),
    st.sampled_from([".yaml", ".json"]),
)
def test_fuzz_rig_file(data: bytes, suffix: str) -> None:
    path = _TMP / f"rig{suffix}"
    path.write_bytes(data)
    _ok_or_documented(Rig.load, path)


_CV_KEYS = ["image_width", "image_height", "camera_matrix", "distortion_coefficients", "R", "rvec", "tvec"]


@fuzz(300)
@given(
    st.dictionaries(
        st.sampled_from(_CV_KEYS),
        st.one_of(
            st.integers(-5, 5000),
            st.floats(allow_nan=True),
            st.text(max_size=5),
            st.tuples(st.integers(1, 4), st.integers(1, 4)).map(lambda s: np.full(s, 0.5)),
        ),
    ),
    st.booleans(),
)
def test_fuzz_opencv_file(fields: dict[str, Any], garbage: bool) -> None:
    """``opencv:`` entries naming a FileStorage file with arbitrary keys/values, or a file that is not one."""
    cv = _TMP / "cam.yml"
    if garbage:
        cv.write_bytes(json.dumps(fields, default=str).encode()[:50])
    else:
        fs = cv2.FileStorage(str(cv), cv2.FILE_STORAGE_WRITE)
        for k, v in fields.items():
            fs.write(k, v)
        fs.release()
    rig = _TMP / "rig_cv.yaml"
    rig.write_text("cameras:\n  - {opencv: cam.yml}\n")
    _ok_or_documented(Rig.load, rig)


# ------------------------------------------------------------------------------------------------ frame sources


def _video(path: Path, frames: list[np.ndarray], codec: str) -> None:
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), 10, (w, h))
    for f in frames:
        writer.write(f)
    writer.release()


@st.composite
def frame_inputs(draw) -> tuple[str, Any]:
    kind = draw(st.sampled_from(["bytes", "cut video", "folder", "glob"]))
    sub = Path(tempfile.mkdtemp(dir=_TMP))
    if kind == "bytes":
        path = sub / f"v{draw(st.sampled_from(['.avi', '.mp4', '.png', '']))}"
        path.write_bytes(draw(st.binary(max_size=300)))
        return kind, path
    if kind == "cut video":
        n = draw(st.integers(1, 4))
        frames = [np.full((16, 24, 3), 40 * i, np.uint8) for i in range(n)]
        path = sub / "v.avi"
        _video(path, frames, draw(st.sampled_from(["FFV1", "MJPG"])))
        data = path.read_bytes()
        path.write_bytes(data[: draw(st.integers(0, len(data)))])
        return kind, path
    count = draw(st.integers(0, 4))
    for i in range(count):
        h, w = draw(st.sampled_from([(8, 8), (8, 12), (12, 8)]))
        shape = draw(st.sampled_from([(h, w), (h, w, 1), (h, w, 3), (h, w, 4)]))
        dtype = draw(st.sampled_from([np.uint8, np.uint16]))
        img = np.full(shape, 7, dtype)
        name = sub / f"img{i}{draw(st.sampled_from(['.png', '.tif', '.jpg']))}"
        if dtype == np.uint16 and name.suffix == ".jpg":
            img = img.astype(np.uint8)
        if draw(st.booleans()):
            cv2.imwrite(str(name), img)
        else:
            name.write_bytes(draw(st.binary(max_size=40)))
    return kind, (sub if kind == "folder" else sub / "img*")


@fuzz(300)
@given(frame_inputs(), st.booleans())
def test_fuzz_frame_sources(item: tuple[str, Any], stop: bool) -> None:
    _kind, spec = item

    def read() -> None:
        frames = open_frames([spec, spec], stop_at_shortest=stop)
        for step in frames:
            for f in step:
                assert f.dtype == np.uint8 and f.ndim == 3 and f.shape[2] == 3

    _ok_or_documented(read)


@fuzz(300)
@given(
    st.sampled_from([np.uint8, np.uint16, np.float32, np.int64, bool]),
    st.lists(st.integers(0, 5), min_size=0, max_size=5),
)
def test_fuzz_array_sources(dtype, shape: list[int]) -> None:
    _ok_or_documented(lambda: list(open_source(np.zeros(shape, dtype))))
