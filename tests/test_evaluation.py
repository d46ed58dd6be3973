"""Evaluation of multi-object ground-plane tracks: motmetrics CLEAR-MOT/IDF1 and the accuracy of Juza et al."""

from __future__ import annotations

import json
import math
import sys

import numpy as np
import pytest

from wptrack.errors import ConfigError
from wptrack.evaluation import SCALAR_METRICS, Evaluation, average, evaluate


@pytest.fixture
def mm():
    """motmetrics (needs pandas); tests of input validation run without it."""
    return pytest.importorskip("motmetrics")


def _table(rows, cls=True):
    """Rows (frame, id, x, y[, class]) -> dict of columns as read_tracks returns them."""
    out = {
        "frame": np.array([r[0] for r in rows], dtype=np.int64),
        "id": np.array([r[1] for r in rows], dtype=np.int64),
        "x": np.array([r[2] for r in rows], dtype=np.float64),
        "y": np.array([r[3] for r in rows], dtype=np.float64),
        "z": np.zeros(len(rows)),
    }
    if cls:
        out["class"] = np.array([r[4] for r in rows], dtype=str)
    return out


def _walk(gid, n, x0, y0, cls="human", dx=0.1, start=0):
    """A straight walk of ``n`` frames from (x0, y0)."""
    return [(start + f, gid, x0 + dx * f, y0, cls) for f in range(n)]


def _write_csv(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(str(v) for v in r) + "\n" for r in rows))
    return path


GT_HEADER = ["frame", "id", "x", "y", "z", "class", "length", "width", "height", "orientation"]


def _gt_rows(rows):
    dims = {"human": (0.5, 0.5, 1.8), "vehicle": (4.5, 1.8, 1.5)}
    return [(f, i, x, y, 0.0, c, *dims[c], 0.0) for f, i, x, y, c in rows]


def _offset(rows, dx=0.0, dy=0.0, hid=None, cls=None):
    return [(f, i if hid is None else hid, x + dx, y + dy, c if cls is None else cls) for f, i, x, y, c in rows]


# ------------------------------------------------------------------------------------------ basic scores


def test_perfect_tracks(mm, tmp_path):
    gt = _walk(1, 20, 0.0, 0.0) + _walk(2, 20, 5.0, 3.0, cls="vehicle")
    gt_path = _write_csv(tmp_path / "groundtruth.csv", GT_HEADER, _gt_rows(gt))
    hyp = _offset(gt[:20], hid=7) + _offset(gt[20:], hid=9)
    ev = evaluate(str(gt_path), _table(hyp))
    assert ev.mota == 1.0 and ev.idf1 == 1.0 and ev.precision == 1.0 and ev.recall == 1.0
    assert ev.motp == 0.0
    assert ev.id_switches == 0 and ev.fragmentations == 0
    assert ev.num_gt_tracks == 2 and ev.num_frames == 20 and ev.num_objects == 40 and ev.num_matches == 40
    assert ev.tracking_accuracy == 1.0 and ev.classification_accuracy == 1.0 and ev.accuracy == 1.0
    assert [(t.gt_id, t.gt_class, t.frames_present, t.frames_matched) for t in ev.per_track] == [
        (1, "human", 20, 20),
        (2, "vehicle", 20, 20),
    ]
    assert [(t.majority_hypothesis, t.majority_class, t.class_correct) for t in ev.per_track] == [
        (7, "human", True),
        (9, "vehicle", True),
    ]
    d = ev.to_dict()
    assert json.loads(json.dumps(d, allow_nan=False)) == d
    assert d["per_track"][1]["gt_class"] == "vehicle" and d["accuracy"] == 1.0


def test_offset_within_threshold_matches_and_motp_in_metres(mm):
    gt = _walk(1, 10, 0.0, 0.0)
    ev = evaluate(_table(gt), _table(_offset(gt, dx=0.3, dy=0.4)))  # 0.5 m away
    assert ev.mota == 1.0 and ev.num_matches == 10
    assert ev.motp == pytest.approx(0.5)
    assert ev.accuracy == 1.0


