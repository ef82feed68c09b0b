"""CommonRoad scenarios of ../shared/data as logs through commonroad-io: obstacles per time step,
the planning problem's start and goal, traffic lights, the lanelet network; bad files give
errors naming the line, the byte or the lanelet."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import LogError
from redrive.io import open_log
from redrive.io.content import log_contents, log_road_map
from redrive.io.datasets.commonroad import CommonRoadReader
from redrive.io.datasets.commonroad_map import boundary_type
from redrive.maps.index import RoadMapIndex
from redrive.types import LightState, ObjectClass

pytest.importorskip("commonroad.common.reader.file_reader_xml")
pytestmark = pytest.mark.shared_data

US101 = "USA_US101-3_3_T-1.xml"
PEACH = "USA_Peach-4_8_T-1.xml"
A9 = "DEU_A9-3_1_T-1.xml"


@pytest.fixture(scope="module")
def scenarios(shared_data: Path) -> Path:
    path = shared_data / "commonroad"
    if not (path / US101).is_file():
        pytest.skip("the CommonRoad scenarios are not in ../shared/data")
    return path


@pytest.mark.parametrize(
    ("name", "obstacles", "lanelets", "steps"),
    [(US101, 12, 12, 32), (PEACH, 9, 79, 61), (A9, 9, 32, 31)],
)
def test_each_scenario_lists_its_obstacles_and_lanelets(
    scenarios: Path, name: str, obstacles: int, lanelets: int, steps: int
) -> None:
    with open_log(scenarios / name) as log:
        assert log.format == "commonroad"
        contents = log_contents(log)
        assert contents["dynamic obstacles"] == obstacles
        assert contents["lanelets"] == lanelets
        assert contents["time steps"] == steps
        assert log.topics["/objects"].count == steps
        road = log_road_map(log)
    assert road is not None
    assert len(road.lanes) == lanelets


def test_obstacles_are_their_trajectory_states_around_the_ego_start(scenarios: Path) -> None:
    with CommonRoadReader(scenarios / US101) as log:
        (start,) = [m.payload.value for m in log.messages(topics=["/ego_pose"])]  # type: ignore[attr-defined]
        problem = next(iter(log.planning_problems.planning_problem_dict.values()))
        np.testing.assert_allclose(start.position[:2], problem.initial_state.position)
        assert start.heading_rad == pytest.approx(problem.initial_state.orientation)
        assert log.goal is not None
        assert log.goal.lanelet_ids == (31,)
        assert log.goal.time_steps == (30, 31)
        step = 5
        objects = log.objects_at(step)
        obstacle = log.scenario.dynamic_obstacles[0]
        state = obstacle.state_at_time(step)
    (o,) = [o for o in objects if o.object_id == obstacle.obstacle_id]
    assert o.object_class is ObjectClass.VEHICLE
    c, s = math.cos(start.heading_rad), math.sin(start.heading_rad)
    x, y = o.box.center[:2]
    np.testing.assert_allclose(
        start.position[:2] + np.array([c * x - s * y, s * x + c * y]), state.position
    )
    assert o.box.yaw_rad == pytest.approx(
        math.remainder(state.orientation - start.heading_rad, math.tau)
    )
    assert o.box.size[0] == pytest.approx(obstacle.obstacle_shape.length)
    assert np.hypot(*o.velocity[:2]) == pytest.approx(state.velocity)


def test_uncertain_states_are_read_at_their_midpoints(scenarios: Path) -> None:
    with CommonRoadReader(scenarios / A9) as log:
        obstacle = log.scenario.dynamic_obstacles[0]
        objects = log.objects_at(0)
    (o,) = [o for o in objects if o.object_id == obstacle.obstacle_id]
    speed = obstacle.initial_state.velocity
    assert np.hypot(*o.velocity[:2]) == pytest.approx(0.5 * (speed.start + speed.end))


_LIGHTS = {
    "red": LightState.RED,
    "redYellow": LightState.RED,
    "yellow": LightState.YELLOW,
    "green": LightState.GREEN,
    "inactive": LightState.UNKNOWN,
}


def test_traffic_lights_follow_their_cycles_and_the_map_knows_them(scenarios: Path) -> None:
    with CommonRoadReader(scenarios / PEACH) as log:
        lights = [m.payload.value for m in log.messages(topics=["/traffic_lights"])]  # type: ignore[attr-defined]
        network = log.scenario.lanelet_network
        road = log_road_map(log)
    assert len(lights) == 61
    for k in (0, 30, 60):
        expected = {
            str(tl.traffic_light_id): tl.get_state_at_time_step(k).value
            for tl in network.traffic_lights
        }
        got = {t.id: t.state for t in lights[k].traffic_lights}
        assert got.keys() == expected.keys()
        for light_id, value in expected.items():
            assert got[light_id] is _LIGHTS[value]
    assert road is not None
    assert {t.light_id for t in road.traffic_lights} == {t.id for t in lights[0].traffic_lights}
    assert all(t.lane_ids for t in road.traffic_lights)
    assert len(road.intersections) == 1
    assert len(road.stop_lines) > 0
    assert {lane.speed_limit_mps for lane in road.lanes} >= {11.176, 15.6464}  # MAX_SPEED signs


def test_the_obstacles_drive_on_the_lanelets(scenarios: Path) -> None:
    with CommonRoadReader(scenarios / US101) as log:
        road = log_road_map(log)
        positions = np.array(
            [
                s.position
                for o in log.scenario.dynamic_obstacles
                for s in o.prediction.trajectory.state_list
            ]
        )
    assert road is not None
    assert RoadMapIndex(road).on_drivable_area(positions).mean() > 0.95


@pytest.mark.parametrize(
    ("marking", "from_right", "from_left"),
    [("solid", "solid", "solid"), ("broad_dashed", "dashed", "dashed"), ("solid_dashed", "dashed", "solid"),
     ("curb", "road_edge", "road_edge"), ("no_marking", "virtual", "virtual"), ("unknown", "unknown", "unknown")],
)  # fmt: skip
def test_markings(marking: str, from_right: str, from_left: str) -> None:
    assert boundary_type(marking, lane_side="right") == from_right
    assert boundary_type(marking, lane_side="left") == from_left


def test_a_cut_file_names_its_line_and_byte(scenarios: Path, tmp_path: Path) -> None:
    cut = tmp_path / US101
    cut.write_bytes((scenarios / US101).read_bytes()[:100_000])
    with pytest.raises(
        LogError, match=r"not well-formed CommonRoad XML at line \d+, column \d+ \(byte \d+\)"
    ):
        open_log(cut)


def test_a_lanelet_without_a_bound_is_named(scenarios: Path, tmp_path: Path) -> None:
    text = (scenarios / US101).read_text()
    start = text.index("<leftBound>")
    end = text.index("</leftBound>") + len("</leftBound>")
    lanelet_id = text[:start].rsplit('<lanelet id="', 1)[1].split('"', 1)[0]
    broken = tmp_path / "broken.xml"
    broken.write_text(text[:start] + text[end:])
    with pytest.raises(
        LogError, match=rf"lanelet {lanelet_id} \(line \d+\): its leftBound has 0 point"
    ):
        open_log(broken)
