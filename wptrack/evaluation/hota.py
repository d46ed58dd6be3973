"""HOTA (Luiten et al., IJCV 2020) on the ground plane: the alignment-weighted matching, DetA, AssA, LocA and their
recall/precision parts, from two tables of ground positions (see :mod:`wptrack.evaluation.mot` for the definitions).

**HOTA** (Luiten et al., *HOTA: A Higher Order Metric for Evaluating Multi-Object Tracking*, IJCV 2020), on the
ground plane with a distance similarity ``S = max(0, 1 - d / threshold)`` (``d`` the ground-plane distance above, in
metres; 1 at the same point, 0 at the threshold and beyond) in place of the paper's box IoU (:func:`hota`):

* Matching (paper section 5; the authors' TrackEval does the same): per frame, one Hungarian assignment maximising
  ``A_global(o, h) * S(o, h)``, where ``A_global(o, h) = P / (n_o + n_h - P)`` is the soft association IoU of the two
  identities over the whole sequence (``n_o``, ``n_h``: their frames; ``P``: their summed per-frame soft overlaps
  ``S / (sum_h' S(o, h') + sum_o' S(o', h) - S)``), so that the matching prefers pairs that stay together. For a
  threshold ``alpha`` the pairs of that assignment with ``S >= alpha`` are the true positives ``TP_alpha``; the other
  objects are misses (FN), the other hypotheses false positives (FP).
* ``DetA_alpha = |TP| / (|TP| + |FN| + |FP|)``; per true positive ``c``, ``A(c) = |TPA(c)| / (|TPA(c)| + |FNA(c)| +
  |FPA(c)|)`` with TPA the true positives of the same object and hypothesis ids, FNA the object's other frames,
  FPA the hypothesis's other frames; ``AssA_alpha`` = mean of ``A(c)`` over ``TP_alpha`` (0 without true positives);
  ``HOTA_alpha = sqrt(DetA_alpha AssA_alpha)`` (paper eqs. 3-9).
* ``HOTA``, ``DetA``, ``AssA`` (and the recall/precision parts ``DetRe``, ``DetPr``, ``AssRe``, ``AssPr``) are the
  means over ``alpha = 0.05, 0.10, ..., 0.95`` (eq. 10); ``LocA`` is the mean similarity of the true positives,
  averaged over the alphas that have any (NaN when none has).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from wptrack.io.atomic import jsonable

if TYPE_CHECKING:
    from wptrack.evaluation.mot import _Table

HOTA_ALPHAS = tuple(round(0.05 * k, 2) for k in range(1, 20))
"""The localisation thresholds alpha = 0.05, 0.10, ..., 0.95 HOTA averages over (paper eq. 10)."""


@dataclasses.dataclass(frozen=True)
class HotaResult:
    """HOTA and its parts on the ground plane (see the module docstring); each scalar is the mean over
    :data:`HOTA_ALPHAS`, each ``*_alpha`` tuple holds the 19 per-alpha values.

    Attributes:
        hota, deta, assa: HOTA, detection accuracy, association accuracy (eqs. 3-10), in [0, 1].
        detre, detpr: detection recall TP / (TP + FN) and precision TP / (TP + FP).
        assre, asspr: association recall and precision (the mean over TP of TPA / (TPA + FNA), TPA / (TPA + FPA)).
        loca: mean similarity of the true positives, over the alphas that have any (NaN when none has).
        alphas: the thresholds.
        threshold: distance (metres) at which the similarity reaches 0.
    """

    hota: float
    deta: float
    assa: float
    detre: float
    detpr: float
    assre: float
    asspr: float
    loca: float
    hota_alpha: tuple[float, ...]
    deta_alpha: tuple[float, ...]
    assa_alpha: tuple[float, ...]
    alphas: tuple[float, ...]
    threshold: float

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict (NaN as None)."""
        return jsonable(dataclasses.asdict(self))


