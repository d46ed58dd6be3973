"""``wptrack batch --address`` that no Ray head answers: one clear line within seconds (exit 2, nothing written), not
Ray's connection retries (``--address bogus:1`` once waited minutes in GCS retries). No cluster is needed: the
addresses are a name that does not resolve, a closed port on this machine, and malformed ones."""

from __future__ import annotations

import socket
import time

import pytest

from wptrack.batch.address import check_address
from wptrack.cli import main
from wptrack.core.errors import ConfigError

pytest.importorskip("ray")


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _manifest(tmp_path) -> str:
    (tmp_path / "fn.py").write_text("def run(out_dir, n):\n    return {'frames': 1, 'n': n}\n")
    path = tmp_path / "batch.yaml"
    path.write_text("tracker: function\nfunction: fn.py:run\nruns:\n  - id: a\n    args: {n: 1}\n")
    return str(path)


@pytest.mark.parametrize(
    ("address", "needle"),
    [
        ("bogus:1", "--address bogus:1: "),  # the example: unknown here; wherever it resolves, port 1 is shut
        ("nohost.invalid:6379", "unknown host 'nohost.invalid'"),
        ("127.0.0.1:{port}", "no Ray head answers at 127.0.0.1:{port} within 5 s"),
        ("ray://127.0.0.1:{port}", "no Ray head answers at 127.0.0.1:{port} within 5 s"),
        ("127.0.0.1", "expected local, auto, inline, HOST:PORT or ray://HOST:PORT"),
        ("head:port", "expected local, auto, inline, HOST:PORT or ray://HOST:PORT"),
        ("http://head:6379", "expected local, auto, inline, HOST:PORT or ray://HOST:PORT"),
    ],
)
def test_unreachable_address_is_one_line_within_seconds(tmp_path, capsys, address, needle):
    port = _closed_port()
    address, needle = address.format(port=port), needle.format(port=port)
    out = tmp_path / "out"
    t0 = time.monotonic()
    code = main(["batch", _manifest(tmp_path), "--out", str(out), "--address", address, "-q"])
    elapsed = time.monotonic() - t0
    err = capsys.readouterr().err
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("Warp CUDA warning")]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("wptrack: error: --address"), err
    assert needle in lines[0] and "Traceback" not in err
    assert elapsed < 15.0, f"{elapsed:.1f} s"  # the check waits at most 5 s; Ray's retries took minutes
    assert not out.exists()


def test_auto_checks_the_address_ray_would_join(monkeypatch):
    """``auto`` with RAY_ADDRESS (or a recorded ``ray start``) pointing at a head that is gone: said as such."""
    port = _closed_port()
    monkeypatch.setenv("RAY_ADDRESS", f"127.0.0.1:{port}")
    with pytest.raises(
        ConfigError, match=rf"--address auto: no Ray head answers at \S+:{port} \(from --address auto\)"
    ):
        check_address("auto")


def test_a_head_that_does_not_answer_in_time(monkeypatch):
    """A connection that times out (a firewalled or unroutable host) is bounded by the timeout and says so."""
    asked = []

    def silent(where, timeout):
        asked.append(timeout)
        raise TimeoutError("timed out")

    monkeypatch.setattr(socket, "create_connection", silent)
    with pytest.raises(ConfigError, match=r"no Ray head answers at 127\.0\.0\.1:6379 within 0\.5 s \(no answer\)"):
        check_address("127.0.0.1:6379", timeout=0.5)
    assert asked == [0.5]


def test_local_and_inline_need_no_head(monkeypatch):
    monkeypatch.setattr(socket, "create_connection", lambda *a, **k: pytest.fail("no connection expected"))
    check_address("local")
    check_address("inline")


def test_a_listening_port_passes(monkeypatch):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        check_address(f"127.0.0.1:{s.getsockname()[1]}", timeout=2.0)


def test_convergence_sweep_checks_the_address_before_its_folder(tmp_path, capsys):
    out = tmp_path / "sweep"
    address = f"127.0.0.1:{_closed_port()}"
    code = main(["convergence", "--out", str(out), "--address", address, "--runs", "1", "--steps", "2", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith(f"wptrack: error: --address {address}: no Ray head answers"), err
    assert not out.exists()
