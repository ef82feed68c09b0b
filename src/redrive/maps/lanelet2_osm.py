"""Lanelet2 maps (OSM XML) as a :class:`~redrive.types.RoadMap`, read through the ``lanelet2``
wheel (a dependency of redrive).

The map is loaded with ``lanelet2.io.loadRobust`` and a ``UtmProjector``: x, y are metres east and
north of the projection origin (a transverse-Mercator projection about it, the Lanelet2
tutorial's ``UtmProjector(Origin(lat, lon))``).  The origin is the caller's (``origin_lat_lon``)
or, for Autoware maps whose nodes carry ``local_x`` / ``local_y`` tags, the map's own frame: the
projection is then shifted onto those coordinates.  A Lanelet2 map without either carries its
origin nowhere, and :func:`read_lanelet2_map` says so.

What becomes what (Lanelet2's tagging specification, ``lanelet2_core/doc/LaneletAndAreaTagging.md``;
its traffic rules and routing graph, ``lanelet2_traffic_rules``, ``lanelet2_routing``):

- every lanelet a vehicle may pass (the ``traffic_rules`` of ``location``, participant
  ``vehicle``) becomes a lane, once per direction it may be driven in (id ``"<lanelet id>"``;
  against its own direction ``"<lanelet id>:inv"``); the lanelet's bounds are the lane's
  boundaries and its centreline Lanelet2's ``centerline``; ``bus_lane`` lanelets have kind
  ``bus``; lanelets only a bicycle may pass become lanes of kind ``bike``;
- successors, predecessors and neighbours come from the routing graph of that participant
  (``following``, ``previous``, ``left`` / ``adjacentLeft``, ``right`` / ``adjacentRight``);
  roadblocks are the rows of mutually neighbouring lanes, id ``"rb:<lane id>"`` of their
  leftmost lane (:func:`redrive.maps.graph.group_roadblocks`);
- speed limits are the traffic rules' ``speedLimit`` (km/h in the Python API, m/s here);
- boundary types: ``line_thin`` / ``line_thick`` ``dashed`` → dashed, ``solid`` and
  ``solid_solid`` → solid, ``solid_dashed`` / ``dashed_solid`` → the half on the lane's side;
  ``curbstone``, ``road_border``, ``guard_rail``, ``wall``, ``fence`` → road_edge; ``virtual`` →
  virtual; other types → unknown;
- ``crosswalk`` lanelets become crosswalks; ``parking`` and ``freespace`` areas drivable areas
  (their outer bound; kinds ``carpark``, ``freespace``); walkways, rails and other areas are left
  out;
- linestrings of type ``stop_line`` and every regulatory element's ``ref_line`` become stop lines
  (controlling the lanes whose lanelet holds that element); each ``traffic_light`` regulatory
  element becomes a traffic light (id ``str(element id)``, position the mean of its light
  bulbs' points, the lanes whose lanelet holds it, its stop line).

Lanelet2 has no intersection element: the map's intersections are empty.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import MapError
from redrive.maps.graph import group_roadblocks
from redrive.types import (
    Crosswalk,
    DrivableArea,
    MapLane,
    MapTrafficLight,
    RoadMap,
    StopLine,
)

__all__ = ["first_node", "read_lanelet2_map"]

F64 = npt.NDArray[np.float64]
_EDGE_TYPES = frozenset({"curbstone", "road_border", "guard_rail", "wall", "fence"})
_AREA_KINDS = {"parking": "carpark", "freespace": "freespace"}
_INSTALL = "install the Lanelet2 wheel: pip install lanelet2 (redrive depends on it)"


def _attr(attributes: Any, key: str, default: str) -> str:
    """``attributes[key]`` of a Lanelet2 AttributeMap (which has no ``get``), else ``default``."""
    return str(attributes[key]) if key in attributes else default


def first_node(path: str | Path) -> tuple[float, float, dict[str, str]]:
    """Lat, lon and tags of the OSM file's first node (an XML error: MapError): the origin
    ``redrive info`` falls back on when the map has none."""
    path = Path(path)
    try:
        for _, elem in ET.iterparse(path, events=("end",)):
            if elem.tag == "node":
                tags = {t.get("k", ""): t.get("v", "") for t in elem.findall("tag")}
                return float(elem.get("lat", "nan")), float(elem.get("lon", "nan")), tags
    except (ET.ParseError, ValueError) as err:
        msg = f"{path}: not a readable Lanelet2 OSM file ({err}); is the file complete?"
        raise MapError(msg) from err
    msg = f"{path}: the OSM file has no node; a Lanelet2 map has its points as nodes"
    raise MapError(msg)


class _Reader:
    def __init__(self, path: Path, lanelet_map: Any, offset: F64, location: str) -> None:
        import lanelet2.traffic_rules as rules
        from lanelet2 import routing

        self.path = path
        self.map = lanelet_map
        self.offset = offset
        self.rules = {
            "vehicle": rules.create(location, rules.Participants.Vehicle),
            "bike": rules.create(location, rules.Participants.Bicycle),
        }
        self.graphs = {k: routing.RoutingGraph(lanelet_map, r) for k, r in self.rules.items()}
        self.lanes: dict[str, MapLane] = {}
        self.group: dict[str, str] = {}  # lane id -> "vehicle" / "bike"
        self.stop_lines: dict[str, StopLine] = {}

    def xy(self, points: Iterable[Any]) -> F64:
        pts = np.array([[p.x, p.y] for p in points], dtype=np.float64).reshape(-1, 2)
        return pts + self.offset

    @staticmethod
    def lane_id(lanelet: Any) -> str:
        return f"{lanelet.id}:inv" if lanelet.inverted() else str(lanelet.id)

    def boundary_type(self, bound: Any, *, left: bool) -> str:
        attrs = bound.attributes
        kind = _attr(attrs, "type", "")
        subtype = _attr(attrs, "subtype", "")
        if kind in _EDGE_TYPES:
            return "road_edge"
        if kind == "virtual":
            return "virtual"
        if kind not in ("line_thin", "line_thick"):
            return "unknown"
        if subtype in ("solid_dashed", "dashed_solid"):
            # the half of the marking on the lane's side: a left bound running along the lane
            # has the lane on its right (the second word), an inverted one on its left
            lane_on_right = left != bool(bound.inverted())
            words = subtype.split("_")
            return words[1] if lane_on_right else words[0]
        return {"dashed": "dashed", "solid": "solid", "solid_solid": "solid"}.get(
            subtype, "unknown"
        )

    def variants(self) -> list[tuple[Any, str]]:
        """(directed lanelet, group) of every lane to build, in map order."""
        out: list[tuple[Any, str]] = []
        for lanelet in self.map.laneletLayer:
            attrs = lanelet.attributes
            subtype = _attr(attrs, "subtype", "road")
            if subtype == "crosswalk":
                continue
            for directed in (lanelet, lanelet.invert()):
                if self.rules["vehicle"].canPass(directed):
                    out.append((directed, "vehicle"))
                elif self.rules["bike"].canPass(directed) and subtype == "bicycle_lane":
                    out.append((directed, "bike"))
        return out

    def build_lanes(self) -> None:
        variants = self.variants()
        ids = {self.lane_id(d) for d, _ in variants}
        for directed, group in variants:
            lane_id = self.lane_id(directed)
            graph = self.graphs[group]
            subtype = _attr(directed.attributes, "subtype", "")

            def known(lanelets: Iterable[Any], ids: set[str] = ids) -> tuple[str, ...]:
                return tuple(i for i in map(self.lane_id, lanelets) if i in ids)

            left = graph.left(directed) or graph.adjacentLeft(directed)
            right = graph.right(directed) or graph.adjacentRight(directed)
            limit = self.rules[group].speedLimit(directed).speedLimit  # km/h (the Python API)
            try:
                lane = MapLane(
                    lane_id=lane_id,
                    centerline=self.xy(directed.centerline),
                    width_m=None,
                    speed_limit_mps=float(limit) / 3.6 if limit > 0 else None,
                    left_boundary=self.xy(directed.leftBound),
                    right_boundary=self.xy(directed.rightBound),
                    left_boundary_type=self.boundary_type(directed.leftBound, left=True),
                    right_boundary_type=self.boundary_type(directed.rightBound, left=False),
                    successors=known(graph.following(directed)),
                    predecessors=known(graph.previous(directed)),
                    left_neighbor=(known([left]) or (None,))[0] if left is not None else None,
                    right_neighbor=(known([right]) or (None,))[0] if right is not None else None,
                    kind="bike"
                    if group == "bike"
                    else "bus"
                    if subtype == "bus_lane"
                    else "vehicle",
                )
            except ValueError as err:
                msg = f"{self.path}: lanelet {directed.id}: {err}; fix the lanelet's bounds"
                raise MapError(msg) from err
            self.lanes[lane_id] = lane
            self.group[lane_id] = group

    def lanes_by_element(self) -> dict[int, tuple[str, ...]]:
        """Regulatory element id → the lanes whose lanelet holds it (one pass over the lanes)."""
        out: dict[int, list[str]] = {}
        for lane_id in self.lanes:
            lanelet = self.map.laneletLayer[int(lane_id.split(":")[0])]
            for element in lanelet.regulatoryElements:
                out.setdefault(element.id, []).append(lane_id)
        return {k: tuple(v) for k, v in out.items()}

    def stop_line(self, line: Any, lane_ids: tuple[str, ...]) -> str:
        stop_id = str(line.id)
        have = self.stop_lines.get(stop_id)
        joined = tuple(dict.fromkeys((*(have.lane_ids if have else ()), *lane_ids)))
        self.stop_lines[stop_id] = StopLine(
            stop_line_id=stop_id, line=self.xy(line), lane_ids=joined
        )
        return stop_id

    def regulatory(self) -> tuple[MapTrafficLight, ...]:
        lights = []
        for line in self.map.lineStringLayer:
            if "type" in line.attributes and line.attributes["type"] == "stop_line":
                self.stop_line(line, ())
        holding = self.lanes_by_element()
        for element in self.map.regulatoryElementLayer:
            params = element.parameters
            refs = list(params["ref_line"]) if "ref_line" in params else []
            lanes = holding.get(element.id, ())
            stop_ids = [self.stop_line(ref, lanes) for ref in refs if len(ref) >= 2]
            if type(element).__name__ != "TrafficLight":
                continue
            bulbs = [p for light in element.trafficLights for p in light]
            if not bulbs:
                msg = f"{self.path}: traffic light {element.id} has no light (no 'refers' member)"
                raise MapError(msg)
            lights.append(
                MapTrafficLight(
                    light_id=str(element.id),
                    position=self.xy(bulbs).mean(axis=0),
                    lane_ids=lanes,
                    stop_line_id=stop_ids[0] if stop_ids else None,
                )
            )
        return tuple(lights)

    def crosswalks_and_areas(self) -> tuple[tuple[Crosswalk, ...], tuple[DrivableArea, ...]]:
        crosswalks = []
        for lanelet in self.map.laneletLayer:
            attrs = lanelet.attributes
            if "subtype" in attrs and attrs["subtype"] == "crosswalk":
                poly = self.xy(lanelet.polygon2d())
                crosswalks.append(Crosswalk(crosswalk_id=str(lanelet.id), polygon=poly))
        areas = []
        for area in self.map.areaLayer:
            subtype = _attr(area.attributes, "subtype", "")
            if subtype in _AREA_KINDS:
                ring = self.xy(area.outerBoundPolygon())
                areas.append(
                    DrivableArea(area_id=str(area.id), polygon=ring, kind=_AREA_KINDS[subtype])
                )
        return tuple(crosswalks), tuple(areas)


def read_lanelet2_map(
    path: str | Path,
    *,
    origin_lat_lon: tuple[float, float] | None = None,
    location: str = "de",
) -> RoadMap:
    """The :class:`RoadMap` of the Lanelet2 map ``path`` (see the module doc for what becomes
    what).

    Args:
        origin_lat_lon: the projection origin, degrees; None: the map's own ``local_x`` /
            ``local_y`` node coordinates (Autoware maps), else a MapError.
        location: the traffic rules' location (``lanelet2.traffic_rules.Locations``: ``de``).

    Raises:
        MapError: the file is missing, cut or not Lanelet2 OSM; Lanelet2 reports an invalid
            element (the message names it: a lanelet without a left or right bound …); the
            projection origin is unknown; the ``lanelet2`` wheel is not installed.
    """
    try:
        import lanelet2
        from lanelet2.io import Origin
        from lanelet2.projection import UtmProjector
    except ImportError as err:
        msg = f"reading the Lanelet2 map {path} needs the lanelet2 package; {_INSTALL}"
        raise MapError(msg) from err
    file = Path(path)
    if not file.is_file():
        msg = f"{file}: no such Lanelet2 map file"
        raise MapError(msg)
    lat, lon, tags = first_node(file)
    local = "local_x" in tags and "local_y" in tags
    if origin_lat_lon is None and not local:
        msg = (
            f"{file}: the Lanelet2 map carries no projection origin (its nodes have lat/lon but "
            "no local_x/local_y); give the origin as latitude, longitude (origin_lat_lon=(49.0, "
            "8.4) / --map-origin 49.0,8.4)"
        )
        raise MapError(msg)
    origin = origin_lat_lon if origin_lat_lon is not None else (lat, lon)
    try:
        projector = UtmProjector(Origin(float(origin[0]), float(origin[1])))
        lanelet_map, errors = lanelet2.io.loadRobust(str(file), projector)
    except RuntimeError as err:
        msg = f"{file}: Lanelet2 cannot read the map ({err}); is the file complete?"
        raise MapError(msg) from err
    problems = [e.strip().lstrip("- ") for e in errors if e.strip() and not e.strip().endswith(":")]
    if problems:
        shown = "; ".join(problems[:5]) + (
            f" (+{len(problems) - 5} more)" if len(problems) > 5 else ""
        )
        msg = f"{file}: invalid Lanelet2 elements: {shown}; fix them in the map (JOSM)"
        raise MapError(msg)
    offset = np.zeros(2)
    if origin_lat_lon is None:
        offset = _local_offset(file, lanelet_map)
    reader = _Reader(file, lanelet_map, offset, location)
    reader.build_lanes()
    reader.lanes, roadblocks = group_roadblocks(reader.lanes)
    lights = reader.regulatory()
    crosswalks, areas = reader.crosswalks_and_areas()
    where = (
        f"origin lat {origin[0]}, lon {origin[1]}"
        if origin_lat_lon is not None
        else "the map's local_x/local_y"
    )
    try:
        return RoadMap(
            lanes=tuple(reader.lanes.values()),
            areas=areas,
            roadblocks=roadblocks,
            crosswalks=crosswalks,
            stop_lines=tuple(reader.stop_lines.values()),
            traffic_lights=lights,
            source=f"lanelet2:{file} ({where})",
        )
    except ValueError as err:
        msg = f"{file}: {err}"
        raise MapError(msg) from err


def _local_offset(path: Path, lanelet_map: Any) -> F64:
    """The shift from the projection onto the nodes' ``local_x`` / ``local_y`` (one for all:
    the two must differ by a translation, within 0.5 m)."""
    shifts = []
    for point in lanelet_map.pointLayer:
        attrs = point.attributes
        if "local_x" in attrs and "local_y" in attrs:
            try:
                local = (float(attrs["local_x"]), float(attrs["local_y"]))
            except ValueError as err:
                msg = f"{path}: node {point.id}: local_x/local_y are not numbers ({err})"
                raise MapError(msg) from err
            shifts.append((local[0] - point.x, local[1] - point.y))
    arr = np.array(shifts, dtype=np.float64).reshape(-1, 2)
    if arr.size == 0:
        msg = f"{path}: no node has local_x/local_y; give the origin latitude, longitude"
        raise MapError(msg)
    spread = float(np.abs(arr - arr[0]).max())
    if spread > 0.5:
        msg = (
            f"{path}: the nodes' local_x/local_y are not one shift of their lat/lon ({spread:.1f} m "
            "apart); give the origin latitude, longitude instead"
        )
        raise MapError(msg)
    return np.asarray(arr.mean(axis=0), dtype=np.float64)
