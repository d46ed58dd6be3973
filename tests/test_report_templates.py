"""Reports of S3 template-tracker runs (``wptrack.trackers.templates.report``): the NumPy template geometry against the
raster kernel, the calibration check (NumPy/OpenCV only, no PyVista), template outlines, and a rendered report of a
tiny s3-people run on the CPU (the PyVista parts skipped where PyVista is not installed)."""

from __future__ import annotations

import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from wptrack.cameras.rig import Camera, GroundPlane, Rig
from wptrack.core.errors import ConfigError

# ------------------------------------------------------------------------------------------------- helpers


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.refs: list[str] = []

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if name in ("src", "href") and value and not value.startswith("#"):
                self.refs.append(value)


def page_refs(index: Path) -> list[str]:
    parser = _Links()
    parser.feed(index.read_text(encoding="utf-8"))
    return parser.refs


def near(img: np.ndarray, uv: np.ndarray, bgr: tuple[int, int, int], radius: int, tol: int = 40) -> int:
    """How many pixels within ``radius`` of ``uv`` are within ``tol`` (per channel) of ``bgr``."""
    u, v = int(round(uv[0])), int(round(uv[1]))
    patch = img[max(0, v - radius) : v + radius + 1, max(0, u - radius) : u + radius + 1].astype(int)
    return int(np.sum(np.all(np.abs(patch - np.array(bgr)) <= tol, axis=-1)))


def plaza_like_camera() -> Camera:
    """A high camera looking down at the ground, with barrel distortion (like the s3 scenes' cam0)."""
    return Camera.look_at("cam0", 320, 240, (0.0, 0.0, 7.5), (0.0, 10.0, 0.0), 290.0, dist=[-0.08, 0.01, 0, 0, 0])


# ------------------------------------------------------------------------------------------------- geometry


def test_template_pieces_shapes_and_extents():
    from wptrack.trackers.templates.report import CABIN_LENGTH, LOWER, template_pieces

    legs, upper = template_pieces("human", (1.8, 0.2, 0.1))
    assert legs.shape == upper.shape == (16, 3)
    # legs: octagonal prism of 0.65 x the body radius up to the hips (half the height)
    np.testing.assert_allclose(np.hypot(legs[:, 0], legs[:, 1]), 0.65 * 0.2)
    np.testing.assert_allclose(sorted(set(np.round(legs[:, 2], 9))), [0.0, 0.9])
    # upper body: hexagons of the body radius at the hips and the shoulders (1.8 - 2.5 x 0.1), head square at the top
    np.testing.assert_allclose(np.hypot(upper[:12, 0], upper[:12, 1]), 0.2)
    np.testing.assert_allclose(sorted(set(np.round(upper[:12, 2], 9))), [0.9, 1.55])
    np.testing.assert_allclose(np.hypot(upper[12:, 0], upper[12:, 1]), 0.1)
    np.testing.assert_allclose(upper[12:, 2], 1.8)
    lower, cabin = template_pieces("vehicle", (4.0, 2.0, 1.5), heading=np.pi / 2)
    assert lower.shape == cabin.shape == (8, 3)
    # rotated a quarter turn: the length lies along ground y
    np.testing.assert_allclose(np.ptp(lower, axis=0), [2.0, 4.0, LOWER * 1.5], atol=1e-12)
    np.testing.assert_allclose(np.ptp(cabin[:, 1]), CABIN_LENGTH * 4.0)
    with pytest.raises(ValueError, match="class"):
        template_pieces("bicycle", (1, 1, 1))


