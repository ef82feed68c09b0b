"""The world's agents in plain Python — the reference the compiled kernels are compared with.

The world moves its lane followers and its scripted ego with compiled kernels
(:class:`~redrive.sim.fleet.LaneFleet`, :class:`~redrive.sim.gaps.GapSearch`,
:class:`~redrive.sim.stepper.FrameStepper`), each bit for bit what is here:

- :func:`gap_ahead`: the nearest obstacle ahead on a route (``GapSearch``);
- :func:`light_gap`: the first stop line ahead that must be respected;
- :class:`ReferenceFollower`: a :class:`~redrive.sim.agents.LaneFollower` that plans (lane
  change, gap, stop lines, IDM, scripted braking) and advances itself (``LaneFleet``);
- :func:`steer` and :func:`accelerate`: the scripted ego's pure pursuit and IDM
  (:class:`~redrive.sim.ego.EgoDriver`'s parameters and state; the frame kernel).
"""

from __future__ import annotations

import math

import numpy as np

from redrive.motion import idm_acceleration
from redrive.sim.agents import LaneFollower, Obstacles, advance_1d
from redrive.sim.ego import BicycleModel, EgoDriver
from redrive.sim.lights import TrafficLights
from redrive.sim.roads import Route
from redrive.types import LightState

__all__ = ["ReferenceFollower", "accelerate", "gap_ahead", "light_gap", "steer"]

_NO_GAP = math.inf


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


class ReferenceFollower(LaneFollower):
    """A :class:`LaneFollower` that plans and moves itself, one Python object per vehicle."""

    def __init__(self, *args: object, **kw: object) -> None:
        super().__init__(*args, **kw)  # type: ignore[arg-type]
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


def steer(driver: EgoDriver, model: BicycleModel) -> float:
    """The scripted ego's step up to the gap search: find the ego on the route again and return the
    steering angle (rad); then search along ``route`` from ``s_m + center_offset_m`` (the
    box centre) and ``s_m + front_offset_m`` (the front) for the ego's width, and call
    :func:`accelerate` with the result (the world batches all agents' searches)."""
    g = model.geometry
    driver.s_m, _ = driver.route.project_point(
        model.x_m, model.y_m, s_min_m=driver.s_m - 2.0, s_max_m=driver.s_m + 10.0
    )
    v = model.speed_mps
    look = min(max(driver.lookahead_time_s * v, driver.min_lookahead_m), driver.max_lookahead_m)
    tx, ty, _ = driver.route.pose_at(driver.s_m + look)
    dx, dy = tx - model.x_m, ty - model.y_m
    c, sn = math.cos(model.yaw_rad), math.sin(model.yaw_rad)
    lx, ly = c * dx + sn * dy, -sn * dx + c * dy
    dist = max(math.hypot(lx, ly), 1e-6)
    return math.atan2(2.0 * g.wheelbase_m * ly, dist * dist)


def accelerate(
    driver: EgoDriver,
    model: BicycleModel,
    time_s: float,
    lights: TrafficLights,
    *,
    gap_m: float,
    leader_speed_mps: float,
) -> float:
    """The scripted ego's step after the gap search: the stop lines, the route's end and IDM (m/s²)."""
    gap, v_lead = gap_m, leader_speed_mps
    v = model.speed_mps
    s_front = driver.s_m + model.geometry.front_offset_m
    stop = light_gap(
        driver.route,
        lights,
        s_front_m=s_front,
        speed_mps=v,
        time_s=time_s,
        comfort_decel_mps2=driver.idm.comfort_decel_mps2,
        committed=driver._committed,
    )
    end = driver.route.length_m - 1.0 - s_front
    if min(stop, end) < gap:
        gap, v_lead = min(stop, end), 0.0
    return idm_acceleration(driver.idm, v, gap_m=gap, leader_speed_mps=v_lead)
