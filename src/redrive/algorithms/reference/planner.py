"""A reference planner: follow a route or the current lane with an IDM speed profile.

:class:`IdmPlanner` plans ``horizon_s`` seconds ahead every frame, from the frame's ego state alone
(no memory of earlier plans except where it was on the route):

* **Where** — the path geometry (a polyline in base_link, the rear-axle centre at the origin). With
  a ``route`` in the config (a list of [x, y] points in the frame of ``frame.vehicle_state``,
  usually ``map``) — else the route of the run's mission (``Algorithm.use_mission``: a closed
  loop on a recorded log with a road map hands over the logged ego path mapped onto the lane
  graph, its lanes' centrelines) — the path is the part of the route ahead of the ego's
  projection onto it. Without a route the planner assumes the lane is what the ego is doing: an arc of
  constant curvature ``yaw_rate / speed`` (clamped to ``max_curvature_1pm``; straight below
  ``min_turn_speed_mps``), at most half a turn long (a plan that goes farther continues straight;
  the speed is not limited on the arc's curve).  On a route the speed is limited for the curves
  ahead: the IDM's desired speed becomes ``min(v0, min_j √(a_lat / |κ_j| + 2·b·d_j))`` — every
  curve within ``range_m`` (curvature κ_j, ``d_j`` ahead of the front bumper) reached at
  ``max_lateral_accel_mps2`` at most, braking for it at ``b_mps2``.
* **How fast** — the Intelligent Driver Model (Treiber, Hennecke & Helbing 2000)::

      a = a_max · [1 − (v / v0)^δ − (s* / s)²],   s* = s0 + max(0, v·T + v·Δv / (2·√(a_max·b)))

  integrated forward from the current speed with step ``dt_s`` (ballistic update, never
  reversing). ``s`` is the gap from the ego's front bumper to the nearest obstacle in the path
  corridor ahead; every obstacle is predicted at constant speed along the path, so a stopped one
  ends the plan ``s0_m`` behind it. The end of a route is a stopped obstacle too. As a guard
  against the discretisation, the plan never moves the bumper closer than ``s0_m`` to an obstacle
  (and does not move at all while it is already closer).

* **Traffic lights** — with a road map (:attr:`Algorithm.road_map`, which synthetic logs and
  scenarios hand over) and light states in ``frame.traffic``, the stop line of a light showing
  red — or yellow while the ego can still stop comfortably (``v² / (2 b)`` within the gap) —
  that the path crosses in its lane's direction is a stopped obstacle at the line (the IDM stops
  ``s0_m`` before it); a yellow it cannot stop for is driven through, until the light is green
  again (:mod:`redrive.algorithms.reference._lights`).  ``traffic_lights = false`` ignores them.

Obstacles are the objects of the last perception algorithm upstream (boxes in base_link of the
frame). One is in the path when the lateral extent of its box (its corners projected onto the path)
overlaps the corridor ``±corridor_half_width_m`` around the path and part of it is ahead of the
front bumper within ``range_m`` of path. Its speed along the path is its velocity (taken as
over-ground, in base_link axes) projected on the path tangent there, floored at 0 (oncoming
traffic in the lane is planned for as stopped). When a perception algorithm ran but failed on this
frame, planning blind is unsafe and the step raises :class:`AlgorithmError`; with no perception
stage at all the road is planned as empty.

Configuration (SI units):

=======================  ========  ==========================================================
key                      default   meaning
=======================  ========  ==========================================================
route                    None      [[x, y], …] metres in the ego state's frame; None: the
                                   mission's route, else the lane arc
v0_mps                   13.9      IDM desired speed (50 km/h)
T_s                      1.5       IDM time headway
a_mps2                   1.5       IDM maximum acceleration
b_mps2                   2.0       IDM comfortable deceleration
s0_m                     2.0       IDM minimum gap (bumper to obstacle) at standstill
delta                    4.0       IDM acceleration exponent
horizon_s                6.0       plan length in time
dt_s                     0.1       integration step = waypoint spacing in time
max_decel_mps2           8.0       the plan's deceleration is clipped to this (physical limit)
corridor_half_width_m    1.5       half width of the path corridor (ego half width + margin)
range_m                  120.0     how far along the path obstacles are looked for
ego_length_m             4.7       ego length, bumper to bumper
rear_overhang_m          0.95      rear bumper to rear axle; front bumper = length − overhang
max_curvature_1pm        0.2       lane-arc curvature limit (radius ≥ 5 m)
min_turn_speed_mps       1.0       below this speed the lane arc is straight
max_route_offset_m       10.0      farther from the route than this is an error
max_lateral_accel_mps2   3.0       on a route: slow for its curves to at most this lateral
                                   acceleration (``v ≤ √(a / κ)``, braking at ``b_mps2`` to
                                   reach each curve at its speed); 0: no curve limit
perception               None      name of the perception algorithm to read; None: the last
traffic_lights           true      stop at red (and stoppable yellow) lights of the road map
=======================  ========  ==========================================================
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any, ClassVar, cast

import numpy as np
import numpy.typing as npt

from redrive.algorithms.base import VEHICLE_STATE, Algorithm, Input, Role, StageOutputs
from redrive.algorithms.reference._kernels import project_on_segments
from redrive.algorithms.reference._lights import Gate, gates_of, stop_arcs
from redrive.algorithms.reference._plan_kernels import (
    box_frames,
    curve_speed,
    gate_crossing,
    idm_profile,
    leaders_on_path,
    path_bounds,
    points_at,
    polyline_arc,
)
from redrive.errors import AlgorithmError, ConfigError
from redrive.geometry.boxes import BOX_CORNER_SIGNS
from redrive.types import (
    DetectedObject,
    Frame,
    Mission,
    ObjectColumns,
    PlannedPath,
    RoadMap,
    SensorType,
    VehicleState,
)
from redrive.types._drafts import draft_class

__all__ = ["IdmPlanner", "Polyline"]

logger = logging.getLogger(__name__)

F64 = npt.NDArray[np.float64]

_ARC_SAMPLE_M = 0.5
_ARC_SAGITTA_M = 1e-3
_ROUTE_WINDOW_BACK_M = 10.0
_ROUTE_WINDOW_AHEAD_M = 60.0
#: the curvature of a route is the heading change over this arc (m), sampled every
#: _CURVE_SAMPLE_M (a lane centreline's vertices are seconds apart, its curvature noisy)
_CURVE_WINDOW_M = 4.0
_CURVE_SAMPLE_M = 1.0


class Polyline:
    """A 2D polyline parametrised by arc length.

    Attributes:
        xy: (M, 2) float64 vertices, metres (consecutive duplicates removed; M ≥ 1).
        s: (M,) float64 cumulative arc length at the vertices, metres, ``s[0] == 0``.
    """

    def __init__(self, xy: npt.ArrayLike) -> None:
        pts = np.ascontiguousarray(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        if len(pts) > 1:  # one compiled pass: the duplicates dropped, the running hypot
            self.xy, self.s = polyline_arc(pts)
        else:
            self.xy = pts
            self.s = np.zeros(1)

    @property
    def length_m(self) -> float:
        return float(self.s[-1])

    def points_at(self, s_m: npt.ArrayLike) -> F64:
        """(K, 2) points at arc lengths ``s_m`` (K,); beyond either end the end segment is
        extended straight."""
        s = np.ascontiguousarray(np.asarray(s_m, dtype=np.float64).reshape(-1))
        return points_at(self.xy, self.s, s)

    def project(
        self, points: npt.ArrayLike, *, s_min_m: float = -math.inf, s_max_m: float = math.inf
    ) -> tuple[F64, F64, F64]:
        """Nearest points on the polyline (only segments overlapping [s_min_m, s_max_m]).

        Returns:
            s: (P,) arc length of the foot point, metres.
            lateral: (P,) signed offset of the point from the polyline, metres, left positive.
            dist: (P,) distance to the foot point, metres (≥ |lateral| at the ends).
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(self.xy) == 1:
            d = p - self.xy[0]
            dist = np.hypot(d[:, 0], d[:, 1])
            return np.zeros(len(p)), d[:, 1], dist
        seg_ok = (self.s[1:] >= s_min_m) & (self.s[:-1] <= s_max_m)
        if not np.any(seg_ok):
            seg_ok[:] = True
        idx = np.flatnonzero(seg_ok)
        a = self.xy[idx]
        ab = self.xy[idx + 1] - a
        seg_len = np.hypot(ab[:, 0], ab[:, 1])
        return project_on_segments(np.ascontiguousarray(p), a, ab, seg_len, self.s[idx])

    def cut(self, s_start_m: float, s_end_m: float) -> Polyline:
        """The part between two arc lengths (clipped to the polyline) as a new polyline."""
        s0 = min(max(s_start_m, 0.0), self.length_m)
        s1 = min(max(s_end_m, s0), self.length_m)
        inner = (self.s > s0) & (self.s < s1)
        ends = self.points_at([s0, s1])
        return Polyline(np.vstack([ends[:1], self.xy[inner], ends[1:]]))


