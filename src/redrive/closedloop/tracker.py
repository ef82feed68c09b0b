"""The built-in path tracker: LQR steering and PID speed control towards a ``PlannedPath``.

Used when a closed-loop pipeline has no control stage.  Following nuPlan's LQR tracker it is two
decoupled stages on the kinematic bicycle (reference point the rear axle, ``redrive.sim.ego``):

Lateral — a discrete-time LQR on the error dynamics linearised about the path (small angles)::

    e_y'  = v · e_ψ                                lateral error, m (left of the path > 0)
    e_ψ'  = v · (tan δ / L − κ)                    heading error, rad
          ≈ v / (L cos² δ_ff) · (δ − δ_ff)         with the feed-forward δ_ff = atan(L · κ)

discretised exactly (zero-order hold over ``dt_s``) at the current speed; the steering angle is
``δ = δ_ff − K · (e_y, e_ψ)`` with ``K`` from the discrete algebraic Riccati equation
(``scipy.linalg.solve_discrete_are``), clipped to the vehicle's steering limit.  The command is an
angle (what ``ControlCommands`` carries), so the steering angle is the input, not a state as in
nuPlan (there the input is the steering rate); the vehicle's rate limit acts on it afterwards.

Longitudinal — a PID on the speed error towards the path's speed profile (from its time column,
looked ``speed_lookahead_s`` ahead), plus the profile's acceleration as feed-forward; the wanted
acceleration becomes throttle or brake through the inverse of the ego's ``PedalModel``.  Near
standstill with a standing reference (below ``stopping_speed_mps``) it holds the brake at
``stop_brake``, as nuPlan switches to its stopping controller.

The path's reference point is found by projecting the ego onto the path polyline (the first and
last segments extended), its heading interpolated between the segments' headings and its curvature
taken ``curvature_preview_s`` ahead along the path.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.linalg import solve_discrete_are

from redrive.geometry import normalize_angle
from redrive.sim.ego import EgoGeometry, PedalModel
from redrive.types import ControlCommands, PlannedPath, VehicleState

__all__ = ["LqrPidTracker"]

_SAME_POINT_M = 1e-6
"""Consecutive waypoints closer than this are one point of the path's geometry."""

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True, kw_only=True)
class _PathShape:
    """A path's geometry (distinct points) and speed profile, in the path's frame.

    ``xy`` (P, 2) metres, ``s_m`` (P,) arc length at each point, ``vertex_heading_rad`` (P,)
    unwrapped, ``curvature_1pm`` (P-1,) per segment; ``t_s`` (T,) strictly increasing seconds
    relative to the path's stamp with ``speed_mps`` and ``accel_mps2`` (T,) at those times.
    """

    xy: F64
    s_m: F64
    vertex_heading_rad: F64
    curvature_1pm: F64
    t_s: F64
    speed_mps: F64
    accel_mps2: F64


