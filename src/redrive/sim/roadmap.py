"""The synthetic world's road network as a :class:`~redrive.types.RoadMap` (what a run stores).

Every lane of the network becomes a :class:`~redrive.types.MapLane` (its centre line, in the
direction of travel, and width); the intersection square of an urban layout becomes a
:class:`~redrive.types.DrivableArea` of kind ``intersection``.  Shoulders and sidewalks are not
drivable.  Speed limits: the layout's ``speed_limit_mps`` (``[road] speed_limit_mps`` of a
scenario) when given, else by road type — urban 50 km/h, highway 120 km/h (the usual limits of
built-up areas and motorways; a scenario that wants another writes it).
"""

from __future__ import annotations

import numpy as np

from redrive.errors import ConfigError
from redrive.sim.roads import RoadNetwork, build_network
from redrive.sim.scenario import Scenario
from redrive.types import DrivableArea, MapLane, RoadMap

__all__ = [
    "HIGHWAY_SPEED_LIMIT_MPS",
    "URBAN_SPEED_LIMIT_MPS",
    "default_speed_limit_mps",
    "road_map",
    "scenario_road_map",
]

#: 50 km/h, the default limit of urban layouts (networks with an intersection).
URBAN_SPEED_LIMIT_MPS = 50.0 / 3.6
#: 120 km/h, the default limit of highway layouts.
HIGHWAY_SPEED_LIMIT_MPS = 120.0 / 3.6


def default_speed_limit_mps(network: RoadNetwork) -> float:
    """50 km/h for an urban network (it has an intersection), 120 km/h for a highway."""
    return (
        URBAN_SPEED_LIMIT_MPS
        if network.intersection_half_m is not None
        else HIGHWAY_SPEED_LIMIT_MPS
    )


def road_map(network: RoadNetwork, *, speed_limit_mps: float | None = None) -> RoadMap:
    """The map of ``network``: its lanes (and the intersection square, if any).

    Args:
        speed_limit_mps: the limit of every lane; None: :func:`default_speed_limit_mps`.

    Raises:
        ConfigError: ``speed_limit_mps`` is not a positive number.
    """
    limit = default_speed_limit_mps(network) if speed_limit_mps is None else float(speed_limit_mps)
    if not limit > 0:
        msg = f"road_map: speed_limit_mps must be > 0 m/s, got {speed_limit_mps!r}"
        raise ConfigError(msg)
    lanes = tuple(
        MapLane(
            lane_id=lane_id,
            centerline=lane.points.copy(),
            width_m=lane.width_m,
            speed_limit_mps=limit,
        )
        for lane_id, lane in network.lanes.items()
    )
    areas: tuple[DrivableArea, ...] = ()
    half = network.intersection_half_m
    if half is not None:
        square = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
        areas = (DrivableArea(area_id="intersection", polygon=square, kind="intersection"),)
    return RoadMap(lanes=lanes, areas=areas)


def scenario_road_map(scenario: Scenario) -> RoadMap:
    """The map of a scenario's road (its layout's ``speed_limit_mps``, else the default)."""
    return road_map(build_network(scenario.road), speed_limit_mps=scenario.road.speed_limit_mps)
