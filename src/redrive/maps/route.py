"""A recorded ego path mapped onto the lane graph: the route a closed loop on the log follows.

:func:`route_along_path` takes the logged ego poses (map frame) and returns the chain of lanes
they drive along and that chain's reference line:

1. each pose's lane is :meth:`RoadMapIndex.lane_of_pose <redrive.maps.index.RoadMapIndex.lane_of_pose>`
   (the lane holding its point in its direction of travel, the nearest centreline when lanes
   overlap); poses on no lane are passed over;
2. the lanes are chained in order: a pose's lane that is not the chain's last is joined to it by
   the cheapest lane-graph route (:meth:`RoadMapIndex.route`: successors, lane changes across
   boundaries that are not solid).  When it cannot be reached from the last lane but from one
   of the two before (overlapping connectors in a junction: the pose was first given the
   sibling it did not take), the chain is cut back to that lane first; a lane reached from none
   of them is passed over (a pose assigned to an overlapping lane of another road);
3. past the last pose the chain goes on along each lane's straightest successor for
   ``extend_m`` metres, so that a planner following it does not see the route's end (a
   stopped obstacle for the IDM planner) where the log ends;
4. the reference line is the lanes' centrelines one after the other, each from where the chain
   enters it to where it leaves; a lane change leaves the first lane at the station of the pose
   where the log changed lanes and enters the second ``lane_change_m`` further on (a straight
   blend between them).

:func:`route_to_goal` is the route of a log that sets a goal instead of driving a path (a
CommonRoad planning problem): from each lane holding the start pose that runs within 90° of its
heading (junction lanes overlap), the cheapest lane-graph route to each goal lane; the shortest
of them by length, extended past it as in step 3; a lane change on it leaves the first lane at
its middle.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import shapely
from shapely.ops import substring

from redrive.maps.index import RoadMapIndex

__all__ = [
    "DEFAULT_EXTEND_M",
    "DEFAULT_LANE_CHANGE_M",
    "route_along_path",
    "route_to_goal",
    "routes_along_paths",
]

F64 = npt.NDArray[np.float64]
#: how far past the log's last pose the route continues along successors, metres
DEFAULT_EXTEND_M = 80.0
#: the length of the straight blend of a lane change, metres
DEFAULT_LANE_CHANGE_M = 12.0
#: chain step 2: how many lanes back a pose's lane may be reached from
_BACKTRACK = 3
#: chain step 2: a lane joined by a route longer than this many lanes is passed over
_MAX_JOIN_LANES = 4


def route_along_path(
    index: RoadMapIndex,
    xy: npt.ArrayLike,
    yaw_rad: npt.ArrayLike,
    *,
    extend_m: float = DEFAULT_EXTEND_M,
    lane_change_m: float = DEFAULT_LANE_CHANGE_M,
) -> tuple[tuple[str, ...], F64]:
    """The lanes the poses ``xy`` (N, 2) / ``yaw_rad`` (N,) drive along and their reference
    line (M, 2), as the module docstring says; ``((), (0, 2))`` when no pose is on a lane."""
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return _route(index, p, index.lane_of_pose(p, yaw_rad), extend_m, lane_change_m)


def routes_along_paths(
    index: RoadMapIndex,
    paths: Sequence[tuple[npt.ArrayLike, npt.ArrayLike]],
    *,
    extend_m: float = DEFAULT_EXTEND_M,
    lane_change_m: float = DEFAULT_LANE_CHANGE_M,
) -> list[tuple[tuple[str, ...], F64]]:
    """:func:`route_along_path` of each (xy, yaw_rad) of ``paths`` — the poses' lanes looked up
    in one query for all of them (a pose's lane does not depend on the others)."""
    points = [np.asarray(xy, dtype=np.float64).reshape(-1, 2) for xy, _ in paths]
    if not points:
        return []
    yaws = [
        np.broadcast_to(np.asarray(yaw, dtype=np.float64), (p.shape[0],))
        for p, (_, yaw) in zip(points, paths, strict=True)
    ]
    lanes = index.lane_of_pose(np.concatenate(points), np.concatenate(yaws))
    out = []
    start = 0
    for p in points:
        end = start + p.shape[0]
        out.append(_route(index, p, lanes[start:end], extend_m, lane_change_m))
        start = end
    return out


def route_to_goal(
    index: RoadMapIndex,
    xy: npt.ArrayLike,
    yaw_rad: float,
    goal_lane_ids: Sequence[str],
    *,
    extend_m: float = DEFAULT_EXTEND_M,
    lane_change_m: float = DEFAULT_LANE_CHANGE_M,
) -> tuple[tuple[str, ...], F64]:
    """The lanes from the start pose ``xy`` (2,) / ``yaw_rad`` — from whichever lane holding it
    runs within 90° of its heading — to the nearest reachable lane of ``goal_lane_ids`` (by
    route length), and their reference line; ``((), (0, 2))`` when the start is on no lane or
    no goal lane of the map can be reached from it."""
    p = np.asarray(xy, dtype=np.float64).reshape(1, 2)
    road = index.road_map
    known = {lane.lane_id for lane in road.lanes}
    # every lane at the start running its way (in a junction they overlap: the start's own
    # lane may be the one that does not lead to the goal)
    at = index.lanes_at(p)[0]
    _, _, heading = index.station(np.repeat(p, len(at), axis=0), at)
    diff = np.abs(np.mod(heading - yaw_rad + math.pi, math.tau) - math.pi)
    starts = [lane for lane, d in zip(at, diff.tolist(), strict=True) if d < math.pi / 2]
    routes = [index.route(a, g) for a in starts for g in goal_lane_ids if g in known]
    routes = [r for r in routes if r]
    if not routes:
        return (), np.zeros((0, 2))
    chain = list(min(routes, key=lambda r: sum(index.lane_length_m(i) for i in r)))
    poses: list[F64] = [p[0]]
    change_at: dict[int, int] = {}
    for i in range(len(chain) - 1):
        if _is_neighbour(index, chain[i], chain[i + 1]):
            line = road.lane(chain[i]).centerline
            poses.append(line[len(line) // 2])
            change_at[i] = len(poses) - 1
    _extend(index, chain, extend_m)
    return tuple(chain), _reference_line(index, chain, change_at, np.array(poses), lane_change_m)


def _route(
    index: RoadMapIndex,
    p: F64,
    lanes: Sequence[str | None],
    extend_m: float,
    lane_change_m: float,
) -> tuple[tuple[str, ...], F64]:
    chain: list[str] = []
    change_at: dict[int, int] = {}  # chain position of a lane change's first lane → pose index
    for k, lane_id in enumerate(lanes):
        if lane_id is None or (chain and lane_id == chain[-1]):
            continue
        if not chain:
            chain.append(lane_id)
            continue
        joined = _join(index, chain, lane_id)
        if joined is None:
            continue
        back, steps = joined
        del chain[len(chain) - back :]
        for key in [c for c in change_at if c >= len(chain)]:
            del change_at[key]
        for nxt in steps:
            if _is_neighbour(index, chain[-1], nxt):
                change_at[len(chain) - 1] = k
            chain.append(nxt)
    if not chain:
        return (), np.zeros((0, 2))
    _extend(index, chain, extend_m)
    return tuple(chain), _reference_line(index, chain, change_at, p, lane_change_m)


def _join(index: RoadMapIndex, chain: list[str], lane_id: str) -> tuple[int, list[str]] | None:
    """(how many lanes to cut off the chain's end, the lanes to append) to reach ``lane_id``."""
    for back in range(min(_BACKTRACK, len(chain))):
        start = chain[len(chain) - 1 - back]
        if start == lane_id:
            return back, []
        route = index.route(start, lane_id)
        if route and len(route) - 1 <= _MAX_JOIN_LANES:
            return back, list(route[1:])
    return None


def _is_neighbour(index: RoadMapIndex, a: str, b: str) -> bool:
    lane = index.road_map.lane(a)
    return b in (lane.left_neighbor, lane.right_neighbor)


def _heading(points: F64, *, at_end: bool) -> float:
    d = points[-1] - points[-2] if at_end else points[1] - points[0]
    return math.atan2(float(d[1]), float(d[0]))


def _extend(index: RoadMapIndex, chain: list[str], extend_m: float) -> None:
    road = index.road_map
    left = extend_m
    seen = set(chain)
    while left > 0.0:
        lane = road.lane(chain[-1])
        if not lane.successors:
            return
        out = _heading(lane.centerline, at_end=True)

        def turn(lane_id: str, out: float = out) -> float:
            return abs(
                math.remainder(
                    _heading(road.lane(lane_id).centerline, at_end=False) - out, math.tau
                )
            )

        nxt = min((s for s in lane.successors if s not in seen), key=turn, default=None)
        if nxt is None:
            return
        chain.append(nxt)
        seen.add(nxt)
        left -= index.lane_length_m(nxt)


def _reference_line(
    index: RoadMapIndex,
    chain: list[str],
    change_at: dict[int, int],
    poses: F64,
    lane_change_m: float,
) -> F64:
    pieces: list[F64] = []
    enter_m = 0.0
    road = index.road_map
    for i, lane_id in enumerate(chain):
        line, length = index.centreline_geometry(lane_id)
        leave_m = length
        next_enter = 0.0
        if i in change_at and i + 1 < len(chain):
            pose = shapely.Point(*poses[change_at[i]])
            leave_m = float(line.project(pose))
            target, target_length = index.centreline_geometry(chain[i + 1])
            next_enter = min(float(target.project(pose)) + lane_change_m, target_length)
        leave_m = max(leave_m, enter_m)
        if (enter_m, leave_m) != (0.0, length):
            coords = np.asarray(
                shapely.get_coordinates(substring(line, enter_m, leave_m)), dtype=np.float64
            )
        else:  # the whole lane: its centreline's own vertices (what the line was made of)
            coords = road.lane(lane_id).centerline
        if coords.shape[0] >= 1:
            pieces.append(coords)
        enter_m = next_enter
    xy = np.concatenate(pieces) if pieces else np.zeros((0, 2))
    if xy.shape[0] > 1:  # joins repeat the shared end point
        keep = np.ones(xy.shape[0], dtype=bool)
        keep[1:] = np.hypot(*np.diff(xy, axis=0).T) > 1e-6
        xy = xy[keep]
    return np.ascontiguousarray(xy)