def test_template_outlines_match_raster_kernel():
    """The report's NumPy template hulls are the tracker's: same vertices, same projection (distortion included),
    on a shifted and tilted ground plane."""
    import warp as wp

    from wptrack.cameras.structs import camera_struct
    from wptrack.kernels.templates import raster as kraster
    from wptrack.trackers.templates.report import template_outlines
    from wptrack.trackers.templates.tracker import Hulls, _plane_struct

    cam = plaza_like_camera()
    plane = GroundPlane(origin=(0.3, -0.2, 0.1), normal=(0.02, -0.05, 1.0), x_axis=(1.0, 0.1, 0.0))
    objects = [("human", (0.8, 9.0), (1.75, 0.2, 0.11), 0.7), ("vehicle", (-2.0, 13.0), (4.4, 1.8, 1.5), 0.4)]
    kinds = {"human": int(kraster.KIND_HUMAN), "vehicle": int(kraster.KIND_VEHICLE)}
    hulls = Hulls(1, len(objects), "cpu")
    hulls.launch(
        camera_struct(cam),
        _plane_struct(plane),
        wp.array([[kinds[o[0]] for o in objects]], dtype=wp.int32, device="cpu"),
        wp.array([[o[1] for o in objects]], dtype=wp.vec2, device="cpu"),
        wp.array([[o[3] for o in objects]], dtype=wp.float32, device="cpu"),
        wp.array([[o[2] for o in objects]], dtype=wp.vec3, device="cpu"),
        "cpu",
    )
    pts, counts = hulls.pts.numpy()[0], hulls.n.numpy()[0]
    for s, (cls, ground, dims, heading) in enumerate(objects):
        ours = template_outlines(cam, plane, cls, ground, dims, heading)
        assert len(ours) == 2
        for piece, hull in enumerate(ours):
            theirs = pts[s * 2 + piece, : counts[s * 2 + piece]]
            assert len(theirs) >= 3
            # every vertex of one hull is a vertex of the other (float32 kernel vs float64 here)
            d = np.linalg.norm(hull[:, None, :] - theirs[None, :, :], axis=2)
            assert d.min(axis=1).max() < 0.05 and d.min(axis=0).max() < 0.05, (cls, piece)


# ------------------------------------------------------------------------------------------------- calibration


def test_calibration_check_grid_passes_through_projected_ground_points():
    from wptrack.trackers.templates.report import GRID_ALPHA, GRID_BGR, calibration_check

    cam = plaza_like_camera()
    plane = GroundPlane(origin=(0.0, 0.0, 0.25))  # a raised ground: the grid must follow the rig's plane
    rig = Rig((cam,), ground=plane)
    frame = np.zeros((cam.height, cam.width, 3), np.uint8)
    out = calibration_check(rig, cam, frame)
    assert out.shape == frame.shape and out.dtype == np.uint8
    assert not np.any(frame), "the input frame is not modified"
    grid = tuple(int(round(GRID_ALPHA * c)) for c in GRID_BGR)
    on_lines = np.array([[1.0, 7.3], [-2.0, 11.6], [0.4, 9.0], [2.7, 12.0]])  # x = 1, x = -2, y = 9, y = 12
    uv, depth = cam.project(plane.to_world(on_lines))
    assert np.all(depth > 0)
    for p in uv:
        assert 20 < p[0] < cam.width - 20 and 30 < p[1] < cam.height - 10
        assert near(out, p, grid, radius=1, tol=60) >= 1, p
    # the middle of a grid cell stays dark
    uv, _ = cam.project(plane.to_world(np.array([[0.5, 9.5], [-1.5, 8.5]])))
    for p in uv:
        assert near(out, p, (0, 0, 0), radius=1, tol=10) == 9, p


