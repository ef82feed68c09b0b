"""The nuScenes detection definition on :class:`~redrive.types.ObjectColumns`, vectorised.

Ported from the nuScenes devkit (``python-sdk/nuscenes/eval/detection/algo.py``: ``accumulate``,
``calc_ap``, ``calc_tp``; ``eval/common/utils.py``: ``center_distance``, ``velocity_l2``,
``scale_iou``, ``yaw_diff``, ``angle_diff``, ``cummean``; ``eval/common/loaders.py``:
``filter_eval_boxes``; ``detection/data_classes.py``: ``DetectionMetricData``,
``DetectionMetrics.mean_ap`` / ``tp_errors`` / ``tp_scores`` / ``nd_score``; configuration
``detection_cvpr_2019.json``) — checked against devkit 1.2.0 to 1e-12 on random scenes.

Details that decide numbers:

* **Order of detections.**  The devkit sorts a class's predictions with
  ``sorted((conf, i) for i, conf in enumerate(confs))[::-1]`` — *not* ``np.argsort``: descending
  confidence, and among equal confidences the one listed **later** (larger index ``i`` over all
  frames, frames in increasing order, objects in their order) comes first.  Here:
  ``np.lexsort((index, confidence))[::-1]``, the same order.
* **Matching.**  In that order each detection takes the nearest ground truth of its class and
  frame not taken yet (BEV centre distance; the first such ground truth on equal distances); it is
  a true positive when that distance is ``< dist_th`` (strictly).  Frames are independent, so the
  greedy loop runs over the k-th detection of every frame at once (:mod:`.matching`).
* **Curves.**  Precision and confidence are interpolated on ``np.linspace(0, 1, 101)`` recall
  (``right=0``); TP errors are cumulative means (NaN-aware) re-sampled at those confidences.
* **AP** = mean of ``max(0, p − min_precision)`` over recall bins ``> min_recall`` (index
  ``round(100·min_recall) + 1`` on), divided by ``1 − min_precision``.  **TP errors** = mean over
  bins ``round(100·min_recall) + 1 … max_recall_ind``; 1.0 when the maximum recall is below.
* A class without ground truth (but with predictions) gets the devkit's "no predictions" data:
  AP 0, TP errors 1.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from redrive.evaluation.detection.matching import pad_by_frame
from redrive.types import CLASS_CODES, ObjectClass, ObjectColumns

__all__ = [
    "NELEM",
    "TP_METRICS",
    "MetricData",
    "NuScenesEvaluation",
    "angle_diff",
    "band_name",
    "calc_ap",
    "calc_tp",
    "center_distance_matching",
    "cummean",
    "evaluate_nuscenes",
    "nd_score_without_attributes",
]

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]

#: points of the interpolated curves (``DetectionMetricData.nelem``).
NELEM = 101
#: the TP errors redrive can compute (the devkit's ``attr_err`` needs attributes; see module doc).
TP_METRICS = ("trans_err", "scale_err", "orient_err", "vel_err")
#: value-name prefix of each TP error (the devkit prints mATE, mASE, mAOE, mAVE).
TP_SHORT = {"trans_err": "ATE", "scale_err": "ASE", "orient_err": "AOE", "vel_err": "AVE"}
TP_UNITS = {"trans_err": "m", "scale_err": "1-IoU", "orient_err": "rad", "vel_err": "m/s"}
#: padded distance tables are cut into chunks of about this many cells (cache-sized).
_CHUNK_CELLS = 200_000


@dataclass(frozen=True, slots=True, kw_only=True)
class MetricData:
    """The devkit's ``DetectionMetricData``: (101,) arrays over recall ``linspace(0, 1, 101)``."""

    recall: F64
    precision: F64
    confidence: F64
    errors: Mapping[str, F64]

    @property
    def max_recall_ind(self) -> int:
        """Index of the last bin with confidence > 0 (0 when none)."""
        nz = np.nonzero(self.confidence)[0]
        return int(nz[-1]) if nz.size else 0

    @classmethod
    def no_predictions(cls) -> MetricData:
        ones = np.ones(NELEM)
        return cls(
            recall=np.linspace(0, 1, NELEM),
            precision=np.zeros(NELEM),
            confidence=np.zeros(NELEM),
            errors={k: ones.copy() for k in TP_METRICS},
        )


