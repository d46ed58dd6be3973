"""Offline smoothing of a completed run's trajectories (wptrack.core.smoothing, wptrack.io.tables.smooth_tracks_file):
the weighted least-squares line of its definition, lines kept, noise reduced, the file edited in place."""

from __future__ import annotations

import numpy as np
import pytest

from wptrack.core.errors import OutputError
from wptrack.core.smoothing import smooth_track, tricube
from wptrack.io.tables import read_tracks, smooth_tracks_file


def _reference(frames, values, w_half):
    """LOESS of degree 1 by its definition: at each row, weighted least squares over the rows within +- W."""
    out = values.astype(float).copy()
    for k, f in enumerate(frames):
        m = np.abs(frames - f) <= w_half
        d = (frames[m] - f).astype(float)
        if len(np.unique(d)) < 2:
            continue
        w = (1 - (np.abs(d) / (w_half + 1)) ** 3) ** 3
        a = np.c_[np.ones(m.sum()), d] * np.sqrt(w)[:, None]
        out[k] = np.linalg.lstsq(a, values[m] * np.sqrt(w)[:, None], rcond=None)[0][0]
    return out


def test_tricube_weights():
    d, w = tricube(3)
    np.testing.assert_array_equal(d, [-3, -2, -1, 0, 1, 2, 3])
    assert w[3] == 1 and np.all(np.diff(w[3:]) < 0) and w[0] > 0 and np.allclose(w, w[::-1])


@pytest.mark.parametrize("w_half", [1, 3, 10])
def test_smooth_track_is_the_weighted_line_of_its_definition(rng, w_half):
    frames = np.sort(rng.choice(60, 35, replace=False))  # gaps of every length
    values = np.c_[np.cumsum(rng.normal(0, 0.3, 35)), rng.normal(0, 1, 35), np.full(35, 1.7)]
    got = smooth_track(frames, values, w_half)
    np.testing.assert_allclose(got, _reference(frames, values, w_half), atol=1e-9)
    order = rng.permutation(35)  # rows in any order: the same value for each row
    np.testing.assert_allclose(smooth_track(frames[order], values[order], w_half), got[order], atol=1e-9)


def test_lines_kept_noise_reduced_and_edges_fitted(rng):
    frames = np.arange(100)
    walk = np.c_[2.0 + 0.06 * frames, -1.0 + 0.02 * frames]  # 1.5 m/s at 25 frames/s
    np.testing.assert_allclose(smooth_track(frames, walk, 25), walk, atol=1e-9)
    noisy = walk + rng.normal(0, 0.2, walk.shape)
    err_raw = np.abs(noisy - walk).mean()
    err = np.abs(smooth_track(frames, noisy, 25) - walk)
    assert err.mean() < 0.4 * err_raw
    assert err[:5].mean() < 0.8 * err_raw and err[-5:].mean() < 0.8 * err_raw  # ends fitted, not pulled inwards
    np.testing.assert_array_equal(smooth_track(frames, noisy, 0), noisy)
    lone = smooth_track(np.array([0, 40]), np.array([[1.0], [5.0]]), 10)  # no neighbour within W: kept
    np.testing.assert_array_equal(lone, [[1.0], [5.0]])


def test_tracks_file_smoothed_in_place(tmp_path, rng):
    path = tmp_path / "tracks.csv"
    lines = ["frame,id,x,y,z,class,existence"]
    truth = {}
    for f in range(30):
        for tid in (3, 7):
            if tid == 7 and f < 10:
                continue
            x = tid + 0.05 * f + rng.normal(0, 0.1)
            truth[(f, tid)] = x
            lines.append(f"{f},{tid},{x:.6f},{-0.02 * f:.6f},0.000000,human,0.5")
    path.write_text("\n".join(lines) + "\n")
    assert smooth_tracks_file(path, 0, ("x", "y", "z")) == 0 and path.read_text() == "\n".join(lines) + "\n"
    assert smooth_tracks_file(path, 5, ("x", "y", "z")) == 50
    t = read_tracks(path)
    assert list(t["frame"]) == [int(line.split(",")[0]) for line in lines[1:]]  # the rows' order kept
    assert set(t["class"]) == {"human"} and np.all(t["existence"] == 0.5)  # other cells as written
    for tid in (3, 7):
        m = t["id"] == tid
        frames = t["frame"][m]
        raw = np.array([truth[(int(f), tid)] for f in frames])
        np.testing.assert_allclose(t["x"][m], _reference(frames, raw[:, None], 5)[:, 0], atol=2e-6)
        np.testing.assert_allclose(t["y"][m], -0.02 * frames, atol=2e-6)  # a line: kept


def test_tracks_file_without_rows_is_left_as_it_is(tmp_path):
    path = tmp_path / "tracks.csv"
    path.write_text("frame,id,x,y\n")
    assert smooth_tracks_file(path, 3, ("x", "y")) == 0 and path.read_text() == "frame,id,x,y\n"


def test_tracks_file_errors_leave_it_as_it_was(tmp_path):
    path = tmp_path / "tracks.csv"
    path.write_text("frame,id,x,y\n0,1,0.0,0.0\n0,1,1.0,1.0\n")
    with pytest.raises(OutputError, match="two rows in one frame"):
        smooth_tracks_file(path, 3, ("x", "y"))
    with pytest.raises(OutputError, match="no z column"):
        smooth_tracks_file(path, 3, ("x", "z"))
    path.write_text("frame,id,x,y\n0,1,0.0,abc\n")
    with pytest.raises(OutputError, match="not a number"):
        smooth_tracks_file(path, 3, ("x", "y"))
    assert path.read_text() == "frame,id,x,y\n0,1,0.0,abc\n"