def _positive(config: Mapping[str, Any], key: str, *, allow_zero: bool = False) -> float:
    try:
        value = float(config[key])
    except (TypeError, ValueError) as err:
        msg = f"IdmPlanner config {key!r} must be a number, got {config[key]!r}"
        raise ConfigError(msg) from err
    if not math.isfinite(value) or value < 0.0 or (value == 0.0 and not allow_zero):
        need = "≥ 0" if allow_zero else "> 0"
        msg = f"IdmPlanner config {key!r} must be finite and {need}, got {value}"
        raise ConfigError(msg)
    return value


class IdmPlanner(Algorithm):
    """Route or lane following with an IDM speed profile that stops for obstacles in the path.

    Reads ``frame.vehicle_state`` and the objects of the last perception algorithm upstream;
    returns a :class:`PlannedPath` in base_link of the frame: one waypoint per ``dt_s`` over
    ``horizon_s`` (x, y, z metres of the rear-axle centre, z = 0; t_s from ``frame.stamp_ns``).
    See the module docstring for the model and the configuration.
    """

    role: ClassVar[Role] = Role.PLANNING
    inputs: ClassVar[tuple[Input, ...]] = (VEHICLE_STATE,)
    version: ClassVar[str] = "1"
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            "route": None,
            "v0_mps": 13.9,
            "T_s": 1.5,
            "a_mps2": 1.5,
            "b_mps2": 2.0,
            "s0_m": 2.0,
            "delta": 4.0,
            "horizon_s": 6.0,
            "dt_s": 0.1,
            "max_decel_mps2": 8.0,
            "corridor_half_width_m": 1.5,
            "range_m": 120.0,
            "ego_length_m": 4.7,
            "rear_overhang_m": 0.95,
            "max_curvature_1pm": 0.2,
            "min_turn_speed_mps": 1.0,
            "max_route_offset_m": 10.0,
            "max_lateral_accel_mps2": 3.0,
            "perception": None,
            "traffic_lights": True,
        }
    )

    def __init__(self, *, name: str | None = None) -> None:
        super().__init__(name=name)
        self._route: Polyline | None = None
        self._route_s_m: float | None = None
        self._gates: tuple[Gate, ...] = ()
        self._committed: set[str] = set()  # yellow lights it drives through
        #: the plan's waypoint times (read-only) and the (steps, dt) they are for
        self._times: tuple[tuple[int, float], F64] | None = None
        self.setup(self.config)

    def setup(self, config: Mapping[str, Any]) -> None:
        self.v0_mps = _positive(config, "v0_mps")
        self.headway_s = _positive(config, "T_s", allow_zero=True)
        self.a_mps2 = _positive(config, "a_mps2")
        self.b_mps2 = _positive(config, "b_mps2")
        self.s0_m = _positive(config, "s0_m", allow_zero=True)
        self.delta = _positive(config, "delta")
        self.horizon_s = _positive(config, "horizon_s")
        self.dt_s = _positive(config, "dt_s")
        if self.dt_s > self.horizon_s:
            msg = f"IdmPlanner: dt_s ({self.dt_s}) must not exceed horizon_s ({self.horizon_s})"
            raise ConfigError(msg)
        self.max_decel_mps2 = _positive(config, "max_decel_mps2")
        self.corridor_half_width_m = _positive(config, "corridor_half_width_m")
        self.range_m = _positive(config, "range_m")
        length_m = _positive(config, "ego_length_m")
        overhang_m = _positive(config, "rear_overhang_m", allow_zero=True)
        self.front_offset_m = length_m - overhang_m
        self.max_curvature_1pm = _positive(config, "max_curvature_1pm", allow_zero=True)
        self.min_turn_speed_mps = _positive(config, "min_turn_speed_mps", allow_zero=True)
        self.max_route_offset_m = _positive(config, "max_route_offset_m")
        self.max_lateral_accel_mps2 = _positive(config, "max_lateral_accel_mps2", allow_zero=True)
        perception = config.get("perception")
        if perception is not None and not isinstance(perception, str):
            msg = f"IdmPlanner config 'perception' must be an algorithm name or None, got {perception!r}"
            raise ConfigError(msg)
        self.perception: str | None = perception
        obey = config.get("traffic_lights", True)
        if not isinstance(obey, bool):
            msg = f"IdmPlanner config 'traffic_lights' must be true or false, got {obey!r}"
            raise ConfigError(msg)
        self.obey_lights = obey
        self._route = self._parse_route(config.get("route"))
        self._route_s_m = None
        #: the straight path ahead without a route (it depends on range_m alone): built once
        self._straight: Polyline | None = None

    @staticmethod
    def _parse_route(route: object) -> Polyline | None:
        if route is None:
            return None
        try:
            pts = np.asarray(route, dtype=np.float64)
        except (TypeError, ValueError) as err:
            msg = f"IdmPlanner config 'route' must be a list of [x, y] points, got {route!r:.80}"
            raise ConfigError(msg) from err
        if pts.ndim != 2 or pts.shape[1] != 2 or not np.all(np.isfinite(pts)):
            msg = (
                f"IdmPlanner config 'route' must be finite [x, y] points (shape (N, 2)), got "
                f"shape {pts.shape}"
            )
            raise ConfigError(msg)
        line = Polyline(pts)
        if line.length_m <= 0.0:
            msg = "IdmPlanner config 'route' needs at least two distinct points"
            raise ConfigError(msg)
        return line

    def reset(self) -> None:
        self._route_s_m = None
        self._committed = set()

    def use_road_map(self, road_map: RoadMap | None) -> None:
        """Keep the map and the stop lines of its traffic lights (the gates the step obeys)."""
        super().use_road_map(road_map)
        self._gates = gates_of(road_map)

    def use_mission(self, mission: Mission | None) -> None:
        """Without a ``route`` in the config, follow the mission's route (a closed loop on a
        recorded log: the logged ego path on the map's lane graph) when it has one."""
        super().use_mission(mission)
        if self.config.get("route") is None:
            self._route = (
                Polyline(mission.route_xy) if mission is not None and mission.has_route else None
            )
            self._route_s_m = None

    def bind(self, sensors: Mapping[str, SensorType], *, extras: Iterable[str] = ()) -> None:
        """As :meth:`Algorithm.bind`, then one made-up plan's profile and projection, so that
        numba loads the planner's kernels from the cache (or compiles them after an install)
        here, before a run's first frame, not inside that frame's latency."""
        super().bind(sensors, extras=extras)
        self.warm_kernels()

    def warm_kernels(self) -> None:
        """The made-up plan of :meth:`bind` (configured, not bound, is enough): numba's kernels
        loaded in this process (also by :mod:`redrive.batch.preload`)."""
        self._profile(1.0, np.array([30.0]), np.array([0.0]))
        line = Polyline([[0.0, 0.0], [1.0, 0.0]])
        line.project([[0.5, 0.5]])
        line.points_at([0.5])
        # the leaders' kernels with the argument types _leaders gives them (the objects' yaws,
        # sizes, centres and velocities are read-only ObjectColumns arrays)
        frozen = np.zeros((1, 3))
        frozen.flags.writeable = False
        yaws = np.zeros(1)
        yaws.flags.writeable = False
        box_frames(yaws, frozen, BOX_CORNER_SIGNS)
        leaders_on_path(np.zeros((1, 8, 3)), frozen, frozen, line.xy, line.s, 1.0, 0.0, 1.0)
        # a stop line's test (_lights.stop_arcs), with the arrays' types a step gives it
        gate_crossing(line.xy, line.s, np.zeros((2, 2)), 0.0, 0.0, 1.0, 1.0)
        path_bounds(line.xy)
        curve_speed(line.xy, line.s, 1.0, _CURVE_SAMPLE_M, 4, 1.0, 1.0, 0.0)

    # -- the step -----------------------------------------------------------------------------

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        state = frame.vehicle_state
        if state is None:
            msg = (
                f"{self.name}: frame {frame.index} (stamp {frame.stamp_ns} ns) has no vehicle "
                "state; the planner needs the ego pose and speed"
            )
            raise AlgorithmError(msg)
        objects = self._objects(frame, upstream)
        speed_mps = state.speed_mps
        path, route_end_m = self._geometry(frame, state, speed_mps)
        leaders_s, leaders_v = self._leaders(path, objects)
        if route_end_m is not None:
            leaders_s = np.concatenate((leaders_s, (route_end_m,)))
            leaders_v = np.concatenate((leaders_v, (0.0,)))
        lights = frame.traffic.traffic_lights
        if self.obey_lights and self._gates and lights:
            stops = stop_arcs(
                self._gates,
                lights,
                state=state,
                path_xy=path.xy,
                path_s=path.s,
                front_offset_m=self.front_offset_m,
                comfort_decel_mps2=self.b_mps2,
                committed=self._committed,
            )
            if stops.size:  # (np.append's values: the leaders, then the lines, stopped)
                leaders_s = np.concatenate((leaders_s, stops))
                leaders_v = np.concatenate((leaders_v, np.zeros(stops.size)))
        v0_mps = self.v0_mps
        if self._route is not None and self.max_lateral_accel_mps2 > 0.0:
            v0_mps = min(v0_mps, self._curve_speed_mps(path))
        t_s, s_m = self._profile(speed_mps, leaders_s, leaders_v, v0_mps=v0_mps)
        # np.column_stack([xy, zeros, t_s])'s array, filled in place
        waypoints = np.empty((len(t_s), 4))
        waypoints[:, :2] = path.points_at(s_m)
        waypoints[:, 2] = 0.0
        waypoints[:, 3] = t_s
        return _trusted_path(frame.stamp_ns, waypoints)

    def _objects(self, frame: Frame, upstream: StageOutputs) -> tuple[DetectedObject, ...]:
        objects = upstream.objects(self.perception)
        if objects is not None:
            return objects
        if self.perception is not None or Role.PERCEPTION in upstream.roles.values():
            which = repr(self.perception) if self.perception else "the perception stage"
            msg = (
                f"{self.name}: {which} produced no objects for frame {frame.index} (stamp "
                f"{frame.stamp_ns} ns; its step failed); refusing to plan blind — fix the "
                "perception error first"
            )
            raise AlgorithmError(msg)
        return ()

    def _geometry(
        self, frame: Frame, state: VehicleState, speed_mps: float
    ) -> tuple[Polyline, float | None]:
        """The path ahead in base_link (starting at the ego or its projection on the route) and,
        when the route ends within ``range_m``, the arc length of its end."""
        if self._route is None:
            kappa = 0.0
            if speed_mps >= max(self.min_turn_speed_mps, 1e-6):
                kappa = state.yaw_rate_rad_s / speed_mps
                kappa = min(max(kappa, -self.max_curvature_1pm), self.max_curvature_1pm)
            length_m = self.range_m
            if abs(kappa) <= 1e-9:  # straight ahead: the same path every frame
                if self._straight is None:
                    s = np.linspace(0.0, length_m, max(2, math.ceil(length_m / _ARC_SAMPLE_M) + 1))
                    self._straight = Polyline(np.column_stack([s, np.zeros_like(s)]))
                return self._straight, None
            length_m = min(length_m, math.pi / abs(kappa))
            # chord error (sagitta) ≤ 1 mm
            step_m = min(_ARC_SAMPLE_M, math.sqrt(8.0 * _ARC_SAGITTA_M / abs(kappa)))
            s = np.linspace(0.0, length_m, max(2, math.ceil(length_m / step_m) + 1))
            xy = np.column_stack([np.sin(kappa * s) / kappa, (1.0 - np.cos(kappa * s)) / kappa])
            return Polyline(xy), None
        route = self._route
        origin = state.position[:2]
        c, sn = math.cos(state.heading_rad), math.sin(state.heading_rad)
        s_ego, dist = self._locate(origin)
        if dist > self.max_route_offset_m:
            msg = (
                f"{self.name}: on frame {frame.index} the ego is {dist:.1f} m from the route "
                f"(more than max_route_offset_m = {self.max_route_offset_m} m); check that the "
                f"route is in the ego state's frame {state.frame_id!r}"
            )
            raise AlgorithmError(msg)
        self._route_s_m = s_ego
        ahead = route.cut(s_ego, s_ego + self.range_m)
        d = ahead.xy - origin
        base_xy = np.column_stack([c * d[:, 0] + sn * d[:, 1], -sn * d[:, 0] + c * d[:, 1]])
        path = Polyline(base_xy)
        end_m = path.length_m if route.length_m - s_ego < self.range_m else None
        return path, end_m

    def _locate(self, origin: F64) -> tuple[float, float]:
        """Arc length of the ego on the route (near the last one when known) and its distance."""
        route = self._route
        assert route is not None
        if self._route_s_m is not None:
            s, _, dist = route.project(
                origin,
                s_min_m=self._route_s_m - _ROUTE_WINDOW_BACK_M,
                s_max_m=self._route_s_m + _ROUTE_WINDOW_AHEAD_M,
            )
            if dist[0] <= self.max_route_offset_m:
                return float(s[0]), float(dist[0])
        s, _, dist = route.project(origin)
        return float(s[0]), float(dist[0])

    def _leaders(self, path: Polyline, objects: tuple[DetectedObject, ...]) -> tuple[F64, F64]:
        """Arc lengths of the rears (metres) and speeds along the path (m/s) of the objects in
        the corridor ahead of the front bumper."""
        if not objects or path.length_m <= 0.0:
            return np.zeros(0), np.zeros(0)
        # the objects' columns (shared with the perception that built them with
        # DetectedObject.many: no pass over the objects), every box's corners in one stacked
        # matmul (box_corners' product, slice by slice: the same values; the unrotated corners
        # and the rotations compiled, the product numpy's — its BLAS product is not the
        # elementwise one on every host — the centres added in the kernel), then one compiled
        # call projects the 4·n bottom corners and the n centres on the path and picks the
        # leaders (:func:`._plan_kernels.leaders_on_path`)
        columns = ObjectColumns.from_objects(objects)
        local, rotations = box_frames(columns.yaw_rad, columns.size_m, BOX_CORNER_SIGNS)
        leaders_s, leaders_v = leaders_on_path(
            local @ rotations,
            columns.center_m,
            columns.velocity_mps,
            path.xy,
            path.s,
            self.corridor_half_width_m,
            self.front_offset_m,
            min(path.length_m, self.range_m) - 1e-6,
        )
        logger.debug("%s: %d object(s) in the path corridor", self.name, len(leaders_s))
        return leaders_s, leaders_v

    def _curve_speed_mps(self, path: Polyline) -> float:
        """The highest speed now from which the ego can slow down at ``b_mps2`` to every curve
        ahead on the route within ``range_m`` at a lateral acceleration of at most
        ``max_lateral_accel_mps2``: ``min_j sqrt(a_lat / |κ_j| + 2 b (s_j − front))``, κ the
        path's curvature over ``_CURVE_WINDOW_M`` (heading change per metre)."""
        length = min(path.length_m, self.range_m)
        if length < 2.0 * _CURVE_WINDOW_M:
            return math.inf
        k = max(1, round(_CURVE_WINDOW_M / _CURVE_SAMPLE_M))
        return curve_speed(
            path.xy,
            path.s,
            float(length),
            _CURVE_SAMPLE_M,
            k,
            float(self.max_lateral_accel_mps2),
            float(self.b_mps2),
            float(self.front_offset_m),
        )

    def _profile(
        self, speed_mps: float, leaders_s: F64, leaders_v: F64, *, v0_mps: float | None = None
    ) -> tuple[F64, F64]:
        """Times (s) and arc lengths of the rear axle along the path (m) of the IDM plan: the
        forward integration is one compiled call (:func:`._plan_kernels.idm_profile`)."""
        n = max(1, round(self.horizon_s / self.dt_s))
        dt = self.dt_s
        times = self._times
        if times is None or times[0] != (n, dt):  # the same times every frame: built once
            t_all = np.arange(n + 1, dtype=np.float64) * dt
            t_all.flags.writeable = False
            times = self._times = ((n, dt), t_all)
        t_out = times[1]
        s_out = idm_profile(
            float(speed_mps),
            np.ascontiguousarray(leaders_s, dtype=np.float64),
            np.ascontiguousarray(leaders_v, dtype=np.float64),
            n,
            dt,
            self.front_offset_m,
            self.s0_m,
            self.v0_mps if v0_mps is None else v0_mps,
            self.delta,
            self.headway_s,
            self.a_mps2,
            self.b_mps2,
            self.max_decel_mps2,
            2.0,
        )
        return t_out, s_out


def _trusted_path(stamp_ns: int, waypoints: F64) -> PlannedPath:
    """``PlannedPath(stamp_ns=…, waypoints=waypoints, frame_id="base_link")`` of a plan's
    (K, 4) float64 waypoints, times non-decreasing by construction: the same object (a
    read-only view of ``waypoints``), without the checks."""
    view = waypoints.view()
    view.flags.writeable = False
    path = _PathDraft()  # (redrive.types._drafts)
    path.stamp_ns = stamp_ns
    path.waypoints = view
    path.frame_id = "base_link"
    path.__class__ = PlannedPath
    return cast("PlannedPath", path)


#: PlannedPath's draft (:mod:`redrive.types._drafts`): the planner's paths are built unchecked
_PathDraft = draft_class(PlannedPath)
