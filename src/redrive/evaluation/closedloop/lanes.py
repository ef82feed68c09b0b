"""nuPlan's lane bookkeeping on the road map's lane graph (``metrics/utils/route_extractor.py``):
which lanes the ego centre is assigned to per state (the driven route), which lanes each
footprint corner is in, whether the four corners are in one common or connected lane, and the
expert route's roadblocks for progress.

A lane with an ``intersection_id`` plays nuPlan's lane connector, any other lane a lane; a
lane's successors are nuPlan's outgoing edges, its predecessors the incoming ones.  On a map
without a graph (no successors, no roadblocks) the rules degrade to per-lane tests.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely

from redrive.maps.index import RoadMapIndex

__all__ = [
    "corners_in_common_or_connected_lanes",
    "corners_route",
    "driven_route",
    "is_connector",
    "lane_edges",
    "progress_along_route",
    "route_roadblocks",
]

F64 = npt.NDArray[np.float64]
#: ``get_route``: a pose that strays into another lane connector keeps the previous ones within
#: this distance, m.
CONNECTOR_PROXIMITY_M = 5.0


def is_connector(road: RoadMapIndex, lane: int) -> bool:
    """Lane ``lane`` (a position in ``road.road_map.lanes``) is a lane connector (it lies in an
    intersection)."""
    return road.road_map.lanes[lane].intersection_id is not None


def lane_edges(road: RoadMapIndex, lane: int, *, outgoing: bool) -> list[int]:
    """Positions of lane ``lane``'s successors (``outgoing``) or predecessors in the map."""
    ids = (
        road.road_map.lanes[lane].successors if outgoing else road.road_map.lanes[lane].predecessors
    )
    out = []
    for lane_id in ids:
        try:
            out.append(road.lane_position(lane_id))
        except KeyError:
            continue  # an edge to a lane the map does not hold
    return out


def _current_route_objects(road: RoadMapIndex, here: tuple[int, ...]) -> tuple[int, ...]:
    """``get_current_route_objects``: the lane holding the point, else every lane connector
    holding it. (Where nuPlan's ``get_one_map_object`` would raise — a point on two lanes'
    shared edge — every lane holding it.)"""
    plain = tuple(k for k in here if not is_connector(road, k))
    return plain if plain else tuple(k for k in here if is_connector(road, k))


def _with_candidates(
    road: RoadMapIndex, here: tuple[int, ...], candidates: tuple[int, ...]
) -> tuple[int, ...]:
    """``get_route_obj_with_candidates``: the candidates holding the point; if none does and
    there is one candidate, its outgoing edges holding it."""
    holding = set(here)
    found = tuple(k for k in candidates if k in holding)
    if not found and len(candidates) == 1:
        found = tuple(k for k in lane_edges(road, candidates[0], outgoing=True) if k in holding)
    return found


