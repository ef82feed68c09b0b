"""Indexed queries on a :class:`~redrive.types.RoadMap`: which lanes hold a point, the lane of a
pose, the drivable area, the distance to the road edge, a route along the lane graph.

:class:`RoadMapIndex` is built once per map (shapely STRtrees over the lane polygons, the
drivable polygons and the road-edge segments; a lane widened from its centreline, and the
drivable area, made when a query first needs them) and answers for N points at a time, so that
a frame of 100 agents costs a few tree queries, not a scan of every lane.

Geometry (the map frame, metres):

- a lane's polygon lies between its boundaries (:meth:`MapLane.boundaries
  <redrive.types.MapLane.boundaries>`); a lane without boundaries is its centreline widened by
  ``width_m / 2`` either side with flat ends (as the closed-loop metrics always measured it);
- the drivable area is the union of the polygons of the lanes cars may use
  (:data:`DRIVABLE_LANE_KINDS`: not bicycle lanes) and the map's :class:`DrivableArea` polygons;
  the road edge is the boundary of that union;
- "on" counts the boundary as inside (a point on a lane's edge is in the lane).
"""

from __future__ import annotations

import functools
import heapq
import math
from collections.abc import Callable, Collection, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely

from redrive.maps._edges import SegmentDistance
from redrive.maps.polylines import polyline_locate
from redrive.types import MapLane, RoadMap

__all__ = [
    "DEFAULT_LANE_CHANGE_COST_M",
    "DEFAULT_MAX_HEADING_DIFF_RAD",
    "DRIVABLE_LANE_KINDS",
    "RoadMapIndex",
    "lane_polygon",
]

F64 = npt.NDArray[np.float64]
#: a step of the lane graph's search: (the next lane, its cost in metres of driving)
Step = tuple[str, float]
#: :meth:`RoadMapIndex.lane_of_pose`: a lane whose direction differs from the pose's heading by
#: more than this is not the pose's lane (90°: the pose travels along it, not against it).
DEFAULT_MAX_HEADING_DIFF_RAD = math.pi / 2.0
#: :meth:`RoadMapIndex.route`: the cost of one lane change, metres of driving (so that of two
#: routes of equal length the one with fewer lane changes wins).
DEFAULT_LANE_CHANGE_COST_M = 5.0
#: the lane kinds that are part of the drivable area (cars may drive there: nuPlan's and
#: NAVSIM's drivable area is roads, not bicycle lanes)
DRIVABLE_LANE_KINDS = frozenset({"vehicle", "bus"})
#: boundary types a lane change of :meth:`RoadMapIndex.route` does not cross
_UNCROSSABLE = frozenset({"solid", "road_edge"})


def lane_polygon(lane: MapLane) -> Any:
    """The shapely polygon of ``lane`` (see the module docstring), made valid."""
    if lane.left_boundary is None and lane.right_boundary is None:
        line = shapely.LineString(lane.centerline)
        return shapely.buffer(line, lane.width_m / 2.0, cap_style="flat")
    left, right = lane.boundaries()
    poly = shapely.Polygon(np.concatenate([left, right[::-1]]))
    if not poly.is_valid:
        poly = shapely.make_valid(poly)
        parts = [p for p in shapely.get_parts(poly) if p.geom_type in ("Polygon", "MultiPolygon")]
        poly = shapely.union_all(parts) if parts else shapely.Polygon()
    return poly


def _points(xy: npt.ArrayLike) -> F64:
    p = np.asarray(xy, dtype=np.float64)
    if p.ndim == 1 and p.shape == (2,):
        p = p.reshape(1, 2)
    if p.ndim != 2 or p.shape[1] != 2:
        msg = f"points must be (N, 2) x, y metres, got shape {p.shape}"
        raise ValueError(msg)
    return p


