"""Run-loop hardening (issue 14): a video truncated mid-stream stops the run at the break and run.json says where."""

from __future__ import annotations

import json

import pytest

from wptrack.bench.soak import cycle_scene
from wptrack.errors import FrameError
from wptrack.frames import write_video
from wptrack.io import read_tracks
from wptrack.runs import run_tracker
from wptrack.runs.colour import ColourRun
from wptrack.trackers.colour import ColorConfig, HSITarget

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