def angle_diff(x_rad: F64, y_rad: F64, period_rad: float) -> F64:
    """Smallest signed difference from y to x with the given period (devkit ``angle_diff``)."""
    diff = np.mod(x_rad - y_rad + period_rad / 2, period_rad) - period_rad / 2
    return np.where(diff > np.pi, diff - 2 * np.pi, diff)


def cummean(x: F64) -> F64:
    """NaN-aware cumulative mean; all NaN → ones (devkit ``eval/common/utils.py::cummean``)."""
    nan = np.isnan(x)
    if nan.all():
        return np.ones(len(x))
    sum_vals = np.nancumsum(x.astype(float))
    count_vals = np.cumsum(~nan)
    out = np.divide(sum_vals, count_vals, out=np.zeros_like(sum_vals), where=count_vals != 0)
    return np.asarray(out, dtype=np.float64)


def calc_ap(md: MetricData, min_recall: float, min_precision: float) -> float:
    """Average precision (devkit ``algo.py::calc_ap``)."""
    prec = np.copy(md.precision)[round(100 * min_recall) + 1 :]
    prec -= min_precision
    prec[prec < 0] = 0
    return float(np.mean(prec)) / (1.0 - min_precision)


def calc_tp(md: MetricData, min_recall: float, metric_name: str) -> float:
    """A true-positive error averaged over the recall bins reached (devkit ``algo.py::calc_tp``)."""
    first_ind = round(100 * min_recall) + 1
    last_ind = md.max_recall_ind
    if last_ind < first_ind:
        return 1.0
    return float(np.mean(md.errors[metric_name][first_ind : last_ind + 1]))


def devkit_order(score: F64) -> I64:
    """Processing order of the devkit: ``sorted((conf, i) …)[::-1]`` (see module doc)."""
    n = score.shape[0]
    return np.asarray(np.lexsort((np.arange(n), score))[::-1], dtype=np.int64)