def _shape(path: PlannedPath) -> _PathShape:
    wp = path.waypoints
    if wp.shape[0] == 0:
        msg = f"the planned path of stamp {path.stamp_ns} has no waypoints: nothing to track"
        raise ValueError(msg)
    bad = ~np.isfinite(wp).all(axis=1)
    if bad.any():
        rows = np.flatnonzero(bad)[:5].tolist()
        msg = (
            f"the planned path of stamp {path.stamp_ns} has non-finite values (NaN or inf) "
            f"in waypoint(s) {rows}: the planner produced an invalid path"
        )
        raise ValueError(msg)
    xy, t = wp[:, :2], wp[:, 3]
    seg = np.hypot(*np.diff(xy, axis=0).T)
    jump = (np.diff(t) <= 0.0) & (seg > _SAME_POINT_M)
    if jump.any():
        i = int(np.flatnonzero(jump)[0])
        msg = (
            f"the planned path of stamp {path.stamp_ns} puts waypoints {i} and {i + 1} "
            f"{seg[i]:.3f} m apart at the same time t_s={t[i]}: the speed would be infinite"
        )
        raise ValueError(msg)
    s_all = np.concatenate([[0.0], np.cumsum(seg)])

    distinct = np.concatenate([[True], seg > _SAME_POINT_M])
    gxy, gs = xy[distinct], s_all[distinct]
    if gxy.shape[0] >= 2:
        d = np.diff(gxy, axis=0)
        seg_heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        inner = 0.5 * (seg_heading[:-1] + seg_heading[1:])
        vertex = np.concatenate([seg_heading[:1], inner, seg_heading[-1:]])
        curvature = np.diff(vertex) / np.diff(gs)
    else:
        vertex, curvature = np.zeros(1), np.zeros(0)

    later = np.concatenate([[True], np.diff(t) > 0.0])
    ts, ss = t[later], s_all[later]
    if ts.shape[0] >= 2:
        # second order at the ends too (from three points): a path starts where the ego is, and a
        # first-order end would misread a braking profile's first speed and acceleration
        if ts.shape[0] >= 3:
            speed = np.gradient(ss, ts, edge_order=2)
            accel = np.gradient(speed, ts, edge_order=2)
        else:
            speed = np.gradient(ss, ts)
            accel = np.gradient(speed, ts)
    else:
        speed, accel = np.zeros(1), np.zeros(1)
    return _PathShape(
        xy=gxy,
        s_m=gs,
        vertex_heading_rad=vertex,
        curvature_1pm=curvature,
        t_s=ts,
        speed_mps=speed,
        accel_mps2=accel,
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class _LateralReference:
    lateral_error_m: float
    heading_error_rad: float
    s_m: float


def _project(shape: _PathShape, x_m: float, y_m: float, yaw_rad: float) -> _LateralReference:
    """The ego's lateral and heading error w.r.t. the nearest point of the path polyline."""
    a, b = shape.xy[:-1], shape.xy[1:]
    d = b - a
    length2 = np.einsum("ij,ij->i", d, d)
    rel = np.array([x_m, y_m]) - a
    u = np.einsum("ij,ij->i", rel, d) / length2
    lo = np.zeros_like(u)
    hi = np.ones_like(u)
    lo[0], hi[-1] = -np.inf, np.inf  # beyond the ends: the extended first and last segments
    u = np.clip(u, lo, hi)
    dist2 = np.einsum("ij,ij->i", rel - u[:, None] * d, rel - u[:, None] * d)
    i = int(np.argmin(dist2))
    length = math.sqrt(float(length2[i]))
    lateral = float(d[i, 0] * rel[i, 1] - d[i, 1] * rel[i, 0]) / length
    w = min(max(float(u[i]), 0.0), 1.0)
    heading = (1.0 - w) * shape.vertex_heading_rad[i] + w * shape.vertex_heading_rad[i + 1]
    return _LateralReference(
        lateral_error_m=lateral,
        heading_error_rad=normalize_angle(yaw_rad - float(heading)),
        s_m=float(shape.s_m[i]) + float(u[i]) * length,
    )


class LqrPidTracker:
    """Follows a ``PlannedPath`` with LQR steering and PID speed control (module docstring).

    Keyword arguments (defaults in parentheses):

    - ``geometry`` (``EgoGeometry()``): wheelbase and steering limit of the ego.
    - ``pedals`` (``PedalModel()``): the ego's pedal model, inverted to turn the wanted
      acceleration into throttle and brake.
    - ``q_lateral_1pm2`` (1.0), ``q_heading_1prad2`` (10.0), ``r_steer_1prad2`` (10.0): LQR weights
      per step on the lateral error² (1/m²), heading error² (1/rad²) and steering angle² (1/rad²)
      relative to the feed-forward angle.  Larger ``r`` steers more gently; the heading
      weight damps the approach (closed loop ζ ≈ 0.9 at 10 m/s and 10 Hz: no visible overshoot).
    - ``min_lqr_speed_mps`` (1.0): the lateral model is linearised at no less than this speed
      (at standstill the steering does not move the vehicle and the Riccati equation has no
      solution).
    - ``curvature_preview_s`` (0.1): the feed-forward curvature is taken this many seconds
      (at the current speed) ahead of the projection, to cover the steering's rate limit.
    - ``kp_speed_1ps`` (1.0), ``ki_speed_1ps2`` (0.1), ``kd_speed`` (0.0): PID gains on the speed
      error (acceleration per m/s, per m, per m/s²).
    - ``integral_limit_m`` (2.0): bound of the integral of the speed error (anti-windup), m.
    - ``accel_feedforward`` (1.0): weight of the profile's acceleration in the command.
    - ``speed_lookahead_s`` (0.0): the speed profile is read this far ahead of the current time
      (a lookahead makes the speed lead the profile: the ego falls behind the path in space).
    - ``stopping_speed_mps`` (0.3): below this speed, with a reference below it too, hold the
      brake at ``stop_brake`` (0.5, fraction of full brake) instead of the PID.

    The tracker keeps the PID's integral and last error between calls; :meth:`reset` clears them.
    """

    name = "lqr+pid"

    def __init__(
        self,
        *,
        geometry: EgoGeometry | None = None,
        pedals: PedalModel | None = None,
        q_lateral_1pm2: float = 1.0,
        q_heading_1prad2: float = 10.0,
        r_steer_1prad2: float = 10.0,
        min_lqr_speed_mps: float = 1.0,
        curvature_preview_s: float = 0.1,
        kp_speed_1ps: float = 1.0,
        ki_speed_1ps2: float = 0.1,
        kd_speed: float = 0.0,
        integral_limit_m: float = 2.0,
        accel_feedforward: float = 1.0,
        speed_lookahead_s: float = 0.0,
        stopping_speed_mps: float = 0.3,
        stop_brake: float = 0.5,
    ) -> None:
        self.geometry = geometry if geometry is not None else EgoGeometry()
        self.pedals = pedals if pedals is not None else PedalModel()
        self.gains: dict[str, float] = {
            "q_lateral_1pm2": q_lateral_1pm2,
            "q_heading_1prad2": q_heading_1prad2,
            "r_steer_1prad2": r_steer_1prad2,
            "min_lqr_speed_mps": min_lqr_speed_mps,
            "curvature_preview_s": curvature_preview_s,
            "kp_speed_1ps": kp_speed_1ps,
            "ki_speed_1ps2": ki_speed_1ps2,
            "kd_speed": kd_speed,
            "integral_limit_m": integral_limit_m,
            "accel_feedforward": accel_feedforward,
            "speed_lookahead_s": speed_lookahead_s,
            "stopping_speed_mps": stopping_speed_mps,
            "stop_brake": stop_brake,
        }
        for key, value in self.gains.items():
            if not (math.isfinite(value) and value >= 0.0):
                msg = f"LqrPidTracker: {key} must be a non-negative number, got {value}"
                raise ValueError(msg)
        for key in ("r_steer_1prad2", "min_lqr_speed_mps"):
            if self.gains[key] <= 0.0:
                msg = f"LqrPidTracker: {key} must be positive, got {self.gains[key]}"
                raise ValueError(msg)
        if stop_brake > 1.0:
            msg = f"LqrPidTracker: stop_brake is a pedal fraction in [0, 1], got {stop_brake}"
            raise ValueError(msg)
        self._q = np.diag([q_lateral_1pm2, q_heading_1prad2])
        self._r = np.array([[r_steer_1prad2]])
        self._integral_m = 0.0
        self._last_error_mps: float | None = None

    def reset(self) -> None:
        """Forget the PID's integral and last error (between runs)."""
        self._integral_m = 0.0
        self._last_error_mps = None

    def describe(self) -> dict[str, Any]:
        """The tracker's name and every gain, for the run manifest."""
        return {
            "name": self.name,
            "lateral": "discrete LQR on (lateral error, heading error), steering angle input",
            "longitudinal": "PID on speed with acceleration feed-forward",
            "wheelbase_m": self.geometry.wheelbase_m,
            "max_steer_rad": self.geometry.max_steer_rad,
            "pedals": asdict(self.pedals),
            **self.gains,
        }

    def commands(
        self, state: VehicleState, path: PlannedPath, dt_s: float, *, stamp_ns: int
    ) -> ControlCommands:
        """Commands for the next ``dt_s`` seconds from ``stamp_ns``.

        ``state`` is the ego in ``path.frame_id``; for a ``base_link`` path the ego is at its
        origin heading +x (the path is in base_link of ``path.stamp_ns``) and only its speed is
        read.  The speed profile is read at ``stamp_ns − path.stamp_ns`` seconds into the path
        (plus the lookahead).  Raises ``ValueError`` for an empty path, a path with non-finite
        values, one that jumps (two places at one time) or a frame it cannot relate to ``state``.
        """
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            msg = f"LqrPidTracker.commands: dt_s must be a positive number of seconds, got {dt_s}"
            raise ValueError(msg)
        shape = _shape(path)
        speed = state.speed_mps
        if path.frame_id == "base_link":
            x, y, yaw = 0.0, 0.0, 0.0
        elif path.frame_id == state.frame_id:
            x, y, yaw = float(state.position[0]), float(state.position[1]), state.heading_rad
        else:
            msg = (
                f"the planned path of stamp {path.stamp_ns} is in frame {path.frame_id!r} but the "
                f"ego state is in {state.frame_id!r}: give the path in base_link or in the "
                "state's frame"
            )
            raise ValueError(msg)
        steer = self._steer(shape, (x, y, yaw), speed_mps=speed, dt_s=dt_s)
        t_s = (stamp_ns - path.stamp_ns) * 1e-9
        throttle, brake = self._pedals(shape, t_s=t_s, speed_mps=speed, dt_s=dt_s)
        return ControlCommands(throttle=throttle, brake=brake, steering_angle_rad=steer)

    def _steer(
        self, shape: _PathShape, pose: tuple[float, float, float], *, speed_mps: float, dt_s: float
    ) -> float:
        """Steering angle (rad) towards the path from the ego's ``pose`` (x m, y m, yaw rad)."""
        g = self.geometry
        if shape.xy.shape[0] < 2:
            return 0.0  # a path that stands still: nothing to steer along
        ref = _project(shape, *pose)
        s_ahead = ref.s_m + speed_mps * self.gains["curvature_preview_s"]
        i = int(np.clip(np.searchsorted(shape.s_m, s_ahead, side="right") - 1, 0, None))
        kappa = float(shape.curvature_1pm[min(i, shape.curvature_1pm.shape[0] - 1)])
        steer_ff = min(max(math.atan(g.wheelbase_m * kappa), -g.max_steer_rad), g.max_steer_rad)
        speed_lin = max(speed_mps, self.gains["min_lqr_speed_mps"])
        gain = self.lqr_gain(speed_lin, steer_ff_rad=steer_ff, dt_s=dt_s)
        error = np.array([ref.lateral_error_m, ref.heading_error_rad])
        steer = steer_ff - float(gain @ error)
        return min(max(steer, -g.max_steer_rad), g.max_steer_rad)

    def lqr_gain(self, speed_mps: float, *, steer_ff_rad: float, dt_s: float) -> F64:
        """The (2,) LQR gain ``K`` on (lateral error m, heading error rad) of the lateral error
        model linearised at ``speed_mps`` and the feed-forward angle ``steer_ff_rad``, discretised
        exactly over ``dt_s`` with the steering angle held (the matrices of :meth:`lateral_model`).
        """
        a_d, b_d = self.lateral_model(speed_mps, steer_ff_rad=steer_ff_rad, dt_s=dt_s)
        p = solve_discrete_are(a_d, b_d, self._q, self._r)
        gain: F64 = np.linalg.solve(self._r + b_d.T @ p @ b_d, b_d.T @ p @ a_d)[0]
        return gain

    def lateral_model(
        self, speed_mps: float, *, steer_ff_rad: float, dt_s: float
    ) -> tuple[F64, F64]:
        """Discrete lateral error model ``x' = A x + B u`` over ``dt_s``: x = (lateral error m,
        heading error rad), u = steering angle − ``steer_ff_rad`` (rad), at ``speed_mps``."""
        b = speed_mps / (self.geometry.wheelbase_m * math.cos(steer_ff_rad) ** 2)
        a_d = np.array([[1.0, speed_mps * dt_s], [0.0, 1.0]])
        b_d = np.array([[0.5 * speed_mps * b * dt_s * dt_s], [b * dt_s]])
        return a_d, b_d

    def _pedals(
        self, shape: _PathShape, *, t_s: float, speed_mps: float, dt_s: float
    ) -> tuple[float, float]:
        """Throttle and brake towards the speed profile at ``t_s`` seconds into the path."""
        speed = speed_mps
        gains = self.gains
        t_ref = t_s + gains["speed_lookahead_s"]
        if t_ref > shape.t_s[-1]:
            v_ref, a_ref = 0.0, 0.0  # past the path's last waypoint: stand
        else:
            v_ref = float(np.interp(t_ref, shape.t_s, shape.speed_mps))
            a_ref = float(np.interp(t_ref, shape.t_s, shape.accel_mps2))
        stop = gains["stopping_speed_mps"]
        if v_ref <= stop and speed <= stop:
            self.reset()
            return 0.0, gains["stop_brake"]
        error = v_ref - speed
        limit = gains["integral_limit_m"]
        self._integral_m = min(max(self._integral_m + error * dt_s, -limit), limit)
        derivative = 0.0
        if self._last_error_mps is not None:
            derivative = (error - self._last_error_mps) / dt_s
        self._last_error_mps = error
        accel = (
            gains["accel_feedforward"] * a_ref
            + gains["kp_speed_1ps"] * error
            + gains["ki_speed_1ps2"] * self._integral_m
            + gains["kd_speed"] * derivative
        )
        return self.pedals.pedals(accel, speed)
