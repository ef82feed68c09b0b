"""nuPlan's lane bookkeeping on a lane graph (``route_extractor``): the driven route through lane
connectors, corners in one common or connected lane, progress along the expert route's
roadblocks (skipped roadblocks included) — on small maps whose answers are worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from redrive.evaluation._kinematics import ego_footprint_corners
from redrive.evaluation.closedloop._common import RoadIndex
from redrive.evaluation.closedloop.lanes import (
    corners_in_common_or_connected_lanes,
    driven_route,
    is_connector,
    lane_edges,
    progress_along_route,
)
from redrive.types import Intersection, MapLane, Roadblock, RoadMap


def lane(lane_id: str, x0: float, x1: float, y: float = 0.0, **kw: object) -> MapLane:
    return MapLane(lane_id=lane_id, centerline=np.array([[x0, y], [x1, y]]), width_m=3.5, **kw)  # type: ignore[arg-type]


def chain(linked: bool) -> RoadIndex:
    """A (0→50 m) then B (50→100 m) along y = 0, in roadblocks RA and RB; A2 beside A (y = 3.5).
    ``linked``: B is A's successor."""
    succ = ("B",) if linked else ()
    pred = ("A",) if linked else ()
    return RoadIndex(
        RoadMap(
            lanes=(
                lane("A", 0.0, 50.0, successors=succ, roadblock_id="RA", left_neighbor="A2"),
                lane("A2", 0.0, 50.0, 3.5, roadblock_id="RA", right_neighbor="A"),
                lane("B", 50.0, 100.0, predecessors=pred, roadblock_id="RB"),
            ),
            roadblocks=(
                Roadblock(roadblock_id="RA", lane_ids=("A", "A2"), successors=("RB",)),
                Roadblock(roadblock_id="RB", lane_ids=("B",), predecessors=("RA",)),
            ),
        )
    )


def footprint(x_rear_axle: float, y: float = 0.0) -> np.ndarray:
    return ego_footprint_corners(
        np.array([[x_rear_axle, y]]),
        np.array([0.0]),
        length_m=4.7,
        width_m=1.9,
        rear_overhang_m=0.95,
    )


def test_a_footprint_across_a_lanes_end_is_in_connected_lanes() -> None:
    across = footprint(48.0)  # rear corners in A, front corners in B
    assert corners_in_common_or_connected_lanes(chain(linked=True), across).tolist() == [True]
    # without the lane graph the two lanes are unrelated: nuPlan would call this "in multiple
    # lanes" (a lateral collision there is the ego's fault)
    assert corners_in_common_or_connected_lanes(chain(linked=False), across).tolist() == [False]
    # on the line between A and A2: two lanes side by side, never connected
    between = footprint(20.0, 1.75)
    assert corners_in_common_or_connected_lanes(chain(linked=True), between).tolist() == [False]
    # one corner off every lane
    off = footprint(20.0, -1.2)
    assert corners_in_common_or_connected_lanes(chain(linked=True), off).tolist() == [False]
    assert corners_in_common_or_connected_lanes(chain(linked=True), footprint(20.0)).tolist() == [
        True
    ]


def junction() -> RoadIndex:
    """Lane A (0→40) into two lane connectors C1, C2 on the same 40→50 centreline (one goes on
    to D, the other to E); D (50→90) continues C1, E elsewhere continues C2."""
    box = np.array([[40.0, -5.0], [50.0, -5.0], [50.0, 5.0], [40.0, 5.0]])
    return RoadIndex(
        RoadMap(
            lanes=(
                lane("A", 0.0, 40.0, successors=("C1", "C2"), speed_limit_mps=10.0),
                lane("C1", 40.0, 50.0, predecessors=("A",), successors=("D",), intersection_id="J"),
                lane("C2", 40.0, 50.0, predecessors=("A",), successors=("E",), intersection_id="J"),
                lane("D", 50.0, 90.0, predecessors=("C1",), speed_limit_mps=20.0),
                lane("E", 50.0, 90.0, 30.0, predecessors=("C2",), speed_limit_mps=30.0),
            ),
            intersections=(Intersection(intersection_id="J", polygon=box, lane_ids=("C1", "C2")),),
        )
    )


def test_the_driven_route_keeps_the_connector_it_ends_up_in() -> None:
    road = junction()
    xs = [30.0, 38.0, 42.0, 45.0, 48.0, 52.0, 60.0]
    route = driven_route(road, np.array([[x, 0.0] for x in xs]))
    names = [[road.road_map.lanes[k].lane_id for k in objs] for objs in route]
    # in the junction both connectors hold the centre; D follows C1 only, so those states are
    # narrowed to C1 (remove_extra_lane_connectors: D's incoming edges)
    assert names == [["A"], ["A"], ["C1"], ["C1"], ["C1"], ["D"], ["D"]]


def test_a_connectors_edges_are_its_predecessors_and_successors() -> None:
    road = junction()
    c1 = road.lane_position("C1")
    assert is_connector(road, c1)
    edges = lane_edges(road, c1, outgoing=True) + lane_edges(road, c1, outgoing=False)
    assert sorted(road.road_map.lanes[k].lane_id for k in edges) == ["A", "D"]


def three_blocks() -> RoadIndex:
    """A (0→50), B (50→60), C (60→120) in succession, each its own roadblock."""
    return RoadIndex(
        RoadMap(
            lanes=(
                lane("A", 0.0, 50.0, successors=("B",), roadblock_id="RA"),
                lane("B", 50.0, 60.0, predecessors=("A",), successors=("C",), roadblock_id="RB"),
                lane("C", 60.0, 120.0, predecessors=("B",), roadblock_id="RC"),
            ),
            roadblocks=(
                Roadblock(roadblock_id="RA", lane_ids=("A",)),
                Roadblock(roadblock_id="RB", lane_ids=("B",)),
                Roadblock(roadblock_id="RC", lane_ids=("C",)),
            ),
        )
    )


def test_progress_along_the_routes_roadblocks_counts_a_skipped_one() -> None:
    road = three_blocks()
    expert = np.array([[x, 0.0] for x in np.arange(1.0, 119.0, 1.0)])
    ego = np.array([[40.0, 0.0], [45.0, 0.0], [65.0, 0.0], [70.0, 0.0]])
    along = progress_along_route(road, expert_points=expert, ego_points=ego)
    assert along is not None
    ego_steps, expert_steps = along
    # 45 → 65 jumps over B: 5 m left of A, B's 10 m (PerFrameProgressAlongRouteComputer's
    # compute_progress_for_skipped_road_block) and 5 m into C
    assert ego_steps.tolist() == pytest.approx([0.0, 5.0, 20.0, 5.0])
    assert float(expert_steps.sum()) == pytest.approx(117.0)
    # an expert in no lane: no route (nuPlan then scores the ratio 1)
    nowhere = np.array([[x, 40.0] for x in range(5)], dtype=np.float64)
    assert progress_along_route(road, expert_points=nowhere, ego_points=ego) is None


def test_progress_along_a_lane_change_stays_in_the_roadblock() -> None:
    road = chain(linked=True)
    # the expert changes from A to A2 (same roadblock RA) and drives on: progress along A's
    # baseline, the lane change moves nothing along it
    expert = np.array([[x, 3.5 * min(1.0, max(0.0, (x - 10.0) / 10.0))] for x in range(0, 45)])
    ego = np.array([[0.0, 0.0], [44.0, 0.0]])
    along = progress_along_route(road, expert_points=expert.astype(float), ego_points=ego)
    assert along is not None
    assert float(along[0].sum()) == pytest.approx(44.0)
    assert float(along[1].sum()) == pytest.approx(44.0)