def center_distance_matching(
    gt: ObjectColumns, pred: ObjectColumns, *, order: I64, dist_ths_m: Sequence[float]
) -> I64:
    """Greedy BEV centre-distance matching of one class, for every threshold.

    Only ground truth nearer than the largest threshold can ever be matched, and the nearest
    *free* ground truth is a match iff it is nearer than the threshold — so each detection keeps
    its candidates within the largest threshold, sorted by (distance, ground-truth order), and
    takes the first free one under the threshold: the devkit's choice (first of equal minima).

    Args:
        gt, pred: ground truth and predictions of one class (rows sorted by frame).
        order: processing order of ``pred`` rows (:func:`devkit_order`).
        dist_ths_m: thresholds, metres; a match needs distance ``< th``.

    Returns:
        (T, P) int64: row of ``gt`` each prediction matched at each threshold; −1 = false positive.
    """
    n_th, n_pred = len(dist_ths_m), len(pred)
    out = np.full((n_th, n_pred), -1, dtype=np.int64)
    if n_pred == 0 or len(gt) == 0 or n_th == 0:
        return out
    frames = np.intersect1d(np.unique(pred.frame_index), np.unique(gt.frame_index))
    if frames.size == 0:
        return out
    max_th = max(float(t) for t in dist_ths_m)
    rank = np.empty(n_pred, dtype=np.int64)
    rank[order] = np.arange(n_pred)
    pp = pad_by_frame(pred.frame_index, frames, order_key=rank)
    gp = pad_by_frame(gt.frame_index, frames)
    # frames with the most detections first: the frames still busy at step k are a prefix
    busy = np.argsort(-pp.valid.sum(axis=1), kind="stable")
    pi, gi = pp.index[busy], gp.index[busy]
    n_f, width_p = pi.shape
    width_g = gi.shape[1]
    pxy, gxy = pred.center_m[:, :2], gt.center_m[:, :2]
    # candidate (frame, det slot, gt slot) triples within the largest threshold
    fs, ks, gs, ds = [], [], [], []
    step = max(1, _CHUNK_CELLS // max(1, width_p * width_g))
    for start in range(0, n_f, step):
        pc, gc = pi[start : start + step], gi[start : start + step]
        d = pxy[pc][:, :, None, :] - gxy[gc][:, None, :, :]
        dist = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1])
        near = (dist < max_th) & (pc >= 0)[:, :, None] & (gc >= 0)[:, None, :]
        f, k, g = np.nonzero(near)
        fs.append(f + start)
        ks.append(k)
        gs.append(g)
        ds.append(dist[f, k, g])
    f, k, g, dist_c = (np.concatenate(a) for a in (fs, ks, gs, ds))
    if f.size == 0:
        return out
    srt = np.lexsort((g, dist_c, k, f))
    f, k, g, dist_c = f[srt], k[srt], g[srt], dist_c[srt]
    cell = f * width_p + k
    first = np.r_[0, np.flatnonzero(np.diff(cell)) + 1]
    pos = np.arange(cell.size) - np.repeat(first, np.diff(np.r_[first, cell.size]))
    width_c = int(pos.max()) + 1
    cand_g = np.zeros((n_f, width_p, width_c), dtype=np.int64)
    cand_d = np.full((n_f, width_p, width_c), np.inf)
    cand_g[f, k, pos] = g
    cand_d[f, k, pos] = dist_c
    busy_count = (pi >= 0).sum(axis=0)  # frames with a detection in slot k (a prefix)
    for t, th in enumerate(dist_ths_m):
        taken = np.zeros((n_f, width_g + 1), dtype=bool)
        for slot in range(width_p):
            n = int(busy_count[slot])
            rows = np.arange(n)
            cg, cd = cand_g[:n, slot], cand_d[:n, slot]
            ok = (cd < th) & ~np.take_along_axis(taken[:n], cg, axis=1)
            j = np.argmax(ok, axis=1)
            hit = ok[rows, j]
            rows_h, g_h = rows[hit], cg[rows[hit], j[hit]]
            taken[rows_h, g_h] = True
            out[t, pi[rows_h, slot]] = gi[rows_h, g_h]
    return out


def _errors(
    gt: ObjectColumns, pred: ObjectColumns, gt_rows: I64, pred_rows: I64, class_name: str
) -> dict[str, F64]:
    d = pred.center_m[pred_rows, :2] - gt.center_m[gt_rows, :2]
    dv = pred.velocity_mps[pred_rows, :2] - gt.velocity_mps[gt_rows, :2]
    g_size, p_size = gt.size_m[gt_rows], pred.size_m[pred_rows]
    inter = np.prod(np.minimum(g_size, p_size), axis=1)
    union = np.prod(g_size, axis=1) + np.prod(p_size, axis=1) - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        iou = np.where(union > 0, inter / union, 0.0)
    period = np.pi if class_name == "barrier" else 2 * np.pi
    return {
        "trans_err": np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]),
        "vel_err": np.sqrt(dv[:, 0] * dv[:, 0] + dv[:, 1] * dv[:, 1]),
        "scale_err": 1.0 - iou,
        "orient_err": np.abs(angle_diff(gt.yaw_rad[gt_rows], pred.yaw_rad[pred_rows], period)),
    }


