"""A CommonRoad lanelet network in the road-map model.

Each lanelet becomes a lane (commonroad-io's ``Lanelet``): its ``center_vertices`` (the mean of
the paired left and right bound vertices, in the direction of travel) as the centreline, its
``left_vertices`` / ``right_vertices`` as the boundaries and their ``line_marking_*`` as the
boundary types (solid, broad solid, double solid → ``solid``; dashed, broad dashed, double dashed
→ ``dashed``; a mixed double line by the paint nearer the lane; curb → ``road_edge``; lowered curb
and no marking → ``virtual``; unknown), the mean distance of the paired bound vertices as its
width, ``successor`` / ``predecessor``, ``adj_left`` / ``adj_right`` as neighbours only when
``adj_*_same_direction``, and its speed limit the ``MAX_SPEED`` traffic sign it refers to, as
commonroad-io's ``TrafficSignInterpreter.speed_limit`` reads it (the lowest of its signs' values,
m/s) for the scenario's country.  ``lanelet_type`` bicycle lane / bus lane / sidewalk / crosswalk
gives the lane's ``kind`` (``bike``, ``bus``, ``sidewalk``, ``crosswalk``; else ``vehicle``);
crosswalk lanelets are also :class:`Crosswalk` polygons.  Roadblocks are the rows of
same-direction neighbours (:func:`redrive.maps.graph.group_roadblocks`).

A lanelet's ``stop_line`` is a :class:`StopLine` (``stop_<lanelet id>``); each traffic light a
:class:`MapTrafficLight` at its ``position`` controlling the lanelets that refer to it (its stop
line the first of theirs).  An intersection becomes an :class:`Intersection` of the lanelets
its incomings turn or go straight into (``outgoing_right`` / ``_straight`` / ``_left``, which the
2020a format calls ``successors*``) with, as CommonRoad draws none, their convex hull as its
outline; those lanelets name it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import shapely

from redrive.errors import LogError
from redrive.maps.graph import group_roadblocks
from redrive.types import Crosswalk, Intersection, MapLane, MapTrafficLight, RoadMap, StopLine

__all__ = ["boundary_type", "road_map_from_lanelets"]

_TYPE = {
    "solid": "solid",
    "broad_solid": "solid",
    "solid_solid": "solid",
    "dashed": "dashed",
    "broad_dashed": "dashed",
    "dashed_dashed": "dashed",
    "curb": "road_edge",
    "lowered_curb": "virtual",
    "no_marking": "virtual",
}
_KIND = {"bicycleLane": "bike", "busLane": "bus", "sidewalk": "sidewalk", "crosswalk": "crosswalk"}


def boundary_type(marking: str, *, lane_side: str) -> str:
    """The boundary type of a CommonRoad ``LineMarking`` value seen from a lane on
    ``lane_side`` ("left" or "right") of it (``solid_dashed`` is solid on its left)."""
    if marking in _TYPE:
        return _TYPE[marking]
    if marking in ("solid_dashed", "dashed_solid"):
        left, right = marking.split("_")
        return right if lane_side == "right" else left
    return "unknown"


def _interpreter(scenario: Any) -> Any:
    from commonroad.scenario.traffic_sign import SupportedTrafficSignCountry
    from commonroad.scenario.traffic_sign_interpreter import TrafficSignInterpreter

    code = str(getattr(scenario.scenario_id, "country_id", "") or "")
    try:
        country = SupportedTrafficSignCountry(code)
    except ValueError:
        country = SupportedTrafficSignCountry.ZAMUNDA
    return TrafficSignInterpreter(country, scenario.lanelet_network)


def _xy(value: Any) -> npt.NDArray[np.float64]:
    return np.asarray(value, dtype=np.float64).reshape(-1, 2)


def road_map_from_lanelets(scenario: Any, *, source: str) -> RoadMap:
    """The road map of a commonroad-io ``Scenario``'s lanelet network.

    Raises:
        LogError: a lanelet's bounds do not pair up or give no width (its id named).
    """
    network = scenario.lanelet_network
    interpreter = _interpreter(scenario)
    ids = {str(lanelet.lanelet_id) for lanelet in network.lanelets}
    intersection_of: dict[str, str] = {}
    intersections = []
    for inter in network.intersections:
        inside: set[int] = set()
        for incoming in inter.incomings:
            for key in ("outgoing_right", "outgoing_straight", "outgoing_left"):
                inside.update(getattr(incoming, key, None) or ())
        members = sorted(str(i) for i in inside if str(i) in ids)
        if not members:
            continue
        points = np.concatenate(
            [
                np.concatenate([_xy(lt.left_vertices), _xy(lt.right_vertices)])
                for lt in (network.find_lanelet_by_id(int(m)) for m in members)
            ]
        )
        hull = shapely.convex_hull(shapely.multipoints(points))
        if hull.geom_type != "Polygon":
            continue
        iid = str(inter.intersection_id)
        intersections.append(
            Intersection(
                intersection_id=iid,
                polygon=np.asarray(hull.exterior.coords, dtype=np.float64)[:-1],
                lane_ids=tuple(members),
            )
        )
        intersection_of.update(dict.fromkeys(members, iid))
    lanes = []
    crosswalks = []
    stop_lines = []
    for lanelet in network.lanelets:
        lid = str(lanelet.lanelet_id)
        left = _xy(lanelet.left_vertices)
        right = _xy(lanelet.right_vertices)
        centre = _xy(lanelet.center_vertices)
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
        limit = interpreter.speed_limit(frozenset({int(lanelet.lanelet_id)}))
        types = {t.value for t in lanelet.lanelet_type or ()}
        kind = next((_KIND[t] for t in sorted(types) if t in _KIND), "vehicle")
        if kind == "crosswalk":
            crosswalks.append(
                Crosswalk(crosswalk_id=lid, polygon=np.concatenate([left, right[::-1]]))
            )
        if lanelet.stop_line is not None:
            line = np.array([lanelet.stop_line.start, lanelet.stop_line.end], dtype=np.float64)
            if np.all(np.isfinite(line)) and not np.array_equal(line[0], line[1]):
                stop_lines.append(StopLine(stop_line_id=f"stop_{lid}", line=line, lane_ids=(lid,)))

        def neighbour(adj: Any, same: Any) -> str | None:
            return str(adj) if adj is not None and same and str(adj) in ids else None

        lanes.append(
            MapLane(
                lane_id=lid,
                centerline=centre,
                width_m=width,
                speed_limit_mps=float(limit) if limit is not None and limit > 0 else None,
                left_boundary=left,
                right_boundary=right,
                left_boundary_type=boundary_type(
                    _marking(lanelet.line_marking_left_vertices), lane_side="right"
                ),
                right_boundary_type=boundary_type(
                    _marking(lanelet.line_marking_right_vertices), lane_side="left"
                ),
                successors=tuple(str(i) for i in lanelet.successor or () if str(i) in ids),
                predecessors=tuple(str(i) for i in lanelet.predecessor or () if str(i) in ids),
                left_neighbor=neighbour(lanelet.adj_left, lanelet.adj_left_same_direction),
                right_neighbor=neighbour(lanelet.adj_right, lanelet.adj_right_same_direction),
                intersection_id=intersection_of.get(lid),
                kind=kind,
            )
        )
    stops = {s.lane_ids[0]: s.stop_line_id for s in stop_lines}
    lights = []
    for light in network.traffic_lights:
        controlled = sorted(
            str(lt.lanelet_id)
            for lt in network.lanelets
            if light.traffic_light_id in (lt.traffic_lights or ())
        )
        position = _xy(light.position)[0]
        stop = next((stops[c] for c in controlled if c in stops), None)
        lights.append(
            MapTrafficLight(
                light_id=str(light.traffic_light_id),
                position=position,
                lane_ids=tuple(controlled),
                stop_line_id=stop,
            )
        )
    grouped, roadblocks = group_roadblocks({lane.lane_id: lane for lane in lanes})
    return RoadMap(
        lanes=tuple(grouped.values()),
        roadblocks=roadblocks,
        intersections=tuple(intersections),
        crosswalks=tuple(crosswalks),
        stop_lines=tuple(stop_lines),
        traffic_lights=tuple(lights),
        source=f"commonroad:{source}",
    )


def _marking(value: Any) -> str:
    return str(getattr(value, "value", value) or "unknown")
