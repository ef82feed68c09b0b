"""The closed-loop metrics (nuPlan's definitions) on runs written with the
real RunWriter: hand-made drives on a two-lane road, and the reference pipeline on a synthetic
cut-in with its road map."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from redrive.evaluation import EvalData, Metric, MetricResult
from redrive.evaluation.closedloop import (
    AtFaultCollisions,
    Comfort,
    DrivableAreaCompliance,
    DrivingDirectionCompliance,
    EgoProgress,
    SpeedLimitCompliance,
    TimeToCollision,
    TrafficLightCompliance,
)
from redrive.evaluation.closedloop._common import EGO_DEFAULTS
from redrive.evaluation.evaluator import evaluate_run
from redrive.results import (
    AlgorithmEntry,
    FrameRecord,
    PipelineInfo,
    RunSetup,
    RunWriter,
    SourceLog,
    open_run,
)
from redrive.types import Box3D, DetectedObject, MapLane, ObjectClass, RoadMap, Role, VehicleState

T0_NS = 1_700_000_000_000_000_000
DT_S = 0.1
SETUP = RunSetup(
    log=SourceLog(path="synthetic", sha256="x", format="synthetic"),
    seed=0,
    pipeline=PipelineInfo(first_frame=0),
    algorithms=(AlgorithmEntry(name="planner", version="1", config_hash="p", role=Role.PLANNING),),
)
#: a straight two-lane road along +x: "east" (y = 0, 50 km/h) and "west" (y = 3.5, the other way)
ROAD = RoadMap(
    lanes=(
        MapLane(
            lane_id="east",
            centerline=np.array([[-100.0, 0.0], [400.0, 0.0]]),
            width_m=3.5,
            speed_limit_mps=50 / 3.6,
        ),
        MapLane(
            lane_id="west",
            centerline=np.array([[400.0, 3.5], [-100.0, 3.5]]),
            width_m=3.5,
            speed_limit_mps=50 / 3.6,
        ),
    )
)
FRONT_M = 4.7 - 0.95  # rear axle → front bumper of the default ego


@dataclass(frozen=True)
class Pose:
    x: float
    y: float
    heading: float
    speed: float


@dataclass(frozen=True)
class Thing:
    """A ground-truth object in the map frame at time t: centre, velocity, class."""

    x: float
    y: float
    vx: float = 0.0
    vy: float = 0.0
    oid: int = 7
    cls: ObjectClass = ObjectClass.VEHICLE
    yaw: float = 0.0


def state(i: int, p: Pose) -> VehicleState:
    c, s = math.cos(p.heading), math.sin(p.heading)
    return VehicleState(
        stamp_ns=T0_NS + round(i * DT_S * 1e9),
        frame_id="map",
        position=np.array([p.x, p.y, 0.0]),
        velocity=np.array([p.speed * c, p.speed * s, 0.0]),
        heading_rad=p.heading,
    )


def in_base_link(t: Thing, p: Pose) -> DetectedObject:
    """``t`` seen from the ego pose ``p`` (what a log stores per frame)."""
    c, s = math.cos(p.heading), math.sin(p.heading)
    dx, dy = t.x - p.x, t.y - p.y
    return DetectedObject(
        object_id=t.oid,
        object_class=t.cls,
        box=Box3D(
            center=np.array([c * dx + s * dy, -s * dx + c * dy, 0.8]),
            size=np.array([4.5, 1.9, 1.5]),
            yaw_rad=t.yaw - p.heading,
        ),
        velocity=np.array([c * t.vx + s * t.vy, -s * t.vx + c * t.vy, 0.0]),
    )


def make_run(
    tmp_path: Path,
    ego: Callable[[float], Pose],
    *,
    n: int = 40,
    things: Callable[[float], Sequence[Thing]] = lambda t: (),
    logged: Callable[[float], Pose] | None = None,
    road: RoadMap | None = ROAD,
    name: str = "run",
) -> Path:
    out = tmp_path / name
    with RunWriter(out, setup=SETUP) as writer:
        for i in range(n):
            t = i * DT_S
            p = ego(t)
            writer.write_frame(
                FrameRecord(
                    frame_index=i,
                    stamp_ns=T0_NS + round(t * 1e9),
                    steps=(),
                    vehicle_state=state(i, p),
                    logged_vehicle_state=None if logged is None else state(i, logged(t)),
                    ground_truth=tuple(in_base_link(th, p) for th in things(t)),
                )
            )
        if road is not None:
            writer.write_map(road)
    return out


def score(metric: Metric, run: Path) -> MetricResult:
    return metric.evaluate(EvalData(open_run(run)))


def cruise(speed: float = 10.0, *, y: float = 0.0, x0: float = 0.0) -> Callable[[float], Pose]:
    return lambda t: Pose(x0 + speed * t, y, 0.0, speed)


# -- collisions ------------------------------------------------------------------------------


def _collision(tmp_path: Path, ego: Callable[[float], Pose], thing: Callable[[float], Thing]):
    run = make_run(tmp_path, ego, n=30, things=lambda t: (thing(t),))
    return score(AtFaultCollisions(), run), run


def test_head_on_is_active_front_at_fault(tmp_path: Path) -> None:
    # a car coming the other way in the ego's lane; they meet within 3 s
    res, _ = _collision(
        tmp_path, cruise(10.0), lambda t: Thing(40.0 - 10.0 * t, 0.0, vx=-10.0, yaw=math.pi)
    )
    assert res.values["active_front"] == 1
    assert res.values["at_fault_collisions"] == 1
    assert res.values["no_at_fault_collisions"] == 0.0
    (mark,) = res.bookmarks
    assert mark.kind == "collision"
    assert "active_front" in mark.detail
    assert "at fault" in mark.detail
    assert res.per_frame["at_fault_collision"][1].sum() == 1  # the track counts once


def test_ego_rear_ended_while_stopped_is_not_at_fault(tmp_path: Path) -> None:
    stopped = lambda t: Pose(50.0, 0.0, 0.0, 0.0)  # noqa: E731
    res, _ = _collision(tmp_path, stopped, lambda t: Thing(30.0 + 8.0 * t, 0.0, vx=8.0))
    assert res.values["stopped_ego"] == 1
    assert res.values["at_fault_collisions"] == 0
    assert res.values["no_at_fault_collisions"] == 1.0


def test_ego_rear_ended_while_moving_is_active_rear_not_at_fault(tmp_path: Path) -> None:
    res, _ = _collision(
        tmp_path, cruise(5.0, x0=50.0), lambda t: Thing(30.0 + 12.0 * t, 0.0, vx=12.0)
    )
    assert res.values["active_rear"] == 1
    assert res.values["no_at_fault_collisions"] == 1.0


def test_stopped_track_is_at_fault_and_an_object_scores_half(tmp_path: Path) -> None:
    cone = lambda t: Thing(30.0, 0.0, cls=ObjectClass.STATIC)  # noqa: E731
    res, _ = _collision(tmp_path, cruise(10.0), cone)
    assert res.values["stopped_track"] == 1
    assert res.values["no_at_fault_collisions"] == 0.5  # nuPlan: one object collision → 0.5


def _side_swipe(y_ego: float) -> tuple[Callable[[float], Pose], Callable[[float], Thing]]:
    # a car beside the ego, same speed, drifting into it from the left
    return cruise(10.0, y=y_ego), lambda t: Thing(
        1.4 + 10.0 * t, y_ego + 3.0 - 1.0 * t, vx=10.0, vy=-1.0
    )


def test_lateral_collision_in_own_lane_is_not_at_fault(tmp_path: Path) -> None:
    res, _ = _collision(tmp_path, *_side_swipe(0.0))
    assert res.values["active_lateral"] == 1
    assert res.values["no_at_fault_collisions"] == 1.0


def test_lateral_collision_straddling_lanes_is_at_fault(tmp_path: Path) -> None:
    res, _ = _collision(tmp_path, *_side_swipe(1.75))  # on the lane line: in two lanes
    assert res.values["active_lateral"] == 1
    assert res.values["no_at_fault_collisions"] == 0.0


def test_ttc_below_threshold_is_flagged(tmp_path: Path) -> None:
    # a stopped car 5 m ahead of the bumper at 10 m/s: TTC 0.5 s on the first frame
    run = make_run(
        tmp_path, cruise(10.0), n=3, things=lambda t: (Thing(FRONT_M + 2.25 + 5.0, 0.0),)
    )
    res = score(TimeToCollision(), run)
    assert res.values["ttc_within_bound"] == 0.0
    assert res.values["min_ttc_s"] == pytest.approx(0.3, abs=1e-9)  # frame 2: 3 m left
    _frames, ttc = res.per_frame["ttc_s"]
    assert ttc[0] == pytest.approx(0.5, abs=1e-9)
    assert {b.kind for b in res.bookmarks} == {"low_ttc"}
    far = make_run(tmp_path, cruise(10.0), n=3, things=lambda t: (Thing(80.0, 0.0),), name="far")
    res = score(TimeToCollision(), far)
    assert res.values["ttc_within_bound"] == 1.0
    assert math.isinf(res.values["min_ttc_s"])


# -- the road --------------------------------------------------------------------------------


def test_leaving_the_lane_polygon_fails_drivable_area(tmp_path: Path) -> None:
    veer = lambda t: Pose(10.0 * t, -1.0 * t, -0.1, 10.0)  # noqa: E731  off the right edge
    res = score(DrivableAreaCompliance(), make_run(tmp_path, veer))
    assert res.values["drivable_area_compliance"] == 0.0
    assert res.values["off_road_frames"] > 0
    assert res.bookmarks[0].kind == "off_road"
    ok = score(DrivableAreaCompliance(), make_run(tmp_path, cruise(), name="ok"))
    assert ok.values["drivable_area_compliance"] == 1.0
    assert ok.values["max_outside_m"] == 0.0


def test_driving_against_the_lane_direction(tmp_path: Path) -> None:
    wrong = lambda t: Pose(200.0 - 10.0 * t, 0.0, math.pi, 10.0)  # noqa: E731  west in "east"
    res = score(DrivingDirectionCompliance(), make_run(tmp_path, wrong))
    assert res.values["driving_direction_compliance"] == 0.0
    # nuPlan sums n + 1 = 11 steps of the 1 s horizon at 10 Hz: 11 steps of 1 m against the lane
    assert res.values["max_wrong_way_m"] == pytest.approx(11.0, abs=0.05)
    assert res.values["min_progress_in_horizon_m"] == pytest.approx(-11.0, abs=0.05)
    slow = lambda t: Pose(200.0 - 3.0 * t, 0.0, math.pi, 3.0)  # noqa: E731  3 m in 1 s
    res = score(DrivingDirectionCompliance(), make_run(tmp_path, slow, name="slow"))
    assert res.values["driving_direction_compliance"] == 0.5
    west = lambda t: Pose(200.0 - 10.0 * t, 3.5, math.pi, 10.0)  # noqa: E731  its own lane
    res = score(DrivingDirectionCompliance(), make_run(tmp_path, west, name="west"))
    assert res.values["driving_direction_compliance"] == 1.0


def test_speed_limit(tmp_path: Path) -> None:
    res = score(SpeedLimitCompliance(), make_run(tmp_path, cruise(50 / 3.6 + 2.23 / 2)))
    assert res.values["speed_limit_compliance"] == pytest.approx(1.0 - 0.5 * 40 / 39, rel=1e-6)
    assert res.values["speeding_frames"] == 40
    assert res.values["max_overspeed_mps"] == pytest.approx(2.23 / 2)
    assert [b.kind for b in res.bookmarks] == ["speeding"]
    legal = score(SpeedLimitCompliance(), make_run(tmp_path, cruise(13.0), name="legal"))
    assert legal.values["speed_limit_compliance"] == 1.0


def test_map_metrics_skip_without_a_map(tmp_path: Path) -> None:
    run = make_run(tmp_path, cruise(), road=None)
    summary = evaluate_run(
        run,
        metrics=[
            DrivableAreaCompliance(),
            DrivingDirectionCompliance(),
            SpeedLimitCompliance(),
        ],
    )
    reasons = {o.metric: o.reason for o in summary.skipped}
    assert set(reasons) == {"drivable_area", "driving_direction", "speed_limit"}
    assert set(reasons.values()) == {
        "no road map in the run (runs of a synthetic scenario or its log store one; recorded logs have none)"
    }
    assert not summary.failed


# -- progress, comfort, the aggregate ----------------------------------------------------------


def test_progress_of_a_never_moving_ego_is_about_zero(tmp_path: Path) -> None:
    parked = lambda t: Pose(0.0, 0.0, 0.0, 0.0)  # noqa: E731
    run = make_run(tmp_path, parked, logged=cruise(10.0))  # the expert drove 39 m
    res = score(EgoProgress(), run)
    assert res.values["expert_progress_m"] == pytest.approx(39.0)
    assert res.values["ego_progress_m"] == pytest.approx(0.0, abs=1e-9)
    assert res.values["ego_progress_ratio"] == pytest.approx(2.0 / 39.0)  # nuPlan's 2 m floor
    assert res.values["making_progress"] == 0.0


def test_progress_of_the_expert_itself_is_one(tmp_path: Path) -> None:
    run = make_run(tmp_path, cruise(10.0))  # open loop: the ego is the logged ego
    assert score(EgoProgress(), run).values["ego_progress_ratio"] == 1.0
    half = make_run(tmp_path, cruise(5.0), logged=cruise(10.0), name="half")
    assert score(EgoProgress(), half).values["ego_progress_ratio"] == pytest.approx(0.5)


def test_harsh_brake_breaks_comfort(tmp_path: Path) -> None:
    def brake(t: float) -> Pose:  # 15 m/s, then −8 m/s² from t = 1 s until stopped
        if t < 1.0:
            return Pose(15.0 * t, 0.0, 0.0, 15.0)
        tb = min(t - 1.0, 15.0 / 8.0)
        return Pose(15.0 + 15.0 * tb - 4.0 * tb * tb, 0.0, 0.0, 15.0 - 8.0 * tb)

    res = score(Comfort(), make_run(tmp_path, brake))
    assert res.values["comfortable"] == 0.0
    assert res.values["min_lon_accel_mps2"] < -4.05
    assert any("lon_accel" in b.detail for b in res.bookmarks)
    smooth = score(Comfort(), make_run(tmp_path, cruise(), name="smooth"))
    assert smooth.values["comfortable"] == 1.0
    assert smooth.values["max_abs_jerk_mps3"] == pytest.approx(0.0, abs=1e-6)


def test_entry_points_match_names() -> None:
    import importlib

    data = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    group = data["project"]["entry-points"]["redrive.metrics"]
    wanted = {
        "at_fault_collisions": AtFaultCollisions,
        "time_to_collision": TimeToCollision,
        "drivable_area": DrivableAreaCompliance,
        "driving_direction": DrivingDirectionCompliance,
        "speed_limit": SpeedLimitCompliance,
        "ego_progress": EgoProgress,
        "comfort": Comfort,
        "traffic_light_compliance": TrafficLightCompliance,
    }
    for name, cls in wanted.items():
        module, _, attr = group[name].partition(":")
        assert getattr(importlib.import_module(module), attr) is cls
        assert cls.name == name
        assert cls.role is None


def test_footprint_defaults_are_the_simulated_egos() -> None:
    from redrive.sim.ego import EgoGeometry

    geometry = EgoGeometry()
    assert dict(EGO_DEFAULTS) == {
        "ego_length_m": geometry.length_m,
        "ego_width_m": geometry.width_m,
        "rear_overhang_m": geometry.rear_overhang_m,
    }


def test_reference_pipeline_on_a_synthetic_cut_in(cut_in_log: Path, tmp_path: Path) -> None:
    """A real run: the scripted expert ego of ``cut_in`` (open loop: the driven ego is the
    logged one), the reference pipeline, the scenario's road map written into the run."""
    from redrive.config import reference_pipeline
    from redrive.engine import RunRequest, run_log
    from redrive.results import write_road_map
    from redrive.sim.roadmap import HIGHWAY_SPEED_LIMIT_MPS, scenario_road_map
    from redrive.sim.scenario import load_scenario

    scenario = load_scenario("cut_in")  # 2 s of it synthesized: cut_in_log
    out = tmp_path / "run"
    report = run_log(RunRequest(log=cut_in_log, pipeline=reference_pipeline(), out=out))
    assert report.status == "complete"
    write_road_map(out, scenario_road_map(scenario))
    road_map = open_run(out).road_map()
    assert road_map is not None
    assert {lane.speed_limit_mps for lane in road_map.lanes} == {HIGHWAY_SPEED_LIMIT_MPS}
    metrics: list[Metric] = [
        AtFaultCollisions(),
        TimeToCollision(),
        DrivableAreaCompliance(),
        DrivingDirectionCompliance(),
        SpeedLimitCompliance(),
        EgoProgress(),
        Comfort(),
    ]
    summary = evaluate_run(out, metrics=metrics)
    assert not summary.failed
    assert not summary.skipped
    got = {s.metric.name: s.result.values for s in summary.scored}
    assert got["at_fault_collisions"]["collisions"] == 0
    assert got["at_fault_collisions"]["no_at_fault_collisions"] == 1.0
    assert got["drivable_area"]["drivable_area_compliance"] == 1.0
    assert got["driving_direction"]["driving_direction_compliance"] == 1.0
    assert got["speed_limit"]["speed_limit_compliance"] == 1.0  # 25 m/s under 120 km/h
    assert got["ego_progress"]["ego_progress_ratio"] == 1.0
    assert got["ego_progress"]["expert_progress_m"] == pytest.approx(25 * 1.9, rel=0.1)
    assert got["time_to_collision"]["min_ttc_s"] > 0.95
    assert got["comfort"]["max_abs_yaw_rate_rad_s"] < 0.1  # a straight road
