"""Traffic-light compliance: NAVSIM v2's TLC, per ego step and for a run.

The definition is NAVSIM's (``navsim/planning/simulation/planner/pdm_planner/scoring/
pdm_scorer.py``, ``PDMScorer._calculate_traffic_light_compliance``, with the red-light geometry
of ``navsim/planning/simulation/planner/pdm_planner/observation/pdm_observation.py``,
``PDMObservation._get_traffic_light_geometries``): at every step of the trajectory, the first
included, the ego footprint polygon is tested for ``intersects`` against the polygons of the
lane connectors whose light is RED and that lie on the route; one hit makes the score 0, else
it is 1.  Quirks kept: only RED counts (yellow and unknown never do); a footprint that merely
touches the connector counts; a red light off the route never counts (a crossing connector the
ego overlaps inside the junction is not its own); the score has no partial values.

The map side (:mod:`redrive.types.roadmap`):

* the lanes a light lets traffic into — NAVSIM's lane connectors — are the
  :class:`~redrive.types.MapTrafficLight`'s ``lane_ids`` that lie in an intersection
  (``MapLane.intersection_id`` set: nuPlan's and Waymo's convention, the light's states name the
  connector lanes); a controlled lane outside any intersection (Lanelet2's and the synthetic
  maps' convention: the lane that carries the light's stop line) stands for its
  ``successors``, the lanes behind the stop line.  A controlled lane with neither contributes
  nothing.
* lane polygons are :func:`redrive.maps.index.lane_polygon` (between the boundaries, flat ends).
* the route: NAVSIM's ``route_lane_dict`` holds every lane of the roadblocks of the log's
  mission (the expert's route); a run stores no mission, so :func:`route_lane_ids` takes the
  roadblocks of the lanes the given poses are in (:meth:`RoadMapIndex.lane_of_pose
  <redrive.maps.index.RoadMapIndex.lane_of_pose>`) — the metric passes the logged ego's and the
  driven ego's poses — and every lane of those roadblocks (a lane without a roadblock: itself).

The reusable function (NAVSIM's EPDMS imports it)::

    red_light_violations(
        road_map: RoadMap,
        corners: (N, 4, 2) float64,       # ego footprint corners per step, map frame, metres
        *,
        states: Sequence[Iterable[TrafficLight]],  # per step, the lights' states (len N)
        route_lane_ids: Collection[str],  # the lanes on the route (route_lane_ids(...))
        index: RoadMapIndex | None = None,  # built from road_map when None
    ) -> (N,) bool                        # step k: the footprint touches a red connector

and :func:`red_light_hits` (the same test, with the ids of the lights hit at each step).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping, Sequence
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt
import shapely

from redrive.evaluation.base import Bookmark, EvalData, Metric, MetricResult, MetricSkipped
from redrive.evaluation.closedloop._common import (
    EGO_DEFAULTS,
    EgoRun,
    ego_run,
    require_road,
    series,
)
from redrive.evaluation.closedloop.deviation import with_deviation
from redrive.maps.index import RoadMapIndex, lane_polygon
from redrive.types import LightState, MapTrafficLight, RoadMap, Role, TrafficLight

__all__ = [
    "TrafficLightCompliance",
    "controlled_lane_ids",
    "red_light_hits",
    "red_light_violations",
    "route_lane_ids",
]

F64 = npt.NDArray[np.float64]


def controlled_lane_ids(road_map: RoadMap, light: MapTrafficLight) -> tuple[str, ...]:
    """The lanes ``light`` lets traffic into (NAVSIM's lane connectors; see the module text).

    Raises:
        KeyError: the light names a lane the map does not have.
    """
    out: dict[str, None] = {}
    for lane_id in light.lane_ids:
        lane = road_map.lane(lane_id)
        if lane.intersection_id is not None:
            out[lane_id] = None
        else:
            out.update(dict.fromkeys(lane.successors))
    return tuple(out)


def route_lane_ids(
    road_map: RoadMap,
    xy: npt.ArrayLike,
    *,
    yaw_rad: npt.ArrayLike,
    index: RoadMapIndex | None = None,
) -> frozenset[str]:
    """Every lane of the roadblocks of the lanes the poses (``xy`` (N, 2) map metres,
    ``yaw_rad`` (N,)) are in — NAVSIM's on-route lanes, from a track instead of a mission."""
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if p.shape[0] == 0:
        return frozenset()
    idx = RoadMapIndex(road_map) if index is None else index
    lanes = {lane for lane in idx.lane_of_pose(p, yaw_rad) if lane is not None}
    blocks = {road_map.lane(lane).roadblock_id for lane in lanes} - {None}
    out = set(lanes)
    for block in road_map.roadblocks:
        if block.roadblock_id in blocks:
            out.update(block.lane_ids)
    return frozenset(out)


def _red_light_lanes(
    road_map: RoadMap, route: Collection[str]
) -> tuple[list[str], list[tuple[str, ...]]]:
    """The map's light ids and, per light, its controlled lanes that lie on ``route``."""
    ids, lanes = [], []
    for light in road_map.traffic_lights:
        ids.append(light.light_id)
        lanes.append(tuple(lane for lane in controlled_lane_ids(road_map, light) if lane in route))
    return ids, lanes


def red_light_hits(
    road_map: RoadMap,
    corners: npt.ArrayLike,
    *,
    states: Sequence[Iterable[TrafficLight]],
    route_lane_ids: Collection[str],
    index: RoadMapIndex | None = None,
) -> list[tuple[str, ...]]:
    """Per step: the ids of the RED lights whose on-route connectors the footprint touches
    (empty: no violation).  Arguments as :func:`red_light_violations`.

    Raises:
        ValueError: ``corners`` is not (N, 4, 2) or ``states`` does not have N entries.
    """
    c = np.asarray(corners, dtype=np.float64)
    if c.ndim != 3 or c.shape[1:] != (4, 2):
        msg = f"red_light_hits: corners must be (N, 4, 2) map metres, got shape {c.shape}"
        raise ValueError(msg)
    n = c.shape[0]
    if len(states) != n:
        msg = f"red_light_hits: {n} footprints but {len(states)} steps of light states"
        raise ValueError(msg)
    out: list[tuple[str, ...]] = [()] * n
    light_ids, light_lanes = _red_light_lanes(road_map, route_lane_ids)
    lanes = sorted({lane for group in light_lanes for lane in group})
    if n == 0 or not lanes:
        return out
    if index is None:
        polygons = [lane_polygon(road_map.lane(lane)) for lane in lanes]
    else:
        polygons = [index.lane_polygons[index.lane_position(lane)] for lane in lanes]
    footprints = shapely.polygons(c)
    # (N, L): the footprint of step k intersects lane l (touching counts: NAVSIM's "intersects")
    touching = shapely.intersects(footprints[:, None], np.array(polygons, dtype=object)[None, :])
    column = {lane: j for j, lane in enumerate(lanes)}
    light_columns = [
        np.array([column[lane] for lane in group], dtype=np.int64) for group in light_lanes
    ]
    for k in np.flatnonzero(touching.any(axis=1)).tolist():
        red = {light.id for light in states[k] if light.state is LightState.RED}
        hit = tuple(
            light_id
            for light_id, cols in zip(light_ids, light_columns, strict=True)
            if light_id in red and cols.size and bool(touching[k, cols].any())
        )
        out[k] = hit
    return out


def red_light_violations(
    road_map: RoadMap,
    corners: npt.ArrayLike,
    *,
    states: Sequence[Iterable[TrafficLight]],
    route_lane_ids: Collection[str],
    index: RoadMapIndex | None = None,
) -> npt.NDArray[np.bool_]:
    """(N,) bool: at step k the ego footprint ``corners[k]`` ((N, 4, 2) float64, map frame)
    intersects a lane connector on the route (``route_lane_ids``) whose light is RED in
    ``states[k]`` (the lights' states at that step, ``TrafficLight.id`` =
    ``MapTrafficLight.light_id``) — NAVSIM's traffic-light-compliance test of one step (see the
    module text).  TLC of the trajectory is ``0.0 if any(...) else 1.0``.

    Args:
        road_map: the map with its traffic lights and lane graph.
        corners: ego footprint corners per step.
        states: per step, the lights' states (a light absent from a step is not red there).
        route_lane_ids: the lanes on the route (:func:`route_lane_ids`).
        index: the map's :class:`~redrive.maps.index.RoadMapIndex`, when the caller has one.

    Raises:
        ValueError: ``corners`` is not (N, 4, 2) or ``states`` does not have N entries.
    """
    hits = red_light_hits(
        road_map, corners, states=states, route_lane_ids=route_lane_ids, index=index
    )
    return np.array([bool(h) for h in hits], dtype=bool)


TLC_DEFAULTS: Mapping[str, Any] = MappingProxyType(dict(EGO_DEFAULTS))


class TrafficLightCompliance(Metric):
    """NAVSIM v2 ``traffic_light_compliance`` (TLC) of the driven ego over the run: 0 when its
    footprint touches, at any frame, an on-route lane connector whose light is red, else 1
    (see :mod:`redrive.evaluation.closedloop.lights`).

    The route is the roadblocks the logged ego (closed loop; in open loop the ego itself) and
    the driven ego drive in.  A map without traffic lights scores 1 (nothing to violate); a map
    with lights but a run without light states (``traffic_lights`` table) is skipped.

    Values: ``traffic_light_compliance`` (headline, 1 or 0), ``red_light_frames`` (frames in
    violation), ``lights_in_map``, ``frames_without_states`` (frames of the ego track with no
    light states: never a violation), in a log-backed closed loop ``deviated_frames``. Per frame
    ``red_light_violation`` (1/0). Bookmarks
    ``red_light`` at the first frame of each violation, naming the lights.
    """

    name: ClassVar[str] = "traffic_light_compliance"
    version: ClassVar[str] = "1"
    role: ClassVar[Role | None] = None
    needs: ClassVar[frozenset[str]] = frozenset({"ego", "road_map"})
    unit: ClassVar[str] = "score"
    higher_is_better: ClassVar[bool] = True
    defaults: ClassVar[Mapping[str, Any]] = TLC_DEFAULTS

    def evaluate(self, data: EvalData) -> MetricResult:
        index = require_road(data)  # the evaluation's one index of the map, shared
        road_map = index.road_map
        ego = ego_run(data)
        frames = ego.frames
        counts = {"lights_in_map": float(len(road_map.traffic_lights))}
        if not road_map.traffic_lights:
            result = _result(
                1.0,
                np.zeros(len(ego), dtype=bool),
                frames=frames,
                hits=[],
                counts=counts,
                without=0,
            )
            return with_deviation(result, data, frames)
        per_frame = data.traffic_lights()
        if not per_frame:
            msg = (
                f"the road map has {len(road_map.traffic_lights)} traffic light(s) but the run "
                "holds no light states (its log has no traffic-light topic)"
            )
            raise MetricSkipped(msg)
        route = _route(road_map, ego, EgoRun.of(data.logged_ego()), index)
        states = [per_frame.get(f, ()) for f in frames.tolist()]
        hits = red_light_hits(
            road_map,
            ego.corners(self.params),
            states=states,
            route_lane_ids=route,
            index=index,
        )
        violated = np.array([bool(h) for h in hits], dtype=bool)
        score = 0.0 if violated.any() else 1.0
        without = sum(1 for f in frames.tolist() if f not in per_frame)
        result = _result(score, violated, frames=frames, hits=hits, counts=counts, without=without)
        return with_deviation(result, data, frames)


def _route(road_map: RoadMap, ego: EgoRun, logged: EgoRun, index: RoadMapIndex) -> frozenset[str]:
    xy = np.concatenate([logged.xy, ego.xy])
    yaw = np.concatenate([logged.heading_rad, ego.heading_rad])
    return route_lane_ids(road_map, xy, yaw_rad=yaw, index=index)


def _result(
    score: float,
    violated: npt.NDArray[np.bool_],
    *,
    frames: npt.NDArray[np.int64],
    hits: Sequence[tuple[str, ...]],
    counts: Mapping[str, float],
    without: int,
) -> MetricResult:
    starts = violated & ~np.concatenate([[False], violated[:-1]])
    return MetricResult(
        values={
            "traffic_light_compliance": score,
            "red_light_frames": float(violated.sum()),
            **counts,
            "frames_without_states": float(without),
        },
        units={
            "red_light_frames": "frames",
            "lights_in_map": "lights",
            "frames_without_states": "frames",
        },
        higher_is_better={
            "red_light_frames": False,
            "lights_in_map": None,
            "frames_without_states": None,
        },
        per_frame={"red_light_violation": series(frames, violated.astype(np.float64))},
        bookmarks=[
            Bookmark(
                frame_index=int(frames[k]),
                kind="red_light",
                detail=f"ego enters the junction on red (light {', '.join(hits[k])})",
                severity=1.0,
            )
            for k in np.flatnonzero(starts).tolist()
        ],
    )