def test_offset_beyond_threshold_and_mota_by_hand(mm):
    # A: 3 frames, hypothesis 0.5 m away (3 matches). B: matched in frame 0, then 1.5 m away in frames 1-2
    # (2 misses and 2 false positives). MOTA = 1 - (2 + 2 + 0) / 6, MOTP = (3 * 0.5 + 0) / 4.
    a = _walk(1, 3, 0.0, 0.0)
    b = _walk(2, 3, 10.0, 0.0)
    hyp = _offset(a, dx=0.5, hid=11) + _offset(b[:1], hid=12) + _offset(b[1:], dy=1.5, hid=12)
    ev = evaluate(_table(a + b), _table(hyp))
    assert (ev.num_objects, ev.num_matches, ev.num_misses, ev.num_false_positives) == (6, 4, 2, 2)
    assert ev.mota == pytest.approx(1.0 - 4.0 / 6.0)
    assert ev.motp == pytest.approx(0.375)
    assert ev.recall == pytest.approx(4 / 6) and ev.precision == pytest.approx(4 / 6)
    assert [t.frames_matched for t in ev.per_track] == [3, 1]
    assert ev.tracking_accuracy == 0.5 and ev.classification_accuracy == 1.0 and ev.accuracy == 0.5

    ev = evaluate(_table(a), _table(_offset(a, dx=1.5)))  # always 1.5 m away: nothing matches
    assert (ev.num_matches, ev.num_misses, ev.num_false_positives) == (0, 3, 3)
    assert ev.mota == pytest.approx(-1.0)  # 1 - (3 + 3) / 3
    assert math.isnan(ev.motp) and ev.recall == 0.0 and ev.accuracy == 0.0

    ev = evaluate(_table(a), _table(_offset(a, dx=1.5)), threshold=2.0)  # a wider gate matches again
    assert ev.mota == 1.0 and ev.motp == pytest.approx(1.5)


def test_identity_change_halfway(mm):
    gt = _walk(1, 10, 0.0, 0.0)
    hyp = _offset(gt[:5], hid=1) + _offset(gt[5:], hid=2)  # the tracker re-initialises the object under a new id
    ev = evaluate(_table(gt), _table(hyp))
    assert ev.id_switches == 1
    assert ev.idf1 == pytest.approx(0.5)  # 2 * 5 / (10 + 10)
    assert ev.mota == pytest.approx(0.9)
    assert ev.tracking_accuracy == 1.0 and ev.accuracy == 1.0
    assert ev.per_track[0].majority_hypothesis == 1  # 5 frames each: the earliest wins the tie


def test_identity_swap_between_two_objects(mm):
    a = _walk(1, 10, 0.0, 0.0)
    b = _walk(2, 10, 0.0, 5.0)
    hyp = _offset(a[:5], hid=1) + _offset(b[:5], hid=2) + _offset(a[5:], hid=2) + _offset(b[5:], hid=1)
    ev = evaluate(_table(a + b), _table(hyp))
    assert ev.id_switches == 2  # motmetrics counts one switch per ground-truth object
    assert ev.idf1 == pytest.approx(0.5) and ev.idf1 < 1
    assert ev.tracking_accuracy == 1.0 and ev.accuracy == 1.0


def test_wrong_class_halves_classification_accuracy(mm):
    a = _walk(1, 10, 0.0, 0.0)
    b = _walk(2, 10, 8.0, 0.0, cls="vehicle")
    hyp = _offset(a, hid=1) + _offset(b, hid=2, cls="human")
    ev = evaluate(_table(a + b), _table(hyp))
    assert ev.tracking_accuracy == 1.0 and ev.classification_accuracy == 0.5 and ev.accuracy == 0.5
    assert [t.class_correct for t in ev.per_track] == [True, False]
    assert ev.per_track[1].majority_class == "human"
    assert ev.mota == 1.0  # classes do not enter CLEAR-MOT


def test_class_is_a_frame_weighted_majority(mm):
    gt = _walk(1, 10, 0.0, 0.0, cls="vehicle")
    hyp = _offset(gt[:3], cls="human") + _offset(gt[3:], cls="Vehicle ")  # case and spaces are ignored
    ev = evaluate(_table(gt), _table(hyp))
    assert ev.per_track[0].majority_class == "vehicle" and ev.classification_accuracy == 1.0


def test_min_coverage(mm):
    a = _walk(1, 10, 0.0, 0.0)
    b = _walk(2, 10, 8.0, 0.0)
    hyp = _offset(a, hid=1) + _offset(b[:5], hid=2)  # b tracked in half of its frames
    ev = evaluate(_table(a + b), _table(hyp))
    assert [t.coverage for t in ev.per_track] == [1.0, 0.5]
    assert [t.correctly_tracked for t in ev.per_track] == [True, False]
    assert ev.per_track[1].class_correct is None
    assert ev.tracking_accuracy == 0.5 and ev.classification_accuracy == 1.0 and ev.accuracy == 0.5
    ev = evaluate(_table(a + b), _table(hyp), min_coverage=0.5)
    assert ev.tracking_accuracy == 1.0


