"""redrive.maps.index: the indexed queries equal brute-force shapely answers over every lane."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely

from redrive.evaluation._kinematics import project_on_polyline
from redrive.maps.index import RoadMapIndex, lane_polygon
from redrive.sim.roadmap import road_map
from redrive.sim.roads import HighwayLayout, UrbanLayout, build_network
from redrive.types import MapLane, RoadMap


@pytest.fixture(scope="module", params=["urban2", "highway"])
def index(request: pytest.FixtureRequest) -> RoadMapIndex:
    layout = UrbanLayout(lanes_per_direction=2) if request.param == "urban2" else HighwayLayout()
    return RoadMapIndex(road_map(build_network(layout)))


def _points(index: RoadMapIndex, n: int = 400) -> np.ndarray:
    """Half uniform over the map's extent, half within a few metres of a centreline point."""
    extent = index.road_map.extent()
    assert extent is not None
    x0, y0, x1, y1 = extent
    rng = np.random.default_rng(7)
    uniform = np.column_stack([rng.uniform(x0 - 5, x1 + 5, n), rng.uniform(y0 - 5, y1 + 5, n)])
    centre = np.concatenate([lane.centerline for lane in index.road_map.lanes])
    near = centre[rng.integers(0, centre.shape[0], n)] + rng.normal(0.0, 3.0, (n, 2))
    return np.concatenate([uniform, near])


def test_lanes_at_equals_a_scan_of_every_lane(index: RoadMapIndex) -> None:
    pts = _points(index)
    got = index.lanes_at(pts)
    for k, p in enumerate(pts):
        want = tuple(
            lane.lane_id
            for lane, poly in zip(index.road_map.lanes, index.lane_polygons, strict=True)
            if shapely.intersects_xy(poly, *p)
        )
        assert got[k] == want
    assert sum(map(len, got)) > 200  # the sample reaches the lanes


def test_lane_of_pose_nearest_centreline_of_the_right_direction(index: RoadMapIndex) -> None:
    pts = _points(index)
    yaw = np.random.default_rng(8).uniform(-math.pi, math.pi, pts.shape[0])
    got = index.lane_of_pose(pts, yaw, max_heading_diff_rad=math.radians(60))
    for k, p in enumerate(pts):
        best: tuple[float, str] | None = None
        for lane_id in index.lanes_at(p)[0]:
            line = index.road_map.lane(lane_id).centerline
            _, dist, heading = project_on_polyline(p.reshape(1, 2), line)
            diff = abs((float(heading[0]) - yaw[k] + math.pi) % (2 * math.pi) - math.pi)
            if diff < math.radians(60) and (best is None or abs(float(dist[0])) < best[0]):
                best = (abs(float(dist[0])), lane_id)
        assert got[k] == (None if best is None else best[1])
    assert sum(g is not None for g in got) > 10


def test_station_gives_arclength_lateral_and_heading(index: RoadMapIndex) -> None:
    lane = index.road_map.lanes[0]
    pts = lane.centerline[::7] + 0.4 * np.array([1.0, -1.0])
    s, lateral, heading = index.station(pts, [lane.lane_id] * len(pts))
    want_s, want_d, want_h = project_on_polyline(pts, lane.centerline)
    np.testing.assert_allclose(s, want_s, atol=1e-9)
    np.testing.assert_allclose(lateral, want_d, atol=1e-9)
    np.testing.assert_allclose(np.cos(heading - want_h), 1.0, atol=1e-9)


def test_drivable_area_and_road_edge_equal_the_union(index: RoadMapIndex) -> None:
    pts = _points(index)
    union = index.drivable
    inside = shapely.intersects_xy(union, pts[:, 0], pts[:, 1])
    np.testing.assert_array_equal(index.on_drivable_area(pts), inside)
    outside = shapely.distance(union, shapely.points(pts))
    np.testing.assert_allclose(index.distance_outside_drivable_m(pts), outside, atol=1e-9)
    edge = shapely.distance(shapely.boundary(union), shapely.points(pts))
    np.testing.assert_allclose(index.distance_to_road_edge_m(pts), edge, atol=1e-9)
    corners = pts[-400:].reshape(100, 4, 2)
    np.testing.assert_array_equal(
        index.footprint_on_drivable_area(corners), inside[-400:].reshape(100, 4).all(axis=1)
    )