def accumulate(
    gt: ObjectColumns,
    pred: ObjectColumns,
    *,
    matched: I64,
    order: I64,
    class_name: str,
    with_errors: bool = True,
) -> MetricData:
    """Precision/recall and TP-error curves of one class at one threshold (devkit ``accumulate``).

    Args:
        gt, pred: that class's ground truth and predictions.
        matched: (P,) the ``gt`` row each prediction matched, −1 for none.
        order: processing order of the predictions (:func:`devkit_order`).
        with_errors: compute the TP-error curves (only those at ``dist_th_tp`` are ever used);
            without, ``errors`` is empty.
    """
    npos = len(gt)
    if npos == 0:
        return MetricData.no_predictions()
    matched_sorted = matched[order]
    is_tp = matched_sorted >= 0
    if not is_tp.any():
        return MetricData.no_predictions()
    tp = np.cumsum(is_tp).astype(float)
    fp = np.cumsum(~is_tp).astype(float)
    conf = pred.confidence[order]
    prec = tp / (fp + tp)
    rec = tp / float(npos)
    rec_interp = np.linspace(0, 1, NELEM)
    prec_i = np.interp(rec_interp, rec, prec, right=0)
    conf_i = np.interp(rec_interp, rec, conf, right=0)
    if not with_errors:
        return MetricData(recall=rec_interp, precision=prec_i, confidence=conf_i, errors={})
    pred_rows = order[is_tp]
    match_conf = pred.confidence[pred_rows]
    errs = _errors(gt, pred, matched[pred_rows], pred_rows, class_name)
    resampled = {
        k: np.interp(conf_i[::-1], match_conf[::-1], cummean(v)[::-1])[::-1]
        for k, v in errs.items()
    }
    return MetricData(recall=rec_interp, precision=prec_i, confidence=conf_i, errors=resampled)


def nd_score_without_attributes(
    mean_ap: float, tp_errors: Mapping[str, float], *, mean_ap_weight: float
) -> float:
    """The devkit's ``nd_score`` over the TP errors given (here four: no attribute error):
    ``(w·mAP + Σ max(0, 1 − err)) / (w + len(errors))`` — NOT the official NDS (which also has
    ``1 − mAAE`` and divides by 10)."""
    scores = [max(0.0, 1.0 - v) for v in tp_errors.values()]  # Python max: NaN → 0.0 as devkit
    return float(mean_ap_weight * mean_ap + np.sum(scores)) / float(mean_ap_weight + len(scores))


def _devkit_tp(name: str, metric: str, value: float) -> float:
    """The devkit's TP error of ``metric`` for class ``name``: NaN for a traffic cone's
    velocity and orientation and a barrier's velocity (``DetectionEval.evaluate``)."""
    if (name == "traffic_cone" and metric in ("vel_err", "orient_err")) or (
        name == "barrier" and metric == "vel_err"
    ):
        return math.nan
    return value


def band_name(lo_m: float, hi_m: float | None) -> str:
    """``band_0_20``, ``band_40_inf``."""
    hi = "inf" if hi_m is None or math.isinf(hi_m) else f"{hi_m:g}"
    return f"band_{lo_m:g}_{hi}"


def thr_name(th: float) -> str:
    return f"{th:.1f}" if float(th) * 10 == int(float(th) * 10) else f"{th:g}"


@dataclass(frozen=True, slots=True, kw_only=True)
class NuScenesEvaluation:
    """What :func:`evaluate_nuscenes` found.

    Attributes:
        values, units, curves: as in ``MetricResult``.
        class_names: the evaluated nuScenes classes (mapped ones, in mapping order).
        gt, pred: the boxes evaluated (mapped classes, after ``filter_eval_boxes``).
        gt_label, pred_label: index into ``class_names`` per row.
        gt_matched: (G,) matched at ``dist_th_tp_m``.
        pred_tp: (P,) a true positive at ``dist_th_tp_m``.
    """

    values: dict[str, float]
    units: dict[str, str]
    curves: dict[str, tuple[F64, F64]]
    class_names: tuple[str, ...]
    gt: ObjectColumns
    pred: ObjectColumns
    gt_label: I64
    pred_label: I64
    gt_matched: B
    pred_tp: B
    metric_data: dict[tuple[str, float], MetricData] = field(default_factory=dict)


