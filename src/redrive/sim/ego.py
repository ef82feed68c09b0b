"""The ego vehicle: a kinematic bicycle model and the simple "driver" that steers it along its route.

Reference point is the rear-axle centre (DESIGN.md); axes REP-103 (x forward, y left, z up).  With
the steering angle held over a step the path has constant curvature ``tan(δ)/L``, so each step is
integrated *exactly* on a circular arc (a straight line for δ = 0) for the distance travelled at
constant acceleration: a vehicle at constant speed and zero steer travels exactly ``v·t``.

The driver is not a redrive algorithm: it follows the route with pure pursuit and sets its speed with
IDM towards the set speed, stopping behind leaders, at red lights and at the end of its route.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.sim.agents import (
    IdmParams,
    Obstacles,
    advance_1d,
    gap_ahead,
    idm_acceleration,
    light_gap,
)
from redrive.sim.lights import TrafficLights
from redrive.sim.roads import Route
from redrive.types import VehicleState

__all__ = ["BicycleModel", "EgoDriver", "EgoGeometry"]


@dataclass(frozen=True, slots=True, kw_only=True)
class EgoGeometry:
    """Dimensions (metres) and actuator limits of the ego vehicle.

    ``rear_overhang_m`` is the distance from the rear bumper to the rear axle (the reference point).
    """

    wheelbase_m: float = 2.8
    length_m: float = 4.7
    width_m: float = 1.9
    height_m: float = 1.5
    rear_overhang_m: float = 0.95
    max_steer_rad: float = 0.6
    max_steer_rate_rad_s: float = 0.8
    max_accel_mps2: float = 3.0
    max_decel_mps2: float = 9.0

    @property
    def front_offset_m(self) -> float:
        """Rear axle to front bumper, metres."""
        return self.length_m - self.rear_overhang_m

    @property
    def center_offset_m(self) -> float:
        """Rear axle to the box centre (along +x of base_link), metres."""
        return self.length_m / 2.0 - self.rear_overhang_m


class BicycleModel:
    """Kinematic bicycle state: rear-axle x, y (metres, map), yaw (rad), speed (m/s), steer (rad)."""

    def __init__(
        self,
        geometry: EgoGeometry,
        *,
        x_m: float = 0.0,
        y_m: float = 0.0,
        yaw_rad: float = 0.0,
        speed_mps: float = 0.0,
        steer_rad: float = 0.0,
    ) -> None:
        self.geometry = geometry
        self.x_m, self.y_m, self.yaw_rad = float(x_m), float(y_m), float(yaw_rad)
        self.speed_mps = float(speed_mps)
        self.steer_rad = float(steer_rad)
        self.accel_mps2 = 0.0

    @property
    def curvature_1pm(self) -> float:
        """Path curvature tan(δ)/L, 1/m (left > 0)."""
        return math.tan(self.steer_rad) / self.geometry.wheelbase_m

    def step(self, dt_s: float, *, accel_mps2: float, steer_rad: float) -> None:
        """Advance ``dt_s`` seconds with a steering command (clipped to range and rate) and a
        longitudinal acceleration (clipped to the limits; the vehicle never reverses)."""
        g = self.geometry
        max_delta = g.max_steer_rate_rad_s * dt_s
        cmd = min(max(steer_rad, -g.max_steer_rad), g.max_steer_rad)
        self.steer_rad += min(max(cmd - self.steer_rad, -max_delta), max_delta)
        self.accel_mps2 = min(max(accel_mps2, -g.max_decel_mps2), g.max_accel_mps2)
        dist, self.speed_mps = advance_1d(0.0, self.speed_mps, self.accel_mps2, dt_s)
        if self.speed_mps == 0.0 and self.accel_mps2 < 0.0:
            self.accel_mps2 = 0.0
        kappa = self.curvature_1pm
        dyaw = kappa * dist
        yaw0 = self.yaw_rad
        if kappa == 0.0:
            self.x_m += dist * math.cos(yaw0)
            self.y_m += dist * math.sin(yaw0)
        else:
            self.x_m += (math.sin(yaw0 + dyaw) - math.sin(yaw0)) / kappa
            self.y_m += (math.cos(yaw0) - math.cos(yaw0 + dyaw)) / kappa
        self.yaw_rad = yaw0 + dyaw

    def state(self, stamp_ns: int) -> VehicleState:
        """The true state of the rear-axle centre in the map frame."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        v, kappa = self.speed_mps, self.curvature_1pm
        lateral = v * v * kappa
        return VehicleState(
            stamp_ns=stamp_ns,
            frame_id="map",
            position=np.array([self.x_m, self.y_m, 0.0]),
            velocity=np.array([v * c, v * s, 0.0]),
            acceleration=np.array(
                [self.accel_mps2 * c - lateral * s, self.accel_mps2 * s + lateral * c, 0.0]
            ),
            heading_rad=math.atan2(s, c),
            yaw_rate_rad_s=v * kappa,
        )

    def map_from_base(self) -> npt.NDArray[np.float64]:
        """4×4 float64 pose of base_link (rear-axle centre) in the map frame."""
        return pose_matrix(self.x_m, self.y_m, self.yaw_rad)


