"""nuscenes_detection: hand-computed cases and the nuScenes devkit's code (ported below) as oracle.

The oracle is a line-by-line port of ``nuscenes/eval/detection/algo.py::accumulate`` (loops over
predictions and ground truth, ``sorted((conf, i))[::-1]``), ``calc_ap``, ``calc_tp`` and
``DetectionMetrics`` of devkit 1.2.0.  (The real devkit, installed in a throwaway venv, agreed with
``evaluate_nuscenes`` to 2e-16 on 150 random scenes with tied confidences; see the report.)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from redrive.cli.main import main
from redrive.evaluation import EvalData
from redrive.evaluation.detection import NuScenesDetection, boxes_by_frame, evaluate_nuscenes
from redrive.evaluation.detection.arrays import class_codes
from redrive.evaluation.detection.classes import NUSCENES_CLASS_RANGE_M, NUSCENES_CLASSES
from redrive.evaluation.detection.nuscenes_core import MetricData, calc_ap, calc_tp
from redrive.results import (
    AlgorithmEntry,
    FrameRecord,
    RunSetup,
    RunWriter,
    SourceLog,
    StepRecord,
    open_run,
)
from redrive.results.evaluation import read_evaluation
from redrive.types import Box3D, DetectedObject, ObjectClass, ObjectColumns, Role

EMPTY = ObjectColumns.from_objects([])
CLASSES = ["vehicle", "truck", "pedestrian", "bicycle", "motorcycle"]
NAMES = ["car", "truck", "pedestrian", "bicycle", "motorcycle"]


def boxes(rows: Sequence[Sequence[float]]) -> ObjectColumns:
    """rows: (frame, class index into CLASSES, x, y, yaw, score[, l, w, h, vx, vy, points])."""
    full = []
    for r in rows:
        full.append([*r, *[4.0, 2.0, 1.5, 0.0, 0.0, -1][len(r) - 6 :]])
    a = np.array(full, dtype=np.float64).reshape(-1, 12)
    codes = class_codes(CLASSES)
    return boxes_by_frame(
        frame_index=a[:, 0],
        object_class=codes[a[:, 1].astype(int)],
        center_m=np.c_[a[:, 2:4], np.zeros(len(a))],
        size_m=a[:, 6:9],
        yaw_rad=a[:, 4],
        velocity_mps=np.c_[a[:, 9:11], np.zeros(len(a))],
        confidence=a[:, 5],
        num_lidar_points=a[:, 11],
    )


def run_eval(gt: ObjectColumns, pred: ObjectColumns, **kw: object) -> dict[str, float]:
    ev = evaluate_nuscenes(
        gt,
        pred,
        class_map=NUSCENES_CLASSES,
        class_range_m=NUSCENES_CLASS_RANGE_M,
        **kw,  # type: ignore[arg-type]
    )
    return ev.values


# ------------------------------------------------------------------------------------------------
# hand-computed cases


def test_perfect_detections() -> None:
    # every GT has a detection on top of it: precision 1 at every recall → AP = (1 − 0.1)/0.9 = 1;
    # TP errors 0 → NDS_no_AAE = (5·1 + 4·1)/9 = 1
    gt = boxes([(f, c, 10 + f, 3 * c, 0.3, 1.0) for f in range(3) for c in (0, 2)])
    pred = boxes([(f, c, 10 + f, 3 * c, 0.3, 0.5 + 0.1 * c) for f in range(3) for c in (0, 2)])
    v = run_eval(gt, pred)
    assert v["mAP"] == pytest.approx(1.0, abs=1e-12)
    for th in ("0.5", "1.0", "2.0", "4.0"):
        assert v[f"AP/car/{th}"] == pytest.approx(1.0, abs=1e-12)
        assert v[f"AP/pedestrian/{th}"] == pytest.approx(1.0, abs=1e-12)
    assert v["mATE"] == pytest.approx(0.0, abs=1e-12)
    assert v["mASE"] == pytest.approx(0.0, abs=1e-12)
    assert v["mAOE"] == pytest.approx(0.0, abs=1e-12)
    assert v["NDS_no_AAE"] == pytest.approx(1.0, abs=1e-12)
    assert v["recall/car/2.0"] == 1.0
    # classes with neither ground truth nor detections are NaN and not averaged
    assert math.isnan(v["AP/truck/2.0"])
    assert math.isnan(v["AP/bicycle"])


def test_devkit_class_mean_averages_over_the_ten_classes() -> None:
    """Cars only, detected perfectly: redrive's default mean (classes present) gives mAP 1, the
    devkit's ten-class mean gives 0.1 — absent classes score AP 0 and TP errors 1, the cone's
    velocity/orientation and the barrier's velocity errors are NaN and left out of the means."""
    gt = boxes([(f, 0, 10 + f, 0.0, 0.3, 1.0) for f in range(3)])
    pred = boxes([(f, 0, 10 + f, 0.0, 0.3, 0.9) for f in range(3)])
    present = run_eval(gt, pred)
    assert present["mAP"] == pytest.approx(1.0, abs=1e-12)
    assert present["NDS_no_AAE"] == pytest.approx(1.0, abs=1e-12)
    assert "NDS" not in present
    v = run_eval(gt, pred, class_mean="devkit")
    assert v["mAP"] == pytest.approx(0.1, abs=1e-12)
    assert v["AP/bus"] == 0.0
    assert v["ATE/bus"] == 1.0
    assert math.isnan(v["AVE/barrier"])
    assert math.isnan(v["AOE/traffic_cone"])
    assert v["mATE"] == pytest.approx(9 / 10, abs=1e-12)  # car 0, nine classes 1
    assert v["mASE"] == pytest.approx(9 / 10, abs=1e-12)
    assert v["mAOE"] == pytest.approx(8 / 9, abs=1e-12)  # the cone's is NaN
    assert v["mAVE"] == pytest.approx(7 / 8, abs=1e-12)  # the cone's and barrier's are NaN
    assert v["mAAE"] == 1.0
    nds = (5 * 0.1 + (1 - 9 / 10) + (1 - 9 / 10) + (1 - 8 / 9) + (1 - 7 / 8) + 0.0) / 10
    assert v["NDS"] == pytest.approx(nds, abs=1e-12)
    with pytest.raises(ValueError, match="class_mean"):
        run_eval(gt, pred, class_mean="mine")


