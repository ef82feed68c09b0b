"""redrive.maps.av2 on the real Argoverse 2 log map (Pittsburgh), and on damaged ones."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from pyarrow import feather

from redrive.errors import MapError
from redrive.maps.av2 import centerline, interp_arc, read_av2_map
from redrive.maps.index import RoadMapIndex
from redrive.types import RoadMap

LOG = "av2_sensor_val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede"


@pytest.fixture(scope="module")
def map_file(shared_data: Path) -> Path:
    (path,) = (shared_data / LOG / "map").glob("log_map_archive_*.json")
    return path


@pytest.fixture(scope="module")
def road(map_file: Path) -> RoadMap:
    return read_av2_map(map_file)


def test_the_map_holds_183_lane_segments_and_its_areas(map_file: Path, road: RoadMap) -> None:
    raw = json.loads(map_file.read_text())
    assert len(road.lanes) == len(raw["lane_segments"]) == 183
    assert len(road.areas) == 13
    assert len(road.crosswalks) == 11
    kinds = {lane.kind for lane in road.lanes}
    assert kinds == {"vehicle", "bike"}
    for key, seg in raw["lane_segments"].items():
        lane = road.lane(key)
        assert lane.left_boundary is not None
        np.testing.assert_array_equal(
            lane.left_boundary, [[p["x"], p["y"]] for p in seg["left_lane_boundary"]]
        )
        # the graph keeps every reference inside the map, drops those beyond its edge
        assert set(lane.successors) == {str(s) for s in seg["successors"]} & set(
            raw["lane_segments"]
        )
        assert (lane.intersection_id is not None) == seg["is_intersection"]
        assert lane.speed_limit_mps is None  # AV2 maps carry no limits
    in_intersections = {i for x in road.intersections for i in x.lane_ids}
    assert in_intersections == {k for k, s in raw["lane_segments"].items() if s["is_intersection"]}


def test_neighbours_run_the_same_way(road: RoadMap) -> None:
    for lane in road.lanes:
        for other in (lane.left_neighbor, lane.right_neighbor):
            if other is not None:
                a = lane.centerline[-1] - lane.centerline[0]
                b = road.lane(other).centerline[-1] - road.lane(other).centerline[0]
                assert float(a @ b) > 0


def test_centreline_is_av2s_midpoint_line() -> None:
    # av2 compute_midpoint_line: 10 points equally spaced in chord length on each boundary,
    # averaged.  Here the boundaries are straight, so the answer is known exactly.
    left = np.array([[0.0, 2.0, 0.0], [3.0, 2.0, 0.0], [9.0, 2.0, 0.0]])
    right = np.array([[0.0, -2.0, 0.0], [9.0, -2.0, 0.0]])
    np.testing.assert_allclose(
        centerline(left, right), np.column_stack([np.arange(10.0), np.zeros(10)])
    )
    # interp_arc keeps the ends and spaces the points evenly along a bend
    pts = interp_arc(5, np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]]))
    np.testing.assert_allclose(pts, [[0, 0], [1, 0], [2, 0], [2, 1], [2, 2]])
    # a one-point boundary (a cul-de-sac): the midpoints to it
    pivot = centerline(np.array([[0.0, 0.0, 0.0]]), np.array([[2.0, 2.0, 0.0], [2.0, -2.0, 0.0]]))
    np.testing.assert_allclose(pivot, [[1.0, 1.0], [1.0, -1.0]])


def test_the_logged_ego_drives_a_chain_of_its_lanes(shared_data: Path, road: RoadMap) -> None:
    poses = feather.read_table(shared_data / LOG / "city_SE3_egovehicle.feather").to_pandas()
    xy = poses[["tx_m", "ty_m"]].to_numpy()
    qw, qx, qy, qz = (poses[c].to_numpy() for c in ("qw", "qx", "qy", "qz"))
    yaw = np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    index = RoadMapIndex(road)
    lanes = index.lane_of_pose(xy, yaw, max_heading_diff_rad=math.radians(45))
    assert None not in lanes  # every one of the 2,706 poses is in a lane running its way
    assert index.on_drivable_area(xy).all()
    assert index.distance_to_road_edge_m(xy).min() > 1.0
    driven = list(dict.fromkeys(lanes))
    assert len(driven) >= 3
    for a, b in itertools.pairwise(driven):
        assert b in road.lane(a).successors
    assert index.route(driven[0], driven[-1]) == tuple(driven)


def _write(tmp_path: Path, data: object, name: str = "log_map_archive_x.json") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


def test_damaged_maps_name_the_element(map_file: Path, tmp_path: Path) -> None:
    text = map_file.read_text()
    cut = tmp_path / "log_map_archive_cut.json"
    cut.write_text(text[: len(text) // 3])
    with pytest.raises(MapError, match=r"not complete JSON .*is the file cut"):
        read_av2_map(cut)
    raw = json.loads(text)
    key = next(iter(raw["lane_segments"]))
    del raw["lane_segments"][key]["left_lane_boundary"]
    with pytest.raises(MapError, match=rf"lane_segments\[{key}\]: 'left_lane_boundary' is missing"):
        read_av2_map(_write(tmp_path, raw))
    raw = json.loads(text)
    raw["lane_segments"][key]["right_lane_boundary"] = [{"x": 1.0, "y": "north"}]
    with pytest.raises(MapError, match=rf"lane_segments\[{key}\]\.right_lane_boundary: points"):
        read_av2_map(_write(tmp_path, raw))
    raw = json.loads(text)
    raw["lane_segments"][key]["lane_type"] = "TRAM"
    with pytest.raises(MapError, match=rf"lane_segments\[{key}\]\.lane_type: 'TRAM'"):
        read_av2_map(_write(tmp_path, raw))
    with pytest.raises(MapError, match="not an Argoverse 2 log_map_archive"):
        read_av2_map(_write(tmp_path, {"lanes": []}))
    with pytest.raises(MapError, match="no such Argoverse 2 map file"):
        read_av2_map(tmp_path / "missing.json")