class RoadMapIndex:
    """Spatial queries on one :class:`RoadMap`, vectorised over N points (see the module doc).

    Args:
        lane_kinds: the kinds of lane the lane queries (:meth:`lanes_at`, :meth:`lane_hits`,
            :meth:`lane_of_pose`) consider; None: every lane.  The drivable area is always the
            lanes of :data:`DRIVABLE_LANE_KINDS` and the map's drivable areas.

    Attributes:
        road_map: the map.
        lane_polygons: shapely polygons, one per lane of ``road_map.lanes`` (same order; made
            when first asked, as the lanes' queries make only those they test).
        drivable: the drivable area (a shapely (multi)polygon, prepared).
    """

    def __init__(self, road_map: RoadMap, *, lane_kinds: Collection[str] | None = None) -> None:
        self.road_map = road_map
        lanes = road_map.lanes
        self._lane_pos = {lane.lane_id: i for i, lane in enumerate(lanes)}
        #: the lane graph's routes asked so far, and each lane's length (route's costs; made
        #: with the centrelines below)
        self._routes: dict[tuple[str, str, float, bool], tuple[str, ...]] = {}
        self._lengths: dict[str, float] = {}
        self._graphs: dict[tuple[float, bool], dict[str, list[Step]]] = {}
        #: the centrelines as shapely lines, and their lengths, as asked (routes' lines)
        self._lines: dict[str, tuple[Any, float]] = {}
        self._build_centrelines(lanes)
        # a lane with boundaries has its polygon now (no buffer: a ring of its points); a lane
        # widened from its centreline has it when a query first needs it (a closed loop on a log
        # asks a few of them; shapely's buffer is most of the index's cost) and a box that holds
        # it until then, in the tree (the box's candidates are tested on the polygon: the same
        # hits)
        self._lane_array = np.empty(len(lanes), dtype=object)
        self._lane_made = np.array(
            [lane.left_boundary is not None or lane.right_boundary is not None for lane in lanes],
            dtype=bool,
        )
        boxes = np.empty(len(lanes), dtype=object)
        for k in np.flatnonzero(self._lane_made).tolist():
            boxes[k] = self._lane_array[k] = lane_polygon(lanes[k])
        widened = np.flatnonzero(~self._lane_made)
        if widened.size:
            boxes[widened] = _holding_boxes(
                self._vertices,
                self._vertex_start,
                np.array([lane.width_m for lane in lanes], dtype=np.float64),
                widened,
            )
        self._areas = [shapely.make_valid(shapely.Polygon(a.polygon)) for a in road_map.areas]
        self._lane_tree = shapely.STRtree(boxes)
        self._considered = (
            None
            if lane_kinds is None
            else np.array([lane.kind in lane_kinds for lane in lanes], dtype=bool)
        )
        # the polygons' point tests are prepared (GEOS indexes a polygon's edges on its first
        # test: a point costs a few edges, not all of them — the same answers)
        shapely.prepare(self._lane_array[self._lane_made])
        self._junction_parts = [shapely.Polygon(i.polygon) for i in road_map.intersections] + [
            p for p, a in zip(self._areas, road_map.areas, strict=True) if a.kind == "intersection"
        ]

    def _lane_polygons_at(self, positions: npt.NDArray[np.intp]) -> npt.NDArray[np.object_]:
        """The prepared polygons of the lanes at ``positions``, each made when first asked."""
        missing = np.unique(positions[~self._lane_made[positions]])
        if missing.size:
            # lane_polygon of each (a lane without boundaries: its centreline buffered by half
            # its width, flat ends), the lines made and buffered in one call each: the same
            # GEOS buffer of the same lines, so the same polygons
            counts = self._vertex_count[missing]
            first = np.repeat(self._vertex_start[missing] - np.cumsum(counts) + counts, counts)
            coords = self._vertices[first + np.arange(int(counts.sum()))]
            lines = shapely.linestrings(coords, indices=np.repeat(np.arange(missing.size), counts))
            lanes = self.road_map.lanes
            half = np.array([lanes[k].width_m for k in missing.tolist()], dtype=np.float64) / 2.0
            made = np.asarray(shapely.buffer(lines, half, cap_style="flat"), dtype=object)
            shapely.prepare(made)
            self._lane_array[missing] = made
            self._lane_made[missing] = True
        return np.asarray(self._lane_array[positions])

    @functools.cached_property
    def lane_polygons(self) -> tuple[Any, ...]:
        """Shapely polygons, one per lane of ``road_map.lanes`` (same order), prepared."""
        return tuple(self._lane_polygons_at(np.arange(len(self.road_map.lanes))).tolist())

    @functools.cached_property
    def _drivable_parts(self) -> list[Any]:
        """The polygons of the drivable area: the lanes of :data:`DRIVABLE_LANE_KINDS`, then
        the map's drivable areas."""
        roads = [
            p
            for p, lane in zip(self.lane_polygons, self.road_map.lanes, strict=True)
            if lane.kind in DRIVABLE_LANE_KINDS
        ]
        return [*roads, *self._areas]

    @functools.cached_property
    def _drivable_tree(self) -> Any:
        return shapely.STRtree(self._drivable_parts)

    @functools.cached_property
    def _drivable_array(self) -> npt.NDArray[np.object_]:
        parts = np.array(self._drivable_parts, dtype=object)
        shapely.prepare(parts)
        return parts

    # the unions are made when first asked for (a closed loop on a log routes along the lanes
    # and never asks for the drivable area's outline)

    @functools.cached_property
    def drivable(self) -> Any:
        """The drivable area (a shapely (multi)polygon, prepared)."""
        area = shapely.union_all(self._drivable_parts)
        shapely.prepare(area)
        return area

    @functools.cached_property
    def _junctions(self) -> Any:
        if not self._junction_parts:
            return None
        area = shapely.union_all(self._junction_parts)
        shapely.prepare(area)
        return area

    @functools.cached_property
    def _edge(self) -> SegmentDistance:
        return SegmentDistance(_edge_segments(self.drivable))

    def _build_centrelines(self, lanes: Sequence[MapLane]) -> None:
        # every centreline's vertices one after the other, their arclength made global (each
        # lane starts 1 m after the previous one ends) so one searchsorted finds the segment of
        # any (lane, arclength) pair.  The segments' lengths and headings of all lanes in one
        # elementwise pass each (a lane's own are the same doubles: np.diff, np.hypot and
        # np.arctan2 of its vertices); per lane only its sums
        counts = np.array([lane.centerline.shape[0] for lane in lanes], dtype=np.int64)
        vertices = (
            np.ascontiguousarray(np.concatenate([lane.centerline for lane in lanes]))
            if lanes
            else np.zeros((0, 2))
        )
        ends = np.cumsum(counts)
        starts = ends - counts
        seg = vertices[1:] - vertices[:-1]  # across two lanes too: those are not used
        length_all = np.hypot(seg[:, 0], seg[:, 1])
        heading_all = np.arctan2(seg[:, 1], seg[:, 0])
        cums, heads = [], []
        offsets = []
        offset = 0.0
        for lane, first, last in zip(lanes, starts.tolist(), ends.tolist(), strict=True):
            length = length_all[first : last - 1]
            heading = heading_all[first : last - 1]
            if not length.all():  # a repeated point (rare): the heading before it, then after
                heading = heading.copy()
                for j in range(1, heading.size):
                    if length[j] == 0.0:
                        heading[j] = heading[j - 1]
                for j in range(heading.size - 2, -1, -1):
                    if length[j] == 0.0:
                        heading[j] = heading[j + 1]
            offsets.append(offset)
            cums.append(np.cumsum(length))
            heads.append(heading)
            # MapLane.length_m, the same doubles (the same segment lengths, summed alike)
            self._lengths[lane.lane_id] = total = float(length.sum())
            offset += total + 1.0
        self._vertex_start = starts
        self._vertex_count = counts
        self._s_offset = np.array(offsets, dtype=np.float64)
        if lanes:
            # per lane: its offset, then its offset plus each running sum; each segment's
            # heading, then the last one again (the lane's end vertex)
            zero = np.zeros(1)
            self._cum_s = np.repeat(self._s_offset, counts) + np.concatenate(
                [part for cum in cums for part in (zero, cum)]
            )
            self._seg_heading = np.concatenate(
                [part for head in heads for part in (head, head[-1:])]
            )
        else:
            self._cum_s = np.zeros(0)
            self._seg_heading = np.zeros(0)
        self._vertices = vertices
        self._vertex_offsets = np.append(starts, ends[-1] if lanes else 0).astype(np.int64)

    # ---- lanes ---------------------------------------------------------------------------

    def lane_position(self, lane_id: str) -> int:
        """The position of ``lane_id`` in ``road_map.lanes`` (KeyError when it is none)."""
        return self._lane_pos[lane_id]

    def lane_length_m(self, lane_id: str) -> float:
        """``road_map.lane(lane_id).length_m``, measured once (KeyError when it is no lane)."""
        return self._lengths[lane_id]

    def centreline_geometry(self, lane_id: str) -> tuple[Any, float]:
        """Lane ``lane_id``'s centreline as a shapely LineString and its length (m), made once
        (KeyError when it is no lane of the map)."""
        known = self._lines.get(lane_id)
        if known is None:
            line = shapely.LineString(self.road_map.lanes[self._lane_pos[lane_id]].centerline)
            known = self._lines[lane_id] = (line, float(line.length))
        return known

    def lane_hits(self, xy: npt.ArrayLike) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """Every (point, lane) pair where lane holds point: the point indices into ``xy`` and
        the lane positions in ``road_map.lanes``, sorted by point then lane (the lanes of the
        index's ``lane_kinds``)."""
        pairs = _hits(self._lane_tree, self._lane_polygons_at, _points(xy), self._considered)
        order = np.lexsort((pairs[1], pairs[0]))
        return pairs[0][order].astype(np.int64), pairs[1][order].astype(np.int64)

    def lanes_at(self, xy: npt.ArrayLike) -> list[tuple[str, ...]]:
        """For each of the points ``xy`` (N, 2): the ids of the lanes holding it (map order)."""
        p = _points(xy)
        which, lane = self.lane_hits(p)
        out: list[list[str]] = [[] for _ in range(p.shape[0])]
        lanes = self.road_map.lanes
        for k, m in zip(which.tolist(), lane.tolist(), strict=True):
            out[k].append(lanes[m].lane_id)
        return [tuple(ids) for ids in out]

    def station(self, xy: npt.ArrayLike, lane_ids: Sequence[str]) -> tuple[F64, F64, F64]:
        """Where each point ``xy[k]`` lies along lane ``lane_ids[k]``: the arclength of its
        closest centreline point (m, from the lane's start), its signed lateral offset (m, left
        > 0) and the lane's direction of travel there (rad)."""
        p = _points(xy)
        if len(lane_ids) != p.shape[0]:
            msg = f"station: {p.shape[0]} points but {len(lane_ids)} lane ids"
            raise ValueError(msg)
        lanes = np.array([self._lane_pos[i] for i in lane_ids], dtype=np.int64)
        return self._station(p, lanes)

    def _station(self, p: F64, lanes: npt.NDArray[np.int64]) -> tuple[F64, F64, F64]:
        if lanes.size == 0:
            empty = np.zeros(0)
            return empty, empty.copy(), empty.copy()
        # shapely.line_locate_point and shapely.distance of each point and its centreline, the
        # same doubles from one compiled pass (redrive.maps.polylines)
        s, dist = polyline_locate(p, lanes, self._vertices, self._vertex_offsets)
        first = self._vertex_start[lanes]
        last_seg = first + self._vertex_count[lanes] - 2
        vertex = np.searchsorted(self._cum_s, self._s_offset[lanes] + s, side="right") - 1
        vertex = np.clip(vertex, first, last_seg)
        heading = self._seg_heading[vertex]
        a, b = self._vertices[vertex], self._vertices[vertex + 1]
        cross = (b[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (
            p[:, 0] - a[:, 0]
        )
        lateral = np.where(cross < 0.0, -dist, dist)
        return s, lateral, heading

    def lane_of_pose(
        self,
        xy: npt.ArrayLike,
        yaw_rad: npt.ArrayLike,
        *,
        max_heading_diff_rad: float = DEFAULT_MAX_HEADING_DIFF_RAD,
    ) -> list[str | None]:
        """For each pose: the lane that holds its point and runs less than
        ``max_heading_diff_rad`` from its heading, the one whose centreline is nearest when
        several do (then the smaller heading difference); None when no lane does."""
        p = _points(xy)
        yaw = np.broadcast_to(np.asarray(yaw_rad, dtype=np.float64), (p.shape[0],))
        which, lane = self.lane_hits(p)
        out: list[str | None] = [None] * p.shape[0]
        if which.size == 0:
            return out
        _, lateral, heading = self._station(p[which], lane)
        diff = np.abs(np.mod(heading - yaw[which] + math.pi, 2.0 * math.pi) - math.pi)
        ok = diff < max_heading_diff_rad
        which, lane, lateral, diff = which[ok], lane[ok], lateral[ok], diff[ok]
        order = np.lexsort((diff, np.abs(lateral), which))
        which, lane = which[order], lane[order]
        first = np.ones(which.size, dtype=bool)
        first[1:] = which[1:] != which[:-1]
        lanes = self.road_map.lanes
        for k, m in zip(which[first].tolist(), lane[first].tolist(), strict=True):
            out[k] = lanes[m].lane_id
        return out

    # ---- the drivable area -----------------------------------------------------------------

    def on_drivable_area(self, xy: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """(N,) each point lies on a lane of :data:`DRIVABLE_LANE_KINDS` or a drivable area
        (its boundary included)."""
        p = _points(xy)
        hits = _hits(self._drivable_tree, self._drivable_array.__getitem__, p, None)
        out = np.zeros(p.shape[0], dtype=bool)
        out[hits[0]] = True
        return out

    def footprint_on_drivable_area(self, corners: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """(N,) every corner of each footprint ``corners`` (N, K, 2) is on the drivable area
        (NAVSIM's drivable-area test: a corner off every drivable polygon puts it off road)."""
        c = np.asarray(corners, dtype=np.float64)
        if c.ndim != 3 or c.shape[2] != 2:
            msg = f"footprint corners must be (N, K, 2), got shape {c.shape}"
            raise ValueError(msg)
        inside = self.on_drivable_area(c.reshape(-1, 2)).reshape(c.shape[0], c.shape[1])
        return np.asarray(inside.all(axis=1))

    def distance_outside_drivable_m(self, xy: npt.ArrayLike) -> F64:
        """(N,) distance of each point to the drivable area, m (0 on it)."""
        p = _points(xy)
        out = np.zeros(p.shape[0])
        if len(self._drivable_tree) == 0:
            out[:] = math.inf
            return out
        idx, dist = self._drivable_tree.query_nearest(
            shapely.points(p), return_distance=True, all_matches=False
        )
        out[idx[0]] = dist
        return out

    def distance_to_road_edge_m(self, xy: npt.ArrayLike) -> F64:
        """(N,) distance of each point to the road edge (the drivable area's boundary), m, ≥ 0
        on either side of it (:meth:`on_drivable_area` tells the side); inf without a road."""
        return self._edge(_points(xy))

    def in_intersection(self, xy: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """(N,) each point lies in an intersection (an :class:`Intersection` or a drivable area
        of kind ``intersection``)."""
        p = _points(xy)
        if self._junctions is None:
            return np.zeros(p.shape[0], dtype=bool)
        return np.asarray(shapely.intersects_xy(self._junctions, p[:, 0], p[:, 1]))

    # ---- the lane graph --------------------------------------------------------------------

    def route(
        self,
        start_lane_id: str,
        goal_lane_id: str,
        *,
        lane_change_cost_m: float = DEFAULT_LANE_CHANGE_COST_M,
        cross_solid: bool = False,
    ) -> tuple[str, ...]:
        """The cheapest chain of lanes from ``start_lane_id`` to ``goal_lane_id`` (both
        included) along successors and left/right neighbours; () when the goal cannot be reached.

        Driving on to a successor costs the length of the lane left; a lane change costs
        ``lane_change_cost_m`` and crosses the boundary on that side, which must not be
        ``solid`` or a ``road_edge`` unless ``cross_solid``.  Raises KeyError for an id that is
        not a lane of the map.
        """
        for lane_id in (start_lane_id, goal_lane_id):
            if lane_id not in self._lane_pos:
                msg = f"route: {lane_id!r} is not a lane of the map"
                raise KeyError(msg)
        key = (start_lane_id, goal_lane_id, float(lane_change_cost_m), bool(cross_solid))
        known = self._routes.get(key)
        if known is None:  # the map does not change: each route is searched once
            known = self._search(
                start_lane_id,
                goal_lane_id,
                lane_change_cost_m=lane_change_cost_m,
                cross_solid=cross_solid,
            )
            self._routes[key] = known
        return known

    def _graph(self, lane_change_cost_m: float, cross_solid: bool) -> dict[str, list[Step]]:
        """Lane id → its steps (next lane, cost) for :meth:`_search`: its successors (the lane's
        length each), then its left and right neighbours (``lane_change_cost_m`` each) across a
        boundary it may cross; made once per cost and ``cross_solid``."""
        key = (float(lane_change_cost_m), bool(cross_solid))
        known = self._graphs.get(key)
        if known is not None:
            return known
        lengths = self._lengths
        graph: dict[str, list[Step]] = {}
        for lane in self.road_map.lanes:
            graph[lane.lane_id] = [(s, lengths[lane.lane_id]) for s in lane.successors] + [
                (n, lane_change_cost_m)
                for n, kind in (
                    (lane.left_neighbor, lane.left_boundary_type),
                    (lane.right_neighbor, lane.right_boundary_type),
                )
                if n is not None and (cross_solid or kind not in _UNCROSSABLE)
            ]
        self._graphs[key] = graph
        return graph

    def _search(
        self,
        start_lane_id: str,
        goal_lane_id: str,
        *,
        lane_change_cost_m: float,
        cross_solid: bool,
    ) -> tuple[str, ...]:
        graph = self._graph(lane_change_cost_m, cross_solid)
        best: dict[str, float] = {start_lane_id: 0.0}
        came_from: dict[str, str] = {}
        queue: list[tuple[float, int, str]] = [(0.0, 0, start_lane_id)]
        tick = 1
        while queue:
            cost, _, lane_id = heapq.heappop(queue)
            if lane_id == goal_lane_id:
                chain = [lane_id]
                while chain[-1] in came_from:
                    chain.append(came_from[chain[-1]])
                return tuple(reversed(chain))
            if cost > best.get(lane_id, math.inf):
                continue
            for nxt, step in graph[lane_id]:
                new = cost + step
                if new < best.get(nxt, math.inf):
                    best[nxt] = new
                    came_from[nxt] = lane_id
                    heapq.heappush(queue, (new, tick, nxt))
                    tick += 1
        return ()


def _hits(
    tree: Any,
    polygons: Callable[[npt.NDArray[np.intp]], npt.NDArray[np.object_]],
    p: F64,
    considered: npt.NDArray[np.bool_] | None,
) -> npt.NDArray[np.intp]:
    """(2, K) the (point, polygon) pairs where polygon ``polygons(k)`` (prepared; the tree's
    geometry ``k`` or a box that holds it) holds point ``p[i]``, its boundary included — what
    ``tree.query(points, predicate="intersects")`` gives on the polygons (in another order): the
    tree's bounding-box candidates, then each candidate's own test (of the polygons
    ``considered``; None: all)."""
    pairs = tree.query(shapely.points(p))
    if considered is not None:
        pairs = pairs[:, considered[pairs[1]]]
    inside = shapely.intersects_xy(polygons(pairs[1]), p[pairs[0], 0], p[pairs[0], 1])
    return np.asarray(pairs[:, inside])


def _holding_boxes(
    vertices: F64, starts: npt.NDArray[np.int64], widths: F64, which: npt.NDArray[np.intp]
) -> npt.NDArray[np.object_]:
    """Boxes that hold :func:`lane_polygon` of the lanes ``which`` (without boundaries: a
    centreline widened by ``width_m / 2`` — every point of it lies within that of the
    centreline's box; a micrometre more for the buffer's rounding); every lane's centreline is
    ``vertices[starts[k]:starts[k + 1]]`` (the last to the end), of at least two vertices."""
    lo = np.minimum.reduceat(vertices, starts, axis=0)[which]
    hi = np.maximum.reduceat(vertices, starts, axis=0)[which]
    grow = np.abs(widths[which]) / 2.0 + 1e-6
    return np.asarray(
        shapely.box(lo[:, 0] - grow, lo[:, 1] - grow, hi[:, 0] + grow, hi[:, 1] + grow)
    )


def _edge_segments(area: Any) -> F64:
    """The boundary of ``area`` as (M, 2, 2) segments (start, end)."""
    boundary = shapely.boundary(area)
    if boundary is None or shapely.is_empty(boundary):
        return np.zeros((0, 2, 2))
    pieces = []
    for part in shapely.get_parts(boundary):
        coords = shapely.get_coordinates(part)
        if coords.shape[0] >= 2:
            pieces.append(np.stack([coords[:-1], coords[1:]], axis=1))
    return np.concatenate(pieces) if pieces else np.zeros((0, 2, 2))
