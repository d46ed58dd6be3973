"""The run loop shared by every tracker (wptrack.runs.loop): outputs, timings, interruption by SIGINT/SIGTERM,
failures, and the extra writers of a job always closed."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from wptrack.io.tables import read_tracks
from wptrack.runs import RunInterrupted, TrackerRun, run_tracker


@dataclass
class _Est:
    frame: int
    value: float
    timings: dict = field(default_factory=dict)


class _Job(TrackerRun):
    """A job over a list of numbers; optionally raises at a frame."""

    name = "fake"
    columns = ["frame", "id", "x", "y", "z", "v"]

    def __init__(self, values, raise_at=None, exc=None):
        self.values = list(values)
        self.total = len(self.values)
        self.config = {"values": len(self.values)}
        self.raise_at, self.exc = raise_at, exc
        self.started = self.finished = False
        self.k = 0

    def info(self):
        return {"device": "none", "seed": 7}

    def frames(self):
        return iter(self.values)

    def start(self, out_dir, resume_after=None):
        self.started = True
        (out_dir / "extra.txt").write_text("")

    def step(self, item):
        if self.k == self.raise_at:
            raise self.exc
        est = _Est(self.k, float(item), {"work": 0.001})
        self.k += 1
        return est

    def record(self, est, out):
        if est.frame % 2 == 0:  # odd frames write no rows: last_frame must still advance
            out.add_rows([[est.frame, 0, est.value, 0.0, 0.0, 2 * est.value]])

    def finish(self):
        self.finished = True

    def state_dict(self):
        return {"job.k": np.int64(self.k)}

    def load_state_dict(self, state):
        self.k = int(state["job.k"])

    def summary(self):
        return {"frames": self.k}


def test_run_writes_rows_timings_and_summary(tmp_path):
    job = _Job(range(5))
    summary = run_tracker(job, tmp_path / "run")
    assert summary == {"frames": 5}
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["status"] == "complete" and run["tracker"] == "fake" and run["seed"] == 7
    assert run["last_frame"] == 4 and run["frames"] == 3  # frames with rows: 0, 2, 4
    assert run["timings"]["work"]["count"] == 5 and run["timings"]["decode_wait"]["count"] == 5
    t = read_tracks(tmp_path / "run" / "tracks.csv")
    assert list(t["frame"]) == [0, 2, 4] and list(t["v"]) == [0.0, 4.0, 8.0]
    assert job.started and job.finished


def test_max_frames_stops_early(tmp_path):
    job = _Job(range(10))
    run_tracker(job, tmp_path, max_frames=3)
    assert job.k == 3
    assert json.loads((tmp_path / "run.json").read_text())["last_frame"] == 2


@pytest.mark.parametrize(
    ("exc", "status"),
    [
        (KeyboardInterrupt(), "interrupted"),
        (RunInterrupted(signal.SIGTERM), "interrupted"),
        (RuntimeError("x"), "failed"),
    ],
)
def test_interrupted_or_failed_run_keeps_valid_outputs(tmp_path, exc, status):
    job = _Job(range(10), raise_at=4, exc=exc)
    with pytest.raises(type(exc)):
        run_tracker(job, tmp_path)
    run = json.loads((tmp_path / "run.json").read_text())
    assert run["status"] == status and run["last_frame"] == 3
    assert list(read_tracks(tmp_path / "tracks.csv")["frame"]) == [0, 2]
    assert job.finished  # the job's extra writers were closed


def test_run_interrupted_exit_code():
    assert RunInterrupted(signal.SIGTERM).exit_code == 128 + signal.SIGTERM
    assert isinstance(RunInterrupted(signal.SIGTERM), KeyboardInterrupt)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_sigterm_mid_run_marks_run_interrupted(tmp_path):
    """A real SIGTERM to a process in the middle of a run: exit code 143, run.json 'interrupted', rows valid."""
    ready = tmp_path / "ready"
    code = textwrap.dedent(
        f"""
        import sys, time
        from pathlib import Path
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from test_runs import _Job
        from wptrack.runs import RunInterrupted, run_tracker

        class Slow(_Job):
            def step(self, item):
                if self.k == 3:
                    Path({str(ready)!r}).write_text("go")
                time.sleep(0.05)
                return super().step(item)

        try:
            run_tracker(Slow(range(100000)), {str(tmp_path / "run")!r})
        except RunInterrupted as e:
            sys.exit(e.exit_code)
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", code], env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        import time

        deadline = time.monotonic() + 60
        while not ready.exists():
            assert time.monotonic() < deadline and proc.poll() is None, "the run did not start"
            time.sleep(0.02)
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert rc == 128 + signal.SIGTERM
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["status"] == "interrupted" and run["last_frame"] >= 2  # frame 3 was being tracked
    frames = read_tracks(tmp_path / "run" / "tracks.csv")["frame"]
    assert frames[-1] <= run["last_frame"] and list(frames) == list(range(0, frames[-1] + 1, 2))


