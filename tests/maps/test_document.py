"""redrive.maps.document: schema 2 round trip of every field, schema 1 still read, errors name
the element."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from redrive.errors import ConfigError
from redrive.maps.document import MAP_SCHEMA_VERSION, road_map_from_json, road_map_to_json
from redrive.sim.roadmap import road_map
from redrive.sim.roads import UrbanLayout, build_network
from redrive.types import Crosswalk, MapLane, RoadMap

_PATH = Path("map.json")


def _full_map() -> RoadMap:
    m = road_map(build_network(UrbanLayout(lanes_per_direction=2)))
    extra = MapLane(
        lane_id="bike",
        centerline=[[0.0, 30.0], [20.0, 30.0]],
        width_m=None,
        left_boundary=[[0.0, 31.0], [20.0, 31.0]],
        right_boundary=[[0.0, 29.0], [10.0, 29.2], [20.0, 29.0]],
        left_boundary_type="road_edge",
        kind="bike",
    )
    cross = Crosswalk(crosswalk_id="x", polygon=[[0.0, 0.0], [3.0, 0.0], [3.0, 8.0], [0.0, 8.0]])
    return RoadMap(
        lanes=(*m.lanes, extra),
        areas=m.areas,
        roadblocks=m.roadblocks,
        intersections=m.intersections,
        crosswalks=(cross,),
        stop_lines=m.stop_lines,
        traffic_lights=m.traffic_lights,
        source=m.source,
    )


def test_schema_2_round_trips_every_field() -> None:
    want = _full_map()
    doc = road_map_to_json(want)
    assert doc["schema_version"] == MAP_SCHEMA_VERSION == 2
    text = json.dumps(doc)
    got = road_map_from_json(json.loads(text), path=_PATH)
    assert road_map_to_json(got) == doc
    bike = got.lane("bike")
    assert bike.kind == "bike"
    assert bike.left_boundary_type == "road_edge"
    assert bike.width_m == want.lane("bike").width_m
    assert bike.right_boundary is not None
    assert np.array_equal(bike.right_boundary, want.lane("bike").right_boundary)  # type: ignore[arg-type]
    assert got.lane("west_in_0").successors == ("west_east_0", "west_north_0")
    assert got.lane("west_in_0").right_neighbor == "west_in_1"
    assert got.traffic_lights[0].stop_line_id == "stop:west"
    assert got.source == "synthetic:urban"
    assert got.crosswalks[0].crosswalk_id == "x"


def test_schema_1_document_still_reads() -> None:
    doc = {
        "schema_version": 1,
        "frame_id": "map",
        "lanes": [
            {
                "lane_id": "a",
                "width_m": 3.5,
                "speed_limit_mps": None,
                "centerline": [[0, 0], [9, 0]],
            }
        ],
        "areas": [{"area_id": "i", "kind": "intersection", "polygon": [[0, 0], [1, 0], [1, 1]]}],
    }
    got = road_map_from_json(doc, path=_PATH)
    lane = got.lane("a")
    assert (lane.width_m, lane.successors, lane.roadblock_id, lane.kind) == (
        3.5,
        (),
        None,
        "vehicle",
    )
    assert got.areas[0].area_id == "i"
    assert got.source is None


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d["lanes"][3].update(successors=["ghost"]), "successors names 'ghost'"),
        (lambda d: d["lanes"][0].update(left_boundary=[[1, 2]]), r"lanes\[0\]: .*left_boundary"),
        (lambda d: d["lanes"][2].update(right_boundary_type="zigzag"), r"lanes\[2\]: .*'zigzag'"),
        (lambda d: d["roadblocks"][1].update(lane_ids="west_in_0"), r"roadblocks\[1\]\.lane_ids"),
        (lambda d: d["stop_lines"][0].pop("line"), r"stop_lines\[0\]: 'line' is missing"),
        (lambda d: d["traffic_lights"][0].update(position=[1]), r"traffic_lights\[0\]: .*shape"),
        (lambda d: d.update(crosswalks={}), "crosswalks: expected a list"),
    ],
)
def test_bad_schema_2_document_names_the_element(edit: object, message: str) -> None:
    doc = json.loads(json.dumps(road_map_to_json(_full_map())))
    edit(doc)  # type: ignore[operator]
    with pytest.raises(ConfigError, match=message) as info:
        road_map_from_json(doc, path=_PATH)
    assert "map.json" in str(info.value)