def _labels(boxes: ObjectColumns, class_map: Mapping[str, str], names: Sequence[str]) -> I64:
    lut = np.full(len(CLASS_CODES), -1, dtype=np.int64)
    for value, name in class_map.items():
        lut[CLASS_CODES[ObjectClass(value)]] = names.index(name)
    return lut[boxes.class_code()] if len(boxes) else np.zeros(0, np.int64)


def _range_mask(
    boxes: ObjectColumns, label: I64, names: Sequence[str], class_range_m: Mapping[str, float]
) -> B:
    """``filter_eval_boxes``: mapped class, ``ego_dist < class_range`` and not 0 LiDAR points."""
    rng = np.array([float(class_range_m.get(n, np.inf)) for n in names] + [-np.inf])
    keep = (label >= 0) & (boxes.distance_xy_m < rng[label]) & (boxes.num_lidar_points != 0)
    return np.asarray(keep, dtype=bool)


def _class_aps(
    gt: ObjectColumns,
    pred: ObjectColumns,
    class_name: str,
    *,
    dist_ths_m: Sequence[float],
    min_recall: float,
    min_precision: float,
    errors_at_m: float | None = None,
) -> tuple[dict[float, MetricData], dict[float, float], I64]:
    order = devkit_order(pred.confidence)
    matched = center_distance_matching(gt, pred, order=order, dist_ths_m=dist_ths_m)
    mds: dict[float, MetricData] = {}
    aps: dict[float, float] = {}
    for t, th in enumerate(dist_ths_m):
        md = accumulate(
            gt, pred, matched=matched[t], order=order, class_name=class_name,
            with_errors=errors_at_m is not None and float(th) == float(errors_at_m),
        )  # fmt: skip
        mds[float(th)] = md
        aps[float(th)] = calc_ap(md, min_recall, min_precision)
    return mds, aps, matched


