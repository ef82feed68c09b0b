"""Argoverse 2 vector maps (``log_map_archive_*.json``) as a :class:`~redrive.types.RoadMap`.

A reader of the documented schema (``av2-api``: ``src/av2/map/map_api.py``
``ArgoverseStaticMap.from_json``, ``lane_segment.py`` ``LaneSegment.from_dict``,
``drivable_area.py``, ``pedestrian_crossing.py``); the ``av2`` package itself is not needed.
Coordinates are the city frame's metres (x, y; z is dropped), the log's ``map`` frame.

What becomes what:

- each lane segment becomes a lane (id ``str(id)``): its left and right lane boundaries are
  the lane's boundaries; its centreline is AV2's ``get_lane_segment_centerline``: both boundaries
  resampled to 10 points equally spaced in 3-D chord length (``interp_arc``) and averaged
  (``compute_midpoint_line``); a boundary of one point (a cul-de-sac) pivots about it;
- ``lane_type`` VEHICLE / BIKE / BUS → kind ``vehicle`` / ``bike`` / ``bus``;
- mark types: DASHED_*, DOUBLE_DASH_* → dashed; SOLID_*, DOUBLE_SOLID_* → solid; the mixed ones
  by the half nearest the lane, the first word (as ``av2.rendering.map`` draws them:
  SOLID_DASH_* → solid, DASH_SOLID_* → dashed); NONE (no paint) → virtual; UNKNOWN → unknown;
- successors, predecessors, neighbours as the file gives them, except references to lane
  segments outside this (cropped) map and neighbours that run the other way (AV2 neighbours may
  be opposing lanes; the model's are of the same direction of travel), which are dropped;
- roadblocks: rows of mutually neighbouring lanes (:func:`redrive.maps.graph.group_roadblocks`);
- intersections: the lanes with ``is_intersection``, grouped where their polygons touch, each
  group an :class:`~redrive.types.Intersection` (``intersection:<k>``) with the union's outline;
- drivable areas (kind ``drivable``) and pedestrian crossings (the polygon of their two edges,
  as ``PedestrianCrossing.polygon``).  AV2 maps carry no speed limits, stop lines or lights.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely

from redrive.errors import MapError
from redrive.maps.graph import drop_dangling, group_roadblocks
from redrive.maps.index import lane_polygon
from redrive.types import Crosswalk, DrivableArea, Intersection, MapLane, RoadMap

__all__ = ["AV2_CENTERLINE_POINTS", "read_av2_map"]

logger = logging.getLogger(__name__)

F64 = npt.NDArray[np.float64]
#: av2 ``interpolate.NUM_CENTERLINE_INTERP_PTS``: the points of a lane segment's centreline
AV2_CENTERLINE_POINTS = 10
_KINDS = {"VEHICLE": "vehicle", "BIKE": "bike", "BUS": "bus"}


def _mark(mark: str) -> str:
    if mark == "NONE":
        return "virtual"
    if mark.startswith(("DASHED_", "DOUBLE_DASH_", "DASH_SOLID_")):
        return "dashed"
    if mark.startswith(("SOLID_", "DOUBLE_SOLID_")):
        return "solid"
    return "unknown"


class _ElementError(Exception):
    """A problem of one element, before the file's name is added."""


def _xyz(value: Any, where: str) -> F64:
    if not isinstance(value, list) or not value:
        raise _ElementError(
            f"{where}: expected a non-empty list of {{x, y, z}} points, got {value!r:.60}"
        )
    try:
        arr = np.array([[p["x"], p["y"], p.get("z", 0.0)] for p in value], dtype=np.float64)
    except (TypeError, KeyError, ValueError, AttributeError) as err:
        raise _ElementError(f"{where}: points must be {{x, y, z}} numbers ({err!r})") from err
    if not np.all(np.isfinite(arr)):
        raise _ElementError(f"{where}: points must be finite")
    return arr


def interp_arc(count: int, points: F64) -> F64:
    """``count`` points equally spaced along ``points`` (N, D) by chord length: av2
    ``geometry.interpolate.interp_arc`` (repeated points carry no length)."""
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 0])
    pts = points[keep]
    if pts.shape[0] == 1:
        return np.repeat(pts, count, axis=0)
    seg = seg[seg > 0]
    cum = np.concatenate([[0.0], np.cumsum(seg)]) / seg.sum()
    t = np.linspace(0.0, 1.0, count)
    out = np.empty((count, points.shape[1]))
    for d in range(points.shape[1]):
        out[:, d] = np.interp(t, cum, pts[:, d])
    return out


