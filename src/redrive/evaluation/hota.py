"""HOTA: Higher Order Tracking Accuracy, and its parts DetA, AssA, LocA.

Definition: J. Luiten, A. Ošep, P. Dendorfer, P. Torr, A. Geiger, L. Leal-Taixé, B. Leibe,
"HOTA: A Higher Order Metric for Evaluating Multi-Object Tracking", IJCV 129, 2021, and its
reference implementation, TrackEval ``trackeval/metrics/hota.py`` ``HOTA.eval_sequence`` and
``HOTA._compute_final_fields``, which :func:`hota_sequence` follows step by step:

1. similarity ``S[g, p] ∈ [0, 1]`` of every (ground truth, prediction) pair of a frame;
2. global alignment score between ids over the whole sequence:
   ``A(g, p) = C(g, p) / (n_g + n_p − C(g, p))`` where ``C`` accumulates, per frame,
   ``S / (row sum + column sum − S)`` and ``n_g``, ``n_p`` count the frames each id is present;
3. per frame, the Hungarian matching maximising ``Σ A(g, p) · S(g, p)``;
4. for every ``α ∈ {0.05, 0.10, …, 0.95}``: matched pairs with ``S ≥ α`` are TPs, the other
   ground truth FNs, the other predictions FPs; ``LocA(α)`` is the mean ``S`` of the TPs;
   ``DetRe = TP / (TP + FN)``, ``DetPr = TP / (TP + FP)``, ``DetA = TP / (TP + FN + FP)``;
   with ``M(g, p)`` the TPs between two ids, ``AssA = Σ M · M / (n_g + n_p − M) / TP``,
   ``AssRe = Σ M · M / n_g / TP``, ``AssPr = Σ M · M / n_p / TP``;
   ``HOTA(α) = sqrt(DetA(α) · AssA(α))``;
5. the reported ``HOTA``, ``DetA`` … are the means over the 19 values of α (TrackEval's summary).

TrackEval's guards are kept (``max(1, ·)`` denominators, ``LocA = 1`` when one side is empty).
One choice of ours: when *both* sides are empty every value is NaN (undefined), where TrackEval
reports 0 for the sequence (and leaves such a class out of its class average).

Similarity (parameter ``similarity``):

* ``"distance"`` (default): ``max(0, 1 − d / zero_distance_m)`` with ``d`` the bird's-eye-view
  centre distance (x, y in ``base_link``), metres — TrackEval's
  ``_BaseDataset._calculate_euclidean_similarity`` with its default ``zero_distance = 2.0``
  (``α = 0.5`` ⇔ a 1 m match radius);
* ``"iou"``: oriented bird's-eye-view IoU (:func:`redrive.evaluation.tracking.bev_iou_matrix`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from redrive.evaluation.base import EvalData, Metric, MetricResult
from redrive.evaluation.tracking import (
    TrackFrame,
    bev_centre_distance_m,
    bev_iou_matrix,
    by_class,
    check_similarity,
    tracking_frames,
)
from redrive.types import Role

__all__ = ["ALPHAS", "Hota", "HotaResult", "hota_sequence"]

#: the localisation thresholds α, exactly TrackEval's ``np.arange(0.05, 0.99, 0.05)`` (19 values).
ALPHAS: npt.NDArray[np.float64] = np.arange(0.05, 0.99, 0.05)

_EPS = float(np.finfo(np.float64).eps)
#: the per-α fields, in the order they are reported.
FIELDS = ("HOTA", "DetA", "AssA", "LocA", "DetRe", "DetPr", "AssRe", "AssPr")


@dataclass(frozen=True, slots=True, kw_only=True)
class HotaResult:
    """HOTA of one sequence, per α.

    Attributes:
        alphas: (19,) the thresholds (:data:`ALPHAS`).
        scores: field name (:data:`FIELDS`) → (19,) float64 value per α.
        tp, fn, fp: (19,) float64 counts per α.
        frame_tp, frame_fn, frame_fp: (T, 19) float64 counts per frame and α.
    """

    alphas: npt.NDArray[np.float64]
    scores: Mapping[str, npt.NDArray[np.float64]]
    tp: npt.NDArray[np.float64]
    fn: npt.NDArray[np.float64]
    fp: npt.NDArray[np.float64]
    frame_tp: npt.NDArray[np.float64]
    frame_fn: npt.NDArray[np.float64]
    frame_fp: npt.NDArray[np.float64]

    def mean(self, name: str) -> float:
        """The value over all α (TrackEval's summary number)."""
        return float(np.mean(self.scores[name]))


def _relabel(ids: Sequence[npt.NDArray[np.int64]]) -> tuple[list[npt.NDArray[np.int64]], int]:
    """Map the ids of a sequence to 0 … n−1 (TrackEval's preprocessing)."""
    everything = np.concatenate(
        [np.asarray(i, dtype=np.int64) for i in ids] + [np.empty(0, np.int64)]
    )
    unique = np.unique(everything)
    return [np.searchsorted(unique, np.asarray(i, dtype=np.int64)) for i in ids], int(unique.size)


def hota_sequence(
    gt_ids: Sequence[npt.NDArray[np.int64]],
    pred_ids: Sequence[npt.NDArray[np.int64]],
    *,
    similarity: Sequence[npt.NDArray[np.float64]],
) -> HotaResult:
    """HOTA of one sequence (TrackEval ``HOTA.eval_sequence``).

    Args:
        gt_ids: per frame, (G_t,) ground-truth track ids (any integers, unique in a frame).
        pred_ids: per frame, (P_t,) predicted track ids.
        similarity: per frame, (G_t, P_t) similarity in [0, 1].
    """
    n_frames = len(gt_ids)
    if len(pred_ids) != n_frames or len(similarity) != n_frames:
        msg = "hota_sequence: gt_ids, pred_ids and similarity must have one entry per frame"
        raise ValueError(msg)
    n_alpha = ALPHAS.size
    gts, n_gt_ids = _relabel(gt_ids)
    preds, n_pred_ids = _relabel(pred_ids)
    sims = [
        np.asarray(s, dtype=np.float64).reshape(g.size, p.size)
        for s, g, p in zip(similarity, gts, preds, strict=True)
    ]
    num_gt = sum(g.size for g in gts)
    num_pred = sum(p.size for p in preds)
    tp = np.zeros(n_alpha)
    fn = np.zeros(n_alpha)
    fp = np.zeros(n_alpha)
    loc = np.zeros(n_alpha)
    frame_tp = np.zeros((n_frames, n_alpha))
    frame_fn = np.array([[g.size] * n_alpha for g in gts], dtype=np.float64).reshape(
        n_frames, n_alpha
    )
    frame_fp = np.array([[p.size] * n_alpha for p in preds], dtype=np.float64).reshape(
        n_frames, n_alpha
    )
    nan = np.full(n_alpha, np.nan)

    def result(scores: dict[str, npt.NDArray[np.float64]]) -> HotaResult:
        return HotaResult(
            alphas=ALPHAS.copy(),
            scores=MappingProxyType(scores),
            tp=tp,
            fn=fn,
            fp=fp,
            frame_tp=frame_tp,
            frame_fn=frame_fn,
            frame_fp=frame_fp,
        )

    if num_gt == 0 and num_pred == 0:
        return result({name: nan.copy() for name in FIELDS})
    if num_pred == 0 or num_gt == 0:  # TrackEval's early return
        fn[:] = num_gt
        fp[:] = num_pred
        zeros = np.zeros(n_alpha)
        scores = {name: zeros.copy() for name in FIELDS}
        scores["LocA"] = np.ones(n_alpha)
        return result(scores)

    # 1. global alignment between ids, accumulated over all frames
    potential = np.zeros((n_gt_ids, n_pred_ids))
    gt_count = np.zeros((n_gt_ids, 1))
    pred_count = np.zeros((1, n_pred_ids))
    for g, p, s in zip(gts, preds, sims, strict=True):
        denom = s.sum(0)[np.newaxis, :] + s.sum(1)[:, np.newaxis] - s
        sim_iou = np.zeros_like(s)
        mask = denom > 0 + _EPS
        sim_iou[mask] = s[mask] / denom[mask]
        potential[g[:, np.newaxis], p[np.newaxis, :]] += sim_iou
        gt_count[g] += 1
        pred_count[0, p] += 1
    alignment = potential / (gt_count + pred_count - potential)

    # 2. per-frame matching, counted per alpha
    matches = np.zeros((n_alpha, n_gt_ids, n_pred_ids))
    for t, (g, p, s) in enumerate(zip(gts, preds, sims, strict=True)):
        if g.size == 0:
            fp += p.size
            continue
        if p.size == 0:
            fn += g.size
            continue
        score = alignment[g[:, np.newaxis], p[np.newaxis, :]] * s
        rows, cols = linear_sum_assignment(-score)
        matched_sim = s[rows, cols]
        for a, alpha in enumerate(ALPHAS):
            ok = matched_sim >= alpha - _EPS
            n = int(ok.sum())
            tp[a] += n
            fn[a] += g.size - n
            fp[a] += p.size - n
            frame_tp[t, a] = n
            frame_fn[t, a] = g.size - n
            frame_fp[t, a] = p.size - n
            if n > 0:
                loc[a] += matched_sim[ok].sum()
                matches[a, g[rows[ok]], p[cols[ok]]] += 1

    # 3. association per alpha, then the final fields
    ass_a = np.zeros(n_alpha)
    ass_re = np.zeros(n_alpha)
    ass_pr = np.zeros(n_alpha)
    for a in range(n_alpha):
        m = matches[a]
        ass_a[a] = np.sum(m * (m / np.maximum(1, gt_count + pred_count - m))) / max(1.0, tp[a])
        ass_re[a] = np.sum(m * (m / np.maximum(1, gt_count))) / max(1.0, tp[a])
        ass_pr[a] = np.sum(m * (m / np.maximum(1, pred_count))) / max(1.0, tp[a])
    loc_a = np.maximum(1e-10, loc) / np.maximum(1e-10, tp)
    det_re = tp / np.maximum(1, tp + fn)
    det_pr = tp / np.maximum(1, tp + fp)
    det_a = tp / np.maximum(1, tp + fn + fp)
    return result(
        {
            "HOTA": np.sqrt(det_a * ass_a),
            "DetA": det_a,
            "AssA": ass_a,
            "LocA": loc_a,
            "DetRe": det_re,
            "DetPr": det_pr,
            "AssRe": ass_re,
            "AssPr": ass_pr,
        }
    )


class Hota(Metric):
    """HOTA (Luiten et al. 2021, TrackEval) of a tracker against the run's ground truth.

    Parameters (``Hota(**params)``):
        similarity: ``"distance"`` (default: ``max(0, 1 − d / zero_distance_m)``, ``d`` the BEV
            centre distance) or ``"iou"`` (oriented BEV IoU).
        zero_distance_m: distance at which the similarity reaches 0, metres (default 2.0,
            TrackEval's ``zero_distance``).
        by_class: also report the values per object class as ``NAME/class`` (default False).

    Values (means over α; headline first): ``HOTA``, ``DetA``, ``AssA``, ``LocA``, ``DetRe``,
    ``DetPr``, ``AssRe``, ``AssPr``, and ``HOTA@0.5`` … at α = 0.5.  Curves over α:
    ``HOTA(alpha)``, ``DetA(alpha)``, ``AssA(alpha)``, ``LocA(alpha)``.  Per frame at α = 0.5:
    ``tp@0.5``, ``fn@0.5``, ``fp@0.5``.  Frames: those of :func:`tracking_frames`.
    """

    name = "hota"
    pooling = "concatenate"
    version = "1"
    role = Role.PERCEPTION
    needs = frozenset({"detections", "ground_truth"})
    unit = ""
    higher_is_better = True
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {"similarity": "distance", "zero_distance_m": 2.0, "by_class": False}
    )

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        check_similarity(self.name, self.params, distance_key="zero_distance_m")

    def similarity(self, frame: TrackFrame) -> npt.NDArray[np.float64]:
        """(G, P) similarity in [0, 1] of one frame."""
        if self.params["similarity"] == "iou":
            return bev_iou_matrix(frame.gt, frame.pred)
        d = bev_centre_distance_m(frame.gt, frame.pred)
        out: npt.NDArray[np.float64] = np.maximum(
            0.0, 1.0 - d / float(self.params["zero_distance_m"])
        )
        return out

    def compute(self, frames: Sequence[TrackFrame]) -> HotaResult:
        """HOTA of the given frames (in order)."""
        return hota_sequence(
            [f.gt_ids for f in frames],
            [f.pred_ids for f in frames],
            similarity=[self.similarity(f) for f in frames],
        )

    def evaluate(self, data: EvalData) -> MetricResult:
        frames = tracking_frames(data)
        res = self.compute(frames)
        half = int(np.argmin(np.abs(ALPHAS - 0.5)))
        values = {name: res.mean(name) for name in FIELDS}
        values.update({f"{name}@0.5": float(res.scores[name][half]) for name in FIELDS[:3]})
        values["num_frames"] = float(len(frames))
        units = {"num_frames": "frames"}
        if self.params["by_class"]:
            for cls, sub in by_class(frames).items():
                r = self.compute(sub)
                values.update({f"{name}/{cls}": r.mean(name) for name in FIELDS})
        index = np.array([f.frame_index for f in frames], dtype=np.int64)
        return MetricResult(
            values=values,
            units=units,
            higher_is_better={"num_frames": None},
            per_frame={
                "tp@0.5": (index, res.frame_tp[:, half]),
                "fn@0.5": (index, res.frame_fn[:, half]),
                "fp@0.5": (index, res.frame_fp[:, half]),
            },
            curves={
                f"{name}(alpha)": (res.alphas, res.scores[name])
                for name in ("HOTA", "DetA", "AssA", "LocA")
            },
        )
