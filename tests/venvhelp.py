"""Making a throw-away venv for the tests (standard library only: it also runs inside a bare venv)."""

from __future__ import annotations

import os
import site
import subprocess
import sys
from pathlib import Path


def clean_env() -> dict[str, str]:
    """The caller's environment without anything that would put a checkout on the import path."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}
    env["PYTHONNOUSERSITE"] = "1"
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


def make_venv(venv: Path, cwd: Path, env: dict[str, str]) -> Path:
    """A venv without pip that sees the packages of the Python running this; returns its interpreter.

    ``--system-site-packages`` shows the *base* Python's site-packages: from inside a virtualenv (the README's
    set-up, and CI's) that is not where Warp, NumPy and pip are (``No module named 'warp'``). So when the caller
    runs in a venv (``sys.prefix != sys.base_prefix``), its own site-packages are added to the new venv by a
    ``.pth`` file (``site.addsitedir``, which also runs the ``.pth`` files found there), after the new venv's own
    site-packages: what is installed into the new venv still comes first.
    """

    def run(cmd: list[str]) -> str:
        r = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=120)
        if r.returncode != 0:
            raise RuntimeError(f"{cmd} exited {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")
        return r.stdout

    run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", str(venv)])
    py = venv / "bin" / "python"
    if sys.prefix != sys.base_prefix:
        purelib = run([str(py), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"]).strip()
        dirs = [d for d in site.getsitepackages() if Path(d).is_dir()]
        lines = "".join(f"import site; site.addsitedir({d!r})\n" for d in dirs)
        (Path(purelib) / "_wptrack_test_caller_site.pth").write_text(lines)
    return py
