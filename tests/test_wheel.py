"""What a user gets from ``pip install wptrack``: build the wheel, install it (not editable) into a fresh venv and run
``wptrack bench`` from a folder outside the checkout.

The venv sees the system site-packages (Warp, NumPy, OpenCV without downloads), where a development install of
wptrack may also live (an editable finder appended to ``sys.meta_path``): the test asserts that ``wptrack``,
``wptrack.kernels`` and ``wptrack.bench`` are imported from the venv's own site-packages, so the wheel is what runs.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from venvhelp import clean_env as _env  # noqa: E402
from venvhelp import make_venv  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
# build outputs, caches and run folders of a working checkout stay out of the copy the wheel is built from (a stale
# build/lib would otherwise leak removed modules into the wheel)
TOP_IGNORE = {".git", "build", "dist", "out", "runs", ".gpu", ".whl", ".warpcache", ".venv", "venv"}
ANY_IGNORE = shutil.ignore_patterns("__pycache__", "*.egg-info", ".pytest_cache", ".ruff_cache", "*.whl")


def _ignore(folder: str, names: list[str]) -> set[str]:
    top = TOP_IGNORE & set(names) if Path(folder).resolve() == REPO else set()
    return top | set(ANY_IGNORE(folder, names))


def _run(cmd: list[str], cwd: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    r = subprocess.run(cmd, cwd=cwd, env=_env(), capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, f"{cmd} exited {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    return r


def test_test_venv_sees_the_callers_packages(tmp_path):
    """make_venv run from inside a venv (as the README's `python3 -m venv` set-up and CI do): a module installed
    only in that outer venv is importable in the venv it makes (plain --system-site-packages shows the base
    Python's packages instead: 'No module named warp' in a venv whose base Python has no Warp)."""
    outer = tmp_path / "outer"
    _run([sys.executable, "-m", "venv", "--without-pip", str(outer)], tmp_path)
    outer_py = outer / "bin" / "python"
    purelib = _run([str(outer_py), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], tmp_path)
    (Path(purelib.stdout.strip()) / "only_in_outer_venv.py").write_text("WHERE = 'outer'\n")
    inner = tmp_path / "inner"
    code = (
        f"import sys, pathlib; sys.path.insert(0, {str(Path(__file__).parent)!r}); import venvhelp; "
        f"venvhelp.make_venv(pathlib.Path({str(inner)!r}), pathlib.Path('.'), venvhelp.clean_env())"
    )
    _run([str(outer_py), "-c", code], tmp_path)
    probe = [str(inner / "bin" / "python"), "-c", "import only_in_outer_venv as m; print(m.WHERE)"]
    assert _run(probe, tmp_path).stdout.strip() == "outer"
    # the bug it fixes: plain --system-site-packages from inside the outer venv shows the base Python's packages
    plain = tmp_path / "plain"
    _run([str(outer_py), "-m", "venv", "--system-site-packages", "--without-pip", str(plain)], tmp_path)
    probe[0] = str(plain / "bin" / "python")
    r = subprocess.run(probe, cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "No module named 'only_in_outer_venv'" in r.stderr


@pytest.mark.slow
def test_wheel_installs_and_runs_bench(tmp_path):
    src, wheels, venv, work = (tmp_path / d for d in ("src", "wheels", "venv", "work"))
    shutil.copytree(REPO, src, ignore=_ignore, symlinks=True)
    work.mkdir()
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(wheels), "."], src)
    (wheel,) = wheels.glob("wptrack-*.whl")
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
    assert {n.split("/")[0] for n in names} == {"wptrack", wheel.name.split("-py")[0] + ".dist-info"}, names
    for mod in ("wptrack/bench/__init__.py", "wptrack/bench/colour.py", "wptrack/bench/numpy_colour.py"):
        assert mod in names
    assert "wptrack/kernels/colour/hsi.py" in names

    # a venv without its own pip: the caller's pip (seen through the caller's site-packages) installs into it
    py = make_venv(venv, work, _env())
    _run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", "--force-reinstall", str(wheel)], work)

    probe = (
        "import importlib.util, json, wptrack, wptrack.kernels, wptrack.bench; "
        "print(json.dumps({'files': [wptrack.__file__, wptrack.kernels.__file__, wptrack.bench.__file__], "
        "'top_level': [m for m in ('kernels', 'benchmarks') if importlib.util.find_spec(m)]}))"
    )
    got = json.loads(_run([str(py), "-c", probe], work).stdout)
    site = venv.resolve()
    for f in got["files"]:
        assert Path(f).resolve().is_relative_to(site), f"{f} is not the installed wheel (venv {site})"
    assert got["top_level"] == []

    out = work / "bench.json"
    argv = ["bench", "-q", "--tracker", "color", "--device", "cpu", "--particles", "1000", "--cameras", "1"]
    r = _run([str(venv / "bin" / "wptrack"), *argv, "--frames", "2", "--out", str(out)], work, timeout=300)
    assert "frame ms" in r.stdout and "numpy ms" in r.stdout, r.stdout
    doc = json.loads(out.read_text())
    (res,) = doc["results"]
    assert (res["particles"], res["cameras"], res["device"]) == (1000, 1, "cpu")
    assert res["equivalent"] is True and res["frame_ms"] > 0 and res["numpy_ms"] > 0
