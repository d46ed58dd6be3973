"""Seen when tried as a new user would: no CUDA noise on a CPU run, readable report files (umask mode, not
mkstemp's 0600), tracebacks only with --debug."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import warp as wp

from wptrack.cameras.rig import Camera, Rig
from wptrack.io.atomic import atomic_imwrite, atomic_save_npz, atomic_write_json, atomic_write_text, default_file_mode

ROOT = Path(__file__).resolve().parents[1]


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}


@pytest.mark.parametrize("spec", ["cpu", "auto"])
def test_no_cuda_noise_on_a_cpu_run(spec):
    """Warp's native 'Could not find or load the NVIDIA CUDA driver' line is kept off stderr; the device choice is
    logged (with -v) once, with the reason."""
    code = (
        "import logging, sys;"
        "logging.basicConfig(level=logging.INFO, stream=sys.stdout, format='%(levelname)s %(name)s: %(message)s');"
        "from wptrack.core.device import resolve_device;"
        f"print('RESOLVED', resolve_device({spec!r})); resolve_device({spec!r})"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=_env())
    assert r.returncode == 0, r.stderr
    assert "CUDA" not in r.stderr and "Could not find" not in r.stderr, r.stderr
    resolved = r.stdout.split("RESOLVED ")[1].split()[0]
    if spec == "cpu" or not wp.get_cuda_devices():
        assert resolved == "cpu"
    assert r.stdout.count("INFO wptrack.core.device: device ") == 1, r.stdout  # said once, with why: "(...)"
    assert "(" in r.stdout.split("INFO wptrack.core.device: device ")[1]


def test_atomic_writes_use_the_umask_mode(tmp_path):
    old = os.umask(0o022)
    try:
        assert default_file_mode() == 0o644
        atomic_write_text(tmp_path / "index.html", "<html></html>")
        atomic_write_json(tmp_path / "run.json", {"a": 1})
        atomic_save_npz(tmp_path / "p.npz", a=[1, 2])
        atomic_imwrite(tmp_path / "fig.png", np.full((4, 5, 3), 9, np.uint8))
        Rig((Camera.look_at("c", 32, 24, (1, 0, 1), (0, 0, 0), 60.0),)).save(tmp_path / "rig.yaml")
        assert cv2.imread(str(tmp_path / "fig.png")).shape == (4, 5, 3)
        assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png", "index.html", "p.npz", "rig.yaml", "run.json"]
        for name in ("index.html", "run.json", "p.npz", "rig.yaml", "fig.png"):
            assert (tmp_path / name).stat().st_mode & 0o777 == 0o644, name
        os.umask(0o077)
        atomic_write_text(tmp_path / "private.txt", "x")
        assert (tmp_path / "private.txt").stat().st_mode & 0o777 == 0o600
    finally:
        os.umask(old)


@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_shows_the_traceback(tmp_path, where):
    args = ["track", "color", "--rig", str(tmp_path / "nope.yaml"), "--video", "x", "--hue", "1", "2", "--sat", "0",
            "1", "--init", "0", "0", "0", "--out", str(tmp_path / "out")]  # fmt: skip
    plain = subprocess.run([sys.executable, "-m", "wptrack.cli", *args], capture_output=True, text=True, env=_env())
    assert plain.returncode == 2 and "Traceback" not in plain.stderr
    assert plain.stderr.strip().splitlines() == [f"wptrack: error: {tmp_path / 'nope.yaml'}: rig file not found"]
    dbg = ["--debug", *args] if where == "before" else [*args[:2], "--debug", *args[2:]]
    debug = subprocess.run([sys.executable, "-m", "wptrack.cli", *dbg], capture_output=True, text=True, env=_env())
    assert debug.returncode == 2 and "Traceback" in debug.stderr and "RigError" in debug.stderr
    assert debug.stderr.strip().splitlines()[-1].startswith("wptrack: error:")


KERNEL_MODULE = """
import warp as wp


@wp.kernel
def twice(a: wp.array(dtype=float), b: wp.array(dtype=float)):
    i = wp.tid()
    b[i] = 2.0 * a[i]
