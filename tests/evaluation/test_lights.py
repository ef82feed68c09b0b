"""traffic_light_compliance (NAVSIM v2's TLC): the per-step test on a hand-made junction, and
closed-loop runs of ``red_light``: a planner that runs the red light scores 0, the reference
pipeline stops at the line while it is red, crosses after green and scores 1."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.config import pipeline_from_plugins
from redrive.evaluation import EvalData
from redrive.evaluation._kinematics import ego_footprint_corners
from redrive.evaluation.closedloop.lights import (
    TrafficLightCompliance,
    controlled_lane_ids,
    red_light_hits,
    red_light_violations,
    route_lane_ids,
)
from redrive.evaluation.evaluator import evaluate_run
from redrive.results import RunStatus, open_run
from redrive.types import (
    Intersection,
    LightState,
    MapLane,
    MapTrafficLight,
    Roadblock,
    RoadMap,
    StopLine,
    TrafficLight,
)

PLUGINS = "tests.closedloop.plugins"
R, Y, G, U = LightState.RED, LightState.YELLOW, LightState.GREEN, LightState.UNKNOWN


def _lane(lane_id: str, xy: list[list[float]], **kw: object) -> MapLane:
    return MapLane(lane_id=lane_id, centerline=np.array(xy), width_m=3.5, **kw)  # type: ignore[arg-type]


#: an approach "in" (x −50 … 0) with its stop line at x = −1, the junction's connectors "straight"
#: (x 0 … 10) and "cross" (south → north across it at x = 5), the exit "out"; light "L" stops
#: "in" (Lanelet2's way: the connectors are its successors), light "C" names "cross" directly
#: (nuPlan's way)
JUNCTION = RoadMap(
    lanes=(
        _lane("in", [[-50.0, 0.0], [0.0, 0.0]], successors=("straight",), roadblock_id="in"),
        _lane(
            "straight",
            [[0.0, 0.0], [10.0, 0.0]],
            predecessors=("in",),
            successors=("out",),
            roadblock_id="in_out",
            intersection_id="j",
        ),
        _lane("out", [[10.0, 0.0], [60.0, 0.0]], predecessors=("straight",), roadblock_id="out"),
        _lane("cross", [[5.0, -10.0], [5.0, 10.0]], roadblock_id="cross", intersection_id="j"),
    ),
    roadblocks=(
        Roadblock(roadblock_id="in", lane_ids=("in",)),
        Roadblock(roadblock_id="in_out", lane_ids=("straight",)),
        Roadblock(roadblock_id="out", lane_ids=("out",)),
        Roadblock(roadblock_id="cross", lane_ids=("cross",)),
    ),
    intersections=(
        Intersection(
            intersection_id="j",
            polygon=np.array([[0.0, -10.0], [10.0, -10.0], [10.0, 10.0], [0.0, 10.0]]),
            lane_ids=("straight", "cross"),
        ),
    ),
    stop_lines=(
        StopLine(stop_line_id="s", line=np.array([[-1.0, 1.75], [-1.0, -1.75]]), lane_ids=("in",)),
    ),
    traffic_lights=(
        MapTrafficLight(
            light_id="L", position=np.array([-1.0, -3.0]), lane_ids=("in",), stop_line_id="s"
        ),
        MapTrafficLight(light_id="C", position=np.array([7.0, -9.0]), lane_ids=("cross",)),
    ),
)
GEOMETRY = {"length_m": 4.7, "width_m": 1.9, "rear_overhang_m": 0.95}


def _corners(rear_x: list[float]) -> np.ndarray:
    xy = np.column_stack([rear_x, np.zeros(len(rear_x))])
    return ego_footprint_corners(xy, np.zeros(len(rear_x)), **GEOMETRY)


def _states(light: LightState, n: int, cross: LightState = R) -> list[tuple[TrafficLight, ...]]:
    return [(TrafficLight(id="L", state=light), TrafficLight(id="C", state=cross))] * n


def test_the_lanes_a_light_controls() -> None:
    lights = {t.light_id: t for t in JUNCTION.traffic_lights}
    assert controlled_lane_ids(JUNCTION, lights["L"]) == ("straight",)  # behind its stop line
    assert controlled_lane_ids(JUNCTION, lights["C"]) == ("cross",)  # a connector itself


def test_the_route_is_the_roadblocks_driven_in() -> None:
    xy = np.array([[-20.0, 0.0], [5.0, 0.0], [30.0, 0.0]])
    assert route_lane_ids(JUNCTION, xy, yaw_rad=np.zeros(3)) == {"in", "straight", "out"}
    assert route_lane_ids(JUNCTION, np.zeros((0, 2)), yaw_rad=np.zeros(0)) == frozenset()


def test_a_footprint_in_a_red_connector_violates_and_nothing_else_does() -> None:
    route = {"in", "straight", "out"}
    # front bumper = rear + 3.75: at −5 it is 1.25 m short of the connector, at −3.75 it
    # touches it (touching counts), at −3.7 it is in; at 20 the ego is past the junction
    rear = [-20.0, -5.0, -3.75, -3.7, 2.0, 20.0]
    red = red_light_violations(JUNCTION, _corners(rear), states=_states(R, 6), route_lane_ids=route)
    assert red.tolist() == [False, False, True, True, True, False]
    for light in (Y, G, U):  # only red counts
        other = red_light_violations(
            JUNCTION, _corners(rear), states=_states(light, 6), route_lane_ids=route
        )
        assert not other.any()
    # the crossing connector is red throughout and the ego overlaps it at rear 2.0: it is off
    # the route, so it never counts; on the route it would
    hits = red_light_hits(
        JUNCTION, _corners(rear), states=_states(G, 6), route_lane_ids=route | {"cross"}
    )
    assert hits == [(), (), (), (), ("C",), ()]
    # a light absent from a step is not red there; off-route red connectors never count
    assert not red_light_violations(
        JUNCTION, _corners(rear), states=[()] * 6, route_lane_ids=route
    ).any()
    assert not red_light_violations(
        JUNCTION, _corners(rear), states=_states(R, 6), route_lane_ids={"in"}
    ).any()


def test_bad_arguments_say_what_is_wrong() -> None:
    with pytest.raises(ValueError, match=r"\(N, 4, 2\)"):
        red_light_violations(JUNCTION, np.zeros((3, 2)), states=[()] * 3, route_lane_ids=())
    with pytest.raises(ValueError, match="2 footprints but 3 steps"):
        red_light_violations(JUNCTION, _corners([0.0, 1.0]), states=[()] * 3, route_lane_ids=())


def _closed_loop(out: Path, *, planning: str, reference: bool, duration_s: float) -> EvalData:
    if reference:
        pipeline = pipeline_from_plugins(
            perception=["noisy-oracle"], planning=[planning], control=["pure-pursuit-pid"]
        )
    else:
        pipeline = pipeline_from_plugins(planning=[planning])
    request = ClosedLoopRequest(
        scenario="red_light", pipeline=pipeline, out=out, duration_s=duration_s
    )
    assert run_closed_loop(request).status is RunStatus.COMPLETE
    return EvalData(open_run(out))


def test_a_planner_that_runs_the_red_light_scores_zero(tmp_path: Path) -> None:
    # red_light: west/east yellow at 5 s, red from 8 s; the blind planner holds 12 m/s and is at
    # the junction (x = −8) near 9.7 s
    data = _closed_loop(
        tmp_path / "blind", planning=f"{PLUGINS}:Straight", reference=False, duration_s=12.0
    )
    result = TrafficLightCompliance().evaluate(data)
    assert result.values["traffic_light_compliance"] == 0.0
    assert result.values["red_light_frames"] >= 10
    assert result.values["lights_in_map"] == 4.0
    first = result.bookmarks[0]
    assert first.kind == "red_light"
    assert "light 0" in first.detail
    lights = data.traffic_lights()[first.frame_index]
    assert {t.id: t.state for t in lights}["0"] is R


def test_the_reference_pipeline_stops_at_red_and_crosses_after_green(tmp_path: Path) -> None:
    # red until 24 s; the stop line's near edge is at x = −9.5, the junction −8 … 8
    data = _closed_loop(tmp_path / "ref", planning="idm-planner", reference=True, duration_s=33.0)
    result = TrafficLightCompliance().evaluate(data)
    assert result.values["traffic_light_compliance"] == 1.0
    assert result.values["red_light_frames"] == 0.0
    ego, lights = data.ego(), data.traffic_lights()
    front = {f: s.position[0] + 3.75 for f, s in ego.items()}  # rear axle + 4.7 − 0.95
    west = {f: {t.id: t.state for t in lights[f]}["0"] for f in ego}
    red = [f for f in ego if west[f] is R]
    assert red
    assert max(front[f] for f in red) < -9.5  # short of the stop line while red
    stopped = [f for f in red if ego[f].speed_mps < 0.05]
    assert len(stopped) > 50  # it waited
    assert max(s.position[0] for s in ego.values()) > 8.0  # through the junction after green
    assert all(west[f] is G for f in ego if -9.5 <= front[f] <= 8.0)


def test_the_metric_runs_from_evaluate_and_a_map_without_lights_scores_one(tmp_path: Path) -> None:
    out = tmp_path / "hw"
    request = ClosedLoopRequest(
        scenario="highway",
        pipeline=pipeline_from_plugins(planning=[f"{PLUGINS}:Straight"]),
        out=out,
        duration_s=1.0,
    )
    assert run_closed_loop(request).status is RunStatus.COMPLETE
    summary = evaluate_run(out, metrics=[TrafficLightCompliance()])
    assert not summary.skipped
    result = TrafficLightCompliance().evaluate(EvalData(open_run(out)))
    assert result.values["traffic_light_compliance"] == 1.0
    assert result.values["lights_in_map"] == 0.0


def test_the_reference_pipeline_plans_to_stop_at_red_on_the_replayed_log(tmp_path: Path) -> None:
    """Open loop over a ``redrive synth`` log of red_light: the reference pipeline (LiDAR
    clusters → tracker → idm-planner → pure pursuit) gets the log's map and light states, and
    while the light is red every plan ends short of the stop line; the logged driver stops too,
    so the run scores TLC 1."""
    import dataclasses
    import math

    from redrive.cli.main import main
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize
    from tests.sim.test_synth import SMALL_RIG

    log = tmp_path / "red_light.mcap"
    synthesize(dataclasses.replace(load_scenario("red_light"), rig=SMALL_RIG), log, duration_s=12.0)
    out = tmp_path / "run"
    assert main(["run", str(log), "--out", str(out), "--no-progress"]) == 0
    run = open_run(out)
    assert run.road_map() is not None
    ego, lights, paths = run.ego(), run.traffic_lights(), run.paths("planner")
    red = [f for f in paths if {t.id: t.state for t in lights[f]}["0"] is R]
    assert len(red) > 30
    for f in red:
        state, wp = ego[f], paths[f].waypoints
        h = state.heading_rad
        end_x = state.position[0] + math.cos(h) * wp[-1, 0] - math.sin(h) * wp[-1, 1]
        assert end_x + 3.75 < -9.5, f  # the plan's front bumper stops short of the line
    result = TrafficLightCompliance().evaluate(EvalData(run))
    assert result.values["traffic_light_compliance"] == 1.0
