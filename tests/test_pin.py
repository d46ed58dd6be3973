"""Behaviour pin: fixed-seed runs of every tracker give the ``tracks.csv`` stored in ``tests/data/pin/`` byte for
byte (``tests/pin_runs.py`` lists the cases and regenerates the files after a deliberate change)."""

from __future__ import annotations

from pathlib import Path

import pytest
from pin_runs import CASES, PIN_DIR, run_case, shared_data  # tests/ is on sys.path


@pytest.fixture(scope="module")
def scenes() -> dict[str, Path]:
    return {}


@pytest.mark.parametrize("case", sorted(CASES))
def test_tracks_csv_is_pinned(case, scenes, tmp_path_factory):
    if CASES[case][0] is None and shared_data("pets09-s2l1-view001-dev") is None:
        pytest.skip("PETS 2009 development clip not present in ../shared/data")
    work = tmp_path_factory.getbasetemp() / "pin"
    work.mkdir(exist_ok=True)
    tracks = run_case(case, work, scenes)
    expected = (PIN_DIR / f"{case}.csv").read_bytes()
    got = tracks.read_bytes()
    if got != expected:
        old, new = expected.decode().splitlines(), got.decode().splitlines()
        pairs = zip(old + ["<end>"], new + ["<end>"], strict=False)
        line, (a, b) = next((i, ab) for i, ab in enumerate(pairs) if ab[0] != ab[1])
        pytest.fail(
            f"{case}: tracks.csv differs from tests/data/pin/{case}.csv ({len(new)} vs {len(old)} lines); first "
            f"difference at line {line + 1}:\n  pinned: {a}\n  now:    {b}"
        )