def test_false_positive_with_higher_confidence() -> None:
    # one car; an FP (conf 0.9, 30 m away) ranks before the TP (conf 0.5, 0.3 m off):
    # tp = [0, 1], fp = [1, 1] → precision [0, 0.5], recall [0, 1]; interpolated p(r) = 0.5·r.
    # AP = Σ_{i=11..100} max(0, 0.5·i/100 − 0.1) / 90 / 0.9; terms are > 0 from i = 20:
    # Σ_{i=20..100} (i/200 − 0.1) = 4860/200 − 8.1 = 16.2 → 16.2 / 90 / 0.9 = 0.2
    gt = boxes([(0, 0, 10.0, 0.0, 0.0, 1.0)])
    pred = boxes([(0, 0, 40.0, 0.0, 0.0, 0.9), (0, 0, 10.3, 0.0, 0.0, 0.5)])
    v = run_eval(gt, pred)
    for th in ("0.5", "1.0", "2.0", "4.0"):
        assert v[f"AP/car/{th}"] == pytest.approx(0.2, abs=1e-12)
    assert v["mAP"] == pytest.approx(0.2, abs=1e-12)
    # one match: its errors at every recall bin: translation 0.3 m, scale 0, orientation 0
    assert v["ATE/car"] == pytest.approx(0.3, abs=1e-12)
    assert v["mASE"] == pytest.approx(0.0, abs=1e-12)
    # NDS_no_AAE = (5·0.2 + (1 − 0.3) + 1 + 1 + 1) / 9 = 4.7 / 9
    assert v["NDS_no_AAE"] == pytest.approx(4.7 / 9, abs=1e-12)


