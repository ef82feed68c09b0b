"""hota: HOTA, DetA, AssA, LocA on small worked examples, checked by hand at one α and over all.

The similarity is TrackEval's distance similarity ``max(0, 1 − d / 2 m)`` unless said otherwise:
a prediction on its truth has similarity 1, one 1 m away 0.5, one ≥ 2 m away 0.
α runs over 0.05, 0.10, …, 0.95 (19 values); index 9 is α = 0.50, index 10 is α = 0.55.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import ConfigError
from redrive.evaluation import EvalData
from redrive.evaluation.hota import ALPHAS, Hota, hota_sequence
from redrive.results import open_run
from redrive.types import ObjectClass
from tests.evaluation.test_tracking import Scene, obj, write_run

A50, A55 = 9, 10


def hota(tmp_path: Path, scenes: list[Scene], **params: object) -> dict[str, float]:
    run = open_run(write_run(tmp_path / "run", scenes))
    return dict(Hota(**params).evaluate(EvalData(run, "trk")).values)


def test_alphas_are_trackevals() -> None:
    assert ALPHAS.size == 19
    assert ALPHAS[0] == pytest.approx(0.05)
    assert ALPHAS[A50] == pytest.approx(0.50)
    assert ALPHAS[A55] == pytest.approx(0.55)
    assert ALPHAS[-1] == pytest.approx(0.95)


def test_perfect_tracking_is_one(tmp_path: Path) -> None:
    scenes: list[Scene] = [
        ((obj(1, 10.0 + i), obj(2, 20.0, 5.0)), (obj(10, 10.0 + i), obj(20, 20.0, 5.0)))
        for i in range(5)
    ]
    v = hota(tmp_path, scenes)
    assert next(iter(v)) == "HOTA"
    for key in ("HOTA", "DetA", "AssA", "LocA", "DetRe", "DetPr", "AssRe", "AssPr", "HOTA@0.5"):
        assert v[key] == pytest.approx(1.0), key


def test_one_prediction_switching_between_two_truths(tmp_path: Path) -> None:
    # truths a (x=10) and b (x=30) on frames 0..3; one track p on a for frames 0, 1, on b for
    # frame 2 and 1 m from b (similarity 0.5) on frame 3.
    scenes: list[Scene] = [
        ((obj(1, 10.0), obj(2, 30.0)), (obj(7, 10.0),)),
        ((obj(1, 10.0), obj(2, 30.0)), (obj(7, 10.0),)),
        ((obj(1, 10.0), obj(2, 30.0)), (obj(7, 30.0),)),
        ((obj(1, 10.0), obj(2, 30.0)), (obj(7, 31.0),)),
    ]
    run = open_run(write_run(tmp_path / "run", scenes))
    res = Hota().evaluate(EvalData(run, "trk"))
    # Global alignment: in every frame p overlaps one truth only, so S / (rowsum + colsum − S)
    # is 1 for that pair (also for S = 0.5: 0.5 / (0.5 + 0.5 − 0.5)); C(a,p) = C(b,p) = 2,
    # n_a = n_b = n_p = 4 → A(a,p) = A(b,p) = 2 / (4 + 4 − 2) = 1/3; the matching is p ↔ the
    # truth it sits on.
    # α ≤ 0.5 (10 values): TP 4, FN 4, FP 0 → DetA = 4/8 = 1/2, DetRe = 1/2, DetPr = 1;
    #   M(a,p) = M(b,p) = 2 → AssA = (2 · 2/(4+4−2) + 2 · 2/(4+4−2)) / 4 = 1/3,
    #   AssRe = (2 · 2/4 + 2 · 2/4) / 4 = 1/2, AssPr = (2 · 2/4 + 2 · 2/4) / 4 = 1/2;
    #   HOTA = sqrt(1/2 · 1/3) = sqrt(1/6); LocA = (1 + 1 + 1 + 0.5) / 4 = 0.875.
    # α > 0.5 (9 values): frame 3's pair (S = 0.5) is not a TP: TP 3, FN 5, FP 1 → DetA = 3/9;
    #   M(a,p) = 2, M(b,p) = 1 → AssA = (2 · 2/6 + 1 · 1/7) / 3 = (2/3 + 1/7) / 3 = 17/63;
    #   HOTA = sqrt(1/3 · 17/63) = sqrt(17/189); LocA = 1.
    c = res.curves
    assert c["HOTA(alpha)"][0] == pytest.approx(ALPHAS)
    assert c["DetA(alpha)"][1][A50] == pytest.approx(0.5)
    assert c["AssA(alpha)"][1][A50] == pytest.approx(1 / 3)
    assert c["HOTA(alpha)"][1][A50] == pytest.approx(math.sqrt(1 / 6))
    assert c["LocA(alpha)"][1][A50] == pytest.approx(0.875)
    assert c["DetA(alpha)"][1][A55] == pytest.approx(1 / 3)
    assert c["AssA(alpha)"][1][A55] == pytest.approx(17 / 63)
    assert c["HOTA(alpha)"][1][A55] == pytest.approx(math.sqrt(17 / 189))
    assert c["LocA(alpha)"][1][A55] == pytest.approx(1.0)
    # the curves are flat on either side of 0.5
    np.testing.assert_allclose(c["HOTA(alpha)"][1][:10], math.sqrt(1 / 6))
    np.testing.assert_allclose(c["HOTA(alpha)"][1][10:], math.sqrt(17 / 189))
    v = res.values
    assert v["HOTA"] == pytest.approx((10 * math.sqrt(1 / 6) + 9 * math.sqrt(17 / 189)) / 19)
    assert v["DetA"] == pytest.approx((10 * 1 / 2 + 9 * 1 / 3) / 19)  # = 8/19
    assert v["AssA"] == pytest.approx((10 * 1 / 3 + 9 * 17 / 63) / 19)  # = 121/399
    assert v["LocA"] == pytest.approx((10 * 0.875 + 9 * 1.0) / 19)
    assert v["DetRe"] == pytest.approx((10 * 4 / 8 + 9 * 3 / 8) / 19)
    assert v["DetPr"] == pytest.approx((10 * 4 / 4 + 9 * 3 / 4) / 19)
    # α > 0.5: AssRe = (2 · 2/4 + 1 · 1/4) / 3 = 5/12, AssPr = (2 · 2/4 + 1 · 1/4) / 3 = 5/12
    assert v["AssRe"] == pytest.approx((10 * 1 / 2 + 9 * 5 / 12) / 19)
    assert v["AssPr"] == pytest.approx((10 * 1 / 2 + 9 * 5 / 12) / 19)
    assert v["HOTA@0.5"] == pytest.approx(math.sqrt(1 / 6))
    # per frame at α = 0.5: one TP, one FN each frame
    assert res.per_frame["tp@0.5"][1].tolist() == [1, 1, 1, 1]
    assert res.per_frame["fn@0.5"][1].tolist() == [1, 1, 1, 1]
    assert res.per_frame["fp@0.5"][1].tolist() == [0, 0, 0, 0]


def test_same_example_from_similarity_matrices() -> None:
    # the example above fed directly, with arbitrary (non-contiguous) ids
    sims = [np.array([[1.0], [0.0]])] * 2 + [np.array([[0.0], [1.0]]), np.array([[0.0], [0.5]])]
    res = hota_sequence([np.array([40, 3])] * 4, [np.array([-9])] * 4, similarity=sims)
    assert res.scores["HOTA"][A50] == pytest.approx(math.sqrt(1 / 6))
    assert res.scores["HOTA"][A55] == pytest.approx(math.sqrt(17 / 189))
    assert res.tp[A50] == 4
    assert res.fn[A55] == 5
    assert res.fp[A55] == 1
    assert res.mean("DetA") == pytest.approx(8 / 19)
    assert res.mean("AssA") == pytest.approx(121 / 399)


def test_id_switch_halves_association(tmp_path: Path) -> None:
    # truth a on frames 0..3, track 1 on frames 0, 1 and track 2 on frames 2, 3, all exact
    scenes: list[Scene] = [
        ((obj(5, 10.0 + i),), (obj(1 if i < 2 else 2, 10.0 + i),)) for i in range(4)
    ]
    v = hota(tmp_path, scenes)
    # every α: TP 4, FN 0, FP 0 → DetA = 1; M(a,1) = M(a,2) = 2, n_a = 4, n_1 = n_2 = 2
    # AssA = (2 · 2/(4+2−2) + 2 · 2/(4+2−2)) / 4 = 1/2; HOTA = sqrt(1 · 1/2)
    # AssRe = (2 · 2/4 + 2 · 2/4) / 4 = 1/2; AssPr = (2 · 2/2 + 2 · 2/2) / 4 = 1
    assert v["DetA"] == pytest.approx(1.0)
    assert v["AssA"] == pytest.approx(0.5)
    assert v["HOTA"] == pytest.approx(math.sqrt(0.5))
    assert v["AssRe"] == pytest.approx(0.5)
    assert v["AssPr"] == pytest.approx(1.0)


def test_missed_frame(tmp_path: Path) -> None:
    # truth a on frames 0..4, track 1 on all but frame 2
    scenes: list[Scene] = [((obj(5, 10.0),), () if i == 2 else (obj(1, 10.0),)) for i in range(5)]
    v = hota(tmp_path, scenes)
    # TP 4, FN 1 → DetA = 4/5; M(a,1) = 4, n_a = 5, n_1 = 4 → AssA = 4 · 4/(5+4−4) / 4 = 4/5
    # HOTA = sqrt(4/5 · 4/5) = 0.8; AssRe = 4/5, AssPr = 1
    assert v["DetA"] == pytest.approx(0.8)
    assert v["AssA"] == pytest.approx(0.8)
    assert v["HOTA"] == pytest.approx(0.8)
    assert v["AssRe"] == pytest.approx(0.8)
    assert v["AssPr"] == pytest.approx(1.0)


def test_alignment_decides_the_matching(tmp_path: Path) -> None:
    # frames 0..2: truth a at x = 10 and track p on it; frame 3: p at (10, 0), a 1 m ahead
    # (S = 0.5) and a new truth b 0.8 m to its left (S = 1 − 0.8/2 = 0.6).  Matching on S alone
    # would take b; HOTA weights S by the alignment A.
    scenes: list[Scene] = [((obj(1, 10.0),), (obj(7, 10.0),)) for _ in range(3)]
    scenes.append(((obj(1, 11.0), obj(2, 10.0, 0.8)), (obj(7, 10.0),)))
    run = open_run(write_run(tmp_path / "run", scenes))
    res = Hota().evaluate(EvalData(run, "trk"))
    # frame 3: column sum 1.1 → C(a,p) += 0.5/1.1 = 5/11, C(b,p) += 0.6/1.1 = 6/11;
    # C(a,p) = 3 + 5/11 = 38/11, n_a = 4, n_b = 1, n_p = 4:
    # A(a,p) = (38/11) / (8 − 38/11) = 38/50 = 0.76, A(b,p) = (6/11) / (5 − 6/11) = 6/49;
    # scores 0.76 · 0.5 = 0.38 > 6/49 · 0.6 ≈ 0.073 → p ↔ a.
    # α ≤ 0.5: TP 4, FN 1 (b), FP 0 → DetA = 4/5; M(a,p) = 4 → AssA = 4 · 4/(4+4−4) / 4 = 1;
    #   HOTA = sqrt(0.8); LocA = (3 + 0.5) / 4 = 0.875
    # α > 0.5: TP 3, FN 2, FP 1 → DetA = 3/6; M(a,p) = 3 → AssA = 3 · 3/(4+4−3) / 3 = 3/5;
    #   HOTA = sqrt(0.5 · 0.6) = sqrt(0.3)
    c = res.curves
    assert c["DetA(alpha)"][1][A50] == pytest.approx(0.8)
    assert c["AssA(alpha)"][1][A50] == pytest.approx(1.0)
    assert c["HOTA(alpha)"][1][A50] == pytest.approx(math.sqrt(0.8))
    assert c["LocA(alpha)"][1][A50] == pytest.approx(0.875)
    assert c["DetA(alpha)"][1][A55] == pytest.approx(0.5)
    assert c["AssA(alpha)"][1][A55] == pytest.approx(0.6)
    assert c["HOTA(alpha)"][1][A55] == pytest.approx(math.sqrt(0.3))
    assert res.values["HOTA"] == pytest.approx((10 * math.sqrt(0.8) + 9 * math.sqrt(0.3)) / 19)


def test_false_positive_track(tmp_path: Path) -> None:
    # truth a tracked exactly on 3 frames plus a ghost track 20 m away on the same frames
    scenes: list[Scene] = [((obj(1, 10.0),), (obj(7, 10.0), obj(9, 30.0, 5.0))) for _ in range(3)]
    v = hota(tmp_path, scenes)
    # TP 3, FN 0, FP 3 → DetA = 3/6, DetPr = 1/2, DetRe = 1; AssA = 3 · 3/(3+3−3) / 3 = 1
    assert v["DetA"] == pytest.approx(0.5)
    assert v["DetPr"] == pytest.approx(0.5)
    assert v["DetRe"] == pytest.approx(1.0)
    assert v["AssA"] == pytest.approx(1.0)
    assert v["HOTA"] == pytest.approx(math.sqrt(0.5))


def test_empty_sides(tmp_path: Path) -> None:
    truths: list[Scene] = [((obj(1, 10.0), obj(2, 20.0)), ()) for _ in range(3)]
    v = hota(tmp_path, truths)
    # TrackEval's early return: FN = 6, DetA = AssA = HOTA = 0, LocA = 1
    assert (v["HOTA"], v["DetA"], v["AssA"], v["DetRe"]) == (0.0, 0.0, 0.0, 0.0)
    assert v["LocA"] == 1.0
    ghosts: list[Scene] = [((), (obj(1, 10.0),)) for _ in range(3)]
    v = hota(tmp_path / "b", ghosts)
    assert (v["HOTA"], v["DetA"], v["DetPr"]) == (0.0, 0.0, 0.0)
    assert v["LocA"] == 1.0
    nothing: list[Scene] = [((), ()) for _ in range(2)]
    v = hota(tmp_path / "c", nothing)
    assert math.isnan(v["HOTA"])  # our choice: undefined (TrackEval would say 0)
    assert v["num_frames"] == 2


def test_iou_similarity(tmp_path: Path) -> None:
    # a 4 × 2 m box 1.2 m ahead of its truth: BEV IoU = 2.8·2 / (8 + 8 − 5.6) = 5.6/10.4 ≈ 0.538;
    # distance similarity 1 − 1.2/2 = 0.4
    scenes: list[Scene] = [((obj(1, 10.0),), (obj(7, 11.2),)) for _ in range(2)]
    run = open_run(write_run(tmp_path / "run", scenes))
    iou = Hota(similarity="iou").evaluate(EvalData(run, "trk"))
    dist = Hota().evaluate(EvalData(run, "trk"))
    # IoU: TP for α ≤ 0.538 (10 values: 0.05 … 0.50) → HOTA(α) = 1 there, 0 above → mean 10/19
    assert iou.values["HOTA"] == pytest.approx(10 / 19)
    # LocA(α) = 0.538 where TPs exist, 1 where there are none (TrackEval's 1e-10 / 1e-10)
    assert iou.values["LocA"] == pytest.approx((10 * 5.6 / 10.4 + 9 * 1.0) / 19)
    # distance: TP for α ≤ 0.4 (8 values) → mean 8/19
    assert dist.values["HOTA"] == pytest.approx(8 / 19)


def test_by_class(tmp_path: Path) -> None:
    scenes: list[Scene] = [
        (
            (obj(1, 10.0), obj(2, 5.0, 3.0, cls=ObjectClass.PEDESTRIAN)),
            (obj(10, 10.0), obj(20, 5.0, 3.0, cls=ObjectClass.BICYCLE)),
        )
        for _ in range(2)
    ]
    v = hota(tmp_path, scenes, by_class=True)
    assert v["HOTA"] == pytest.approx(1.0)  # class-agnostic
    assert v["HOTA/vehicle"] == pytest.approx(1.0)
    assert v["HOTA/pedestrian"] == 0.0  # nothing predicted as pedestrian
    assert v["DetPr/bicycle"] == 0.0


def test_bad_parameters() -> None:
    with pytest.raises(ConfigError, match="similarity"):
        Hota(similarity="l2")
    with pytest.raises(ConfigError, match="zero_distance_m"):
        Hota(zero_distance_m=-1.0)
    with pytest.raises(ValueError, match="one entry per frame"):
        hota_sequence([np.array([1])], [], similarity=[])


def test_real_run(demo_run: Path) -> None:
    res = Hota().evaluate(EvalData(open_run(demo_run), "tracker"))
    for key in ("HOTA", "DetA", "AssA", "LocA", "DetRe", "DetPr", "AssRe", "AssPr"):
        assert 0.0 <= res.values[key] <= 1.0, key
    assert res.values["HOTA"] > 0.0
    # DetA can only fall as α rises (fewer matched pairs pass)
    det_a = res.curves["DetA(alpha)"][1]
    assert np.all(np.diff(det_a) <= 1e-12)
    # HOTA(α) = sqrt(DetA(α) · AssA(α))
    np.testing.assert_allclose(
        res.curves["HOTA(alpha)"][1], np.sqrt(det_a * res.curves["AssA(alpha)"][1])
    )
