"""Tests for the camera rig model (wptrack.cameras.rig)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml

from wptrack.cameras.rig import Camera, Rig, camera_from_dict, save_opencv
from wptrack.core.errors import OutputError, RigError


def _cam_entry(name: str = "cam0", **overrides: Any) -> dict[str, Any]:
    """A valid rig-file camera entry (camera 3 m back along -y, looking along +y, z up)."""
    entry: dict[str, Any] = {
        "name": name,
        "width": 320,
        "height": 240,
        "K": [[300.0, 0.0, 159.5], [0.0, 310.0, 119.5], [0.0, 0.0, 1.0]],
        "dist": [0.01, -0.002, 0.0005, -0.0003, 0.0001],
        "R": [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
        "t": [0.1, 0.2, 3.0],
    }
    entry.update(overrides)
    return entry


def _random_camera(rng: np.random.Generator, name: str) -> Camera:
    position = rng.uniform(-4, 4, size=3) + np.array([0.0, 0.0, 2.0])
    target = rng.uniform(-0.5, 0.5, size=3)
    cam = Camera.look_at(name, 640, 480, position, target, fx=rng.uniform(400, 600), roll_deg=rng.uniform(-20, 20))
    return Camera(cam.name, cam.width, cam.height, cam.K, rng.normal(0, 0.01, size=5), cam.R, cam.t)


def _random_rig(rng: np.random.Generator, volume: bool = True) -> Rig:
    cams = tuple(_random_camera(rng, f"cam{i}") for i in range(3))
    vol = (np.array([-1.0, -2.0, 0.0]), np.array([1.0, 2.0, 2.5])) if volume else None
    return Rig(cams, volume=vol)


def _assert_cameras_equal(a: Camera, b: Camera) -> None:
    assert (a.name, a.width, a.height) == (b.name, b.width, b.height)
    for field in ("K", "dist", "R", "t"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)


def _write_yaml(path: Path, data: Any) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


# --------------------------------------------------------------------------------------------- files & round trips


@pytest.mark.parametrize("suffix", [".yaml", ".yml", ".json"])
def test_save_load_round_trip(tmp_path: Path, rng: np.random.Generator, suffix: str) -> None:
    rig = _random_rig(rng)
    path = tmp_path / f"rig{suffix}"
    rig.save(path)
    loaded = Rig.load(path)
    assert loaded.source == str(path)
    assert loaded.names == rig.names == ["cam0", "cam1", "cam2"]
    for a, b in zip(rig, loaded, strict=True):
        _assert_cameras_equal(a, b)
    np.testing.assert_array_equal(loaded.volume[0], rig.volume[0])
    np.testing.assert_array_equal(loaded.volume[1], rig.volume[1])
    # no temp files left behind by the atomic write
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
    if suffix == ".json":
        assert json.loads(path.read_text())["cameras"][1]["name"] == "cam1"


def test_save_without_volume_and_overwrite(tmp_path: Path, rng: np.random.Generator) -> None:
    path = tmp_path / "rig.yaml"
    _random_rig(rng, volume=True).save(path)
    rig = _random_rig(rng, volume=False)
    rig.save(path)  # replaces the existing file
    loaded = Rig.load(path)
    assert loaded.volume is None
    _assert_cameras_equal(loaded[2], rig[2])


def test_save_errors(tmp_path: Path, rng: np.random.Generator) -> None:
    rig = _random_rig(rng)
    with pytest.raises(RigError, match="extension"):
        rig.save(tmp_path / "rig.txt")
    with pytest.raises(OutputError, match="cannot write"):
        rig.save(tmp_path / "missing_dir" / "rig.yaml")


def test_rvec_form_equals_r_form(tmp_path: Path) -> None:
    rvec = [0.3, -1.2, 0.4]
    R = cv2.Rodrigues(np.array(rvec))[0]
    entry_r = _cam_entry(R=R.tolist())
    entry_rvec = _cam_entry()
    del entry_rvec["R"]
    entry_rvec["rvec"] = rvec
    both = _cam_entry(R=R.tolist(), rvec=rvec)
    a = camera_from_dict(entry_r)
    b = camera_from_dict(entry_rvec)
    c = camera_from_dict(both)
    np.testing.assert_allclose(b.R, a.R, atol=1e-15)
    np.testing.assert_allclose(c.R, a.R, atol=1e-15)
    np.testing.assert_allclose(a.rvec, rvec, atol=1e-12)
    pts = np.array([[0.1, 0.2, 0.3], [-0.5, 1.0, 0.2]])
    np.testing.assert_allclose(a.project(pts)[0], b.project(pts)[0], atol=1e-9)


def test_opencv_entry(tmp_path: Path, rng: np.random.Generator) -> None:
    cam = _random_camera(rng, "side")
    (tmp_path / "calib").mkdir()
    save_opencv(cam, tmp_path / "calib" / "side.yml")
    assert "camera_matrix" in (tmp_path / "calib" / "side.yml").read_text()
    rig_path = _write_yaml(
        tmp_path / "rig.yaml",
        {
            "cameras": [
                _cam_entry("front"),
                {"opencv": "calib/side.yml"},
                {"name": "small", "opencv": "calib/side.yml", "width": 320, "height": 240},
            ]
        },
    )
    rig = Rig.load(rig_path)
    assert rig.names == ["front", "side", "small"]  # default name: the file stem
    _assert_cameras_equal(rig["side"], cam)
    assert (rig["small"].width, rig["small"].height) == (320, 240)  # overrides beside opencv:
    np.testing.assert_array_equal(rig["small"].K, cam.K)


def test_opencv_entry_written_by_cv2_with_tvec_only(tmp_path: Path) -> None:
    """A file as cv2 calibration tools write it: rvec/tvec column vectors, no R."""
    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    fs = cv2.FileStorage(str(tmp_path / "c.yml"), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", np.array([[0.1], [-0.05], [0.0], [0.0]]))  # 4 coefficients, column
    fs.write("rvec", np.array([[0.1], [0.2], [0.3]]))
    fs.write("T", np.array([[1.0], [2.0], [3.0]]))
    fs.release()
    cam = Rig.load(_write_yaml(tmp_path / "rig.yaml", {"cameras": [{"opencv": "c.yml"}]}))["c"]
    np.testing.assert_array_equal(cam.dist, [0.1, -0.05, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(cam.t, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(cam.rvec, [0.1, 0.2, 0.3], atol=1e-12)
    np.testing.assert_array_equal(cam.K, K)


# --------------------------------------------------------------------------------------------- geometry


def test_look_at_centres_target_and_keeps_up() -> None:
    position, target = np.array([4.0, -3.0, 2.5]), np.array([0.5, 0.2, 0.8])
    cam = Camera.look_at("c", 640, 480, position, target, fx=500.0)
    assert (cam.cx, cam.cy, cam.fy) == (319.5, 239.5, 500.0)
    np.testing.assert_allclose(cam.center, position, atol=1e-12)
    uv, depth = cam.project(np.stack([target, target + [0, 0, 0.3], target + [0, 0, -0.3]]))
    np.testing.assert_allclose(uv[0], [cam.cx, cam.cy], atol=1e-9)
    np.testing.assert_allclose(depth[0], np.linalg.norm(target - position), rtol=1e-12)
    assert uv[1, 1] < uv[0, 1] - 10 < uv[2, 1] - 20  # above -> smaller v, below -> larger v
    assert abs(uv[1, 0] - uv[0, 0]) < 1e-6  # a vertical world line stays vertical through the image centre
    # camera x (image right) is horizontal, and the camera is right-handed
    assert abs(cam.R[0] @ [0, 0, 1]) < 1e-12
    assert np.linalg.det(cam.R) == pytest.approx(1.0)


def test_look_at_right_is_world_right() -> None:
    """Looking north (+y) with z up, east (+x) must appear on the image right."""
    cam = Camera.look_at("c", 100, 100, [0, -5, 0], [0, 0, 0], fx=100.0)
    uv, depth = cam.project(np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]))
    assert uv[0, 0] > cam.cx > uv[1, 0]
    assert np.all(depth > 0)
    uv_behind, depth_behind = cam.project(np.array([[0.0, -10.0, 0.0]]))
    assert depth_behind[0] < 0


def test_look_at_roll() -> None:
    position, target = [0.0, -5.0, 1.0], [0.0, 0.0, 1.0]
    base = Camera.look_at("c", 480, 640, position, target, fx=400.0)
    rolled = Camera.look_at("c", 480, 640, position, target, fx=400.0, roll_deg=90.0)
    above = np.array([target, [0.0, 0.0, 1.5]])
    uv, _ = rolled.project(above)
    np.testing.assert_allclose(uv[0], [rolled.cx, rolled.cy], atol=1e-9)
    assert uv[1, 0] < uv[0, 0] - 10  # world up -> image left (-u)
    assert abs(uv[1, 1] - uv[0, 1]) < 1e-6
    uv_m, _ = Camera.look_at("c", 480, 640, position, target, fx=400.0, roll_deg=-90.0).project(above)
    assert uv_m[1, 0] > uv_m[0, 0] + 10  # -90: world up -> image right (+u)
    # same optical axis and centre, rotated image axes
    np.testing.assert_allclose(rolled.R[2], base.R[2], atol=1e-12)
    np.testing.assert_allclose(rolled.R[0], base.R[1], atol=1e-12)
    np.testing.assert_allclose(rolled.center, base.center, atol=1e-12)


def test_look_at_degenerate() -> None:
    with pytest.raises(RigError, match="target"):
        Camera.look_at("c", 10, 10, [1, 2, 3], [1, 2, 3], fx=10.0)
    with pytest.raises(RigError, match="parallel to up"):
        Camera.look_at("c", 10, 10, [0, 0, 5], [0, 0, 0], fx=10.0)
    cam = Camera.look_at("c", 10, 10, [0, 0, 5], [0, 0, 0], fx=10.0, up=(0, 1, 0))  # top-down camera
    assert cam.project(np.array([[0.0, 1.0, 0.0]]))[0][0, 1] < cam.cy


def test_project_matches_manual_pinhole(rng: np.random.Generator) -> None:
    cam = camera_from_dict(_cam_entry(dist=None))
    pts = rng.uniform(-0.5, 0.5, size=(20, 3))
    uv, depth = cam.project(pts)
    xc = pts @ cam.R.T + cam.t
    np.testing.assert_allclose(depth, xc[:, 2])
    np.testing.assert_allclose(uv[:, 0], cam.fx * xc[:, 0] / xc[:, 2] + cam.cx, rtol=1e-12)
    np.testing.assert_allclose(uv[:, 1], cam.fy * xc[:, 1] / xc[:, 2] + cam.cy, rtol=1e-12)
    # distortion is applied: same camera with k1 != 0 moves off-centre points
    distorted = camera_from_dict(_cam_entry(dist=[0.2, 0, 0, 0]))
    assert np.max(np.abs(distorted.project(pts)[0] - uv)) > 0.1
    empty_uv, empty_depth = cam.project(np.zeros((0, 3)))
    assert empty_uv.shape == (0, 2) and empty_depth.shape == (0,)
    with pytest.raises(ValueError, match="shape"):
        cam.project(np.zeros((4, 2)))


def test_scaled(rng: np.random.Generator) -> None:
    cam = _random_camera(rng, "c")
    small = cam.scaled(320, 120)
    assert (small.width, small.height, small.name) == (320, 120, "c")
    np.testing.assert_allclose([small.fx, small.cx], [cam.fx / 2, cam.cx / 2])
    np.testing.assert_allclose([small.fy, small.cy], [cam.fy / 4, cam.cy / 4])
    pts = rng.uniform(-0.5, 0.5, size=(10, 3))
    uv, depth = cam.project(pts)
    uv_s, depth_s = small.project(pts)
    np.testing.assert_allclose(uv_s, uv * [0.5, 0.25], rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(depth_s, depth)
    np.testing.assert_array_equal(small.dist, cam.dist)
    with pytest.raises(RigError, match="width"):
        cam.scaled(0, 10)


def test_camera_arrays_are_readonly_float64() -> None:
    K = np.array([[100, 0, 50], [0, 100, 40], [0, 0, 1]], dtype=np.int32)
    R = np.eye(3, dtype=np.float32)
    cam = Camera("c", 100, 80, K, None, R, [0, 0, 1])
    for field in ("K", "dist", "R", "t"):
        arr = getattr(cam, field)
        assert arr.dtype == np.float64 and arr.flags.c_contiguous and not arr.flags.writeable
    np.testing.assert_array_equal(cam.dist, np.zeros(5))
    K[0, 0] = 7  # the camera holds a copy
    assert cam.fx == 100.0
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0
    assert isinstance(cam.fx, float) and cam.to_dict()["K"][0][0] == 100.0


# --------------------------------------------------------------------------------------------- rig queries


def test_rig_indexing_and_bounds() -> None:
    a = Camera.look_at("a", 64, 48, [0, -3, 1], [0, 0, 1], fx=50.0)
    b = Camera.look_at("b", 64, 48, [2, 1, 2], [0, 0, 1], fx=50.0)
    rig = Rig((a, b))
    assert len(rig) == 2 and list(rig) == [a, b] and rig.names == ["a", "b"]
    assert rig[1] is b and rig["a"] is a and rig[-1] is b
    with pytest.raises(RigError, match="no camera named 'z'"):
        rig["z"]
    with pytest.raises(RigError, match="out of range"):
        rig[2]
    lo, hi = rig.bounds()
    np.testing.assert_allclose(lo, [-0.25, -3.25, 0.75])
    np.testing.assert_allclose(hi, [2.25, 1.25, 2.25])
    vol = Rig((a, b), volume=([-1, -1, 0], [1, 1, 2]))
    lo, hi = vol.bounds()
    np.testing.assert_array_equal(lo, [-1, -1, 0])
    np.testing.assert_array_equal(hi, [1, 1, 2])
    assert vol.volume[0].dtype == np.float64


def test_frame_sizes_check_and_scale(tmp_path: Path) -> None:
    """Frames of the calibrated size use the rig as it is; a resized copy (same aspect ratio) scales K; another
    aspect ratio is an error naming the source, the camera and both sizes."""
    path = _write_yaml(tmp_path / "rig.yaml", {"cameras": [_cam_entry("cam0"), _cam_entry("cam1", width=640)]})
    rig = Rig.load(path)
    assert rig.at_sizes([(320, 240), (640, 240)], ["a.mp4", "b.mp4"]) is rig
    with pytest.raises(RigError) as info:
        rig.at_sizes([(320, 240), (320, 240)], ["a.mp4", "b.mp4"])
    assert str(info.value).startswith(
        f"b.mp4: frame size 320x240 differs from camera 'cam1' calibration 640x240 in {path}"
    )
    half = rig.at_sizes([(160, 120), (640, 240)], ["a.mp4", "b.mp4"])
    assert (half[0].width, half[0].height) == (160, 120) and half[1] is rig[1]
    np.testing.assert_allclose(half[0].K[:2], rig[0].K[:2] / 2)


# --------------------------------------------------------------------------------------------- validation

_NOT_ROTATION = [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
_REFLECTION = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]


def _without(key: str) -> dict[str, Any]:
    entry = _cam_entry("cam1")
    del entry[key]
    return entry


# (camera entry for cameras[1], substrings the message must contain)
CAMERA_CASES: list[tuple[str, dict[str, Any], list[str]]] = [
    ("missing width", _without("width"), ["missing field 'width'", "pixels"]),
    ("missing height", _without("height"), ["missing field 'height'"]),
    ("missing K", _without("K"), ["missing field 'K'"]),
    ("missing t", _without("t"), ["missing field 't'"]),
    ("missing R", _without("R"), ["missing field 'R' or 'rvec'"]),
    ("width zero", _cam_entry("cam1", width=0), ["width:", "positive integer", "got 0"]),
    ("width float", _cam_entry("cam1", width=320.5), ["width:", "positive integer"]),
    ("width text", _cam_entry("cam1", width="320"), ["width:", "positive integer"]),
    ("height negative", _cam_entry("cam1", height=-240), ["height:", "positive integer"]),
    ("height bool", _cam_entry("cam1", height=True), ["height:", "positive integer"]),
    ("K shape", _cam_entry("cam1", K=[[300.0, 0.0, 160.0], [0.0, 300.0, 120.0]]), ["K:", "3x3", "(2, 3)"]),
    ("K ragged", _cam_entry("cam1", K=[[300.0, 0.0], [0.0, 300.0, 120.0], [0, 0, 1]]), ["K:", "3x3"]),
    ("K text", _cam_entry("cam1", K="eye"), ["K:", "3x3"]),
    ("K nan", _cam_entry("cam1", K=[[float("nan"), 0, 160], [0, 300, 120], [0, 0, 1]]), ["K:", "finite"]),
    (
        "fx negative",
        _cam_entry("cam1", K=[[-3.0, 0, 160], [0, 300, 120], [0, 0, 1]]),
        ["K: focal length fx must be > 0, got -3.0"],
    ),
    (
        "fy zero",
        _cam_entry("cam1", K=[[300.0, 0, 160], [0, 0.0, 120], [0, 0, 1]]),
        ["K: focal length fy must be > 0, got 0.0"],
    ),
    ("K skew", _cam_entry("cam1", K=[[300.0, 2.0, 160], [0, 300, 120], [0, 0, 1]]), ["K:", "skew"]),
    ("K last row", _cam_entry("cam1", K=[[300.0, 0, 160], [0, 300, 120], [0, 0, 2]]), ["K:", "[0, 0, 1]"]),
    ("dist length", _cam_entry("cam1", dist=[0.1, 0.2, 0.3]), ["dist:", "4 or 5", "got 3"]),
    ("dist inf", _cam_entry("cam1", dist=[0.1, float("inf"), 0, 0, 0]), ["dist:", "finite"]),
    ("R shape", _cam_entry("cam1", R=[[1.0, 0.0], [0.0, 1.0]]), ["R:", "3x3"]),
    ("R nan", _cam_entry("cam1", R=[[float("nan"), 0, 0], [0, 1, 0], [0, 0, 1]]), ["R:", "finite"]),
    ("R not orthonormal", _cam_entry("cam1", R=_NOT_ROTATION), ["R:", "not a rotation"]),
    ("R reflection", _cam_entry("cam1", R=_REFLECTION), ["R:", "determinant", "+1"]),
    ("rvec shape", {**_without("R"), "rvec": [0.1, 0.2]}, ["rvec:", "(2,)"]),
    ("rvec nan", {**_without("R"), "rvec": [0.1, float("nan"), 0.0]}, ["rvec:", "finite"]),
    ("R and rvec disagree", _cam_entry("cam1", rvec=[0.0, 0.0, 0.1]), ["rvec:", "disagrees with R"]),
    ("t shape", _cam_entry("cam1", t=[0.0, 1.0]), ["t:", "(2,)"]),
    ("t inf", _cam_entry("cam1", t=[0.0, float("-inf"), 1.0]), ["t:", "finite"]),
    ("t missing value", _cam_entry("cam1", t=None), ["t:", "3 values"]),
    ("unknown field", _cam_entry("cam1", distortion=[0, 0, 0, 0, 0]), ["unknown field 'distortion'"]),
    ("name empty", _cam_entry(""), ["name:", "non-empty"]),
    ("entry not mapping", [1, 2, 3], ["cameras[1]", "mapping"]),  # type: ignore[list-item]
    ("opencv missing file", {"name": "cam1", "opencv": "nope.yml"}, ["opencv:", "not found", "nope.yml"]),
]


@pytest.mark.parametrize("fmt", ["yaml", "json"])
@pytest.mark.parametrize(("case", "entry", "needles"), CAMERA_CASES, ids=[c[0] for c in CAMERA_CASES])
def test_camera_validation_errors(
    tmp_path: Path, fmt: str, case: str, entry: dict[str, Any], needles: list[str]
) -> None:
    data = {"cameras": [_cam_entry("cam0"), copy.deepcopy(entry)]}
    path = tmp_path / f"rig.{fmt}"
    if fmt == "json":
        path.write_text(json.dumps(data))  # json writes NaN/Infinity, which json.loads reads back
    else:
        _write_yaml(path, data)
    with pytest.raises(RigError) as info:
        Rig.load(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}: cameras[1]"), msg
    if case not in ("entry not mapping", "name empty"):
        assert "cameras[1] 'cam1':" in msg, msg
    for needle in needles:
        assert needle in msg, (needle, msg)
    # the same entry is fine when the bad field is fixed: the valid entry loads
    Rig.from_dict({"cameras": [_cam_entry("cam0")]})


def test_fixture_entry_is_valid() -> None:
    """Guard: the base entry used by the validation cases loads, so each case fails for its own reason."""
    rig = Rig.from_dict({"cameras": [_cam_entry("cam0"), _cam_entry("cam1")]}, source="x.yaml")
    assert rig.names == ["cam0", "cam1"]
    both = _cam_entry("cam1", rvec=cv2.Rodrigues(np.array(_cam_entry()["R"]))[0].ravel().tolist())
    assert Rig.from_dict({"cameras": [both]})[0].name == "cam1"


def test_opencv_file_missing_keys(tmp_path: Path) -> None:
    fs = cv2.FileStorage(str(tmp_path / "partial.yml"), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("tvec", np.zeros((3, 1)))
    fs.write("rvec", np.zeros((3, 1)))
    fs.release()
    path = _write_yaml(tmp_path / "rig.yaml", {"cameras": [{"opencv": "partial.yml"}]})
    with pytest.raises(RigError, match=r"cameras\[0\] 'partial': opencv: .*missing key 'camera_matrix'"):
        Rig.load(path)
    # the missing key can be supplied beside opencv:
    path = _write_yaml(
        tmp_path / "rig.yaml", {"cameras": [{"opencv": "partial.yml", "K": [[500, 0, 320], [0, 500, 240], [0, 0, 1]]}]}
    )
    assert Rig.load(path)[0].fx == 500.0

    fs = cv2.FileStorage(str(tmp_path / "norot.yml"), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", np.eye(3))
    fs.write("T", np.zeros((3, 1)))
    fs.release()
    path = _write_yaml(tmp_path / "rig.yaml", {"cameras": [{"opencv": "norot.yml"}]})
    with pytest.raises(RigError, match="missing key 'rvec' or 'R'"):
        Rig.load(path)
    (tmp_path / "garbage.yml").write_text("")
    path = _write_yaml(tmp_path / "rig.yaml", {"cameras": [{"opencv": "garbage.yml"}]})
    with pytest.raises(RigError, match="opencv: cannot"):
        Rig.load(path)


RIG_CASES: list[tuple[str, str, list[str]]] = [
    ("not yaml", "cameras: [\n  - {name: a\n", ["not valid YAML"]),
    ("not mapping", "- 1\n- 2\n", ["expected a mapping"]),
    ("empty file", "", ["expected a mapping"]),
    ("no cameras key", "volume: {min: [0, 0, 0], max: [1, 1, 1]}\n", ["missing field 'cameras'"]),
    ("empty cameras", "cameras: []\n", ["cameras:", "non-empty list"]),
    ("cameras not list", "cameras: {a: 1}\n", ["cameras:", "non-empty list"]),
    ("unknown top level", "camera: []\n", ["unknown top-level field 'camera'"]),
]


@pytest.mark.parametrize(("case", "text", "needles"), RIG_CASES, ids=[c[0] for c in RIG_CASES])
def test_rig_file_errors(tmp_path: Path, case: str, text: str, needles: list[str]) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    with pytest.raises(RigError) as info:
        Rig.load(path)
    msg = str(info.value)
    assert msg.startswith(f"{path}: ") and "\n" not in msg, msg
    for needle in needles:
        assert needle in msg, (needle, msg)


def test_rig_file_level_errors(tmp_path: Path) -> None:
    with pytest.raises(RigError, match="rig file not found"):
        Rig.load(tmp_path / "absent.yaml")
    with pytest.raises(RigError, match="extension"):
        Rig.load(tmp_path / "rig.txt")
    (tmp_path / "bad.json").write_text("{cameras: ")
    with pytest.raises(RigError, match="not valid JSON"):
        Rig.load(tmp_path / "bad.json")
    (tmp_path / "dir.yaml").mkdir()
    with pytest.raises(RigError, match="cannot read"):
        Rig.load(tmp_path / "dir.yaml")
    (tmp_path / "bin.yaml").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(RigError, match="bin.yaml"):
        Rig.load(tmp_path / "bin.yaml")


def test_duplicate_names(tmp_path: Path) -> None:
    path = _write_yaml(tmp_path / "rig.yaml", {"cameras": [_cam_entry("a"), _cam_entry("b"), _cam_entry("a")]})
    with pytest.raises(
        RigError, match=r"rig.yaml: cameras\[2\] 'a': name: duplicate camera name \(also cameras\[0\]\)"
    ):
        Rig.load(path)


@pytest.mark.parametrize(
    ("volume", "needle"),
    [
        ({"min": [0, 0, 0], "max": [1, 0, 1]}, "min must be < max"),
        ({"min": [0, 0, 0], "max": [1, 1]}, "volume: max"),
        ({"min": [0, 0, float("nan")], "max": [1, 1, 1]}, "finite"),
        ({"lo": [0, 0, 0], "hi": [1, 1, 1]}, "volume: expected"),
    ],
)
def test_volume_errors(tmp_path: Path, volume: dict[str, Any], needle: str) -> None:
    path = _write_yaml(tmp_path / "rig.yaml", {"volume": volume, "cameras": [_cam_entry()]})
    with pytest.raises(RigError, match="rig.yaml: volume") as info:
        Rig.load(path)
    assert needle in str(info.value)


def test_python_api_validation() -> None:
    good = camera_from_dict(_cam_entry())
    with pytest.raises(RigError, match=r"^<memory>: camera 'x': K: focal length fx must be > 0, got -1.0$"):
        Camera("x", 10, 10, [[-1.0, 0, 5], [0, 1, 5], [0, 0, 1]], None, np.eye(3), [0, 0, 0])
    with pytest.raises(RigError, match="<memory>: camera 'x': R: not a rotation"):
        Camera("x", 10, 10, good.K, None, np.eye(3) * 2, [0, 0, 0])
    with pytest.raises(RigError, match="<memory>: camera 'x': width"):
        Camera("x", 10.5, 10, good.K, None, good.R, good.t)
    with pytest.raises(RigError, match="<memory>: cameras: the rig has no cameras"):
        Rig(())
    with pytest.raises(RigError, match="duplicate"):
        Rig((good, good))
    with pytest.raises(RigError, match="volume: min must be < max"):
        Rig((good,), volume=(np.ones(3), np.zeros(3)))
    assert Camera("x", 320.0, 240, good.K, None, good.R, good.t).width == 320  # integral float accepted


def test_rvec_is_computed_once_and_read_only() -> None:
    """Camera.rvec (what project() passes to OpenCV every call) is R's Rodrigues vector, computed once, read-only."""
    R, _ = cv2.Rodrigues(np.array([0.3, -1.1, 0.4]))
    cam = Camera("c", 64, 48, [[50.0, 0, 32], [0, 50.0, 24], [0, 0, 1]], None, R, [0.1, 0.2, 3.0])
    expected, _ = cv2.Rodrigues(np.array(R))
    np.testing.assert_allclose(cam.rvec, expected.reshape(3), rtol=0, atol=1e-12)
    assert cam.rvec is cam.rvec and not cam.rvec.flags.writeable
    with pytest.raises(ValueError):
        cam.rvec[0] = 1.0
