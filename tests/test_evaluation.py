"""Evaluation of multi-object ground-plane tracks: motmetrics CLEAR-MOT/IDF1 and the accuracy of Juza et al."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from wptrack.core.errors import ConfigError
from wptrack.evaluation.mot import SCALAR_METRICS, Evaluation, average, evaluate


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
    # accuracies 1.0, 0.5, 0.0: sample standard deviation 0.5
    assert avg["accuracy"] == {"mean": pytest.approx(0.5), "min": 0.0, "max": 1.0, "std": pytest.approx(0.5), "n": 3}
    assert average(runs[:1])["accuracy"]["std"] == 0.0
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


def test_evaluate_cli_writes_mot_files_for_ground_truth_without_z(mm, tmp_path, capsys):
    """`wptrack evaluate RUN --groundtruth frame,id,x,y.csv` (the EPFL terrace's table) scores and writes its
    MOTChallenge files with z = 0 (it crashed with KeyError 'z' after printing the metrics)."""
    import json

    from wptrack.cli import main

    gt = _write_csv(tmp_path / "gt.csv", ["frame", "id", "x", "y"], [(0, 1, 0.0, 0.0), (1, 1, 0.1, 0.0)])
    run = tmp_path / "run"
    run.mkdir()
    _write_csv(run / "tracks.csv", ["frame", "id", "x", "y", "z"], [(0, 7, 0.2, 0.0, 0.9), (1, 7, 0.3, 0.0, 0.9)])
    args = ["evaluate", str(run), "--groundtruth", str(gt), "--threshold", "1", "--out", str(tmp_path / "ev.json")]
    assert main(args) == 0
    assert json.loads((tmp_path / "ev.json").read_text())["mota"] == pytest.approx(1.0)
    world = (run / "mot" / "gt" / "world.txt").read_text().splitlines()
    assert len(world) == 2 and all(float(line.split(",")[-1]) == 0.0 for line in world)  # z on the ground


def test_ground_plane_table_without_z(mm, tmp_path):
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


# ------------------------------------------------------------------------------------------ HOTA (issue 30)


def _pts(rows):
    """Rows (frame, id, x, y) -> columns."""
    return _table([(*r, "human") for r in rows], cls=False)


def test_hota_perfect_tracking_is_one():
    from wptrack.evaluation.hota import HOTA_ALPHAS
    from wptrack.evaluation.mot import hota

    gt = [(f, 1, 0.1 * f, 0.0) for f in range(5)] + [(f, 2, 3.0, 0.2 * f) for f in range(2, 6)]
    r = hota(_pts(gt), _pts([(f, i + 10, x, y) for f, i, x, y in gt]))  # other ids: HOTA does not care
    assert (r.hota, r.deta, r.assa, r.loca, r.detre, r.detpr, r.assre, r.asspr) == (1, 1, 1, 1, 1, 1, 1, 1)
    assert r.alphas == HOTA_ALPHAS and len(HOTA_ALPHAS) == 19 and HOTA_ALPHAS[0] == 0.05 and HOTA_ALPHAS[-1] == 0.95


@pytest.mark.parametrize(("d", "threshold", "kept"), [(0.33, 1.0, 13), (0.1, 0.5, 16), (0.6, 0.5, 0)])
def test_hota_of_a_constant_offset(d, threshold, kept):
    """Tracks a constant distance d away: similarity s = 1 - d / threshold in every frame, so every alpha <= s has
    DetA = AssA = 1 and every alpha > s has nothing: HOTA = (alphas <= s) / 19, LocA = s."""
    from wptrack.evaluation.mot import hota

    gt = [(f, 1, 0.1 * f, 0.0) for f in range(6)]
    r = hota(_pts(gt), _pts([(f, 4, x + 0.6 * d, y + 0.8 * d) for f, i, x, y in gt]), threshold=threshold)
    assert r.hota == pytest.approx(kept / 19)
    assert r.deta == pytest.approx(kept / 19) and r.assa == pytest.approx(kept / 19)
    if kept:
        assert r.loca == pytest.approx(1 - d / threshold)
    else:
        assert math.isnan(r.loca)


def test_hota_identity_switch_halves_association():
    """One object, tracked exactly by id 5 in frames 0-1 and id 6 in frames 2-3: DetA = 1, each TP's association
    IoU = 2 / (4 + 2 - 2) = 0.5, AssA = 0.5, HOTA = sqrt(0.5)."""
    from wptrack.evaluation.mot import hota

    gt = [(f, 1, 0.1 * f, 0.0) for f in range(4)]
    r = hota(_pts(gt), _pts([(f, 5 if f < 2 else 6, x, y) for f, i, x, y in gt]))
    assert r.deta == pytest.approx(1.0) and r.assa == pytest.approx(0.5) and r.hota == pytest.approx(math.sqrt(0.5))
    assert r.assre == pytest.approx(0.5) and r.asspr == pytest.approx(1.0)  # each id's frames all belong to it


def test_hota_false_positives_lower_detection_only():
    """A second hypothesis 5 m away in every frame: TP = 3, FP = 3, DetA = 3 / 6, AssA = 1, HOTA = sqrt(0.5)."""
    from wptrack.evaluation.mot import hota

    gt = [(f, 1, 0.1 * f, 0.0) for f in range(3)]
    tracks = [(f, 5, x, y) for f, i, x, y in gt] + [(f, 9, x + 5.0, y) for f, i, x, y in gt]
    r = hota(_pts(gt), _pts(tracks))
    assert r.deta == pytest.approx(0.5) and r.assa == pytest.approx(1.0) and r.hota == pytest.approx(math.sqrt(0.5))
    assert r.detre == pytest.approx(1.0) and r.detpr == pytest.approx(0.5)
    assert hota(_pts(gt), _pts(gt[:0])).hota == 0.0  # no tracks at all


def test_hota_matching_prefers_the_lasting_identity():
    """The object is followed 0.2 m away by id 1 in frames 0-3; in frame 1 id 2 sits exactly on it. A per-frame
    best-similarity match would take id 2 there (AssA 0.5125); HOTA's matching weighs each pair by its identities'
    alignment over the sequence (A(o, 1) = 3.444 / (8 - 3.444) = 0.756 > A(o, 2) = 0.125 / ...), keeps id 1: TP = 4,
    FP = 1, DetA = 0.8, AssA = 1 for alpha <= 0.8 (similarity 0.8), nothing above: HOTA = 16 / 19 sqrt(0.8)."""
    from wptrack.evaluation.mot import hota

    gt = [(f, 7, 0.0, 0.0) for f in range(4)]
    tracks = [(f, 1, 0.2, 0.0) for f in range(4)] + [(1, 2, 0.0, 0.0)]
    r = hota(_pts(gt), _pts(tracks))
    assert r.hota == pytest.approx(16 / 19 * math.sqrt(0.8))
    assert r.deta_alpha[15] == pytest.approx(0.8) and r.assa_alpha[15] == pytest.approx(1.0)  # alpha 0.80
    assert r.deta_alpha[16] == 0.0 and r.loca == pytest.approx(0.8)


def test_hota_properties_on_random_scenes():
    """Symmetric in ground truth and tracks, blind to id labels and row order, in [0, 1], HOTA_alpha = sqrt(DetA
    AssA), DetA non-increasing in alpha; more noise never scores better (fixed seeds)."""
    from wptrack.evaluation.mot import hota

    rng = np.random.default_rng(30)
    for trial in range(5):
        n_obj, frames = 4, 12
        start = rng.uniform(0, 6, (n_obj, 2))
        vel = rng.normal(0, 0.2, (n_obj, 2))
        gt = [(f, k, *(start[k] + f * vel[k])) for f in range(frames) for k in range(n_obj) if rng.random() > 0.1]
        noisy = [(f, (k * 7 + 3) % 11, x + rng.normal(0, 0.15), y + rng.normal(0, 0.15)) for f, k, x, y in gt]
        noisy = [r for r in noisy if rng.random() > 0.15] + [(f, 50, *rng.uniform(0, 6, 2)) for f in range(0, 12, 3)]
        a = hota(_pts(gt), _pts(noisy))
        b = hota(_pts(noisy), _pts(gt))
        assert a.hota == pytest.approx(b.hota, abs=1e-12) and a.deta == pytest.approx(b.deta, abs=1e-12)
        assert a.assa == pytest.approx(b.assa, abs=1e-12)
        relabelled = [(f, 1000 - i, x, y) for f, i, x, y in reversed(noisy)]
        assert hota(_pts(gt), _pts(relabelled)).hota == pytest.approx(a.hota, abs=1e-12)
        assert 0 < a.hota < 1 and all(0 <= v <= 1 for v in a.hota_alpha)
        for h, d, s in zip(a.hota_alpha, a.deta_alpha, a.assa_alpha, strict=True):
            assert h == pytest.approx(math.sqrt(d * s))
        assert all(x >= y - 1e-12 for x, y in zip(a.deta_alpha, a.deta_alpha[1:], strict=False))
        worse = [(f, i, x + rng.normal(0, 0.3), y + rng.normal(0, 0.3)) for f, i, x, y in noisy]
        assert hota(_pts(gt), _pts(worse)).hota < a.hota + 0.02, trial


def test_evaluate_reports_hota(mm):
    gt = _walk(1, 10, 0.0, 0.0) + _walk(2, 10, 8.0, 0.0)
    ev = evaluate(_table(gt), _table(_offset(gt, dx=0.33)))
    assert ev.hota == pytest.approx(13 / 19) and ev.hota_detail.hota == ev.hota and ev.loca == pytest.approx(0.67)
    d = ev.to_dict()
    assert d["hota"] == ev.hota and len(d["hota_detail"]["hota_alpha"]) == 19
    json.dumps(d, allow_nan=False)
    assert {"hota", "deta", "assa", "loca"} <= set(SCALAR_METRICS)


# ------------------------------------------------------------------------------------------ MOTChallenge files


def _template_camera():
    from wptrack.cameras.rig import Camera, GroundPlane

    return Camera.look_at("cam 0", 320, 240, position=[0, -8, 5], target=[0, 4, 0], fx=260), GroundPlane()


def test_mot_files_world_and_image_boxes(tmp_path, mm):
    """world.txt: 1-based frames, ids, no box, the world position; <camera>.txt: the bounding box of the projected
    3D box corners; both read back by motmetrics' MOT15 loader."""
    from wptrack.evaluation.motfiles import write_mot_files

    cam, plane = _template_camera()
    rows = {
        "frame": np.array([0, 0, 1]),
        "id": np.array([3, 4, 3]),
        "x": np.array([0.0, 1.5, 0.1]),
        "y": np.array([2.0, 4.0, 2.0]),
        "z": np.zeros(3),
        "length": np.array([0.5, 4.5, 0.5]),
        "width": np.array([0.5, 1.8, 0.5]),
        "height": np.array([1.8, 1.5, 1.8]),
        "orientation": np.array([0.0, 0.3, 0.0]),
        "existence": np.array([0.9, 1.0, 0.8]),
    }
    paths = write_mot_files(rows, tmp_path / "mot", cam, plane)
    assert [p.name for p in paths] == ["world.txt", "cam_0.txt"]
    world = np.loadtxt(paths[0], delimiter=",")
    assert world[:, 0].tolist() == [1, 1, 2] and world[:, 1].tolist() == [3, 4, 3]
    assert np.all(world[:, 2:6] == -1) and np.allclose(world[:, 6], [0.9, 1.0, 0.8])
    assert np.allclose(world[:, 7:], np.column_stack([rows["x"], rows["y"], rows["z"]]), atol=1e-4)
    boxes = np.loadtxt(paths[1], delimiter=",")
    # the person at (0, 2): its 8 corners projected independently
    corners = np.array([[x, y, z] for x in (-0.25, 0.25) for y in (1.75, 2.25) for z in (0.0, 1.8)])
    uv, _ = cam.project(corners)
    left, top = uv.min(axis=0)
    w, h = uv.max(axis=0) - uv.min(axis=0)
    assert np.allclose(boxes[0, 2:6], [left + 1, top + 1, w, h], atol=0.01) and np.all(boxes[:, 7:] == -1)
    assert boxes[1, 4] > 3 * boxes[0, 4]  # the car's box is wider than the person's
    import warnings

    with warnings.catch_warnings():  # motmetrics' loader trips a pandas deprecation warning (not ours)
        warnings.simplefilter("ignore")
        df = mm.io.loadtxt(str(paths[1]), fmt="mot15-2D")
        assert len(mm.io.loadtxt(str(paths[0]), fmt="mot15-2D")) == 3
    assert len(df) == 3 and sorted(df.index.get_level_values("Id").tolist()) == [3, 3, 4]
    assert np.allclose(df["X"].to_numpy(), boxes[:, 2] - 1, atol=0.01)  # the loader's 0-based pixels: OpenCV's


def test_cli_evaluate_several_runs_spread_and_mot_files(tmp_path, capsys, mm):
    """`wptrack evaluate run0 run1 --groundtruth gt.csv`: each run's scores with HOTA, the spread (mean, min, max,
    std) over the runs, the JSON of both, and each run's MOTChallenge files (world coordinates: no rig)."""
    from wptrack.cli import main

    gt = _walk(1, 10, 0.0, 0.0) + _walk(2, 10, 8.0, 0.0)
    _write_csv(tmp_path / "gt.csv", ["frame", "id", "x", "y", "z"], [(f, i, x, y, 0.0) for f, i, x, y, _ in gt])
    for k, dx in enumerate((0.0, 0.33)):
        (tmp_path / f"run{k}").mkdir()
        rows = [(f, i + 5, x + dx, y, 0.0) for f, i, x, y, _ in gt]
        _write_csv(tmp_path / f"run{k}" / "tracks.csv", ["frame", "id", "x", "y", "z"], rows)
    out = tmp_path / "ev.json"
    argv = ["evaluate", str(tmp_path / "run0"), str(tmp_path / "run1"), "--groundtruth", str(tmp_path / "gt.csv")]
    assert main([*argv, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "HOTA 1.000" in text and "HOTA 0.684" in text and "over 2 runs: mean (min, max, std)" in text
    doc = json.loads(out.read_text())
    assert set(doc["runs"]) == {str(tmp_path / "run0"), str(tmp_path / "run1")}
    spread = doc["spread"]["hota"]
    assert spread["mean"] == pytest.approx((1 + 13 / 19) / 2) and spread["min"] == pytest.approx(13 / 19)
    assert spread["std"] == pytest.approx(np.std([1.0, 13 / 19], ddof=1))
    for k in range(2):
        assert (tmp_path / f"run{k}" / "mot" / "world.txt").is_file()
        assert (tmp_path / f"run{k}" / "mot" / "gt" / "world.txt").is_file()
        assert not list((tmp_path / f"run{k}" / "mot").glob("cam*.txt"))  # no rig: no image boxes
    assert main([*argv[:2], "--groundtruth", str(tmp_path / "gt.csv"), "--no-mot"]) == 0


# ------------------------------------------------------------------------------- box tables with ground positions

TOWNCENTRE_TINY = Path(__file__).parent / "data" / "towncentre" / "groundtruth_tiny.csv"
"""A few rows in the format of Oxford TownCentre's groundtruth.csv (frame, orig_frame, id, head/body validity,
head and body boxes, ground x, y): ids 6 and 18 have valid bodies in frames 0-2, id 30's body is never valid."""


def test_box_ground_table_keeps_valid_bodies_at_their_ground_positions():
    from wptrack.evaluation.groundtruth import box_ground_table, is_box_ground_table
    from wptrack.io.tables import read_tracks

    columns = read_tracks(TOWNCENTRE_TINY)
    assert is_box_ground_table(columns)
    assert not is_box_ground_table(_table([(0, 1, 0.0, 0.0, "human")]))  # a wptrack table (z column)
    t = box_ground_table(columns)
    assert t["frame"].tolist() == [0, 0, 1, 1, 2, 2]
    assert t["id"].tolist() == [6, 18, 6, 18, 6, 18]  # id 30 (body not valid) left out
    np.testing.assert_allclose(t["x"], [23.761, 21.390, 23.661, 21.390, 23.561, 21.390])
    np.testing.assert_allclose(t["y"], [3.069, 11.470, 3.069, 11.370, 3.069, 11.270])
    assert (t["z"] == 0).all()
    bad = dict(columns, body_valid=np.where(columns["body_valid"] == 0, 2, 1))
    with pytest.raises(ConfigError, match="body_valid"):
        box_ground_table(bad)


def test_evaluate_reads_a_towncentre_groundtruth_csv(mm, tmp_path):
    """The format is found by the header; people whose body box is not valid are not scored (a track on id 30's
    position is a false positive, a miss there would not count)."""
    rows = [(f, 1, 23.761 - 0.1 * f + 0.2, 3.069) for f in range(3)]  # on id 6, 0.2 m off
    rows += [(f, 2, 5.0, 5.0 + 0.1 * f) for f in range(2)]  # on id 30 (not valid)
    tracks = _write_csv(tmp_path / "tracks.csv", ["frame", "id", "x", "y", "z"], [(*r, 0.0) for r in rows])
    ev = evaluate(TOWNCENTRE_TINY, tracks)
    assert ev.num_objects == 6 and ev.num_gt_tracks == 2
    assert ev.num_matches == 3 and ev.num_misses == 3 and ev.num_false_positives == 2
    assert ev.motp == pytest.approx(0.2, abs=1e-9)
    assert ev.mota == pytest.approx(1 - 5 / 6)


def test_cli_evaluate_reads_a_towncentre_groundtruth_csv(mm, tmp_path, capsys):
    from wptrack.cli import main

    rows = [(0, 7, 23.761, 3.069, 0.0), (0, 8, 21.39, 11.47, 0.0), (1, 7, 23.661, 3.069, 0.0)]
    rows += [(1, 8, 21.39, 11.37, 0.0), (2, 7, 23.561, 3.069, 0.0), (2, 8, 21.39, 11.27, 0.0)]
    tracks = _write_csv(tmp_path / "tracks.csv", ["frame", "id", "x", "y", "z"], rows)
    assert main(["evaluate", str(tracks), "--groundtruth", str(TOWNCENTRE_TINY)]) == 0
    assert "MOTA 1.000, IDF1 1.000" in capsys.readouterr().out


def test_evaluate_cli_out_file_folder_and_mistakes(mm, tmp_path, capsys):
    """`wptrack evaluate ... --out new/ev.json` creates the folder (it was an internal error, FileNotFoundError, after
    the metrics and the MOTChallenge files); `--out` naming a folder is one `wptrack: error:` line and exit 2 before
    anything is written (it was IsADirectoryError after the MOTChallenge files)."""
    from wptrack.cli import main

    gt = _write_csv(tmp_path / "gt.csv", ["frame", "id", "x", "y"], [(0, 1, 0.0, 0.0), (1, 1, 0.1, 0.0)])
    run = tmp_path / "run"
    run.mkdir()
    _write_csv(run / "tracks.csv", ["frame", "id", "x", "y", "z"], [(0, 7, 0.2, 0.0, 0.9), (1, 7, 0.3, 0.0, 0.9)])
    out = tmp_path / "new" / "deeper" / "ev.json"
    assert main(["evaluate", str(run), "--groundtruth", str(gt), "--out", str(out)]) == 0
    assert json.loads(out.read_text())["mota"] == pytest.approx(1.0)
    capsys.readouterr()
    run2 = tmp_path / "run2"
    run2.mkdir()
    (run2 / "tracks.csv").write_text((run / "tracks.csv").read_text())
    assert main(["evaluate", str(run2), "--groundtruth", str(gt), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("wptrack: error:") and "is a folder" in err[0], err
    assert not (run2 / "mot").exists(), "nothing may be written for a bad --out"
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    assert main(["evaluate", str(run2), "--groundtruth", str(gt), "--out", str(blocker / "ev.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not writable" in err[0] and "Traceback" not in err[0], err
    assert not (run2 / "mot").exists()


def test_evaluate_cli_says_when_the_run_stops_before_the_ground_truth(mm, tmp_path, capsys, caplog):
    """A run tracked with --max-frames is scored over all the ground truth's frames, the rest as misses (walking the
    docs, 30 PETS frames scored MOTA 0.04 against 400 labelled frames without a word): a warning names the frames;
    a run that covers the ground truth gets none."""
    import logging

    from wptrack.cli import main

    rows = [(f, 1, 0.1 * f, 0.0) for f in range(6)]
    gt = _write_csv(tmp_path / "gt.csv", ["frame", "id", "x", "y"], rows)
    run = tmp_path / "run"
    run.mkdir()
    _write_csv(run / "tracks.csv", ["frame", "id", "x", "y", "z"], [(f, 7, 0.1 * f, 0.0, 0.0) for f in range(2)])
    (run / "run.json").write_text(json.dumps({"status": "complete", "last_frame": 2}))
    with caplog.at_level(logging.WARNING, logger="wptrack"):
        assert main(["evaluate", str(run), "--groundtruth", str(gt), "--no-mot"]) == 0
    notes = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(notes) == 1 and "end at frame 2" in notes[0] and "3 later labelled frames" in notes[0], notes
    caplog.clear()
    (run / "run.json").write_text(json.dumps({"status": "complete", "last_frame": 5}))  # frames 2-5 had no track
    with caplog.at_level(logging.WARNING, logger="wptrack"):
        assert main(["evaluate", str(run), "--groundtruth", str(gt), "--no-mot"]) == 0
    assert not [r for r in caplog.records if r.levelno == logging.WARNING]
    capsys.readouterr()
