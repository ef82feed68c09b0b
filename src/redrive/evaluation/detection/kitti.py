"""``kitti_detection``: KITTI 3D and BEV average precision (R40) on a run.

Definition: the KITTI object benchmark as implemented by mmdetection3d
``mmdet3d/evaluation/functional/kitti_utils/eval.py`` (from second.pytorch ``kitti_common``/
``eval.py``): ``compute_statistics_jit``, ``get_thresholds``, ``eval_class``, ``get_mAP40``;
overlaps ``bev_box_overlap`` / ``d3_box_overlap`` (exact rotated-rectangle intersection, here
:mod:`.iou`).  Per class and metric (BEV, 3D):

1. Per frame, ground truths in label order each take, among the class's detections not assigned
   yet with overlap ``> min_overlap`` (strictly), the one with the **highest score** (first pass,
   ``compute_fp=False``); the scores of these true positives give, through ``get_thresholds``,
   up to 41 score thresholds at recall ≈ 0, 1/40, …, 1.
2. For every threshold: detections scoring below it are dropped; ground truths in label order take
   the free detection of **highest overlap** ``> min_overlap``; unmatched valid ground truth = FN,
   unassigned detections = FP; precision = TP/(TP+FP), recall = TP/(TP+FN), summed over frames.
3. precision[i] = max(precision[i:]); AP_R40 = Σ precision[1..40] / 40 (KITTI prints ×100; here a
   fraction in [0, 1]).

Differences, because the data model lacks what they need:

* **One difficulty level ("all")**: KITTI's easy/moderate/hard filter on 2D box height,
  occlusion and truncation, which redrive's objects do not carry; nothing is ignored for
  difficulty, and detections are not filtered on 2D height.
* **DontCare** regions only change 2D-box evaluation (``metric == 0``), not BEV/3D; redrive's
  KITTI reader drops them.  KITTI's "similar class" rule (Van for Car, Person_sitting for
  Pedestrian: neither TP, FN nor FP) is ``ignored_classes``; redrive's reader already merges Van
  into vehicle and Person_sitting into pedestrian, so the default ignores nothing.
* KITTI labels cover the front camera's view only; with detections from a 360° LiDAR, set
  ``max_azimuth_deg`` (e.g. 45) so objects outside that view (ground truth and detections alike)
  are left out.  Default: everything.

Frames: every frame with ground truth; a failed detector step counts as no detections.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from redrive.evaluation.base import EvalData, Metric, MetricResult
from redrive.evaluation.detection.arrays import class_codes, objects_to_arrays
from redrive.evaluation.detection.classes import KITTI_CLASSES, KITTI_MIN_OVERLAP
from redrive.evaluation.detection.iou import bev_iou_pairs, iou_3d_pairs
from redrive.evaluation.detection.matching import PaddedFrames, pad_by_frame
from redrive.types import ObjectColumns, Role

__all__ = [
    "KittiClassResult",
    "KittiDetection",
    "evaluate_kitti_class",
    "get_thresholds",
    "padded_overlaps",
]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]

#: KITTI's N_SAMPLE_PTS: 41 recall positions, the first (recall 0) left out of R40.
N_SAMPLE_PTS = 41


def get_thresholds(scores: F64, num_gt: int, num_sample_pts: int = N_SAMPLE_PTS) -> F64:
    """Score thresholds at recall ≈ 0, 1/40, … (``kitti_utils/eval.py::get_thresholds``)."""
    s = np.sort(np.asarray(scores, dtype=np.float64))[::-1]
    current_recall = 0.0
    thresholds: list[float] = []
    n = len(s)
    for i, score in enumerate(s):  # one pass over the true positives (not over box pairs)
        l_recall = (i + 1) / num_gt
        r_recall = (i + 2) / num_gt if i < n - 1 else l_recall
        if (r_recall - current_recall) < (current_recall - l_recall) and i < n - 1:
            continue
        thresholds.append(float(score))
        current_recall += 1 / (num_sample_pts - 1.0)
    return np.array(thresholds, dtype=np.float64)


def padded_overlaps(
    gt: ObjectColumns, pred: ObjectColumns, gp: PaddedFrames, dp: PaddedFrames, *, kind: str
) -> F64:
    """(F, D, G) overlap of the k-th detection and the g-th ground truth of every frame (0 in
    empty slots); ``kind`` "bev" or "3d"."""
    n_f, n_d = dp.index.shape
    n_g = gp.index.shape[1]
    out = np.zeros((n_f, n_d, n_g))
    both = dp.valid[:, :, None] & gp.valid[:, None, :]
    f, d, g = np.nonzero(both)
    if f.size == 0:
        return out
    pi, gi = dp.index[f, d], gp.index[f, g]
    p7 = np.c_[pred.center_m, pred.size_m, pred.yaw_rad]
    g7 = np.c_[gt.center_m, gt.size_m, gt.yaw_rad]
    if kind == "bev":
        iou = bev_iou_pairs(p7[pi][:, [0, 1, 3, 4, 6]], g7[gi][:, [0, 1, 3, 4, 6]])
    else:
        iou = iou_3d_pairs(p7[pi], g7[gi])
    out[f, d, g] = iou
    return out


def _statistics(
    overlap: F64,
    det_ok: B,
    score: F64,
    gt_state: I64,
    *,
    min_overlap: float,
    thresh: float,
    compute_fp: bool,
) -> tuple[I64, I64, I64, F64]:
    """``compute_statistics_jit`` for all frames at once.

    Args:
        overlap: (F, D, G) detection × ground-truth overlaps.
        det_ok: (F, D) a detection of the class in this slot.
        score: (F, D) its score.
        gt_state: (F, G) 0 = valid ground truth, 1 = ignored (similar class), −1 = none.

    Returns:
        per-frame tp, fp, fn (F,) and the scores of the true positives (pass 1).
    """
    n_f, _ = det_ok.shape
    rows = np.arange(n_f)
    active = det_ok & (score >= thresh) if compute_fp else det_ok.copy()
    assigned = np.zeros_like(det_ok)
    tp = np.zeros(n_f, np.int64)
    fn = np.zeros(n_f, np.int64)
    tp_scores: list[F64] = []
    n_g = gt_state.shape[1] if det_ok.shape[1] else 0  # no detections: nothing to assign
    fn = np.sum(gt_state == 0, axis=1).astype(np.int64) if n_g == 0 else fn
    for g in range(n_g):
        state = gt_state[:, g]
        cand = active & ~assigned & (overlap[:, :, g] > min_overlap)
        key = overlap[:, :, g] if compute_fp else score
        j = np.argmax(np.where(cand, key, -np.inf), axis=1)  # first of equals, like the jit
        found = cand[rows, j] & (state >= 0)
        fn += (~found & (state == 0)).astype(np.int64)
        assigned[rows[found], j[found]] = True
        is_tp = found & (state == 0)
        tp += is_tp.astype(np.int64)
        tp_scores.append(score[rows[is_tp], j[is_tp]])
    fp = (
        (active & ~assigned).sum(axis=1).astype(np.int64) if compute_fp else np.zeros(n_f, np.int64)
    )
    scores = np.concatenate(tp_scores) if tp_scores else np.zeros(0)
    return tp, fp, fn, scores


@dataclass(frozen=True, slots=True, kw_only=True)
class KittiClassResult:
    """One class, one overlap kind.

    Attributes:
        ap_r40: AP over 40 recall positions, in [0, 1]; NaN without ground truth and detections.
        precision, recall: (41,) after KITTI's running maximum (zeros past the thresholds).
        thresholds: the score thresholds used.
        tp, fp, fn: per-frame counts with every detection (threshold 0).
        num_gt: valid ground truths.
    """

    ap_r40: float
    precision: F64
    recall: F64
    thresholds: F64
    tp: I64
    fp: I64
    fn: I64
    num_gt: int


def evaluate_kitti_class(
    gt: ObjectColumns,
    pred: ObjectColumns,
    frames: I64,
    *,
    gt_state: I64,
    det_ok: B,
    min_overlap: float,
    kind: str,
) -> KittiClassResult:
    """KITTI AP_R40 of one class (``eval_class`` + ``get_mAP40`` for one difficulty).

    Args:
        gt, pred: all boxes of the evaluated frames.
        frames: the evaluated frames, increasing.
        gt_state: (G,) 0 valid ground truth of the class, 1 ignored (similar class), −1 other.
        det_ok: (P,) detection of the class.
        min_overlap: overlap a match must exceed.
        kind: "bev" or "3d".
    """
    g_rows, d_rows = np.flatnonzero(gt_state >= 0), np.flatnonzero(det_ok)
    g_c, p_c = gt.take(g_rows), pred.take(d_rows)
    state_c = gt_state[g_rows]
    gp, dp = pad_by_frame(g_c.frame_index, frames), pad_by_frame(p_c.frame_index, frames)
    overlap = padded_overlaps(g_c, p_c, gp, dp, kind=kind)
    state = np.where(gp.valid, state_c[np.maximum(gp.index, 0)], -1)
    score = np.where(dp.valid, p_c.confidence[np.maximum(dp.index, 0)], -np.inf)
    num_gt = int(np.sum(state_c == 0))
    _, _, _, tp_scores = _statistics(
        overlap, dp.valid, score, state, min_overlap=min_overlap, thresh=0.0, compute_fp=False
    )
    thresholds = get_thresholds(tp_scores, num_gt) if tp_scores.size else np.zeros(0)
    precision = np.zeros(N_SAMPLE_PTS)
    recall = np.zeros(N_SAMPLE_PTS)
    for i, th in enumerate(thresholds[:N_SAMPLE_PTS]):
        tp, fp, fn, _ = _statistics(
            overlap, dp.valid, score, state, min_overlap=min_overlap, thresh=th, compute_fp=True
        )
        t, f, n = float(tp.sum()), float(fp.sum()), float(fn.sum())
        recall[i] = t / (t + n)
        precision[i] = t / (t + f)
    precision = np.maximum.accumulate(precision[::-1])[::-1]
    recall = np.maximum.accumulate(recall[::-1])[::-1]
    ap = float(np.sum(precision[1:]) / 40.0)
    if num_gt == 0 and d_rows.size == 0:
        ap = math.nan
    tp0, fp0, fn0, _ = _statistics(
        overlap, dp.valid, score, state, min_overlap=min_overlap, thresh=-np.inf, compute_fp=True
    )
    return KittiClassResult(
        ap_r40=ap,
        precision=precision,
        recall=recall,
        thresholds=thresholds,
        tp=tp0,
        fp=fp0,
        fn=fn0,
        num_gt=num_gt,
    )


def _in_view(boxes: ObjectColumns, max_azimuth_deg: float | None) -> B:
    if max_azimuth_deg is None:
        return np.ones(len(boxes), dtype=bool)
    az = np.degrees(np.abs(np.arctan2(boxes.center_m[:, 1], boxes.center_m[:, 0])))
    return np.asarray(az <= float(max_azimuth_deg), dtype=bool)


class KittiDetection(Metric):
    """KITTI 3D and BEV AP (40 recall positions), one difficulty level ("all").

    Parameters (``defaults``):
        classes: KITTI class → ObjectClass values that count as it
            ({"car": ["vehicle"], "pedestrian": ["pedestrian"], "cyclist": ["bicycle"]}).
        min_overlap_3d, min_overlap_bev: class → IoU a match must exceed (0.7 car, 0.5 others).
        ignored_classes: class → ObjectClass values whose ground truth is ignored (KITTI's
            Van/Person_sitting rule); default none.
        max_azimuth_deg: keep only objects with |atan2(y, x)| ≤ this (camera view); None = all.

    Values: ``mAP3D`` (headline), ``mAPBEV``, ``AP3D/<class>``, ``APBEV/<class>``,
    ``recall3D/<class>``, ``recallBEV/<class>`` (with every detection), ``gt/<class>``; curves ``PR3D/<class>``,
    ``PRBEV/<class>`` (recall, precision at the thresholds); per frame (3D, every detection):
    ``tp``, ``fp``, ``missed``.
    """

    name = "kitti_detection"
    pooling = "concatenate"
    version = "1"
    role = Role.PERCEPTION
    needs = frozenset({"detections", "ground_truth"})
    unit = ""
    higher_is_better = True
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            "classes": {k: list(v) for k, v in KITTI_CLASSES.items()},
            "min_overlap_3d": dict(KITTI_MIN_OVERLAP),
            "min_overlap_bev": dict(KITTI_MIN_OVERLAP),
            "ignored_classes": {},
            "max_azimuth_deg": None,
        }
    )

    def evaluate(self, data: EvalData) -> MetricResult:
        gt_by_frame = data.ground_truth()
        frames = np.array(sorted(gt_by_frame), dtype=np.int64)
        gt = objects_to_arrays(gt_by_frame, frames.tolist())
        pred = objects_to_arrays(data.detections(), frames.tolist())
        return self.evaluate_arrays(gt, pred, frames)

    def evaluate_arrays(self, gt: ObjectColumns, pred: ObjectColumns, frames: I64) -> MetricResult:
        """The metric on boxes already in columns (``frames``: the evaluated frames)."""
        p = self.params
        gt = gt.take(_in_view(gt, p["max_azimuth_deg"]))
        pred = pred.take(_in_view(pred, p["max_azimuth_deg"]))
        classes: Mapping[str, Sequence[str]] = p["classes"]
        ignored: Mapping[str, Sequence[str]] = p["ignored_classes"]
        values: dict[str, float] = {"mAP3D": math.nan, "mAPBEV": math.nan}
        units: dict[str, str] = {}
        curves: dict[str, tuple[F64, F64]] = {}
        n_f = frames.size
        tp_f, fp_f, fn_f = (np.zeros(n_f) for _ in range(3))
        means: dict[str, list[float]] = {"3D": [], "BEV": []}
        gt_codes, pred_codes = gt.class_code(), pred.class_code()
        for cls, members in classes.items():
            state = np.full(len(gt), -1, dtype=np.int64)
            state[np.isin(gt_codes, class_codes(ignored.get(cls, ())))] = 1
            state[np.isin(gt_codes, class_codes(members))] = 0
            det_ok = np.isin(pred_codes, class_codes(members))
            for label, kind, key in (
                ("3D", "3d", "min_overlap_3d"),
                ("BEV", "bev", "min_overlap_bev"),
            ):
                res = evaluate_kitti_class(
                    gt, pred, frames, gt_state=state, det_ok=det_ok,
                    min_overlap=float(p[key][cls]), kind=kind,
                )  # fmt: skip
                values[f"AP{label}/{cls}"] = res.ap_r40
                n = res.thresholds.size
                if not math.isnan(res.ap_r40):
                    means[label].append(res.ap_r40)
                    curves[f"PR{label}/{cls}"] = (res.recall[:n], res.precision[:n])
                t, m = res.tp.sum(), res.fn.sum()
                values[f"recall{label}/{cls}"] = float(t / (t + m)) if t + m else math.nan
                if label == "3D":
                    values[f"gt/{cls}"] = float(res.num_gt)
                    units[f"gt/{cls}"] = "objects"
                    tp_f += res.tp
                    fp_f += res.fp
                    fn_f += res.fn
        for label in ("3D", "BEV"):
            if means[label]:
                values[f"mAP{label}"] = float(np.mean(means[label]))
        return MetricResult(
            values=values,
            units=units,
            higher_is_better={k: None for k in values if k.startswith("gt/")},  # counts
            curves=curves,
            per_frame={"tp": (frames, tp_f), "fp": (frames, fp_f), "missed": (frames, fn_f)},
        )
