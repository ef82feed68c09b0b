"""IdmPlanner and traffic lights: the stop line of a red light is a stopped obstacle, a yellow one
is stopped for only while the ego can still stop comfortably, green and other lanes' lights are
driven through; the road map comes through the engine's LogInputs."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from redrive.algorithms import ROAD_MAP, Algorithm, StageOutputs
from redrive.algorithms.reference._lights import gates_of
from redrive.algorithms.reference.planner import IdmPlanner
from redrive.config import pipeline_from_plugins
from redrive.engine.graph import LogInputs, build_graph
from redrive.errors import ConfigError
from redrive.types import (
    Frame,
    LightState,
    MapLane,
    MapTrafficLight,
    PlannedPath,
    RoadMap,
    StopLine,
    TrafficData,
    TrafficLight,
)
from tests.algorithms.test_planner import FRONT_M, make_frame

R, Y, G = LightState.RED, LightState.YELLOW, LightState.GREEN
EMPTY = StageOutputs({}, {})
#: an eastbound approach ending at x = 0 with its stop line at x = −1, a connector behind it; the
#: westbound lane beside it (y = 3.5) has a light of its own, "W", with no stop line
MAP = RoadMap(
    lanes=(
        MapLane(lane_id="in", centerline=np.array([[-200.0, 0.0], [0.0, 0.0]]), width_m=3.5),
        MapLane(lane_id="through", centerline=np.array([[0.0, 0.0], [20.0, 0.0]]), width_m=3.5),
        MapLane(lane_id="west", centerline=np.array([[200.0, 3.5], [20.0, 3.5]]), width_m=3.5),
    ),
    stop_lines=(
        StopLine(stop_line_id="s", line=np.array([[-1.0, 1.75], [-1.0, -1.75]]), lane_ids=("in",)),
    ),
    traffic_lights=(
        MapTrafficLight(
            light_id="E", position=np.array([-1.0, -3.0]), lane_ids=("in",), stop_line_id="s"
        ),
        MapTrafficLight(light_id="W", position=np.array([21.0, 6.0]), lane_ids=("west",)),
    ),
)


def planner(**config: object) -> IdmPlanner:
    p = IdmPlanner(name="planner")
    p.configure(config)
    p.use_road_map(MAP)
    return p


def lit(frame: Frame, east: LightState, west: LightState = R) -> Frame:
    lights = (TrafficLight(id="E", state=east), TrafficLight(id="W", state=west))
    return dataclasses.replace(frame, traffic=TrafficData(traffic_lights=lights))


def end_x(path: PlannedPath) -> float:
    return float(path.waypoints[-1, 0])


def test_gates_come_from_stop_lines_or_the_lanes_ends() -> None:
    gates = {g.light_id: g for g in gates_of(MAP)}
    np.testing.assert_allclose(gates["E"].line, [[-1.0, 1.75], [-1.0, -1.75]])
    np.testing.assert_allclose(gates["E"].direction, [1.0, 0.0])
    # W has no stop line: the end of its lane, across it, travelling west
    np.testing.assert_allclose(gates["W"].line, [[20.0, 1.75], [20.0, 5.25]])
    np.testing.assert_allclose(gates["W"].direction, [-1.0, 0.0])
    assert gates_of(None) == ()


def test_red_stops_before_the_line_green_drives_on() -> None:
    ego = make_frame(10.0, x_m=-60.0)  # 55 m of road to the line, bumper to line
    red = planner().step(lit(ego, R), EMPTY)
    # the IDM stops s0 = 2 m short of the line (and never beyond it)
    assert -60.0 + end_x(red) + FRONT_M <= -1.0 - 2.0 + 1e-6
    steps = np.diff(red.waypoints[:, 0])
    assert steps[-1] < 0.5 * steps[0]  # braking for it
    green = planner().step(lit(ego, G), EMPTY)
    assert end_x(green) > 55.0
    # the westbound light is red throughout: its lane is beside the path, never crossed
    assert end_x(planner().step(lit(ego, G, R), EMPTY)) == end_x(green)
    # without states, or told to ignore lights, the planner drives on too
    assert end_x(planner().step(ego, EMPTY)) == end_x(green)
    assert end_x(planner(traffic_lights=False).step(lit(ego, R), EMPTY)) == end_x(green)


def test_yellow_stops_only_when_it_still_can_and_then_commits() -> None:
    far = make_frame(10.0, x_m=-80.0)  # 75 m ahead, 25 m needed at b = 2 m/s²
    assert -80.0 + end_x(planner().step(lit(far, Y), EMPTY)) + FRONT_M < -1.0
    near = make_frame(10.0, x_m=-20.0)  # 15 m ahead: too close to stop comfortably
    p = planner()
    assert end_x(p.step(lit(near, Y), EMPTY)) > 30.0
    # committed: it drives on through the red that follows, until the light is green again
    assert end_x(p.step(lit(near, R), EMPTY)) > 30.0
    p.step(lit(near, G), EMPTY)
    assert -20.0 + end_x(p.step(lit(near, R), EMPTY)) + FRONT_M < -1.0
    p.reset()
    assert -20.0 + end_x(p.step(lit(near, R), EMPTY)) + FRONT_M < -1.0


def test_a_line_behind_the_bumper_holds_nothing() -> None:
    past = make_frame(5.0, x_m=-4.0)  # bumper at −0.25: through the line (> 0.5 m past)
    assert end_x(planner().step(lit(past, R), EMPTY)) > 20.0


def test_a_wrong_traffic_lights_value_is_refused() -> None:
    with pytest.raises(ConfigError, match="traffic_lights"):
        planner(traffic_lights="yes")


class NeedsMap(Algorithm):
    role = IdmPlanner.role
    inputs = (ROAD_MAP,)

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:  # pragma: no cover
        raise NotImplementedError


def test_the_engine_hands_the_map_over_and_a_map_input_is_checked() -> None:
    pipeline = pipeline_from_plugins(planning=["idm-planner"])
    graph = build_graph(pipeline, LogInputs(has_vehicle_state=True, road_map=MAP))
    algo = graph.algorithms[0].instance
    assert algo.road_map is MAP
    assert isinstance(algo, IdmPlanner)
    assert {g.light_id for g in algo._gates} == {"E", "W"}
    assert (
        build_graph(pipeline, LogInputs(has_vehicle_state=True)).algorithms[0].instance.road_map
        is None
    )
    needs = pipeline_from_plugins(planning=[f"{__name__}:NeedsMap"])
    with pytest.raises(ConfigError, match="road map"):
        build_graph(needs, LogInputs())
    assert build_graph(needs, LogInputs(road_map=MAP)).algorithms[0].instance.road_map is MAP