def centerline(left: F64, right: F64, count: int = AV2_CENTERLINE_POINTS) -> F64:
    """av2 ``compute_midpoint_line`` in x, y: both boundaries resampled by :func:`interp_arc`
    and averaged; a one-point boundary pivots (the midpoints of it and every point of the other)."""
    if left.shape[0] == 1:
        return np.asarray(((right + left[0]) / 2.0)[:, :2], dtype=np.float64)
    if right.shape[0] == 1:
        return np.asarray(((left + right[0]) / 2.0)[:, :2], dtype=np.float64)
    mid = (interp_arc(count, left) + interp_arc(count, right)) / 2.0
    return np.asarray(mid[:, :2], dtype=np.float64)


def _field(item: Any, key: str, where: str) -> Any:
    if not isinstance(item, dict) or key not in item:
        raise _ElementError(f"{where}: '{key}' is missing")
    return item[key]


def _lane(item: Any, where: str) -> MapLane:
    lane_id = _field(item, "id", where)
    left = _xyz(_field(item, "left_lane_boundary", where), f"{where}.left_lane_boundary")
    right = _xyz(_field(item, "right_lane_boundary", where), f"{where}.right_lane_boundary")
    lane_type = _field(item, "lane_type", where)
    if lane_type not in _KINDS:
        raise _ElementError(f"{where}.lane_type: {lane_type!r} is not one of {', '.join(_KINDS)}")
    refs: dict[str, Any] = {}
    for key in ("successors", "predecessors"):
        value = item.get(key) or []
        if not isinstance(value, list) or not all(isinstance(v, int) for v in value):
            raise _ElementError(
                f"{where}.{key}: expected a list of lane segment ids, got {value!r:.60}"
            )
        refs[key] = tuple(str(v) for v in value)
    for key in ("left_neighbor_id", "right_neighbor_id"):
        value = item.get(key)
        if value is not None and not isinstance(value, int):
            raise _ElementError(
                f"{where}.{key}: expected a lane segment id or null, got {value!r:.60}"
            )
        refs[key] = None if value is None else str(value)
    marks = [str(item.get(k, "UNKNOWN")) for k in ("left_lane_mark_type", "right_lane_mark_type")]
    pivot = left.shape[0] == 1 or right.shape[0] == 1
    try:
        return MapLane(
            lane_id=str(lane_id),
            centerline=centerline(left, right),
            width_m=None,
            left_boundary=np.repeat(left[:, :2], 2, axis=0) if left.shape[0] == 1 else left[:, :2],
            right_boundary=np.repeat(right[:, :2], 2, axis=0)
            if right.shape[0] == 1
            else right[:, :2],
            left_boundary_type=_mark(marks[0]),
            right_boundary_type=_mark(marks[1]),
            successors=refs["successors"],
            predecessors=refs["predecessors"],
            left_neighbor=refs["left_neighbor_id"],
            right_neighbor=refs["right_neighbor_id"],
            kind=_KINDS[lane_type],
            intersection_id="pending" if item.get("is_intersection") is True else None,
        )
    except ValueError as err:
        extra = " (a one-point boundary)" if pivot else ""
        raise _ElementError(f"{where}: {err}{extra}") from err


def _same_direction(a: MapLane, b: MapLane) -> bool:
    da = a.centerline[-1] - a.centerline[0]
    db = b.centerline[-1] - b.centerline[0]
    return float(da @ db) > 0.0


def _polygon(points: F64) -> F64:
    xy = points[:, :2]
    if xy.shape[0] > 1 and np.array_equal(xy[0], xy[-1]):
        xy = xy[:-1]  # AV2 repeats the first vertex; the model's polygons are not closed
    return np.asarray(xy, dtype=np.float64)


def read_av2_map(path: str | Path) -> RoadMap:
    """The :class:`RoadMap` of an Argoverse 2 vector map file (see the module doc).

    Raises:
        MapError: the file is missing, cut or not JSON, or an element is missing a field or
            has a wrong one (the message names the file and the element: ``lane_segments[<id>]
            .left_lane_boundary`` …).
    """
    file = Path(path)
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except FileNotFoundError as err:
        msg = f"{file}: no such Argoverse 2 map file"
        raise MapError(msg) from err
    except (OSError, UnicodeDecodeError) as err:
        msg = f"{file}: cannot be read ({err})"
        raise MapError(msg) from err
    except json.JSONDecodeError as err:
        msg = f"{file}: not complete JSON ({err}); is the file cut? read a whole log_map_archive"
        raise MapError(msg) from err
    try:
        return _parse(data, file)
    except _ElementError as err:
        msg = f"{file}: {err}; the Argoverse 2 map is not valid there"
        raise MapError(msg) from err


