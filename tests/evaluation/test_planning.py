"""Planning metrics on hand-built runs with exactly known answers.

The logged ego drives straight at 10 m/s with heading 0.5 rad from map (100, 50); frames every
0.1 s. Plans are in base_link of their frame (x forward), so "exact" is x = 10 t, y = 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import ConfigError
from redrive.evaluation.base import EvalData
from redrive.evaluation.evaluator import evaluate_run
from redrive.evaluation.planning import COMFORT_BOUNDS, PlanningMetrics, time_to_collision_s
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
from redrive.types import Box3D, DetectedObject, ObjectClass, PlannedPath, Role, VehicleState

T0_NS = 1_700_000_000_000_000_000
DT_NS = 100_000_000
HEADING = 0.5
SPEED = 10.0
SETUP = RunSetup(
    log=SourceLog(path="synthetic", sha256="x", format="synthetic"),
    seed=0,
    pipeline=PipelineInfo(first_frame=0),
    algorithms=(AlgorithmEntry(name="planner", version="1", config_hash="p", role=Role.PLANNING),),
)

Plan = Callable[[int], np.ndarray]
Truth = Callable[[int], "tuple[DetectedObject, ...] | None"]


def ego_state(i: int) -> VehicleState:
    t = i * 0.1
    c, s = math.cos(HEADING), math.sin(HEADING)
    return VehicleState(
        stamp_ns=T0_NS + i * DT_NS,
        frame_id="map",
        position=np.array([100.0 + SPEED * t * c, 50.0 + SPEED * t * s, 0.0]),
        velocity=np.array([SPEED * c, SPEED * s, 0.0]),
        heading_rad=HEADING,
    )


def plan_xy(x_of_t: Callable[[np.ndarray], np.ndarray], *, y: float = 0.0, end_s: float = 3.0):
    def make(_: int) -> np.ndarray:
        t = np.round(np.arange(0.0, end_s + 1e-9, 0.1), 10)
        return np.column_stack([x_of_t(t), np.full_like(t, y), np.zeros_like(t), t])

    return make


def car(x: float, y: float = 0.0, *, vx: float = 0.0, oid: int = 7) -> DetectedObject:
    """A 4.5 × 1.8 m vehicle, yaw 0, centre (x, y) in base_link, velocity (vx, 0) over ground."""
    return DetectedObject(
        object_id=oid,
        object_class=ObjectClass.VEHICLE,
        box=Box3D(center=np.array([x, y, 0.8]), size=np.array([4.5, 1.8, 1.5])),
        velocity=np.array([vx, 0.0, 0.0]),
    )


def make_run(
    tmp_path: Path, plan: Plan, *, n: int = 40, truth: Truth | None = None, labels: bool = True
) -> Path:
    """A run of a planner; ``labels=False``: the log has no ground-truth objects at all."""
    out = tmp_path / "run"
    with RunWriter(out, setup=SETUP) as writer:
        for i in range(n):
            path = PlannedPath(stamp_ns=T0_NS + i * DT_NS, waypoints=plan(i))
            step = StepRecord(
                algorithm="planner", stage="planning", role="planning", status="ok", output=path
            )
            writer.write_frame(
                FrameRecord(
                    frame_index=i,
                    stamp_ns=T0_NS + i * DT_NS,
                    steps=(step,),
                    vehicle_state=ego_state(i),
                    ground_truth=(truth(i) if truth else ()) if labels else None,
                    wall_ns=1_000_000,
                )
            )
    return out


def evaluate(run: Path, **params: object):
    return PlanningMetrics(**params).evaluate(EvalData(open_run(run), "planner"))


def test_exact_plan_has_zero_displacement_full_progress_and_is_comfortable(tmp_path: Path) -> None:
    res = evaluate(make_run(tmp_path, plan_xy(lambda t: SPEED * t)))
    assert res.headline == "ADE/3s"
    for h in (1, 2, 3):
        assert res.values[f"ADE/{h}s"] == pytest.approx(0.0, abs=1e-9)
        assert res.values[f"FDE/{h}s"] == pytest.approx(0.0, abs=1e-9)
    # 40 frames span 0..3.9 s: a 3 s horizon is covered from frames 0..9 (0.9 + 3 = 3.9)
    frames, _ = res.per_frame["ADE/3s"]
    assert frames.tolist() == list(range(10))
    assert res.per_frame["ADE/1s"][0].tolist() == list(range(30))
    assert res.values["progress_ratio"] == pytest.approx(1.0)
    assert res.values["comfortable_fraction"] == 1.0
    assert res.values["max_abs_lat_accel_mps2"] == pytest.approx(0.0, abs=1e-9)
    # empty ground truth everywhere: nothing to hit, TTC infinite, nothing bookmarked
    assert res.values["collision_rate"] == 0.0
    assert res.values["min_ttc_s"] == math.inf
    assert res.values["low_ttc_fraction"] == 0.0
    assert res.bookmarks == ()
    assert res.values["frames"] == 40


def test_a_log_without_object_labels_still_scores_the_plan_against_the_ego(
    tmp_path: Path,
) -> None:
    """Real logs often have odometry but no labelled objects: ADE/FDE, progress and comfort
    need only the ego track; the collision and TTC values are not defined."""
    run = make_run(tmp_path, plan_xy(lambda t: SPEED * t, y=1.0), labels=False)
    summary = evaluate_run(run, metrics=[PlanningMetrics()])
    assert not summary.skipped, summary.skipped
    (scored,) = summary.scored
    values = scored.result.values
    assert values["ADE/3s"] == pytest.approx(1.0, abs=1e-9)
    assert values["progress_ratio"] == pytest.approx(1.0)
    assert values["comfortable_fraction"] == 1.0
    assert "collision_rate" not in values or math.isnan(values["collision_rate"])
    assert "min_ttc_s" not in values or math.isnan(values["min_ttc_s"])


def test_lateral_offset_of_one_metre_gives_ade_and_fde_one(tmp_path: Path) -> None:
    res = evaluate(make_run(tmp_path, plan_xy(lambda t: SPEED * t, y=1.0)))
    for h in (1, 2, 3):
        # every waypoint is 1 m left of where the logged ego was at that time
        assert res.values[f"ADE/{h}s"] == pytest.approx(1.0, abs=1e-9)
        assert res.values[f"FDE/{h}s"] == pytest.approx(1.0, abs=1e-9)
    # the plan's end projects onto the logged (straight) route at the logged distance
    assert res.values["progress_ratio"] == pytest.approx(1.0)


def test_longitudinal_error_and_progress(tmp_path: Path) -> None:
    fast = evaluate(make_run(tmp_path / "fast", plan_xy(lambda t: 11.0 * t)))
    # error at waypoint t is (11 − 10)·t = t:
    # ADE/1s = mean(0.1 … 1.0) = 0.55, FDE/1s = 1.0; ADE/3s = mean(0.1 … 3.0) = 1.55, FDE 3.0
    assert fast.values["ADE/1s"] == pytest.approx(0.55)
    assert fast.values["FDE/1s"] == pytest.approx(1.0)
    assert fast.values["ADE/3s"] == pytest.approx(1.55)
    assert fast.values["FDE/3s"] == pytest.approx(3.0)
    # ahead of the logged ego: progress 33 m > 30 m logged, ratio clipped to 1 (nuPlan)
    frames, progress = fast.per_frame["progress_m"]
    assert progress[0] == pytest.approx(33.0)
    assert fast.values["progress_ratio"] == pytest.approx(1.0)

    slow = evaluate(make_run(tmp_path / "slow", plan_xy(lambda t: 5.0 * t)))
    frames, ratio = slow.per_frame["progress_ratio"]
    # plan end 5·3 = 15 m along a 30 m logged route → 0.5; frames whose log ends before
    # stamp + 3 s (10 … 39) are not scored
    assert frames.tolist() == list(range(10))
    np.testing.assert_allclose(ratio, 0.5)
    # 0.2 s plans: 1 m against 2 m logged (at the 2 m threshold) → 0.5; 0.1 s plans: 0.5 m
    # against 1 m logged, below the threshold → no ratio (the logged ego barely moved)
    short = evaluate(make_run(tmp_path / "short", plan_xy(lambda t: 5.0 * t, end_s=0.2)))
    assert short.values["progress_ratio"] == pytest.approx(0.5)
    shorter = evaluate(make_run(tmp_path / "shorter", plan_xy(lambda t: 5.0 * t, end_s=0.1)))
    assert math.isnan(shorter.values["progress_ratio"])
    assert shorter.values["progress_m"] == pytest.approx(0.5)


def test_stopped_car_in_the_path_collision_at_fault_and_ttc(tmp_path: Path) -> None:
    # A stopped car (4.5 m long) whose centre is 18.35 − i m ahead of the rear axle at frame i
    # (it stands still in the map while the ego drives 1 m per frame). The ego's front bumper is
    # 4.7 − 0.95 = 3.75 m ahead of the rear axle, the car's rear 2.25 m behind its centre:
    # gap = 18.35 − i − 2.25 − 3.75 = 12.35 − i m, so TTC = gap / 10 m/s = 1.235 − 0.1 i s.
    # A car 8 m behind doing 15 m/s rear-ends the plan (not at fault) and is left out of TTC.
    def truth(i: int) -> tuple[DetectedObject, ...] | None:
        if i >= 10:
            return None
        return (car(18.35 - i, oid=7), car(-8.0, vx=15.0, oid=8))

    res = evaluate(make_run(tmp_path, plan_xy(lambda t: SPEED * t), truth=truth))
    frames, ttc = res.per_frame["min_ttc_s"]
    assert frames.tolist() == list(range(10))
    np.testing.assert_allclose(ttc, 1.235 - 0.1 * np.arange(10), atol=2e-4)
    assert res.values["min_ttc_s"] == pytest.approx(0.335, abs=2e-4)
    # below nuPlan's 0.95 s: 1.235 − 0.1 i < 0.95 ⇔ i ≥ 3 → 7 of 10 frames
    assert res.values["low_ttc_fraction"] == pytest.approx(0.7)
    # the plan drives through the stopped car: a stopped-track collision, at fault, every frame
    assert res.values["collision_rate"] == 1.0
    assert res.values["at_fault_collision_rate"] == 1.0
    assert res.values["collisions"] == 10
    collisions = [b for b in res.bookmarks if b.kind == "collision"]
    low = [b for b in res.bookmarks if b.kind == "low_ttc"]
    assert [b.frame_index for b in collisions] == list(range(10))
    assert [b.frame_index for b in low] == list(range(10))  # all below 1.5 s
    assert low[0].severity == pytest.approx(1 / 1.235, rel=1e-3)
    # frame 0: the rear car touches first: its front −8 + 2.25 + 15 t reaches the ego's rear
    # −0.95 + 10 t at t = 0.96 → waypoint t = 1.0; the stopped car at 3.75 + 10 t ≥ 16.1,
    # t ≥ 1.235 → waypoint 1.3. Severity: the at-fault contact's relative speed, 10 m/s.
    assert "t=1.00 s (active_rear, not at fault" in collisions[0].detail
    assert "at fault with vehicle 7" in collisions[0].detail
    assert collisions[0].severity == pytest.approx(10.0)


def test_rear_end_only_is_not_at_fault_and_behind_objects_have_no_ttc(tmp_path: Path) -> None:
    res = evaluate(
        make_run(tmp_path, plan_xy(lambda t: SPEED * t), n=5, truth=lambda i: (car(-8.0, vx=15.0),))
    )
    assert res.values["collision_rate"] == 1.0
    assert res.values["at_fault_collision_rate"] == 0.0
    assert res.values["min_ttc_s"] == math.inf


def test_car_in_the_next_lane_is_no_collision(tmp_path: Path) -> None:
    # 3.5 m to the left: ego half width 0.95 + car half width 0.9 = 1.85 < 3.5
    res = evaluate(
        make_run(tmp_path, plan_xy(lambda t: SPEED * t), n=5, truth=lambda i: (car(15.0, 3.5),))
    )
    assert res.values["collision_rate"] == 0.0
    assert res.values["min_ttc_s"] == math.inf


def test_plan_that_stops_before_the_car_has_no_collision_but_a_ttc(tmp_path: Path) -> None:
    # brake at 4 m/s² from 10 m/s: stops after 10² / (2·4) = 12.5 m at t = 2.5 s; the car's rear
    # is at 30 − 2.25 = 27.75 m, the stopped ego's front at 12.5 + 3.75 = 16.25 m
    def braking(t: np.ndarray) -> np.ndarray:
        return np.where(t < 2.5, 10 * t - 2 * t**2, 12.5)

    res = evaluate(make_run(tmp_path, plan_xy(braking), n=5, truth=lambda i: (car(30.0 - i),)))
    assert res.values["collision_rate"] == 0.0
    # but TTC assumes the ego keeps its logged 10 m/s along the plan's line (extended past its
    # end): gap 30 − i − 2.25 − 3.75 = 24 − i m → 2.4 − 0.1 i s, within the 3 s horizon
    _, ttc = res.per_frame["min_ttc_s"]
    np.testing.assert_allclose(ttc, 2.4 - 0.1 * np.arange(5), atol=2e-4)


def test_hard_braking_plan_is_not_comfortable(tmp_path: Path) -> None:
    # x = 10 t − 3 t² for 1.5 s: lon accel −6 m/s² < nuPlan's −4.05; jerk 0 (numpy.gradient with
    # second-order edges is exact on quadratics)
    hard = evaluate(make_run(tmp_path / "hard", plan_xy(lambda t: 10 * t - 3 * t**2, end_s=1.5)))
    assert hard.values["min_lon_accel_mps2"] == pytest.approx(-6.0, abs=1e-9)
    assert hard.values["max_lon_accel_mps2"] == pytest.approx(-6.0, abs=1e-9)
    assert hard.values["max_abs_lon_jerk_mps3"] == pytest.approx(0.0, abs=1e-6)
    assert hard.values["comfortable_fraction"] == 0.0
    _, comfortable = hard.per_frame["comfortable"]
    assert comfortable.tolist() == [0.0] * 40
    # −2 m/s² is within bounds
    gentle = evaluate(make_run(tmp_path / "gentle", plan_xy(lambda t: 10 * t - t**2, end_s=1.5)))
    assert gentle.values["min_lon_accel_mps2"] == pytest.approx(-2.0, abs=1e-9)
    assert gentle.values["comfortable_fraction"] == 1.0
    # a 1.5 s plan has no 2 s or 3 s horizon: undefined, not zero
    assert math.isnan(hard.values["ADE/3s"])


def test_tight_turn_breaks_the_lateral_acceleration_bound(tmp_path: Path) -> None:
    # a circle of radius 20 m at 10 m/s: lat accel v²/R = 5.0 > 4.89, yaw rate v/R = 0.5 rad/s.
    # Central differences of sin(ωt) with step h carry a factor sin(ωh)/(ωh) ≈ 1 − (ωh)²/6 per
    # derivative (ωh = 0.05): within 1e-2 of the exact values.
    def circle(_: int) -> np.ndarray:
        t = np.round(np.arange(0.0, 3.0 + 1e-9, 0.1), 10)
        w = 0.5
        return np.column_stack([20 * np.sin(w * t), 20 * (1 - np.cos(w * t)), 0 * t, t])

    res = evaluate(make_run(tmp_path, circle, n=3))
    assert res.values["max_abs_lat_accel_mps2"] == pytest.approx(5.0, abs=1e-2)
    assert res.values["max_abs_yaw_rate_rad_s"] == pytest.approx(0.5, abs=1e-3)
    assert res.values["comfortable_fraction"] == 0.0


def test_ttc_function_and_bounds_are_nuplans() -> None:
    assert dict(COMFORT_BOUNDS) == {
        "min_lon_accel_mps2": -4.05,
        "max_lon_accel_mps2": 2.40,
        "max_abs_lat_accel_mps2": 4.89,
        "max_abs_yaw_rate_rad_s": 0.95,
        "max_abs_yaw_accel_rad_s2": 1.93,
        "max_abs_lon_jerk_mps3": 4.13,
        "max_abs_jerk_mps3": 8.37,
    }
    line = np.array([[0.0, 0.0], [30.0, 0.0]])
    # car 12 m ahead driving away at 4 m/s, ego 10 m/s: gap 12 − 2.25 − 3.75 = 6 m closes at
    # 6 m/s → 1.0 s
    ttc, oid = time_to_collision_s(line, [car(12.0, vx=4.0, oid=3)], speed_mps=10.0)
    assert ttc == pytest.approx(1.0, abs=2e-4)
    assert oid == 3
    # already touching → 0; stopped ego → inf
    assert time_to_collision_s(line, [car(5.0)], speed_mps=10.0)[0] == 0.0
    assert time_to_collision_s(line, [car(12.0)], speed_mps=0.0)[0] == math.inf
    # along a bent path: the ego follows the plan's geometry, not a straight line
    bent = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 30.0]])
    ttc_bent, _ = time_to_collision_s(bent, [car(20.0)], speed_mps=10.0)
    assert ttc_bent == math.inf


def test_parameters_are_checked() -> None:
    with pytest.raises(ConfigError):
        PlanningMetrics(horizons_s=(0.0,))
    with pytest.raises(ConfigError):
        PlanningMetrics(not_a_param=1)


def test_demo_run_gives_finite_values(demo_run: Path) -> None:
    res = PlanningMetrics().evaluate(EvalData(open_run(demo_run), "planner"))
    finite = [k for k, v in res.values.items() if k not in ("min_ttc_s",)]
    assert all(math.isfinite(res.values[k]) for k in finite), dict(res.values)
    assert res.values["frames"] > 0
