"""redrive.maps.graph: references out of a cropped map dropped, roadblocks from neighbours."""

from __future__ import annotations

from redrive.maps.graph import drop_dangling, group_roadblocks
from redrive.types import MapLane, RoadMap


def _lane(lane_id: str, y: float, **kw: object) -> MapLane:
    return MapLane(lane_id=lane_id, centerline=[[0.0, y], [10.0, y]], width_m=3.0, **kw)  # type: ignore[arg-type]


def test_dangling_references_are_dropped_and_counted() -> None:
    lanes = {
        "a": _lane("a", 0.0, successors=("b", "far"), left_neighbor="gone"),
        "b": _lane("b", 0.0, predecessors=("a", "before")),
    }
    kept, dropped = drop_dangling(lanes)
    assert dropped == 3
    assert kept["a"].successors == ("b",)
    assert kept["a"].left_neighbor is None
    assert kept["b"].predecessors == ("a",)
    RoadMap(lanes=tuple(kept.values()))  # a valid map now


def test_roadblocks_are_rows_of_mutual_neighbours() -> None:
    lanes = {
        "l": _lane("l", 3.0, right_neighbor="m", successors=("n",)),
        "m": _lane("m", 0.0, left_neighbor="l", right_neighbor="r"),
        "r": _lane("r", -3.0, left_neighbor="x"),  # names another lane: not mutual with m
        "x": _lane("x", 9.0),
        "n": _lane("n", 3.0, predecessors=("l",)),
    }
    out, blocks = group_roadblocks(lanes)
    rows = {b.roadblock_id: b.lane_ids for b in blocks}
    assert rows == {"rb:l": ("l", "m"), "rb:r": ("r",), "rb:x": ("x",), "rb:n": ("n",)}
    assert {i: lane.roadblock_id for i, lane in out.items()} == {
        "l": "rb:l",
        "m": "rb:l",
        "r": "rb:r",
        "x": "rb:x",
        "n": "rb:n",
    }
    by_id = {b.roadblock_id: b for b in blocks}
    assert by_id["rb:l"].successors == ("rb:n",)
    assert by_id["rb:n"].predecessors == ("rb:l",)
    RoadMap(lanes=tuple(out.values()), roadblocks=blocks)
