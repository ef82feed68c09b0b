"""clear_mot: CLEAR MOT and identity metrics on hand-made tracks, checked by hand.

Every scenario is a small run written with the real RunWriter: ground-truth boxes 4 m × 2 m,
predictions placed at known offsets, so every count and ratio below is worked out in comments.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import ConfigError
from redrive.evaluation import EvalData, MetricSkipped
from redrive.evaluation.evaluator import evaluate_run
from redrive.evaluation.tracking import ClearMot, bev_iou_matrix
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
SETUP = RunSetup(
    log=SourceLog(path="/data/tracks.mcap", sha256="t", format="mcap"),
    seed=0,
    pipeline=PipelineInfo(first_frame=0, stages=("p",)),
    algorithms=(
        AlgorithmEntry(name="trk", version="1", config_hash="c1", role=Role.PERCEPTION),
        AlgorithmEntry(name="det", version="1", config_hash="c2", role=Role.PERCEPTION),
    ),
)

#: one frame of a scenario: (ground truth or None, tracker output or None = step failed).
Scene = tuple[tuple[DetectedObject, ...] | None, tuple[DetectedObject, ...] | None]


def obj(
    oid: int,
    x: float,
    y: float = 0.0,
    *,
    cls: ObjectClass = ObjectClass.VEHICLE,
    yaw_rad: float = 0.0,
    size: tuple[float, float, float] = (4.0, 2.0, 1.5),
) -> DetectedObject:
    return DetectedObject(
        object_id=oid,
        object_class=cls,
        confidence=0.9,
        box=Box3D(center=np.array([x, y, 0.75]), size=np.array(size), yaw_rad=yaw_rad),
    )


def write_run(path: Path, scenes: Sequence[Scene]) -> Path:
    """A run with tracker ``trk`` (the scenes) and detector ``det`` (the same boxes, ids −1)."""
    with RunWriter(path, setup=SETUP) as writer:
        for i, (gt, pred) in enumerate(scenes):
            steps = []
            if pred is None:
                steps.append(
                    StepRecord(
                        algorithm="trk",
                        stage="p",
                        role="perception",
                        status="error",
                        error_type="RuntimeError",
                        error_message="boom",
                    )
                )
            else:
                steps.append(
                    StepRecord(
                        algorithm="trk", stage="p", role="perception", status="ok", output=pred
                    )
                )
            no_ids = tuple(
                obj(-1, float(o.box.center[0]), float(o.box.center[1])) for o in pred or ()
            )
            steps.append(
                StepRecord(
                    algorithm="det", stage="p", role="perception", status="ok", output=no_ids
                )
            )
            writer.write_frame(
                FrameRecord(
                    frame_index=i,
                    stamp_ns=T0_NS + i * 100_000_000,
                    steps=tuple(steps),
                    ground_truth=gt,
                )
            )
    return path


def clear(tmp_path: Path, scenes: Sequence[Scene], **params: object) -> dict[str, float]:
    run = open_run(write_run(tmp_path / "run", scenes))
    return dict(ClearMot(**params).evaluate(EvalData(run, "trk")).values)


def check_mota_identity(v: dict[str, float]) -> None:
    """MOTA recomputed from the counts: 1 − (FN + FP + IDSW) / GT."""
    want = 1.0 - (v["num_misses"] + v["num_false_positives"] + v["num_switches"]) / v["num_objects"]
    assert v["MOTA"] == pytest.approx(want, abs=1e-12)


def test_perfect_tracking(tmp_path: Path) -> None:
    # two tracks over 5 frames; track 20 is 0.3 m ahead of its truth, track 10 exact
    scenes = [
        ((obj(1, 10 + i), obj(2, 20 - i, 5)), (obj(10, 10 + i), obj(20, 20.3 - i, 5)))
        for i in range(5)
    ]
    v = clear(tmp_path, scenes)
    assert next(iter(v)) == "MOTA"
    assert v["MOTA"] == 1.0  # 1 − (0 + 0 + 0) / 10
    assert v["MOTP"] == pytest.approx(0.15)  # (5 × 0 + 5 × 0.3) / 10 matches
    assert v["IDF1"] == v["IDP"] == v["IDR"] == 1.0
    assert v["num_objects"] == 10
    assert v["num_matches"] == 10
    assert v["num_switches"] == v["num_fragmentations"] == 0
    assert v["num_false_positives"] == v["num_misses"] == 0
    assert v["mostly_tracked"] == 2
    assert v["mostly_lost"] == 0
    assert v["num_frames"] == 5


def test_one_id_switch(tmp_path: Path) -> None:
    # ground truth 7 over frames 0..3; track 1 follows it on 0, 1, track 2 on 2, 3
    scenes = [((obj(7, 10.0 + i),), (obj(1 if i < 2 else 2, 10.0 + i),)) for i in range(4)]
    run = open_run(write_run(tmp_path / "run", scenes))
    res = ClearMot().evaluate(EvalData(run, "trk"))
    v = dict(res.values)
    assert v["num_switches"] == 1
    assert v["MOTA"] == pytest.approx(0.75)  # 1 − (0 FN + 0 FP + 1 IDSW) / 4
    check_mota_identity(v)
    # best one-to-one id assignment: 7 ↔ 1 (or 2): IDTP = 2 of 4 truths and 4 predictions
    assert v["IDF1"] == pytest.approx(0.5)  # 2·2 / (4 + 4)
    assert v["IDP"] == pytest.approx(0.5)  # 2 / 4
    assert v["IDR"] == pytest.approx(0.5)  # 2 / 4
    assert v["num_fragmentations"] == 0  # never untracked
    frames, switches = res.per_frame["switches"]
    assert frames.tolist() == [0, 1, 2, 3]
    assert switches.tolist() == [0, 0, 1, 0]
    assert res.per_frame["fp"][1].tolist() == [0, 0, 0, 0]
    assert len(res.bookmarks) == 1
    mark = res.bookmarks[0]
    assert (mark.frame_index, mark.kind, mark.severity) == (2, "id_switch", 1.0)
    assert mark.detail == "vehicle 7 changed from track 1 to track 2"


def test_one_missed_frame_is_a_fragmentation(tmp_path: Path) -> None:
    # ground truth 7 over frames 0..4; track 1 on every frame but 2
    scenes = [((obj(7, 10.0 + i),), () if i == 2 else (obj(1, 10.0 + i),)) for i in range(5)]
    run = open_run(write_run(tmp_path / "run", scenes))
    res = ClearMot().evaluate(EvalData(run, "trk"))
    v = dict(res.values)
    assert v["num_misses"] == 1
    assert v["num_fragmentations"] == 1  # tracked → lost → tracked again
    assert v["num_switches"] == 0  # the same track resumes
    assert v["MOTA"] == pytest.approx(0.8)  # 1 − 1 / 5
    check_mota_identity(v)
    assert v["IDF1"] == pytest.approx(8 / 9)  # 2·4 / (5 + 4)
    assert v["IDP"] == 1.0  # 4 / 4
    assert v["IDR"] == pytest.approx(0.8)  # 4 / 5
    assert v["mostly_tracked"] == 1  # 4 / 5 = 80 % ≥ 80 %
    assert res.per_frame["misses"][1].tolist() == [0, 0, 1, 0, 0]
    assert res.bookmarks == ()


def test_gate_distance(tmp_path: Path) -> None:
    # frame 2: the track is 3 m off (beyond the 2 m gate): one FP and one FN there
    scenes = [((obj(7, 10.0),), (obj(1, 13.0 if i == 2 else 10.5),)) for i in range(5)]
    v = clear(tmp_path, scenes)
    assert (v["num_misses"], v["num_false_positives"]) == (1, 1)
    assert v["MOTA"] == pytest.approx(0.6)  # 1 − (1 + 1) / 5
    assert v["MOTP"] == pytest.approx(0.5)  # 4 matches at 0.5 m
    # a 4 m gate takes it: MOTP = (4 × 0.5 + 3) / 5 = 1.0
    v4 = clear(tmp_path / "b", scenes, max_distance_m=4.0)
    assert v4["MOTA"] == 1.0
    assert v4["MOTP"] == pytest.approx(1.0)


def test_false_positive_track(tmp_path: Path) -> None:
    # ground truth 7 tracked exactly on 3 frames; a ghost track 9 20 m away on the same frames
    scenes = [((obj(7, 10.0),), (obj(1, 10.0), obj(9, 30.0, 5.0))) for _ in range(3)]
    run = open_run(write_run(tmp_path / "run", scenes))
    res = ClearMot().evaluate(EvalData(run, "trk"))
    v = dict(res.values)
    assert v["num_false_positives"] == 3
    assert v["MOTA"] == 0.0  # 1 − 3 / 3
    check_mota_identity(v)
    assert v["IDF1"] == pytest.approx(2 / 3)  # 2·3 / (3 + 6)
    assert v["IDP"] == pytest.approx(0.5)  # 3 / 6
    assert v["IDR"] == 1.0  # 3 / 3
    assert res.per_frame["fp"][1].tolist() == [1, 1, 1]


def test_empty_ground_truth(tmp_path: Path) -> None:
    # "nothing there" on 3 frames, two tracks reported on each: 6 FPs, MOTA undefined (÷ 0)
    scenes = [((), (obj(1, 10.0), obj(2, 20.0))) for _ in range(3)]
    v = clear(tmp_path, scenes)
    assert v["num_objects"] == 0
    assert v["num_false_positives"] == 6
    assert math.isnan(v["MOTA"])
    assert math.isnan(v["MOTP"])  # no matches
    assert v["IDF1"] == 0.0  # 2·0 / (0 + 6)
    assert v["IDP"] == 0.0


def test_empty_predictions_and_failed_steps(tmp_path: Path) -> None:
    # two truths on 4 frames; the tracker reports nothing on 0, 1, 3 and fails on frame 2
    scenes: list[Scene] = [((obj(1, 10.0), obj(2, 20.0)), None if i == 2 else ()) for i in range(4)]
    v = clear(tmp_path, scenes)
    assert v["num_misses"] == 8  # a failed step is an empty output
    assert v["MOTA"] == 0.0  # 1 − 8 / 8
    assert v["IDF1"] == 0.0  # 2·0 / (8 + 0)
    assert v["IDR"] == 0.0
    assert v["mostly_lost"] == 2
    assert math.isnan(v["MOTP"])
    # nothing on either side: counts 0, ratios undefined
    v0 = clear(tmp_path / "b", [((), ()), ((), ())])
    assert v0["num_objects"] == v0["num_false_positives"] == v0["num_switches"] == 0
    assert math.isnan(v0["MOTA"])
    assert math.isnan(v0["IDF1"])
    assert v0["num_frames"] == 2


def test_frames_without_ground_truth_are_not_scored(tmp_path: Path) -> None:
    # frame 1 has no ground truth in the log (None): its ghost is not a false positive
    scenes: list[Scene] = [
        ((obj(7, 10.0),), (obj(1, 10.0),)),
        (None, (obj(1, 10.0), obj(2, 40.0))),
        ((obj(7, 10.0),), (obj(1, 10.0),)),
    ]
    v = clear(tmp_path, scenes)
    assert v["num_frames"] == 2
    assert v["num_false_positives"] == 0
    assert v["MOTA"] == 1.0


def test_detector_without_track_ids_is_refused(tmp_path: Path) -> None:
    scenes = [((obj(7, 10.0),), (obj(1, 10.0),))]
    path = write_run(tmp_path / "run", scenes)
    with pytest.raises(MetricSkipped, match="'det' produces no track ids"):
        ClearMot().evaluate(EvalData(open_run(path), "det"))
    # evaluate_run scores the tracker and lists the detector as skipped, with the reason
    result = evaluate_run(path, metrics=[ClearMot()])
    assert [(s.metric.name, s.algorithm) for s in result.scored] == [("clear_mot", "trk")]
    assert [s.algorithm for s in result.skipped] == ["det"]
    assert "no track ids" in result.skipped[0].reason


def test_duplicate_ids_in_a_frame_are_refused(tmp_path: Path) -> None:
    scenes = [((obj(7, 10.0),), (obj(1, 10.0), obj(1, 20.0)))]
    with pytest.raises(ConfigError, match="same object_id twice"):
        clear(tmp_path, scenes)


def test_bev_iou_matrix_by_hand() -> None:
    gt = [obj(1, 10.0)]  # 4 × 2 m at (10, 0)
    preds = [
        obj(2, 10.0),  # identical → 1
        obj(3, 11.0),  # 1 m ahead: overlap 3 × 2 = 6, union 8 + 8 − 6 = 10 → 0.6
        obj(4, 10.0, yaw_rad=math.pi / 2),  # crossed: 2 × 2 = 4, union 8 + 8 − 4 = 12 → 1/3
        obj(5, 10.0, yaw_rad=math.pi),  # turned around: the same rectangle → 1
        obj(6, 10.0, yaw_rad=-math.pi + 1e-9),  # across the ±π wrap → 1
        obj(7, 20.0),  # apart → 0
        obj(8, 10.0, size=(0.0, 0.0, 0.0)),  # degenerate: union 8, intersection 0 → 0
    ]
    iou = bev_iou_matrix(gt, preds)
    assert iou.shape == (1, 7)
    np.testing.assert_allclose(iou[0], [1.0, 0.6, 1 / 3, 1.0, 1.0, 0.0, 0.0], atol=1e-9)
    assert bev_iou_matrix([], preds).shape == (0, 7)


def test_iou_similarity(tmp_path: Path) -> None:
    # frame 0: 1 m ahead (IoU 0.6 ≥ 0.5, distance 1 − 0.6 = 0.4);
    # frame 1: crossed at the same centre (IoU 1/3 < 0.5): one FP and one FN
    scenes = [
        ((obj(7, 10.0),), (obj(1, 11.0),)),
        ((obj(7, 10.0),), (obj(1, 10.0, yaw_rad=math.pi / 2),)),
    ]
    run = open_run(write_run(tmp_path / "run", scenes))
    res = ClearMot(similarity="iou").evaluate(EvalData(run, "trk"))
    v = dict(res.values)
    assert v["MOTP"] == pytest.approx(0.4)
    assert res.units["MOTP"] == "1 - IoU"
    assert (v["num_misses"], v["num_false_positives"]) == (1, 1)
    assert v["MOTA"] == 0.0  # 1 − (1 + 1) / 2
    # with the centre distance both frames match: MOTP = (1 + 0) / 2 m
    vd = ClearMot().evaluate(EvalData(run, "trk"))
    assert vd.values["MOTA"] == 1.0
    assert vd.values["MOTP"] == pytest.approx(0.5)
    assert vd.units["MOTP"] == "m"


def test_by_class(tmp_path: Path) -> None:
    # a car tracked right; a pedestrian tracked at the right place but labelled bicycle
    ped = ObjectClass.PEDESTRIAN
    scenes = [
        (
            (obj(1, 10.0), obj(2, 5.0, 3.0, cls=ped)),
            (obj(10, 10.0), obj(20, 5.0, 3.0, cls=ObjectClass.BICYCLE)),
        )
        for _ in range(2)
    ]
    v = clear(tmp_path, scenes, by_class=True)
    assert v["MOTA"] == 1.0  # class-agnostic: both match
    assert v["MOTA/vehicle"] == 1.0
    assert v["MOTA/pedestrian"] == 0.0  # 1 − 2 misses / 2
    assert v["num_false_positives/bicycle"] == 2
    assert math.isnan(v["MOTA/bicycle"])  # no bicycle in the ground truth
    assert "MOTA/truck" not in v


def test_mota_identity_on_a_busy_scene(tmp_path: Path) -> None:
    # 30 frames, 4 truths, a noisy tracker that drops, swaps and adds tracks (seeded)
    rng = np.random.default_rng(5)
    scenes: list[Scene] = []
    for i in range(30):
        gt = tuple(obj(k, 10.0 * k + 0.2 * i, 3.0 * k) for k in range(4))
        pred = []
        for k in range(4):
            if rng.random() < 0.8:
                tid = 100 + k + (10 if i > 15 and k == 1 else 0)
                pred.append(obj(tid, 10.0 * k + 0.2 * i + rng.normal(0, 0.8), 3.0 * k))
        if rng.random() < 0.3:
            pred.append(obj(999, 60.0, 0.0))
        scenes.append((gt, tuple(pred)))
    run = open_run(write_run(tmp_path / "run", scenes))
    res = ClearMot().evaluate(EvalData(run, "trk"))
    v = dict(res.values)
    check_mota_identity(v)
    # the per-frame series add up to the totals
    assert res.per_frame["fp"][1].sum() == v["num_false_positives"]
    assert res.per_frame["misses"][1].sum() == v["num_misses"]
    assert res.per_frame["switches"][1].sum() == v["num_switches"] == len(res.bookmarks)
    assert v["num_switches"] >= 1  # track 101 becomes 111 at frame 16
    assert v["num_objects"] == 120
    assert 0.0 < v["MOTA"] < 1.0


def test_real_run(demo_run: Path) -> None:
    run = open_run(demo_run)
    res = ClearMot().evaluate(EvalData(run, "tracker"))
    v = dict(res.values)
    for key in ("MOTA", "MOTP", "IDF1", "IDP", "IDR"):
        assert math.isfinite(v[key]), key
    assert v["MOTA"] <= 1.0
    assert 0.0 <= v["IDF1"] <= 1.0
    assert 0.0 <= v["MOTP"] <= 2.0  # metres, inside the gate
    check_mota_identity(v)
    with pytest.raises(MetricSkipped, match="no track ids"):
        ClearMot().evaluate(EvalData(run, "clusters"))


def test_bad_parameters() -> None:
    with pytest.raises(ConfigError, match="similarity"):
        ClearMot(similarity="giou")
    with pytest.raises(ConfigError, match="max_distance_m"):
        ClearMot(max_distance_m=0.0)
    with pytest.raises(ConfigError, match="unknown parameter"):
        ClearMot(gate=1.0)