def evaluate_nuscenes(
    gt: ObjectColumns,
    pred: ObjectColumns,
    *,
    class_map: Mapping[str, str],
    class_range_m: Mapping[str, float],
    dist_ths_m: Sequence[float] = (0.5, 1.0, 2.0, 4.0),
    dist_th_tp_m: float = 2.0,
    min_recall: float = 0.1,
    min_precision: float = 0.1,
    mean_ap_weight: float = 5.0,
    distance_bands_m: Sequence[tuple[float, float | None]] = ((0, 20), (20, 40), (40, None)),
    class_mean: str = "present",
) -> NuScenesEvaluation:
    """nuScenes detection metrics of predictions against ground truth (frames as given: the
    caller decides which frames count).

    Args:
        gt, pred: boxes in base_link of their frame (ego distance = BEV norm of the centre).
        class_map: ObjectClass value → nuScenes class name; unmapped classes are not evaluated.
        class_range_m: nuScenes class → evaluation range, metres (unlisted: unlimited).
        dist_ths_m: matching thresholds (BEV centre distance, metres).
        dist_th_tp_m: threshold for the TP errors, recall, per-frame counts and bookmarks.
        min_recall, min_precision: ``calc_ap`` / ``calc_tp`` clipping.
        mean_ap_weight: weight of mAP in the NDS formula (devkit 5).
        distance_bands_m: [lo, hi) ego-distance bands for ``AP/band_lo_hi/th`` (hi None = ∞).
        class_mean: ``present`` — the means run over the classes with ground truth or
            predictions; ``devkit`` — over the devkit's ten classes (``class_range_m``'s keys, in
            their order) and any other mapped class, a class with neither scoring AP 0 and TP
            errors 1 as the devkit's ``accumulate`` gives it, plus ``mAAE`` and the official
            ``NDS`` (redrive has no attributes: every attribute error is NaN, which the
            devkit's ``cummean`` turns into 1, so mAAE = 1).

    Returns:
        values ``mAP`` (first), ``NDS_no_AAE``, ``mATE`` ``mASE`` ``mAOE`` ``mAVE``,
        ``AP/<class>/<th>``, ``AP/<class>``, ``ATE/<class>`` …, ``recall/<class>/<tp th>``,
        ``AP/<band>/<th>``, ``mAP/<band>``, ``gt_objects``, ``detections``; curves
        ``PR/<class>/<th>``.  A class with neither ground truth nor predictions is NaN and left
        out of the means.
    """
    if class_mean not in ("present", "devkit"):
        msg = f"class_mean must be 'present' or 'devkit', not {class_mean!r}"
        raise ValueError(msg)
    devkit = class_mean == "devkit"
    names: list[str] = list(class_range_m) if devkit else []
    for name in class_map.values():
        if name not in names:
            names.append(name)
    ths = [float(t) for t in dist_ths_m]
    if float(dist_th_tp_m) not in ths:
        ths.append(float(dist_th_tp_m))
    g_label = _labels(gt, class_map, names)
    p_label = _labels(pred, class_map, names)
    g_keep = _range_mask(gt, g_label, names, class_range_m)
    p_keep = _range_mask(pred, p_label, names, class_range_m)
    gt_f, pred_f = gt.take(g_keep), pred.take(p_keep)
    g_label, p_label = g_label[g_keep], p_label[p_keep]
    gt_matched = np.zeros(len(gt_f), dtype=bool)
    pred_tp = np.zeros(len(pred_f), dtype=bool)
    values: dict[str, float] = {"mAP": math.nan, "NDS_no_AAE": math.nan}
    units: dict[str, str] = {}
    curves: dict[str, tuple[F64, F64]] = {}
    mds_all: dict[tuple[str, float], MetricData] = {}
    class_ap: dict[str, float] = {}
    class_tp: dict[str, dict[str, float]] = {}
    tp_name = thr_name(dist_th_tp_m)
    for c, name in enumerate(names):
        g_rows, p_rows = np.flatnonzero(g_label == c), np.flatnonzero(p_label == c)
        present = g_rows.size > 0 or p_rows.size > 0
        if not present:
            # devkit: accumulate() of a class without ground truth is "no predictions": AP 0
            # at every threshold, TP errors 1 (NaN where the class has no such error)
            for th in dist_ths_m:
                values[f"AP/{name}/{thr_name(th)}"] = 0.0 if devkit else math.nan
            values[f"AP/{name}"] = 0.0 if devkit else math.nan
            absent = {k: _devkit_tp(name, k, 1.0) if devkit else math.nan for k in TP_METRICS}
            for k in TP_METRICS:
                values[f"{TP_SHORT[k]}/{name}"] = absent[k]
            values[f"recall/{name}/{tp_name}"] = math.nan
            if devkit:
                class_ap[name] = 0.0
                class_tp[name] = absent
            continue
        g_c, p_c = gt_f.take(g_rows), pred_f.take(p_rows)
        mds, aps, matched = _class_aps(
            g_c, p_c, name, dist_ths_m=ths, min_recall=min_recall, min_precision=min_precision,
            errors_at_m=dist_th_tp_m,
        )  # fmt: skip
        for th in dist_ths_m:
            values[f"AP/{name}/{thr_name(th)}"] = aps[float(th)]
            md = mds[float(th)]
            curves[f"PR/{name}/{thr_name(th)}"] = (md.recall, md.precision)
            mds_all[(name, float(th))] = md
        class_ap[name] = float(np.mean([aps[float(th)] for th in dist_ths_m]))
        values[f"AP/{name}"] = class_ap[name]
        md_tp = mds[float(dist_th_tp_m)]
        errs: dict[str, float] = {}
        for k in TP_METRICS:
            errs[k] = _devkit_tp(name, k, calc_tp(md_tp, min_recall, k))
            values[f"{TP_SHORT[k]}/{name}"] = errs[k]
            units[f"{TP_SHORT[k]}/{name}"] = TP_UNITS[k]
        class_tp[name] = errs
        m_tp = matched[ths.index(float(dist_th_tp_m))]
        hit = m_tp >= 0
        gt_matched[g_rows[m_tp[hit]]] = True
        pred_tp[p_rows[hit]] = True
        values[f"recall/{name}/{tp_name}"] = (
            float(hit.sum()) / g_rows.size if g_rows.size else math.nan
        )
    if class_ap:
        mean_ap = float(np.mean(list(class_ap.values())))
        tp_errors: dict[str, float] = {}
        for k in TP_METRICS:
            errs_k = np.array([class_tp[n][k] for n in class_tp])
            tp_errors[k] = float(np.nanmean(errs_k)) if np.any(~np.isnan(errs_k)) else math.nan
        values["mAP"] = mean_ap
        values["NDS_no_AAE"] = nd_score_without_attributes(
            mean_ap, tp_errors, mean_ap_weight=mean_ap_weight
        )
        for k in TP_METRICS:
            values[f"m{TP_SHORT[k]}"] = tp_errors[k]
        if devkit:  # no attributes: attr_err 1 for every class but traffic_cone (NaN)
            values["mAAE"] = 1.0
            values["NDS"] = nd_score_without_attributes(  # with the attribute error: official
                mean_ap, {**tp_errors, "attr_err": 1.0}, mean_ap_weight=mean_ap_weight
            )
    else:
        for k in TP_METRICS:
            values[f"m{TP_SHORT[k]}"] = math.nan
    for k in TP_METRICS:
        units[f"m{TP_SHORT[k]}"] = TP_UNITS[k]
    _bands(
        values,
        (gt_f, pred_f),
        labels=(g_label, p_label),
        names=names,
        dist_ths_m=dist_ths_m,
        bands=distance_bands_m,
        min_recall=min_recall,
        min_precision=min_precision,
    )
    values["gt_objects"] = float(len(gt_f))
    values["detections"] = float(len(pred_f))
    units["gt_objects"] = units["detections"] = "objects"
    return NuScenesEvaluation(
        values=values,
        units=units,
        curves=curves,
        class_names=tuple(names),
        gt=gt_f,
        pred=pred_f,
        gt_label=g_label,
        pred_label=p_label,
        gt_matched=gt_matched,
        pred_tp=pred_tp,
        metric_data=mds_all,
    )