def test_calibration_check_grey_and_resized_frames_and_errors():
    from wptrack.trackers.templates.report import calibration_check

    cam = plaza_like_camera()
    rig = Rig((cam,))
    grey = np.full((cam.height // 2, cam.width // 2), 50, np.uint8)  # a half-size copy: the camera is scaled
    out = calibration_check(rig, cam, grey)
    assert out.shape == (cam.height // 2, cam.width // 2, 3)
    assert np.any(out != 50)
    with pytest.raises(ValueError, match="frame size"):
        calibration_check(rig, cam, np.zeros((100, 100, 3), np.uint8))
    with pytest.raises(ValueError, match="step"):
        calibration_check(rig, cam, grey, step=0.0)


def test_calibration_check_needs_neither_pyvista_nor_warp():
    code = (
        "import sys, numpy as np\n"
        "from wptrack.cameras.rig import Camera, Rig\n"
        "from wptrack.trackers.templates.report import calibration_check\n"
        "cam = Camera.look_at('c', 64, 48, (0, 0, 3), (0, 5, 0), 60.0)\n"
        "out = calibration_check(Rig((cam,)), cam, np.zeros((48, 64), np.uint8))\n"
        "assert out.shape == (48, 64, 3)\n"
        "bad = [m for m in ('pyvista', 'vtk', 'matplotlib', 'warp') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr


def test_draw_templates_outline_and_truth_where_projected():
    from wptrack.trackers.templates.report import TRUTH_BGR, TemplateObject, draw_templates, id_bgr

    cam = plaza_like_camera()
    plane = GroundPlane()
    image = np.full((cam.height, cam.width, 3), 100, np.uint8)
    objs = [
        TemplateObject(3, "human", np.array([1.0, 9.0]), (1.75, 0.2, 0.1), 0.0),
        TemplateObject(5, "vehicle", np.array([-3.0, 14.0]), (4.4, 1.8, 1.5), 0.3),
    ]
    truth = [(0, "human", np.array([2.5, 8.0]))]
    out = draw_templates(image, cam, plane, objs, truth, scale=2)
    assert out.shape == (2 * cam.height, 2 * cam.width, 3)
    for o in objs:
        uv, _ = cam.project(plane.to_world(o.ground.reshape(1, 2)))
        assert near(out, 2 * uv[0] + 0.5, id_bgr(o.id), radius=3) >= 6, o.id
    uv, _ = cam.project(plane.to_world(truth[0][2].reshape(1, 2)))
    assert near(out, 2 * uv[0] + 0.5, TRUTH_BGR, radius=12) >= 10


# ------------------------------------------------------------------------------------------------- a tiny run


@pytest.fixture(scope="module")
def people_run(tmp_path_factory) -> dict:
    """s3-people, 8 frames, tracked on the CPU from the scene's perfect motion masks (100 particles)."""
    from wptrack.synth import render_scene
    from wptrack.trackers.templates.run import run_template_tracking
    from wptrack.trackers.templates.tracker import TemplateConfig

    root = tmp_path_factory.mktemp("s3")
    res = render_scene("s3-people", root / "scene", frames=8, seed=0)
    run_template_tracking(
        res.rig_path,
        root / "run",
        TemplateConfig(particles=100, seed=0),
        video=res.videos[0],
        masks=res.mask_videos[0],
        device="cpu",
        save_masks=True,
    )
    return {"run": root / "run", "scene": root / "scene", "rig": res.rig_path, "root": root}


SMALL = dict(still_size=(320, 240), movie_size=(160, 120), movie_frames=4, auto_frames=2)


@pytest.fixture(scope="module")
def report(people_run) -> Path:
    pytest.importorskip("matplotlib")
    from wptrack.report import ReportOptions, build_report

    return build_report(people_run["run"], options=ReportOptions(**SMALL))


def test_report_page_references_the_images(report, people_run):
    assert report == people_run["run"] / "report" / "index.html"
    html = report.read_text(encoding="utf-8")
    assert "S3 3D template tracker" in html
    refs = page_refs(report)
    for ref in refs:
        assert (report.parent / ref).is_file(), f"{ref} referenced but missing"
    names = {Path(r).name for r in refs}
    for expected in ("calibration.png", "birdseye.png", "objects_vs_frame.png", "timings.png"):
        assert expected in names
    for prefix in ("overlay_frame", "fig5_frame", "movie."):
        assert any(n.startswith(prefix) for n in names), prefix
    if "pyvista" in sys.modules:
        assert any(n.startswith("scene_frame") for n in names)
    assert "particle clouds are left out" not in html  # the colour tracker's notes do not apply
    assert "<script" not in html


def test_report_overlay_outlines_tracked_object(report, people_run):
    """The object's colour is drawn at the projected ground point of a tracked object (overlay_scale 2)."""
    import cv2

    from wptrack.io.tables import read_tracks
    from wptrack.trackers.templates.report import id_bgr

    rig = Rig.load(people_run["rig"])
    cam, plane = rig[0], rig.ground_plane
    tracks = read_tracks(people_run["run"] / "tracks.csv")
    overlays = sorted(report.parent.glob("overlay_frame*.png"))
    assert overlays
    checked = 0
    for path in overlays:
        frame = int(path.stem.replace("overlay_frame", ""))
        img = cv2.imread(str(path))
        assert img.shape[:2] == (2 * cam.height, 2 * cam.width)
        for r in np.flatnonzero(tracks["frame"] == frame):
            uv, _ = cam.project(plane.to_world(np.array([[tracks["gx"][r], tracks["gy"][r]]])))
            assert near(img, 2 * uv[0] + 0.5, id_bgr(int(tracks["id"][r])), radius=4) >= 6, (frame, r)
            checked += 1
    assert checked > 0


def test_report_fig5_has_mask_and_virtual_panels(report):
    import cv2

    figs = sorted(report.parent.glob("fig5_frame*.png"))
    assert figs
    img = cv2.imread(str(figs[-1]))
    assert img.shape[1] > 4 * 640  # frame, mask, virtual scene and XOR side by side
    assert np.all(img == 255, axis=2).sum() > 1000  # the label bar, mask foreground and XOR agreement


def test_calibration_section_on_masks_without_video(people_run, tmp_path):
    """A run without a video shows the calibration check on its first motion mask."""
    import cv2

    from wptrack.report.data import load_run
    from wptrack.report.model import ReportContext, ReportOptions
    from wptrack.trackers.templates.report import section_calibration

    data = load_run(people_run["run"])
    data.run["config"]["video"] = None
    ctx = ReportContext(out_dir=tmp_path, data=data, sweep=None, options=ReportOptions())
    sec = section_calibration(ctx)
    assert sec is not None and [f.path for f in sec.figures] == ["calibration.png"]
    assert "motion mask" in sec.figures[0].caption
    cam = Rig.load(people_run["rig"])[0]
    img = cv2.imread(str(tmp_path / "calibration.png"))
    assert img.shape[:2] == (cam.height, cam.width)


def test_groundtruth_option_and_scene_fallback(people_run, tmp_path):
    from wptrack.report import ReportOptions, build_report, use_groundtruth
    from wptrack.report.data import load_run
    from wptrack.report.model import ReportContext
    from wptrack.trackers.templates.report import template_run

    gt = people_run["scene"] / "groundtruth.csv"
    data = load_run(people_run["run"])
    data.groundtruth, data.groundtruth_path = None, None
    use_groundtruth(data, gt)
    assert data.groundtruth_path == gt and data.groundtruth
    with pytest.raises(ConfigError, match="ground truth not found"):
        build_report(people_run["run"], out_dir=tmp_path / "r", options=ReportOptions(groundtruth=tmp_path / "no.csv"))
    # no ground truth found by the loader: ../scene/groundtruth.csv next to the run folder is used
    data = load_run(people_run["run"])
    data.groundtruth, data.groundtruth_path = None, None
    ctx = ReportContext(out_dir=tmp_path, data=data, sweep=None, options=ReportOptions())
    run = template_run(ctx)
    assert run.truth is not None and data.groundtruth_path.resolve() == gt.resolve()
    assert run.truth_at(3) and run.objects_at(int(data.frames[-1]))
