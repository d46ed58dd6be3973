"""Issue 32: the multi-node set-up, as far as one machine allows: a Ray head started with ``ray start --head`` on
localhost (its own ports and temp folder), then ``wptrack batch --address auto`` joins it from another process and
the runs go to workers of that cluster, which write into the batch folder the command named (a relative ``--out``
once went to the workers' own folder). Skipped where Ray cannot start a head here (no ``ray`` command, or the head
does not come up in time)."""

from __future__ import annotations

import csv
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]

RUN = """\
import os


def run(out_dir, n):
    return {"frames": 1, "pid": os.getpid(), "n": n}
"""


def _free_ports(n: int) -> list[int]:
    socks = [socket.socket() for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def _stop(head: subprocess.Popen) -> None:
    """Stop the head we started (SIGTERM: `ray start --block` stops the processes it started), by its pid."""
    if head.poll() is None:
        head.send_signal(signal.SIGTERM)
        try:
            head.wait(timeout=30)
        except subprocess.TimeoutExpired:
            head.kill()
            head.wait(timeout=10)


def test_batch_joins_a_cluster_started_with_ray_start(tmp_path):
    pytest.importorskip("ray")
    ray_cmd = shutil.which("ray")
    if ray_cmd is None:
        pytest.skip("no 'ray' command")
    temp = tempfile.mkdtemp(prefix="rt", dir="/tmp")  # short: Ray's socket paths are limited to ~100 characters
    gcs, agent, grpc, env_agent, metrics = _free_ports(5)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    env.pop("RAY_ADDRESS", None)
    env.setdefault("RAY_AUTH_MODE", "token")  # the head and the batch both use Ray's token (~/.ray/auth_token)
    log = open(tmp_path / "head.log", "wb")  # noqa: SIM115 - closed in finally
    head = subprocess.Popen(
        [ray_cmd, "start", "--head", "--block", "--node-ip-address", "127.0.0.1", "--port", str(gcs),
         "--num-cpus", "2", "--num-gpus", "0",
         "--include-dashboard", "false", "--disable-usage-stats", "--temp-dir", temp,
         "--dashboard-agent-listen-port", str(agent), "--dashboard-agent-grpc-port", str(grpc),
         "--runtime-env-agent-port", str(env_agent), "--metrics-export-port", str(metrics)],
        env=env, stdout=subprocess.DEVNULL, stderr=log, start_new_session=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 90
        while not (Path(temp) / "ray_current_cluster").exists():
            if head.poll() is not None or time.monotonic() > deadline:
                why = (
                    (tmp_path / "head.log").read_text(errors="replace")[-300:] if head.poll() is not None else "timeout"
                )
                pytest.skip(f"ray start --head did not come up here: {why}")
            time.sleep(0.5)
        (tmp_path / "job.py").write_text(RUN)
        (tmp_path / "runs.yaml").write_text(
            "tracker: function\nfunction: job.py:run\nruns:\n  - id: 'r{n}'\n    grid: {n: [0, 1, 2]}\n"
        )
        argv = [sys.executable, "-m", "wptrack.cli", "batch", "runs.yaml", "--out", "out", "--address", "auto"]
        client_env = {**env, "RAY_ADDRESS": f"127.0.0.1:{gcs}"}  # what `--address auto` finds (else /tmp/ray)
        done = subprocess.run(argv, cwd=tmp_path, env=client_env, capture_output=True, text=True, timeout=180)
        assert done.returncode == 0, done.stderr[-2000:]
        assert "3/3 runs complete" in done.stdout
        with open(tmp_path / "out" / "summary.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        assert [r["status"] for r in rows] == ["complete"] * 3
        assert all(int(r["pid"]) not in (os.getpid(), head.pid) for r in rows)  # in the cluster's workers
        # the workers run elsewhere (the head's folder): `--out out` is the driver's, made absolute before them
        assert all((tmp_path / "out" / f"r{n}" / "batch.json").exists() for n in range(3))
    finally:
        _stop(head)
        log.close()
        shutil.rmtree(temp, ignore_errors=True)