"""


def test_warm_up_says_compiling_only_on_a_cache_miss(tmp_path):
    """The first run compiles (and says so, naming the cache), the second finds the cache and says nothing; the
    kernels then launch without compiling again."""
    (tmp_path / "tinykern.py").write_text(KERNEL_MODULE)
    code = (
        "import sys, numpy as np, warp as wp, tinykern;"
        "from wptrack.core.device import warm_up;"
        "print('MISSING', warm_up([tinykern], 'cpu', say=lambda m: print('SAY', m)));"
        "a = wp.array(np.arange(3, dtype=np.float32)); b = wp.zeros(3);"
        "wp.launch(tinykern.twice, dim=3, inputs=[a], outputs=[b]); print('OUT', b.numpy().tolist())"
    )
    env = {**_env(), "WARP_CACHE_PATH": str(tmp_path / "cache")}
    env["PYTHONPATH"] = str(tmp_path) + os.pathsep + env["PYTHONPATH"]
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env) for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr
        assert "OUT [0.0, 2.0, 4.0]" in r.stdout
    assert "MISSING ['tinykern']" in runs[0].stdout
    assert f"SAY compiling kernels (first run only; cache: {tmp_path / 'cache'}" in runs[0].stdout
    assert "MISSING []" in runs[1].stdout and "SAY" not in runs[1].stdout


def _readme() -> str:
    return (ROOT / "README.md").read_text(encoding="utf-8")


def _code_block_after(text: str, marker: str, lang: str = "bash") -> list[str]:
    """The lines of the first fenced ``lang`` block after ``marker`` in ``text``."""
    rest = text[text.index(marker) :]
    start = rest.index(f"```{lang}\n") + len(f"```{lang}\n")
    return rest[start : rest.index("```", start)].splitlines()


def test_ci_runs_the_readme_test_commands_in_a_fresh_venv():
    """Issue 30 item 1: CI runs exactly the README's test commands, and those make a fresh virtualenv first (a
    test that only works in the system Python is caught)."""
    readme = _code_block_after(_readme(), "exactly what `.ci/run` runs")
    ci = (ROOT / ".ci" / "run").read_text().split("# --- the README's test commands (keep the two identical) ---\n")
    assert len(ci) == 2
    assert [line for line in ci[1].splitlines() if line.strip()] == readme
    assert readme[0].startswith("python3 -m venv ") and ". .venv/bin/activate" in readme[0]
    assert readme[-1] == 'python3 -m pip install -q -e ".[dev,ray]" && python3 -m pytest -q'
    assert "rm -rf .venv" in ci[0]  # fresh every run


@pytest.mark.parametrize("path", ["wptrack-demo/track/run.json", "examples/lab/cam1.avi", "lab-batch/summary.csv"])
def test_readme_outputs_are_ignored_by_git(path):
    """Issue 30 item 16: `wptrack demo` in a checkout left wptrack-demo/ untracked (and the README's batch example
    examples/lab/ and lab-batch/)."""
    import shutil

    if not (ROOT / ".git").exists() or shutil.which("git") is None:
        pytest.skip("not a git checkout")
    r = subprocess.run(["git", "check-ignore", "-q", path], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, f"{path} is not ignored: {r.stderr}"


def test_readme_says_which_commands_take_a_device():
    """Issue 30 item 17: the README said every command takes a device (synth, report, evaluate, batch do not)."""
    import argparse
    import re

    from wptrack.cli import build_parser

    readme = _readme()
    assert "Every command" not in readme
    line = readme[readme.index("Commands that take a device:") :].split("--device auto")[0]
    said = set(re.findall(r"`([a-z]+)`", line)) - {"sweep"}
    parser = build_parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    have = set()
    for name, sub in subs.choices.items():
        opts = {o for a in sub._actions for o in a.option_strings}
        nested = [a for a in sub._actions if isinstance(a, argparse._SubParsersAction)]
        if nested:
            opts |= {o for p in nested[0].choices.values() for a in p._actions for o in a.option_strings}
        if "--device" in opts and name != "sweep":
            have.add(name)
    assert said == have


def test_readme_lists_the_colour_tracks_columns():
    """Issue 30 item 17: the colour tracker's columns `detection` and `degenerate` were not listed."""
    from wptrack.trackers.colour.run import COLOR_TRACK_COLUMNS

    readme = _readme()
    listed = readme[readme.index("- `tracks.csv`: `frame,id,x,y,z,") :].split("`")[3]
    assert listed.split(",") == list(COLOR_TRACK_COLUMNS)
    for name in ("detection", "degenerate"):
        assert f"`{name}` (" in readme


def test_truncated_video_shows_no_ffmpeg_lines(tmp_path):
    """Issue 30 item 20: a truncated video showed FFmpeg's raw '[ffv1 @ 0x...] Slice pointer chain broken' beside
    wptrack's own message; with -v they are shown."""
    from wptrack.io.video import write_video

    rng = np.random.default_rng(0)
    write_video(tmp_path / "full.avi", [rng.integers(0, 255, (96, 128, 3), dtype=np.uint8) for _ in range(10)], fps=10)
    data = (tmp_path / "full.avi").read_bytes()
    (tmp_path / "cut.avi").write_bytes(data[: int(len(data) * 0.6)])
    env = {k: v for k, v in _env().items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    argv = [sys.executable, "-m", "wptrack.cli", "masks", "--video", str(tmp_path / "cut.avi"), "--device", "cpu"]
    quiet = subprocess.run([*argv, "--out", str(tmp_path / "a"), "-q"], capture_output=True, text=True, env=env)
    assert quiet.returncode == 0, quiet.stderr
    assert "ended after" in quiet.stderr  # wptrack's own line
    assert "@ 0x" not in quiet.stderr and "[ffv1" not in quiet.stderr, quiet.stderr
    loud = subprocess.run([*argv, "--out", str(tmp_path / "b"), "-v"], capture_output=True, text=True, env=env)
    assert "[ffv1" in loud.stderr or "FFMPEG" in loud.stderr.upper()  # the same file does make FFmpeg talk
