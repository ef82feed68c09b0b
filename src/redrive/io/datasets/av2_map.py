"""An Argoverse 2 vector map (``map/log_map_archive_*.json``) in redrive's road-map model.

The schema is av2-api's (``map/map_api.py``, ``ArgoverseStaticMap.from_json``): ``lane_segments``
(id → left/right boundary polylines of ``{x, y, z}`` points, mark types, ``successors``,
``predecessors``, ``left_neighbor_id`` / ``right_neighbor_id``, ``lane_type``,
``is_intersection``), ``drivable_areas`` (``area_boundary``) and ``pedestrian_crossings``
(``edge1``, ``edge2``).  Coordinates are the city frame, which is redrive's ``map``.

A lane's centreline is av2-api's: ``get_lane_segment_centerline`` → ``compute_midpoint_line``
(``geometry/interpolate.py``): both boundaries resampled at 10 points equally spaced along their
chordal length (``interp_arc``), averaged; its width is ``compute_lane_width``, the mean distance
between the resampled points.  (A boundary of one point — a cul-de-sac — is refused: av2-api
pivots an arc around it, which no map of the sensor dataset needs.)

The rest of the lane graph: the boundaries as given (``left_boundary`` / ``right_boundary``);
their types from the mark types (:func:`boundary_type`: the paint nearest the lane of a double
line — ``DASH_SOLID_*`` is dashed on its left, solid on its right); ``successors`` /
``predecessors`` (ids outside this log's cropped map dropped); ``left_neighbor`` /
``right_neighbor`` when the neighbour runs the same way (AV2's neighbours may be of the opposite
direction; the model's are not); ``lane_type`` VEHICLE / BIKE / BUS as ``kind``;
``is_intersection`` lanes are grouped into no :class:`Intersection` (AV2 has no intersection
outlines) but keep their place in the graph.  Drivable areas are ``drivable`` polygons, pedestrian
crossings :class:`Crosswalk` polygons (``edge1[0], edge1[1], edge2[1], edge2[0]``, av2-api's
``PedestrianCrossing.polygon``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import LogError
from redrive.types import Crosswalk, DrivableArea, MapLane, RoadMap

__all__ = [
    "NUM_CENTERLINE_POINTS",
    "boundary_type",
    "interp_arc",
    "read_av2_map",
    "read_map_json",
    "road_map_from_av2",
]

#: av2-api's NUM_CENTERLINE_INTERP_PTS
NUM_CENTERLINE_POINTS = 10


def interp_arc(count: int, points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``count`` points equally spaced along the polyline ``points`` (N, D) by chordal length
    (av2-api ``interp_arc``; consecutive duplicate points are dropped first)."""
    keep = np.ones(len(points), dtype=bool)
    keep[1:] = np.any(np.diff(points, axis=0) != 0, axis=1)
    pts = points[keep]
    n = len(pts)
    if n < 2:
        return np.repeat(pts[:1], count, axis=0)
    chord = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    chord = chord / chord.sum()
    cumarc = np.zeros(n)
    cumarc[1:] = np.cumsum(chord)
    targets = np.linspace(0.0, 1.0, count)
    bins = np.digitize(targets, bins=cumarc).astype(int)
    bins[(bins <= 0) | (targets <= 0)] = 1
    bins[(bins >= n) | (targets >= 1)] = n - 1
    s = (targets - cumarc[bins - 1]) / chord[bins - 1]
    out: npt.NDArray[np.float64] = pts[bins - 1] + (pts[bins] - pts[bins - 1]) * s[:, None]
    return out


def boundary_type(mark: str, *, lane_side: str) -> str:
    """The :data:`~redrive.types.roadmap.BOUNDARY_TYPES` word of an AV2 ``LaneMarkType`` seen
    from a lane on ``lane_side`` ("left" or "right") of the marking: a double marking's two
    paints are named left first, and the lane sees the nearer one (a lane's left boundary has
    the lane on its right)."""
    mark = str(mark).upper()
    if mark == "NONE":
        return "virtual"
    parts = mark.split("_")
    paint = parts[:2] if parts[0] in ("DASH", "SOLID") and len(parts) > 2 else parts[:1]
    if parts[0] == "DOUBLE":
        paint = [parts[1]]
    if len(paint) == 2:  # DASH_SOLID_x / SOLID_DASH_x: left paint, right paint
        paint = [paint[1] if lane_side == "right" else paint[0]]
    word = paint[0]
    if word == "SOLID":
        return "solid"
    if word in ("DASH", "DASHED"):
        return "dashed"
    return "unknown"


def _polyline(raw: Any, *, where: str) -> npt.NDArray[np.float64]:
    try:
        out = np.array([[float(p["x"]), float(p["y"])] for p in raw], dtype=np.float64)
    except (TypeError, KeyError, ValueError) as err:
        msg = f"{where}: not a list of {{x, y, z}} points ({err!r})"
        raise LogError(msg) from err
    if out.ndim != 2 or not np.all(np.isfinite(out)):
        msg = f"{where}: points are missing or not finite"
        raise LogError(msg)
    return out


