"""``track color --proposal``: the detection column of tracks.csv, 'no detection' frames (colour ranges matching
nothing) marked without NaN, and ``--proposal prior`` giving the paper's filter (detection = -1)."""

from __future__ import annotations

import json

import numpy as np
from test_cli import scene, track_args  # noqa: F401  (module fixture)

from wptrack.cli import main
from wptrack.io.tables import read_tracks


def _replace(args, flag, values):
    i = args.index(flag)
    return args[: i + 1] + list(values) + args[i + 1 + len(values) :]


def test_detection_column_and_prior_flag(scene, tmp_path):  # noqa: F811
    assert main(track_args(scene, tmp_path / "mix", "--mixture", "0.3")) == 0
    t = read_tracks(tmp_path / "mix" / "tracks.csv")
    assert list(t)[-2:] == ["detection", "degenerate"] and list(t)[:13][-2:] == ["ess", "loglik"]
    assert np.all(t["detection"] == 1)
    run = json.loads((tmp_path / "mix" / "run.json").read_text())
    assert run["config"]["tracker"]["proposal"] == "mixture" and run["config"]["tracker"]["mixture"] == 0.3
    assert main(track_args(scene, tmp_path / "prior", "--proposal", "prior")) == 0
    assert np.all(read_tracks(tmp_path / "prior" / "tracks.csv")["detection"] == -1)


def test_colour_matching_nothing_is_flagged_per_frame(scene, tmp_path):  # noqa: F811
    args = _replace(_replace(track_args(scene, tmp_path / "run"), "--hue", ["100", "140"]), "--sat", ["0.9", "1"])
    assert main(args) == 0
    t = read_tracks(tmp_path / "run" / "tracks.csv")
    assert len(t["frame"]) == 6 and np.all(t["detection"] == 0)
    for col in ("x", "y", "z", "sx", "ess", "loglik"):
        assert np.all(np.isfinite(t[col])), col
