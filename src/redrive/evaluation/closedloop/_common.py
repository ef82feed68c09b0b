"""What the closed-loop metrics share: the ego track of a run, its footprint, the ground truth
put into the map frame, the road map's geometric queries, and the collision classification.

Planar throughout: x, y metres in ``map``, headings radians about +z.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt
import shapely

from redrive.evaluation._kinematics import (
    ego_footprint_corners,
    rectangle_corners,
    rectangles_overlap,
)
from redrive.evaluation.base import EvalData, MetricSkipped, Series
from redrive.evaluation.closedloop.lanes import corners_in_common_or_connected_lanes
from redrive.maps.index import DRIVABLE_LANE_KINDS, RoadMapIndex
from redrive.types import DetectedObject, ObjectClass, ObjectColumns, RoadMap, VehicleState

F64 = npt.NDArray[np.float64]

#: the ego footprint: ``redrive.sim.ego.EgoGeometry``'s defaults (the run manifest records no
#: vehicle geometry; evaluation may not import the simulator, a test keeps the two equal).
EGO_DEFAULTS: Mapping[str, float] = MappingProxyType(
    {"ego_length_m": 4.7, "ego_width_m": 1.9, "rear_overhang_m": 0.95}
)
#: nuPlan ``_get_collision_type`` / ``is_track_stopped``: stopped below this speed, m/s.
STOPPED_SPEED_MPS = 5e-2
#: nuPlan ``is_agent_behind`` (150°) and ``is_agent_ahead`` (30°) angle tolerances, rad.
BEHIND_ANGLE_RAD = math.radians(150.0)
AHEAD_ANGLE_RAD = math.radians(30.0)
#: object classes nuPlan counts as agents (an at-fault collision with one scores 0); the others
#: are objects (one at-fault collision scores 0.5): nuPlan ``AGENT_TYPES``.
AGENT_CLASSES = frozenset(
    {
        ObjectClass.VEHICLE,
        ObjectClass.TRUCK,
        ObjectClass.PEDESTRIAN,
        ObjectClass.BICYCLE,
        ObjectClass.MOTORCYCLE,
    }
)


@dataclass(frozen=True, slots=True)
class EgoRun:
    """The ego of a run, per frame with a state, in stamp order (arrays share the first axis).

    Attributes:
        frames: frame indices (N,); stamps_ns (N,); xy: rear axle (N, 2) m; heading_rad (N,);
        speed_mps: (N,) norm of the stored velocity; accel_xy: (N, 2) the stored acceleration
        of the rear axle in the map frame, m/s²; yaw_rate_rad_s: (N,) the stored yaw rate.
    """

    frames: npt.NDArray[np.int64]
    stamps_ns: npt.NDArray[np.int64]
    xy: F64
    heading_rad: F64
    speed_mps: F64
    accel_xy: F64
    yaw_rate_rad_s: F64

    @classmethod
    def of(cls, states: Mapping[int, VehicleState]) -> EgoRun:
        items = sorted(states.items(), key=lambda kv: (kv[1].stamp_ns, kv[0]))
        n = len(items)
        return cls(
            frames=np.array([k for k, _ in items], dtype=np.int64),
            stamps_ns=np.array([s.stamp_ns for _, s in items], dtype=np.int64),
            xy=np.array([s.position[:2] for _, s in items], dtype=np.float64).reshape(n, 2),
            heading_rad=np.array([s.heading_rad for _, s in items], dtype=np.float64),
            speed_mps=np.array([s.speed_mps for _, s in items], dtype=np.float64),
            accel_xy=np.array([s.acceleration[:2] for _, s in items], dtype=np.float64).reshape(
                n, 2
            ),
            yaw_rate_rad_s=np.array([s.yaw_rate_rad_s for _, s in items], dtype=np.float64),
        )

    def __len__(self) -> int:
        return int(self.frames.size)

    @property
    def t_s(self) -> F64:
        """Seconds since the first state."""
        return np.asarray((self.stamps_ns - self.stamps_ns[0]) / 1e9, dtype=np.float64)

    def corners(self, p: Mapping[str, Any]) -> F64:
        """Footprint corners (N, 4, 2): front-left, rear-left, rear-right, front-right."""
        return ego_footprint_corners(
            self.xy,
            self.heading_rad,
            length_m=float(p["ego_length_m"]),
            width_m=float(p["ego_width_m"]),
            rear_overhang_m=float(p["rear_overhang_m"]),
        )

    def centres(self, p: Mapping[str, Any]) -> F64:
        """Footprint centres (N, 2)."""
        shift = float(p["ego_length_m"]) / 2.0 - float(p["rear_overhang_m"])
        h = self.heading_rad
        return self.xy + shift * np.column_stack([np.cos(h), np.sin(h)])


def ego_run(data: EvalData, *, minimum: int = 1) -> EgoRun:
    """The driven ego of ``data``; MetricSkipped with fewer than ``minimum`` states."""
    ego = EgoRun.of(data.ego())
    if len(ego) < minimum:
        msg = f"the run has {len(ego)} ego states; this metric needs at least {minimum}"
        raise MetricSkipped(msg)
    return ego


def map_objects(
    objects: Sequence[DetectedObject], ego_xy: F64, ego_heading: float
) -> ObjectColumns:
    """``objects`` (base_link of a frame whose ego pose is ``ego_xy``, ``ego_heading``) in the
    map frame: centres rotated and shifted, yaws and velocities rotated (planar: z kept)."""
    local = ObjectColumns.from_objects(objects)
    c, s = math.cos(ego_heading), math.sin(ego_heading)
    rot = np.array([[c, -s], [s, c]])
    center = local.center_m.copy()
    velocity = local.velocity_mps.copy()
    center[:, :2] = np.ascontiguousarray(local.center_m[:, :2]) @ rot.T + ego_xy
    velocity[:, :2] = np.ascontiguousarray(local.velocity_mps[:, :2]) @ rot.T
    return dataclasses.replace(
        local, center_m=center, yaw_rad=local.yaw_rad + ego_heading, velocity_mps=velocity
    )


def corners(objs: ObjectColumns, dt_s: float = 0.0) -> F64:
    """Footprint corners (M, 4, 2) of ``objs`` after ``dt_s`` at constant velocity."""
    xy = objs.center_m[:, :2] + dt_s * objs.velocity_mps[:, :2]
    return rectangle_corners(xy, objs.yaw_rad, objs.size_m[:, 0], objs.size_m[:, 1])


def speed_mps(objs: ObjectColumns) -> F64:
    """(M,) planar speed of each object."""
    v = objs.velocity_mps
    return np.asarray(np.hypot(v[:, 0], v[:, 1]), dtype=np.float64)


def bearing_rad(ego_xy: F64, ego_heading: float, points: F64) -> F64:
    """|angle| (M,) between the ego heading and the direction rear axle → each point."""
    d = np.asarray(points, dtype=np.float64).reshape(-1, 2) - ego_xy
    ang = np.arctan2(d[:, 1], d[:, 0]) - ego_heading
    return np.abs((ang + math.pi) % (2.0 * math.pi) - math.pi)


class RoadIndex(RoadMapIndex):
    """The metrics' questions to a :class:`RoadMap`, answered by its indexed queries
    (:class:`~redrive.maps.index.RoadMapIndex`, built once per evaluation) over the lanes cars
    drive in (:data:`~redrive.maps.index.DRIVABLE_LANE_KINDS`: nuPlan's lanes, not bicycle
    lanes)."""

    def __init__(self, road_map: RoadMap) -> None:
        super().__init__(road_map, lane_kinds=DRIVABLE_LANE_KINDS)
        self.lanes = road_map.lanes

    def lanes_containing(self, points: F64) -> npt.NDArray[np.bool_]:
        """(L, K): lane l contains point k (its boundary included)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        which, lane = self.lane_hits(p)
        out = np.zeros((len(self.lanes), p.shape[0]), dtype=bool)
        out[lane, which] = True
        return out

    def distance_outside(self, points: F64) -> F64:
        """(K,) distance of each point to the drivable area, m (0 inside or on it)."""
        return self.distance_outside_drivable_m(np.asarray(points, dtype=np.float64).reshape(-1, 2))

    def in_multiple_lanes(self, corners: F64) -> bool:
        """NAVSIM's ``MULTIPLE_LANES`` area: more than one lane holds a corner and no lane holds
        all four (the ego straddles lanes, as in a lane change)."""
        held = self.lanes_at(np.asarray(corners, dtype=np.float64).reshape(-1, 2))
        every = {lane for lanes in held for lane in lanes}
        return len(every) > 1 and not set.intersection(*(set(h) for h in held))

    def off_road(self, corners: F64) -> bool:
        """A corner lies outside the drivable area (NAVSIM's ``NON_DRIVABLE_AREA``)."""
        return bool(not self.footprint_on_drivable_area(np.asarray(corners).reshape(1, -1, 2))[0])

    def lane_tangent(self, lane: int, point: F64) -> F64:
        """Unit direction of travel (2,) of lane ``lane`` nearest ``point``."""
        _, _, heading = self.station(
            np.asarray(point, dtype=np.float64).reshape(1, 2), [self.lanes[lane].lane_id]
        )
        return np.array([math.cos(float(heading[0])), math.sin(float(heading[0]))])