def test_ties_in_confidence_later_detection_first() -> None:
    # Two detections with the same confidence near one car: the devkit sorts (conf, index)
    # pairs and reverses, so the one listed LATER is matched first.
    # A (index 0) 1.5 m off, B (index 1) 0.2 m off → B matched → ATE 0.2.
    gt = boxes([(0, 0, 10.0, 0.0, 0.0, 1.0)])
    a, b = (0, 0, 11.5, 0.0, 0.0, 0.5), (0, 0, 10.2, 0.0, 0.0, 0.5)
    v = run_eval(gt, boxes([a, b]))
    assert v["ATE/car"] == pytest.approx(0.2, abs=1e-12)
    # tp = [1, 0]: precision [1, 0.5] at recall [1, 1] → p = 1 below recall 1, 0.5 at 1:
    # AP = (89·0.9 + 0.4) / 90 / 0.9 = 80.5 / 81
    assert v["AP/car/2.0"] == pytest.approx(80.5 / 81, abs=1e-12)
    # listed the other way round, A is matched first (1.5 m < 2 m) and B is a false positive
    v = run_eval(gt, boxes([b, a]))
    assert v["ATE/car"] == pytest.approx(1.5, abs=1e-12)
    # at 1 m, A (1.5 m) is no match, so B (free GT, 0.2 m) matches: tp = [0, 1] → AP 0.2 as above
    assert v["AP/car/1.0"] == pytest.approx(0.2, abs=1e-12)
    # ties across frames: the later frame's detection goes first
    gt2 = boxes([(0, 0, 10.0, 0.0, 0.0, 1.0), (1, 0, 10.0, 0.0, 0.0, 1.0)])
    pred2 = boxes([(0, 0, 10.0, 0.0, 0.0, 0.5), (1, 0, 45.0, 0.0, 0.0, 0.5)])
    # order: frame-1 FP, then frame-0 TP: tp = [0, 1], precision [0, 0.5], recall [0, 0.5]
    # → p(r) = r up to 0.5, 0 beyond: Σ_{i=11..50} (i − 10)/100 = 820/100 = 8.2 → 8.2 / 81.
    # (TP first would give p = 1 below recall 0.5: (39·0.9 + 0.4) / 81.)
    assert run_eval(gt2, pred2)["AP/car/2.0"] == pytest.approx(8.2 / 81, abs=1e-12)


def test_small_curve_interpolation_and_clipping_by_hand() -> None:
    # 5 cars in 5 frames; detections by confidence 0.9 TP, 0.8 TP, 0.7 FP, 0.6 TP:
    # tp = [1, 2, 2, 3], fp = [0, 0, 1, 1] → precision [1, 1, 2/3, 3/4], recall [.2, .4, .4, .6].
    gt = boxes([(f, 0, 10.0, 0.0, 0.0, 1.0) for f in range(5)])
    pred = boxes(
        [
            (0, 0, 10.0, 0.0, 0.0, 0.9),
            (1, 0, 10.0, 0.0, 0.0, 0.8),
            (2, 0, 30.0, 0.0, 0.0, 0.7),
            (3, 0, 10.0, 0.0, 0.0, 0.6),
        ]
    )
    ev = evaluate_nuscenes(
        gt, pred, class_map=NUSCENES_CLASSES, class_range_m=NUSCENES_CLASS_RANGE_M
    )
    md = ev.metric_data[("car", 2.0)]
    r = np.linspace(0, 1, 101)
    # np.interp on the 101 recalls: 1 up to r < 0.4; at r = 0.4 (a repeated recall) the later
    # point 2/3; linear from (0.4, 2/3) to (0.6, 3/4); 0 beyond 0.6 (right=0)
    expected = np.where(r < 0.4 - 1e-12, 1.0, 2 / 3 + (r - 0.4) / 0.2 * (3 / 4 - 2 / 3))
    expected[r > 0.6 + 1e-12] = 0.0
    np.testing.assert_allclose(md.precision, expected, atol=1e-12)
    # AP: bins 11..100 (min_recall 0.1 excluded), minus min_precision 0.1, clipped at 0:
    # i = 11..39: 29 × 0.9 = 26.1; i = 40: 2/3 − 0.1; i = 41..59: 2/3 − 0.1 + k/240 (k = 1..19),
    # i = 60: 3/4 − 0.1 = 0.65; i > 60: 0 → total / 90 / 0.9
    total = 26.1 + (2 / 3 - 0.1) + 19 * (2 / 3 - 0.1) + 190 / 240 + 0.65
    assert ev.values["AP/car/2.0"] == pytest.approx(total / 90 / 0.9, abs=1e-12)
    # the confidence curve is > 0 up to recall 0.6 → max_recall_ind 60
    assert md.max_recall_ind == 60


