"""The road map as a JSON document (schema 1): the one codec of :class:`~redrive.types.RoadMap`.

A run stores it as ``RUN/map.json`` (:mod:`redrive.results.roadmap`); a ``redrive synth`` MCAP
carries it in a metadata record (:mod:`redrive.io.mcap.metadata`)::

    {"schema_version": 1, "frame_id": "map",
     "lanes": [{"lane_id": "entry:f0", "width_m": 3.75, "speed_limit_mps": 33.33,
                "centerline": [[x, y], ...]}, ...],
     "areas": [{"area_id": "intersection", "kind": "intersection",
                "polygon": [[x, y], ...]}, ...]}
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from redrive.errors import ConfigError
from redrive.types import DrivableArea, MapLane, RoadMap

__all__ = ["MAP_SCHEMA_VERSION", "road_map_from_json", "road_map_to_json"]

MAP_SCHEMA_VERSION = 1
_ADVICE = "write it again (redrive synth for a log, RunWriter.write_map for a run)"


def road_map_to_json(road_map: RoadMap) -> dict[str, Any]:
    """The JSON document of ``road_map`` (plain lists and numbers)."""
    return {
        "schema_version": MAP_SCHEMA_VERSION,
        "frame_id": road_map.frame_id,
        "lanes": [
            {
                "lane_id": lane.lane_id,
                "width_m": lane.width_m,
                "speed_limit_mps": lane.speed_limit_mps,
                "centerline": lane.centerline.tolist(),
            }
            for lane in road_map.lanes
        ],
        "areas": [
            {"area_id": a.area_id, "kind": a.kind, "polygon": a.polygon.tolist()}
            for a in road_map.areas
        ],
    }


class _DocumentError(Exception):
    """A problem of the document, before the caller's advice is added."""


def _error(path: Path, where: str, problem: str) -> _DocumentError:
    return _DocumentError(f"{path}: {where}: {problem}")


def _field(path: Path, item: Any, key: str, where: str, kinds: tuple[type, ...]) -> Any:
    if not isinstance(item, dict) or key not in item:
        raise _error(path, where, f"'{key}' is missing")
    value = item[key]
    if not isinstance(value, kinds) or isinstance(value, bool):
        names = " or ".join(k.__name__ for k in kinds)
        raise _error(path, f"{where}.{key}", f"expected {names}, got {value!r:.60}")
    return value


def road_map_from_json(data: Any, *, path: Path, advice: str = _ADVICE) -> RoadMap:
    """The :class:`RoadMap` of a road-map document read from ``path`` (a file or a log).

    Raises:
        ConfigError: a field is missing or has a wrong type or value, or the schema version is
            not one this redrive reads (the message names the file, the field and ``advice``:
            what to do).
    """
    try:
        return _parse(data, path)
    except _DocumentError as err:
        msg = f"{err}; {advice}"
        raise ConfigError(msg) from err.__cause__


def _parse(data: Any, path: Path) -> RoadMap:
    if not isinstance(data, dict):
        raise _error(path, "document", "expected a JSON object")
    version = data.get("schema_version")
    if version != MAP_SCHEMA_VERSION:
        raise _error(
            path,
            "schema_version",
            f"{version!r} is not {MAP_SCHEMA_VERSION} (the version this redrive reads)",
        )
    frame_id = _field(path, data, "frame_id", "document", (str,))
    lanes_raw = _field(path, data, "lanes", "document", (list,))
    areas_raw = data.get("areas", [])
    if not isinstance(areas_raw, list):
        raise _error(path, "areas", "expected a list")
    lanes: list[MapLane] = []
    areas: list[DrivableArea] = []
    try:
        for i, item in enumerate(lanes_raw):
            where = f"lanes[{i}]"
            limit = item.get("speed_limit_mps") if isinstance(item, dict) else None
            if limit is not None:
                limit = _field(path, item, "speed_limit_mps", where, (int, float))
            lanes.append(
                MapLane(
                    lane_id=_field(path, item, "lane_id", where, (str,)),
                    width_m=_field(path, item, "width_m", where, (int, float)),
                    speed_limit_mps=limit,
                    centerline=_points(
                        path, _field(path, item, "centerline", where, (list,)), where
                    ),
                )
            )
        for i, item in enumerate(areas_raw):
            where = f"areas[{i}]"
            areas.append(
                DrivableArea(
                    area_id=_field(path, item, "area_id", where, (str,)),
                    kind=_field(path, item, "kind", where, (str,)),
                    polygon=_points(path, _field(path, item, "polygon", where, (list,)), where),
                )
            )
        return RoadMap(lanes=tuple(lanes), areas=tuple(areas), frame_id=frame_id)
    except ValueError as err:
        raise _error(path, "document", str(err)) from err


def _points(path: Path, value: list[Any], where: str) -> np.ndarray[Any, np.dtype[np.float64]]:
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise _error(path, where, f"points must be [x, y] numbers ({err})") from err
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise _error(path, where, f"points must be a list of [x, y], got shape {arr.shape}")
    return arr
