"""The people run's report: occupancy iso-surfaces and hull meshes rendered off-screen, the projected hulls on every
camera's frame in the id's colour, metrics against the ground truth."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from wptrack.cli import main

sys.path.insert(0, str(Path(__file__).parent))
from test_cli_people import _args, scene  # noqa: E402, F401  (the module-scoped scene fixture)


def test_people_report(scene, tmp_path):  # noqa: F811
    pytest.importorskip("pyvista")
    import cv2

    from wptrack.cameras.rig import Rig
    from wptrack.trackers.people.report import draw_people, load_hulls
    from wptrack.trackers.templates.report import id_bgr

    out = tmp_path / "run"
    assert main([*_args(scene, out), "--occupancy-every", "5"]) == 0
    assert main(["report", str(out), "--groundtruth", str(scene / "groundtruth.csv"), "--no-movie", "-q"]) == 0
    rep = out / "report"
    html = (rep / "index.html").read_text()
    for key in ("occupancy", "segmentation", "metrics", "MOTA"):
        assert key in html
    occ = sorted(rep.glob("occupancy_frame*.png"))
    seg = sorted(rep.glob("segmentation_frame*.png"))
    assert occ and seg
    img = cv2.imread(str(occ[-1]))
    assert img is not None and img.std() > 5  # not blank
    # the projected hull is drawn in the person's colour where the person stands in the camera
    hulls = load_hulls(out)
    frame = max(f for f, _ in hulls)
    rig = Rig.load(scene / "rig.yaml")
    cam = rig.cameras[0]
    pid, verts = next((i, v) for (f, i), v in hulls.items() if f == frame)
    blank = np.full((cam.height, cam.width, 3), 128, np.uint8)
    drawn = draw_people(blank, cam, [(pid, verts)])
    uv, _ = cam.project(verts.mean(0)[None])
    u, v = np.round(uv[0]).astype(int)
    expected = 0.35 * np.array(id_bgr(pid)) + 0.65 * 128
    assert np.abs(drawn[v, u].astype(float) - expected).max() < 3


def test_people_report_has_a_movie_and_says_what_its_views_show(scene, tmp_path):  # noqa: F811
    """Issue 30 items 18, 19: the people report had no movie although the README lists one; its bird's-eye section
    said 'particle clouds' and then 'no particles.npz: only the trajectories are shown'; the occupancy views had no
    axes or scale."""
    pytest.importorskip("pyvista")
    out = tmp_path / "run"
    assert main([*_args(scene, out), "--occupancy-every", "5", "--max-frames", "20"]) == 0
    argv = ["report", str(out), "--groundtruth", str(scene / "groundtruth.csv"), "--movie-frames", "3", "-q"]
    assert main(argv) == 0
    rep = out / "report"
    html = (rep / "index.html").read_text()
    assert "3D view over time" in html and list(rep.glob("movie.*"))
    assert "Bird&#x27;s-eye view of the trajectories" in html or "Bird's-eye view of the trajectories" in html
    assert "particle cloud over time" not in html and "no particles.npz" not in html
    assert "Particle clouds over time" not in html
    assert html.count("the world axes (lower left)") >= 2  # the 3D scene and the occupancy views
    assert "bounding volume projected into every camera" in html  # the segmentation captions say what is drawn