def _bands(
    values: dict[str, float],
    boxes: tuple[ObjectColumns, ObjectColumns],
    *,
    labels: tuple[I64, I64],
    names: Sequence[str],
    dist_ths_m: Sequence[float],
    bands: Sequence[tuple[float, float | None]],
    min_recall: float,
    min_precision: float,
) -> None:
    """``AP/<band>/<th>`` and ``mAP/<band>``: the evaluation redone on the boxes (ground truth
    and predictions alike) whose ego distance lies in [lo, hi)."""
    gt, pred = boxes
    g_label, p_label = labels
    g_dist, p_dist = gt.distance_xy_m, pred.distance_xy_m
    for lo, hi in bands:
        top = math.inf if hi is None else float(hi)
        bname = band_name(lo, hi)
        g_in = (g_dist >= lo) & (g_dist < top)
        p_in = (p_dist >= lo) & (p_dist < top)
        per_th: dict[float, list[float]] = {float(t): [] for t in dist_ths_m}
        for c, name in enumerate(names):
            g_rows = np.flatnonzero(g_in & (g_label == c))
            p_rows = np.flatnonzero(p_in & (p_label == c))
            if g_rows.size == 0 and p_rows.size == 0:
                continue
            _, aps, _ = _class_aps(
                gt.take(g_rows),
                pred.take(p_rows),
                name,
                dist_ths_m=dist_ths_m,
                min_recall=min_recall,
                min_precision=min_precision,
            )
            for t in dist_ths_m:
                per_th[float(t)].append(aps[float(t)])
        for t in dist_ths_m:
            aps_t = per_th[float(t)]
            values[f"AP/{bname}/{thr_name(t)}"] = float(np.mean(aps_t)) if aps_t else math.nan
        means = [values[f"AP/{bname}/{thr_name(t)}"] for t in dist_ths_m]
        values[f"mAP/{bname}"] = (
            float(np.mean(means)) if not any(map(math.isnan, means)) else math.nan
        )
