"""redrive.types.roadmap: the road-map model's checks (boundaries, derived width, references)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from redrive.types import (
    Intersection,
    MapLane,
    MapTrafficLight,
    Roadblock,
    RoadMap,
    StopLine,
)


def _lane(lane_id: str, y: float = 0.0, **kw: object) -> MapLane:
    return MapLane(
        lane_id=lane_id,
        centerline=np.array([[0.0, y], [10.0, y]]),
        width_m=kw.pop("width_m", 3.0),  # type: ignore[arg-type]
        **kw,  # type: ignore[arg-type]
    )


def test_width_is_derived_from_both_boundaries() -> None:
    parallel = MapLane(
        lane_id="a",
        centerline=[[0.0, 0.0], [10.0, 0.0]],
        width_m=None,
        left_boundary=[[0.0, 1.5], [10.0, 1.5]],
        right_boundary=[[0.0, -1.5], [4.0, -1.5], [10.0, -1.5]],
    )
    assert parallel.width_m == pytest.approx(3.0)
    left = np.array([[0.0, 1.5], [5.0, 1.5], [10.0, 2.0]])
    right = np.array([[0.0, -1.5], [10.0, -1.0]])
    lane = MapLane(
        lane_id="b",
        centerline=[[0.0, 0.0], [10.0, 0.0]],
        width_m=None,
        left_boundary=left,
        right_boundary=right,
    )
    # the mean distance of every vertex of each boundary to the other (shapely as the reference)
    dists = [shapely.Point(p).distance(shapely.LineString(right)) for p in left] + [
        shapely.Point(p).distance(shapely.LineString(left)) for p in right
    ]
    assert lane.width_m == pytest.approx(float(np.mean(dists)), rel=1e-12)
    got_left, got_right = lane.boundaries()
    assert got_left is lane.left_boundary
    assert got_right is lane.right_boundary
    assert not got_left.flags.writeable


def test_width_needed_without_both_boundaries() -> None:
    with pytest.raises(ValueError, match="width_m is needed unless both boundaries"):
        MapLane(
            lane_id="a", centerline=[[0, 0], [1, 0]], width_m=None, left_boundary=[[0, 1], [1, 1]]
        )


def test_derived_boundaries_are_the_centreline_shifted() -> None:
    lane = MapLane(lane_id="a", centerline=[[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]], width_m=2.0)
    left, right = lane.boundaries()
    # a left turn: the left boundary's corner is the mitre point inside the bend
    np.testing.assert_allclose(left, [[0, 1], [9, 1], [9, 10]], atol=1e-12)
    np.testing.assert_allclose(right, [[0, -1], [11, -1], [11, 10]], atol=1e-12)


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"left_boundary_type": "painted"}, "left_boundary_type 'painted' is not one of"),
        ({"right_boundary": [[0.0, 1.0]]}, "right_boundary: needs >= 2 finite"),
        ({"successors": ("",)}, "ids must be non-empty strings"),
        ({"kind": ""}, "kind must be a non-empty string"),
        ({"left_neighbor": 3}, "left_neighbor must be a non-empty string or None"),
        ({"width_m": -1.0}, "width_m must be > 0"),
    ],
)
def test_bad_lane_is_refused_naming_it(kw: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message) as info:
        _lane("lane-7", **kw)
    assert "'lane-7'" in str(info.value)


def test_lane_lookup_and_extent() -> None:
    m = RoadMap(lanes=tuple(_lane(f"l{i}", y=4.0 * i) for i in range(1000)))
    assert m.lane("l777").centerline[0, 1] == 4.0 * 777
    with pytest.raises(KeyError):
        m.lane("nope")
    assert m.extent() == (0.0, -1.5, 10.0, 4.0 * 999 + 1.5)
    assert RoadMap(lanes=()).extent() is None


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (
            lambda: RoadMap(lanes=(_lane("a", successors=("b",)),)),
            r"lane 'a'\.successors names 'b'",
        ),
        (
            lambda: RoadMap(lanes=(_lane("a", roadblock_id="r"),)),
            r"lane 'a'\.roadblock_id names 'r'",
        ),
        (
            lambda: RoadMap(
                lanes=(_lane("a"),), roadblocks=(Roadblock(roadblock_id="r", lane_ids=("a", "z")),)
            ),
            r"roadblock 'r'\.lane_ids names 'z'",
        ),
        (
            lambda: RoadMap(
                lanes=(_lane("a"),),
                intersections=(
                    Intersection(
                        intersection_id="i", polygon=[[0, 0], [1, 0], [1, 1]], lane_ids=("q",)
                    ),
                ),
            ),
            r"intersection 'i'\.lane_ids names 'q'",
        ),
        (
            lambda: RoadMap(
                lanes=(_lane("a"),),
                traffic_lights=(
                    MapTrafficLight(
                        light_id="7", position=[1.0, 2.0], lane_ids=("a",), stop_line_id="s"
                    ),
                ),
            ),
            r"traffic light '7'\.stop_line_id names 's'",
        ),
        (
            lambda: RoadMap(
                lanes=(_lane("a"),),
                stop_lines=(
                    StopLine(stop_line_id="s", line=[[0, 0], [0, 1]]),
                    StopLine(stop_line_id="s", line=[[0, 0], [0, 1]]),
                ),
            ),
            "stop line id 's' appears twice",
        ),
    ],
)
def test_a_reference_out_of_the_map_is_refused(build: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build()  # type: ignore[operator]