def _hota_tables(gt: _Table, hyp: _Table, eval_frames: np.ndarray, threshold: float) -> HotaResult:
    """HOTA of two validated tables restricted to ``eval_frames`` (see the module docstring)."""
    from scipy.optimize import linear_sum_assignment

    alphas = np.asarray(HOTA_ALPHAS, dtype=np.float64)
    gt_ids, gt_codes = np.unique(gt.ids, return_inverse=True)
    hyp_ids, hyp_codes = np.unique(hyp.ids, return_inverse=True)
    ng, nh = len(gt_ids), len(hyp_ids)
    gt_count = np.bincount(gt_codes, minlength=ng).astype(np.float64)
    hyp_count = np.bincount(hyp_codes, minlength=nh).astype(np.float64)
    g0s, g1s = np.searchsorted(gt.frame, eval_frames, "left"), np.searchsorted(gt.frame, eval_frames, "right")
    h0s, h1s = np.searchsorted(hyp.frame, eval_frames, "left"), np.searchsorted(hyp.frame, eval_frames, "right")

    def similarity(g0: int, g1: int, h0: int, h1: int) -> np.ndarray:
        d = np.linalg.norm(gt.xy[g0:g1, None, :] - hyp.xy[None, h0:h1, :], axis=2)
        return np.maximum(0.0, 1.0 - d / threshold)

    # the identities' soft association over the whole sequence (the matching's preference for lasting pairs)
    potential = np.zeros((ng, nh))
    frames = list(zip(g0s.tolist(), g1s.tolist(), h0s.tolist(), h1s.tolist(), strict=True))
    for g0, g1, h0, h1 in frames:
        if g1 == g0 or h1 == h0:
            continue
        sim = similarity(g0, g1, h0, h1)
        denom = sim.sum(axis=0, keepdims=True) + sim.sum(axis=1, keepdims=True) - sim
        soft = np.divide(sim, denom, out=np.zeros_like(sim), where=denom > 1e-12)
        np.add.at(potential, (gt_codes[g0:g1, None], hyp_codes[None, h0:h1]), soft)
    alignment = potential / np.maximum(gt_count[:, None] + hyp_count[None, :] - potential, 1e-12)

    # one assignment per frame; each alpha keeps its pairs with S >= alpha
    pair_g, pair_h, pair_s = [], [], []
    for g0, g1, h0, h1 in frames:
        if g1 == g0 or h1 == h0:
            continue
        sim = similarity(g0, g1, h0, h1)
        rows, cols = linear_sum_assignment(-(alignment[gt_codes[g0:g1, None], hyp_codes[None, h0:h1]] * sim))
        keep = sim[rows, cols] > 0.0
        pair_g.append(gt_codes[g0 + rows[keep]])
        pair_h.append(hyp_codes[h0 + cols[keep]])
        pair_s.append(sim[rows[keep], cols[keep]])
    pg = np.concatenate(pair_g) if pair_g else np.zeros(0, np.int64)
    ph = np.concatenate(pair_h) if pair_h else np.zeros(0, np.int64)
    ps = np.concatenate(pair_s) if pair_s else np.zeros(0)

    n_gt, n_hyp = float(gt_count.sum()), float(hyp_count.sum())
    per = {k: np.zeros(len(alphas)) for k in ("hota", "deta", "assa", "detre", "detpr", "assre", "asspr", "loca")}
    for a, alpha in enumerate(alphas):
        sel = ps >= alpha - 1e-9
        tp = float(sel.sum())
        fn, fp = n_gt - tp, n_hyp - tp
        per["deta"][a] = tp / (tp + fn + fp) if tp + fn + fp > 0 else 0.0
        per["detre"][a] = tp / n_gt if n_gt else 0.0
        per["detpr"][a] = tp / n_hyp if n_hyp else 0.0
        if tp > 0:
            keys, counts = np.unique(pg[sel] * nh + ph[sel], return_counts=True)
            g, h, c = keys // nh, keys % nh, counts.astype(np.float64)
            per["assa"][a] = float(np.sum(c * c / (gt_count[g] + hyp_count[h] - c))) / tp
            per["assre"][a] = float(np.sum(c * c / gt_count[g])) / tp
            per["asspr"][a] = float(np.sum(c * c / hyp_count[h])) / tp
            per["loca"][a] = float(ps[sel].mean())
        else:
            per["loca"][a] = np.nan
        per["hota"][a] = math.sqrt(per["deta"][a] * per["assa"][a])
    loca = per["loca"][np.isfinite(per["loca"])]
    return HotaResult(
        hota=float(per["hota"].mean()),
        deta=float(per["deta"].mean()),
        assa=float(per["assa"].mean()),
        detre=float(per["detre"].mean()),
        detpr=float(per["detpr"].mean()),
        assre=float(per["assre"].mean()),
        asspr=float(per["asspr"].mean()),
        loca=float(loca.mean()) if loca.size else math.nan,
        hota_alpha=tuple(float(v) for v in per["hota"]),
        deta_alpha=tuple(float(v) for v in per["deta"]),
        assa_alpha=tuple(float(v) for v in per["assa"]),
        alphas=HOTA_ALPHAS,
        threshold=threshold,
    )