def test_empty_tracks(mm, tmp_path):
    gt = _walk(1, 5, 0.0, 0.0) + _walk(2, 5, 4.0, 0.0, cls="vehicle")
    tracks = _write_csv(tmp_path / "tracks.csv", ["frame", "id", "x", "y", "z", "class"], [])
    ev = evaluate(_table(gt), tracks)
    assert ev.mota == 0.0 and ev.recall == 0.0 and ev.idf1 == 0.0
    assert math.isnan(ev.motp) and math.isnan(ev.precision)
    assert (ev.num_misses, ev.num_false_positives) == (10, 0)
    assert ev.tracking_accuracy == 0.0 and ev.classification_accuracy is None and ev.accuracy == 0.0
    assert all(t.majority_hypothesis is None and t.majority_class is None for t in ev.per_track)
    d = ev.to_dict()
    assert d["motp"] is None and d["precision"] is None
    json.dumps(d, allow_nan=False)


def test_tracks_csv_with_extra_columns(mm, tmp_path):
    gt = _walk(1, 6, 0.0, 0.0) + _walk(2, 6, 0.0, 6.0, cls="vehicle")
    gt_path = _write_csv(tmp_path / "gt.csv", GT_HEADER, _gt_rows(gt))
    header = ["frame", "id", "x", "y", "z", "class", "score", "sx", "sy", "sz", "template"]
    rows = [(f, i + 10, f"{x:.6f}", f"{y:.6f}", "0.0", c, 0.9, 0.1, 0.1, 0.2, f"{c}-small") for f, i, x, y, c in gt]
    rows.append((2, 99, "nan", "nan", "nan", "human", 0.1, 0, 0, 0, ""))  # no estimate: dropped
    rows.append((50, 98, 0.0, 0.0, 0.0, "human", 0.1, 0, 0, 0, ""))  # frame without ground truth: ignored
    ev = evaluate(gt_path, _write_csv(tmp_path / "tracks.csv", header, rows))
    assert ev.mota == 1.0 and ev.num_false_positives == 0 and ev.accuracy == 1.0
    assert [t.majority_hypothesis for t in ev.per_track] == [11, 12]


def test_without_class_columns(mm):
    gt = _walk(1, 10, 0.0, 0.0) + _walk(2, 10, 8.0, 0.0)
    hyp = _offset(gt[:10], hid=1) + _offset(gt[10:15], hid=2)
    for g, h in ((_table(gt, cls=False), _table(hyp)), (_table(gt), _table(hyp, cls=False))):
        ev = evaluate(g, h)
        assert ev.classification_accuracy is None
        assert ev.tracking_accuracy == 0.5 and ev.accuracy == 0.5  # tracking accuracy alone
        assert all(t.class_correct is None for t in ev.per_track)


def test_frames_restriction(mm):
    gt = _walk(1, 10, 0.0, 0.0)
    hyp = _offset(gt[:5])  # tracked in frames 0-4 only
    assert evaluate(_table(gt), _table(hyp)).tracking_accuracy == 0.0
    ev = evaluate(_table(gt), _table(hyp), frames=range(0, 5))
    assert ev.num_frames == 5 and ev.mota == 1.0 and ev.tracking_accuracy == 1.0
    # frames absent from the ground truth are evaluated when listed: their hypotheses are false positives
    extra = _table(hyp + [(20, 5, 1.0, 1.0, "human")])
    ev = evaluate(_table(gt), extra, frames=[*range(5), 20])
    assert ev.num_frames == 6 and ev.num_false_positives == 1 and ev.mota == pytest.approx(1 - 1 / 5)
    with pytest.raises(ConfigError, match="no ground-truth objects"):
        evaluate(_table(gt), _table(hyp), frames=[100, 101])


def test_average(mm):
    gt = _walk(1, 10, 0.0, 0.0) + _walk(2, 10, 8.0, 0.0)
    runs = [
        evaluate(_table(gt), _table(_offset(gt[:10], hid=1) + _offset(gt[10:], hid=2))),
        evaluate(_table(gt), _table(_offset(gt[:10], hid=1) + _offset(gt[10:15], hid=2))),
        evaluate(_table(gt), _table(gt[:0])),
    ]
    avg = average(runs)
    assert avg["runs"] == 3 and set(SCALAR_METRICS) <= set(avg)
    assert avg["accuracy"] == {"mean": pytest.approx(0.5), "min": 0.0, "max": 1.0, "n": 3}
    assert avg["classification_accuracy"]["n"] == 2  # None for the empty run
    assert avg["motp"]["n"] == 2  # NaN for the empty run
    json.dumps(avg, allow_nan=False)
    assert isinstance(runs[0], Evaluation)
    with pytest.raises(ConfigError):
        average([])


