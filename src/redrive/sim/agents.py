"""Agents of the synthetic world: IDM vehicles and cyclists on routes, walking pedestrians, parked cars.

Vehicles use Treiber's Intelligent Driver Model (:mod:`redrive.motion.idm`: the one kernel that
the world's compiled steps and the reference planner call too) with the gap ``s`` to the nearest
obstacle on the route ahead (another agent, the ego, a pedestrian in the lane) or to a stop line
whose light is red (or yellow, when there is room to stop comfortably): a red light is a stopped
virtual leader at the stop line.

Every update is two-phase: all agents *plan* from one :class:`Obstacles` snapshot, then all
*advance*; nothing depends on iteration order of sets or on wall-clock time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.motion import IdmParams, idm_acceleration
from redrive.sim.lights import TrafficLights
from redrive.sim.roads import Route
from redrive.types import LightState, ObjectClass

__all__ = [
    "LaneChange",
    "LaneFollower",
    "Obstacles",
    "ParkedObject",
    "Walker",
    "gap_ahead",
    "light_gap",
]

F64 = npt.NDArray[np.float64]
_NO_GAP = math.inf


@dataclass(frozen=True, slots=True, kw_only=True)
class Obstacles:
    """Footprints of everything that can block a route, map frame (arrays share the first axis).

    Attributes:
        ids: (M,) int64; centers: (M, 2) metres; lengths, widths: (M,) metres;
        velocities: (M, 2) m/s.
    """

    ids: npt.NDArray[np.int64]
    centers: F64
    lengths: F64
    widths: F64
    velocities: F64


def gap_ahead(
    route: Route,
    obstacles: Obstacles,
    *,
    s_center_m: float,
    s_front_m: float,
    width_m: float,
    self_id: int,
    horizon_m: float = 80.0,
    margin_m: float = 0.4,
) -> tuple[float, float]:
    """Gap (metres, front bumper to the obstacle's rear) and speed along the route (m/s) of the
    nearest obstacle ahead on ``route`` whose centre is within half the widths (+ margin) of it."""
    if len(obstacles.ids) == 0:
        return _NO_GAP, 0.0
    s_max = s_front_m + horizon_m
    reach = (width_m + obstacles.widths) / 2.0 + margin_m
    # project only what can be in the lane: most obstacles are far from this piece of route
    # (the same values as projecting all of them; the others could never be ahead)
    near = np.flatnonzero(
        route.near(obstacles.centers, s_min_m=s_center_m, s_max_m=s_max, radius_m=reach)
        & (obstacles.ids != self_id)
    )
    if len(near) == 0:
        return _NO_GAP, 0.0
    s, lat = route.project(obstacles.centers[near], s_min_m=s_center_m, s_max_m=s_max)
    ahead = (s > s_center_m + 1e-6) & (s < s_max - 1e-6) & (np.abs(lat) < reach[near])
    if not np.any(ahead):
        return _NO_GAP, 0.0
    gaps = np.where(ahead, s - obstacles.lengths[near] / 2.0 - s_front_m, np.inf)
    k = int(np.argmin(gaps))
    _, _, heading = route.pose_at(float(s[k]))
    vx, vy = obstacles.velocities[near[k]]
    return float(gaps[k]), float(vx * math.cos(heading) + vy * math.sin(heading))


def light_gap(
    route: Route,
    lights: TrafficLights,
    *,
    s_front_m: float,
    speed_mps: float,
    time_s: float,
    comfort_decel_mps2: float,
    committed: set[int],
) -> float:
    """Gap (metres) to the first stop line ahead that must be respected, inf if none.

    Yellow counts as red when the vehicle can stop comfortably before the line; otherwise the
    vehicle commits (its index is added to ``committed``) and ignores that line from then on.
    """
    for index, stop in enumerate(route.stop_lines):
        gap = stop.s_m - s_front_m
        if gap < -0.5 or index in committed:
            continue
        state = lights.state(stop.light_id, time_s)
        if state is LightState.GREEN:
            return _NO_GAP
        if state is LightState.YELLOW and speed_mps**2 / (2.0 * comfort_decel_mps2) > gap:
            committed.add(index)  # cannot stop comfortably: go through
            continue
        return max(gap, 0.0)
    return _NO_GAP


@dataclass(frozen=True, slots=True, kw_only=True)
class LaneChange:
    """Move onto ``target`` (an adjacent, parallel route) from ``start_time_s`` over ``duration_s``."""

    target: Route
    start_time_s: float
    duration_s: float = 3.0


class LaneFollower:
    """A vehicle or cyclist driving along a route with IDM, optionally braking hard or changing lane.

    The reference point is the box centre, at arclength ``s_m`` of ``route`` and lateral offset
    ``lateral_offset_m`` (plus the fading offset of a lane change).
    """

    def __init__(
        self,
        agent_id: int,
        object_class: ObjectClass,
        *,
        route: Route,
        s_m: float,
        speed_mps: float,
        idm: IdmParams,
        size_lwh_m: tuple[float, float, float],
        color_rgb: tuple[int, int, int],
        reflectivity: float = 0.5,
        lateral_offset_m: float = 0.0,
        obeys_lights: bool = True,
        brake_time_s: float | None = None,
        brake_decel_mps2: float = 6.0,
        lane_change: LaneChange | None = None,
    ) -> None:
        self.agent_id = agent_id
        self.object_class = object_class
        self.route = route
        self.s_m = float(s_m)
        self.speed_mps = float(speed_mps)
        self.accel_mps2 = 0.0
        self.idm = idm
        self.size_lwh_m = size_lwh_m
        self.color_rgb = color_rgb
        self.reflectivity = reflectivity
        self.lateral_offset_m = lateral_offset_m
        self.obeys_lights = obeys_lights
        self.brake_time_s = brake_time_s
        self.brake_decel_mps2 = brake_decel_mps2
        self.lane_change = lane_change
        self.active = True
        self._committed: set[int] = set()
        self._lc_offset0_m = 0.0
        self._lc_started = False
        self._time_s = 0.0

    def _lc_offset(self) -> tuple[float, float]:
        """Extra lateral offset (m) and its rate (m/s) of an ongoing lane change."""
        lc = self.lane_change
        if lc is None or not self._lc_started:
            return 0.0, 0.0
        u = min(max((self._time_s - lc.start_time_s) / lc.duration_s, 0.0), 1.0)
        fade = 1.0 - (10 * u**3 - 15 * u**4 + 6 * u**5)
        rate = -(30 * u**2 - 60 * u**3 + 30 * u**4) / lc.duration_s
        return self._lc_offset0_m * fade, self._lc_offset0_m * rate

    def pose(self) -> tuple[float, float, float]:
        """Box centre x, y (metres) and yaw (rad) in the map frame."""
        off, rate = self._lc_offset()
        x, y, heading = self.route.pose_at(self.s_m, self.lateral_offset_m + off)
        return x, y, heading + math.atan2(rate, max(self.speed_mps, 0.5))

    def velocity(self) -> tuple[float, float]:
        """Map-frame velocity (m/s)."""
        _, _, yaw = self.pose()
        return self.speed_mps * math.cos(yaw), self.speed_mps * math.sin(yaw)

    def plan(self, time_s: float, obstacles: Obstacles, lights: TrafficLights) -> None:
        """Choose the acceleration for the next step from the snapshot ``obstacles``."""
        self.start_plan(time_s)
        half_l = self.size_lwh_m[0] / 2.0
        gap, v_lead = gap_ahead(
            self.route,
            obstacles,
            s_center_m=self.s_m,
            s_front_m=self.s_m + half_l,
            width_m=self.size_lwh_m[1],
            self_id=self.agent_id,
        )
        self.finish_plan(time_s, lights, gap_m=gap, leader_speed_mps=v_lead)

    def start_plan(self, time_s: float) -> None:
        """:meth:`plan` up to the gap search (a lane change that starts now moves the vehicle onto
        its target route): then search along ``route`` from ``s_m`` (the box centre) and
        ``s_m + length / 2`` (the front), for the width ``size_lwh_m[1]``, and call
        :meth:`finish_plan` with the result (the world batches all agents' searches)."""
        self._time_s = time_s
        lc = self.lane_change
        if lc is not None and not self._lc_started and time_s >= lc.start_time_s:
            x, y, _ = self.pose()
            s_new, lat = lc.target.project([[x, y]], s_min_m=0.0, s_max_m=lc.target.length_m)
            self.route, self.s_m = lc.target, float(s_new[0])
            self._lc_offset0_m = float(lat[0]) - self.lateral_offset_m
            self._lc_started = True

    def finish_plan(
        self, time_s: float, lights: TrafficLights, *, gap_m: float, leader_speed_mps: float
    ) -> None:
        """:meth:`plan` after the gap search: the stop lines, IDM and the scripted braking."""
        gap, v_lead = gap_m, leader_speed_mps
        half_l = self.size_lwh_m[0] / 2.0
        if self.obeys_lights and lights.signals:
            stop = light_gap(
                self.route,
                lights,
                s_front_m=self.s_m + half_l,
                speed_mps=self.speed_mps,
                time_s=time_s,
                comfort_decel_mps2=self.idm.comfort_decel_mps2,
                committed=self._committed,
            )
            if stop < gap:
                gap, v_lead = stop, 0.0
        accel = idm_acceleration(self.idm, self.speed_mps, gap_m=gap, leader_speed_mps=v_lead)
        if self.brake_time_s is not None and time_s >= self.brake_time_s:
            accel = min(accel, -self.brake_decel_mps2)
        self.accel_mps2 = accel

    def advance(self, dt_s: float) -> None:
        """Move by ``dt_s`` at constant acceleration (never backwards); leave at the route end."""
        self.s_m, self.speed_mps = advance_1d(self.s_m, self.speed_mps, self.accel_mps2, dt_s)
        if self.speed_mps == 0.0 and self.accel_mps2 < 0.0:
            self.accel_mps2 = 0.0
        if self.s_m - self.size_lwh_m[0] / 2.0 > self.route.length_m:
            self.active = False


def advance_1d(s_m: float, speed_mps: float, accel_mps2: float, dt_s: float) -> tuple[float, float]:
    """Exact constant-acceleration motion over ``dt_s`` that stops at zero speed."""
    v1 = speed_mps + accel_mps2 * dt_s
    if v1 >= 0.0:
        return s_m + speed_mps * dt_s + 0.5 * accel_mps2 * dt_s * dt_s, v1
    return s_m + speed_mps * speed_mps / (-2.0 * accel_mps2), 0.0


class Walker:
    """A pedestrian walking in a straight line at constant speed once started, then standing.

    ``start_time_s`` may be ``None`` (waiting for a trigger: :meth:`start`).
    """

    def __init__(
        self,
        agent_id: int,
        *,
        start_xy: tuple[float, float],
        end_xy: tuple[float, float],
        speed_mps: float,
        start_time_s: float | None,
        size_lwh_m: tuple[float, float, float] = (0.5, 0.6, 1.75),
        color_rgb: tuple[int, int, int] = (200, 60, 60),
        reflectivity: float = 0.3,
    ) -> None:
        self.agent_id = agent_id
        self.object_class = ObjectClass.PEDESTRIAN
        self.start_xy = start_xy
        self.end_xy = end_xy
        self.speed_mps = speed_mps
        self.start_time_s = start_time_s
        self.size_lwh_m = size_lwh_m
        self.color_rgb = color_rgb
        self.reflectivity = reflectivity
        self.active = True
        dx, dy = end_xy[0] - start_xy[0], end_xy[1] - start_xy[1]
        self.distance_m = math.hypot(dx, dy)
        self.yaw_rad = math.atan2(dy, dx)
        self._time_s = 0.0

    def start(self, time_s: float) -> None:
        """Start walking at ``time_s`` (no effect if already scheduled)."""
        if self.start_time_s is None:
            self.start_time_s = time_s

    def walked_m(self) -> float:
        """Distance walked so far (metres)."""
        if self.start_time_s is None:
            return 0.0
        return min(max(self.speed_mps * (self._time_s - self.start_time_s), 0.0), self.distance_m)

    def is_walking(self) -> bool:
        return self.start_time_s is not None and 0.0 < self.walked_m() < self.distance_m

    def pose(self) -> tuple[float, float, float]:
        f = self.walked_m() / self.distance_m if self.distance_m > 0 else 0.0
        x = self.start_xy[0] + f * (self.end_xy[0] - self.start_xy[0])
        y = self.start_xy[1] + f * (self.end_xy[1] - self.start_xy[1])
        return x, y, self.yaw_rad

    def velocity(self) -> tuple[float, float]:
        if not self.is_walking():
            return 0.0, 0.0
        return self.speed_mps * math.cos(self.yaw_rad), self.speed_mps * math.sin(self.yaw_rad)

    def set_time(self, time_s: float) -> None:
        """Position is a pure function of time: set the clock (seconds since scenario start)."""
        self._time_s = time_s


@dataclass(frozen=True, slots=True, kw_only=True)
class ParkedObject:
    """A parked vehicle (ground truth, never moves): centre (metres), yaw (rad), size l/w/h."""

    agent_id: int
    object_class: ObjectClass
    center_xy: tuple[float, float]
    yaw_rad: float
    size_lwh_m: tuple[float, float, float]
    color_rgb: tuple[int, int, int]
    reflectivity: float = 0.5