def test_route_along_successors_and_lane_changes() -> None:
    index = RoadMapIndex(road_map(build_network(UrbanLayout(lanes_per_direction=2))))
    # the left turn leaves from the inner lane: change lanes first, then turn
    assert index.route("west_in_1", "north_out_0") == (
        "west_in_1",
        "west_in_0",
        "west_north_0",
        "north_out_0",
    )
    assert index.route("west_in_0", "west_in_0") == ("west_in_0",)
    assert index.route("north_out_0", "west_in_0") == ()  # leaves the map
    with pytest.raises(KeyError, match="'ghost' is not a lane"):
        index.route("ghost", "west_in_0")
    highway = RoadMapIndex(road_map(build_network(HighwayLayout())))
    assert highway.route("entry:f2", "exit:f2") == ("entry:f2", "curve:f2", "exit:f2")
    assert highway.route("entry:f2", "entry:f0") == ("entry:f2", "entry:f1", "entry:f0")


def test_route_does_not_change_lanes_across_a_solid_line() -> None:
    def lane(lane_id: str, y: float, **kw: object) -> MapLane:
        return MapLane(lane_id=lane_id, centerline=[[0.0, y], [50.0, y]], width_m=3.5, **kw)  # type: ignore[arg-type]

    road = RoadMap(
        lanes=(
            lane("a", 0.0, left_neighbor="b", left_boundary_type="solid"),
            lane("b", 3.5, right_neighbor="a", right_boundary_type="dashed"),
        )
    )
    index = RoadMapIndex(road)
    assert index.route("a", "b") == ()  # a's left line is solid
    assert index.route("a", "b", cross_solid=True) == ("a", "b")
    assert index.route("b", "a") == ("b", "a")  # b's right line is dashed


def test_lane_with_boundaries_is_the_polygon_between_them() -> None:
    lane = MapLane(
        lane_id="a",
        centerline=[[0.0, 0.0], [10.0, 0.0]],
        width_m=None,
        left_boundary=[[0.0, 2.0], [10.0, 1.0]],
        right_boundary=[[0.0, -1.0], [10.0, -1.0]],
    )
    poly = lane_polygon(lane)
    assert poly.area == pytest.approx(25.0)
    index = RoadMapIndex(RoadMap(lanes=(lane,)))
    assert index.lanes_at([[9.0, 1.05], [9.0, 1.5]]) == [("a",), ()]
    assert index.distance_to_road_edge_m([[5.0, 0.0]])[0] == pytest.approx(1.0)


def test_empty_map() -> None:
    index = RoadMapIndex(RoadMap(lanes=()))
    assert index.lanes_at([[0.0, 0.0]]) == [()]
    assert index.lane_of_pose([[0.0, 0.0]], [0.0]) == [None]
    assert not index.on_drivable_area([[0.0, 0.0]])[0]
    assert index.distance_to_road_edge_m([[0.0, 0.0]])[0] == math.inf


def test_segment_distance_is_exact_against_shapely() -> None:
    from redrive.maps._edges import SegmentDistance

    rng = np.random.default_rng(3)
    starts = rng.uniform(-50, 50, (300, 2))
    ends = starts + rng.normal(0, 8, (300, 2))
    ends[:10] = starts[:10]  # zero-length segments count as points
    segments = np.stack([starts, ends], axis=1)
    pts = rng.uniform(-80, 80, (500, 2))
    got = SegmentDistance(segments, spacing_m=3.0)(pts)
    lines = shapely.multilinestrings(list(segments[10:])).union(shapely.multipoints(starts[:10]))
    np.testing.assert_allclose(got, shapely.distance(lines, shapely.points(pts)), atol=1e-9)
    assert SegmentDistance(np.zeros((0, 2, 2)))(pts[:3]).tolist() == [math.inf] * 3


