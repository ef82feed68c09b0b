"""The roadgraph of a Waymo Open Motion ``Scenario`` (its ``map_features``) in the road-map model.

``map.proto``'s ``LaneCenter`` is a centreline (``polyline``, in the direction of travel) with a
``speed_limit_mph`` (0: unknown), ``entry_lanes`` / ``exit_lanes``, left/right neighbours and
boundary segments: ``lane_start_index``..``lane_end_index`` of the centreline bounded by the road
line or edge ``boundary_feature_id``.  WOMD gives no lane width: it is measured here, per lane,
as the mean over the centreline points bounded on both sides of the sum of the distances to the
left and right boundary features (twice the one distance where only one side is bounded); a lane
bounded nowhere (lanes interpolated through intersections) takes the median width of those that
are.  A lane of fewer than two points has no direction and is left out (``redrive info`` counts
the lanes of the scenario, the map the ones it keeps).

The lane graph: ``exit_lanes`` are the successors, ``entry_lanes`` the predecessors, the first
``left_neighbors`` / ``right_neighbors`` entry the neighbour on that side (WOMD's neighbours are
lanes of the same direction one can change into); ids not in the map are dropped.  A side's
boundary type is that of the boundary segment bounding most of the lane: a road edge feature →
``road_edge``, a broken line → ``dashed``, a solid line → ``solid``, a passing double yellow (solid
on one side, broken on the other, and WOMD does not say which faces the lane) → ``unknown``; a side
bounded nowhere is ``virtual`` on an interpolated lane (through an intersection), else
``unknown``.  ``TYPE_BIKE_LANE`` lanes have kind ``bike``.  Roadblocks are the rows of mutual
neighbours (:func:`redrive.maps.graph.group_roadblocks`).  Crosswalks are :class:`Crosswalk`
polygons; each lane a dynamic map state controls is a :class:`MapTrafficLight` whose ``light_id``
is the lane's id (as ``TrafficLight.id`` of the reader's ``/traffic_lights``), at the state's
``stop_point``.  WOMD has no stop lines; a stop sign (its ``position`` and the ``lane`` ids it
controls) and each signal's ``stop_point`` become a :class:`StopLine` across each lane it
stops: perpendicular to the lane at the centreline point nearest it, one lane width long
(``stop_sign:<id>:<lane>``, ``signal:<lane>``; a light names its own).  Speed bumps and
driveways have no element in the model (``redrive info`` counts them).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable
from types import SimpleNamespace
from typing import Any, NamedTuple, cast

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError
from redrive.io.datasets.womd_wire_map import LaneStates, MapLanes
from redrive.maps.graph import roadblock_rows
from redrive.maps.polylines import polyline_distances
from redrive.types import Crosswalk, MapLane, MapTrafficLight, RoadMap, StopLine
from redrive.types._drafts import draft_class

__all__ = ["MPH_TO_MPS", "lane_widths", "road_map_from_scenario"]

logger = logging.getLogger(__name__)

#: one mile per hour in m/s
MPH_TO_MPS = 0.44704


def _xy(points: Any) -> npt.NDArray[np.float64]:
    # one flat list (numpy converts it far faster than a list of pairs)
    return np.array([v for p in points for v in (p.x, p.y)], dtype=np.float64).reshape(-1, 2)


#: (P, 2) every map feature's points, one after the other, and (F + 1,) the offsets of each
#: feature's (:func:`~redrive.io.datasets.womd_wire.map_polylines`)
Points = tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]


def _points_of(points: Points, k: int) -> npt.NDArray[np.float64]:
    xy, offsets = points
    return xy[offsets[k] : offsets[k + 1]].copy()


#: a boundary segment: (lane_start_index, lane_end_index, boundary_feature_id, boundary_type)
Segment = tuple[int, int, int, int]


class _Lane(NamedTuple):
    """What the map reads of a ``LaneCenter`` but its polyline (neighbours by feature id)."""

    speed_limit_mph: float
    type: int
    interpolating: bool
    entry_lanes: list[int]
    exit_lanes: list[int]
    left_neighbors: list[int]
    right_neighbors: list[int]
    left_boundaries: list[Segment]
    right_boundaries: list[Segment]


#: every map feature's (id, ``feature_data`` kind or None), in order, and the lanes' records
#: by feature position
Roadgraph = tuple[list[tuple[int, str | None]], dict[int, _Lane]]
_KINDS = {3: "lane", 4: "road_line", 5: "road_edge", 7: "stop_sign", 8: "crosswalk"}
_KINDS.update({9: "speed_bump", 10: "driveway"})


def _roadgraph(scenario: Any, walked: MapLanes | None) -> Roadgraph:
    """The features' kinds and the lanes' records: from the record's wire format (``walked``,
    :func:`~redrive.io.datasets.womd_wire_map.map_lanes`), else from the runtime's objects."""
    if walked is None:
        features: list[tuple[int, str | None]] = []
        lanes: dict[int, _Lane] = {}
        for k, f in enumerate(scenario.map_features):
            kind = f.WhichOneof("feature_data")
            features.append((int(f.id), kind))
            if kind != "lane":
                continue
            lane = f.lane
            segments = [
                [
                    (
                        int(seg.lane_start_index),
                        int(seg.lane_end_index),
                        int(seg.boundary_feature_id),
                        int(seg.boundary_type),
                    )
                    for seg in side
                ]
                for side in (lane.left_boundaries, lane.right_boundaries)
            ]
            lanes[k] = _Lane(
                float(lane.speed_limit_mph),
                int(lane.type),
                bool(lane.interpolating),
                [int(i) for i in lane.entry_lanes],
                [int(i) for i in lane.exit_lanes],
                [int(n.feature_id) for n in lane.left_neighbors],
                [int(n.feature_id) for n in lane.right_neighbors],
                *segments,
            )
        return features, lanes
    feats, speeds, ids, segs = walked
    rows = feats.tolist()
    features = [(fid, _KINDS.get(number)) for fid, number, _, _ in rows]
    lists: dict[int, tuple[list[Any], ...]] = {
        k: ([], [], [], [], [], []) for k, row in enumerate(rows) if row[1] == 3
    }
    for k, code, value in ids.tolist():  # (entry, exit, left, right: womd_wire_map's codes)
        lists[k][code].append(value)
    for k, side, *segment in segs.tolist():
        lists[k][4 + side].append(tuple(segment))
    limits = speeds.tolist()
    lanes = {k: _Lane(limits[k], rows[k][2], bool(rows[k][3]), *lists[k]) for k in lists}
    return features, lanes