def _section(data: Any, key: str) -> dict[str, Any]:
    value = data.get(key, {}) if isinstance(data, dict) else None
    if not isinstance(value, dict):
        raise _ElementError(f"{key}: expected an object of id → element")
    return value


def _parse(data: Any, file: Path) -> RoadMap:
    if not isinstance(data, dict) or "lane_segments" not in data:
        raise _ElementError("document: no 'lane_segments' (not an Argoverse 2 log_map_archive)")
    lanes: dict[str, MapLane] = {}
    for key, item in _section(data, "lane_segments").items():
        lane = _lane(item, f"lane_segments[{key}]")
        if lane.lane_id in lanes:
            raise _ElementError(
                f"lane_segments[{key}]: lane segment id {lane.lane_id} appears twice"
            )
        lanes[lane.lane_id] = lane
    lanes, dropped = drop_dangling(lanes)
    opposing = 0
    for lane_id in list(lanes):
        for side in ("left_neighbor", "right_neighbor"):
            other = getattr(lanes[lane_id], side)
            if other is not None and not _same_direction(lanes[lane_id], lanes[other]):
                lanes[lane_id] = _replace(lanes[lane_id], **{side: None})
                opposing += 1
    logger.debug(
        "%s: %d references out of the map and %d opposing neighbours dropped",
        file,
        dropped,
        opposing,
    )
    lanes, intersections = _intersections(lanes)
    lanes, roadblocks = group_roadblocks(lanes)
    areas = []
    for key, item in _section(data, "drivable_areas").items():
        where = f"drivable_areas[{key}]"
        ring = _polygon(_xyz(_field(item, "area_boundary", where), f"{where}.area_boundary"))
        try:
            areas.append(
                DrivableArea(area_id=str(item.get("id", key)), polygon=ring, kind="drivable")
            )
        except ValueError as err:
            raise _ElementError(f"{where}: {err}") from err
    crosswalks = []
    for key, item in _section(data, "pedestrian_crossings").items():
        where = f"pedestrian_crossings[{key}]"
        e1 = _xyz(_field(item, "edge1", where), f"{where}.edge1")
        e2 = _xyz(_field(item, "edge2", where), f"{where}.edge2")
        if e1.shape[0] != 2 or e2.shape[0] != 2:
            raise _ElementError(f"{where}: each edge needs 2 points")
        poly = np.array([e1[0, :2], e1[1, :2], e2[1, :2], e2[0, :2]])
        try:
            crosswalks.append(Crosswalk(crosswalk_id=str(item.get("id", key)), polygon=poly))
        except ValueError as err:
            raise _ElementError(f"{where}: {err}") from err
    try:
        return RoadMap(
            lanes=tuple(lanes.values()),
            areas=tuple(areas),
            roadblocks=roadblocks,
            intersections=intersections,
            crosswalks=tuple(crosswalks),
            source=f"av2:{file}",
        )
    except ValueError as err:
        raise _ElementError(str(err)) from err


def _replace(lane: MapLane, **changes: Any) -> MapLane:
    import dataclasses

    return dataclasses.replace(lane, **changes)


def _intersections(
    lanes: dict[str, MapLane],
) -> tuple[dict[str, MapLane], tuple[Intersection, ...]]:
    """The ``is_intersection`` lanes grouped where their polygons touch: one Intersection each."""
    inside = [i for i, lane in lanes.items() if lane.intersection_id is not None]
    if not inside:
        return lanes, ()
    polys = [lane_polygon(lanes[i]) for i in inside]
    union = shapely.union_all(polys)
    parts = [p for p in shapely.get_parts(union) if not p.is_empty]
    tree = shapely.STRtree(parts)
    found: list[tuple[F64, list[str]]] = [
        (np.asarray(shapely.get_coordinates(p.exterior)[:-1]), []) for p in parts
    ]
    for lane_id, poly in zip(inside, polys, strict=True):
        hits = tree.query(shapely.point_on_surface(poly), predicate="intersects")
        k = int(hits[0]) if len(hits) else int(tree.query_nearest(shapely.centroid(poly))[0])
        found[k][1].append(lane_id)
    out = dict(lanes)
    intersections = []
    for k, (ring, ids) in enumerate(found):
        if not ids or ring.shape[0] < 3:
            continue
        inter_id = f"intersection:{k}"
        intersections.append(
            Intersection(intersection_id=inter_id, polygon=ring, lane_ids=tuple(ids))
        )
        for i in ids:
            out[i] = _replace(out[i], intersection_id=inter_id)
    for i in inside:  # a lane whose group has no outline: not in an intersection after all
        if out[i].intersection_id == "pending":
            out[i] = _replace(out[i], intersection_id=None)
    return out, tuple(intersections)