def test_calc_ap_and_calc_tp_clipping() -> None:
    # precision 0.05 everywhere (below min_precision) → AP 0; 0.55 everywhere → (0.45)/0.9 = 0.5
    zeros = np.zeros(101)
    md = MetricData(
        recall=np.linspace(0, 1, 101),
        precision=np.full(101, 0.05),
        confidence=zeros,
        errors={"trans_err": zeros},
    )
    assert calc_ap(md, 0.1, 0.1) == 0.0
    md = MetricData(
        recall=md.recall,
        precision=np.full(101, 0.55),
        confidence=zeros,
        errors={"trans_err": zeros},
    )
    assert calc_ap(md, 0.1, 0.1) == pytest.approx(0.5, abs=1e-12)
    # max recall below min_recall (confidence > 0 only up to bin 10) → TP error 1
    conf = np.where(np.arange(101) <= 10, 0.5, 0.0)
    md = MetricData(
        recall=md.recall, precision=md.precision, confidence=conf, errors={"trans_err": zeros}
    )
    assert calc_tp(md, 0.1, "trans_err") == 1.0
    # errors 0..1 by bin, confidence to bin 20 → mean of bins 11..20 = 0.155
    conf = np.where(np.arange(101) <= 20, 0.5, 0.0)
    md = MetricData(
        recall=md.recall,
        precision=md.precision,
        confidence=conf,
        errors={"trans_err": np.linspace(0, 1, 101)},
    )
    assert calc_tp(md, 0.1, "trans_err") == pytest.approx(0.155, abs=1e-12)


def test_empty_ground_truth_and_empty_predictions() -> None:
    # predictions only: the class has no GT → devkit "no predictions": AP 0, TP errors 1;
    # NDS_no_AAE = (5·0 + 4·0) / 9 = 0
    v = run_eval(EMPTY, boxes([(0, 0, 10.0, 0.0, 0.0, 0.9)]))
    assert v["mAP"] == 0.0
    assert v["mATE"] == 1.0
    assert v["NDS_no_AAE"] == 0.0
    # ground truth only: AP 0, recall 0
    v = run_eval(boxes([(0, 2, 5.0, 1.0, 0.0, 1.0)]), EMPTY)
    assert v["AP/pedestrian/2.0"] == 0.0
    assert v["recall/pedestrian/2.0"] == 0.0
    assert v["mAP"] == 0.0
    # nothing at all: undefined
    v = run_eval(EMPTY, EMPTY)
    assert math.isnan(v["mAP"])
    assert math.isnan(v["NDS_no_AAE"])


def test_yaw_wrap_around() -> None:
    # GT yaw π − ε, detection −π + ε: the boxes differ by 2ε across the wrap, not 2π − 2ε
    eps = 0.01
    gt = boxes([(0, 0, 10.0, 0.0, math.pi - eps, 1.0)])
    pred = boxes([(0, 0, 10.0, 0.0, -math.pi + eps, 0.9)])
    v = run_eval(gt, pred)
    assert v["AOE/car"] == pytest.approx(2 * eps, abs=1e-12)
    assert v["AP/car/0.5"] == pytest.approx(1.0, abs=1e-12)
    # barrier-like classes have period π: a box turned by π − 0.02 is 0.02 off
    gt = boxes([(0, 0, 10.0, 0.0, 0.1, 1.0)])
    pred = boxes([(0, 0, 10.0, 0.0, 0.1 + math.pi - 0.02, 0.9)])
    ev = evaluate_nuscenes(
        gt, pred, class_map={"vehicle": "barrier"}, class_range_m=NUSCENES_CLASS_RANGE_M
    )
    assert ev.values["AOE/barrier"] == pytest.approx(0.02, abs=1e-12)
    assert math.isnan(ev.values["AVE/barrier"])  # devkit: no velocity error for barriers


