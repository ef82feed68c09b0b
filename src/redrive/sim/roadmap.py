"""The synthetic world's road network as a :class:`~redrive.types.RoadMap` (what a run stores).

Every lane of the network becomes a :class:`~redrive.types.MapLane` (its centre line, in the
direction of travel, and width); the intersection square of an urban layout becomes a
:class:`~redrive.types.DrivableArea` of kind ``intersection`` and an
:class:`~redrive.types.Intersection` holding the connector lanes.  Shoulders and sidewalks are not
drivable.  Speed limits: the layout's ``speed_limit_mps`` (``[road] speed_limit_mps`` of a
scenario) when given, else by road type — urban 50 km/h, highway 120 km/h (the usual limits of
built-up areas and motorways; a scenario that wants another writes it).

The lane graph:

- successors / predecessors: consecutive lanes of the network's routes (every lane lies on one);
- neighbours: the adjacent lanes of one direction of a road segment (lane ``i`` has lane ``i - 1``
  on its left: lane 0 runs next to the centre line);
- roadblocks: the lanes of one direction of a segment (``west_in``, ``entry:f`` …) and, inside the
  intersection, the connectors from one approach to one exit (``west_east`` …: nuPlan's roadblock
  connectors);
- boundary types as :func:`redrive.sim.ground.rasterize` paints them: ``solid`` centre and edge
  lines, ``dashed`` between lanes of one direction, ``virtual`` inside the intersection;
- stop lines (``stop:{approach}``) across the incoming lanes where :func:`rasterize` paints them,
  and one :class:`~redrive.types.MapTrafficLight` per signal head, ``light_id`` = ``str`` of the
  signal's id (the id :class:`~redrive.types.TrafficLight` states carry), controlling the incoming
  lanes of its approach.
"""

from __future__ import annotations

import numpy as np

from redrive.errors import ConfigError
from redrive.sim.roads import STOP_LINE_WIDTH_M, RoadNetwork, RoadSegment, build_network
from redrive.sim.scenario import Scenario
from redrive.types import (
    DrivableArea,
    Intersection,
    MapLane,
    MapTrafficLight,
    Roadblock,
    RoadMap,
    StopLine,
)

__all__ = [
    "HIGHWAY_SPEED_LIMIT_MPS",
    "INTERSECTION_ID",
    "URBAN_SPEED_LIMIT_MPS",
    "default_speed_limit_mps",
    "road_map",
    "scenario_road_map",
]

#: 50 km/h, the default limit of urban layouts (networks with an intersection).
URBAN_SPEED_LIMIT_MPS = 50.0 / 3.6
#: 120 km/h, the default limit of highway layouts.
HIGHWAY_SPEED_LIMIT_MPS = 120.0 / 3.6
#: the id of the urban layout's intersection (its Intersection and DrivableArea)
INTERSECTION_ID = "intersection"


def default_speed_limit_mps(network: RoadNetwork) -> float:
    """50 km/h for an urban network (it has an intersection), 120 km/h for a highway."""
    return (
        URBAN_SPEED_LIMIT_MPS
        if network.intersection_half_m is not None
        else HIGHWAY_SPEED_LIMIT_MPS
    )


def _directions(network: RoadNetwork, seg: RoadSegment) -> list[tuple[str, list[str]]]:
    """The roadblocks of a segment: (id, its lane ids from the centre line outwards) per
    direction (urban arms name their lanes ``{arm}_in_{i}`` / ``{arm}_out_{i}``)."""
    if network.intersection_half_m is not None:
        names = [(f"{seg.name}_in", seg.lanes_forward), (f"{seg.name}_out", seg.lanes_backward)]
        return [(rb, [f"{rb}_{i}" for i in range(n)]) for rb, n in names if n]
    names = [(f"{seg.name}:f", seg.lanes_forward), (f"{seg.name}:b", seg.lanes_backward)]
    return [(rb, [f"{rb}{i}" for i in range(n)]) for rb, n in names if n]


def _graph(network: RoadNetwork) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
    succ: dict[str, list[str]] = {lane_id: [] for lane_id in network.lanes}
    pred: dict[str, list[str]] = {lane_id: [] for lane_id in network.lanes}
    for route in network.routes.values():
        for a, b in zip(route.lane_ids, route.lane_ids[1:], strict=False):
            if b not in succ[a]:
                succ[a].append(b)
            if a not in pred[b]:
                pred[b].append(a)
    return succ, pred


