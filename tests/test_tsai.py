"""Tsai calibrations (wptrack.cameras.tsai), the tsai: rig entry and box ground truth (wptrack.evaluation.groundtruth).

Fixtures: tests/data/pets/ (PETS 2009 View_001 calibration, 5 annotated frames). The real-video test reads
<repo>/../shared/data/pets09-s2l1-view001-dev when present and is skipped otherwise.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import kernel_harness as harness
import numpy as np
import pytest
import warp as wp

from wptrack.cameras.rig import Rig
from wptrack.cameras.structs import DeviceRig
from wptrack.cameras.tsai import _distorted_radius, load_tsai_camera, read_tsai, tsai_fit_residual, tsai_to_camera
from wptrack.core.errors import ConfigError, RigError
from wptrack.evaluation.groundtruth import boxes_to_ground, read_box_groundtruth, read_boxes

DATA = Path(__file__).parent / "data" / "pets"
XML = DATA / "View_001.xml"
BOXES = DATA / "S2L1-frames0-4.xml"
REPO = Path(__file__).resolve().parents[1]
# ../shared/data beside the checkout (or beside a folder of worktrees above it)
SHARED = next(
    (
        p / "shared/data/pets09-s2l1-view001-dev"
        for p in REPO.parents
        if (p / "shared/data/pets09-s2l1-view001-dev").is_dir()
    ),
    REPO.parent / "shared/data/pets09-s2l1-view001-dev",
)


def world_grid(calib):
    """World points (mm) on the ground and at 1 m and 1.8 m, whose Tsai projections fall inside the image."""
    x, y, z = np.meshgrid(np.linspace(-20e3, 30e3, 50), np.linspace(-20e3, 30e3, 50), [0.0, 1000.0, 1800.0])
    pts = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    uv, zc = calib.project(pts)
    inside = (zc > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= calib.width - 1) & (uv[:, 1] >= 0)
    inside &= uv[:, 1] <= calib.height - 1
    return pts[inside], uv[inside]


def test_parse_values():
    c = read_tsai(XML)
    assert (c.width, c.height) == (768, 576)
    assert c.focal == pytest.approx(5.5549183034) and c.kappa1 == pytest.approx(5.1113043639e-3)
    np.testing.assert_allclose(c.T, [828.73214225, -3175.4796051, 35469.298547])
    R = c.R
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_distorted_radius_solves_cubic():
    ru = np.linspace(0.0, 4.0, 101)
    for k in (5e-3, -5e-3, 0.0):
        rd = _distorted_radius(ru, k)
        np.testing.assert_allclose(rd * (1 + k * rd * rd), ru, atol=1e-12)  # (T3)


def test_tsai_reference_round_trip():
    c = read_tsai(XML)
    pts, uv = world_grid(c)
    ground = pts[:, 2] == 0
    back = c.back_project(uv[ground])
    np.testing.assert_allclose(back, pts[ground], atol=1e-6)  # mm


def test_converted_camera_matches_tsai(device):
    c = read_tsai(XML)
    cam = tsai_to_camera(c, "View_001")
    pts, uv = world_grid(c)
    assert len(pts) > 1000
    uv_cv, depth = cam.project(pts / 1000.0)
    assert np.all(depth > 0)
    assert np.abs(uv_cv - uv).max() < 0.001  # measured 2.8e-4 px
    assert tsai_fit_residual(c) < 0.001
    # the Warp kernel path (float32)
    drig = DeviceRig(Rig((cam,)), device)
    out = wp.zeros((1, len(pts)), dtype=wp.vec3, device=device)
    wp.launch(
        harness.project_kernel,
        dim=(1, len(pts)),
        inputs=[drig.cams, wp.array(pts / 1000.0, dtype=wp.vec3, device=device)],
        outputs=[out],
        device=device,
    )
    got = out.numpy()[0]
    assert np.all(got[:, 2] > 0)
    assert np.abs(got[:, :2] - uv).max() < 0.01


def test_converted_camera_back_projection():
    c = read_tsai(XML)
    cam = tsai_to_camera(c, "View_001")
    u, v = np.meshgrid(np.arange(0, 768, 16.0), np.arange(120, 576, 16.0))  # below the horizon
    uv = np.column_stack([u.ravel(), v.ravel()])
    ref = c.back_project(uv) / 1000.0
    boxes = {"frame": np.zeros(len(uv), int), "id": np.arange(len(uv)), "xc": uv[:, 0], "yc": uv[:, 1]}
    boxes["h"] = np.zeros(len(uv))
    got = boxes_to_ground(boxes, cam)
    assert len(got["x"]) == len(uv)
    dist = np.linalg.norm(ref - cam.center, axis=1)
    err = np.hypot(got["x"] - ref[:, 0], got["y"] - ref[:, 1])
    assert dist.max() > 20.0
    assert np.all(err < 1e-4 * dist)  # < 1 mm at 10 m (measured ~1e-6 relative)


def test_scaled_and_units():
    c = read_tsai(XML)
    big = tsai_to_camera(c, "v")
    small = tsai_to_camera(c, "v", width=480, height=360)
    assert (small.width, small.height) == (480, 360)
    pts, _ = world_grid(c)
    uv_big, _ = big.project(pts / 1000.0)
    uv_small, _ = small.project(pts / 1000.0)
    np.testing.assert_allclose(uv_small, uv_big * 0.625, atol=1e-9)
    metres = tsai_to_camera(c.__class__(**{**c.__dict__, "T": c.T / 1000.0}), "v", units="m")
    np.testing.assert_allclose(metres.t, big.t)
    with pytest.raises(RigError, match="units"):
        tsai_to_camera(c, "v", units="cm")


def test_rig_entry(tmp_path):
    (tmp_path / "cal").mkdir()
    (tmp_path / "cal" / "View_001.xml").write_text(XML.read_text())
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text("cameras:\n  - tsai: cal/View_001.xml\n    width: 480\n    height: 360\n")
    rig = Rig.load(rig_file)
    cam = rig[0]
    assert cam.name == "View_001" and (cam.width, cam.height) == (480, 360)
    ref = load_tsai_camera(XML, width=480, height=360)
    np.testing.assert_allclose(cam.K, ref.K)
    np.testing.assert_allclose(cam.t, ref.t)
    assert np.linalg.norm(cam.center - [-28.94, -19.53, 7.07]) < 0.01  # metres, ~7 m above the ground


@pytest.mark.parametrize(
    "text,match",
    [
        (None, "file not found"),
        ("<Camera><Geometry", "cannot read as Tsai"),
        ("<Camera/>", "missing element <Geometry>"),
    ],
)
def test_rig_entry_errors(tmp_path, text, match):
    if text is not None:
        (tmp_path / "c.xml").write_text(text)
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text("cameras:\n  - tsai: c.xml\n")
    with pytest.raises(RigError, match=match) as e:
        Rig.load(rig_file)
    assert "rig.yaml" in str(e.value) and "c.xml" in str(e.value)


def test_missing_and_bad_fields(tmp_path):
    text = XML.read_text()
    bad = tmp_path / "c.xml"
    bad.write_text(text.replace('dpx="5.1273271277e-03" ', ""))
    with pytest.raises(RigError, match=r"<Geometry> is missing attribute 'dpx'"):
        read_tsai(bad)
    bad.write_text(text.replace('kappa1="5.1113043639e-03"', 'kappa1="abc"'))
    with pytest.raises(RigError, match=r"<Intrinsic> kappa1: expected a number"):
        read_tsai(bad)
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text(f"cameras:\n  - tsai: {XML}\n    K: 1\n")
    with pytest.raises(RigError, match="unknown field 'K'"):
        Rig.load(rig_file)


def test_box_groundtruth(tmp_path):
    boxes = read_boxes(BOXES)
    assert set(boxes["frame"].tolist()) == set(range(5))
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text(f"cameras:\n  - tsai: {XML}\n")
    gt = read_box_groundtruth(BOXES, rig_file)
    assert len(gt["x"]) == len(boxes["frame"])
    np.testing.assert_allclose(gt["z"], 0.0, atol=1e-9)
    # feet project back onto the boxes' feet (Tsai reference)
    uv, _ = read_tsai(XML).project(np.column_stack([gt["x"], gt["y"], gt["z"]]) * 1000.0)
    feet = np.column_stack([boxes["xc"], boxes["yc"] + boxes["h"] / 2])
    assert np.abs(uv - feet).max() < 0.01
    # a rig camera built for the video size, boxes in the calibration's size
    rig_file.write_text(f"cameras:\n  - tsai: {XML}\n    width: 480\n    height: 360\n")
    gt_small = read_box_groundtruth(BOXES, rig_file, box_size=(768, 576))
    np.testing.assert_allclose(gt_small["x"], gt["x"], atol=1e-9)
    # ... without the boxes' size they would land on wrong ground points: refused, naming what to give
    with pytest.raises(ConfigError, match=r"beyond camera .*480x360.*--box-size"):
        read_box_groundtruth(BOXES, rig_file)
    bad = tmp_path / "b.xml"
    bad.write_text('<dataset><frame number="0"><objectlist><object id="1"><box xc="1" yc="2" w="3"/></object>')
    with pytest.raises(ConfigError, match="cannot read"):
        read_boxes(bad)
    bad.write_text(
        '<dataset><frame number="0"><objectlist><object id="1"><box xc="1" yc="2" w="3"/></object>'
        "</objectlist></frame></dataset>"
    )
    with pytest.raises(ConfigError, match="frame 0 object 1 <box>: missing attribute 'h'"):
        read_boxes(bad)


def test_cli_evaluate_xml(tmp_path):
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text(f"cameras:\n  - tsai: {XML}\n")
    gt = read_box_groundtruth(BOXES, rig_file)
    # tracks: the ground truth itself, one object shifted 2 m (a miss and a false positive in its frames)
    x = gt["x"].copy()
    x[gt["id"] == gt["id"][0]] += 2.0
    rows = ["frame,id,x,y,z"] + [
        f"{f},{i},{a},{b},0" for f, i, a, b in zip(gt["frame"], gt["id"], x, gt["y"], strict=True)
    ]
    (tmp_path / "tracks.csv").write_text("\n".join(rows) + "\n")
    pytest.importorskip("motmetrics")
    cmd = [sys.executable, "-m", "wptrack.cli", "evaluate", str(tmp_path / "tracks.csv"), "--groundtruth", str(BOXES)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH")) if p)}
    res = subprocess.run([*cmd, "--rig", str(rig_file)], capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode == 0, res.stderr
    n = len(gt["x"])
    k = int(np.sum(gt["id"] == gt["id"][0]))
    assert f"MOTA {1 - 2 * k / n:.3f}" in res.stdout
    res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=120)
    assert res.returncode == 2 and "need --rig" in res.stderr and "Traceback" not in res.stderr


@pytest.mark.skipif(not SHARED.is_dir(), reason="PETS 2009 development clip not present in ../shared/data")
def test_real_video_frames(tmp_path):
    cv2 = pytest.importorskip("cv2")
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text(f"cameras:\n  - tsai: {SHARED / 'View_001.xml'}\n")
    rig = Rig.load(rig_file)
    cap = cv2.VideoCapture(str(SHARED / "video.avi"))
    frames = []
    for _ in range(5):
        ok, frame = cap.read()
        assert ok
        frames.append(frame)
    cap.release()
    h, w = frames[0].shape[:2]
    cam = rig[0].for_size(w, h, "video.avi", str(rig_file))
    assert (cam.width, cam.height) == (w, h) == (480, 360)
    gt = read_box_groundtruth(SHARED / "PETS2009-S2L1-frames0-399.xml", rig_file)
    first = gt["frame"] < 5
    boxes = read_boxes(SHARED / "PETS2009-S2L1-frames0-399.xml")
    feet = np.column_stack([boxes["xc"], boxes["yc"] + boxes["h"] / 2])[boxes["frame"] < 5] * (w / 768.0)
    uv, depth = cam.project(np.column_stack([gt["x"], gt["y"], gt["z"]])[first])
    assert np.all(depth > 0)
    assert np.abs(uv - feet).max() < 1.0
    assert math.isclose(cam.K[0, 0] / rig[0].K[0, 0], 480 / 768)
