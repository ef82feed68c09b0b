"""nuPlan's comfort signals and its scenario score (and CLS over a batch) on small drives whose
values are derived by hand here, written with the real RunWriter on the two-lane road of
``test_closedloop_metrics``."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from redrive.evaluation import EvalData, MetricResult
from redrive.evaluation.closedloop import Comfort, DrivableAreaCompliance, NuplanScenarioScore
from redrive.evaluation.closedloop.nuplan import nuplan_scenario_score
from redrive.evaluation.pooling import pool_metric
from redrive.results import FrameRecord, RunWriter, open_run
from redrive.types import ObjectClass, VehicleState
from tests.evaluation.test_closedloop_metrics import (
    ROAD,
    SETUP,
    T0_NS,
    Pose,
    Thing,
    cruise,
    make_run,
)

DT_S = 0.1


def score(run: Path) -> dict[str, float]:
    return dict(NuplanScenarioScore().evaluate(EvalData(open_run(run))).values)


# -- comfort: the states' own acceleration, nuPlan's windows, strict bounds ---------------------


def write_states(tmp_path: Path, name: str, states: list[VehicleState]) -> Path:
    out = tmp_path / name
    with RunWriter(out, setup=SETUP) as writer:
        for i, s in enumerate(states):
            writer.write_frame(
                FrameRecord(frame_index=i, stamp_ns=s.stamp_ns, steps=(), vehicle_state=s)
            )
        writer.write_map(ROAD)
    return out


def braking(accel_mps2: float, n: int = 30) -> list[VehicleState]:
    """Along +x from 25 m/s at a constant ``accel_mps2``, the acceleration in the states."""
    out = []
    for i in range(n):
        t = i * DT_S
        v = 25.0 + accel_mps2 * t
        out.append(
            VehicleState(
                stamp_ns=T0_NS + round(t * 1e9),
                position=np.array([25.0 * t + 0.5 * accel_mps2 * t * t, 0.0, 0.0]),
                velocity=np.array([v, 0.0, 0.0]),
                acceleration=np.array([accel_mps2, 0.0, 0.0]),
            )
        )
    return out


def comfort(run: Path) -> MetricResult:
    return Comfort().evaluate(EvalData(open_run(run)))


def test_comfort_reads_the_states_acceleration_and_its_bounds_are_strict(tmp_path: Path) -> None:
    # a constant signal stays itself under any Savitzky-Golay smoothing: exactly the bound
    at = comfort(write_states(tmp_path, "at", braking(-4.05)))
    assert at.values["acceleration_from_states"] == 1.0
    assert at.values["min_lon_accel_mps2"] == pytest.approx(-4.05, abs=1e-8)
    assert at.values["lon_accel_mps2_within_bound"] == 0.0  # nuPlan: min < value, strictly
    assert at.values["comfortable"] == 0.0
    inside = comfort(write_states(tmp_path, "inside", braking(-4.0)))
    assert inside.values["comfortable"] == 1.0
    assert inside.values["max_abs_jerk_mps3"] == pytest.approx(0.0, abs=1e-8)
    hard = comfort(write_states(tmp_path, "hard", braking(-8.0)))
    assert hard.values["min_lon_accel_mps2"] == pytest.approx(-8.0, abs=1e-8)
    assert hard.values["comfortable"] == 0.0
    assert hard.bookmarks[0].kind == "discomfort"


def turning(yaw_rate: float, n: int = 30, speed: float = 10.0) -> list[VehicleState]:
    """A circle at constant speed and yaw rate (states carry v²κ laterally, as the simulator's)."""
    out = []
    r = speed / yaw_rate
    for i in range(n):
        t = i * DT_S
        h = yaw_rate * t
        c, s = math.cos(h), math.sin(h)
        out.append(
            VehicleState(
                stamp_ns=T0_NS + round(t * 1e9),
                position=np.array([r * s, r * (1.0 - c), 0.0]),
                velocity=np.array([speed * c, speed * s, 0.0]),
                acceleration=np.array([-speed * yaw_rate * s, speed * yaw_rate * c, 0.0]),
                heading_rad=h,
                yaw_rate_rad_s=yaw_rate,
            )
        )
    return out


def test_yaw_rate_bound_is_strict_and_the_centre_shift_is_the_devkits(tmp_path: Path) -> None:
    res = comfort(write_states(tmp_path, "turn", turning(0.5)))
    _, yaw_rate = res.per_frame["yaw_rate_rad_s"]
    assert yaw_rate == pytest.approx(0.5, abs=1e-8)  # a linear heading: its exact derivative
    assert res.values["max_abs_yaw_accel_rad_s2"] == pytest.approx(0.0, abs=1e-8)
    # DynamicCarState.center_acceleration_2d: x gains d·ω² (d = 4.7/2 − 0.95 = 1.4 m), y is the
    # rear axle's lateral acceleration v·ω
    _, lon = res.per_frame["lon_accel_mps2"]
    _, lat = res.per_frame["lat_accel_mps2"]
    assert lon == pytest.approx(1.4 * 0.5**2, abs=1e-8)
    assert lat == pytest.approx(10.0 * 0.5, abs=1e-8)
    assert res.values["comfortable"] == 0.0  # 5 m/s² lateral > 4.89
    assert res.values["lat_accel_mps2_within_bound"] == 0.0
    slow = comfort(write_states(tmp_path, "slow", turning(0.95, speed=2.0)))
    assert slow.values["max_abs_yaw_rate_rad_s"] == pytest.approx(0.95, abs=1e-8)
    assert slow.values["yaw_rate_rad_s_within_bound"] == 0.0  # |0.95| < 0.95 fails


def test_states_without_an_acceleration_get_it_from_their_speeds(tmp_path: Path) -> None:
    states = [
        VehicleState(stamp_ns=s.stamp_ns, position=s.position, velocity=s.velocity, heading_rad=0.0)
        for s in braking(-3.0)
    ]
    res = comfort(write_states(tmp_path, "bare", states))
    assert res.values["acceleration_from_states"] == 0.0
    assert res.values["min_lon_accel_mps2"] == pytest.approx(-3.0, abs=1e-8)


# -- nuplan_scenario_score: hand-derived cases --------------------------------------------------


def test_score_of_a_never_moving_ego_is_zero(tmp_path: Path) -> None:
    parked = lambda t: Pose(0.0, 0.0, 0.0, 0.0)  # noqa: E731
    v = score(make_run(tmp_path, parked, logged=cruise(10.0)))  # the expert drove 39 m
    ep = 2.0 / 39.0  # nuPlan floors both progresses at 2 m
    assert v["ego_progress_along_expert_route"] == pytest.approx(ep)
    assert v["ego_is_making_progress"] == 0.0  # 0.051 < 0.2
    assert v["time_to_collision_within_bound"] == 1.0  # stopped: TTC inf
    assert v["weighted_average"] == pytest.approx((5 * ep + 5 + 4 + 2) / 16)
    assert v["multiplier"] == 0.0
    assert v["nuplan_scenario_score"] == 0.0


def test_score_after_an_at_fault_collision(tmp_path: Path) -> None:
    car = make_run(tmp_path, cruise(10.0), things=lambda t: (Thing(30.0, 0.0),), name="car")
    v = score(car)
    assert v["no_ego_at_fault_collisions"] == 0.0  # a stopped vehicle: an agent
    assert v["nuplan_scenario_score"] == 0.0
    cone = make_run(
        tmp_path,
        cruise(10.0),
        things=lambda t: (Thing(30.0, 0.0, cls=ObjectClass.STATIC),),
        name="cone",
    )
    v = score(cone)
    # one object: max(0, 1 − 1/(1 + 1)) = 0.5; TTC 0 at the at-fault frame; the rest 1
    assert v["no_ego_at_fault_collisions"] == 0.5
    assert v["time_to_collision_within_bound"] == 0.0
    assert v["nuplan_scenario_score"] == pytest.approx(0.5 * (5 + 0 + 4 + 2) / 16)


def test_score_with_an_off_road_step(tmp_path: Path) -> None:
    def step_out(y: float) -> Callable[[float], Pose]:
        return lambda t: Pose(10.0 * t, y if abs(t - 2.0) < 1e-9 else 0.0, 0.0, 10.0)

    # at t = 2 s the footprint's right edge (y − 0.95) is 1.7 m past the lane's (−1.75)
    far = make_run(tmp_path, step_out(-2.5), name="far")
    v = score(far)
    assert v["drivable_area_compliance"] == 0.0
    assert v["nuplan_scenario_score"] == 0.0
    # 0.2 m past it: within nuPlan's 0.3 m tolerance
    near = make_run(tmp_path, step_out(-1.0), name="near")
    dac = DrivableAreaCompliance().evaluate(EvalData(open_run(near))).values
    assert dac["off_road_frames"] == 1
    assert dac["max_outside_m"] == pytest.approx(0.2)
    v = score(near)
    assert v["drivable_area_compliance"] == 1.0
    assert v["nuplan_scenario_score"] == pytest.approx(1.0)


def test_score_of_a_slow_but_safe_drive(tmp_path: Path) -> None:
    v = score(make_run(tmp_path, cruise(5.0), logged=cruise(10.0)))
    assert v["ego_progress_along_expert_route"] == pytest.approx(19.5 / 39.0)
    assert v["multiplier"] == 1.0
    assert v["nuplan_scenario_score"] == pytest.approx((5 * 0.5 + 5 + 4 + 2) / 16)


def test_score_of_a_speeding_drive(tmp_path: Path) -> None:
    v = score(make_run(tmp_path, cruise(50 / 3.6 + 2.23 / 2)))
    sl = 1.0 - 0.5 * 40 / 39  # half the 2.23 m/s over, every frame: Σ·dt / (2.23 · 3.9 s)
    assert v["speed_limit_compliance"] == pytest.approx(sl)
    assert v["nuplan_scenario_score"] == pytest.approx((5 + 5 + 4 * sl + 2) / 16)


def test_the_aggregator_leaves_out_a_score_of_none() -> None:
    scores = {
        "no_ego_at_fault_collisions": 1.0,
        "driving_direction_compliance": 0.5,  # a multiplier, its 0.5 as it is
        "ego_progress_along_expert_route": 1.0,
        "time_to_collision_within_bound": 0.0,
        "ego_is_comfortable": None,
        "some_other_metric": 1.0,  # weighted by "default"
    }
    weights = {
        "ego_progress_along_expert_route": 5.0,
        "time_to_collision_within_bound": 5.0,
        "default": 1.0,
    }
    total, multiplier, average = nuplan_scenario_score(scores, weights)
    assert multiplier == 0.5
    assert average == pytest.approx(6.0 / 11.0)
    assert total == pytest.approx(0.5 * 6.0 / 11.0)


def test_cls_is_the_plain_mean_over_the_scenarios(tmp_path: Path) -> None:
    parked = lambda t: Pose(0.0, 0.0, 0.0, 0.0)  # noqa: E731
    runs = [
        make_run(tmp_path, parked, logged=cruise(10.0), name="parked"),  # 0
        make_run(tmp_path, cruise(5.0), logged=cruise(10.0), n=20, name="slow"),
    ]
    metric = NuplanScenarioScore()
    opened = [open_run(r) for r in runs]
    results = [metric.evaluate(EvalData(r)) for r in opened]
    slow = results[1].values["nuplan_scenario_score"]
    assert slow == pytest.approx((5 * 0.5 + 5 + 4 + 2) / 16)
    pooled = pool_metric(metric, algorithm="", runs=opened, results=results)
    assert pooled.rule == "scenario_mean"
    assert next(iter(pooled.values)) == "cls"
    assert pooled.values["cls"] == pytest.approx(slow / 2)  # not weighted by 40 and 20 frames
    assert pooled.values["nuplan_scenario_score"] == pooled.values["cls"]
    assert pooled.frames == 60
