"""A road map: lanes with their boundaries and lane graph, roadblocks, intersections, drivable
areas, crosswalks, stop lines and traffic-light positions.

Coordinates are metres in the ``map`` frame (float64: map coordinates are large).  A lane's
direction of travel is the order of its centreline points; its boundaries run the same way.
Geometric queries (which lane holds a pose, how far the road edge is, a route along the lanes)
are :class:`redrive.maps.index.RoadMapIndex`'s; this is only the data.  Dynamic light *states*
are not in the map: they are per frame in :class:`redrive.types.TrafficData`, where
``TrafficLight.id`` is a :class:`MapTrafficLight`'s ``light_id``.

The lane graph (nuPlan's, Lanelet2's and Argoverse 2's): a lane's ``successors`` continue it, its
``predecessors`` lead into it, ``left_neighbor`` / ``right_neighbor`` are the adjacent lanes of
the same direction of travel.  A :class:`Roadblock` groups the parallel lanes of one direction
(nuPlan's roadblock, a lane group); lanes inside an intersection (nuPlan's lane connectors) name
their :class:`Intersection`.  Every id a map element names must be an element of the map
(:class:`RoadMap` checks; readers drop references that point out of a cropped map).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import frozen_array

__all__ = [
    "BOUNDARY_TYPES",
    "Crosswalk",
    "DrivableArea",
    "Intersection",
    "MapLane",
    "MapTrafficLight",
    "RoadMap",
    "Roadblock",
    "StopLine",
]

F64 = npt.NDArray[np.float64]

#: the kinds of lane boundary: painted ``solid`` / ``dashed`` lines, the ``road_edge`` (curb,
#: end of the paved road), ``virtual`` (no marking: inside an intersection, a lane split) and
#: ``unknown`` (the source does not say).
BOUNDARY_TYPES = frozenset({"solid", "dashed", "road_edge", "virtual", "unknown"})


def _points(value: Any, *, name: str, minimum: int) -> F64:
    arr = frozen_array(value, name=name, dtype=np.float64, shape=(None, 2))
    if arr.shape[0] < minimum or not np.all(np.isfinite(arr)):
        msg = f"{name}: needs >= {minimum} finite [x, y] points, got {arr.shape[0]}"
        raise ValueError(msg)
    return arr


def _ids(value: Any, *, name: str) -> tuple[str, ...]:
    ids = tuple(value)
    for i in ids:
        if not isinstance(i, str) or not i:
            msg = f"{name}: ids must be non-empty strings, got {i!r}"
            raise ValueError(msg)
    return ids


def _point_to_polyline_m(points: F64, line: F64) -> F64:
    """(K,) distance of each point to the polyline ``line`` (M, 2), metres."""
    a = line[:-1]
    seg = line[1:] - a
    seg_len2 = np.maximum((seg**2).sum(axis=1), 1e-300)
    rel = points[:, None, :] - a[None, :, :]
    t = np.clip((rel * seg[None]).sum(axis=-1) / seg_len2[None], 0.0, 1.0)
    diff = rel - t[..., None] * seg[None]
    return np.asarray(np.sqrt((diff**2).sum(axis=-1).min(axis=1)), dtype=np.float64)


def offset_polyline(line: F64, offset_m: float) -> F64:
    """``line`` (N, 2) shifted ``offset_m`` to its left (negative: right), vertex by vertex.

    Each vertex moves along the normal of the mean of its two segment directions, by
    ``offset_m / cos(half the turn)`` (a mitre, capped at twice the offset) so that the offset
    segments stay parallel to the originals.
    """
    seg = np.diff(line, axis=0)
    norm = np.hypot(seg[:, 0], seg[:, 1])
    unit = seg / np.maximum(norm, 1e-300)[:, None]
    tangent = np.empty_like(line)
    tangent[0], tangent[-1] = unit[0], unit[-1]
    tangent[1:-1] = unit[:-1] + unit[1:]
    tnorm = np.hypot(tangent[:, 0], tangent[:, 1])
    tangent = np.where(tnorm[:, None] > 1e-12, tangent / np.maximum(tnorm, 1e-300)[:, None], 0.0)
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    cos_half = np.ones(line.shape[0])
    cos_half[1:-1] = (normal[1:-1] * np.column_stack([-unit[:-1, 1], unit[:-1, 0]])).sum(axis=1)
    scale = offset_m / np.maximum(cos_half, 0.5)
    return np.asarray(line + normal * scale[:, None], dtype=np.float64)


@dataclass(frozen=True, slots=True, kw_only=True)
class MapLane:
    """One lane (or a lane connector inside an intersection).

    Attributes:
        lane_id: unique in its map.
        centerline: (N, 2) float64, metres, map frame, N ≥ 2, in the direction of travel.
        width_m: lane width, > 0.  Without boundaries the lane covers ``width_m / 2`` either
            side of the centreline; it may be None when both boundaries are given, then it is
            their mean distance (every vertex of each boundary to the other boundary).
        speed_limit_mps: the legal speed limit, m/s; None when unknown.
        left_boundary, right_boundary: (M, 2) float64 polylines in the direction of travel, or
            None: the centreline shifted by ``width_m / 2`` (:meth:`boundaries`).
        left_boundary_type, right_boundary_type: one of :data:`BOUNDARY_TYPES`.
        successors, predecessors: ids of the lanes that continue this one / lead into it.
        left_neighbor, right_neighbor: the adjacent lane of the same direction of travel on that
            side (a lane change target), None when there is none.
        roadblock_id: the :class:`Roadblock` the lane belongs to, None when the map has none.
        intersection_id: the :class:`Intersection` the lane lies in (lane connectors), else None.
        kind: what drives on it: ``vehicle`` (default), ``bike``, ``bus`` or another word.
    """

    lane_id: str
    centerline: F64
    width_m: float
    speed_limit_mps: float | None = None
    left_boundary: F64 | None = None
    right_boundary: F64 | None = None
    left_boundary_type: str = "unknown"
    right_boundary_type: str = "unknown"
    successors: tuple[str, ...] = ()
    predecessors: tuple[str, ...] = ()
    left_neighbor: str | None = None
    right_neighbor: str | None = None
    roadblock_id: str | None = None
    intersection_id: str | None = None
    kind: str = "vehicle"

    if TYPE_CHECKING:  # width_m may be None when both boundaries are given (derived then)

        def __init__(
            self,
            *,
            lane_id: str,
            centerline: npt.ArrayLike,
            width_m: float | None = None,
            speed_limit_mps: float | None = None,
            left_boundary: npt.ArrayLike | None = None,
            right_boundary: npt.ArrayLike | None = None,
            left_boundary_type: str = "unknown",
            right_boundary_type: str = "unknown",
            successors: tuple[str, ...] = (),
            predecessors: tuple[str, ...] = (),
            left_neighbor: str | None = None,
            right_neighbor: str | None = None,
            roadblock_id: str | None = None,
            intersection_id: str | None = None,
            kind: str = "vehicle",
        ) -> None: ...

    def __post_init__(self) -> None:
        name = f"MapLane {self.lane_id!r}"
        line = frozen_array(
            self.centerline, name=f"{name}.centerline", dtype=np.float64, shape=(None, 2)
        )
        if line.shape[0] < 2 or not np.all(np.isfinite(line)):
            msg = f"{name}: centerline needs >= 2 finite points, got {line.shape[0]}"
            raise ValueError(msg)
        object.__setattr__(self, "centerline", line)
        for side in ("left", "right"):
            bound = getattr(self, f"{side}_boundary")
            if bound is not None:
                bound = _points(bound, name=f"{name}.{side}_boundary", minimum=2)
                object.__setattr__(self, f"{side}_boundary", bound)
            kind = getattr(self, f"{side}_boundary_type")
            if kind not in BOUNDARY_TYPES:
                msg = (
                    f"{name}: {side}_boundary_type {kind!r} is not one of "
                    f"{', '.join(sorted(BOUNDARY_TYPES))}"
                )
                raise ValueError(msg)
        width: Any = self.width_m
        if width is None:
            if self.left_boundary is None or self.right_boundary is None:
                msg = f"{name}: width_m is needed unless both boundaries are given"
                raise ValueError(msg)
            left, right = self.left_boundary, self.right_boundary
            width = float(
                np.concatenate(
                    [_point_to_polyline_m(left, right), _point_to_polyline_m(right, left)]
                ).mean()
            )
        try:
            width = float(width)
        except (TypeError, ValueError):
            width = math.nan
        if not (width > 0 and math.isfinite(width)):
            msg = f"{name}: width_m must be > 0, got {self.width_m!r}"
            raise ValueError(msg)
        object.__setattr__(self, "width_m", width)
        limit = self.speed_limit_mps
        if limit is not None:
            limit = float(limit)
            if not (limit > 0 and math.isfinite(limit)):
                msg = f"{name}: speed_limit_mps must be > 0 or None, got {limit}"
                raise ValueError(msg)
            object.__setattr__(self, "speed_limit_mps", limit)
        for key in ("successors", "predecessors"):
            object.__setattr__(self, key, _ids(getattr(self, key), name=f"{name}.{key}"))
        for key in ("left_neighbor", "right_neighbor", "roadblock_id", "intersection_id"):
            ref = getattr(self, key)
            if ref is not None and (not isinstance(ref, str) or not ref):
                msg = f"{name}: {key} must be a non-empty string or None, got {ref!r}"
                raise ValueError(msg)
        if not isinstance(self.kind, str) or not self.kind:
            msg = f"{name}: kind must be a non-empty string, got {self.kind!r}"
            raise ValueError(msg)

    @property
    def length_m(self) -> float:
        """Length of the centreline, metres."""
        return float(np.hypot(*np.diff(self.centerline, axis=0).T).sum())

    def boundaries(self) -> tuple[F64, F64]:
        """The left and right boundary polylines, each derived from the centreline ± ``width_m
        / 2`` (:func:`offset_polyline`) when the lane has none."""
        half = self.width_m / 2.0
        left = self.left_boundary
        right = self.right_boundary
        if left is None:
            left = offset_polyline(self.centerline, half)
        if right is None:
            right = offset_polyline(self.centerline, -half)
        return left, right


@dataclass(frozen=True, slots=True, kw_only=True)
class DrivableArea:
    """A drivable polygon that is not a lane (an intersection square, a car park …).

    Attributes:
        area_id: unique in its map.
        polygon: (N, 2) float64 vertices, metres, map frame, N ≥ 3, not closed (the last
            vertex joins the first).
        kind: what it is: ``intersection`` (lateral tracks count for time-to-collision there, as in
            nuPlan), ``shoulder``, ``carpark``, ``drivable`` (a map's drivable-area polygon) or
            another word.
    """

    area_id: str
    polygon: F64
    kind: str = "intersection"

    def __post_init__(self) -> None:
        poly = frozen_array(
            self.polygon,
            name=f"DrivableArea {self.area_id!r}.polygon",
            dtype=np.float64,
            shape=(None, 2),
        )
        if poly.shape[0] < 3 or not np.all(np.isfinite(poly)):
            msg = f"DrivableArea {self.area_id!r}: polygon needs >= 3 finite vertices"
            raise ValueError(msg)
        object.__setattr__(self, "polygon", poly)


@dataclass(frozen=True, slots=True, kw_only=True)
class Roadblock:
    """The parallel lanes of one direction of travel along a stretch of road (nuPlan's
    roadblock or roadblock connector, a lane group).

    Attributes:
        roadblock_id: unique among the map's roadblocks.
        lane_ids: its lanes.
        successors, predecessors: ids of the roadblocks that continue it / lead into it.
    """

    roadblock_id: str
    lane_ids: tuple[str, ...]
    successors: tuple[str, ...] = ()
    predecessors: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        name = f"Roadblock {self.roadblock_id!r}"
        for key in ("lane_ids", "successors", "predecessors"):
            object.__setattr__(self, key, _ids(getattr(self, key), name=f"{name}.{key}"))


@dataclass(frozen=True, slots=True, kw_only=True)
class Intersection:
    """A junction: its outline and the lanes (connectors) that cross it.

    Attributes:
        intersection_id: unique among the map's intersections.
        polygon: (N, 2) float64 vertices, N ≥ 3, not closed.
        lane_ids: the lanes inside it.
    """

    intersection_id: str
    polygon: F64
    lane_ids: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        name = f"Intersection {self.intersection_id!r}"
        object.__setattr__(
            self, "polygon", _points(self.polygon, name=f"{name}.polygon", minimum=3)
        )
        object.__setattr__(self, "lane_ids", _ids(self.lane_ids, name=f"{name}.lane_ids"))


@dataclass(frozen=True, slots=True, kw_only=True)
class Crosswalk:
    """A pedestrian crossing: (N, 2) float64 polygon vertices, N ≥ 3, not closed."""

    crosswalk_id: str
    polygon: F64

    def __post_init__(self) -> None:
        name = f"Crosswalk {self.crosswalk_id!r}.polygon"
        object.__setattr__(self, "polygon", _points(self.polygon, name=name, minimum=3))


@dataclass(frozen=True, slots=True, kw_only=True)
class StopLine:
    """A stop line: the (N, 2) float64 polyline (N ≥ 2) across the lanes ``lane_ids`` it stops."""

    stop_line_id: str
    line: F64
    lane_ids: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        name = f"StopLine {self.stop_line_id!r}"
        object.__setattr__(self, "line", _points(self.line, name=f"{name}.line", minimum=2))
        object.__setattr__(self, "lane_ids", _ids(self.lane_ids, name=f"{name}.lane_ids"))


@dataclass(frozen=True, slots=True, kw_only=True)
class MapTrafficLight:
    """Where a traffic light stands and what it controls (its state is per frame, in
    :class:`~redrive.types.TrafficData`, under ``TrafficLight.id == light_id``).

    Attributes:
        light_id: unique among the map's lights.
        position: (2,) float64, metres, map frame.
        lane_ids: the lanes it controls (the lanes that stop at its stop line).
        stop_line_id: its :class:`StopLine`, None when the map has none for it.
    """

    light_id: str
    position: F64
    lane_ids: tuple[str, ...] = ()
    stop_line_id: str | None = None

    def __post_init__(self) -> None:
        name = f"MapTrafficLight {self.light_id!r}"
        pos = frozen_array(self.position, name=f"{name}.position", dtype=np.float64, shape=(2,))
        if not np.all(np.isfinite(pos)):
            msg = f"{name}: position must be finite, got {pos.tolist()}"
            raise ValueError(msg)
        object.__setattr__(self, "position", pos)
        object.__setattr__(self, "lane_ids", _ids(self.lane_ids, name=f"{name}.lane_ids"))


def _unique(what: str, ids: list[str]) -> set[str]:
    seen: set[str] = set()
    for i in ids:
        if i in seen:
            msg = f"RoadMap: {what} id {i!r} appears twice"
            raise ValueError(msg)
        seen.add(i)
    return seen


def _known(owner: str, key: str, refs: tuple[str, ...] | str | None, known: set[str]) -> None:
    if refs is None:
        return
    for ref in (refs,) if isinstance(refs, str) else refs:
        if ref not in known:
            msg = f"RoadMap: {owner}.{key} names {ref!r}, which is not in the map"
            raise ValueError(msg)


@dataclass(frozen=True, slots=True, kw_only=True)
class RoadMap:
    """The road of a run or a map file (map frame).

    The drivable area is the union of the lanes (the polygon between a lane's boundaries; the
    centreline widened by half its width either side when it has none) and the areas.

    Attributes:
        lanes: the lanes; ids unique.  :meth:`lane` finds one by id in O(1).
        areas: extra drivable polygons; ids unique.
        frame_id: the frame of the coordinates (``map``).
        roadblocks, intersections, crosswalks, stop_lines, traffic_lights: the other map
            elements (ids unique per kind); every id any element names must exist.
        source: where the map came from (``"lanelet2:PATH"``, ``"av2:PATH"``, ``"synthetic:urban"``
            …), None when unknown.
    """

    lanes: tuple[MapLane, ...]
    areas: tuple[DrivableArea, ...] = ()
    frame_id: str = "map"
    roadblocks: tuple[Roadblock, ...] = ()
    intersections: tuple[Intersection, ...] = ()
    crosswalks: tuple[Crosswalk, ...] = ()
    stop_lines: tuple[StopLine, ...] = ()
    traffic_lights: tuple[MapTrafficLight, ...] = ()
    source: str | None = None
    _lane_by_id: dict[str, MapLane] = field(init=False, repr=False, compare=False)
    _roadblock_by_id: dict[str, Roadblock] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for key in (
            "lanes",
            "areas",
            "roadblocks",
            "intersections",
            "crosswalks",
            "stop_lines",
            "traffic_lights",
        ):
            object.__setattr__(self, key, tuple(getattr(self, key)))
        lanes = _unique("lane", [lane.lane_id for lane in self.lanes])
        _unique("area", [a.area_id for a in self.areas])
        blocks = _unique("roadblock", [b.roadblock_id for b in self.roadblocks])
        inters = _unique("intersection", [i.intersection_id for i in self.intersections])
        _unique("crosswalk", [c.crosswalk_id for c in self.crosswalks])
        stops = _unique("stop line", [s.stop_line_id for s in self.stop_lines])
        _unique("traffic light", [t.light_id for t in self.traffic_lights])
        for lane in self.lanes:
            owner = f"lane {lane.lane_id!r}"
            for key in ("successors", "predecessors", "left_neighbor", "right_neighbor"):
                _known(owner, key, getattr(lane, key), lanes)
            _known(owner, "roadblock_id", lane.roadblock_id, blocks)
            _known(owner, "intersection_id", lane.intersection_id, inters)
        for block in self.roadblocks:
            owner = f"roadblock {block.roadblock_id!r}"
            _known(owner, "lane_ids", block.lane_ids, lanes)
            _known(owner, "successors", block.successors, blocks)
            _known(owner, "predecessors", block.predecessors, blocks)
        for inter in self.intersections:
            _known(f"intersection {inter.intersection_id!r}", "lane_ids", inter.lane_ids, lanes)
        for stop in self.stop_lines:
            _known(f"stop line {stop.stop_line_id!r}", "lane_ids", stop.lane_ids, lanes)
        for light in self.traffic_lights:
            owner = f"traffic light {light.light_id!r}"
            _known(owner, "lane_ids", light.lane_ids, lanes)
            _known(owner, "stop_line_id", light.stop_line_id, stops)
        object.__setattr__(self, "_lane_by_id", {lane.lane_id: lane for lane in self.lanes})
        object.__setattr__(self, "_roadblock_by_id", {b.roadblock_id: b for b in self.roadblocks})

    def lane(self, lane_id: str) -> MapLane:
        """The lane ``lane_id`` (KeyError when there is none), O(1)."""
        return self._lane_by_id[lane_id]

    def roadblock(self, roadblock_id: str) -> Roadblock:
        """The roadblock ``roadblock_id`` (KeyError when there is none), O(1)."""
        return self._roadblock_by_id[roadblock_id]

    def extent(self) -> tuple[float, float, float, float] | None:
        """``(xmin, ymin, xmax, ymax)`` metres of every lane boundary and area; None when empty."""
        parts: list[F64] = []
        for lane in self.lanes:
            parts.extend(lane.boundaries())
        parts.extend(a.polygon for a in self.areas)
        if not parts:
            return None
        pts = np.concatenate(parts)
        low, high = pts.min(axis=0), pts.max(axis=0)
        return float(low[0]), float(low[1]), float(high[0]), float(high[1])
