"""A run's road map as shapes: lane surfaces, boundaries by type, centrelines, crosswalks, drivable
areas, intersections and stop lines — topic ``/redrive/map``, in the map's frame.

The map does not change over a run: the export writes it once, at the first frame's stamp (a
viewer that seeks later is given the topic's latest message before the seek point, as Foxglove
and Lichtblick do). Light *states* change: :mod:`.light_shapes` draws them per frame.

=====================  ==========================================================================
element                drawn as
=====================  ==========================================================================
lane                   its surface: the polygon between its boundaries, triangulated; cars'
                       lanes dark grey, bike lanes green, bus lanes red (translucent)
lane boundary          a line coloured by type: ``solid`` white, ``dashed`` light grey (thin),
                       ``road_edge`` orange (wide), ``virtual`` faint, ``unknown`` grey
centreline             a thin blue line (the direction of travel is its point order)
crosswalk              white translucent triangles (its polygon triangulated) and its outline
drivable area          grey translucent triangles (car parks, intersection squares …)
intersection           its outline, yellow
stop line              a wide white line
=====================  ==========================================================================
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import numpy.typing as npt

from redrive.interop.shapes import Color, LineShape, ShapeSet, TriangleShape
from redrive.types import MapLane, RoadMap

__all__ = ["BOUNDARY_COLORS", "MAP_TOPIC", "lane_triangles", "map_shapes", "polygon_triangles"]

MAP_TOPIC = "/redrive/map"
F64 = npt.NDArray[np.float64]
Point = tuple[float, float, float]

BOUNDARY_COLORS: Mapping[str, Color] = {
    "solid": (0.95, 0.95, 0.95, 0.95),
    "dashed": (0.75, 0.75, 0.75, 0.70),
    "road_edge": (1.00, 0.55, 0.10, 0.95),
    "virtual": (0.60, 0.60, 0.60, 0.20),
    "unknown": (0.60, 0.60, 0.60, 0.60),
}
_BOUNDARY_WIDTH_M = {"solid": 0.15, "dashed": 0.10, "road_edge": 0.30, "virtual": 0.05}
_LANE_FILL: Mapping[str, Color] = {
    "vehicle": (0.30, 0.30, 0.35, 0.45),
    "bike": (0.20, 0.60, 0.30, 0.45),
    "bus": (0.70, 0.20, 0.20, 0.45),
}
_OTHER_FILL: Color = (0.40, 0.40, 0.40, 0.45)
_CENTRE: Color = (0.30, 0.60, 1.00, 0.60)
_CROSSWALK: Color = (0.95, 0.95, 0.95, 0.40)
_AREA: Color = (0.45, 0.45, 0.45, 0.30)
_INTERSECTION: Color = (1.00, 0.85, 0.20, 0.60)
_STOP: Color = (1.00, 1.00, 1.00, 0.95)


def _resample(line: F64, count: int) -> F64:
    """``count`` points equally spaced in arclength along ``line``."""
    step = np.hypot(*np.diff(line, axis=0).T)
    arc = np.concatenate([[0.0], np.cumsum(step)])
    if arc[-1] <= 0.0:
        return np.repeat(line[:1], count, axis=0)
    at = np.linspace(0.0, arc[-1], count)
    return np.column_stack([np.interp(at, arc, line[:, 0]), np.interp(at, arc, line[:, 1])])


def lane_triangles(lane: MapLane, *, z_m: float = 0.0) -> tuple[Point, ...]:
    """The lane's surface as triangles (three points each): the polygon between its boundaries
    (the index's lane polygon) triangulated; when that polygon is not simple (boundaries that
    cross), the boundaries resampled to as many points as the longer has, each quad between
    them split in two."""
    left, right = lane.boundaries()
    import shapely

    shape = shapely.Polygon(np.vstack([left, right[::-1]]))
    if shape.is_valid and shape.area > 0.0:
        return polygon_triangles(np.asarray(shape.exterior.coords)[:-1], z_m=z_m)
    count = max(len(left), len(right), 2)
    a, b = _resample(np.asarray(left), count), _resample(np.asarray(right), count)
    out: list[Point] = []
    for i in range(count - 1):
        l0, l1, r0, r1 = a[i], a[i + 1], b[i], b[i + 1]
        for p, q, r in ((l0, r0, l1), (l1, r0, r1)):
            out += [(float(p[0]), float(p[1]), z_m), (float(q[0]), float(q[1]), z_m)]
            out.append((float(r[0]), float(r[1]), z_m))
    return tuple(out)


def polygon_triangles(polygon: F64, *, z_m: float = 0.0) -> tuple[Point, ...]:
    """A simple polygon's triangles (a constrained Delaunay triangulation, shapely ≥ 2.1);
    ``()`` for a degenerate one."""
    import shapely

    shape = shapely.Polygon(np.asarray(polygon, dtype=np.float64))
    if not shape.is_valid:
        shape = shape.buffer(0.0)
    if shape.is_empty or shape.area <= 0.0:
        return ()
    out: list[Point] = []
    for tri in shapely.get_parts(shapely.constrained_delaunay_triangles(shape)):
        ring = np.asarray(tri.exterior.coords)[:3]
        out += [(float(x), float(y), z_m) for x, y in ring]
    return tuple(out)


def _line(ident: str, points: F64, color: Color, width_m: float, z_m: float) -> LineShape:
    return LineShape(
        id=ident,
        points=tuple((float(x), float(y), z_m) for x, y in np.asarray(points).tolist()),
        color=color,
        width_m=width_m,
    )


def _ring(points: F64) -> F64:
    ring = np.asarray(points, dtype=np.float64)
    return np.vstack([ring, ring[:1]])


def map_shapes(road_map: RoadMap, *, stamp_ns: int) -> ShapeSet:
    """Everything of ``road_map`` the map topic shows (the table of the module text)."""
    lines: list[LineShape] = []
    triangles: list[TriangleShape] = []
    for lane in road_map.lanes:
        fill = _LANE_FILL.get(lane.kind, _OTHER_FILL)
        triangles.append(
            TriangleShape(id=f"lane/{lane.lane_id}", points=lane_triangles(lane), color=fill)
        )
        left, right = lane.boundaries()
        for side, bound, kind in (
            ("left", left, lane.left_boundary_type),
            ("right", right, lane.right_boundary_type),
        ):
            color = BOUNDARY_COLORS.get(kind, BOUNDARY_COLORS["unknown"])
            width = _BOUNDARY_WIDTH_M.get(kind, 0.08)
            lines.append(_line(f"lane/{lane.lane_id}/{side}", bound, color, width, 0.03))
        lines.append(_line(f"lane/{lane.lane_id}/centre", lane.centerline, _CENTRE, 0.06, 0.02))
    for area in road_map.areas:
        triangles.append(
            TriangleShape(
                id=f"area/{area.area_id}", points=polygon_triangles(area.polygon), color=_AREA
            )
        )
    for walk in road_map.crosswalks:
        ident = f"crosswalk/{walk.crosswalk_id}"
        triangles.append(
            TriangleShape(
                id=ident, points=polygon_triangles(walk.polygon, z_m=0.04), color=_CROSSWALK
            )
        )
        lines.append(_line(f"{ident}/outline", _ring(walk.polygon), _STOP, 0.10, 0.05))
    for inter in road_map.intersections:
        outline = _ring(inter.polygon)
        lines.append(
            _line(f"intersection/{inter.intersection_id}", outline, _INTERSECTION, 0.15, 0.05)
        )
    for stop in road_map.stop_lines:
        lines.append(_line(f"stop_line/{stop.stop_line_id}", stop.line, _STOP, 0.40, 0.06))
    return ShapeSet(
        stamp_ns=stamp_ns,
        frame_id=road_map.frame_id,
        lines=tuple(lines),
        triangles=tuple(t for t in triangles if t.points),
    )