def test_scale_and_velocity_errors() -> None:
    # GT 4×2×1.5, detection 5×2×1 (aligned): intersection 4·2·1 = 8, union 12 + 10 − 8 = 14
    # → ASE = 1 − 8/14 = 3/7; velocity (1, 0) vs (1, 2) → AVE 2
    gt = boxes([(0, 0, 10.0, 0.0, 0.0, 1.0, 4.0, 2.0, 1.5, 1.0, 0.0, -1)])
    pred = boxes([(0, 0, 10.0, 0.0, 0.0, 0.9, 5.0, 2.0, 1.0, 1.0, 2.0, -1)])
    v = run_eval(gt, pred)
    assert v["ASE/car"] == pytest.approx(3 / 7, abs=1e-12)
    assert v["AVE/car"] == pytest.approx(2.0, abs=1e-12)


def test_filtering_range_points_and_classes() -> None:
    # car at 55 m (range 50) dropped, car with 0 LiDAR points dropped, 'unknown' not evaluated;
    # a detection at 55 m is dropped too (the devkit filters predictions alike)
    gt = boxes(
        [
            (0, 0, 55.0, 0.0, 0.0, 1.0),
            (0, 0, 20.0, 0.0, 0.0, 1.0, 4, 2, 1.5, 0, 0, 0),
            (0, 0, 10.0, 0.0, 0.0, 1.0, 4, 2, 1.5, 0, 0, 12),
        ]
    )
    unknown = boxes_by_frame(
        frame_index=[0],
        object_class=class_codes(["unknown"]),
        center_m=[[5.0, 0, 0]],
        size_m=[[1, 1, 1]],
        yaw_rad=[0],
    )
    pred = boxes([(0, 0, 10.0, 0.0, 0.0, 0.8), (0, 0, 55.0, 0.0, 0.0, 0.9)])
    v = run_eval(gt, pred)
    assert v["gt_objects"] == 1.0
    assert v["detections"] == 1.0
    assert v["AP/car/2.0"] == pytest.approx(1.0, abs=1e-12)
    assert run_eval(gt, boxes_by_frame(
        frame_index=np.r_[pred.frame_index, unknown.frame_index],
        object_class=np.r_[pred.class_code(), unknown.class_code()],
        center_m=np.r_[pred.center_m, unknown.center_m], size_m=np.r_[pred.size_m, unknown.size_m],
        yaw_rad=np.r_[pred.yaw_rad, unknown.yaw_rad], confidence=np.r_[pred.confidence, 0.99],
    ))["detections"] == 1.0  # fmt: skip


def test_distance_bands() -> None:
    # a car at 10 m found, a car at 30 m missed, a pedestrian at 50 m out of its 40 m range
    gt = boxes(
        [(0, 0, 10.0, 0.0, 0.0, 1.0), (0, 0, 30.0, 0.0, 0.0, 1.0), (0, 2, 50.0, 0.0, 0.0, 1.0)]
    )
    pred = boxes([(0, 0, 10.1, 0.0, 0.0, 0.7)])
    v = run_eval(gt, pred)
    assert v["AP/band_0_20/2.0"] == pytest.approx(1.0, abs=1e-12)
    assert v["AP/band_20_40/2.0"] == 0.0
    assert math.isnan(v["AP/band_40_inf/2.0"])
    assert v["mAP/band_0_20"] == pytest.approx(1.0, abs=1e-12)


# ------------------------------------------------------------------------------------------------
# the devkit, ported (loops), as the oracle