def _bounded_spans(
    n: int, segments: list[Segment], lines: dict[int, int]
) -> list[tuple[int, int, int]]:
    """The (first, last point index, boundary number) of each boundary segment of one side of
    an ``n``-point centreline that bounds some of it, in the order given (a later one bounding
    a point again replaces the earlier)."""
    out = []
    for start, end, boundary, _ in segments:
        line = lines.get(boundary)
        if line is None:
            continue
        lo = max(start, 0)
        hi = min(end, n - 1)
        if hi >= lo:
            out.append((lo, hi, line))
    return out


def lane_widths(
    scenario: Any,
    centres: dict[int, npt.NDArray[np.float64]] | None = None,
    points: Points | None = None,
    roadgraph: Roadgraph | None = None,
) -> dict[int, float | None]:
    """Lane feature id → its measured width (m), or None where no boundary bounds it.

    ``centres``: lane feature id → its centreline (N, 2), when the caller has them already;
    ``points``: every feature's points (:func:`~redrive.io.datasets.womd_wire.map_polylines`
    of the record), when the caller has them; ``roadgraph``: the features' kinds and lanes'
    records, when the caller has them.

    The distance of a centreline point to a boundary is GEOS's (``shapely.distance`` of the
    point and the boundary's linestring: the least over its segments of
    ``Distance::pointToSegment``; a one-point boundary, the distance between the points),
    computed here in one compiled pass over every bounded point of every lane
    (:func:`redrive.maps.polylines.polyline_distances`: the same doubles)."""
    features, records = roadgraph or _roadgraph(scenario, None)
    coords: list[npt.NDArray[np.float64]] = []
    lines: dict[int, int] = {}  # feature id → its number in coords
    for k, (fid, kind) in enumerate(features):
        if kind in ("road_line", "road_edge"):
            xy = (
                _points_of(points, k)
                if points
                else _xy(getattr(scenario.map_features[k], kind).polyline)
            )
            if len(xy) >= 1:
                lines[fid] = len(coords)
                coords.append(xy)
    # per lane: (id, first point in the flat sides, n points); every span's centreline points
    # and boundary number in one flat list each, in the order the spans are given (left, right)
    lanes: list[tuple[int, int, int]] = []
    spans: list[tuple[int, int, int]] = []  # (side 0/1, first flat point, n points) per span
    bounded: list[npt.NDArray[np.float64]] = []
    which: list[int] = []  # each span's boundary number
    total = 0
    for k, (fid, kind) in enumerate(features):
        if kind != "lane":
            continue
        centre = (
            centres[fid]
            if centres is not None and fid in centres
            else _xy(scenario.map_features[k].lane.polyline)
        )
        if len(centre) < 2:
            continue
        n = len(centre)
        lane = records[k]
        for side, segments in enumerate((lane.left_boundaries, lane.right_boundaries)):
            for lo, hi, line in _bounded_spans(n, segments, lines):
                bounded.append(centre[lo : hi + 1])
                which.append(line)
                spans.append((side, total + lo, hi + 1 - lo))
        lanes.append((fid, total, n))
        total += n
    out: dict[int, float | None] = {}
    if not lanes:
        return out
    # every lane's left and right distances one after the other (NaN where no span bounds a
    # point; a later span bounding a point again replaces the earlier)
    sides = np.full((2, total), np.nan)
    if bounded:
        offsets = np.cumsum([0, *(len(c) for c in coords)]).astype(np.int64)
        flat = polyline_distances(
            np.concatenate(bounded),
            np.repeat(np.array(which, dtype=np.int64), [count for _, _, count in spans]),
            np.ascontiguousarray(np.concatenate(coords)),
            offsets,
        )
        at = 0
        for side, first, count in spans:
            sides[side, first : first + count] = flat[at : at + count]
            at += count
    left_m, right_m = sides
    left_ok, right_ok = np.isfinite(left_m), np.isfinite(right_m)
    both = left_ok & right_ok
    starts = np.array([first for _, first, _ in lanes], dtype=np.int64)
    any_both = np.logical_or.reduceat(both, starts).tolist()
    any_one = np.logical_or.reduceat(left_ok | right_ok, starts).tolist()
    # np.mean(left[both] + right[both]) of a lane: the sum of its slice of the pairs (the same
    # pairwise sum of the same values) over their count; 2 · np.nanmean(one side) of a lane
    # bounded on one side only: the sum of its points with NaN as 0 over the others' count
    pairs = (left_m + right_m)[both]
    pair_end = np.cumsum(both).tolist()
    one = np.where(left_ok, left_m, right_m)
    one_nan = np.isnan(one)
    one_zeroed = np.where(one_nan, 0.0, one)
    one_end = np.cumsum(~one_nan).tolist()
    for k, (fid, first, n) in enumerate(lanes):
        last = first + n - 1
        width: float | None = None
        if any_both[k]:
            lo = pair_end[first - 1] if first else 0
            count = pair_end[last] - lo
            width = float(pairs[lo : pair_end[last]].sum()) / count
        elif any_one[k]:
            lo = one_end[first - 1] if first else 0
            count = one_end[last] - lo
            width = float(2.0 * (float(one_zeroed[first : last + 1].sum()) / count))
        out[fid] = width if width is not None and width > 0.5 else None
    return out