def pose_matrix(x_m: float, y_m: float, yaw_rad: float) -> npt.NDArray[np.float64]:
    """4×4 float64 planar pose: rotation ``yaw_rad`` about +z, translation (x, y, 0) metres."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    out = np.eye(4)
    out[0, 0], out[0, 1], out[1, 0], out[1, 1] = c, -s, s, c
    out[0, 3], out[1, 3] = x_m, y_m
    return out


class EgoDriver:
    """Pure pursuit on ``route`` and IDM towards ``idm.desired_speed_mps`` (the set speed).

    The lookahead distance is ``clip(lookahead_time_s · v, min_lookahead_m, max_lookahead_m)``.
    """

    def __init__(
        self,
        route: Route,
        s_m: float,
        *,
        idm: IdmParams,
        ego_id: int = 0,
        lookahead_time_s: float = 0.8,
        min_lookahead_m: float = 4.0,
        max_lookahead_m: float = 25.0,
    ) -> None:
        self.route = route
        self.s_m = float(s_m)
        self.idm = idm
        self.ego_id = ego_id
        self.lookahead_time_s = lookahead_time_s
        self.min_lookahead_m = min_lookahead_m
        self.max_lookahead_m = max_lookahead_m
        self._committed: set[int] = set()

    def control(
        self, model: BicycleModel, time_s: float, obstacles: Obstacles, lights: TrafficLights
    ) -> tuple[float, float]:
        """Acceleration (m/s²) and steering angle (rad) for the next step."""
        g = model.geometry
        s, _ = self.route.project(
            [[model.x_m, model.y_m]], s_min_m=self.s_m - 2.0, s_max_m=self.s_m + 10.0
        )
        self.s_m = float(s[0])
        v = model.speed_mps
        look = min(max(self.lookahead_time_s * v, self.min_lookahead_m), self.max_lookahead_m)
        tx, ty, _ = self.route.pose_at(self.s_m + look)
        dx, dy = tx - model.x_m, ty - model.y_m
        c, sn = math.cos(model.yaw_rad), math.sin(model.yaw_rad)
        lx, ly = c * dx + sn * dy, -sn * dx + c * dy
        dist = max(math.hypot(lx, ly), 1e-6)
        steer = math.atan2(2.0 * g.wheelbase_m * ly, dist * dist)
        s_front = self.s_m + g.front_offset_m
        gap, v_lead = gap_ahead(
            self.route,
            obstacles,
            s_center_m=self.s_m + g.center_offset_m,
            s_front_m=s_front,
            width_m=g.width_m,
            self_id=self.ego_id,
        )
        stop = light_gap(
            self.route,
            lights,
            s_front_m=s_front,
            speed_mps=v,
            time_s=time_s,
            comfort_decel_mps2=self.idm.comfort_decel_mps2,
            committed=self._committed,
        )
        end = self.route.length_m - 1.0 - s_front
        if min(stop, end) < gap:
            gap, v_lead = min(stop, end), 0.0
        accel = idm_acceleration(self.idm, v, gap_m=gap, leader_speed_mps=v_lead)
        return accel, steer
