"""Reactive agents on a road map (redrive.closedloop.lane_agents): a logged vehicle the driven
ego holds up follows it under IDM along its lane, stops at a red light the log drove through,
goes on at green and hands back to its logged track once it has caught up with it."""

from __future__ import annotations

import numpy as np
import pytest

from redrive.closedloop.lane_agents import LaneAgents
from redrive.maps.index import DRIVABLE_LANE_KINDS, RoadMapIndex
from redrive.types import LightState, MapLane, MapTrafficLight, RoadMap, StopLine

DT_S = 0.1
STEP_NS = 100_000_000
LENGTH_M = 4.5
EGO_LENGTH_M = 4.7
#: the ego somewhere no lane agent meets it
AWAY = (1000.0, 500.0, 0.0, 0.0, EGO_LENGTH_M)


def _road(*, stop_line: bool = True) -> RoadMap:
    x = np.linspace(0.0, 300.0, 61)
    lane = MapLane(lane_id="a", centerline=np.column_stack([x, np.zeros_like(x)]), width_m=3.5)
    stop = StopLine(
        stop_line_id="sl", line=np.array([[100.0, -1.75], [100.0, 1.75]]), lane_ids=("a",)
    )
    if not stop_line:  # the light holds lane "a" at its end: a second lane at x = 100
        x1, x2 = np.linspace(0.0, 100.0, 21), np.linspace(100.0, 300.0, 41)
        a = MapLane(
            lane_id="a",
            centerline=np.column_stack([x1, np.zeros_like(x1)]),
            width_m=3.5,
            successors=("b",),
        )
        b = MapLane(
            lane_id="b",
            centerline=np.column_stack([x2, np.zeros_like(x2)]),
            width_m=3.5,
            predecessors=("a",),
        )
        light = MapTrafficLight(light_id="L", position=np.array([101.0, 3.0]), lane_ids=("a",))
        return RoadMap(lanes=(a, b), traffic_lights=(light,))
    light = MapTrafficLight(
        light_id="L", position=np.array([101.0, 3.0]), lane_ids=("a",), stop_line_id="sl"
    )
    return RoadMap(lanes=(lane,), stop_lines=(stop,), traffic_lights=(light,))


def _logged_x(t_s: float) -> float:
    """The log: 10 m/s from x = 20 m, stopping at x = 150 m (t = 13 s), standing to t = 40 s."""
    return 20.0 + 10.0 * min(t_s, 13.0)


def _agents(*, stop_line: bool = True) -> LaneAgents:
    stamps = [k * STEP_NS for k in range(401)]
    xy = [(_logged_x(k * DT_S), 0.0) for k in range(401)]
    tracks = {7: (stamps, xy, [0.0] * 401, (LENGTH_M, 1.9))}
    road = _road(stop_line=stop_line)
    return LaneAgents(tracks, index=RoadMapIndex(road, lane_kinds=DRIVABLE_LANE_KINDS))


def _drive(
    agents: LaneAgents, *, ego_at: object, light_at: object, seconds: float
) -> list[tuple[float, float | None, float]]:
    """Step the agents; per step (t, agent x or None when replayed, logged x)."""
    out = []
    for k in range(round(seconds / DT_S)):
        t = k * DT_S
        agents.step(k * STEP_NS, dt_s=DT_S, ego=ego_at(t), lights={"L": light_at(t)})  # type: ignore[operator]
        pose = agents.pose(7, (k + 1) * STEP_NS)
        out.append((t + DT_S, None if pose is None else pose[0], _logged_x(t + DT_S)))
    return out


def test_a_vehicle_never_held_up_is_replayed_exactly() -> None:
    agents = _agents()
    trace = _drive(agents, ego_at=lambda t: AWAY, light_at=lambda t: LightState.RED, seconds=20.0)
    assert all(x is None for _, x, _ in trace)  # the log (through its own lights) throughout


def test_held_up_it_queues_behind_the_ego_then_hands_back_to_its_log() -> None:
    agents = _agents()

    # the ego stands at x = 60 (its centre) for 12 s, then is gone
    def ego(t: float) -> tuple[float, float, float, float, float]:
        return (60.0, 0.0, 0.0, 0.0, EGO_LENGTH_M) if t < 12.0 else AWAY

    trace = _drive(agents, ego_at=ego, light_at=lambda t: LightState.GREEN, seconds=30.0)
    held = [(t, x) for t, x, _ in trace if t <= 12.0]
    assert held[0][1] is not None  # the ego 35 m ahead, standing: inside IDM's desired gap
    gaps = [60.0 - EGO_LENGTH_M / 2 - (x + LENGTH_M / 2) for _, x in held if x is not None]
    assert min(gaps) > 1.0  # it stops behind the ego, never into it
    assert gaps[-1] == pytest.approx(2.0, abs=0.1)  # IDM's standstill gap s0 = 2 m
    # then it drives on along its lane, behind its log, and takes its logged track again once
    # it has caught up with it (the log stands at x = 150 from t = 13 s)
    after = [(t, x, logged) for t, x, logged in trace if t > 12.0]
    assert all(x is None or x <= logged + 1e-6 for _, x, logged in after)
    assert after[-1][1] is None


@pytest.mark.parametrize("stop_line", [True, False], ids=["stop line", "lane end"])
def test_it_stops_at_a_red_light_the_log_drove_through_and_goes_at_green(stop_line: bool) -> None:
    agents = _agents(stop_line=stop_line)

    def ego(t: float) -> tuple[float, float, float, float, float]:
        return (45.0, 0.0, 0.0, 0.0, EGO_LENGTH_M) if t < 3.0 else AWAY

    def light(t: float) -> LightState:
        return LightState.RED if t < 20.0 else LightState.GREEN

    trace = _drive(agents, ego_at=ego, light_at=light, seconds=40.0)
    red = [x for t, x, _ in trace if 15.0 < t < 20.0]
    assert all(x is not None for x in red)  # on its lane, not on the log (which is at 150 m)
    fronts = [x + LENGTH_M / 2 for x in red if x is not None]
    assert max(fronts) <= 100.0  # never past the stop line while red
    assert fronts[-1] == pytest.approx(98.0, abs=0.6)  # stopped s0 before it
    # green: it goes through and, the log standing at 150 m, catches up and hands back
    assert trace[-1][1] is None
