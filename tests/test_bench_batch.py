"""The batch benchmark (``wptrack/bench/batch.py``) at tiny sizes on the CPU: the ping-pong frame order of long runs,
the real-size template video it writes, and one whole measurement (warm actors, 2 CPU workers) whose numbers hang
together: E = T1 / (G TG) = (r1 / rG) x (bG / b1), the same tracks with 1 and 2 workers."""

from __future__ import annotations

import pytest

from wptrack.bench.batch import format_row, parallel_efficiency, pingpong, template_scene

pytestmark = pytest.mark.slow


def test_pingpong_plays_forward_and_back():
    assert list(pingpong(4, 11)) == [0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2]
    assert list(pingpong(1, 3)) == [0, 0, 0]


def test_template_video_is_scaled_and_as_long_as_asked(tmp_path, monkeypatch):
    """The plaza video scaled to the asked size and played forward and back (a stand-in render: 3 frames whose
    brightness is their index, the rig file; the real s3-people render takes seconds)."""
    import numpy as np

    import wptrack.synth
    from wptrack.io.frames import open_source
    from wptrack.io.video import write_video

    def render(name, out, frames, seed):
        assert name == "s3-people" and frames == 3
        out.mkdir(parents=True)
        write_video(out / "cam0.avi", [np.full((48, 64, 3), 80 * i, np.uint8) for i in range(3)], fps=15)
        (out / "rig.yaml").write_text("cameras: []\n")
        (out / "scene.json").write_text("{}")

    monkeypatch.setattr(wptrack.synth, "render_scene", render)
    scene = template_scene(tmp_path, frames=7, size=(320, 240), render_max=3)
    video = open_source(str(scene / "video.mp4"))
    assert (video.width, video.height, len(video)) == (320, 240, 7)
    means = [float(f.mean()) / 80 for f in video]  # MPEG-4 is lossy: the order, not the bytes
    assert [round(m) for m in means] == [0, 1, 2, 1, 0, 1, 2]
    assert (scene / "rig.yaml").exists()
    assert template_scene(tmp_path, frames=7, size=(320, 240), render_max=3) == scene  # written once


def test_parallel_efficiency_tiny_cpu(tmp_path):
    pytest.importorskip("ray")
    r = parallel_efficiency(runs=2, workers=2, particles=200, frames=3, gpu=False, work_dir=tmp_path, pool="actors")
    assert r["equivalent"] is True and r["workers_seen_g"] == 2
    assert r["parallel_efficiency"] == pytest.approx(r["t1_s"] / (2 * r["tg_s"]))
    assert r["parallel_efficiency"] == pytest.approx(r["run_ratio"] * r["busy_ratio"], rel=1e-9)
    assert r["pool_start_1"] > 0 and r["pool_start_g"] > 0  # the pools were started before the timed batches
    assert r["stages_g"]["module_load_s"] < 0.05  # warm workers: the kernels were loaded by the warm-up runs
    assert 0 < r["busy_1"] <= 1 and 0 < r["busy_g"] <= 1
    assert "batch" in format_row(r) and "alone:" in format_row(r)
