"""redrive.maps.lanelet2_osm on the real Lanelet2 example map (Karlsruhe), and on damaged ones."""

from __future__ import annotations

import itertools
import math
import re
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import MapError
from redrive.maps.index import RoadMapIndex
from redrive.maps.lanelet2_osm import read_lanelet2_map
from redrive.types import RoadMap

lanelet2 = pytest.importorskip("lanelet2")

ORIGIN = (49.0, 8.4)  # the origin the Lanelet2 examples load this map with


@pytest.fixture(scope="module")
def osm(shared_data: Path) -> Path:
    return shared_data / "lanelet2_maps" / "mapping_example.osm"


@pytest.fixture(scope="module")
def road(osm: Path) -> RoadMap:
    return read_lanelet2_map(osm, origin_lat_lon=ORIGIN)


def _lanelet2_map(osm: Path) -> object:
    from lanelet2.io import Origin
    from lanelet2.projection import UtmProjector

    return lanelet2.io.load(str(osm), UtmProjector(Origin(*ORIGIN)))


def test_the_map_holds_its_lanes_lights_and_crossings(road: RoadMap) -> None:
    kinds = [lane.kind for lane in road.lanes]
    # 328 vehicle lanelets, 60 of them two-way (driven both ways: 388 lanes), 28 bicycle lanes
    assert (kinds.count("vehicle"), kinds.count("bike"), len(road.lanes)) == (388, 28, 416)
    assert sum(lane.lane_id.endswith(":inv") for lane in road.lanes) == 60 + 14
    assert len(road.traffic_lights) == 6  # the six traffic_light regulatory elements
    assert len(road.crosswalks) == 8
    assert len(road.stop_lines) == 28
    assert {a.kind for a in road.areas} == {"carpark"}
    assert len(road.areas) == 19
    assert road.source is not None
    assert road.source.startswith("lanelet2:")
    # the lights control the lanes that hold them and stop at their ref_line
    for light in road.traffic_lights:
        assert light.lane_ids
        stop = next(s for s in road.stop_lines if s.stop_line_id == light.stop_line_id)
        assert set(light.lane_ids) <= set(stop.lane_ids)
    # urban Germany: 50 km/h, the highway lanelets 130 km/h (Lanelet2's German rules)
    limits = {round(lane.speed_limit_mps * 3.6) for lane in road.lanes if lane.kind == "vehicle"}  # type: ignore[operator]
    assert limits == {50, 130}


def test_lanes_are_the_lanelets_bounds_and_centreline(osm: Path, road: RoadMap) -> None:
    ll_map = _lanelet2_map(osm)
    by_id = {lane.lane_id: lane for lane in road.lanes}
    for lanelet in list(ll_map.laneletLayer)[:40]:  # type: ignore[attr-defined]
        lane_id = str(lanelet.id)
        if lane_id not in by_id:
            continue
        lane = road.lane(lane_id)
        left = np.array([[p.x, p.y] for p in lanelet.leftBound])
        centre = np.array([[p.x, p.y] for p in lanelet.centerline])
        assert lane.left_boundary is not None
        np.testing.assert_allclose(lane.left_boundary, left)
        np.testing.assert_allclose(lane.centerline, centre)
        inv = by_id.get(f"{lane_id}:inv")
        if inv is not None:  # the other direction runs the other way between swapped bounds
            assert inv.right_boundary is not None
            np.testing.assert_allclose(inv.right_boundary, left[::-1])


