"""A CommonRoad lanelet network in the road-map model.

Each lanelet becomes a lane: its ``center_vertices`` (commonroad-io: the mean of the left and
right bound vertices, in the direction of travel) as the centreline, its width the mean distance
between the paired left and right bound vertices, its speed limit the ``MAX_SPEED`` traffic sign
the lanelet refers to, as commonroad-io's ``TrafficSignInterpreter.speed_limit`` reads it (the
lowest of its signs' values, m/s) for the scenario's country.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from redrive.errors import LogError
from redrive.types import MapLane, RoadMap

__all__ = ["road_map_from_lanelets"]


def _interpreter(scenario: Any) -> Any:
    from commonroad.scenario.traffic_sign import SupportedTrafficSignCountry
    from commonroad.scenario.traffic_sign_interpreter import TrafficSignInterpreter

    code = str(getattr(scenario.scenario_id, "country_id", "") or "")
    try:
        country = SupportedTrafficSignCountry(code)
    except ValueError:
        country = SupportedTrafficSignCountry.ZAMUNDA
    return TrafficSignInterpreter(country, scenario.lanelet_network)


def road_map_from_lanelets(scenario: Any, *, source: str) -> RoadMap:
    """The road map of a commonroad-io ``Scenario``'s lanelet network.

    Raises:
        LogError: a lanelet's bounds do not pair up or give no width (its id named).
    """
    interpreter = _interpreter(scenario)
    lanes = []
    for lanelet in scenario.lanelet_network.lanelets:
        lid = int(lanelet.lanelet_id)
        left = np.asarray(lanelet.left_vertices, dtype=np.float64)[:, :2]
        right = np.asarray(lanelet.right_vertices, dtype=np.float64)[:, :2]
        centre = np.asarray(lanelet.center_vertices, dtype=np.float64)[:, :2]
        if left.shape != right.shape or len(centre) < 2:
            msg = (
                f"{source}: lanelet {lid}: its bounds have {len(left)} and {len(right)} "
                "vertices; CommonRoad pairs them one to one"
            )
            raise LogError(msg)
        width = float(np.linalg.norm(left - right, axis=1).mean())
        if not width > 0:
            msg = f"{source}: lanelet {lid}: its left and right bounds coincide (width 0)"
            raise LogError(msg)
        limit = interpreter.speed_limit(frozenset({lid}))
        lanes.append(
            MapLane(
                lane_id=str(lid),
                centerline=centre,
                width_m=width,
                speed_limit_mps=float(limit) if limit is not None and limit > 0 else None,
            )
        )
    return RoadMap(lanes=tuple(lanes))
