"""Command line: end-to-end on a tiny scene, and every bad input of the foundation issue gives one clear
line on stderr, exit code 2, no traceback and no output written."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import warp as wp

from wptrack.cameras.rig import Camera, Rig
from wptrack.cli import main
from wptrack.io.tables import read_tracks
from wptrack.io.video import write_video

BALL = np.array([0.42, 0.45, 0.035])


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> dict:
    """Two small cameras watching a pink disc at BALL, 6 frames each (FFV1/MJPG video)."""
    import cv2

    d = tmp_path_factory.mktemp("scene")
    c1 = Camera.look_at("cam1", 96, 72, (0.5, 0.0, 0.195), (0.4, 0.45, 0.05), 90.0)
    c2 = Camera.look_at("cam2", 72, 96, (0.07, 0.485, 0.085), (0.45, 0.45, 0.05), 90.0, roll_deg=90)
    rig = Rig((c1, c2))
    rig.save(d / "rig.yaml")
    videos = []
    for cam in rig.cameras:
        img = np.full((cam.height, cam.width, 3), 90, np.uint8)
        uv, depth = cam.project(BALL[None])
        r = max(2, int(0.035 * cam.fx / depth[0]))
        cv2.circle(img, (int(round(uv[0, 0])), int(round(uv[0, 1]))), r, (180, 60, 230), -1)
        path = d / f"{cam.name}.avi"
        write_video(path, [img] * 6, fps=10)
        videos.append(str(path))
    return {"dir": d, "rig": str(d / "rig.yaml"), "videos": videos}


def track_args(scene, out, *extra):
    args = [
        "track",
        "color",
        "-q",
        "--rig",
        scene["rig"],
        "--hue",
        "300",
        "340",
        "--sat",
        "0.3",
        "1",
        "--init",
        "0.42",
        "0.45",
        "0.05",
        "--particles",
        "300",
        "--device",
        "cpu",
        "--out",
        str(out),
    ]
    for v in scene["videos"]:
        args += ["--video", v]
    return args + list(extra)


def test_track_color_end_to_end(scene, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(track_args(scene, out, "--keep-particles", "50")) == 0
    t = read_tracks(out / "tracks.csv")
    assert list(t)[:5] == ["frame", "id", "x", "y", "z"]
    assert list(t["frame"]) == list(range(6))
    est = np.column_stack([t["x"], t["y"], t["z"]])
    assert np.linalg.norm(est[-1] - BALL) < 0.03
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "complete" and run["frames"] == 6
    assert run["device"] == "cpu" and run["seed"] == 0
    assert run["config"]["tracker"]["particles"] == 300
    assert {"upload", "filter", "decode_wait"} <= set(run["timings"])
    assert run["versions"]["warp"] == wp.config.version
    p = np.load(out / "particles.npz")
    assert p["positions"].shape == (6, 50, 3)
    assert "tracked 6 frames" in capsys.readouterr().out


def test_same_seed_same_output(scene, tmp_path):
    for name in ("a", "b"):
        assert main(track_args(scene, tmp_path / name, "--seed", "7")) == 0
    assert (tmp_path / "a" / "tracks.csv").read_text() == (tmp_path / "b" / "tracks.csv").read_text()
    assert main(track_args(scene, tmp_path / "c", "--seed", "8")) == 0
    assert (tmp_path / "a" / "tracks.csv").read_text() != (tmp_path / "c" / "tracks.csv").read_text()


def test_init_random_uses_the_rig_volume(scene, tmp_path):
    out = tmp_path / "run"
    args = [a for a in track_args(scene, out) if a not in ("--init", "0.42", "0.45", "0.05")] + ["--init-random"]
    assert main(args) == 0
    run = json.loads((out / "run.json").read_text())
    lo, hi = Rig.load(scene["rig"]).bounds()
    np.testing.assert_allclose(np.reshape(run["config"]["tracker"]["init_box"], (2, 3)), [lo, hi])  # xyz min, max
    assert run["config"]["tracker"]["init"] is None
    assert len(read_tracks(out / "tracks.csv")["frame"]) == 6


def _bad_rig(scene, tmp_path):
    text = Path(scene["rig"]).read_text().replace("width: 96", "width: -96", 1)
    p = tmp_path / "bad_rig.yaml"
    p.write_text(text)
    return p


BAD_INPUTS = {
    "missing video": (lambda s, t: ["--video", str(t / "nope.avi"), "--video", s["videos"][1]], "nope.avi"),
    "unreadable video": (lambda s, t: ["--video", str(_garbage(t)), "--video", s["videos"][1]], "garbage.avi"),
    "rig bad field": (lambda s, t: ["--rig", str(_bad_rig(s, t))], "width"),
    "camera count": (lambda s, t: ["--video", s["videos"][0]], "camera"),
    "hue out of range": (lambda s, t: ["--hue", "300", "400"], "hue"),
    "sat out of range": (lambda s, t: ["--sat", "0.3", "1.5"], "sat"),
    "particles zero": (lambda s, t: ["--particles", "0"], "particles"),
    "particles negative": (lambda s, t: ["--particles", "-5"], "particles"),
    "sigma zero": (lambda s, t: ["--sigma", "0"], "sigma"),
    "sigma negative": (lambda s, t: ["--sigma", "-0.1"], "sigma"),
    "unknown resampling": (lambda s, t: ["--resampling", "bogus"], "resampling"),
    # the colour run ran and silently skipped the error report of a missing --groundtruth
    "missing groundtruth": (lambda s, t: ["--groundtruth", str(t / "nope.csv")], "nope.csv"),
    # a ground-plane table (the EPFL terrace's frame,id,x,y) was an internal error, KeyError 'z'
    "groundtruth without z": (lambda s, t: ["--groundtruth", str(_ground_plane_gt(t))], "frame,id,x,y,z"),
}


def _ground_plane_gt(tmp_path):
    p = tmp_path / "gt_xy.csv"
    p.write_text("frame,id,x,y\n0,0,0.42,0.45\n1,0,0.42,0.45\n")
    return p


def _garbage(tmp_path):
    p = tmp_path / "garbage.avi"
    p.write_bytes(b"this is not a video" * 100)
    return p


def _replace(args, extra):
    """Apply overrides: options given in `extra` replace those in `args` (``--video`` replaces all videos)."""
    out, i = [], 0
    keys = {e for e in extra if e.startswith("--")}
    while i < len(args):
        a = args[i]
        if a in keys:
            i += 1
            while i < len(args) and not args[i].startswith("--"):
                i += 1
            continue
        out.append(a)
        i += 1
    return out + extra


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_clear_error(scene, tmp_path, capsys, case):
    make, needle = BAD_INPUTS[case]
    out = tmp_path / "out"
    args = _replace(track_args(scene, out), make(scene, tmp_path))
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2, err
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("Warp CUDA warning")]
    assert len(lines) == 1 and lines[0].startswith("wptrack: error:"), err
    assert needle in lines[0]
    assert "Traceback" not in err
    assert not out.exists(), "nothing may be written for a bad input"


def test_output_not_writable(scene, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code = main(track_args(scene, blocker / "run"))
    err = capsys.readouterr().err
    assert code == 2 and "not writable" in err and "Traceback" not in err


@pytest.mark.skipif(bool(wp.get_cuda_devices()), reason="CUDA is available here")
def test_cuda_unavailable(scene, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(_replace(track_args(scene, out), ["--device", "cuda"]))
    err = capsys.readouterr().err
    assert code == 2 and "CUDA is not available" in err
    assert not out.exists()


def test_console_script_subprocess_exit_code(scene, tmp_path):
    """The installed entry point: a user mistake is one line and exit 2, no traceback."""
    out = tmp_path / "out"
    args = _replace(track_args(scene, out), ["--particles", "0"])
    r = subprocess.run([sys.executable, "-m", "wptrack.cli", *args], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert "wptrack: error: particles" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.skipif(bool(wp.get_cuda_devices()), reason="CUDA is available here")
def test_demo_without_cuda_fails_before_rendering(tmp_path, capsys):
    """Issue 30 item 6: `wptrack demo --device cuda` without a GPU rendered the scene (48 MB) and then failed."""
    out = tmp_path / "demo"
    assert main(["demo", "--device", "cuda", "--out", str(out), "-q"]) == 2
    captured = capsys.readouterr()
    assert "CUDA is not available" in captured.err and "rendering" not in captured.out
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "names"),
    [
        ([], ["demo", "synth", "track", "evaluate", "report", "batch", "bench"]),
        (["track"], ["color", "templates", "people"]),
    ],
)
def test_command_alone_prints_the_usage_with_the_list(argv, names):
    """Issue 30 item 12: `wptrack` and `wptrack track` alone printed one line without the commands / trackers."""
    r = subprocess.run([sys.executable, "-m", "wptrack.cli", *argv], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.startswith("usage: wptrack")
    for name in names:
        assert f"\n    {name} " in r.stderr or f"\n    {name}\n" in r.stderr, (name, r.stderr)
    assert r.stderr.strip().splitlines()[-1].startswith("wptrack: error: give a ")


def test_plural_and_convergence_words():
    """Issue 30 item 11: 'converges in 1 iterations', 'after the jump in not within the run', '1 objects'."""
    from wptrack.cli.commands import convergence_words
    from wptrack.cli.common import plural

    assert (plural(1, "object"), plural(2, "object"), plural(1, "person", "people")) == (
        "1 object",
        "2 objects",
        "1 person",
    )
    assert plural(0, "person", "people") == "0 people"
    text = convergence_words({"converge_initial": 1, "converge_after_jump": None}, 30)
    assert text == "converges in 1 iteration; after the jump, no convergence within the run"
    text = convergence_words({"converge_initial": None, "converge_after_jump": 4}, 30)
    assert text == "no convergence in 30 iterations; after the jump, in 4 iterations"


def test_convergence_output_reads_as_sentences(tmp_path, capsys):
    argv = ["convergence", "--sigma", "0.3", "--particles", "50", "--iterations", "8", "--jump-at", "4", "--runs", "1"]
    assert main([*argv, "--device", "cpu", "--out", str(tmp_path), "-q"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("sigma_m = "))
    assert "after the jump, " in line and "not within" not in line and ">" not in line and "1 iterations" not in line


def test_missing_groundtruth_is_named_as_ground_truth(scene, tmp_path, capsys):
    """Issue 30 item 14: `evaluate --groundtruth missing.csv` called the ground-truth file a 'tracks file'."""
    out = tmp_path / "run"
    assert main(track_args(scene, out)) == 0
    capsys.readouterr()
    assert main(["evaluate", str(out), "--groundtruth", str(tmp_path / "missing.csv")]) == 2
    err = capsys.readouterr().err
    assert f"ground truth file not found: {tmp_path / 'missing.csv'}" in err and "tracks file" not in err
    (tmp_path / "gt.csv").write_text("frame,id,x,y,z\n0,1,0.4,0.4,0.0\n")
    assert main(["evaluate", str(tmp_path / "nothing"), "--groundtruth", str(tmp_path / "gt.csv")]) == 2
    assert "tracks file not found" in capsys.readouterr().err


def test_no_convergence_line_names_the_criterion():
    """`wptrack demo --frames 20` printed 'did not converge (final error 0.2 cm)': converged at frame 14, but the
    criterion (below 5 cm for 10 frames) needs 10 frames; the line names the criterion."""
    from wptrack.cli.track import colour_summary_lines
    from wptrack.evaluation.convergence import summarize

    errors = [0.4] * 14 + [0.002] * 6
    summary = {"frames": 20, "device": "cpu", "score_mode": "direct", "error": summarize(errors).as_dict()}
    line = colour_summary_lines(summary, "out")[1]
    assert line.startswith("did not converge") and "5 cm for 10 frames" in line and "0.2 cm" in line, line
