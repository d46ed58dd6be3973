"""Rendered reports (issue 4): the OpenCV -> VTK camera, content of a small report of a real (synthetic) run, the
page's links, missing inputs, bad inputs, sweeps, the CLI flags and the tracker registry.

Everything that renders needs PyVista (skipped where it is not installed, e.g. on the GPU test machine)."""

from __future__ import annotations

import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from wptrack.cameras.rig import Camera
from wptrack.core.errors import ConfigError, OutputError

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


def read_rgb(path: Path) -> np.ndarray:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert img is not None, path
    return img[..., ::-1]


def assert_not_blank(path: Path, min_colours: int = 20) -> None:
    img = read_rgb(path)
    assert img.std() > 5.0, f"{path.name} looks blank"
    colours = np.unique(img.reshape(-1, 3)[:: max(1, img.size // 3 // 20000)], axis=0)
    assert len(colours) >= min_colours, f"{path.name} has only {len(colours)} colours"


def near(img: np.ndarray, uv: np.ndarray, rgb: tuple[int, int, int], radius: int, tol: int = 60) -> int:
    """How many pixels within ``radius`` of ``uv`` are within ``tol`` (per channel) of ``rgb``."""
    u, v = int(round(uv[0])), int(round(uv[1]))
    patch = img[max(0, v - radius) : v + radius + 1, max(0, u - radius) : u + radius + 1].astype(int)
    return int(np.sum(np.all(np.abs(patch - np.array(rgb)) <= tol, axis=-1)))


# ------------------------------------------------------------------------------------------------- vtkcam


CAMERAS = [
    Camera.look_at("square", 160, 120, (0.0, -1.0, 0.5), (0.1, 0.0, 0.1), 130.0, cx=70.3, cy=65.8),
    Camera.look_at(
        "aniso", 120, 160, (1.0, -1.0, 0.3), (0.0, 0.0, 0.1), 150.0, fy=120.0, cx=50.2, cy=88.9, roll_deg=90
    ),
]
POINTS = np.array([[0.1, 0.0, 0.1], [0.3, 0.2, 0.0], [-0.2, 0.1, 0.3], [0.0, 0.25, 0.05]])


def test_vtk_camera_params_geometry():
    from wptrack.report.vtkcam import vtk_camera_params

    cam = CAMERAS[1]
    p = vtk_camera_params(cam, distance=2.0)
    np.testing.assert_allclose(p.position, -cam.R.T @ cam.t)
    np.testing.assert_allclose(p.focal_point - p.position, 2.0 * cam.R.T @ [0, 0, 1])
    np.testing.assert_allclose(p.view_up, -cam.R.T @ [0, 1, 0])
    assert p.view_angle == pytest.approx(np.degrees(2 * np.arctan(cam.height / (2 * cam.fy))))
    assert p.x_scale == pytest.approx(cam.fx / cam.fy)
    # a centred principal point ((w - 1) / 2, (h - 1) / 2) needs no window shift
    centred = Camera.look_at("c", 64, 48, (0, -1, 0), (0, 0, 0), 50.0)
    assert vtk_camera_params(centred).window_center == pytest.approx((0.0, 0.0), abs=1e-12)


@pytest.mark.parametrize("cam", CAMERAS, ids=lambda c: c.name)
def test_vtk_camera_render_matches_opencv(cam):
    """A small bright sphere rendered from a rig camera lands within 1 px of cv2.projectPoints."""
    pv = pytest.importorskip("pyvista")
    from wptrack.report.offscreen import new_plotter
    from wptrack.report.vtkcam import apply_camera

    uv, depth = cam.project(POINTS)
    assert np.all(depth > 0)
    pl = new_plotter(cam.width, cam.height, background="black")
    try:
        actors = [
            pl.add_mesh(pv.Sphere(radius=0.015, center=p), color="white", lighting=False, render=False) for p in POINTS
        ]
        apply_camera(pl, cam)
        for i in range(len(POINTS)):
            for j, actor in enumerate(actors):
                actor.SetVisibility(i == j)
            pl.render()
            img = pl.screenshot(return_img=True).astype(np.float64).mean(axis=2)
            ys, xs = np.nonzero(img > 0)
            assert len(xs) >= 3, f"point {i} not rendered"
            w = img[ys, xs]
            centroid = np.array([(xs * w).sum() / w.sum(), (ys * w).sum() / w.sum()])
            assert np.linalg.norm(centroid - uv[i]) < 1.0, (i, centroid, uv[i])
    finally:
        pl.close()


def test_apply_camera_checks_window_size():
    pytest.importorskip("pyvista")
    from wptrack.report.offscreen import new_plotter
    from wptrack.report.vtkcam import apply_camera

    pl = new_plotter(50, 40)
    try:
        with pytest.raises(ValueError, match="scaled"):
            apply_camera(pl, CAMERAS[0])
    finally:
        pl.close()


# ------------------------------------------------------------------------------------------------- a small run


@pytest.fixture(scope="module")
def lab_run(tmp_path_factory) -> dict:
    """The s1-lab scene (10 frames) tracked on the CPU: run folder, scene folder."""
    from wptrack.synth import render_scene
    from wptrack.trackers.colour.run import run_color_tracking
    from wptrack.trackers.colour.tracker import ColorConfig, HSITarget

    root = tmp_path_factory.mktemp("lab")
    res = render_scene("s1-lab", root / "scene", frames=10, seed=0)
    hints = json.loads(Path(res.scene_json).read_text())
    t = hints["target"]
    target = HSITarget(hue=tuple(t["hue"]), sat=tuple(t["sat"]), intensity=tuple(t["intensity"]))
    config = ColorConfig(particles=150, sigma=0.03, init=tuple(hints["init"]), seed=0, keep_particles=150)
    run_color_tracking(
        res.rig_path, res.videos, target, root / "run", config, device="cpu", groundtruth=res.groundtruth_path
    )
    return {"run": root / "run", "scene": root / "scene", "root": root}


SMALL = dict(still_size=(320, 240), movie_size=(160, 120), movie_frames=5, auto_frames=3)


@pytest.fixture(scope="module")
def report(lab_run) -> Path:
    pytest.importorskip("pyvista")
    from wptrack.report import ReportOptions, build_report

    return build_report(lab_run["run"], options=ReportOptions(**SMALL))


def test_report_page_links_exist_and_header(report, lab_run):
    assert report == lab_run["run"] / "report" / "index.html"
    refs = page_refs(report)
    assert refs, "the page references no file"
    for ref in refs:
        assert not re.match(r"^[a-z]+://", ref), f"network reference {ref}"
        assert (report.parent / ref).is_file(), f"{ref} referenced but missing"
    html = report.read_text()
    for text in (
        "S1 colour particle filter",
        "complete",
        "tracker.sigma",
        "warp",
        "vtkEGLRenderWindow|vtk",
        "decode",
        "converged_at",
        "device",
    ):
        assert re.search(text, html), text
    names = {Path(r).name for r in refs}
    for expected in (
        "scene_overview.png",
        "birdseye.png",
        "error_vs_frame.png",
        "timings.png",
        "camview_cam1.png",
        "camview_cam2.png",
    ):
        assert expected in names
    assert any(n.startswith("overlay_frame") for n in names)
    assert any(n.startswith("movie.") for n in names)
    assert "<script" not in html  # a static page


def test_report_images_not_blank(report):
    for png in sorted(report.parent.glob("*.png")):
        assert_not_blank(png)


def test_overlay_shows_truth_and_estimate_where_projected(report, lab_run):
    """The green ground-truth circle and the orange estimate cross are drawn at their projections in each
    camera's panel of the overlay composite."""
    from wptrack.cameras.rig import Rig
    from wptrack.io.tables import read_tracks
    from wptrack.report.overlays import LABEL_HEIGHT
    from wptrack.report.scene3d import ESTIMATE_RGB, TRUTH_RGB

    rig = Rig.load(lab_run["scene"] / "rig.yaml")
    gt = read_tracks(lab_run["scene"] / "groundtruth.csv")
    est = read_tracks(lab_run["run"] / "tracks.csv")
    overlay = sorted(report.parent.glob("overlay_frame*.png"))[-1]
    frame = int(overlay.stem.replace("overlay_frame", ""))
    img = read_rgb(overlay)
    x0 = 0
    for cam in rig.cameras:
        for table, rgb, radius in ((gt, TRUTH_RGB, 9), (est, ESTIMATE_RGB, 7)):
            k = int(np.nonzero(table["frame"] == frame)[0][0])
            uv, depth = cam.project(np.array([[table["x"][k], table["y"][k], table["z"][k]]]))
            if depth[0] <= 0 or not (0 <= uv[0, 0] < cam.width and 0 <= uv[0, 1] < cam.height):
                continue
            px = uv[0] * 2 + 0.5 + np.array([x0, LABEL_HEIGHT])
            assert near(img, px, rgb, radius, tol=50) >= 6, (cam.name, rgb)
        x0 += 2 * cam.width + 6


def test_camera_view_shows_truth_marker_where_projected(report, lab_run):
    """The 3D scene rendered from each rig camera puts the ground-truth marker where cv2 projects it (no
    distortion: the frame is undistorted and the render is a pinhole)."""
    import cv2

    from wptrack.cameras.rig import Rig
    from wptrack.io.tables import read_tracks
    from wptrack.report.scene3d import TRUTH_RGB

    rig = Rig.load(lab_run["scene"] / "rig.yaml")
    gt = read_tracks(lab_run["scene"] / "groundtruth.csv")
    html = report.read_text()
    frame = int(re.search(r"cam1, frame (\d+)", html).group(1))
    k = int(np.nonzero(gt["frame"] == frame)[0][0])
    p = np.array([[gt["x"][k], gt["y"][k], gt["z"][k]]])
    for cam0 in rig.cameras:
        img = read_rgb(report.parent / f"camview_{cam0.name}.png")
        cam = cam0.scaled(2 * cam0.width, 2 * cam0.height)  # rendered at overlay_scale (2) times the resolution
        assert img.shape[:2] == (cam.height, cam.width)
        uv, _ = cv2.projectPoints(p, cam.rvec, np.asarray(cam.t), np.asarray(cam.K), None)
        assert near(img, uv.reshape(2), TRUTH_RGB, 2, tol=40) >= 6, cam.name


def test_movie_has_frames(report):
    import cv2

    web = [p for p in report.parent.glob("movie.*") if p.suffix in (".webm", ".gif")]
    assert len(web) == 1
    if web[0].suffix == ".webm":
        cap = cv2.VideoCapture(str(web[0]))
        n = 0
        while cap.read()[0]:
            n += 1
        cap.release()
        assert n == SMALL["movie_frames"]
    mp4 = report.parent / "movie.mp4"
    if mp4.exists():
        assert mp4.stat().st_size > 0


def test_gif_fallback_without_webm_encoder(tmp_path, monkeypatch):
    pytest.importorskip("PIL")
    from PIL import Image

    from wptrack.report import movie

    monkeypatch.setattr(movie, "WEBM_CODECS", ())
    frames = [np.full((40, 60, 3), 40 * i, np.uint8) for i in range(4)]
    files = movie.encode_movie(iter(frames), tmp_path, fps=5)
    assert files.web is not None and files.web.suffix == ".gif"
    assert any("GIF" in n for n in files.notes)
    with Image.open(files.web) as gif:
        assert gif.n_frames == 4


def test_draw_overlay_colours_by_weight():
    """The heaviest particle is drawn in viridis yellow exactly at its (upscaled) projection."""
    from wptrack.report.overlays import draw_overlay

    cam = CAMERAS[0]
    image = np.full((cam.height, cam.width, 3), 128, np.uint8)
    pts = np.array([[0.1, 0.0, 0.1], [0.0, 0.25, 0.05]])
    out = draw_overlay(image, cam, pts, np.array([1.0, 0.0]), scale=2)
    uv, _ = cam.project(pts)
    bgr = out.astype(int)
    heavy = bgr[int(round(2 * uv[0, 1] + 0.5)), int(round(2 * uv[0, 0] + 0.5))]
    light = bgr[int(round(2 * uv[1, 1] + 0.5)), int(round(2 * uv[1, 0] + 0.5))]
    assert heavy[2] > 200 and heavy[1] > 180 and heavy[0] < 100  # yellow (BGR)
    assert light[2] < 100 and light[0] > 60  # dark purple


# ------------------------------------------------------------------------------------------------- missing inputs


def _copy_run(src: Path, dst: Path) -> Path:
    dst.mkdir(parents=True)
    for name in ("run.json", "tracks.csv", "particles.npz"):
        shutil.copy(src / name, dst / name)
    return dst


def test_missing_groundtruth_and_videos_leave_panels_out(lab_run, tmp_path):
    pytest.importorskip("pyvista")
    from wptrack.report import ReportOptions, build_report

    run = _copy_run(lab_run["run"], tmp_path / "run")
    lonely = tmp_path / "rigonly"
    lonely.mkdir()
    shutil.copy(lab_run["scene"] / "rig.yaml", lonely / "rig.yaml")  # no groundtruth.csv beside it
    meta = json.loads((run / "run.json").read_text())
    meta["config"]["rig"] = str(lonely / "rig.yaml")
    meta["config"]["videos"] = [str(tmp_path / "gone1.avi"), str(tmp_path / "gone2.avi")]
    (run / "run.json").write_text(json.dumps(meta))
    index = build_report(run, out_dir=tmp_path / "rep", options=ReportOptions(**{**SMALL, "movie": False}))
    html = index.read_text()
    assert "no groundtruth.csv" in html
    assert "video(s) not found" in html
    assert not list(index.parent.glob("overlay_*.png"))
    assert not list(index.parent.glob("camview_*.png"))
    assert (index.parent / "scene_overview.png").is_file()
    assert "ground truth" in html and "error panel is left out" in html
    for ref in page_refs(index):
        assert (index.parent / ref).is_file()


# ------------------------------------------------------------------------------------------------- bad inputs


def test_not_a_run_directory(tmp_path):
    from wptrack.report import build_report

    with pytest.raises(OutputError, match="no run.json"):
        build_report(tmp_path)
    with pytest.raises(OutputError, match="not found"):
        build_report(tmp_path / "missing")


def test_unknown_tracker_and_empty_tracks(lab_run, tmp_path):
    from wptrack.report import build_report

    run = _copy_run(lab_run["run"], tmp_path / "unknown")
    meta = json.loads((run / "run.json").read_text())
    meta["tracker"] = "kalman"
    (run / "run.json").write_text(json.dumps(meta))
    with pytest.raises(ConfigError, match="no report for tracker 'kalman'"):
        build_report(run)
    empty = _copy_run(lab_run["run"], tmp_path / "empty")
    (empty / "tracks.csv").write_text("frame,id,x,y,z\n")
    with pytest.raises(OutputError, match="no rows"):
        build_report(empty)


def test_cli_report_errors_one_line(tmp_path, capsys):
    from wptrack.cli import main

    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("wptrack: error:") and "run.json" in err[0]
    assert main(["report", str(tmp_path), "--sweep", str(tmp_path / "nothing")]) == 2
    assert "sigma sweep" in capsys.readouterr().err
    other = tmp_path / "groundtruth.csv"  # another table: the line said only "cannot read sigma sweep ...: 'sigma'"
    other.write_text("frame,id,x,y,z\n0,0,0.4,0.5,0.06\n")
    assert main(["report", str(tmp_path), "--sweep", str(other)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing column 'sigma'" in err[0] and "wptrack convergence" in err[0], err


# ------------------------------------------------------------------------------------------------- sweeps, CLI


def _sweep_dir(path: Path) -> Path:
    from wptrack.trackers.colour.sweep import write_sweep

    sigmas = np.array([0.001, 0.05, 0.1])
    it = np.arange(30)
    errors = np.array(
        [
            np.where(it < 10, 0.2, 2.0),
            0.02 + 2.0 * np.exp(-(it - 10) / 3.0) * (it >= 10),
            0.05 + 2.0 * np.exp(-(it - 10) / 1.5) * (it >= 10),
        ]
    )
    write_sweep({"sigmas": sigmas, "errors": errors, "std": errors * 0.1, "params": {}, "summary": []}, path)
    return path


def test_sweep_only_report(tmp_path):
    pytest.importorskip("pyvista")
    from wptrack.cli import main

    sweep = _sweep_dir(tmp_path / "sweep")
    assert main(["report", str(sweep)]) == 0
    index = sweep / "report" / "index.html"
    assert {Path(r).name for r in page_refs(index)} == {"sweep_heatmap.png"}
    assert_not_blank(index.parent / "sweep_heatmap.png")


def test_track_color_report_flag_and_sweep_option(lab_run, tmp_path, capsys):
    """``track color --report`` renders OUT/report after tracking; ``report RUN --sweep`` adds the heatmap."""
    pytest.importorskip("pyvista")
    from wptrack.cli import build_parser, main

    assert build_parser().parse_args(["demo"]).report is True
    assert build_parser().parse_args(["demo", "--no-report"]).report is False
    scene = lab_run["scene"]
    out = tmp_path / "run"
    args = [
        "track",
        "color",
        "-q",
        "--rig",
        str(scene / "rig.yaml"),
        "--video",
        str(scene / "cam1.avi"),
        "--video",
        str(scene / "cam2.avi"),
        "--hue",
        "312",
        "348",
        "--sat",
        "0.3",
        "0.8",
        "--init",
        "0.4",
        "0.1",
        "0.2",
        "--particles",
        "60",
        "--max-frames",
        "3",
        "--device",
        "cpu",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    assert not (out / "report").exists()  # off by default
    assert main([*args, "--report", "--overwrite"]) == 0  # the same --out again: replace the run
    assert (out / "report" / "index.html").is_file()
    assert "report:" in capsys.readouterr().out
    sweep = _sweep_dir(tmp_path / "sweep")
    assert (
        main(
            [
                "report",
                str(out),
                "--out",
                str(tmp_path / "rep"),
                "--sweep",
                str(sweep / "errors.csv"),
                "--frames",
                "0",
                "2",
                "--no-movie",
            ]
        )
        == 0
    )
    index = tmp_path / "rep" / "index.html"
    names = {Path(r).name for r in page_refs(index)}
    assert {"sweep_heatmap.png", "scene_frame00000.png", "scene_frame00002.png", "overlay_frame00002.png"} <= names
    assert not list(index.parent.glob("movie.*"))
    assert main(["report", str(out), "--frames", "99"]) == 2  # outside the run


# ------------------------------------------------------------------------------------------------- registry


def test_registry_plugs_in_a_new_tracker(lab_run, tmp_path):
    """A tracker registers its own section builders; the page shows them (S2/S3 plug in this way)."""
    from wptrack.report import REPORTERS, Section, build_report, register_reporter

    assert "color" in REPORTERS
    run = _copy_run(lab_run["run"], tmp_path / "custom")
    meta = json.loads((run / "run.json").read_text())
    meta["tracker"] = "unit-test-tracker"
    (run / "run.json").write_text(json.dumps(meta))

    def people_section(ctx):
        return Section("people", "People boxes", notes=[f"{len(ctx.data.estimates)} object(s), frames {ctx.frames}"])

    register_reporter("unit-test-tracker", "a test tracker", (people_section,))
    try:
        html = build_report(run, frames=[1]).read_text()
    finally:
        REPORTERS.pop("unit-test-tracker")
    assert "People boxes" in html and "1 object(s), frames [1]" in html


def test_3d_views_have_axes_and_a_scale_and_captions_say_the_markers(report):
    """Issue 30 item 19: the 3D scene had no axes or scale bar, and the overlay captions did not say what the
    markers are."""
    import cv2

    html = report.read_text()
    assert "the world axes (lower left)" in html and "grid" in html and "spacing in metres" in html
    assert "orange cross" in html and "green circle" in html and "yellow = heaviest" in html  # overlay captions
    assert "orange sphere" in html and "green sphere" in html  # per-frame 3D stills
    # the axes marker is drawn in the lower left corner, the grid label in the upper right
    img = cv2.imread(str(report.parent / "scene_overview.png"))
    h, w = img.shape[:2]
    corner = img[int(0.8 * h) :, : int(0.2 * w)]
    assert (corner.min(axis=2) < 128).sum() > 20, "no axes marker in the lower left corner"
    right = img[: int(0.1 * h), int(0.6 * w) :]
    assert (right.max(axis=2) < 80).sum() > 20, "no scale label in the upper right corner"


def test_ground_grid_step_is_returned():
    pytest.importorskip("pyvista")
    from wptrack.report.offscreen import import_pyvista, new_plotter
    from wptrack.report.scene3d import SceneGeometry, add_ground

    pv = import_pyvista()
    pl = new_plotter(160, 120)
    try:
        geo = SceneGeometry(np.zeros(3), np.array([4.0, 3.0, 2.0]), up=2, up_sign=1.0, ground=0.0, frustum_depth=0.5)
        assert add_ground(pl, pv, geo, None) == 0.5  # 4 m / 8 -> the nice step 0.5 m, the label's number
    finally:
        pl.close()
