"""What NAVSIM scores a proposal against: the agents' logged future at 10 Hz, the map's layers
around the ego, its route and centreline, and the red lights on the route.

Follows NAVSIM's metric cache (``navsim/planning/metric_caching/metric_cache_processor.py``
``MetricCacheProcessor._interpolate_gt_observation``, ``_interpolate_traffic_light_status``;
``metric_caching_utils.py`` ``StateInterpolator``; ``observation/pdm_observation.py``
``PDMObservation.update_detections_tracks`` / ``_get_traffic_light_geometries``): the logged
boxes are sampled at 2 Hz and linearly interpolated to 10 Hz (headings unwrapped); an object
seen in only one 2-Hz sample stays where it was at every step (NAVSIM appends its first box
whenever its interpolator's start equals its end); the velocity is kept only for agents.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import shapely

from redrive.evaluation._kinematics import rectangle_corners
from redrive.evaluation.closedloop._common import AGENT_CLASSES
from redrive.evaluation.closedloop.lights import controlled_lane_ids
from redrive.maps.index import DRIVABLE_LANE_KINDS
from redrive.types import LightState, MapLane, ObjectClass, ObjectColumns, RoadMap

F64 = npt.NDArray[np.float64]

__all__ = [
    "MapContext",
    "Occupancy",
    "TrackInfo",
    "interpolate_observation",
    "lane_polygons",
    "map_context",
    "red_light_polygons",
]

#: NAVSIM's 2-Hz resolution of the logged boxes (``resolution_step``), s.
RESOLUTION_S = 0.5


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackInfo:
    """NAVSIM's ``unique_objects[token]``: the object as first seen in the observation (its
    class, heading and velocity there: NAVSIM classifies collisions with that instance)."""

    object_class: ObjectClass
    velocity_xy: F64
    heading_rad: float

    @property
    def is_agent(self) -> bool:
        return self.object_class in AGENT_CLASSES


@dataclass(frozen=True, slots=True, kw_only=True)
class Occupancy:
    """The boxes at one 10-Hz step: tokens (M,), corners (M, 4, 2) front-left, rear-left,
    rear-right, front-right, map frame."""

    tokens: tuple[str, ...]
    corners: F64

    @classmethod
    def empty(cls) -> Occupancy:
        return cls(tokens=(), corners=np.zeros((0, 4, 2), dtype=np.float64))

    def centroid(self, m: int) -> F64:
        return np.asarray(self.corners[m].mean(axis=0), dtype=np.float64)

    def polygon(self, m: int) -> shapely.Polygon:
        return shapely.Polygon(self.corners[m])


def _wrap(a: F64) -> F64:
    return np.asarray(np.arctan2(np.sin(a), np.cos(a)), dtype=np.float64)


def interpolate_observation(
    samples: Sequence[ObjectColumns | None],
    *,
    n_steps: int,
    interval_s: float = 0.1,
) -> tuple[list[Occupancy], dict[str, TrackInfo]]:
    """The 10-Hz observation of ``n_steps`` steps from the 2-Hz samples (``samples[k]`` the
    boxes at ``k · 0.5`` s, map frame; None where the log has no frame there).

    Returns the occupancy of each step and the first-seen instance of each token."""
    tracks: dict[str, list[tuple[float, F64]]] = {}
    sizes: dict[str, tuple[float, float]] = {}
    unique: dict[str, TrackInfo] = {}
    for k, objs in enumerate(samples):
        if objs is None:
            continue
        t = k * RESOLUTION_S
        for m in range(len(objs)):
            oid = int(objs.object_id[m])
            token = str(oid) if oid >= 0 else f"k{k}:{m}"
            cls = objs.object_class[m]
            agent = cls in AGENT_CLASSES
            vel = objs.velocity_mps[m, :2] if agent else np.zeros(2)
            state = np.array(
                [objs.center_m[m, 0], objs.center_m[m, 1], objs.yaw_rad[m], vel[0], vel[1]],
                dtype=np.float64,
            )
            if token not in tracks:
                tracks[token] = []
                sizes[token] = (float(objs.size_m[m, 0]), float(objs.size_m[m, 1]))
                unique[token] = TrackInfo(
                    object_class=cls,
                    velocity_xy=np.asarray(vel, dtype=np.float64).copy(),
                    heading_rad=float(objs.yaw_rad[m]),
                )
            tracks[token].append((t, state))
    times = np.arange(n_steps, dtype=np.float64) * interval_s
    # every (step, token) box gathered, the corners computed in one call
    step_of: list[npt.NDArray[np.int64]] = []
    tok_of: list[str] = []
    xs: list[F64] = []
    ys: list[F64] = []
    hs: list[F64] = []
    lengths: list[F64] = []
    widths: list[F64] = []
    for token, rows in tracks.items():
        t_k = np.array([r[0] for r in rows])
        st = np.stack([r[1] for r in rows])
        if t_k[0] == t_k[-1]:  # one sample: NAVSIM keeps its first box at every step
            idx = np.arange(n_steps, dtype=np.int64)
            xq, yq, hq = (np.full(n_steps, st[0, c]) for c in range(3))
        else:
            idx = np.flatnonzero((times >= t_k[0]) & (times <= t_k[-1])).astype(np.int64)
            xq = np.interp(times[idx], t_k, st[:, 0])
            yq = np.interp(times[idx], t_k, st[:, 1])
            hq = _wrap(np.interp(times[idx], t_k, np.unwrap(st[:, 2])))
        step_of.append(idx)
        tok_of += [token] * idx.size
        xs.append(xq)
        ys.append(yq)
        hs.append(hq)
        lengths.append(np.full(idx.size, sizes[token][0]))
        widths.append(np.full(idx.size, sizes[token][1]))
    if not step_of:
        return [Occupancy.empty() for _ in range(n_steps)], unique
    steps = np.concatenate(step_of)
    corners = rectangle_corners(
        np.column_stack([np.concatenate(xs), np.concatenate(ys)]),
        np.concatenate(hs),
        np.concatenate(lengths),
        np.concatenate(widths),
    )
    order = np.argsort(steps, kind="stable")  # per step, tokens in first-seen order
    bounds = np.searchsorted(steps[order], np.arange(n_steps + 1))
    occupancy = [
        Occupancy(
            tokens=tuple(tok_of[j] for j in order[bounds[i] : bounds[i + 1]].tolist()),
            corners=corners[order[bounds[i] : bounds[i + 1]]],
        )
        for i in range(n_steps)
    ]
    return occupancy, unique


@dataclass(slots=True)
class MapContext:
    """The map as NAVSIM's scorer sees it around one scene.

    Attributes:
        lane_polygons: the lanes (NAVSIM's LANE / LANE_CONNECTOR layers) near the ego.
        lane_ids: their ids.
        drivable: the union of lanes and drivable areas (NAVSIM's ROADBLOCK, INTERSECTION,
            DRIVABLE_AREA, CARPARK_AREA layers; their union here, so a corner on the seam of
            two lanes is on the road).
        intersection: the union of intersection polygons, None when the map has none.
        route_lane_ids: the lanes of the route (NAVSIM's ``route_lane_ids``).
        centerline: the route's centreline (NAVSIM's PDM-Closed ``_centerline``), None when no
            route lane is near the ego.
        centerline_speed_limit_mps: the speed limit of the starting lane (None if unknown).
    """

    lane_polygons: list[shapely.Polygon]
    lane_ids: list[str]
    drivable: shapely.Geometry
    intersection: shapely.Geometry | None
    route_lane_ids: frozenset[str]
    centerline: shapely.LineString | None
    centerline_xyh: F64 | None
    centerline_speed_limit_mps: float | None
    lane_polygon_by_id: dict[str, shapely.Polygon] = field(default_factory=dict)
    lane_bounds: F64 = field(default_factory=lambda: np.zeros((0, 4)))

    def in_intersection(self, xy: F64) -> npt.NDArray[np.bool_]:
        """(K,) points within an intersection polygon (NAVSIM ``is_in_layer``: ``within``)."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.intersection is None:
            return np.zeros(p.shape[0], dtype=bool)
        return np.asarray(shapely.contains_xy(self.intersection, p[:, 0], p[:, 1]), dtype=bool)


def _lane_polygon(road_map: RoadMap, i: int) -> shapely.Polygon:
    lane = road_map.lanes[i]
    left = getattr(lane, "left_boundary", None)
    right = getattr(lane, "right_boundary", None)
    if left is not None and right is not None:
        ring = np.concatenate([np.asarray(left), np.asarray(right)[::-1]])
        return shapely.make_valid(shapely.Polygon(ring))
    width = float(lane.width_m)
    return shapely.buffer(shapely.LineString(lane.centerline), width / 2.0, cap_style="flat")


def _route_lanes(road_map: RoadMap, visited: Sequence[str]) -> frozenset[str]:
    """The lanes of the route: the roadblocks of the visited lanes when the map has roadblocks
    (NAVSIM takes every lane of the route's roadblocks), else the visited lanes."""
    blocks = getattr(road_map, "roadblocks", ())
    if not blocks:
        return frozenset(visited)
    by_lane = {lid: b for b in blocks for lid in b.lane_ids}
    out = set(visited)
    for lid in visited:
        block = by_lane.get(lid)
        if block is not None:
            out.update(block.lane_ids)
    return frozenset(out)


def _centerline(
    road_map: RoadMap, start: int, route: frozenset[str], *, max_length_m: float
) -> F64:
    """The route's centreline from lane ``start``: its centreline followed by successors on the
    route (the map's ``successors`` when it has them, else the route lane that starts where the
    last one ends), as PDM-Closed's ``_get_discrete_centerline`` follows its Dijkstra path."""
    lanes = road_map.lanes
    index = {lane.lane_id: i for i, lane in enumerate(lanes)}
    chain = [start]
    length = lanes[start].length_m
    while length < max_length_m and len(chain) < 64:
        cur = lanes[chain[-1]]
        succ = [s for s in getattr(cur, "successors", ()) if s in route and s in index]
        nxt: int | None = index[succ[0]] if succ else None
        if nxt is None:
            end = cur.centerline[-1]
            best = math.inf
            for lid in route:
                j = index.get(lid)
                if j is None or j in chain:
                    continue
                d = float(np.hypot(*(lanes[j].centerline[0] - end)))
                if d < 1.0 and d < best:
                    best, nxt = d, j
        if nxt is None or nxt in chain:
            break
        chain.append(nxt)
        length += lanes[nxt].length_m
    pts = np.concatenate([lanes[i].centerline for i in chain])
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.hypot(*np.diff(pts, axis=0).T) > 1e-6
    pts = pts[keep]
    step = np.diff(pts, axis=0)
    heading = np.arctan2(step[:, 1], step[:, 0])
    heading = np.append(heading, heading[-1])
    return np.column_stack([pts, np.unwrap(heading)])


def _drives(lane: MapLane) -> bool:
    """A lane cars drive in (NAVSIM's LANE / LANE_CONNECTOR layers: not bicycle lanes)."""
    return getattr(lane, "kind", "vehicle") in DRIVABLE_LANE_KINDS


def lane_polygons(road_map: RoadMap) -> tuple[list[shapely.Polygon], shapely.Geometry]:
    """Each lane's polygon (its boundaries when the map has them, else its centreline widened
    by half its width either side) and the drivable union of the lanes cars drive in and the
    areas, prepared."""
    polys = [_lane_polygon(road_map, i) for i in range(len(road_map.lanes))]
    for poly in polys:
        shapely.prepare(poly)
    areas = [shapely.Polygon(a.polygon) for a in road_map.areas]
    cars = [p for p, lane in zip(polys, road_map.lanes, strict=True) if _drives(lane)]
    drivable = shapely.union_all([*cars, *areas])
    shapely.prepare(drivable)
    return polys, drivable


def map_context(
    road_map: RoadMap,
    *,
    lanes: tuple[list[shapely.Polygon], shapely.Geometry] | None = None,
    ego_xy: F64,
    ego_heading_rad: float,
    visited_lane_ids: Sequence[str],
    radius_m: float = 100.0,
    centerline_length_m: float = 200.0,
) -> MapContext:
    """The scene's map around the ego's rear axle ``ego_xy`` (lanes within ``radius_m``: NAVSIM's
    ``map_radius``), its route (the lanes the logged ego drives, ``visited_lane_ids``) and the
    centreline from the starting lane (PDM-Closed ``_get_starting_lane``: the on-route lane
    under the rear axle with the least heading error, else the nearest on-route lane)."""
    all_polys, drivable = lane_polygons(road_map) if lanes is None else lanes
    centre = shapely.Point(float(ego_xy[0]), float(ego_xy[1]))
    dist = shapely.distance(np.array(all_polys, dtype=object), centre)
    near = [i for i in np.flatnonzero(dist <= radius_m).tolist() if _drives(road_map.lanes[i])]
    inter = [shapely.Polygon(a.polygon) for a in road_map.areas if a.kind == "intersection"] + [
        shapely.Polygon(x.polygon) for x in getattr(road_map, "intersections", ())
    ]
    intersection = shapely.union_all(inter) if inter else None
    if intersection is not None:
        shapely.prepare(intersection)
    route = _route_lanes(road_map, visited_lane_ids)
    start: int | None = None
    best = math.inf
    for i in near:
        lane = road_map.lanes[i]
        if lane.lane_id not in route or not all_polys[i].contains(centre):
            continue
        d = np.diff(lane.centerline, axis=0)
        seg = int(np.argmin(np.hypot(*(lane.centerline[:-1] - ego_xy).T)))
        err = abs(math.remainder(ego_heading_rad - math.atan2(d[seg, 1], d[seg, 0]), math.tau))
        if err < best:
            best, start = err, i
    if start is None:
        dist = [
            (all_polys[i].distance(centre), i) for i in near if road_map.lanes[i].lane_id in route
        ]
        start = min(dist)[1] if dist else None
    line_xyh = (
        None
        if start is None
        else _centerline(road_map, start, route, max_length_m=centerline_length_m)
    )
    line = None if line_xyh is None else shapely.LineString(line_xyh[:, :2])
    polys = [all_polys[i] for i in near]
    ids = [road_map.lanes[i].lane_id for i in near]
    return MapContext(
        lane_polygons=polys,
        lane_ids=ids,
        drivable=drivable,
        intersection=intersection,
        route_lane_ids=route,
        centerline=line,
        centerline_xyh=line_xyh,
        centerline_speed_limit_mps=None if start is None else road_map.lanes[start].speed_limit_mps,
        lane_polygon_by_id={road_map.lanes[i].lane_id: all_polys[i] for i in range(len(all_polys))},
        lane_bounds=np.asarray(
            shapely.bounds(np.array(polys, dtype=object)), dtype=np.float64
        ).reshape(-1, 4),
    )


def red_light_polygons(
    road_map: RoadMap,
    ctx: MapContext,
    states: Sequence[Mapping[str, LightState] | None],
) -> list[list[shapely.Polygon]]:
    """Per step, the polygons of the on-route lanes whose light is red (NAVSIM
    ``_get_traffic_light_geometries``: a red light's token covers its lane connector's polygon).

    ``states[i]``: light id → state at step ``i`` (the last state logged at or before it), None
    where nothing is known.  The lanes a light controls are
    :func:`redrive.evaluation.closedloop.lights.controlled_lane_ids`' (the rule the traffic-light
    metric uses too: a lane inside an intersection itself, a lane that leads to the stop line its
    successors — the connectors beyond it, NAVSIM's red-light polygons); a map without lights has
    no red lights."""
    beyond = {
        light.light_id: controlled_lane_ids(road_map, light) for light in road_map.traffic_lights
    }
    out: list[list[shapely.Polygon]] = []
    for st in states:
        polys: list[shapely.Polygon] = []
        if st:
            for light_id, state in st.items():
                if state is not LightState.RED:
                    continue
                for lane_id in beyond.get(light_id, ()):
                    poly = ctx.lane_polygon_by_id.get(lane_id)
                    if poly is not None and lane_id in ctx.route_lane_ids:
                        polys.append(poly)
        out.append(polys)
    return out