def _oracle_accumulate(
    gt: list[dict], pred: list[dict], npos: int, dist_th: float, period: float
) -> dict:
    pred_confs = [p["score"] for p in pred]
    sortind = [i for (v, i) in sorted((v, i) for (i, v) in enumerate(pred_confs))][::-1]
    tp, fp, conf = [], [], []
    md: dict[str, list[float]] = {
        "trans_err": [],
        "vel_err": [],
        "scale_err": [],
        "orient_err": [],
        "conf": [],
    }
    taken = set()
    for ind in sortind:
        p = pred[ind]
        min_dist, match = np.inf, None
        for gi, g in enumerate(gt):
            if g["frame"] == p["frame"] and gi not in taken:
                d = np.linalg.norm(np.array(p["xy"]) - np.array(g["xy"]))
                if d < min_dist:
                    min_dist, match = d, gi
        if min_dist < dist_th:
            taken.add(match)
            g = gt[match]
            tp.append(1), fp.append(0), conf.append(p["score"])
            md["trans_err"].append(float(np.linalg.norm(np.array(p["xy"]) - np.array(g["xy"]))))
            md["vel_err"].append(float(np.linalg.norm(np.array(p["v"]) - np.array(g["v"]))))
            mn = np.minimum(g["size"], p["size"])
            inter = np.prod(mn)
            md["scale_err"].append(1 - inter / (np.prod(g["size"]) + np.prod(p["size"]) - inter))
            diff = (g["yaw"] - p["yaw"] + period / 2) % period - period / 2
            if diff > np.pi:
                diff = diff - 2 * np.pi
            md["orient_err"].append(abs(diff))
            md["conf"].append(p["score"])
        else:
            tp.append(0), fp.append(1), conf.append(p["score"])
    nelem = 101
    if npos == 0 or not md["trans_err"]:
        return {
            "precision": np.zeros(nelem),
            "confidence": np.zeros(nelem),
            **{k: np.ones(nelem) for k in md if k != "conf"},
        }
    tpc = np.cumsum(tp).astype(float)
    fpc = np.cumsum(fp).astype(float)
    confs = np.array(conf)
    prec = tpc / (fpc + tpc)
    rec = tpc / float(npos)
    rec_interp = np.linspace(0, 1, nelem)
    out = {"precision": np.interp(rec_interp, rec, prec, right=0)}
    out["confidence"] = np.interp(rec_interp, rec, confs, right=0)
    for key in ("trans_err", "vel_err", "scale_err", "orient_err"):
        x = np.array(md[key])
        tmp = np.nancumsum(x) / np.cumsum(~np.isnan(x))
        out[key] = np.interp(out["confidence"][::-1], np.array(md["conf"])[::-1], tmp[::-1])[::-1]
    return out


def _oracle(gt_rows: list[tuple], pred_rows: list[tuple]) -> dict[str, float]:
    """devkit: filter, accumulate per class and threshold, calc_ap, calc_tp, mean_ap, tp_errors."""

    def conv(rows: list[tuple]) -> list[dict]:
        out = []
        for r in rows:
            name = NAMES[int(r[1])]
            if math.hypot(r[2], r[3]) < NUSCENES_CLASS_RANGE_M[name] and r[11] != 0:
                out.append(
                    {
                        "frame": r[0],
                        "name": name,
                        "xy": (r[2], r[3]),
                        "yaw": r[4],
                        "score": r[5],
                        "size": np.array(r[6:9]),
                        "v": (r[9], r[10]),
                    }
                )
        return out

    gts, preds = conv(gt_rows), conv(pred_rows)
    res: dict[str, float] = {}
    aps, tps = {}, {}
    for name in NAMES:
        g = [x for x in gts if x["name"] == name]
        p = [x for x in preds if x["name"] == name]
        if not g and not p:
            continue
        per = []
        for th in (0.5, 1.0, 2.0, 4.0):
            md = _oracle_accumulate(g, p, len(g), th, 2 * np.pi)
            prec = md["precision"][11:] - 0.1
            prec[prec < 0] = 0
            ap = float(np.mean(prec)) / 0.9
            res[f"AP/{name}/{th:.1f}"] = ap
            per.append(ap)
            if th == 2.0:
                nz = np.nonzero(md["confidence"])[0]
                last = nz[-1] if len(nz) else 0
                tps[name] = {
                    k: 1.0 if last < 11 else float(np.mean(md[k][11 : last + 1]))
                    for k in ("trans_err", "scale_err", "orient_err", "vel_err")
                }
        aps[name] = float(np.mean(per))
    if aps:
        res["mAP"] = float(np.mean(list(aps.values())))
        for k, short in (
            ("trans_err", "mATE"),
            ("scale_err", "mASE"),
            ("orient_err", "mAOE"),
            ("vel_err", "mAVE"),
        ):
            res[short] = float(np.nanmean([tps[n][k] for n in tps]))
    return res


