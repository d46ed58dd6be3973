"""Run-loop hardening (issue 14): a video truncated mid-stream stops the run at the break and run.json says where."""

from __future__ import annotations

import json

import pytest

from wptrack.bench.soak import cycle_scene
from wptrack.core.errors import FrameError
from wptrack.io.tables import read_tracks
from wptrack.io.video import write_video
from wptrack.runs import run_tracker
from wptrack.trackers.colour.run import ColourRun
from wptrack.trackers.colour.tracker import ColorConfig, HSITarget

TARGET = HSITarget(hue=(300.0, 340.0), sat=(0.3, 1.0), intensity=(20.0, 240.0))


@pytest.fixture(scope="module")
def videos(tmp_path_factory):
    """Two 30-frame FFV1 AVIs of the soak scene, the second also cut in half (bytes cut off the end)."""
    root = tmp_path_factory.mktemp("cut")
    rig, frames, balls = cycle_scene(2)
    rig.save(root / "rig.yaml")
    paths = []
    for i, v in enumerate(frames):
        paths.append(root / f"cam{i}.avi")
        write_video(paths[-1], v[:30])
    cut = root / "cam1_cut.avi"
    data = paths[1].read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    cfg = ColorConfig(particles=50, sigma=0.01, init=tuple(balls[0]), keep_particles=10)
    return root / "rig.yaml", paths, cut, cfg


def test_truncated_video_stops_the_run_at_the_break(tmp_path, videos):
    rig_path, (a, b), cut, cfg = videos
    run_tracker(ColourRun(rig_path, [a, b], TARGET, cfg, device="cpu"), tmp_path / "whole")
    assert json.loads((tmp_path / "whole" / "run.json").read_text())["stopped_early"] is None

    # --stop-at-shortest: the frames up to the break are tracked, the run completes and says where it stopped
    run_tracker(ColourRun(rig_path, [a, cut], TARGET, cfg, device="cpu", stop_at_shortest=True), tmp_path / "cut")
    run = json.loads((tmp_path / "cut" / "run.json").read_text())
    stop = run["stopped_early"]
    assert run["status"] == "complete" and stop["camera"] == str(cut) and stop["expected"] == 30
    assert 0 < stop["frame"] < 30 and "ended after" in stop["reason"]
    tracks = read_tracks(tmp_path / "cut" / "tracks.csv")
    assert tracks["frame"].max() == stop["frame"] - 1 == run["last_frame"] and run["frames"] == stop["frame"]

    # without it the other camera continues: the run fails at the break (clear error), outputs up to it kept
    with pytest.raises(FrameError, match="ended after"):
        run_tracker(ColourRun(rig_path, [a, cut], TARGET, cfg, device="cpu"), tmp_path / "fail")
    run = json.loads((tmp_path / "fail" / "run.json").read_text())
    assert run["status"] == "failed" and run["stopped_early"]["frame"] == stop["frame"]
    assert run["last_frame"] == stop["frame"] - 1 and str(cut) in run["error"]


# ------------------------------------------------------------------------------------------ degenerate weights


@pytest.mark.parametrize("partition", [False, True], ids=["joint", "partitioned"])
def test_template_tracker_flags_a_frame_with_zero_likelihood_everywhere(device, partition):
    """All log-weights NaN (a broken observation): the score kernel floors them, the frame keeps the predicted
    particles with uniform weights, stays finite and is flagged; the next frame is normal again. The partitioned
    filter resamples every group on its own factor of the observation (the particles' prior weights are uniform
    after every frame, so it reads none): the frame is flagged, and its groups' weights stay finite."""
    import numpy as np

    from wptrack.cameras.rig import Camera, Rig
    from wptrack.kernels.core.reduce import LOGW_FLOOR
    from wptrack.trackers.templates.tracker import TemplateConfig, TemplateTracker

    cam = Camera.look_at("cam0", 160, 120, position=[0, -4, 10], target=[0, 9, 0], fx=125.0)
    cfg = TemplateConfig(particles=200, max_objects=4, seed=1, partition=partition)
    tr = TemplateTracker(Rig(cameras=(cam,)), cfg, device=device)
    mask = np.zeros((120, 160), np.uint8)
    mask[40:80, 60:70] = 1
    for _ in range(3):
        assert not tr.step(mask).degenerate
    tr.state[tr.parity].logw.fill_(float("nan"))
    lost = tr.step(mask)
    assert lost.degenerate and lost.loglik == pytest.approx(float(LOGW_FLOOR))
    assert lost.ess == pytest.approx(200, rel=1e-6)  # uniform joint weights: the prior
    if partition:
        w = tr.weights.numpy()[: lost.groups]
        assert lost.groups >= 1 and np.all(np.isfinite(w)) and np.all(w.max(axis=1) == 1.0)
    else:
        np.testing.assert_array_equal(tr.weights.numpy(), 1.0)
    assert all(np.all(np.isfinite(o.position)) for o in lost.objects + lost.best)
    back = tr.step(mask)
    assert not back.degenerate and np.isfinite(back.loglik) and back.loglik > 0.5 * float(LOGW_FLOOR)


def test_people_tracker_flags_a_person_with_zero_likelihood_everywhere(device):
    """A person's appearance model turned NaN: every particle's log-likelihood is NaN, floored; the person's estimate
    keeps the predicted cloud (uniform weights), stays finite and is flagged."""
    import sys
    from pathlib import Path

    import numpy as np

    sys.path.insert(0, str(Path(__file__).parent))
    from test_tracker_people import crossing, render, rig3

    from wptrack.trackers.people.tracker import PeopleConfig, PeopleTracker

    rng = np.random.default_rng(5)
    rig = rig3()
    tr = PeopleTracker(rig, PeopleConfig(particles=300, seed=3), device=device)
    est = None
    for _, people in crossing(10):
        est = tr.step(*render(rig, people, rng))
        assert not any(p.degenerate for p in est.people)
    assert est.people, "nobody tracked after 10 frames"
    for f in tr.pool:
        for m in f.model:
            m.fill_(float("nan"))
    lost = tr.step(*render(rig, people, rng))
    assert lost.people and all(p.degenerate for p in lost.people)
    for p in lost.people:
        assert np.all(np.isfinite(p.mean)) and np.all(np.isfinite(p.std))
        assert p.ess == pytest.approx(300, rel=1e-3)