def road_map_from_scenario(
    scenario: Any,
    *,
    source: str,
    points: Points | None = None,
    lane_states: LaneStates | None = None,
    lanes_walked: MapLanes | None = None,
) -> RoadMap:
    """The road map of a decoded ``Scenario``; ``points``: its features' points read from the
    record (:func:`~redrive.io.datasets.womd_wire.map_polylines`; None: from ``scenario``),
    ``lane_states``: its dynamic map states' lane states read from the record
    (:func:`~redrive.io.datasets.womd_wire_map.lane_states`; None: from ``scenario``),
    ``lanes_walked``: its features' kinds and lanes' numbers read from the record
    (:func:`~redrive.io.datasets.womd_wire_map.map_lanes`; None: from ``scenario``).

    Raises:
        LogError: a lane's points are not finite, or two features share an id.
    """
    roadgraph = _roadgraph(scenario, lanes_walked)
    features, records = roadgraph
    centres = {
        fid: _points_of(points, k) if points else _xy(scenario.map_features[k].lane.polyline)
        for k, (fid, kind) in enumerate(features)
        if kind == "lane"
    }
    widths = lane_widths(scenario, centres, points, roadgraph)
    known = [w for w in widths.values() if w is not None]
    fallback = float(np.median(known)) if known else None
    lanes: list[tuple[int, _Lane, npt.NDArray[np.float64], float]] = []
    seen: set[int] = set()
    skipped = 0
    # the walk's points all finite (the common case): so is every lane's centreline
    checked = points is not None and bool(np.isfinite(points[0]).all())
    for k, (fid, kind) in enumerate(features):
        if fid in seen:
            msg = f"{source}: map feature id {fid} appears twice; the roadgraph is damaged"
            raise LogError(msg)
        seen.add(fid)
        if kind != "lane":
            continue
        centre = centres[fid]
        if not checked and not np.all(np.isfinite(centre)):
            msg = f"{source}: lane {fid}: its polyline holds a point that is not finite"
            raise LogError(msg)
        if len(centre) < 2:
            skipped += 1
            continue
        width = widths.get(fid) or fallback
        if width is None:
            msg = (
                f"{source}: lane {fid}: no lane of the roadgraph has a boundary, so no width "
                "can be measured"
            )
            raise LogError(msg)
        lanes.append((fid, records[k], centre, width))
    if skipped:
        logger.debug("%s: %d lanes of fewer than two points left out", source, skipped)
    kept = {fid: str(fid) for fid, *_ in lanes}  # feature id → lane id
    edges = {fid for fid, kind in features if kind == "road_edge"}

    def in_map(ids: Any) -> tuple[str, ...]:
        return tuple(kept[i] for i in ids if i in kept)

    def first(ids: list[int]) -> str | None:
        return next((kept[i] for i in ids if i in kept), None)

    fields: dict[str, dict[str, Any]] = {}
    for fid, lane, centre, width in lanes:
        limit = float(lane.speed_limit_mph) * MPH_TO_MPS
        fields[str(fid)] = {
            "lane_id": str(fid),
            "centerline": centre,
            "width_m": width,
            "speed_limit_mps": limit if limit > 0 else None,
            "left_boundary_type": _side_type(lane.left_boundaries, edges, lane.interpolating),
            "right_boundary_type": _side_type(lane.right_boundaries, edges, lane.interpolating),
            "successors": in_map(lane.exit_lanes),
            "predecessors": in_map(lane.entry_lanes),
            "left_neighbor": first(lane.left_neighbors),
            "right_neighbor": first(lane.right_neighbors),
            "kind": "bike" if int(lane.type) == _BIKE_LANE else "vehicle",
        }
    # the roadblocks from the lanes' neighbours first: each lane is made (and checked) once
    block_of, roadblocks = roadblock_rows({i: SimpleNamespace(**f) for i, f in fields.items()})
    out = [_lane(f, block_of[i]) for i, f in fields.items()]
    crosswalks = []
    for k, (fid, kind) in enumerate(features):
        if kind == "crosswalk":
            poly = (
                _points_of(points, k) if points else _xy(scenario.map_features[k].crosswalk.polygon)
            )
            if len(poly) >= 3 and np.all(np.isfinite(poly)):
                crosswalks.append(Crosswalk(crosswalk_id=str(fid), polygon=poly))
    by_id = {lane.lane_id: lane for lane in out}
    stop_lines: list[StopLine] = []
    for k, (fid, kind) in enumerate(features):
        if kind != "stop_sign":
            continue
        sign = scenario.map_features[k].stop_sign
        where = np.array([sign.position.x, sign.position.y], dtype=np.float64)
        for lid in in_map(sign.lane):
            stop_lines.append(
                StopLine(
                    stop_line_id=f"stop_sign:{fid}:{lid}",
                    line=_stop_line_across(by_id[lid], where),
                    lane_ids=(lid,),
                )
            )
    lights: dict[str, MapTrafficLight] = {}
    # (lane id, has a stop point, its x, y) of every lane state, step by step
    stops: Iterable[tuple[int, bool, tuple[float, float]]]
    if lane_states is None:
        stops = (
            (
                int(lane_state.lane),
                lane_state.HasField("stop_point"),
                (lane_state.stop_point.x, lane_state.stop_point.y),
            )
            for state in scenario.dynamic_map_states
            for lane_state in state.lane_states
        )
    else:
        _, lane_ids, _, has_stop, stop_xy, _ = lane_states
        stops = zip(lane_ids.tolist(), has_stop.tolist(), stop_xy.tolist(), strict=True)
    for lane_id, has_stop_point, (x, y) in stops:
        lid = str(lane_id)
        if lid in lights or not has_stop_point:
            continue
        position = np.array([x, y], dtype=np.float64)
        stop_id = None
        if lid in by_id:
            stop_id = f"signal:{lid}"
            line = _stop_line_across(by_id[lid], position)
            stop_lines.append(StopLine(stop_line_id=stop_id, line=line, lane_ids=(lid,)))
        lights[lid] = MapTrafficLight(
            light_id=lid,
            position=position,
            lane_ids=(lid,) if lid in by_id else (),
            stop_line_id=stop_id,
        )
    return RoadMap(
        lanes=tuple(out),
        roadblocks=roadblocks,
        crosswalks=tuple(crosswalks),
        stop_lines=tuple(stop_lines),
        traffic_lights=tuple(lights.values()),
        source=f"womd:{source}",
    )


