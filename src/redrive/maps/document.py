"""The road map as a JSON document (schema 2; schema 1 is read too): the one codec of
:class:`~redrive.types.RoadMap`.

A run stores it as ``RUN/map.json`` (:mod:`redrive.results.roadmap`); a ``redrive synth`` MCAP
carries it in a metadata record (:mod:`redrive.io.mcap.metadata`)::

    {"schema_version": 2, "frame_id": "map", "source": "synthetic:urban",
     "lanes": [{"lane_id": "west_in_0", "width_m": 3.5, "speed_limit_mps": 13.89,
                "centerline": [[x, y], ...],
                "left_boundary": null, "right_boundary": [[x, y], ...],
                "left_boundary_type": "solid", "right_boundary_type": "solid",
                "successors": ["west_east_0"], "predecessors": [],
                "left_neighbor": null, "right_neighbor": null,
                "roadblock_id": "west_in", "intersection_id": null, "kind": "vehicle"}, ...],
     "areas": [{"area_id": "intersection", "kind": "intersection", "polygon": [[x, y], ...]}],
     "roadblocks": [{"roadblock_id": "west_in", "lane_ids": [...], "successors": [...],
                     "predecessors": [...]}],
     "intersections": [{"intersection_id": "intersection", "polygon": [...], "lane_ids": [...]}],
     "crosswalks": [{"crosswalk_id": "c1", "polygon": [...]}],
     "stop_lines": [{"stop_line_id": "stop:west", "line": [...], "lane_ids": [...]}],
     "traffic_lights": [{"light_id": "0", "position": [x, y], "lane_ids": [...],
                         "stop_line_id": "stop:west"}]}

Schema 1 documents (``lanes`` with ``lane_id``, ``width_m``, ``speed_limit_mps``,
``centerline``; ``areas``) read as maps without a lane graph.  In a schema-2 document every key
but ``schema_version``, ``frame_id`` and ``lanes`` may be left out (its default then).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from redrive.errors import ConfigError
from redrive.types import (
    Crosswalk,
    DrivableArea,
    Intersection,
    MapLane,
    MapTrafficLight,
    Roadblock,
    RoadMap,
    StopLine,
)

__all__ = ["MAP_SCHEMA_VERSION", "READ_SCHEMA_VERSIONS", "road_map_from_json", "road_map_to_json"]

MAP_SCHEMA_VERSION = 2
#: the versions :func:`road_map_from_json` reads
READ_SCHEMA_VERSIONS = (1, 2)
_ADVICE = "write it again (redrive synth for a log, RunWriter.write_map for a run)"


def _as_list(points: Any) -> Any:
    return points.tolist()


def _as_array(points: Any) -> Any:
    return np.ascontiguousarray(points, dtype=np.float64)


def road_map_to_json(road_map: RoadMap, *, arrays: bool = False) -> dict[str, Any]:
    """The JSON document of ``road_map`` (plain lists and numbers, schema 2).

    Args:
        arrays: the point lists (centrelines, boundaries, polygons, lines, positions) as
            C-contiguous float64 arrays, not lists, for an encoder that writes numpy arrays
            (orjson's ``OPT_SERIALIZE_NUMPY``: the same numbers, parsed back).
    """
    pts = _as_array if arrays else _as_list

    def _line(value: Any) -> Any:
        return None if value is None else pts(value)

    return {
        "schema_version": MAP_SCHEMA_VERSION,
        "frame_id": road_map.frame_id,
        "source": road_map.source,
        "lanes": [
            {
                "lane_id": lane.lane_id,
                "width_m": lane.width_m,
                "speed_limit_mps": lane.speed_limit_mps,
                "centerline": pts(lane.centerline),
                "left_boundary": _line(lane.left_boundary),
                "right_boundary": _line(lane.right_boundary),
                "left_boundary_type": lane.left_boundary_type,
                "right_boundary_type": lane.right_boundary_type,
                "successors": list(lane.successors),
                "predecessors": list(lane.predecessors),
                "left_neighbor": lane.left_neighbor,
                "right_neighbor": lane.right_neighbor,
                "roadblock_id": lane.roadblock_id,
                "intersection_id": lane.intersection_id,
                "kind": lane.kind,
            }
            for lane in road_map.lanes
        ],
        "areas": [
            {"area_id": a.area_id, "kind": a.kind, "polygon": pts(a.polygon)}
            for a in road_map.areas
        ],
        "roadblocks": [
            {
                "roadblock_id": b.roadblock_id,
                "lane_ids": list(b.lane_ids),
                "successors": list(b.successors),
                "predecessors": list(b.predecessors),
            }
            for b in road_map.roadblocks
        ],
        "intersections": [
            {
                "intersection_id": i.intersection_id,
                "polygon": pts(i.polygon),
                "lane_ids": list(i.lane_ids),
            }
            for i in road_map.intersections
        ],
        "crosswalks": [
            {"crosswalk_id": c.crosswalk_id, "polygon": pts(c.polygon)} for c in road_map.crosswalks
        ],
        "stop_lines": [
            {"stop_line_id": s.stop_line_id, "line": pts(s.line), "lane_ids": list(s.lane_ids)}
            for s in road_map.stop_lines
        ],
        "traffic_lights": [
            {
                "light_id": t.light_id,
                "position": pts(t.position),
                "lane_ids": list(t.lane_ids),
                "stop_line_id": t.stop_line_id,
            }
            for t in road_map.traffic_lights
        ],
    }


class _DocumentError(Exception):
    """A problem of the document, before the caller's advice is added."""


def _error(path: Path, where: str, problem: str) -> _DocumentError:
    return _DocumentError(f"{path}: {where}: {problem}")


class _Reader:
    """Typed access to one document's fields, errors naming the file and the field."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def get(self, item: Any, key: str, where: str, kinds: tuple[type, ...]) -> Any:
        if not isinstance(item, dict) or key not in item:
            raise _error(self.path, where, f"'{key}' is missing")
        value = item[key]
        if not isinstance(value, kinds) or isinstance(value, bool):
            names = " or ".join(k.__name__ for k in kinds)
            raise _error(self.path, f"{where}.{key}", f"expected {names}, got {value!r:.60}")
        return value

    def optional(
        self, item: Any, key: str, where: str, kinds: tuple[type, ...], default: Any = None
    ) -> Any:
        if not isinstance(item, dict) or item.get(key) is None:
            return default
        return self.get(item, key, where, kinds)

    def ids(self, item: Any, key: str, where: str) -> tuple[str, ...]:
        values = self.optional(item, key, where, (list,), [])
        for v in values:
            if not isinstance(v, str):
                raise _error(self.path, f"{where}.{key}", f"ids must be strings, got {v!r:.60}")
        return tuple(values)

    def points(self, item: Any, key: str, where: str, *, optional: bool = False) -> Any:
        if optional and (not isinstance(item, dict) or item.get(key) is None):
            return None
        value = self.get(item, key, where, (list,))
        try:
            arr = np.array(value, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise _error(
                self.path, f"{where}.{key}", f"points must be [x, y] numbers ({err})"
            ) from err
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise _error(
                self.path, f"{where}.{key}", f"points must be [[x, y], ...], got shape {arr.shape}"
            )
        return arr

    def items(self, data: dict[str, Any], key: str) -> list[Any]:
        value = data.get(key, [])
        if not isinstance(value, list):
            raise _error(self.path, key, "expected a list")
        return value


def road_map_from_json(data: Any, *, path: Path, advice: str = _ADVICE) -> RoadMap:
    """The :class:`RoadMap` of a road-map document (schema 1 or 2) read from ``path`` (a file
    or a log).

    Raises:
        ConfigError: a field is missing or has a wrong type or value, an element names an id the
            map lacks, or the schema version is not one this redrive reads (the message names the
            file, the element and ``advice``: what to do).
    """
    try:
        return _parse(data, _Reader(path))
    except _DocumentError as err:
        msg = f"{err}; {advice}"
        raise ConfigError(msg) from err.__cause__


def _lane(r: _Reader, item: Any, where: str) -> MapLane:
    width = r.optional(item, "width_m", where, (int, float))
    if width is None:
        r.get(item, "width_m", where, (int, float))  # missing: the same error as schema 1's
    return MapLane(
        lane_id=r.get(item, "lane_id", where, (str,)),
        width_m=width,
        speed_limit_mps=r.optional(item, "speed_limit_mps", where, (int, float)),
        centerline=r.points(item, "centerline", where),
        left_boundary=r.points(item, "left_boundary", where, optional=True),
        right_boundary=r.points(item, "right_boundary", where, optional=True),
        left_boundary_type=r.optional(item, "left_boundary_type", where, (str,), "unknown"),
        right_boundary_type=r.optional(item, "right_boundary_type", where, (str,), "unknown"),
        successors=r.ids(item, "successors", where),
        predecessors=r.ids(item, "predecessors", where),
        left_neighbor=r.optional(item, "left_neighbor", where, (str,)),
        right_neighbor=r.optional(item, "right_neighbor", where, (str,)),
        roadblock_id=r.optional(item, "roadblock_id", where, (str,)),
        intersection_id=r.optional(item, "intersection_id", where, (str,)),
        kind=r.optional(item, "kind", where, (str,), "vehicle"),
    )


def _element(r: _Reader, key: str, item: Any, where: str) -> Any:
    if key == "areas":
        return DrivableArea(
            area_id=r.get(item, "area_id", where, (str,)),
            kind=r.get(item, "kind", where, (str,)),
            polygon=r.points(item, "polygon", where),
        )
    if key == "roadblocks":
        return Roadblock(
            roadblock_id=r.get(item, "roadblock_id", where, (str,)),
            lane_ids=r.ids(item, "lane_ids", where),
            successors=r.ids(item, "successors", where),
            predecessors=r.ids(item, "predecessors", where),
        )
    if key == "intersections":
        return Intersection(
            intersection_id=r.get(item, "intersection_id", where, (str,)),
            polygon=r.points(item, "polygon", where),
            lane_ids=r.ids(item, "lane_ids", where),
        )
    if key == "crosswalks":
        return Crosswalk(
            crosswalk_id=r.get(item, "crosswalk_id", where, (str,)),
            polygon=r.points(item, "polygon", where),
        )
    if key == "stop_lines":
        return StopLine(
            stop_line_id=r.get(item, "stop_line_id", where, (str,)),
            line=r.points(item, "line", where),
            lane_ids=r.ids(item, "lane_ids", where),
        )
    return MapTrafficLight(
        light_id=r.get(item, "light_id", where, (str,)),
        position=r.get(item, "position", where, (list,)),
        lane_ids=r.ids(item, "lane_ids", where),
        stop_line_id=r.optional(item, "stop_line_id", where, (str,)),
    )


_ELEMENTS = ("areas", "roadblocks", "intersections", "crosswalks", "stop_lines", "traffic_lights")


def _parse(data: Any, r: _Reader) -> RoadMap:
    if not isinstance(data, dict):
        raise _error(r.path, "document", "expected a JSON object")
    version = data.get("schema_version")
    if version not in READ_SCHEMA_VERSIONS or isinstance(version, bool):
        raise _error(
            r.path,
            "schema_version",
            f"{version!r} is not {' or '.join(map(str, READ_SCHEMA_VERSIONS))} "
            "(the versions this redrive reads)",
        )
    frame_id = r.get(data, "frame_id", "document", (str,))
    lanes_raw = r.get(data, "lanes", "document", (list,))
    lanes: list[MapLane] = []
    elements: dict[str, list[Any]] = {key: [] for key in _ELEMENTS}
    where = "document"
    try:
        for i, item in enumerate(lanes_raw):
            where = f"lanes[{i}]"
            lanes.append(_lane(r, item, where))
        for key in _ELEMENTS:
            if version == 1 and key != "areas":
                continue
            for i, item in enumerate(r.items(data, key)):
                where = f"{key}[{i}]"
                elements[key].append(_element(r, key, item, where))
        where = "document"
        return RoadMap(
            lanes=tuple(lanes),
            frame_id=frame_id,
            source=r.optional(data, "source", "document", (str,)),
            **{key: tuple(values) for key, values in elements.items()},
        )
    except ValueError as err:
        raise _error(r.path, where, str(err)) from err