def road_index(data: EvalData) -> RoadIndex | None:
    """The run's road map as a :class:`RoadIndex`, None when it has none (cached per data)."""
    road_map = data.road_map()
    if road_map is None:
        return None
    cache = data._cache  # one index per EvalData, shared by every road metric of the evaluation
    index = cache.get("road_index")
    if not isinstance(index, RoadIndex):
        index = RoadIndex(road_map)
        cache["road_index"] = index
    return index


def require_road(data: EvalData) -> RoadIndex:
    index = road_index(data)
    if index is None:
        raise MetricSkipped(
            "no road map in the run (runs of a synthetic scenario or its log store one; recorded logs have none)"
        )
    return index


@dataclass(frozen=True, slots=True)
class Collision:
    """The first contact of the ego with one object (nuPlan counts each track once)."""

    frame: int
    object_id: int
    object_class: ObjectClass
    kind: str  # nuPlan CollisionType, lower case: stopped_ego, stopped_track, active_front …
    at_fault: bool
    relative_speed_mps: float


def classify(
    objs: ObjectColumns,
    m: int,
    *,
    ego_xy: F64,
    ego_heading: float,
    ego_speed: float,
    ego_corners: F64,
    straddling: bool | None,
    stopped_speed_mps: float = STOPPED_SPEED_MPS,
) -> tuple[str, bool]:
    """nuPlan's ``_get_collision_type`` and at-fault rule for object ``m`` touching the ego.

    ``straddling``: the ego's footprint is not in one common or connected lane (nuPlan's
    ``classify_at_fault_collisions``: "in multiple lanes or nondrivable area"; None: no map,
    then a lateral collision is never at fault)."""
    obj_corners = corners(objs)[m]
    if ego_speed <= stopped_speed_mps:
        return "stopped_ego", False
    if float(speed_mps(objs)[m]) <= stopped_speed_mps:
        return "stopped_track", True
    if float(bearing_rad(ego_xy, ego_heading, objs.center_m[m : m + 1, :2])[0]) > BEHIND_ANGLE_RAD:
        return "active_rear", False
    front = shapely.LineString([ego_corners[0], ego_corners[3]])
    if front.intersects(shapely.Polygon(obj_corners)):
        return "active_front", True
    return "active_lateral", bool(straddling)