def road_map(network: RoadNetwork, *, speed_limit_mps: float | None = None) -> RoadMap:
    """The map of ``network``: its lanes and lane graph, roadblocks, the intersection, stop
    lines and traffic lights (urban layouts).

    Args:
        speed_limit_mps: the limit of every lane; None: :func:`default_speed_limit_mps`.

    Raises:
        ConfigError: ``speed_limit_mps`` is not a positive number.
    """
    limit = default_speed_limit_mps(network) if speed_limit_mps is None else float(speed_limit_mps)
    if not limit > 0:
        msg = f"road_map: speed_limit_mps must be > 0 m/s, got {speed_limit_mps!r}"
        raise ConfigError(msg)
    urban = network.intersection_half_m is not None
    succ, pred = _graph(network)
    left_of: dict[str, str | None] = {}
    right_of: dict[str, str | None] = {}
    kinds: dict[str, tuple[str, str]] = {}
    lane_block: dict[str, str] = {}
    blocks: dict[str, list[str]] = {}
    stop_lines: list[StopLine] = []
    for seg in network.segments:
        for block_id, ids in _directions(network, seg):
            blocks[block_id] = ids
            for i, lane_id in enumerate(ids):
                lane_block[lane_id] = block_id
                left_of[lane_id] = ids[i - 1] if i > 0 else None
                right_of[lane_id] = ids[i + 1] if i + 1 < len(ids) else None
                kinds[lane_id] = (
                    "solid" if i == 0 else "dashed",
                    "solid" if i + 1 == len(ids) else "dashed",
                )
        if urban and network.signals and seg.lanes_forward:
            # rasterize's stop line: s in [L - 1 - width, L - 1], from the centre to the right
            s = seg.length_m - 1.0 - STOP_LINE_WIDTH_M
            d = np.array([0.0, -seg.lanes_forward * seg.lane_width_m])
            x, y, _ = seg.pose_at(np.array([s, s]), d)
            ids = [f"{seg.name}_in_{i}" for i in range(seg.lanes_forward)]
            stop_lines.append(
                StopLine(
                    stop_line_id=f"stop:{seg.name}",
                    line=np.column_stack([x, y]),
                    lane_ids=tuple(ids),
                )
            )
    connectors = [lane_id for lane_id in network.lanes if lane_id not in lane_block]
    for lane_id in connectors:  # urban connectors {from}_{to}_{i}: one roadblock per from → to
        block_id = lane_id.rsplit("_", 1)[0]
        blocks.setdefault(block_id, []).append(lane_id)
        lane_block[lane_id] = block_id
        kinds[lane_id] = ("virtual", "virtual")
    lanes = tuple(
        MapLane(
            lane_id=lane_id,
            centerline=lane.points.copy(),
            width_m=lane.width_m,
            speed_limit_mps=limit,
            successors=tuple(succ[lane_id]),
            predecessors=tuple(pred[lane_id]),
            roadblock_id=lane_block[lane_id],
            left_neighbor=left_of.get(lane_id),
            right_neighbor=right_of.get(lane_id),
            left_boundary_type=kinds[lane_id][0],
            right_boundary_type=kinds[lane_id][1],
            intersection_id=INTERSECTION_ID if urban and lane_id in connectors else None,
        )
        for lane_id, lane in network.lanes.items()
    )
    roadblocks = tuple(
        Roadblock(
            roadblock_id=block_id,
            lane_ids=tuple(ids),
            successors=tuple(dict.fromkeys(lane_block[s] for i in ids for s in succ[i])),
            predecessors=tuple(dict.fromkeys(lane_block[p] for i in ids for p in pred[i])),
        )
        for block_id, ids in blocks.items()
    )
    areas: tuple[DrivableArea, ...] = ()
    intersections: tuple[Intersection, ...] = ()
    half = network.intersection_half_m
    if half is not None:
        square = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
        areas = (DrivableArea(area_id=INTERSECTION_ID, polygon=square, kind="intersection"),)
        intersections = (
            Intersection(
                intersection_id=INTERSECTION_ID, polygon=square, lane_ids=tuple(connectors)
            ),
        )
    lights = tuple(
        MapTrafficLight(
            light_id=str(sig.light_id),
            position=np.array(sig.position[:2], dtype=np.float64),
            lane_ids=tuple(i for i, lane in network.lanes.items() if lane.light_id == sig.light_id),
            stop_line_id=f"stop:{sig.approach}"
            if any(s.stop_line_id == f"stop:{sig.approach}" for s in stop_lines)
            else None,
        )
        for sig in network.signals
    )
    return RoadMap(
        lanes=lanes,
        areas=areas,
        roadblocks=roadblocks,
        intersections=intersections,
        stop_lines=tuple(stop_lines),
        traffic_lights=lights,
        source="synthetic:urban" if urban else "synthetic:highway",
    )


def scenario_road_map(scenario: Scenario) -> RoadMap:
    """The map of a scenario's road (its layout's ``speed_limit_mps``, else the default)."""
    return road_map(build_network(scenario.road), speed_limit_mps=scenario.road.speed_limit_mps)