def test_bike_lanes_are_lanes_but_not_drivable() -> None:
    car = MapLane(lane_id="car", centerline=[[0.0, 0.0], [20.0, 0.0]], width_m=3.0)
    bike = MapLane(lane_id="bike", centerline=[[0.0, 2.5], [20.0, 2.5]], width_m=2.0, kind="bike")
    road = RoadMap(lanes=(car, bike))
    every = RoadMapIndex(road)
    cars = RoadMapIndex(road, lane_kinds={"vehicle", "bus"})
    on_bike = [[10.0, 2.8]]
    assert every.lanes_at(on_bike) == [("bike",)]
    assert cars.lanes_at(on_bike) == [()]
    assert cars.lane_of_pose(on_bike, [0.0]) == [None]
    assert every.lane_of_pose(on_bike, [0.0]) == ["bike"]
    assert not every.on_drivable_area(on_bike)[0]  # the drivable area is the cars' road
    assert every.distance_outside_drivable_m(on_bike)[0] == pytest.approx(1.3)
    assert every.distance_to_road_edge_m([[10.0, 0.0]])[0] == pytest.approx(1.5)


def test_the_centrelines_are_measured_lane_by_lane() -> None:
    """The index's arclengths, headings and lengths (made over all lanes at once) are each
    lane's own np.diff / hypot / arctan2 / cumsum / sum, a repeated vertex taking the heading
    before it; each widened lane's box holds its polygon."""
    lanes = (
        MapLane(lane_id="a", centerline=[[0, 0], [1, 0], [1, 0], [2, 1], [2, 1]], width_m=3.0),
        MapLane(
            lane_id="b",
            centerline=[[5.0, 5.0], [6.0, 5.5]],
            width_m=2.0,
            left_boundary=[[5.0, 6.0], [6.0, 6.5]],
        ),
        MapLane(lane_id="c", centerline=[[0.1, 7.0], [3.3, 9.1], [7.9, 8.0]], width_m=3.5),
    )
    index = RoadMapIndex(RoadMap(lanes=lanes))
    offset = 0.0
    for k, lane in enumerate(lanes):
        seg = np.diff(lane.centerline, axis=0)
        length = np.hypot(seg[:, 0], seg[:, 1])
        heading = np.arctan2(seg[:, 1], seg[:, 0])
        for j in range(1, heading.size):
            if length[j] == 0.0:
                heading[j] = heading[j - 1]
        for j in range(heading.size - 2, -1, -1):
            if length[j] == 0.0:
                heading[j] = heading[j + 1]
        first = int(index._vertex_start[k])
        n = lane.centerline.shape[0]
        cum = offset + np.concatenate([[0.0], np.cumsum(length)])
        assert index._cum_s[first : first + n].tobytes() == cum.tobytes()
        assert index._seg_heading[first : first + n].tolist() == [*heading, heading[-1]]
        assert index.lane_length_m(lane.lane_id) == lane.length_m
        offset += float(length.sum()) + 1.0
        if lane.left_boundary is None:
            box = index._lane_tree.geometries[k]
            assert box.contains(lane_polygon(lane))


def _assert_polygons_are_lane_polygon(road: RoadMap) -> None:
    index = RoadMapIndex(road)
    widened = [k for k, lane in enumerate(road.lanes) if lane.left_boundary is None]
    assert widened  # the maps below have lanes widened from their centrelines
    rng = np.random.default_rng(3)
    # some asked first (a closed loop's queries make those they test), in no order, then all
    index._lane_polygons_at(rng.permutation(np.array(widened))[: max(1, len(widened) // 3)])
    for lane, poly in zip(road.lanes, index.lane_polygons, strict=True):
        assert shapely.to_wkb(poly) == shapely.to_wkb(lane_polygon(lane)), lane.lane_id


def test_widened_lanes_are_lane_polygon_made_in_one_call(index: RoadMapIndex) -> None:
    """The polygons the index makes of lanes without boundaries, all in one buffer call, are
    :func:`lane_polygon`'s, vertex for vertex."""
    _assert_polygons_are_lane_polygon(index.road_map)


def test_widened_lanes_of_the_waymo_map_are_lane_polygon(shared_data: Path) -> None:
    from redrive.io import open_log
    from redrive.io.content import log_road_map

    road = log_road_map(open_log(shared_data / "womd" / "motion_data_one_scenario.tfrecord"))
    assert road is not None
    assert len(road.lanes) == 198
    _assert_polygons_are_lane_polygon(road)