@dataclass(slots=True)
class SceneData:
    """Per frame of the ego track: its objects in the map frame and the map's verdicts."""

    ego: EgoRun
    corners: F64
    objects: dict[int, ObjectColumns] = field(default_factory=dict)
    #: nuPlan: the footprint is *not* in one common or connected lane (None: no map)
    straddling: dict[int, bool | None] = field(default_factory=dict)
    #: NAVSIM: the ego is in multiple lanes or off the drivable area (None: no map)
    multiple_lanes_or_off_road: dict[int, bool | None] = field(default_factory=dict)


def scene(data: EvalData, params: Mapping[str, Any]) -> SceneData:
    """The ego, its footprints and each frame's ground truth in the map frame (cached)."""
    key = "closedloop_scene:" + ",".join(f"{params[k]!r}" for k in EGO_DEFAULTS)
    cached = data._cache.get(key)
    if isinstance(cached, SceneData):
        return cached
    ego = ego_run(data)
    truth = data.ground_truth()
    road = road_index(data)
    corners = ego.corners(params)
    out = SceneData(ego=ego, corners=corners)
    one_lane = None if road is None else corners_in_common_or_connected_lanes(road, corners)
    for i, frame in enumerate(ego.frames.tolist()):
        objs = truth.get(frame)
        if objs is None:
            continue
        out.objects[frame] = map_objects(objs, ego.xy[i], float(ego.heading_rad[i]))
        if road is None or one_lane is None:
            out.straddling[frame] = None
            out.multiple_lanes_or_off_road[frame] = None
            continue
        out.straddling[frame] = not bool(one_lane[i])
        out.multiple_lanes_or_off_road[frame] = road.in_multiple_lanes(corners[i]) or road.off_road(
            corners[i]
        )
    data._cache[key] = out
    return out