def _lane(f: dict[str, Any], roadblock_id: str) -> MapLane:
    """``MapLane(**f, roadblock_id=roadblock_id)`` of a lane made above, built without its
    checks (:mod:`redrive.types._drafts`) when they cannot fail: its centreline has two or more
    finite points (checked above; it becomes a read-only view, as the constructor makes it), its
    width and speed limit are finite and positive (else the constructor is called, and refuses
    them), its boundary types are the model's, its ids non-empty strings."""
    width, limit = f["width_m"], f["speed_limit_mps"]
    if not (math.isfinite(width) and width > 0.0) or not (
        limit is None or (math.isfinite(limit) and limit > 0.0)
    ):
        return MapLane(**f, roadblock_id=roadblock_id)
    line = f["centerline"].view()
    line.flags.writeable = False
    lane = _LaneDraft()
    lane.lane_id = f["lane_id"]
    lane.centerline = line
    lane.width_m = float(width)
    lane.speed_limit_mps = None if limit is None else float(limit)
    lane.left_boundary = None
    lane.right_boundary = None
    lane.left_boundary_type = f["left_boundary_type"]
    lane.right_boundary_type = f["right_boundary_type"]
    lane.successors = f["successors"]
    lane.predecessors = f["predecessors"]
    lane.left_neighbor = f["left_neighbor"]
    lane.right_neighbor = f["right_neighbor"]
    lane.roadblock_id = roadblock_id
    lane.intersection_id = None
    lane.kind = f["kind"]
    lane.__class__ = MapLane
    return cast("MapLane", lane)