def road_map_from_av2(doc: dict[str, Any], *, source: str) -> RoadMap:
    """The road map of a parsed AV2 map archive (``source`` names it in errors).

    Raises:
        LogError: a lane segment or area lacks a field or has too few points (named by id).
    """
    segments = doc.get("lane_segments")
    if not isinstance(segments, dict):
        msg = f"{source}: no lane_segments object; not an Argoverse 2 map archive"
        raise LogError(msg)
    built: dict[str, dict[str, Any]] = {}
    for key, seg in segments.items():
        where = f"{source}: lane segment {key}"
        if not isinstance(seg, dict):
            msg = f"{where}: not an object"
            raise LogError(msg)
        for name in ("left_lane_boundary", "right_lane_boundary"):
            if name not in seg:
                msg = f"{where}: no {name}; the map is incomplete, restore it"
                raise LogError(msg)
        left = _polyline(seg["left_lane_boundary"], where=f"{where} left_lane_boundary")
        right = _polyline(seg["right_lane_boundary"], where=f"{where} right_lane_boundary")
        if len(left) < 2 or len(right) < 2:
            msg = f"{where}: a boundary has {min(len(left), len(right))} point(s), needs >= 2"
            raise LogError(msg)
        left_even = interp_arc(NUM_CENTERLINE_POINTS, left)
        right_even = interp_arc(NUM_CENTERLINE_POINTS, right)
        width = float(np.linalg.norm(left_even - right_even, axis=1).mean())
        if not width > 0:
            msg = f"{where}: its boundaries coincide (width 0)"
            raise LogError(msg)
        built[str(seg.get("id", key))] = {
            "seg": seg,
            "centerline": (left_even + right_even) / 2.0,
            "width_m": width,
            "left": left,
            "right": right,
        }
    lanes = [_lane(lane_id, b, built) for lane_id, b in built.items()]
    areas = []
    for key, area in (doc.get("drivable_areas") or {}).items():
        where = f"{source}: drivable area {key}"
        poly = _polyline(area.get("area_boundary"), where=f"{where} area_boundary")
        if len(poly) > 3 and np.array_equal(poly[0], poly[-1]):
            poly = poly[:-1]
        if len(poly) < 3:
            msg = f"{where}: {len(poly)} vertices, needs >= 3"
            raise LogError(msg)
        areas.append(DrivableArea(area_id=str(area.get("id", key)), polygon=poly, kind="drivable"))
    crosswalks = []
    for key, crossing in (doc.get("pedestrian_crossings") or {}).items():
        where = f"{source}: pedestrian crossing {key}"
        edge1 = _polyline(crossing.get("edge1"), where=f"{where} edge1")
        edge2 = _polyline(crossing.get("edge2"), where=f"{where} edge2")
        if len(edge1) != 2 or len(edge2) != 2:
            msg = f"{where}: each edge needs 2 points, got {len(edge1)} and {len(edge2)}"
            raise LogError(msg)
        polygon = np.array([edge1[0], edge1[1], edge2[1], edge2[0]])
        crosswalks.append(Crosswalk(crosswalk_id=str(crossing.get("id", key)), polygon=polygon))
    return RoadMap(
        lanes=tuple(lanes),
        areas=tuple(areas),
        crosswalks=tuple(crosswalks),
        source=f"av2:{source}",
    )


_KIND = {"VEHICLE": "vehicle", "BIKE": "bike", "BUS": "bus"}


def _direction(line: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    d: npt.NDArray[np.float64] = line[-1] - line[0]
    n = float(np.hypot(*d))
    return d / n if n > 0 else d


def _lane(lane_id: str, b: dict[str, Any], built: dict[str, dict[str, Any]]) -> MapLane:
    seg = b["seg"]
    here = _direction(b["centerline"])

    def neighbour(key: str) -> str | None:
        ref = seg.get(key)
        if ref is None or str(ref) not in built:
            return None
        there = _direction(built[str(ref)]["centerline"])
        return str(ref) if float(here @ there) > 0 else None

    return MapLane(
        lane_id=lane_id,
        centerline=b["centerline"],
        width_m=b["width_m"],
        left_boundary=b["left"],
        right_boundary=b["right"],
        left_boundary_type=boundary_type(
            seg.get("left_lane_mark_type", "UNKNOWN"), lane_side="right"
        ),
        right_boundary_type=boundary_type(
            seg.get("right_lane_mark_type", "UNKNOWN"), lane_side="left"
        ),
        successors=tuple(str(i) for i in seg.get("successors") or () if str(i) in built),
        predecessors=tuple(str(i) for i in seg.get("predecessors") or () if str(i) in built),
        left_neighbor=neighbour("left_neighbor_id"),
        right_neighbor=neighbour("right_neighbor_id"),
        kind=_KIND.get(
            str(seg.get("lane_type", "VEHICLE")).upper(), str(seg.get("lane_type")).lower()
        ),
    )


def read_av2_map(path: Path) -> RoadMap:
    """The road map of an AV2 map archive file.

    Raises:
        LogError: unreadable, not JSON (the byte offset is named), or an element is malformed.
    """
    return road_map_from_av2(read_map_json(path), source=str(path))


def read_map_json(path: Path) -> dict[str, Any]:
    """An AV2 map archive as JSON.

    Raises:
        LogError: unreadable or not JSON (with the byte offset of the error).
    """
    try:
        text = path.read_bytes()
    except OSError as err:
        msg = f"{path}: cannot read the map ({err.strerror}); restore it"
        raise LogError(msg) from err
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as err:
        msg = (
            f"{path}: the map is not JSON at byte {err.pos} of {len(text)} ({err.msg}); it is "
            "cut off or damaged, restore it"
        )
        raise LogError(msg) from err
    except UnicodeDecodeError as err:
        msg = f"{path}: the map is not UTF-8 JSON at byte {err.start}; restore it"
        raise LogError(msg) from err
    if not isinstance(doc, dict):
        msg = f"{path}: the map must be a JSON object (lane_segments, drivable_areas, …)"
        raise LogError(msg)
    return doc
