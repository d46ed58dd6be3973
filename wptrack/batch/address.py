"""The Ray address of ``wptrack batch --address`` (and ``wptrack convergence --address``), checked before Ray is
started or joined: a head that does not answer is one clear error within seconds, not Ray's connection retries
(``--address bogus:1`` once waited minutes in GCS retries before any message)."""

from __future__ import annotations

import socket

from wptrack.core.errors import ConfigError

__all__ = ["ADDRESS_TIMEOUT_S", "check_address", "check_ray_address"]

ADDRESS_TIMEOUT_S = 5.0
"""How long ``wptrack batch --address HOST:PORT`` waits for the Ray head to answer before saying it does not."""

_ADDRESS_FORMS = "local, auto, inline, HOST:PORT or ray://HOST:PORT"


def check_address(address: str, timeout: float = ADDRESS_TIMEOUT_S) -> None:
    """Before ``ray.init``: the Ray head of ``address`` answers, so a wrong address is one clear error within
    ``timeout`` seconds, not Ray's connection retries (minutes, with GCS warnings). ``local`` and ``inline`` need
    nothing; ``auto`` is checked at the address Ray would join (``RAY_ADDRESS`` or the last ``ray start`` on this
    machine); ``HOST:PORT`` and ``ray://HOST:PORT`` at that host and port (a TCP connection: a port that accepts
    connections but is not a Ray head is still left to Ray).

    Raises:
        ConfigError: the address is malformed, its host unknown, nothing answers there in time, or ``auto`` finds
            no cluster.
    """
    if address in ("local", "inline"):
        return
    target = address
    if address == "auto":
        try:
            from ray._private.services import canonicalize_bootstrap_address
        except ImportError:  # a Ray without it: Ray's own error (it says it quickly when nothing runs)
            return
        try:
            target = canonicalize_bootstrap_address("auto")
        except ConnectionError:
            raise ConfigError(
                "--address auto: no running Ray cluster found on this machine (start one with `ray start --head`, "
                "give its HOST:PORT, or use --address local)"
            ) from None
        except Exception:  # noqa: BLE001 - a private helper of Ray: if it changed, Ray's own behaviour applies
            return
        if not target:
            return
    head = target.split("://", 1)[1] if target.startswith("ray://") else target
    host, sep, port = head.rpartition(":")
    host = host.strip("[]")  # [IPv6]:PORT
    if "://" in head or not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"--address {address}: expected {_ADDRESS_FORMS}")
    where = f"{host}:{port}" + (f" (from --address {address})" if target != address else "")
    try:
        socket.getaddrinfo(host, int(port), type=socket.SOCK_STREAM)
    except OSError as e:
        raise ConfigError(
            f"--address {address}: unknown host {host!r} ({e.strerror or e}); expected {_ADDRESS_FORMS}"
        ) from None
    try:
        socket.create_connection((host, int(port)), timeout=timeout).close()
    except OSError as e:
        why = "no answer" if isinstance(e, TimeoutError) else (e.strerror or str(e)).lower()
        raise ConfigError(
            f"--address {address}: no Ray head answers at {where} within {timeout:g} s ({why}); start it with "
            "`ray start --head` on that machine or check the host and port"
        ) from None


def check_ray_address(address: str) -> None:
    """:func:`check_address` for a batch about to start or join Ray at ``address``: nothing when this process joined
    Ray before (that instance is used as it is) or Ray is not installed (:func:`run_batch` says so)."""
    import importlib.util

    if address == "inline" or importlib.util.find_spec("ray") is None:
        return
    import ray

    if not ray.is_initialized():
        check_address(address)