def _scene(seed: int) -> tuple[list[tuple], list[tuple]]:
    rng = np.random.default_rng(seed)
    gts: list[tuple] = []
    preds: list[tuple] = []
    for f in range(int(rng.integers(1, 12))):
        frame_gt = []
        for _ in range(int(rng.integers(0, 8))):
            g = (
                f,
                int(rng.integers(0, 3)),
                *rng.uniform(-45, 45, 2),
                rng.uniform(-4, 4),
                1.0,
                *rng.uniform(0.3, 5, 3),
                *rng.uniform(-3, 3, 2),
                int(rng.choice([-1, 0, 5])),
            )
            frame_gt.append(g)
        gts += frame_gt
        for _ in range(int(rng.integers(0, 10))):
            score = float(np.round(rng.uniform(), 1))  # ties
            if frame_gt and rng.random() < 0.7:
                g = frame_gt[int(rng.integers(len(frame_gt)))]
                xy = np.array(g[2:4]) + rng.normal(0, rng.choice([0.2, 1.0]), 2)
                preds.append(
                    (
                        f,
                        g[1],
                        *xy,
                        g[4] + rng.normal(0, 0.3),
                        score,
                        *(np.array(g[6:9]) * rng.uniform(0.8, 1.2, 3)),
                        *(np.array(g[9:11]) + rng.normal(0, 1, 2)),
                        -1,
                    )
                )
            else:
                preds.append(
                    (
                        f,
                        int(rng.integers(0, 3)),
                        *rng.uniform(-45, 45, 2),
                        rng.uniform(-4, 4),
                        score,
                        *rng.uniform(0.3, 5, 3),
                        0.0,
                        0.0,
                        -1,
                    )
                )
    return gts, preds


@pytest.mark.parametrize("seed", range(40))
def test_equals_devkit_port(seed: int) -> None:
    gt_rows, pred_rows = _scene(seed)
    ref = _oracle(gt_rows, pred_rows)
    ours = run_eval(boxes(gt_rows), boxes(pred_rows))
    for key, value in ref.items():
        assert ours[key] == pytest.approx(value, abs=1e-9), key


# ------------------------------------------------------------------------------------------------
# the metric on a run directory


def _obj(cls: ObjectClass, x: float, y: float, conf: float = 1.0) -> DetectedObject:
    return DetectedObject(
        object_class=cls,
        confidence=conf,
        box=Box3D(center=np.array([x, y, 0.8]), size=np.array([4.0, 2.0, 1.5])),
    )


def _write_run(path: Path) -> None:
    setup = RunSetup(
        log=SourceLog(path="x", sha256="s", format="mcap"),
        seed=0,
        algorithms=(
            AlgorithmEntry(name="det", version="1", config_hash="c", role=Role.PERCEPTION),
        ),
    )
    truth = {
        0: (_obj(ObjectClass.VEHICLE, 10, 0), _obj(ObjectClass.PEDESTRIAN, 5, 2)),
        1: (_obj(ObjectClass.VEHICLE, 12, 0),),
        2: (_obj(ObjectClass.VEHICLE, 8, 1),),
    }
    found = {
        0: (_obj(ObjectClass.VEHICLE, 10.2, 0, 0.9), _obj(ObjectClass.VEHICLE, 30, 5, 0.3)),
        1: (_obj(ObjectClass.VEHICLE, 12, 0.1, 0.8),),
    }
    with RunWriter(path, setup=setup) as writer:
        for i in range(3):
            status = "ok" if i < 2 else "error"  # frame 2: the detector failed → no detections
            step = StepRecord(
                algorithm="det",
                stage="perception",
                role="perception",
                status=status,
                output=found.get(i, ()) if status == "ok" else None,
                error_type="" if status == "ok" else "E",
                error_message="",
            )
            writer.write_frame(
                FrameRecord(
                    frame_index=i, stamp_ns=10**9 * (i + 1), steps=(step,), ground_truth=truth[i]
                )
            )