def test_a_drive_along_a_lanelet2_route_finds_its_lanes(osm: Path, road: RoadMap) -> None:
    import lanelet2.traffic_rules as rules
    from lanelet2 import routing

    ll_map = _lanelet2_map(osm)
    graph = routing.RoutingGraph(
        ll_map, rules.create(rules.Locations.Germany, rules.Participants.Vehicle)
    )
    start = ll_map.laneletLayer[45082]  # type: ignore[attr-defined]
    reach = graph.reachableSet(start, 400.0, 0)
    goal = max(reach, key=lambda ll: len(graph.shortestPath(start, ll) or []))
    path = [
        str(ll.id) + (":inv" if ll.inverted() else "") for ll in graph.shortestPath(start, goal)
    ]
    assert len(path) >= 5
    poses, headings = [], []
    for lane_id in path:
        line = road.lane(lane_id).centerline
        mids = (line[:-1] + line[1:]) / 2.0  # segment midpoints: inside the lanelet
        d = np.diff(line, axis=0)
        poses.append(mids)
        headings.append(np.arctan2(d[:, 1], d[:, 0]))
    xy, yaw = np.concatenate(poses), np.concatenate(headings)
    found = RoadMapIndex(road).lane_of_pose(xy, yaw, max_heading_diff_rad=math.radians(45))
    on_path = [f in path for f in found]
    assert np.mean(on_path) > 0.95, [f for f in found if f not in path]
    # redrive's own route between the ends is a chain of successors and lane changes
    chain = RoadMapIndex(road).route(path[0], path[-1])
    assert chain[0] == path[0]
    assert chain[-1] == path[-1]
    for a, b in itertools.pairwise(chain):
        lane = road.lane(a)
        assert b in (*lane.successors, lane.left_neighbor, lane.right_neighbor)


def test_no_origin_is_an_error_that_says_what_to_give(osm: Path) -> None:
    with pytest.raises(MapError, match=r"carries no projection origin.*origin_lat_lon"):
        read_lanelet2_map(osm)


def test_autoware_local_coordinates_are_the_origin(
    osm: Path, tmp_path: Path, road: RoadMap
) -> None:
    """Nodes with local_x / local_y (Autoware's maps): the map's own frame, no origin needed."""
    text = osm.read_text(encoding="utf-8")
    proj = _lanelet2_map(osm)
    shift = np.array([1000.0, -2000.0])

    def tag(match: re.Match[str]) -> str:
        node_id = int(match.group(1))
        p = proj.pointLayer[node_id]  # type: ignore[attr-defined]
        x, y = p.x + shift[0], p.y + shift[1]
        return (
            f"{match.group(0)[:-2]}>\n    <tag k='local_x' v='{x:.4f}' />\n"
            f"    <tag k='local_y' v='{y:.4f}' />\n  </node>"
        )

    tagged = re.sub(r"<node id='(-?\d+)'[^>]*/>", tag, text)
    path = tmp_path / "autoware.osm"
    path.write_text(tagged, encoding="utf-8")
    local = read_lanelet2_map(path)
    lane = road.lanes[0]
    np.testing.assert_allclose(
        local.lane(lane.lane_id).centerline, lane.centerline + shift, atol=2e-3
    )


def test_a_cut_file_and_a_lanelet_without_a_bound_name_the_problem(
    osm: Path, tmp_path: Path
) -> None:
    text = osm.read_text(encoding="utf-8")
    cut = tmp_path / "cut.osm"
    cut.write_text(text[: len(text) // 2], encoding="utf-8")
    with pytest.raises(
        MapError, match=r"cut\.osm: Lanelet2 cannot read the map .*is the file complete"
    ):
        read_lanelet2_map(cut, origin_lat_lon=ORIGIN)
    start = text.index("<relation id='42440'")
    relation = text[start : text.index("</relation>", start)]
    broken = relation.replace("<member type='way' ref='44574' role='left' />", "")
    assert broken != relation
    bad = tmp_path / "nobound.osm"
    bad.write_text(text.replace(relation, broken), encoding="utf-8")
    with pytest.raises(MapError, match=r"primitive 42440: Lanelet has not exactly one left border"):
        read_lanelet2_map(bad, origin_lat_lon=ORIGIN)
    with pytest.raises(MapError, match="no such Lanelet2 map file"):
        read_lanelet2_map(tmp_path / "missing.osm", origin_lat_lon=ORIGIN)
