"""A reference controller: pure pursuit for steering, a PID on speed for throttle and brake.

:class:`PurePursuitPid` follows the :class:`PlannedPath` of the last planning algorithm upstream
(waypoints in base_link of the frame, the rear-axle centre at the origin; REP-103, left positive):

* **Lateral** — pure pursuit (Coulter 1992). The lookahead distance is
  ``ld = lookahead_gain_s · v + lookahead_min_m``; the target point lies ``ld`` metres of arc length
  along the path from the foot of the rear axle on it (the path's last segment is extended straight
  when the path is shorter). With the target at (x, y) in base_link, ``α = atan2(y, x)`` and
  ``d = hypot(x, y)``, the road-wheel angle is ``δ = atan(2 · L · sin α / d)``, clipped to
  ``±max_steer_rad``. A path with no length (a plan at standstill) steers straight.
* **Longitudinal** — a PID on the speed error ``e = v_target − v`` (m/s), where ``v_target`` is the
  speed the waypoints imply around ``t = speed_preview_s`` (arc length over time between waypoints
  ``±`` half a waypoint step, shifted by the age of the path when it was planned on an earlier
  stamp). ``dt`` comes from the frame stamps; on the first frame (and after a gap longer than
  ``max_dt_s`` or a stamp going backwards) only the P term acts. Anti-windup: the integral is
  clipped so that its share ``ki · ∫e`` stays within ``±integral_limit``, and it is frozen while
  the output is saturated in the direction of the error or the plan accelerates or brakes (every
  frame replans from the measured speed, so the preview error during a speed change is the plan's
  own acceleration, not an offset to integrate). The output ``u`` (a signed pedal fraction) is
  split into ``throttle = clip(u, 0, 1)`` and ``brake = clip(−u, 0, 1)``: never both > 0. When the
  target and the speed are both below ``stop_speed_mps`` the controller holds the vehicle with
  ``hold_brake`` and empties the integral.

Configuration (SI units; gains are pedal fraction per unit):

====================  =======  ================================================================
key                   default  meaning
====================  =======  ================================================================
wheelbase_m           2.8      L, front to rear axle
lookahead_gain_s      0.6      lookahead distance per m/s of speed
lookahead_min_m       3.0      lookahead distance at standstill
max_steer_rad         0.6      road-wheel angle limit
speed_preview_s       0.5      when on the path the target speed is read
kp                    1.0      per m/s of speed error
ki                    0.1      per metre (m/s integrated over seconds)
kd                    0.0      per m/s² (derivative of the error; off by default: the error
                               jumps whenever the plan changes)
integral_limit        0.3      |ki · ∫e| ≤ this
integrate_below_mps2  0.3      the integral runs only while the plan's acceleration around the
                               preview time is below this: it corrects steady errors (drag,
                               grade) and does not wind up while the plan changes speed
max_dt_s              0.5      a longer gap between frames restarts the I and D terms
stop_speed_mps        0.3      below this (target and speed) the vehicle is held
hold_brake            0.4      brake while held
path                  None     name of the planning algorithm to follow; None: the last one
====================  =======  ================================================================
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from redrive.algorithms.base import VEHICLE_STATE, Algorithm, Input, Role, StageOutputs
from redrive.algorithms.reference._control_kernels import lookahead_point, path_speeds
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import ControlCommands, Frame, PlannedPath, SensorType

__all__ = ["PurePursuitPid", "path_speed_mps", "pure_pursuit_steer_rad"]

logger = logging.getLogger(__name__)

F64 = npt.NDArray[np.float64]


def pure_pursuit_steer_rad(
    xy: npt.ArrayLike, lookahead_m: float, *, wheelbase_m: float, max_steer_rad: float
) -> float:
    """Pure-pursuit road-wheel angle (rad, left positive) for a path ``xy`` (K, 2) in base_link
    (rear axle at the origin); 0 when the path has no length or the target is behind.  The
    target point is one compiled pass over the path (:func:`._control_kernels.lookahead_point`)."""
    pts = np.ascontiguousarray(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
    return _steer_rad(pts, lookahead_m, wheelbase_m=wheelbase_m, max_steer_rad=max_steer_rad)


def _steer_rad(xy: F64, lookahead_m: float, *, wheelbase_m: float, max_steer_rad: float) -> float:
    """:func:`pure_pursuit_steer_rad` on the first two columns of ``xy`` (K, ≥ 2) float64."""
    found, x, y = lookahead_point(xy, float(lookahead_m))
    if not found:
        return 0.0
    dist = math.hypot(x, y)
    if dist < 1e-6:
        return 0.0
    alpha = math.atan2(y, x)
    steer = math.atan(2.0 * wheelbase_m * math.sin(alpha) / dist)
    return min(max(steer, -max_steer_rad), max_steer_rad)


def path_speed_mps(path: PlannedPath, t_s: float) -> float:
    """The speed (m/s) the waypoints imply around ``t_s`` (seconds after ``path.stamp_ns``):
    arc length over time across one waypoint step centred on ``t_s`` (clipped to the path's
    times); 0 for a path of fewer than two distinct times."""
    return float(path_speeds(path.waypoints, np.array([float(t_s)]))[0])


class PurePursuitPid(Algorithm):
    """Pure-pursuit steering and PID speed control along the upstream planned path.

    Reads ``frame.vehicle_state`` (its speed) and the path of the last planning algorithm
    upstream; returns :class:`ControlCommands` (throttle and brake in [0, 1], never both > 0;
    road-wheel angle in radians, left positive). See the module docstring for the laws and the
    configuration.
    """

    role: ClassVar[Role] = Role.CONTROL
    inputs: ClassVar[tuple[Input, ...]] = (VEHICLE_STATE,)
    version: ClassVar[str] = "1"
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType(
        {
            "wheelbase_m": 2.8,
            "lookahead_gain_s": 0.6,
            "lookahead_min_m": 3.0,
            "max_steer_rad": 0.6,
            "speed_preview_s": 0.5,
            "kp": 1.0,
            "ki": 0.1,
            "kd": 0.0,
            "integral_limit": 0.3,
            "integrate_below_mps2": 0.3,
            "max_dt_s": 0.5,
            "stop_speed_mps": 0.3,
            "hold_brake": 0.4,
            "path": None,
        }
    )

    def __init__(self, *, name: str | None = None) -> None:
        super().__init__(name=name)
        self._integral = 0.0  # ∫e dt, metres
        self._last_error_mps: float | None = None
        self._last_stamp_ns: int | None = None
        #: the three preview times of a step (reused: the kernel reads them)
        self._previews = np.zeros(3)
        self.setup(self.config)

    def setup(self, config: Mapping[str, Any]) -> None:
        values: dict[str, float] = {}
        for key in (
            "wheelbase_m",
            "lookahead_gain_s",
            "lookahead_min_m",
            "max_steer_rad",
            "speed_preview_s",
            "kp",
            "ki",
            "kd",
            "integral_limit",
            "integrate_below_mps2",
            "max_dt_s",
            "stop_speed_mps",
            "hold_brake",
        ):
            try:
                value = float(config[key])
            except (TypeError, ValueError) as err:
                msg = f"{self.name} config {key!r} must be a number, got {config[key]!r}"
                raise ConfigError(msg) from err
            if not math.isfinite(value) or value < 0.0:
                msg = f"{self.name} config {key!r} must be finite and ≥ 0, got {value}"
                raise ConfigError(msg)
            values[key] = value
        if values["wheelbase_m"] <= 0.0 or values["hold_brake"] > 1.0:
            msg = (
                f"{self.name} config: wheelbase_m must be > 0 and hold_brake in [0, 1], got "
                f"{values['wheelbase_m']} and {values['hold_brake']}"
            )
            raise ConfigError(msg)
        self.wheelbase_m = values["wheelbase_m"]
        self.lookahead_gain_s = values["lookahead_gain_s"]
        self.lookahead_min_m = values["lookahead_min_m"]
        self.max_steer_rad = values["max_steer_rad"]
        self.speed_preview_s = values["speed_preview_s"]
        self.kp, self.ki, self.kd = values["kp"], values["ki"], values["kd"]
        self.integral_limit = values["integral_limit"]
        self.integrate_below_mps2 = values["integrate_below_mps2"]
        self.max_dt_s = values["max_dt_s"]
        self.stop_speed_mps = values["stop_speed_mps"]
        self.hold_brake = values["hold_brake"]
        path = config.get("path")
        if path is not None and not isinstance(path, str):
            msg = f"{self.name} config 'path' must be an algorithm name or None, got {path!r}"
            raise ConfigError(msg)
        self.path_from: str | None = path
        self.reset()

    def bind(self, sensors: Mapping[str, SensorType], *, extras: Iterable[str] = ()) -> None:
        """As :meth:`Algorithm.bind`, then one made-up path's lookups, so that numba loads the
        controller's kernels from the cache (or compiles them after an install) here, before a
        run's first frame, not inside that frame's latency."""
        super().bind(sensors, extras=extras)
        self.warm_kernels()

    def warm_kernels(self) -> None:
        """The made-up path of :meth:`bind` (configured, not bound, is enough): numba's kernels
        loaded in this process (also by :mod:`redrive.batch.preload`)."""
        path = np.array([[0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.1]])
        lookahead_point(np.ascontiguousarray(path[:, :2]), 1.0)
        path_speeds(path, self._previews)
        path.flags.writeable = False  # as a PlannedPath's waypoints (numba types them apart)
        lookahead_point(path, 1.0)
        path_speeds(path, self._previews)

    def reset(self) -> None:
        self._integral = 0.0
        self._last_error_mps = None
        self._last_stamp_ns = None

    def step(self, frame: Frame, upstream: StageOutputs) -> ControlCommands:
        path = upstream.path(self.path_from)
        if path is None:
            msg = (
                f"{self.name}: no planned path upstream for frame {frame.index} (stamp "
                f"{frame.stamp_ns} ns); run a planning algorithm before this controller"
            )
            raise AlgorithmError(msg)
        state = frame.vehicle_state
        if state is None:
            msg = (
                f"{self.name}: frame {frame.index} (stamp {frame.stamp_ns} ns) has no vehicle "
                "state; the controller needs the ego speed"
            )
            raise AlgorithmError(msg)
        speed_mps = state.speed_mps
        lookahead_m = self.lookahead_gain_s * speed_mps + self.lookahead_min_m
        steer = _steer_rad(
            path.waypoints,
            lookahead_m,
            wheelbase_m=self.wheelbase_m,
            max_steer_rad=self.max_steer_rad,
        )
        age_s = (frame.stamp_ns - path.stamp_ns) * 1e-9
        t_preview_s = self.speed_preview_s + age_s
        previews = self._previews
        previews[0], previews[1], previews[2] = t_preview_s, t_preview_s + 0.5, t_preview_s - 0.5
        speeds = path_speeds(path.waypoints, previews)
        target_mps, ahead_mps, behind_mps = float(speeds[0]), float(speeds[1]), float(speeds[2])
        # the plan's acceleration around the preview time (m/s², over one second)
        plan_accel_mps2 = ahead_mps - behind_mps
        steady = abs(plan_accel_mps2) <= self.integrate_below_mps2
        throttle, brake = self._longitudinal(
            frame.stamp_ns, target_mps, speed_mps, integrate=steady
        )
        logger.debug(
            "%s frame %d: v=%.2f target=%.2f steer=%.3f throttle=%.2f brake=%.2f",
            self.name,
            frame.index,
            speed_mps,
            target_mps,
            steer,
            throttle,
            brake,
        )
        return ControlCommands(throttle=throttle, brake=brake, steering_angle_rad=steer)

    def _longitudinal(
        self, stamp_ns: int, target_mps: float, speed_mps: float, *, integrate: bool
    ) -> tuple[float, float]:
        dt_s: float | None = None
        if self._last_stamp_ns is not None:
            dt = (stamp_ns - self._last_stamp_ns) * 1e-9
            if 0.0 < dt <= self.max_dt_s:
                dt_s = dt
        self._last_stamp_ns = stamp_ns
        error = target_mps - speed_mps
        if target_mps < self.stop_speed_mps and speed_mps < self.stop_speed_mps:
            self._integral = 0.0
            self._last_error_mps = error
            return 0.0, self.hold_brake
        u_pd = self.kp * error
        if dt_s is not None and self._last_error_mps is not None:
            u_pd += self.kd * (error - self._last_error_mps) / dt_s
        self._last_error_mps = error
        if dt_s is not None and self.ki > 0.0 and integrate:
            candidate = self._integral + error * dt_s
            limit = self.integral_limit / self.ki
            candidate = min(max(candidate, -limit), limit)
            u_try = u_pd + self.ki * candidate
            saturated = (u_try > 1.0 and error > 0.0) or (u_try < -1.0 and error < 0.0)
            if not saturated:
                self._integral = candidate
        u = u_pd + self.ki * self._integral
        return min(max(u, 0.0), 1.0), min(max(-u, 0.0), 1.0)