# ------------------------------------------------------------------------------------------ bad input


def test_missing_column_names_file_and_column(tmp_path):
    path = _write_csv(tmp_path / "gt.csv", ["frame", "id", "x", "z"], [(0, 1, 0.0, 0.0)])
    with pytest.raises(ConfigError, match=r"gt\.csv.*'y'"):
        evaluate(path, {"frame": [0], "id": [1], "x": [0.0], "y": [0.0], "z": [0.0]})
    gt = _table(_walk(1, 3, 0.0, 0.0))
    with pytest.raises(ConfigError, match=r"tracks <table>.*'x'"):
        evaluate(gt, {"frame": [0], "id": [1], "y": [0.0], "z": [0.0]})


def test_non_numeric_values(tmp_path):
    gt = _table(_walk(1, 3, 0.0, 0.0))
    path = _write_csv(tmp_path / "tracks.csv", ["frame", "id", "x", "y", "z"], [(0, 1, "abc", 0.0, 0.0)])
    with pytest.raises(ConfigError, match=r"tracks\.csv: column 'x' has non-numeric values"):
        evaluate(gt, path)
    with pytest.raises(ConfigError, match=r"ground truth <table>: column 'id' has non-integer"):
        evaluate({**gt, "id": gt["id"] + 0.5}, gt)
    with pytest.raises(ConfigError, match=r"ground truth <table>: column 'y' has missing"):
        evaluate({**gt, "y": np.array([0.0, np.nan, 0.0])}, gt)
    with pytest.raises(ConfigError, match=r"ground truth <table>: column 'class' has empty"):
        evaluate({**gt, "class": np.array(["human", "", "human"])}, gt)


def test_negative_frames_and_duplicates(tmp_path):
    gt = _table(_walk(1, 3, 0.0, 0.0))
    path = _write_csv(tmp_path / "g.csv", ["frame", "id", "x", "y", "z"], [(-1, 1, 0.0, 0.0, 0.0)])
    with pytest.raises(ConfigError, match=r"g\.csv: column 'frame' has negative values"):
        evaluate(path, gt)
    dup = _table(_walk(1, 3, 0.0, 0.0) + [(1, 1, 5.0, 5.0, "human")])
    with pytest.raises(ConfigError, match=r"tracks <table>: id 1 appears more than once in frame 1"):
        evaluate(gt, dup)
    with pytest.raises(ConfigError, match="frames"):
        evaluate(gt, gt, frames=[-3])


def test_bad_files_and_parameters(tmp_path):
    gt = _table(_walk(1, 3, 0.0, 0.0))
    with pytest.raises(ConfigError, match="not found"):
        evaluate(tmp_path / "missing.csv", gt)
    with pytest.raises(ConfigError, match="threshold"):
        evaluate(gt, gt, threshold=0.0)
    with pytest.raises(ConfigError, match="min_coverage"):
        evaluate(gt, gt, min_coverage=1.5)
    with pytest.raises(TypeError):
        evaluate(42, gt)


def test_missing_motmetrics_is_a_config_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "motmetrics", None)  # import motmetrics raises ImportError
    gt = _table(_walk(1, 3, 0.0, 0.0))
    with pytest.raises(ConfigError, match="pip install motmetrics"):
        evaluate(gt, gt)


def test_ground_plane_table_without_z(tmp_path):
    """Ground-plane annotations (frame,id,x,y: the EPFL datasets) are scored like tables with z; a z column that is
    present is still checked."""
    path = _write_csv(tmp_path / "gt.csv", ["frame", "id", "x", "y"], [(0, 1, 0.0, 0.0), (1, 1, 0.1, 0.0)])
    tracks = {"frame": [0, 1], "id": [7, 7], "x": [0.2, 0.3], "y": [0.0, 0.0]}
    ev = evaluate(path, tracks, threshold=1.0)
    assert ev.mota == pytest.approx(1.0) and ev.idf1 == pytest.approx(1.0)
    far = evaluate(path, {"frame": [0, 1], "id": [7, 7], "x": [2.0, 2.0], "y": [0.0, 0.0]}, threshold=1.0)
    assert far.num_misses == 2 and far.num_false_positives == 2
    with pytest.raises(ConfigError, match=r"'z'"):
        evaluate(path, {**tracks, "z": ["a", "b"]})
