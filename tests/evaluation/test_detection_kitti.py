"""kitti_detection: hand-computed R40 cases, a loop port of mmdetection3d's
``kitti_utils/eval.py`` (``compute_statistics_jit``, ``get_thresholds``, ``eval_class``,
``get_mAP40``; IoU by shapely) as oracle, and the reference detector on the real KITTI frames."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
import shapely

from redrive.cli.main import main
from redrive.evaluation import EvalData
from redrive.evaluation.detection import KittiDetection, NuScenesDetection, boxes_by_frame
from redrive.evaluation.detection.arrays import class_codes
from redrive.evaluation.detection.iou import bev_corners
from redrive.evaluation.detection.kitti import get_thresholds
from redrive.results import open_run
from redrive.types import ObjectColumns

EMPTY = ObjectColumns.from_objects([])
CLASSES = ["vehicle", "pedestrian", "bicycle", "truck"]


def boxes(rows: Sequence[Sequence[float]]) -> ObjectColumns:
    """rows: (frame, class index into CLASSES, x, y, z, l, w, h, yaw, score)."""
    a = np.array(rows, dtype=np.float64).reshape(-1, 10)
    return boxes_by_frame(
        frame_index=a[:, 0],
        object_class=class_codes(CLASSES)[a[:, 1].astype(int)],
        center_m=a[:, 2:5],
        size_m=a[:, 5:8],
        yaw_rad=a[:, 8],
        confidence=a[:, 9],
    )


def car(frame: int, x: float, y: float = 0.0, score: float = 1.0, yaw: float = 0.0) -> tuple:
    return (frame, 0, x, y, 0.0, 4.0, 2.0, 1.5, yaw, score)


def evaluate(
    gt: ObjectColumns, pred: ObjectColumns, frames: Sequence[int], **params: object
) -> dict[str, float]:
    return dict(
        KittiDetection(**params).evaluate_arrays(gt, pred, np.array(frames, np.int64)).values
    )


def test_get_thresholds_by_hand() -> None:
    # 4 GT, TP scores .9 .8 .7 .6: each step moves recall by 1/4 ≥ 1/40 → all four kept
    np.testing.assert_array_equal(
        get_thresholds(np.array([0.6, 0.9, 0.7, 0.8]), 4), [0.9, 0.8, 0.7, 0.6]
    )
    # 80 GT, 80 TPs (recall (i+1)/80 after score i); the target recall starts at 0 and moves
    # 1/40 = 2/80 per kept score; score i is skipped when the next recall is nearer the target:
    # i=0: kept (target 0 → 2/80); i=1: |3/80 − 2/80| < |2/80 − 2/80|? no → kept (→ 4/80);
    # i=2: |4/80 − 4/80| < |4/80 − 3/80| → skipped; i=3 kept (→ 6/80); … → i = 0, 1, 3, 5, …, 79
    s = np.linspace(1.0, 0.01, 80)
    th = get_thresholds(s, 80)
    assert th.size == 41
    np.testing.assert_array_equal(th, s[[0, *range(1, 80, 2)]])


def test_r40_small_case_by_hand() -> None:
    # 4 cars; detections: exact boxes with scores .9, .7, .6 and a false positive (.8) far away.
    # pass 1: TP scores .9 .7 .6 → thresholds [.9, .7, .6] (4 GT: each TP moves recall 1/4)
    # th .9: TP 1, FP 0 → P 1,   R .25
    # th .7: TP 2, FP 1 → P 2/3, R .5
    # th .6: TP 3, FP 1 → P 3/4, R .75
    # running max from the right: P = [1, .75, .75, 0, …] → AP_R40 = (.75 + .75) / 40 = 0.0375
    gt = boxes([car(0, 10), car(0, 20), car(1, 10), car(1, 30)])
    pred = boxes(
        [
            car(0, 10, score=0.9),
            car(0, 20, score=0.7),
            car(1, 10, score=0.6),
            car(1, -30, score=0.8),
        ]
    )
    v = evaluate(gt, pred, [0, 1])
    assert v["AP3D/car"] == pytest.approx(0.0375, abs=1e-12)
    assert v["APBEV/car"] == pytest.approx(0.0375, abs=1e-12)
    assert v["recall3D/car"] == 0.75
    assert math.isnan(v["AP3D/pedestrian"])  # neither GT nor detections
    assert v["mAP3D"] == pytest.approx(0.0375, abs=1e-12)  # the only class with data


def test_perfect_detections() -> None:
    # 80 cars (8 frames × 10), exact detections with distinct scores: 41 thresholds, precision 1
    # at each → AP_R40 = 40/40 = 1
    rows = [car(f, 8.0 * k, score=1 - (10 * f + k) / 100) for f in range(8) for k in range(10)]
    v = evaluate(boxes(rows), boxes(rows), range(8))
    assert v["AP3D/car"] == pytest.approx(1.0, abs=1e-12)
    assert v["APBEV/car"] == pytest.approx(1.0, abs=1e-12)
    # KITTI's R40 with ONE ground truth: get_thresholds gives one threshold, stored at recall
    # position 0, which R40 leaves out → AP 0 even for a perfect detection (the published code)
    one = boxes([car(0, 10)])
    assert evaluate(one, boxes([car(0, 10, score=0.9)]), [0])["AP3D/car"] == 0.0


def test_assignment_by_overlap_not_score() -> None:
    # one car; A (score .9) overlaps it by 3/4.2 (0.5 m off: BEV 3.5·2 / (8 + 8 − 7) = 7/9),
    # B (score .5) sits exactly on it.  With every detection, KITTI gives the GT the detection of
    # highest OVERLAP (B): 1 TP, A is the FP.
    gt = boxes([car(0, 10)])
    pred = boxes([car(0, 10.5, score=0.9), car(0, 10, score=0.5)])
    res = KittiDetection().evaluate_arrays(gt, pred, np.array([0]))
    assert res.per_frame["tp"][1].tolist() == [1.0]
    assert res.per_frame["fp"][1].tolist() == [1.0]
    # min overlap is strict: a detection at IoU exactly … just below 0.7 is no match:
    # shifted 1.2 m: BEV 2.8·2 / (16 − 5.6) = 5.6/10.4 = 0.538 < 0.7 → FN
    res = KittiDetection().evaluate_arrays(gt, boxes([car(0, 11.2, score=0.9)]), np.array([0]))
    assert res.per_frame["missed"][1].tolist() == [1.0]


def test_ignored_classes_and_empty() -> None:
    # a truck GT ignored for "car" (KITTI's Van rule): a car detection on it is neither TP nor FP
    gt = boxes([(0, 3, 10.0, 0.0, 0.0, 4.0, 2.0, 1.5, 0.0, 1.0), car(0, 30)])
    pred = boxes([car(0, 10, score=0.9), car(0, 30, score=0.8)])
    res = KittiDetection(ignored_classes={"car": ["truck"]}).evaluate_arrays(
        gt, pred, np.array([0])
    )
    assert res.per_frame["tp"][1].tolist() == [1.0]
    assert res.per_frame["fp"][1].tolist() == [0.0]
    assert res.values["gt/car"] == 1.0
    # without the rule, the truck is another class: the car detection on it is an FP
    res = KittiDetection().evaluate_arrays(gt, pred, np.array([0]))
    assert res.per_frame["fp"][1].tolist() == [1.0]
    # no ground truth, detections → 0; neither → NaN; ground truth only → 0
    assert evaluate(EMPTY, pred, [0])["AP3D/car"] == 0.0
    assert math.isnan(evaluate(EMPTY, EMPTY, [0])["mAP3D"])
    assert evaluate(gt, EMPTY, [0])["AP3D/car"] == 0.0


def test_yaw_wrap_around_matches() -> None:
    eps = 1e-6
    gt = boxes([car(0, 10, yaw=math.pi - eps)])
    res = KittiDetection().evaluate_arrays(
        gt, boxes([car(0, 10, score=0.9, yaw=-math.pi + eps)]), np.array([0])
    )
    assert res.per_frame["tp"][1].tolist() == [1.0]


def test_azimuth_filter() -> None:
    # a detection behind the car (x < 0) is left out with max_azimuth_deg = 45
    gt = boxes([car(0, 10)])
    pred = boxes([car(0, 10, score=0.5), car(0, -10, score=0.9)])
    res = KittiDetection(max_azimuth_deg=45).evaluate_arrays(gt, pred, np.array([0]))
    assert res.per_frame["fp"][1].tolist() == [0.0]


# ------------------------------------------------------------------------------------------------
# oracle: mmdetection3d kitti_utils/eval.py, loops as published (one difficulty, no DontCare)


def _iou(a: np.ndarray, b: np.ndarray, kind: str) -> float:
    pa = shapely.polygons(bev_corners(a[None, [2, 3, 5, 6, 8]]))[0]
    pb = shapely.polygons(bev_corners(b[None, [2, 3, 5, 6, 8]]))[0]
    inter = shapely.area(shapely.intersection(pa, pb))
    if kind == "bev":
        u = a[5] * a[6] + b[5] * b[6] - inter
        return inter / u if u > 0 else 0.0
    iw = min(a[4] + a[7] / 2, b[4] + b[7] / 2) - max(a[4] - a[7] / 2, b[4] - b[7] / 2)
    if inter <= 0 or iw <= 0:
        return 0.0
    inc = inter * iw
    return inc / (np.prod(a[5:8]) + np.prod(b[5:8]) - inc)


def _compute_statistics(overlaps, ignored_gt, scores, *, min_overlap, thresh, compute_fp):  # type: ignore[no-untyped-def]
    det_size, gt_size = overlaps.shape
    assigned = [False] * det_size
    ignored_threshold = [compute_fp and scores[i] < thresh for i in range(det_size)]
    no_det = -10000000
    tp = fp = fn = 0
    thresholds = []
    for i in range(gt_size):
        if ignored_gt[i] == -1:
            continue
        det_idx, valid, max_overlap = -1, no_det, 0
        for j in range(det_size):
            if assigned[j] or ignored_threshold[j]:
                continue
            ov = overlaps[j, i]
            if not compute_fp and ov > min_overlap and scores[j] > valid:
                det_idx, valid = j, scores[j]
            elif compute_fp and ov > min_overlap and ov > max_overlap:
                max_overlap, det_idx, valid = ov, j, 1
        if valid == no_det and ignored_gt[i] == 0:
            fn += 1
        elif valid != no_det and ignored_gt[i] == 1:
            assigned[det_idx] = True
        elif valid != no_det:
            tp += 1
            thresholds.append(scores[det_idx])
            assigned[det_idx] = True
    if compute_fp:
        fp = sum(1 for i in range(det_size) if not (assigned[i] or ignored_threshold[i]))
    return tp, fp, fn, thresholds


def _oracle_ap(
    gt: np.ndarray, dt: np.ndarray, *, frames: list[int], cls: int, min_overlap: float, kind: str
) -> float:
    per = []
    num_gt = 0
    for f in frames:
        g = gt[(gt[:, 0] == f)]
        g = g[g[:, 1] == cls]
        d = dt[(dt[:, 0] == f) & (dt[:, 1] == cls)]
        ov = np.array([[_iou(a, b, kind) for b in g] for a in d]).reshape(len(d), len(g))
        per.append((ov, [0] * len(g), d[:, 9]))
        num_gt += len(g)
    ths = []
    for ov, ig, sc in per:
        ths += _compute_statistics(
            ov, ig, sc, min_overlap=min_overlap, thresh=0.0, compute_fp=False
        )[3]
    thresholds = get_thresholds(np.array(ths), num_gt) if ths else []
    prec = np.zeros(41)
    for i, t in enumerate(thresholds):
        tp = fp = fn = 0
        for ov, ig, sc in per:
            a, b, c, _ = _compute_statistics(
                ov, ig, sc, min_overlap=min_overlap, thresh=t, compute_fp=True
            )
            tp, fp, fn = tp + a, fp + b, fn + c
        prec[i] = tp / (tp + fp)
    for i in range(len(thresholds)):
        prec[i] = np.max(prec[i:])
    return float(sum(prec[1:]) / 40)


@pytest.mark.parametrize("seed", range(12))
def test_equals_kitti_port(seed: int) -> None:
    rng = np.random.default_rng(seed)
    gts, dts = [], []
    for f in range(6):
        for _ in range(int(rng.integers(3, 12))):
            c = int(rng.integers(0, 2))
            g = [
                f,
                c,
                *rng.uniform(0, 40, 2),
                0.0,
                *(rng.uniform(3.5, 4.5), rng.uniform(1.6, 2.0), 1.5),
                rng.uniform(-3.2, 3.2),
                1.0,
            ]
            gts.append(g)
            if rng.random() < 0.85:
                d = list(g)
                d[2] += rng.normal(0, 0.3)
                d[3] += rng.normal(0, 0.3)
                d[4] += rng.normal(0, 0.2)
                d[8] += rng.normal(0, 0.1)
                d[9] = float(np.round(rng.uniform(0.05, 1), 2))
                dts.append(d)
        for _ in range(int(rng.integers(0, 4))):
            dts.append(
                [
                    f,
                    int(rng.integers(0, 2)),
                    *rng.uniform(0, 40, 2),
                    0.0,
                    4.0,
                    1.8,
                    1.5,
                    0.0,
                    float(np.round(rng.uniform(0, 1), 2)),
                ]
            )
    g, d = np.array(gts), np.array(dts)
    v = evaluate(
        boxes(gts),
        boxes(dts),
        range(6),
        min_overlap_3d={"car": 0.5, "pedestrian": 0.3, "cyclist": 0.5},
        min_overlap_bev={"car": 0.6, "pedestrian": 0.4, "cyclist": 0.5},
    )
    for cls, name, ov3, ovb in ((0, "car", 0.5, 0.6), (1, "pedestrian", 0.3, 0.4)):
        assert v[f"AP3D/{name}"] == pytest.approx(
            _oracle_ap(g, d, frames=list(range(6)), cls=cls, min_overlap=ov3, kind="3d"), abs=1e-9
        )
        assert v[f"APBEV/{name}"] == pytest.approx(
            _oracle_ap(g, d, frames=list(range(6)), cls=cls, min_overlap=ovb, kind="bev"), abs=1e-9
        )


# ------------------------------------------------------------------------------------------------
# the reference detector on the real KITTI frames


@pytest.mark.shared_data
def test_reference_detector_on_kitti(shared_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert (
        main(
            [
                "run",
                str(shared_data / "kitti_object"),
                "--perception",
                "cluster-detector",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    data = EvalData(open_run(out), "cluster-detector")
    # KITTI's strict overlaps (car 0.7, pedestrian/cyclist 0.5) and trucks at 0.7, camera view
    strict = KittiDetection(
        classes={
            "car": ["vehicle"],
            "pedestrian": ["pedestrian"],
            "cyclist": ["bicycle"],
            "truck": ["truck"],
        },
        min_overlap_3d={"car": 0.7, "pedestrian": 0.5, "cyclist": 0.5, "truck": 0.7},
        min_overlap_bev={"car": 0.7, "pedestrian": 0.5, "cyclist": 0.5, "truck": 0.7},
        max_azimuth_deg=45,
    ).evaluate(data)
    v = strict.values
    # found: the pedestrian (3D IoU 0.53) and the truck (3D IoU 0.71) — missed: both cars at 0.7
    # (the near car's box is 0.52 BEV IoU; the far 9-point car has no detection) and the cyclist
    assert v["recall3D/pedestrian"] == 1.0
    assert v["recall3D/truck"] == 1.0
    assert v["recall3D/car"] == 0.0
    assert v["recall3D/cyclist"] == 0.0
    assert (v["gt/car"], v["gt/pedestrian"], v["gt/truck"], v["gt/cyclist"]) == (2.0, 1.0, 1.0, 1.0)
    # one ground truth per class: R40 has one threshold at recall position 0 → AP 0 everywhere
    assert v["mAP3D"] == 0.0
    assert v["mAPBEV"] == 0.0
    # KITTI's loose overlaps (car 0.5 BEV): the near car is found, the 9-point car is not
    loose = KittiDetection(
        min_overlap_bev={"car": 0.5, "pedestrian": 0.25, "cyclist": 0.25}, max_azimuth_deg=45
    ).evaluate(data)
    assert loose.values["recallBEV/car"] == 0.5
    nus = NuScenesDetection().evaluate(data).values
    assert nus["recall/pedestrian/2.0"] == 1.0
    assert nus["recall/car/2.0"] == 1.0  # the 9-point car at 61 m is beyond nuScenes' 50 m range
    # the truck at 70 m and the cyclist at 46 m are beyond 50 m / 40 m: no GT, detections → AP 0
    assert math.isnan(nus["recall/truck/2.0"])
    assert nus["AP/truck"] == 0.0
    assert nus["gt_objects"] == 2.0  # the pedestrian and the near car
    assert 0.0 < nus["mAP"] < 0.05  # many false positives: 65 detections for 2 objects