def find_collisions(
    sc: SceneData, *, stopped_speed_mps: float = STOPPED_SPEED_MPS
) -> list[Collision]:
    """Every new contact of the ego footprint with a ground-truth box, classified (nuPlan's
    ``_find_new_collisions``: a track collides once, later frames leave it out; stopped below
    ``stopped_speed_mps``, ``_get_collision_type``'s ``stopped_speed_threshold``)."""
    seen: set[int] = set()
    found: list[Collision] = []
    ego = sc.ego
    for i, frame in enumerate(ego.frames.tolist()):
        objs = sc.objects.get(frame)
        if objs is None or len(objs) == 0:
            continue
        touching = rectangles_overlap(sc.corners[i][None], corners(objs))
        for m in np.flatnonzero(touching):
            oid = int(objs.object_id[m])
            if oid in seen:
                continue
            seen.add(oid)
            kind, at_fault = classify(
                objs,
                int(m),
                ego_xy=ego.xy[i],
                ego_heading=float(ego.heading_rad[i]),
                ego_speed=float(ego.speed_mps[i]),
                ego_corners=sc.corners[i],
                straddling=sc.straddling.get(frame),
                stopped_speed_mps=stopped_speed_mps,
            )
            h = float(ego.heading_rad[i])
            ego_v = float(ego.speed_mps[i]) * np.array([math.cos(h), math.sin(h)])
            found.append(
                Collision(
                    frame=frame,
                    object_id=oid,
                    object_class=objs.object_class[m],
                    kind=kind,
                    at_fault=at_fault,
                    relative_speed_mps=float(np.hypot(*(ego_v - objs.velocity_mps[m, :2]))),
                )
            )
    return found


#: nuPlan ``VRU_types`` (an at-fault collision with one counts against ``max_violations_vru``);
#: the other agent classes count as vehicles.
VRU_CLASSES = frozenset({ObjectClass.PEDESTRIAN, ObjectClass.BICYCLE})


def collision_score(
    collisions: Sequence[Collision],
    *,
    max_violations_vru: int = 0,
    max_violations_vehicle: int = 0,
    max_violations_object: int = 1,
) -> float:
    """nuPlan ``EgoAtFaultCollisionStatistics.compute_score`` (NAVSIM's NC): 1 without at-fault
    collisions; else the product over VRUs, vehicles and objects of ``max(0, 1 − n / (m + 1))``
    for n at-fault collisions of that kind and its threshold m (the config's
    ``max_violation_threshold_vru`` 0, ``_vehicle`` 0, ``_object`` 1): 0 after one with an
    agent, 0.5 after one with an object, 0 after two."""
    fault = [c for c in collisions if c.at_fault]
    if not fault:
        return 1.0
    vru = sum(c.object_class in VRU_CLASSES for c in fault)
    vehicle = sum(c.object_class in AGENT_CLASSES - VRU_CLASSES for c in fault)
    objects = len(fault) - vru - vehicle
    score = 1.0
    for n, m in (
        (vru, max_violations_vru),
        (vehicle, max_violations_vehicle),
        (objects, max_violations_object),
    ):
        score *= max(0.0, 1.0 - n / (m + 1))
    return score


COLLISION_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {
        **EGO_DEFAULTS,
        "max_violations_vru": 0,
        "max_violations_vehicle": 0,
        "max_violations_object": 1,
        "stopped_speed_mps": STOPPED_SPEED_MPS,
    }
)


def collision_params(p: Mapping[str, Any]) -> dict[str, int]:
    """The :func:`collision_score` thresholds of a metric's parameters."""
    return {k: int(p[k]) for k in COLLISION_DEFAULTS if k.startswith("max_violations_")}


def series(frames: Sequence[int] | npt.NDArray[np.int64], values: Sequence[float] | F64) -> Series:
    return np.asarray(frames, dtype=np.int64), np.asarray(values, dtype=np.float64)