def test_metric_on_a_run(tmp_path: Path) -> None:
    _write_run(tmp_path / "run")
    res = NuScenesDetection().evaluate(EvalData(open_run(tmp_path / "run"), "det"))
    assert res.headline == "mAP"
    assert res.values["frames"] == 3.0
    assert res.values["frames_without_output"] == 1.0
    np.testing.assert_array_equal(res.per_frame["tp"][1], [1, 1, 0])
    np.testing.assert_array_equal(res.per_frame["fp"][1], [1, 0, 0])
    np.testing.assert_array_equal(res.per_frame["missed"][1], [1, 0, 1])
    np.testing.assert_array_equal(res.per_frame["gt"][1], [2, 1, 1])
    # missed within 20 m: the pedestrian at √29 m (frame 0), the car at √65 m (frame 2)
    marks = sorted(res.bookmarks, key=lambda b: b.frame_index)
    assert [(b.frame_index, b.kind) for b in marks] == [(0, "missed_object"), (2, "missed_object")]
    assert marks[0].severity == pytest.approx(1 / math.sqrt(29))
    assert "pedestrian" in marks[0].detail
    assert marks[1].severity == pytest.approx(1 / math.sqrt(65))
    # car: 3 GT; by confidence TP (0.9), TP (0.8), FP (0.3): p = 1 up to recall 2/3, then the
    # FP at recall 2/3 gives 2/3; beyond 2/3 → 0.  bins 11..66 → 56 × 0.9; bin 67 → 0
    assert res.values["AP/car/2.0"] == pytest.approx(56 * 0.9 / 90 / 0.9, abs=1e-12)
    assert res.curves["PR/car/2.0"][0].shape == (101,)


def test_cli_metric_params_and_devkit_compat_are_stored_with_the_values(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    _write_run(run)
    argv = ["evaluate", str(run), "--metric", "nuscenes_detection"]
    assert (
        main([*argv, "--metric-param", "nuscenes_detection.dist_ths_m=1,2", "--devkit-compat"]) == 0
    )
    ev = read_evaluation(run)
    (record,) = [m for m in ev.metrics if m["name"] == "nuscenes_detection"]
    assert record["params"]["dist_ths_m"] == [1, 2]
    assert record["params"]["class_mean"] == "devkit"
    keys = {r["key"] for r in ev.values.to_pylist()}
    assert {"AP/car/1.0", "AP/car/2.0", "NDS", "mAAE", "AP/bus"} <= keys
    assert "AP/car/0.5" not in keys
    # by redrive's default the mean runs over the two classes present (car, pedestrian); the
    # devkit's over ten, eight of them absent with AP 0
    assert main([*argv, "--metric-param", "nuscenes_detection.dist_ths_m=1,2"]) == 0
    present = read_evaluation(run).value("nuscenes_detection", "mAP", algorithm="det")
    devkit = ev.value("nuscenes_detection", "mAP", algorithm="det")
    assert present > 0
    assert devkit == pytest.approx(present * 2 / 10, abs=1e-12)
    capsys.readouterr()
    assert main([*argv, "--metric-param", "nuscenes_detection.no_such=1"]) == 1
    assert "unknown parameter(s) no_such" in capsys.readouterr().err
    assert main([*argv, "--metric-param", "latency.deadline_ms=50"]) == 1
    assert "not among the metrics evaluated" in capsys.readouterr().err
    assert main([*argv, "--metric-param", "nuscenes_detection"]) == 1
    assert "give METRIC.PARAM=VALUE" in capsys.readouterr().err
