"""The run's road map in the Foxglove export: a ROS bag run with ``--map`` (the real Lanelet2
map of Karlsruhe), exported to MCAP and read back — lanes, boundaries by type, crosswalks,
stop lines on ``/redrive/map`` in the map frame, lights on ``/redrive/traffic_lights`` per
frame; the MarkerArray copy holds the same."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoders
from mcap_ros2.decoder import DecoderFactory as Ros2Decoders

from redrive.cli.main import main
from redrive.interop.map_shapes import (
    BOUNDARY_COLORS,
    MAP_TOPIC,
    lane_triangles,
    map_shapes,
    polygon_triangles,
)
from redrive.results import open_run
from redrive.types import MapLane, RoadMap
from tests._map_drive import drive_poses, write_drive_bag

pytest.importorskip("lanelet2")
pytest.importorskip("foxglove")


@pytest.fixture(scope="module")
def mapped_run(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    from redrive.maps.files import read_map_file

    osm = shared_data / "lanelet2_maps" / "mapping_example.osm"
    road = read_map_file(osm, origin_lat_lon=(49.0, 8.4))
    folder = tmp_path_factory.mktemp("map_export")
    bag = write_drive_bag(folder / "drive.bag", drive_poses(road, seconds=2.0), frame="map")
    out = folder / "run"
    code = main(["run", str(bag), "--planning", "idm-planner", "--out", str(out), "--no-progress",
                 "--map", str(osm), "--map-origin", "49.0,8.4"])  # fmt: skip
    assert code == 0
    return out


@pytest.fixture(scope="module")
def decoded(mapped_run: Path) -> dict[str, list[tuple[int, Any]]]:
    out = mapped_run.parent / "export"
    assert main(["export", str(mapped_run), "--format", "mcap", "-o", str(out)]) == 0
    found: dict[str, list[tuple[int, Any]]] = defaultdict(list)
    with (out / "run.mcap").open("rb") as fh:
        reader = make_reader(fh, decoder_factories=[ProtobufDecoders(), Ros2Decoders()])
        summary = reader.get_summary()
        assert summary is not None
        ours = [c.topic for c in summary.channels.values() if c.topic.startswith("/redrive/")]
        for _, channel, message, value in reader.iter_decoded_messages(
            topics=ours, log_time_order=True
        ):
            found[channel.topic].append((message.log_time, value))
    return dict(found)


def test_the_map_is_drawn_once_in_its_frame_with_every_element(
    mapped_run: Path, decoded: dict[str, list[tuple[int, Any]]]
) -> None:
    run = open_run(mapped_run)
    road_map = run.road_map()
    assert road_map is not None
    first = run.table("frames").column("stamp_ns")[0].as_py()
    ((stamp, update),) = decoded[MAP_TOPIC]  # static: one update, at the first frame
    assert stamp == first
    by_id = {e.id: e for e in update.entities}
    assert {e.frame_id for e in update.entities} == {"map"}
    for lane in road_map.lanes:  # every lane: surface, both boundaries, centreline
        surface = by_id[f"lane/{lane.lane_id}"].triangles[0]
        assert len(surface.points) % 3 == 0
        assert len(surface.points) > 0
        for side, kind in (("left", lane.left_boundary_type), ("right", lane.right_boundary_type)):
            line = by_id[f"lane/{lane.lane_id}/{side}"].lines[0]
            want = lane.boundaries()[0 if side == "left" else 1]
            got = np.array([(p.x, p.y) for p in line.points])
            np.testing.assert_allclose(got, want, atol=1e-9)
            color = (line.color.r, line.color.g, line.color.b, line.color.a)
            assert color == pytest.approx(BOUNDARY_COLORS[kind])
        centre = by_id[f"lane/{lane.lane_id}/centre"].lines[0]
        np.testing.assert_allclose([(p.x, p.y) for p in centre.points], lane.centerline)
    kinds = {lane.left_boundary_type for lane in road_map.lanes}
    assert {"solid", "dashed", "road_edge"} <= kinds  # the Karlsruhe map has all three
    assert len(road_map.crosswalks) == 8
    for walk in road_map.crosswalks:
        tris = by_id[f"crosswalk/{walk.crosswalk_id}"].triangles[0]
        area = _area([(p.x, p.y) for p in tris.points])
        import shapely

        assert area == pytest.approx(shapely.Polygon(walk.polygon).area, rel=1e-6)
    assert len(road_map.stop_lines) == 28
    for stop in road_map.stop_lines:
        assert f"stop_line/{stop.stop_line_id}" in by_id
    # the RViz copy: a MarkerArray with the same lines and triangle lists
    ((_, markers),) = decoded["/redrive/markers/map"]
    types = [m.type for m in markers.markers]
    assert types.count(4) == 3 * len(road_map.lanes) + len(road_map.crosswalks) + 28
    assert types.count(11) == len(road_map.lanes) + len(road_map.areas) + len(road_map.crosswalks)


def test_the_lights_of_the_map_are_drawn_every_frame(
    mapped_run: Path, decoded: dict[str, list[tuple[int, Any]]]
) -> None:
    """The bag records no light states: the six lights of the map stand grey (unknown) at their
    positions on every frame."""
    from redrive.interop.light_shapes import STATE_COLORS
    from redrive.types import LightState

    run = open_run(mapped_run)
    road_map = run.road_map()
    assert road_map is not None
    frames = run.table("frames").column("stamp_ns").to_pylist()
    updates = decoded["/redrive/traffic_lights"]
    assert [t for t, _ in updates] == frames
    for _, update in updates:
        cubes = {e.id: e.cubes[0] for e in update.entities if e.cubes}
        assert len(cubes) == len(road_map.traffic_lights) == 6
        for light in road_map.traffic_lights:
            cube = cubes[f"light/{light.light_id}"]
            assert (cube.pose.position.x, cube.pose.position.y) == pytest.approx(
                tuple(light.position)
            )
            color = (cube.color.r, cube.color.g, cube.color.b, cube.color.a)
            assert color == pytest.approx(STATE_COLORS[LightState.UNKNOWN])


def _area(points: list[tuple[float, float]]) -> float:
    """Sum of the areas of the triangles (three points each)."""
    total = 0.0
    for i in range(0, len(points), 3):
        (ax, ay), (bx, by), (cx, cy) = points[i : i + 3]
        total += abs((bx - ax) * (cy - ay) - (cx - ax) * (by - ay)) / 2.0
    return total


def test_a_lane_surface_covers_the_lane_between_its_boundaries() -> None:
    lane = MapLane(
        lane_id="a",
        width_m=None,
        centerline=[[0.0, 0.0], [10.0, 0.0], [20.0, 5.0]],
        left_boundary=[[0.0, 1.5], [10.0, 1.5], [20.0, 6.5]],
        right_boundary=[[0.0, -1.5], [20.0, 3.5]],
    )
    points = lane_triangles(lane)
    import shapely

    left, right = lane.boundaries()
    polygon = shapely.Polygon(np.vstack([left, right[::-1]]))
    assert _area([p[:2] for p in points]) == pytest.approx(polygon.area, rel=0.02)
    assert polygon_triangles(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.5, 0.2]]))
    assert polygon_triangles(np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])) == ()
    shapes = map_shapes(RoadMap(lanes=(lane,), frame_id="odom"), stamp_ns=7)
    assert shapes.frame_id == "odom"
    assert set(shapes.ids) == {"lane/a", "lane/a/left", "lane/a/right", "lane/a/centre"}