def driven_route(road: RoadMapIndex, points: F64) -> list[tuple[int, ...]]:
    """nuPlan ``get_route``: per point (the ego centre of each state), the lanes it is assigned
    to, as positions in ``road.lanes`` (empty: in none).

    A point keeps those of the previous point's lanes that still hold it (or, after a single
    lane, its successor holding it); only when none does is the map searched again (the lane
    holding it, else every connector). A pose that strays from a connector into another
    connector (or into an intersection outside any lane) keeps the previous connectors within
    5 m. Then ``remove_extra_lane_connectors``, walking back from the end: a set of several
    lanes holding all of the next point's lanes is narrowed to those, and several connectors
    followed by a lane are narrowed to the lane's predecessors among them.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    which, lane = road.lane_hits(p)
    held: list[list[int]] = [[] for _ in range(p.shape[0])]
    for k, m in zip(which.tolist(), lane.tolist(), strict=True):
        held[k].append(m)
    route: list[tuple[int, ...]] = []
    current: tuple[int, ...] = ()
    for k in range(p.shape[0]):
        here = tuple(held[k])
        if current:
            current = _with_candidates(road, here, current)
        if not current:
            current = _current_route_objects(road, here)
            previous = route[-1] if route else ()
            if (
                k > 1
                and previous
                and is_connector(road, previous[0])
                and (
                    (current and is_connector(road, current[0]))
                    or (not current and bool(road.in_intersection(p[k : k + 1])[0]))
                )
            ):
                point = shapely.Point(*p[k])
                near = tuple(
                    i
                    for i in previous
                    if float(shapely.distance(road.lane_polygons[i], point)) < CONNECTOR_PROXIMITY_M
                )
                if near:
                    current = near
        route.append(current)
    return _remove_extra_lane_connectors(road, route)


def _remove_extra_lane_connectors(
    road: RoadMapIndex, route: list[tuple[int, ...]]
) -> list[tuple[int, ...]]:
    out = list(route)
    for k in range(len(out) - 2, -1, -1):
        original = out[k]
        if len(original) <= 1:
            continue
        after = out[k + 1]
        if len(original) > len(after) and all(i in original for i in after):
            out[k] = after
        if after and not is_connector(road, after[0]):
            incoming = set(lane_edges(road, after[0], outgoing=False))
            keep = tuple(i for i in original if i in incoming)
            if keep:
                out[k] = keep
    return out


def corners_route(road: RoadMapIndex, corners: F64) -> list[list[tuple[int, ...]]]:
    """nuPlan ``extract_corners_route``: per state, per corner (front-left, rear-left,
    rear-right, front-right), the lanes it is in — looked for first among the lanes the four
    corners were in at the previous state (and a single such lane's successors), else in the
    map. ``corners``: (N, 4, 2). (The devkit seeds the candidates from the search at its
    second state, ``ind == 1``, as it is written.)"""
    c = np.asarray(corners, dtype=np.float64).reshape(-1, 4, 2)
    which, lane = road.lane_hits(c.reshape(-1, 2))
    held: list[list[int]] = [[] for _ in range(c.shape[0] * 4)]
    for k, m in zip(which.tolist(), lane.tolist(), strict=True):
        held[k].append(m)
    out: list[list[tuple[int, ...]]] = []
    candidates: list[int] = []
    for n in range(c.shape[0]):
        per_corner: list[tuple[int, ...]] = []
        next_candidates: list[int] = []
        for j in range(4):
            here = tuple(held[4 * n + j])
            found: tuple[int, ...] = ()
            if candidates:
                found = _with_candidates(road, here, tuple(candidates))
            if not found:
                found = _current_route_objects(road, here)
                if n == 1:
                    candidates += [i for i in found if i not in candidates]
            next_candidates += [i for i in found if i not in next_candidates]
            per_corner.append(found)
        out.append(per_corner)
        candidates = next_candidates
    return out


def _common_or_connected(road: RoadMapIndex, corners: list[tuple[int, ...]]) -> bool:
    """``extract_common_or_connecting_route_objs`` is truthy: the four corners share a lane, or
    the rear corners are in the same or successive lanes and each front corner in the same or
    a preceding lane of the opposite rear corner's."""
    if any(not objs for objs in corners):
        return False  # some (or every) corner outside the lanes: None (or an empty set)
    fl, rl, rr, fr = (set(objs) for objs in corners)
    if fl & rl & rr & fr:
        return True

    def out_of(objs: set[int]) -> set[int]:
        return {e for k in objs for e in lane_edges(road, k, outgoing=True)}

    def into(objs: set[int]) -> set[int]:
        return {e for k in objs for e in lane_edges(road, k, outgoing=False)}

    rr_or_out = rr | out_of(rr)
    rl_or_out = rl | out_of(rl)
    if not ((rl & rr_or_out) | (rr & rl_or_out)):
        return False
    fl_rr = (fl | into(fl)) & rr_or_out
    fr_rl = (fr | into(fr)) & rl_or_out
    return bool(fl_rr & fr_rl)


def corners_in_common_or_connected_lanes(road: RoadMapIndex, corners: F64) -> npt.NDArray[np.bool_]:
    """(N,) per state: the footprint is in one common or connected lane (nuPlan's
    ``get_timestamps_in_common_or_connected_route_objs``); False where the ego straddles
    unconnected lanes or a corner is outside every lane — there a lateral collision is the
    ego's fault and TTC looks sideways too."""
    return np.array(
        [_common_or_connected(road, per) for per in corners_route(road, corners)], dtype=bool
    )


@dataclass(slots=True)
class _Block:
    """``RouteBaselineRoadBlockPair``: a roadblock of the expert route and the baseline (the
    centreline of the route's first lane in it)."""

    polygon: Any
    baseline: Any
    next: _Block | None = None

    def contains(self, xy: F64) -> bool:
        return bool(shapely.contains_xy(self.polygon, float(xy[0]), float(xy[1])))


def _project(line: Any, xy: F64) -> float:
    """``get_distance_of_closest_baseline_point_to_its_start``."""
    return float(shapely.line_locate_point(line, shapely.Point(float(xy[0]), float(xy[1]))))


def _end(line: Any, *, last: bool) -> F64:
    coords = shapely.get_coordinates(line)
    return np.asarray(coords[-1 if last else 0], dtype=np.float64)


def _positions(road: RoadMapIndex, lane_ids: tuple[str, ...]) -> list[int]:
    out = []
    for lane_id in lane_ids:
        try:
            out.append(road.lane_position(lane_id))
        except KeyError:
            continue  # a roadblock naming a lane the map does not hold
    return out


def route_roadblocks(road: RoadMapIndex, expert_points: F64) -> _Block | None:
    """The expert route's roadblocks as nuPlan links them: ``get_route`` of the expert centres,
    ``get_route_simplified`` (repeats dropped), then one block per change of the first lane's
    roadblock (``get_route_baseline_roadblock_linkedlist``); None when the expert is in no lane.

    A lane without a ``roadblock_id`` is its own roadblock."""
    route = driven_route(road, expert_points)
    simplified: list[tuple[int, ...]] = []
    for objs in route:
        if objs and (not simplified or not set(simplified[-1]) & set(objs)):
            simplified.append(objs)
    lanes = road.road_map.lanes
    blocks = {b.roadblock_id: b for b in road.road_map.roadblocks}
    head: _Block | None = None
    tail: _Block | None = None
    previous: str | None = None
    for objs in simplified:
        lane = lanes[objs[0]]
        block_id = lane.roadblock_id if lane.roadblock_id is not None else f"lane:{lane.lane_id}"
        if block_id == previous:
            continue
        previous = block_id
        members = blocks[block_id].lane_ids if block_id in blocks else (lane.lane_id,)
        polygon = shapely.union_all([road.lane_polygons[k] for k in _positions(road, members)])
        block = _Block(polygon=polygon, baseline=shapely.LineString(lane.centerline))
        if tail is None:
            head = block
        else:
            tail.next = block
        tail = block
    return head


class _ProgressAlongRoute:
    """``PerFrameProgressAlongRouteComputer``: per pose, the progress since the previous pose
    along the baselines of the route's roadblocks (including roadblocks skipped between two
    poses); the first pose's is 0."""

    def __init__(self, head: _Block) -> None:
        self.curr = head
        self.prev_distance = 0.0
        self.next: _Block | None = None
        self.skipped: _Block | None = None

    def __call__(self, points: F64) -> F64:
        self.prev_distance = _project(self.curr.baseline, points[0])
        progress = [0.0]
        for xy in points[1:]:
            if self.curr.contains(xy):
                distance = _project(self.curr.baseline, xy)
                progress.append(distance - self.prev_distance)
                self.prev_distance = distance
            else:
                progress.append(self._multi_block(xy))
        return np.asarray(progress, dtype=np.float64)

    def _multi_block(self, xy: F64) -> float:
        skipped_progress = 0.0
        self.next = self.curr.next
        self.skipped = None
        while self.next is not None:
            if self.next.contains(xy):
                return self._entering(xy, skipped_progress)
            if self.next.next is None:
                break
            skipped_progress += self._skip()
        return 0.0

    def _skip(self) -> float:
        assert self.next is not None
        before = self.skipped if self.skipped is not None else self.curr
        prev_last = _end(before.baseline, last=True)
        self.skipped = self.next
        skipped_start = _project(self.skipped.baseline, prev_last)
        self.next = self.next.next
        assert self.next is not None
        next_first = _end(self.next.baseline, last=False)
        return _project(self.skipped.baseline, next_first) - skipped_start

    def _entering(self, xy: F64, skipped_progress: float) -> float:
        assert self.next is not None
        in_prev = float(self.curr.baseline.length) - self.prev_distance
        prev_last = _end(self.curr.baseline, last=True)
        self.curr = self.next
        distance = _project(self.curr.baseline, xy)
        in_new = distance - _project(self.curr.baseline, prev_last)
        self.prev_distance = distance
        return in_prev + in_new + skipped_progress


def progress_along_route(
    road: RoadMapIndex, *, expert_points: F64, ego_points: F64
) -> tuple[F64, F64] | None:
    """Per-pose progress (m) of the ego and of the expert along the expert route's roadblocks
    (nuPlan ``EgoProgressAlongExpertRouteStatistics.compute``); None when the expert is in no
    lane (nuPlan then scores the ratio 1)."""
    head = route_roadblocks(road, expert_points)
    if head is None:
        return None
    ego = _ProgressAlongRoute(head)(np.asarray(ego_points, dtype=np.float64).reshape(-1, 2))
    expert = _ProgressAlongRoute(head)(np.asarray(expert_points, dtype=np.float64).reshape(-1, 2))
    return ego, expert
