"""Evaluation of multi-object ground-plane tracks against ground truth.

This module scores the output of a multi-object tracker (a ``tracks.csv``) against a ground-truth table, both with
the columns ``frame,id,x,y`` (metres), optionally ``z`` (checked when present, not used: matching is on the ground
plane; ground-plane annotations such as the EPFL datasets' have none) and optionally ``class``. It reports the
standard CLEAR-MOT and identity metrics, computed by `py-motmetrics <https://github.com/cheind/py-motmetrics>`_ (the
``motmetrics`` package, a dependency of wptrack), and the accuracy of Juza et al. (*3D template based single camera
multiple object tracking*, sections 5.1-5.2), following our reading of that paper set out below.

**Evaluated frames.** The frames scored are the distinct frames of the ground-truth table, or, when ``frames`` is
given, exactly those frames. Ground-truth and tracker rows outside the evaluated frames are ignored. An evaluated
frame absent from the tracks is a frame with no hypotheses (every object in it is a miss). A frame in which the
scene is empty has no ground-truth rows, so it is only evaluated (and its hypotheses counted as false positives)
when it is listed in ``frames``. Tracker rows whose ``x`` or ``y`` is not finite (NaN: no estimate) are dropped.

**Per-frame matching.** In every evaluated frame the ground-truth objects and the hypotheses are compared by their
Euclidean distance on the ground plane, ``d = sqrt((x_o - x_h)^2 + (y_o - y_h)^2)`` in metres (``z`` is not used).
Pairs with ``d > threshold`` (1 m by default) may not be matched. The matching itself is motmetrics'
``MOTAccumulator.update``, i.e. the CLEAR-MOT procedure of Bernardin and Stiefelhagen: a correspondence of the
previous frame is kept while its distance stays within the threshold, and the remaining objects and hypotheses are
paired by a minimum-cost (Hungarian) assignment of the distances. Its costs are the Euclidean distances (the square
root of ``mm.distances.norm2squared_matrix(..., max_d2=threshold**2)``), so the assignment minimises the summed
distance and MOTP is in metres. An object is *matched in a frame* when the accumulator records a ``MATCH`` or a
``SWITCH`` event for it in that frame.

**CLEAR-MOT and identity metrics** (all from ``mm.metrics.create().compute``):

* ``mota`` = 1 - (misses + false positives + identity switches) / (ground-truth objects summed over frames); it can
  be negative, and is 0 when there are no hypotheses at all.
* ``motp`` = mean distance (metres) of the matched pairs; NaN when nothing is matched.
* ``idf1`` = 2 IDTP / (ground-truth objects + hypotheses over frames), after the global one-to-one assignment of
  ground-truth to hypothesis identities (Ristani et al.), with the same distance threshold.
* ``precision`` = matches / hypotheses, ``recall`` = matches / ground-truth objects (over frames).
* ``id_switches`` = motmetrics ``num_switches``; ``fragmentations`` = ``num_fragmentations`` (tracked -> not
  tracked transitions within the tracked span of each object).

**The paper's accuracy** ("a product of the tracking accuracy, which equals to the percentage of correctly tracked
objects, and the classification accuracy defined as the percentage of objects modeled by the right template"):

* A ground-truth track is an identity of the ground-truth table with at least one row in the evaluated frames. It is
  *present* in ``frames_present`` frames and *matched* in ``frames_matched`` of them (per-frame matching above, to
  any hypothesis: an identity switch does not break it).
* A ground-truth track is *correctly tracked* when ``frames_matched >= min_coverage * frames_present`` (0.8 by
  default).
* ``tracking_accuracy`` = correctly tracked ground-truth tracks / ground-truth tracks.
* For each ground-truth track, the *majority hypothesis* and the *majority class* are the hypothesis id and the
  hypothesis ``class`` most frequent over its matched frames (each matched frame votes once, with the id and the
  class of the hypothesis matched in that frame; a tie goes to the value matched earliest). The class of a
  ground-truth track is the most frequent value of its ``class`` column. Classes are compared as stripped,
  lower-case strings; a hypothesis with an empty class never has the right class.
* ``classification_accuracy`` = among the correctly tracked ground-truth tracks, the fraction whose majority class
  equals the ground-truth class. It is ``None`` when either table has no ``class`` column, or when no track is
  correctly tracked (0/0).
* ``accuracy`` = ``tracking_accuracy * classification_accuracy``; when ``classification_accuracy`` is ``None`` it is
  ``tracking_accuracy`` alone (classification not scored; with no correctly tracked track that is 0).

**HOTA** beside them: :mod:`wptrack.evaluation.hota`. **MOTChallenge files**: :mod:`wptrack.evaluation.motfiles`.

The paper runs the probabilistic tracker six times per sequence and averages the results: see :func:`average`
(mean, min, max and the standard deviation over runs, e.g. seeds).

Example:
    >>> from wptrack.evaluation.mot import evaluate, average
    >>> runs = [evaluate("seq1/groundtruth.csv", f"seq1/run{i}/tracks.csv") for i in range(6)]  # doctest: +SKIP
    >>> average(runs)["accuracy"]["mean"]  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from types import ModuleType
from typing import Any

import numpy as np

from wptrack.core.errors import ConfigError, WptrackError
from wptrack.evaluation.hota import HotaResult, _hota_tables
from wptrack.io.atomic import jsonable
from wptrack.io.tables import read_tracks

#: Columns every ground-truth and tracks table must have (``z`` is optional: matching is on the ground plane).
REQUIRED_COLUMNS = ("frame", "id", "x", "y")

#: The scalar fields of :class:`Evaluation` that :func:`average` summarises.
SCALAR_METRICS = (
    "mota",
    "motp",
    "idf1",
    "precision",
    "recall",
    "id_switches",
    "fragmentations",
    "num_gt_tracks",
    "tracking_accuracy",
    "classification_accuracy",
    "accuracy",
    "num_frames",
    "num_objects",
    "num_matches",
    "num_misses",
    "num_false_positives",
    "hota",
    "deta",
    "assa",
    "loca",
)

# motmetrics metric name -> Evaluation field.
_MM_METRICS = {
    "mota": "mota",
    "motp": "motp",
    "idf1": "idf1",
    "precision": "precision",
    "recall": "recall",
    "num_switches": "id_switches",
    "num_fragmentations": "fragmentations",
    "num_objects": "num_objects",
    "num_detections": "num_matches",
    "num_misses": "num_misses",
    "num_false_positives": "num_false_positives",
}

TableLike = Mapping[str, Any] | str | os.PathLike


@dataclasses.dataclass(frozen=True)
class TrackResult:
    """How one ground-truth track was tracked.

    Attributes:
        gt_id: Ground-truth identity.
        gt_class: Its class (most frequent value of the ground truth's ``class`` column), or ``None`` without one.
        frames_present: Evaluated frames in which it is present.
        frames_matched: Of those, frames in which it is matched to a hypothesis.
        coverage: ``frames_matched / frames_present``.
        correctly_tracked: ``frames_matched >= min_coverage * frames_present``.
        majority_hypothesis: Hypothesis id most often matched to it (``None`` if never matched).
        majority_class: Class of its matched hypotheses, frame-weighted majority (``None`` if never matched, if
            the tracks have no ``class`` column, or if that majority is an empty class).
        class_correct: Whether ``majority_class == gt_class``; ``None`` when the track is not correctly tracked or
            classes are not available.
    """

    gt_id: int
    gt_class: str | None
    frames_present: int
    frames_matched: int
    coverage: float
    correctly_tracked: bool
    majority_hypothesis: int | None
    majority_class: str | None
    class_correct: bool | None


@dataclasses.dataclass(frozen=True)
class Evaluation:
    """Scores of one tracker run against ground truth (see the module docstring for the definitions).

    Attributes:
        mota: Multiple object tracking accuracy (motmetrics ``mota``; can be negative).
        motp: Mean ground-plane distance of the matched pairs in metres (NaN when nothing matched).
        idf1: Identity F1 score.
        precision: Matches / hypotheses (NaN without hypotheses).
        recall: Matches / ground-truth objects.
        id_switches: Identity switches.
        fragmentations: Track fragmentations.
        num_gt_tracks: Ground-truth identities present in the evaluated frames.
        tracking_accuracy: Fraction of ground-truth tracks correctly tracked.
        classification_accuracy: Fraction of correctly tracked ground-truth tracks with the right class, or
            ``None`` (no ``class`` column, or no correctly tracked track).
        accuracy: ``tracking_accuracy * classification_accuracy`` (``tracking_accuracy`` when the latter is None).
        per_track: One :class:`TrackResult` per ground-truth track, by increasing id.
        num_frames: Evaluated frames.
        num_objects: Ground-truth objects summed over the evaluated frames.
        num_matches: Matched (object, hypothesis) pairs summed over frames, switches included.
        num_misses: Unmatched ground-truth objects summed over frames.
        num_false_positives: Unmatched hypotheses summed over frames.
        threshold: Matching distance threshold (metres).
        min_coverage: Fraction of its frames a track must be matched in to count as correctly tracked.
        hota: HOTA with the distance similarity of the same threshold (:func:`hota`).
        deta: Its detection accuracy DetA.
        assa: Its association accuracy AssA.
        loca: Its localisation accuracy LocA (mean similarity of the true positives).
        hota_detail: The whole :class:`HotaResult` (per-alpha values, recall and precision parts).
    """

    mota: float
    motp: float
    idf1: float
    precision: float
    recall: float
    id_switches: int
    fragmentations: int
    num_gt_tracks: int
    tracking_accuracy: float
    classification_accuracy: float | None
    accuracy: float
    per_track: tuple[TrackResult, ...]
    num_frames: int
    num_objects: int
    num_matches: int
    num_misses: int
    num_false_positives: int
    threshold: float
    min_coverage: float
    hota: float = math.nan
    deta: float = math.nan
    assa: float = math.nan
    loca: float = math.nan
    hota_detail: HotaResult | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict (``per_track`` as a list of dicts; NaN and infinities as ``None``)."""
        return jsonable(dataclasses.asdict(self))


# ----------------------------------------------------------------------------------------------- input tables


@dataclasses.dataclass
class _Table:
    """A validated table: rows sorted by (frame, id)."""

    label: str
    frame: np.ndarray  # (N,) int64
    ids: np.ndarray  # (N,) int64
    xy: np.ndarray  # (N, 2) float64
    classes: np.ndarray | None  # (N,) object array of str | None, or None without a class column

    def restrict(self, frames: np.ndarray) -> _Table:
        keep = np.isin(self.frame, frames)
        return _Table(
            self.label,
            self.frame[keep],
            self.ids[keep],
            self.xy[keep],
            None if self.classes is None else self.classes[keep],
        )


def _numeric(label: str, name: str, values: np.ndarray) -> np.ndarray:
    """Column as float64, or ConfigError naming the table and column."""
    if values.dtype.kind in "biuf":
        return values.astype(np.float64)
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        for v in values.tolist():
            try:
                float(v)
            except (TypeError, ValueError):
                raise ConfigError(f"{label}: column '{name}' has non-numeric values (e.g. {v!r})") from None
        raise ConfigError(f"{label}: column '{name}' has non-numeric values") from None


def _integers(label: str, name: str, values: np.ndarray, non_negative: bool) -> np.ndarray:
    """Column of integer values (ints or integral floats) as int64, or ConfigError."""
    if values.dtype.kind in "iu":
        out = values.astype(np.int64)
    else:
        v = _numeric(label, name, values)
        bad = ~np.isfinite(v)
        if bad.any():
            raise ConfigError(
                f"{label}: column '{name}' has missing or non-finite values (data row {int(np.argmax(bad)) + 1})"
            )
        bad = v != np.round(v)
        if bad.any():
            raise ConfigError(f"{label}: column '{name}' has non-integer values (e.g. {v[np.argmax(bad)]!r})")
        out = v.astype(np.int64)
    if non_negative and (out < 0).any():
        raise ConfigError(f"{label}: column '{name}' has negative values (e.g. {int(out[np.argmax(out < 0)])})")
    return out


def _class_value(v: Any) -> str | None:
    """Normalised class label: stripped lower-case string; None for an empty cell or NaN."""
    if v is None or (isinstance(v, (float, np.floating)) and math.isnan(v)):
        return None
    if isinstance(v, (np.integer, int)) and not isinstance(v, bool):
        v = int(v)
    text = str(v).strip().lower()
    return text or None


def _load(source: TableLike, role: str, ground_truth: bool) -> _Table:
    """Read and validate a ground-truth or tracks table (dict of columns or CSV path)."""
    if isinstance(source, (str, os.PathLike)):
        label = f"{role} {os.fspath(source)}"
        try:
            columns: Mapping[str, Any] = read_tracks(source, what=f"{role} file")
        except WptrackError as e:
            raise ConfigError(str(e)) from None
    elif isinstance(source, Mapping):
        label = f"{role} <table>"
        columns = source
    else:
        raise TypeError(f"{role} must be a dict of columns or a CSV path, got {type(source).__name__}")

    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if missing:
        raise ConfigError(
            f"{label}: missing column{'s' if len(missing) > 1 else ''} {', '.join(repr(c) for c in missing)} "
            f"(required: {','.join(REQUIRED_COLUMNS)})"
        )
    names = list(REQUIRED_COLUMNS) + [c for c in ("z", "class") if c in columns]
    arrays = {}
    for name in names:
        a = np.asarray(columns[name])
        if a.ndim != 1:
            raise ConfigError(f"{label}: column '{name}' must be one-dimensional, got shape {a.shape}")
        arrays[name] = a
    lengths = {name: len(a) for name, a in arrays.items()}
    if len(set(lengths.values())) > 1:
        raise ConfigError(f"{label}: columns have different lengths {lengths}")

    frame = _integers(label, "frame", arrays["frame"], non_negative=True)
    ids = _integers(label, "id", arrays["id"], non_negative=False)
    x = _numeric(label, "x", arrays["x"])
    y = _numeric(label, "y", arrays["y"])
    if "z" in arrays:
        _numeric(label, "z", arrays["z"])  # checked, not used: matching is on the ground plane
    classes = None
    if "class" in arrays:
        classes = np.array([_class_value(v) for v in arrays["class"].tolist()], dtype=object)

    finite = np.isfinite(x) & np.isfinite(y)
    if ground_truth:
        if not finite.all():
            row = int(np.argmax(~finite))
            name = "x" if not np.isfinite(x[row]) else "y"
            raise ConfigError(f"{label}: column '{name}' has missing or non-finite values (data row {row + 1})")
        if classes is not None and any(c is None for c in classes):
            row = next(i for i, c in enumerate(classes) if c is None)
            raise ConfigError(f"{label}: column 'class' has empty values (data row {row + 1})")
    else:  # a tracker row without a finite position is no hypothesis
        frame, ids, x, y = frame[finite], ids[finite], x[finite], y[finite]
        classes = None if classes is None else classes[finite]

    order = np.lexsort((ids, frame))
    frame, ids = frame[order], ids[order]
    dup = (np.diff(frame) == 0) & (np.diff(ids) == 0)
    if dup.any():
        i = int(np.argmax(dup))
        raise ConfigError(f"{label}: id {int(ids[i])} appears more than once in frame {int(frame[i])}")
    xy = np.stack([x[order], y[order]], axis=1)
    return _Table(label, frame, ids, xy, None if classes is None else classes[order])


def _evaluated_frames(frames: Iterable[int] | None, gt: _Table) -> np.ndarray:
    if frames is None:
        return np.unique(gt.frame)
    if isinstance(frames, (str, bytes)) or not isinstance(frames, Iterable):
        raise ConfigError(f"frames must be an iterable of frame numbers (e.g. range(0, 100)), got {frames!r}")
    values = list(frames)
    out = _integers("frames", "frames", np.asarray(values if values else [], dtype=object), non_negative=True)
    if out.size == 0:
        raise ConfigError("frames: no frames to evaluate")
    return np.unique(out)


def _import_motmetrics() -> ModuleType:
    try:
        import motmetrics
    except ImportError as e:
        raise ConfigError(
            f"scoring needs the motmetrics package, a dependency of wptrack that is not importable here ({e}): "
            "pip install motmetrics"
        ) from None
    return motmetrics


def _majority(values: Sequence[Any]) -> Any:
    """Most frequent value; a tie goes to the value seen first. None for an empty sequence."""
    counts: dict[Any, int] = {}
    for v in values:
        counts[v] = counts.get(v, 0) + 1
    return max(counts, key=counts.__getitem__) if counts else None  # max keeps the first of equal counts


# ----------------------------------------------------------------------------------------------- HOTA


def hota(
    groundtruth: TableLike, tracks: TableLike, threshold: float = 1.0, frames: Iterable[int] | None = None
) -> HotaResult:
    """HOTA of ground-plane tracks against ground truth with the similarity ``max(0, 1 - d / threshold)``.

    Args:
        groundtruth: Ground truth (dict of columns or CSV path; ``frame,id,x,y,z``), as for :func:`evaluate`.
        tracks: Tracker output, same forms; rows with a non-finite ``x`` or ``y`` are dropped.
        threshold: Ground-plane distance (metres) at which the similarity reaches 0.
        frames: Frames to evaluate; by default the frames of the ground truth.

    Returns:
        The :class:`HotaResult`.

    Raises:
        ConfigError: As :func:`evaluate` (motmetrics is not needed).
    """
    threshold = float(threshold)
    if not (math.isfinite(threshold) and threshold > 0):
        raise ConfigError(f"threshold must be a positive distance in metres, got {threshold}")
    gt = _load(groundtruth, "ground truth", ground_truth=True)
    hyp = _load(tracks, "tracks", ground_truth=False)
    eval_frames = _evaluated_frames(frames, gt)
    gt, hyp = gt.restrict(eval_frames), hyp.restrict(eval_frames)
    if gt.frame.size == 0:
        raise ConfigError(f"{gt.label}: no ground-truth objects in the evaluated frames")
    return _hota_tables(gt, hyp, eval_frames, threshold)


# ----------------------------------------------------------------------------------------------- evaluation


def evaluate(
    groundtruth: TableLike,
    tracks: TableLike,
    threshold: float = 1.0,
    min_coverage: float = 0.8,
    frames: Iterable[int] | None = None,
) -> Evaluation:
    """Score tracks against ground truth on the ground plane (definitions in the module docstring).

    Args:
        groundtruth: Ground truth: a dict of columns as returned by :func:`wptrack.io.tables.read_tracks`, or the
            path of a CSV file. Columns ``frame,id,x,y`` required; ``z`` and ``class`` optional; other columns ignored.
        tracks: Tracker output (e.g. a run's ``tracks.csv``), same forms and columns. Rows with a non-finite
            ``x`` or ``y`` are dropped.
        threshold: Largest ground-plane distance (metres) at which an object and a hypothesis may be matched.
        min_coverage: A ground-truth track is correctly tracked when matched in at least this fraction of the
            evaluated frames in which it is present; in (0, 1].
        frames: Frames to evaluate (e.g. ``range(100, 500)``); by default the frames of the ground truth.

    Returns:
        The :class:`Evaluation`.

    Raises:
        ConfigError: A table is unreadable, lacks a required column, has non-numeric values, negative or
            non-integer frames, non-integer ids, an id twice in a frame, non-finite ground-truth positions or
            empty ground-truth classes (the message names the file, or ``<table>``, and the column); no
            ground-truth object in the evaluated frames; a bad ``threshold``/``min_coverage``/``frames``; or
            motmetrics is not installed.
    """
    threshold = float(threshold)
    if not (math.isfinite(threshold) and threshold > 0):
        raise ConfigError(f"threshold must be a positive distance in metres, got {threshold}")
    min_coverage = float(min_coverage)
    if not (0.0 < min_coverage <= 1.0):
        raise ConfigError(f"min_coverage must be in (0, 1], got {min_coverage}")

    gt = _load(groundtruth, "ground truth", ground_truth=True)
    hyp = _load(tracks, "tracks", ground_truth=False)
    eval_frames = _evaluated_frames(frames, gt)
    gt, hyp = gt.restrict(eval_frames), hyp.restrict(eval_frames)
    if gt.frame.size == 0:
        raise ConfigError(f"{gt.label}: no ground-truth objects in the evaluated frames")

    mm = _import_motmetrics()

    # Identities become 0..K-1 codes (motmetrics stores ids as floats); rows are sorted by frame.
    gt_ids, gt_codes = np.unique(gt.ids, return_inverse=True)
    hyp_ids, hyp_codes = np.unique(hyp.ids, return_inverse=True)
    gt_start = np.searchsorted(gt.frame, eval_frames, side="left")
    gt_stop = np.searchsorted(gt.frame, eval_frames, side="right")
    hyp_start = np.searchsorted(hyp.frame, eval_frames, side="left")
    hyp_stop = np.searchsorted(hyp.frame, eval_frames, side="right")

    acc = mm.MOTAccumulator(auto_id=False)
    max_d2 = threshold * threshold
    for f, g0, g1, h0, h1 in zip(eval_frames.tolist(), gt_start, gt_stop, hyp_start, hyp_stop, strict=True):
        d2 = mm.distances.norm2squared_matrix(gt.xy[g0:g1], hyp.xy[h0:h1], max_d2=max_d2)
        acc.update(gt_codes[g0:g1], hyp_codes[h0:h1], np.sqrt(d2), frameid=f)

    summary = mm.metrics.create().compute(acc, metrics=list(_MM_METRICS), name="evaluation")
    scores: dict[str, Any] = {}
    for mm_name, field in _MM_METRICS.items():
        value = summary[mm_name].iloc[0]
        scores[field] = (
            int(value) if field in ("id_switches", "fragmentations") or field.startswith("num_") else float(value)
        )

    # Per-frame matches (MATCH or SWITCH events; TRANSFER/ASCEND/MIGRATE only annotate them).
    events = acc.mot_events
    types = np.asarray(events["Type"].astype(str))
    is_match = (types == "MATCH") | (types == "SWITCH")
    m_frame = np.asarray(events.index.get_level_values("FrameId"))[is_match].astype(np.int64)
    m_obj = np.asarray(events["OId"])[is_match].astype(np.int64)
    m_hyp = np.asarray(events["HId"])[is_match].astype(np.int64)
    order = np.lexsort((m_frame, m_obj))  # by object, then frame
    m_frame, m_obj, m_hyp = m_frame[order], m_obj[order], m_hyp[order]

    with_classes = gt.classes is not None and hyp.classes is not None
    hyp_class: dict[tuple[int, int], str | None] = {}
    if hyp.classes is not None:
        hyp_class = dict(zip(zip(hyp.frame.tolist(), hyp_codes.tolist(), strict=True), hyp.classes, strict=True))

    present = np.bincount(gt_codes, minlength=len(gt_ids))
    per_track = []
    for k, gid in enumerate(gt_ids.tolist()):
        lo, hi = np.searchsorted(m_obj, [k, k + 1])
        frames_k, hyps_k = m_frame[lo:hi].tolist(), m_hyp[lo:hi].tolist()
        matched = len(frames_k)
        correct = matched >= min_coverage * int(present[k]) - 1e-9
        gt_class = _majority(gt.classes[gt_codes == k].tolist()) if gt.classes is not None else None
        majority_class = None
        if hyp.classes is not None:
            majority_class = _majority([hyp_class[(f, h)] for f, h in zip(frames_k, hyps_k, strict=True)])
        majority_hyp = _majority(hyps_k)
        per_track.append(
            TrackResult(
                gt_id=int(gid),
                gt_class=gt_class,
                frames_present=int(present[k]),
                frames_matched=matched,
                coverage=matched / int(present[k]),
                correctly_tracked=bool(correct),
                majority_hypothesis=None if majority_hyp is None else int(hyp_ids[majority_hyp]),
                majority_class=majority_class,
                class_correct=(majority_class is not None and majority_class == gt_class)
                if with_classes and correct
                else None,
            )
        )

    n_correct = sum(t.correctly_tracked for t in per_track)
    tracking_accuracy = n_correct / len(per_track)
    classification_accuracy = None
    if with_classes and n_correct:
        classification_accuracy = sum(bool(t.class_correct) for t in per_track) / n_correct
    accuracy = tracking_accuracy * (1.0 if classification_accuracy is None else classification_accuracy)

    ho = _hota_tables(gt, hyp, eval_frames, threshold)
    return Evaluation(
        mota=scores["mota"],
        motp=scores["motp"],
        idf1=scores["idf1"],
        precision=scores["precision"],
        recall=scores["recall"],
        id_switches=scores["id_switches"],
        fragmentations=scores["fragmentations"],
        num_gt_tracks=len(per_track),
        tracking_accuracy=tracking_accuracy,
        classification_accuracy=classification_accuracy,
        accuracy=accuracy,
        per_track=tuple(per_track),
        num_frames=int(eval_frames.size),
        num_objects=scores["num_objects"],
        num_matches=scores["num_matches"],
        num_misses=scores["num_misses"],
        num_false_positives=scores["num_false_positives"],
        threshold=threshold,
        min_coverage=min_coverage,
        hota=ho.hota,
        deta=ho.deta,
        assa=ho.assa,
        loca=ho.loca,
        hota_detail=ho,
    )


# ----------------------------------------------------------------------------------------------- MOTChallenge files


def average(evaluations: Sequence[Evaluation]) -> dict[str, Any]:
    """Mean, minimum, maximum and standard deviation of the scalar metrics over several runs (e.g. seeds; the paper
    averages six per sequence).

    Values that are ``None`` or NaN (e.g. ``motp`` with nothing matched, ``classification_accuracy`` without
    classes) are left out of a metric's statistics; ``n`` says how many runs contributed.

    Args:
        evaluations: Evaluations of runs of one sequence.

    Returns:
        ``{"runs": R, metric: {"mean": m, "min": lo, "max": hi, "std": s, "n": n}, ...}`` for every name in
        :data:`SCALAR_METRICS` (``std``: the sample standard deviation, ``n - 1`` in the denominator, 0 for one run);
        ``mean``/``min``/``max``/``std`` are ``None`` when ``n`` is 0. JSON-ready.

    Raises:
        ConfigError: ``evaluations`` is empty.
    """
    runs = list(evaluations)
    if not runs:
        raise ConfigError("average() needs at least one evaluation")
    out: dict[str, Any] = {"runs": len(runs)}
    for name in SCALAR_METRICS:
        values = [float(v) for v in (getattr(e, name) for e in runs) if v is not None and math.isfinite(float(v))]
        if values:
            mean = math.fsum(values) / len(values)
            var = math.fsum((v - mean) ** 2 for v in values) / (len(values) - 1) if len(values) > 1 else 0.0
            out[name] = {"mean": mean, "min": min(values), "max": max(values), "std": math.sqrt(var), "n": len(values)}
        else:
            out[name] = {"mean": None, "min": None, "max": None, "std": None, "n": 0}
    return out
