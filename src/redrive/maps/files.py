"""Map files by format: which reader a file needs, the map it holds, and what ``redrive info``
says of it.

Formats: ``lanelet2`` (``*.osm``: :func:`~redrive.maps.lanelet2_osm.read_lanelet2_map`), ``av2``
(an Argoverse 2 ``log_map_archive_*.json``: :func:`~redrive.maps.av2.read_av2_map`) and
``redrive`` (a run's ``map.json``: :mod:`redrive.maps.document`).
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from redrive.errors import ConfigError, MapError
from redrive.maps.document import road_map_from_json
from redrive.types import RoadMap

__all__ = ["MAP_FORMATS", "MapSummary", "map_format", "read_map_file", "summarize_map"]

MAP_FORMATS = ("lanelet2", "av2", "redrive")


def map_format(path: str | Path) -> str | None:
    """The map format of ``path`` (one of :data:`MAP_FORMATS`), None when it is no map file
    (a log, a folder …).  JSON files are told apart by their keys."""
    file = Path(path)
    if not file.is_file():
        return None
    suffix = file.suffix.lower()
    if suffix == ".osm":
        return "lanelet2"
    if suffix != ".json":
        return None
    if file.name.startswith("log_map_archive_"):
        return "av2"
    try:
        with file.open("rb") as fh:
            head = fh.read(4096).decode("utf-8", errors="replace")
    except OSError:
        return None
    if '"lane_segments"' in head:
        return "av2"
    if '"schema_version"' in head and '"lanes"' in head:
        return "redrive"
    return None


def read_map_file(
    path: str | Path, *, origin_lat_lon: tuple[float, float] | None = None
) -> RoadMap:
    """The map in ``path``, by its :func:`map_format`.

    Args:
        origin_lat_lon: a Lanelet2 map's projection origin (see
            :func:`~redrive.maps.lanelet2_osm.read_lanelet2_map`); ignored by the other formats.

    Raises:
        MapError: not a map file redrive reads, or the map's own reader refuses it.
    """
    file = Path(path)
    fmt = map_format(file)
    if fmt == "lanelet2":
        from redrive.maps.lanelet2_osm import read_lanelet2_map

        return read_lanelet2_map(file, origin_lat_lon=origin_lat_lon)
    if fmt == "av2":
        from redrive.maps.av2 import read_av2_map  # shapely: imported when a map is read

        return read_av2_map(file)
    if fmt == "redrive":
        try:
            data = json.loads(file.read_text(encoding="utf-8"))
            return road_map_from_json(data, path=file, advice="write it again")
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, ConfigError) as err:
            msg = f"{file}: not a readable redrive map ({err})"
            raise MapError(msg) from err
    msg = (
        f"{file}: not a map file redrive reads (Lanelet2 .osm, Argoverse 2 log_map_archive_*.json"
        ", a run's map.json)"
    )
    raise MapError(msg)


@dataclass(frozen=True, slots=True, kw_only=True)
class MapSummary:
    """What a map holds (``redrive info MAPFILE``).

    Attributes:
        path, format: the file and its :func:`map_format`.
        source: the map's ``source``; frame_id its frame.
        extent: ``(xmin, ymin, xmax, ymax)`` metres, None for an empty map.
        lanes: lane count; lane_kinds: count per kind; lane_length_m: their centrelines' sum.
        roadblocks, intersections, areas, crosswalks, stop_lines, traffic_lights: counts.
        with_successors, with_neighbors: lanes that have a successor / a left or right neighbour.
    """

    path: str
    format: str
    source: str | None
    frame_id: str
    extent: tuple[float, float, float, float] | None
    lanes: int
    lane_kinds: dict[str, int]
    lane_length_m: float
    roadblocks: int
    intersections: int
    areas: int
    crosswalks: int
    stop_lines: int
    traffic_lights: int
    with_successors: int
    with_neighbors: int

    def to_json(self) -> dict[str, Any]:
        return {
            "path": self.path,
            "format": self.format,
            "source": self.source,
            "frame_id": self.frame_id,
            "extent_m": None if self.extent is None else list(self.extent),
            "lanes": self.lanes,
            "lane_kinds": dict(self.lane_kinds),
            "lane_length_m": self.lane_length_m,
            "roadblocks": self.roadblocks,
            "intersections": self.intersections,
            "areas": self.areas,
            "crosswalks": self.crosswalks,
            "stop_lines": self.stop_lines,
            "traffic_lights": self.traffic_lights,
            "lanes_with_successors": self.with_successors,
            "lanes_with_neighbors": self.with_neighbors,
        }


def summarize_map(road_map: RoadMap, *, path: str | Path, fmt: str) -> MapSummary:
    """The :class:`MapSummary` of ``road_map`` read from ``path`` in format ``fmt``."""
    lanes = road_map.lanes
    return MapSummary(
        path=str(path),
        format=fmt,
        source=road_map.source,
        frame_id=road_map.frame_id,
        extent=road_map.extent(),
        lanes=len(lanes),
        lane_kinds=dict(Counter(lane.kind for lane in lanes).most_common()),
        lane_length_m=float(sum(lane.length_m for lane in lanes)),
        roadblocks=len(road_map.roadblocks),
        intersections=len(road_map.intersections),
        areas=len(road_map.areas),
        crosswalks=len(road_map.crosswalks),
        stop_lines=len(road_map.stop_lines),
        traffic_lights=len(road_map.traffic_lights),
        with_successors=sum(1 for lane in lanes if lane.successors),
        with_neighbors=sum(
            1 for lane in lanes if lane.left_neighbor is not None or lane.right_neighbor is not None
        ),
    )