#: MapLane's draft (:mod:`redrive.types._drafts`): the roadgraph's lanes built unchecked
_LaneDraft = draft_class(MapLane)


def _stop_line_across(lane: MapLane, point: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """A segment across ``lane``, one lane width long, perpendicular to it at the centreline
    vertex nearest ``point``."""
    line = lane.centerline
    i = int(np.argmin(np.hypot(*(line - point).T)))
    j, k = max(i - 1, 0), min(i + 1, len(line) - 1)
    tangent = line[k] - line[j]
    tangent = tangent / max(float(np.hypot(*tangent)), 1e-9)
    normal = np.array([-tangent[1], tangent[0]]) * (lane.width_m / 2.0)
    return np.array([line[i] + normal, line[i] - normal])


_BIKE_LANE = 3  # LaneCenter.LaneType.TYPE_BIKE_LANE
_LINE_TYPE = {1: "dashed", 2: "solid", 3: "solid", 4: "dashed", 5: "dashed", 6: "solid", 7: "solid"}


def _side_type(segments: list[Segment], edges: set[int], interpolating: bool) -> str:
    """The boundary type of the segment bounding most of one side of a lane."""
    best: Segment | None = None
    best_span = -1
    for seg in segments:
        span = seg[1] - seg[0]
        if span > best_span:
            best, best_span = seg, span
    if best is None:
        return "virtual" if interpolating else "unknown"
    if best[2] in edges:
        return "road_edge"
    return _LINE_TYPE.get(best[3], "unknown")
