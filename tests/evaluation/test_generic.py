"""Generic label/number metrics and object attributes, with hand-computed answers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from redrive.evaluation.base import EvalData
from redrive.evaluation.generic import (
    ObjectAttributes,
    accuracy,
    mae,
    match_by_centre,
    per_class_scores,
    precision_recall,
    rmse,
)
from redrive.results import (
    AlgorithmEntry,
    FrameRecord,
    PipelineInfo,
    RunSetup,
    RunWriter,
    SourceLog,
    StepRecord,
    open_run,
)
from redrive.types import Box3D, DetectedObject, ObjectClass, Role

T0_NS = 1_700_000_000_000_000_000


def test_accuracy() -> None:
    assert accuracy(["a", "b", "c", "a"], ["a", "b", "a", "a"]) == 0.75  # 3 of 4
    assert accuracy(np.array([1, 0, 1]), np.array([1, 1, 1])) == pytest.approx(2 / 3)
    assert math.isnan(accuracy([], []))
    with pytest.raises(ValueError, match="2 predictions but 1 truths"):
        accuracy([1, 2], [1])


def test_precision_recall_and_their_undefined_cases() -> None:
    labels = [True, True, False, True, False]
    truth = [True, False, False, True, True]
    # TP = 2 (0, 3), FP = 1 (1), FN = 1 (4): P = 2/3, R = 2/3
    p, r = precision_recall(labels, truth)
    assert (p, r) == (pytest.approx(2 / 3), pytest.approx(2 / 3))
    # nothing predicted positive → precision NaN; recall 0/2 = 0
    p, r = precision_recall([False, False], [True, True])
    assert math.isnan(p)
    assert r == 0.0
    # nothing truly positive → recall NaN; precision 0/1 = 0
    p, r = precision_recall(["car", "ped"], ["ped", "ped"], positive="car")
    assert p == 0.0
    assert math.isnan(r)
    # empty → both NaN
    assert all(math.isnan(x) for x in precision_recall([], []))


def test_per_class_macro_and_micro() -> None:
    labels = ["car", "car", "ped", "ped", "bike"]
    truth = ["car", "ped", "ped", "ped", "car"]
    s = per_class_scores(labels, truth)
    # car: TP 1, FP 1 (pred car, truth ped), FN 1 (truth car, pred bike): P 1/2, R 1/2, F1 1/2
    # ped: TP 2, FP 0, FN 1: P 1, R 2/3, F1 = 2·(2/3)/(5/3) = 0.8
    # bike: TP 0, FP 1, FN 0 (no bike in truth): P 0, R NaN, F1 NaN
    assert list(s.per_class) == ["bike", "car", "ped"]  # sorted
    assert s.per_class["car"] == (0.5, 0.5, 0.5, 2)
    prec, rec, f1, support = s.per_class["ped"]
    assert (prec, rec, f1, support) == (1.0, pytest.approx(2 / 3), pytest.approx(0.8), 3)
    bike = s.per_class["bike"]
    assert bike[0] == 0.0
    assert math.isnan(bike[1])
    assert math.isnan(bike[2])
    assert bike[3] == 0
    # macro over defined values: P (0 + 0.5 + 1)/3 = 0.5; R (0.5 + 2/3)/2 = 7/12;
    # F1 (0.5 + 0.8)/2 = 0.65
    assert s.macro_precision == pytest.approx(0.5)
    assert s.macro_recall == pytest.approx(7 / 12)
    assert s.macro_f1 == pytest.approx(0.65)
    # micro: TP 3, FP 2, FN 2 → P = R = F1 = 3/5 = accuracy
    assert s.micro_precision == s.micro_recall == s.micro_f1 == pytest.approx(0.6)
    assert accuracy(labels, truth) == pytest.approx(0.6)
    # F1 is 0 (not NaN) when precision and recall are both 0
    assert per_class_scores(["a", "b"], ["b", "a"]).per_class["a"][2] == 0.0
    empty = per_class_scores([], [])
    assert dict(empty.per_class) == {}
    assert math.isnan(empty.macro_f1)
    assert math.isnan(empty.micro_precision)


def test_rmse_and_mae() -> None:
    # errors 1, −2, 2: RMSE = sqrt((1 + 4 + 4)/3) = sqrt(3); MAE = 5/3
    assert rmse([1.0, 0.0, 5.0], [0.0, 2.0, 3.0]) == pytest.approx(math.sqrt(3))
    assert mae([1.0, 0.0, 5.0], [0.0, 2.0, 3.0]) == pytest.approx(5 / 3)
    # any shape, all elements: [[3, 4]] vs 0 → sqrt(25/2)
    assert rmse([[3.0, 4.0]], [[0.0, 0.0]]) == pytest.approx(math.sqrt(12.5))
    assert math.isnan(rmse([], []))
    assert math.isnan(mae([], []))
    assert math.isnan(rmse([1.0, math.nan], [1.0, 1.0]))  # NaN propagates
    with pytest.raises(ValueError, match="differ"):
        mae([1.0, 2.0], [1.0])


def obj(
    x: float,
    y: float,
    cls: ObjectClass,
    *,
    size: tuple[float, float, float] = (4.0, 2.0, 1.5),
    yaw: float = 0.0,
    v: tuple[float, float] = (0.0, 0.0),
) -> DetectedObject:
    return DetectedObject(
        object_id=-1,
        object_class=cls,
        confidence=0.9,
        box=Box3D(center=np.array([x, y, 0.8]), size=np.array(size), yaw_rad=yaw),
        velocity=np.array([v[0], v[1], 0.0]),
    )


def test_matching_is_optimal_not_greedy() -> None:
    # truth at x = 1 and x = −1; detections at 0.1 and 1.9 (gate 2 m). Greedy-nearest would pair
    # 0.1 with 1 (0.9 m) and leave 1.9 ↔ −1 (2.9 m) beyond the gate: one pair. The optimal
    # assignment pairs 0.1 ↔ −1 (1.1 m) and 1.9 ↔ 1 (0.9 m): two pairs.
    truth = [obj(1.0, 0.0, ObjectClass.VEHICLE), obj(-1.0, 0.0, ObjectClass.VEHICLE)]
    dets = [obj(0.1, 0.0, ObjectClass.VEHICLE), obj(1.9, 0.0, ObjectClass.VEHICLE)]
    assert sorted(match_by_centre(dets, truth)) == [(0, 1), (1, 0)]
    assert match_by_centre(dets, truth, max_distance_m=0.5) == []
    assert match_by_centre([], truth) == []


SETUP = RunSetup(
    log=SourceLog(path="synthetic", sha256="x", format="synthetic"),
    seed=0,
    pipeline=PipelineInfo(first_frame=0),
    algorithms=(AlgorithmEntry(name="det", version="1", config_hash="a", role=Role.PERCEPTION),),
)


def test_object_attributes(tmp_path: Path) -> None:
    frame0_truth = (
        obj(10.0, 0.0, ObjectClass.VEHICLE, yaw=0.1, v=(1.0, 0.0)),
        obj(20.0, 5.0, ObjectClass.PEDESTRIAN, size=(0.5, 0.5, 1.8), yaw=3.1, v=(0.0, 1.0)),
    )
    frame0_dets = (
        # Δ position (0.3, 0.4) → 0.5 m; Δ size (0.5, 0, 0); Δ yaw (0.05 + 2π) − 0.1 → −0.05
        obj(
            10.3,
            0.4,
            ObjectClass.VEHICLE,
            size=(4.5, 2.0, 1.5),
            yaw=0.05 + 2 * math.pi,
            v=(1.5, 0.0),
        ),
        # a pedestrian called a vehicle; Δ position (0, 0.5); Δ yaw −3.1 − 3.1 = −6.2 → wrapped
        # −6.2 + 2π = 0.0831853; Δ velocity (0, −1)
        obj(20.0, 5.5, ObjectClass.VEHICLE, size=(0.5, 0.5, 1.8), yaw=-3.1),
        obj(50.0, 0.0, ObjectClass.VEHICLE),  # nothing there
    )
    out = tmp_path / "run"
    with RunWriter(out, setup=SETUP) as writer:
        for i, (dets, truth, status) in enumerate(
            [
                (frame0_dets, frame0_truth, "ok"),
                ((), (), "ok"),  # empty ground truth
                (None, (obj(0.0, 0.0, ObjectClass.VEHICLE),), "error"),  # step failed
            ]
        ):
            step = StepRecord(
                algorithm="det", stage="perception", role="perception", status=status, output=dets
            )
            writer.write_frame(
                FrameRecord(
                    frame_index=i, stamp_ns=T0_NS + i * 10**8, steps=(step,), ground_truth=truth
                )
            )
    res = ObjectAttributes().evaluate(EvalData(open_run(out), "det"))
    v = res.values
    assert res.headline == "class_accuracy"
    assert v["class_accuracy"] == 0.5  # 1 of 2 matched pairs
    assert v["precision/vehicle"] == 0.5  # two called vehicle, one is
    assert v["recall/vehicle"] == 1.0
    assert math.isnan(v["precision/pedestrian"])  # never predicted
    assert v["recall/pedestrian"] == 0.0
    assert v["position_rmse_m"] == pytest.approx(0.5)  # sqrt((0.25 + 0.25)/2)
    assert v["size_rmse_m"] == pytest.approx(math.sqrt(0.125))  # sqrt((0.25 + 0)/2)
    yaw_rmse = math.sqrt((0.05**2 + (2 * math.pi - 6.2) ** 2) / 2)
    assert v["yaw_rmse_rad"] == pytest.approx(yaw_rmse)
    assert v["velocity_rmse_mps"] == pytest.approx(math.sqrt((0.25 + 1.0) / 2))
    assert v["matched"] == 2
    assert v["unmatched_detections"] == 1
    assert v["unmatched_ground_truth"] == 1  # the failed frame's object
    frames, matched = res.per_frame["matched"]
    assert frames.tolist() == [0, 1, 2]
    assert matched.tolist() == [2.0, 0.0, 0.0]


def test_demo_run_gives_finite_values(demo_run: Path) -> None:
    res = ObjectAttributes().evaluate(EvalData(open_run(demo_run), "tracker"))
    keys = [
        "class_accuracy",
        "position_rmse_m",
        "size_rmse_m",
        "yaw_rmse_rad",
        "velocity_rmse_mps",
        "matched",
    ]
    assert all(math.isfinite(res.values[k]) for k in keys), dict(res.values)
    assert res.values["matched"] > 0