def test_existing_run_folder_is_refused_without_overwrite(tmp_path):
    """Issue 30 item 4: a second run into a run folder was written over the first, keeping its stale files (an old
    report and masks.avi beside the new run.json). Now it is refused; --overwrite removes what the run wrote."""
    from wptrack.core.errors import ConfigError

    out = tmp_path / "run"
    run_tracker(_Job(range(6)), out)
    (out / "masks.avi").write_bytes(b"old masks")
    (out / "report").mkdir()
    (out / "report" / "index.html").write_text("200 particles")
    (out / "my-notes.txt").write_text("kept")
    before = (out / "run.json").read_bytes()
    with pytest.raises(ConfigError, match="holds a previous run.*--overwrite"):
        run_tracker(_Job(range(2)), out)
    assert (out / "run.json").read_bytes() == before and (out / "masks.avi").exists()
    run_tracker(_Job(range(2)), out, overwrite=True)
    assert json.loads((out / "run.json").read_text())["last_frame"] == 1
    assert not (out / "masks.avi").exists() and not (out / "report").exists()
    assert (out / "my-notes.txt").read_text() == "kept" and (out / "extra.txt").exists()  # the new run's own
    with pytest.raises(ConfigError, match="give one of them"):
        run_tracker(_Job(range(2)), out, overwrite=True, resume=True)


_LOCK_HOLDER = """
import sys, time
from pathlib import Path
sys.path.insert(0, {tests!r})
from test_runs import _Job
from wptrack.runs import RunInterrupted, run_tracker

class Slow(_Job):
    def step(self, item):
        if self.k == 1:
            Path({ready!r}).write_text("go")
        time.sleep(0.05)
        return super().step(item)

try:
    run_tracker(Slow(range(100000)), {out!r})
except RunInterrupted as e:
    sys.exit(e.exit_code)
"""


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_run_folder_in_use_is_locked(tmp_path):
    """Issue 30 item 22: two runs into one --out both ran and reported success. The second now refuses, naming
    the first's pid; the lock goes with the run that held it."""
    from wptrack.core.errors import ConfigError
    from wptrack.io.rundir import LOCK_FILE

    out, ready = tmp_path / "run", tmp_path / "ready"
    code = _LOCK_HOLDER.format(tests=str(Path(__file__).parent), ready=str(ready), out=str(out))
    proc = subprocess.Popen([sys.executable, "-c", code], env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        import time

        deadline = time.monotonic() + 60
        while not ready.exists():
            assert time.monotonic() < deadline and proc.poll() is None, "the run did not start"
            time.sleep(0.02)
        lock = json.loads((out / LOCK_FILE).read_text())
        assert lock["pid"] == proc.pid and lock["host"] and lock["started"]
        for kw in ({}, {"overwrite": True}, {"resume": True}):
            with pytest.raises(ConfigError, match=f"in use by another wptrack run \\(pid {proc.pid} on "):
                run_tracker(_Job(range(3)), out, **kw)
        assert json.loads((out / "run.json").read_text())["status"] == "running"  # the first run is untouched
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=60) == 128 + signal.SIGTERM
    finally:
        if proc.poll() is None:
            proc.kill()
    assert not (out / LOCK_FILE).exists()


def test_a_stale_lock_is_taken_over(tmp_path, caplog):
    """A lock left by a dead process of this host (SIGKILL, crash) is taken over with a warning; one of another
    host (which cannot be checked) is refused."""
    import socket

    from wptrack.core.errors import ConfigError
    from wptrack.io.rundir import LOCK_FILE

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)
    out = tmp_path / "run"
    out.mkdir()
    (out / LOCK_FILE).write_text(json.dumps({"pid": pid, "host": socket.gethostname(), "started": "earlier"}))
    with caplog.at_level("WARNING", logger="wptrack.runs.loop"):
        run_tracker(_Job(range(3)), out)
    assert f"stale lock of process {pid}" in caplog.text and not (out / LOCK_FILE).exists()
    (out / LOCK_FILE).write_text(json.dumps({"pid": os.getpid(), "host": "elsewhere.example", "started": "x"}))
    with pytest.raises(ConfigError, match="elsewhere.example"):
        run_tracker(_Job(range(3)), out, overwrite=True)
