"""Shared pytest fixtures: a ``device`` fixture over every available Warp device (CPU always, CUDA when
present). ``--device cpu`` or ``WPTRACK_TEST_DEVICES=cpu,cuda:0`` restricts the list."""

from __future__ import annotations

import os

import numpy as np
import pytest
import warp as wp

wp.config.quiet = True
wp.config.log_level = wp.LOG_WARNING
wp.init()


def pytest_addoption(parser):
    parser.addoption("--device", action="append", default=None, help="Warp device(s) to test (default: all)")


def _devices(config) -> list[str]:
    chosen = config.getoption("--device") or []
    env = os.environ.get("WPTRACK_TEST_DEVICES")
    if env:
        chosen += [d.strip() for d in env.split(",") if d.strip()]
    available = [d.alias for d in wp.get_devices()]
    if not chosen:
        return available
    missing = [d for d in chosen if d not in available]
    if missing:
        raise pytest.UsageError(f"requested device(s) {missing} not available (have {available})")
    return chosen


def pytest_generate_tests(metafunc):
    if "device" in metafunc.fixturenames:
        metafunc.parametrize("device", _devices(metafunc.config))


@pytest.fixture
def rng(request) -> np.random.Generator:
    """A fresh seeded generator per test (seed derived from the test's name, so it is stable)."""
    import zlib

    return np.random.default_rng(zlib.crc32(request.node.nodeid.encode()))
