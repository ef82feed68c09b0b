"""Plain-number and label metrics any algorithm output can be scored with, and object attributes.

The functions follow the textbook definitions (as in scikit-learn's ``accuracy_score``,
``precision_recall_fscore_support`` and ``mean_squared_error``) except for undefined cases,
which are NaN here instead of scikit-learn's ``zero_division`` 0 with a warning:

* ``accuracy`` = #(predicted == truth) / N; NaN when N = 0.
* precision = TP / (TP + FP), NaN when nothing is predicted positive; recall = TP / (TP + FN),
  NaN when nothing is truly positive; F1 = 2PR / (P + R), NaN when P or R is NaN, 0 when both
  are 0.
* macro averages: the unweighted mean over classes of the defined (non-NaN) per-class values;
  NaN when none is defined. micro averages: precision, recall and F1 from the TP, FP, FN summed
  over classes (for single-label data all three equal the accuracy).
* ``rmse`` = sqrt(mean((p − t)²)), ``mae`` = mean(|p − t|), over all elements; NaN when empty.

:class:`ObjectAttributes` (``object_attributes``) matches detections to ground truth per frame by
bird's-eye-view centre distance — the optimal one-to-one assignment (Hungarian,
``scipy.optimize.linear_sum_assignment``) among pairs within ``max_distance_m`` (2 m, nuScenes'
middle threshold) — and scores the attributes of the matched pairs.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment

from redrive.errors import ConfigError
from redrive.evaluation._kinematics import wrap_angle
from redrive.evaluation.base import EvalData, Metric, MetricResult
from redrive.types import DetectedObject, Role

__all__ = [
    "ClassScores",
    "ObjectAttributes",
    "accuracy",
    "mae",
    "match_by_centre",
    "per_class_scores",
    "precision_recall",
    "rmse",
]


def _labels(x: Sequence[Hashable] | npt.ArrayLike) -> list[Hashable]:
    return list(np.asarray(x, dtype=object).reshape(-1).tolist())


def _same_length(predicted: list[Hashable], truth: list[Hashable], what: str) -> None:
    if len(predicted) != len(truth):
        msg = f"{what}: {len(predicted)} predictions but {len(truth)} truths; pair them one to one"
        raise ValueError(msg)


def accuracy(
    predicted: Sequence[Hashable] | npt.ArrayLike, truth: Sequence[Hashable] | npt.ArrayLike
) -> float:
    """Fraction of labels equal to the truth; NaN for empty input.

    Raises:
        ValueError: the two have different lengths.
    """
    p, t = _labels(predicted), _labels(truth)
    _same_length(p, t, "accuracy")
    if not p:
        return math.nan
    return sum(a == b for a, b in zip(p, t, strict=True)) / len(p)


def _ratio(num: int, den: int) -> float:
    return num / den if den else math.nan


def _f1(precision: float, recall: float) -> float:
    if math.isnan(precision) or math.isnan(recall):
        return math.nan
    if precision + recall == 0:
        return 0.0
    return 2 * precision * recall / (precision + recall)


def precision_recall(
    labels: Sequence[Hashable] | npt.ArrayLike,
    truth: Sequence[Hashable] | npt.ArrayLike,
    *,
    positive: Hashable = True,
) -> tuple[float, float]:
    """(precision, recall) of the class ``positive``: TP / (TP + FP) and TP / (TP + FN).

    precision is NaN when no label is ``positive``; recall is NaN when no truth is.
    """
    p, t = _labels(labels), _labels(truth)
    _same_length(p, t, "precision_recall")
    tp = sum(a == positive and b == positive for a, b in zip(p, t, strict=True))
    predicted = sum(a == positive for a in p)
    actual = sum(b == positive for b in t)
    return _ratio(tp, predicted), _ratio(tp, actual)


@dataclass(frozen=True, slots=True, kw_only=True)
class ClassScores:
    """Per-class and averaged precision, recall and F1.

    Attributes:
        per_class: class → (precision, recall, F1, support = number of truths of the class).
        macro_precision, macro_recall, macro_f1: means over classes of the defined values.
        micro_precision, micro_recall, micro_f1: from TP, FP, FN summed over classes.
    """

    per_class: Mapping[Hashable, tuple[float, float, float, int]]
    macro_precision: float
    macro_recall: float
    macro_f1: float
    micro_precision: float
    micro_recall: float
    micro_f1: float


def _nanmean(values: Sequence[float]) -> float:
    defined = [v for v in values if not math.isnan(v)]
    return sum(defined) / len(defined) if defined else math.nan


def per_class_scores(
    labels: Sequence[Hashable] | npt.ArrayLike,
    truth: Sequence[Hashable] | npt.ArrayLike,
    *,
    classes: Sequence[Hashable] | None = None,
) -> ClassScores:
    """Precision, recall and F1 of every class (default: every label seen in either input, in
    sorted order when sortable), with macro and micro averages (see the module docstring)."""
    p, t = _labels(labels), _labels(truth)
    _same_length(p, t, "per_class_scores")
    if classes is None:
        seen = list(dict.fromkeys(t + p))
        with contextlib.suppress(TypeError):  # unorderable labels keep first-seen order
            seen = sorted(seen)  # type: ignore[type-var]
        classes = seen
    per: dict[Hashable, tuple[float, float, float, int]] = {}
    tp_sum = fp_sum = fn_sum = 0
    for c in classes:
        tp = sum(a == c and b == c for a, b in zip(p, t, strict=True))
        fp = sum(a == c and b != c for a, b in zip(p, t, strict=True))
        fn = sum(a != c and b == c for a, b in zip(p, t, strict=True))
        prec, rec = _ratio(tp, tp + fp), _ratio(tp, tp + fn)
        per[c] = (prec, rec, _f1(prec, rec), tp + fn)
        tp_sum, fp_sum, fn_sum = tp_sum + tp, fp_sum + fp, fn_sum + fn
    micro_p, micro_r = _ratio(tp_sum, tp_sum + fp_sum), _ratio(tp_sum, tp_sum + fn_sum)
    return ClassScores(
        per_class=MappingProxyType(per),
        macro_precision=_nanmean([v[0] for v in per.values()]),
        macro_recall=_nanmean([v[1] for v in per.values()]),
        macro_f1=_nanmean([v[2] for v in per.values()]),
        micro_precision=micro_p,
        micro_recall=micro_r,
        micro_f1=_f1(micro_p, micro_r),
    )


def _pair(predicted: npt.ArrayLike, truth: npt.ArrayLike, what: str) -> npt.NDArray[np.float64]:
    p = np.asarray(predicted, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    if p.shape != t.shape:
        msg = f"{what}: predictions of shape {p.shape} and truths of shape {t.shape} differ"
        raise ValueError(msg)
    return np.asarray(p - t, dtype=np.float64)


def rmse(predicted: npt.ArrayLike, truth: npt.ArrayLike) -> float:
    """Root mean squared error over all elements; NaN when empty (NaN inputs propagate)."""
    d = _pair(predicted, truth, "rmse")
    return float(np.sqrt(np.mean(d**2))) if d.size else math.nan


def mae(predicted: npt.ArrayLike, truth: npt.ArrayLike) -> float:
    """Mean absolute error over all elements; NaN when empty (NaN inputs propagate)."""
    d = _pair(predicted, truth, "mae")
    return float(np.mean(np.abs(d))) if d.size else math.nan


def match_by_centre(
    detections: Sequence[DetectedObject],
    truth: Sequence[DetectedObject],
    *,
    max_distance_m: float = 2.0,
) -> list[tuple[int, int]]:
    """One-to-one (detection index, truth index) pairs minimising the total BEV centre distance
    (x, y of ``Box3D.center``) among pairs no farther than ``max_distance_m``."""
    if not detections or not truth:
        return []
    d = np.array([o.box.center[:2] for o in detections], dtype=np.float64)
    g = np.array([o.box.center[:2] for o in truth], dtype=np.float64)
    dist = np.hypot(d[:, None, 0] - g[None, :, 0], d[:, None, 1] - g[None, :, 1])
    allowed = dist <= max_distance_m
    # pairs beyond the gate get a cost larger than any sum of allowed ones, so the assignment
    # first maximises the number of allowed pairs, then minimises their total distance
    big = 1.0 + float(dist[allowed].sum()) if allowed.any() else 1.0
    cost = np.where(allowed, dist, big * (1 + min(dist.shape)))
    rows, cols = linear_sum_assignment(cost)
    return [(int(r), int(c)) for r, c in zip(rows, cols, strict=True) if allowed[r, c]]


class ObjectAttributes(Metric):
    """Attributes of detections matched to ground truth (see :func:`match_by_centre`).

    Parameters (defaults): ``max_distance_m`` 2.0.

    Values: ``class_accuracy`` (headline: fraction of matched pairs whose class agrees),
    ``precision/CLASS`` and ``recall/CLASS`` of the class label over the matched pairs (classes
    seen in either), ``macro_f1``, ``position_rmse_m`` (BEV centre, x and y),
    ``size_rmse_m`` (norm of the length/width/height difference), ``yaw_rmse_rad`` (difference
    wrapped to [−π, π)), ``velocity_rmse_mps`` (vx, vy), ``matched``,
    ``unmatched_detections``, ``unmatched_ground_truth``. Frames: those with ground truth; a
    frame where the algorithm's step failed counts as no detections. Per-frame series:
    ``matched``, ``position_rmse_m``.
    """

    name: ClassVar[str] = "object_attributes"
    pooling: ClassVar[str] = "concatenate"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = Role.PERCEPTION
    needs: ClassVar[frozenset[str]] = frozenset({"detections", "ground_truth"})
    unit: ClassVar[str] = "ratio"
    higher_is_better: ClassVar[bool] = True
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType({"max_distance_m": 2.0})

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        if not float(self.params["max_distance_m"]) > 0:
            msg = (
                "metric 'object_attributes': max_distance_m must be > 0, "
                f"got {self.params['max_distance_m']!r}"
            )
            raise ConfigError(msg)

    def evaluate(self, data: EvalData) -> MetricResult:
        gate = float(self.params["max_distance_m"])
        detections = data.detections()
        truth = data.ground_truth()
        pred_cls: list[str] = []
        true_cls: list[str] = []
        dpos: list[npt.NDArray[np.float64]] = []
        dsize: list[npt.NDArray[np.float64]] = []
        dyaw: list[float] = []
        dvel: list[npt.NDArray[np.float64]] = []
        unmatched_det = unmatched_gt = 0
        frames: list[int] = []
        matched_per_frame: list[float] = []
        pos_rmse_per_frame: list[float] = []
        for frame in sorted(truth):
            gts = truth[frame]
            dets = detections.get(frame, ())
            pairs = match_by_centre(dets, gts, max_distance_m=gate)
            unmatched_det += len(dets) - len(pairs)
            unmatched_gt += len(gts) - len(pairs)
            frame_pos: list[npt.NDArray[np.float64]] = []
            for i, j in pairs:
                d, g = dets[i], gts[j]
                pred_cls.append(d.object_class.value)
                true_cls.append(g.object_class.value)
                frame_pos.append(d.box.center[:2] - g.box.center[:2])
                dsize.append(d.box.size - g.box.size)
                dyaw.append(float(wrap_angle(d.box.yaw_rad - g.box.yaw_rad)))
                dvel.append(d.velocity[:2] - g.velocity[:2])
            dpos.extend(frame_pos)
            frames.append(frame)
            matched_per_frame.append(float(len(pairs)))
            pos_rmse_per_frame.append(_norm_rmse(frame_pos))
        values: dict[str, float] = {"class_accuracy": accuracy(pred_cls, true_cls)}
        scores = per_class_scores(pred_cls, true_cls)
        for cls, (prec, rec, _, _) in scores.per_class.items():
            values[f"precision/{cls}"] = prec
            values[f"recall/{cls}"] = rec
        values["macro_f1"] = scores.macro_f1
        values["position_rmse_m"] = _norm_rmse(dpos)
        values["size_rmse_m"] = _norm_rmse(dsize)
        values["yaw_rmse_rad"] = rmse(np.array(dyaw), np.zeros(len(dyaw)))
        values["velocity_rmse_mps"] = _norm_rmse(dvel)
        values["matched"] = float(len(pred_cls))
        values["unmatched_detections"] = float(unmatched_det)
        values["unmatched_ground_truth"] = float(unmatched_gt)
        units = {
            "position_rmse_m": "m",
            "size_rmse_m": "m",
            "yaw_rmse_rad": "rad",
            "velocity_rmse_mps": "m/s",
            "matched": "pairs",
            "unmatched_detections": "objects",
            "unmatched_ground_truth": "objects",
        }
        idx = np.array(frames, dtype=np.int64)
        errors = ("position_rmse_m", "size_rmse_m", "yaw_rmse_rad", "velocity_rmse_mps")
        directions: dict[str, bool | None] = dict.fromkeys(errors, False)
        directions.update(unmatched_detections=False, unmatched_ground_truth=False, matched=None)
        return MetricResult(
            values=values,
            units=units,
            higher_is_better=directions,
            per_frame={
                "matched": (idx, np.array(matched_per_frame)),
                "position_rmse_m": (idx, np.array(pos_rmse_per_frame)),
            },
        )


def _norm_rmse(diffs: Sequence[npt.NDArray[np.float64]]) -> float:
    """sqrt(mean over vectors of their squared norm); NaN when empty."""
    if not diffs:
        return math.nan
    d = np.asarray(diffs, dtype=np.float64)
    return float(np.sqrt(np.mean(np.sum(d**2, axis=-1))))
