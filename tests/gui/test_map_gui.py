"""The planview draws a run's road map: a ROS bag run with ``--map`` (the real Lanelet2 map of
Karlsruhe) — lane lines, road edges, centrelines, crosswalks, stop lines and the lights, in the
ego's base_link; ``redrive.gui.map_layers`` on its own (no Qt) for the lights' colours."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from redrive.gui.map_layers import LIGHT_COLORS, map_layers, map_lines
from redrive.types import LightState, MapLane, MapTrafficLight, RoadMap, VehicleState
from tests._map_drive import drive_poses, write_drive_bag

_WAIT_MS = 30_000


@pytest.fixture(scope="module")
def mapped_run(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("lanelet2")
    from redrive.cli.main import main
    from redrive.maps.files import read_map_file

    osm = shared_data / "lanelet2_maps" / "mapping_example.osm"
    road = read_map_file(osm, origin_lat_lon=(49.0, 8.4))
    folder = tmp_path_factory.mktemp("map_gui")
    bag = write_drive_bag(folder / "drive.bag", drive_poses(road, seconds=10.0), frame="map")
    out = folder / "run"
    code = main(["run", str(bag), "--planning", "idm-planner", "--out", str(out), "--no-progress",
                 "--map", str(osm), "--map-origin", "49.0,8.4"])  # fmt: skip
    assert code == 0
    return out


def test_the_planview_of_an_open_loop_run_draws_its_map(
    qtbot: Any, window: Any, mapped_run: Path
) -> None:
    from redrive.results import open_run

    run = open_run(mapped_run)
    ego = run.ego()
    frame = 75  # 9 m before the junction of light 45234, two crosswalks ahead
    with qtbot.waitSignal(window.frame_shown, timeout=_WAIT_MS):
        window.open_path(mapped_run)
    with qtbot.waitSignal(
        window.frame_shown, timeout=_WAIT_MS, check_params_cb=lambda i: i == frame
    ):
        window.go_to(frame)
    layers = {layer.name: layer for layer in window.scene.layers}
    for name in ("lane lines", "road edges", "centrelines", "crosswalks", "stop lines"):
        assert f"map: {name}" in layers, sorted(layers)
        assert len(layers[f"map: {name}"].segments) > 0
    assert "map: traffic lights (unknown)" in layers  # the bag has no light states: grey
    # the lane the ego drives: its centreline passes under base_link (0, 0)
    state = ego[sorted(ego)[frame]]
    road_map = run.road_map()
    assert road_map is not None
    centre = layers["map: centrelines"].segments.reshape(-1, 2, 3)[:, :, :2]
    a, b = centre[:, 0], centre[:, 1]
    t = np.clip(np.einsum("ij,ij->i", -a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1)
    nearest = np.hypot(*(a + (b - a) * t[:, None]).T).min()
    assert nearest < 0.05
    # a light in base_link: the map position turned into the ego's frame
    light = next(x for x in road_map.traffic_lights if x.light_id == "45234")
    c, s = math.cos(state.heading_rad), math.sin(state.heading_rad)
    dx, dy = light.position - state.position[:2]
    want = np.array([c * dx + s * dy, -s * dx + c * dy])
    marks = layers["map: traffic lights (unknown)"].segments[:, :2].reshape(-1, 2)
    assert np.min(np.hypot(*(marks - want).T)) < 1.01 * math.sqrt(2)  # a corner of its square


def test_lights_take_the_colour_of_their_state_and_far_elements_are_left_out() -> None:
    lane = MapLane(lane_id="a", centerline=[[0.0, 0.0], [30.0, 0.0]], width_m=3.0,
                   left_boundary_type="road_edge", right_boundary_type="dashed")  # fmt: skip
    far = MapLane(lane_id="b", centerline=[[500.0, 0.0], [530.0, 0.0]], width_m=3.0)
    road = RoadMap(
        lanes=(lane, far),
        traffic_lights=(
            MapTrafficLight(light_id="1", position=[20.0, 3.0], lane_ids=("a",)),
            MapTrafficLight(light_id="2", position=[20.0, -3.0], lane_ids=("a",)),
        ),
    )
    ego = VehicleState(stamp_ns=0, position=np.array([10.0, 0.0, 0.0]), heading_rad=0.0)
    layers = {m.name: m for m in map_layers(map_lines(road), ego, lights={"1": LightState.RED})}
    assert layers["map: traffic lights (red)"].color == LIGHT_COLORS[LightState.RED]
    assert layers["map: traffic lights (unknown)"].color == LIGHT_COLORS[LightState.UNKNOWN]
    red = layers["map: traffic lights (red)"].segments
    assert red[:, :2].mean(axis=0) == pytest.approx([10.0, 3.0])  # light 1 in base_link
    edge = layers["map: road edges"].segments  # lane a's left boundary, 1.5 m left of it
    np.testing.assert_allclose(edge[:, 1], 1.5)
    lines = layers["map: lane lines"].segments  # its right one, and lane b is 490 m away: left out
    np.testing.assert_allclose(lines[:, :2], [[-10.0, -1.5], [20.0, -1.5]])
