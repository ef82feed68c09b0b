"""The built-in path tracker: nuPlan's LQR tracker, turning a ``PlannedPath`` into commands.

Used when a closed-loop pipeline has no control stage.  It is nuplan-devkit's ``LQRTracker``
(``nuplan/planning/simulation/controller/tracker/lqr.py``) with the defaults of its
``nuplan/planning/script/config/simulation/ego_controller/tracker/lqr_tracker.yaml``: two
decoupled one-step LQR problems on the kinematic bicycle (reference point the rear axle), solved
against a reference read ``tracking_horizon · discretization_time_s`` (1 s) ahead.

Reference (:mod:`redrive.closedloop.profiles`): the path resampled every
``discretization_time_s`` and its speed and curvature profiles fitted by regularised least
squares (``jerk_penalty``, ``curvature_rate_penalty``).  The reference speed is the fitted speed
at ``t + N·dt`` (N = ``tracking_horizon``), the curvature profile the fitted curvature at
``t, t + dt, …, t + (N−1)·dt`` — ``_compute_reference_velocity_and_curvature_profile``.

Longitudinal (``_longitudinal_lqr_controller``): the acceleration ``a`` held over the horizon
takes the speed from ``v`` to ``v + N·dt·a``; the one-step LQR with weights ``q_longitudinal``,
``r_longitudinal`` gives the proportional law::

    a = N·dt·q / ((N·dt)²·q + r) · (v_ref − v)        (10/11 · (v_ref − v) with the defaults)

Stopping (``_stopping_controller``): when the reference speed and the ego speed are both at or
below ``stopping_velocity_mps``, ``a = stopping_proportional_gain · (v_ref − v)`` and the
steering rate is zero.  A plan that starts from rest is not "stopped": its speed one second on is
what is read.

Lateral (``_lateral_lqr_controller``): state (lateral error m, heading error rad, steering angle
rad) with respect to the path's pose *at the current time*, input the steering rate, dynamics
linearised (small angles) and Euler-discretised over ``dt`` at the speeds ``v + k·dt·a`` and the
reference curvatures::

    e_y'  = v · e_ψ          e_ψ' = v · (δ / L − κ)          δ' = steering rate

composed over the N steps into ``x_N = A x_0 + B u + g``; the rate minimises
``x_Nᵀ Q x_N + uᵀ R u`` with ``Q = diag(q_lateral)``, ``R = r_lateral`` (angles wrapped).

What reaches the ego: nuPlan hands acceleration and steering rate to its motion model; here the
command is ``ControlCommands`` — the steering angle ``δ + rate · dt_s`` at the end of the step
(the bicycle's own range and rate limits act on it) and the throttle or brake that give the
acceleration through the inverse of the ego's ``PedalModel`` (at standstill a wanted
deceleration needs no pedal: the car stands).
"""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.closedloop._tracker_kernels import (
    MAX_HORIZON,
    path_is_trackable,
    resample_grid,
    track_path,
)
from redrive.closedloop.profiles import ReferenceProfiles, fit_profiles, resample_poses
from redrive.motion.lqr import curvature_gram, jerk_gram, lateral_lqr, longitudinal_lqr
from redrive.sim.ego import EgoGeometry, PedalModel
from redrive.types import ControlCommands, PlannedPath, VehicleState

__all__ = ["LQR_DEFAULTS", "LqrTracker"]

F64 = npt.NDArray[np.float64]

#: nuPlan's ``lqr_tracker.yaml`` (the defaults of :class:`LqrTracker`).
LQR_DEFAULTS: dict[str, Any] = {
    "q_longitudinal": (10.0,),
    "r_longitudinal": (1.0,),
    "q_lateral": (1.0, 10.0, 0.0),
    "r_lateral": (1.0,),
    "discretization_time_s": 0.1,
    "tracking_horizon": 10,
    "jerk_penalty": 1e-4,
    "curvature_rate_penalty": 1e-2,
    "stopping_proportional_gain": 0.5,
    "stopping_velocity_mps": 0.2,
}

#: the source of the tracker's definition and defaults, for the manifest.
SOURCE = (
    "nuplan-devkit nuplan/planning/simulation/controller/tracker/lqr.py LQRTracker "
    "(defaults: nuplan/planning/script/config/simulation/ego_controller/tracker/lqr_tracker.yaml)"
)


def _wrap(angle_rad: float) -> float:
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def _weights(name: str, values: tuple[float, ...], size: int, *, positive: bool) -> F64:
    if len(values) != size:
        msg = f"LqrTracker: {name} has {size} weight(s), got {len(values)}: {values}"
        raise ValueError(msg)
    for v in values:
        if not math.isfinite(v) or v < 0.0 or (positive and v == 0.0):
            kind = "positive" if positive else "non-negative"
            msg = f"LqrTracker: the weights of {name} must be {kind} numbers, got {values}"
            raise ValueError(msg)
    return np.diag(np.asarray(values, dtype=np.float64))


class LqrTracker:
    """Follows a ``PlannedPath`` as nuPlan's LQR tracker does (module docstring).

    Keyword arguments (defaults: nuPlan's, :data:`LQR_DEFAULTS`):

    - ``geometry`` (``EgoGeometry()``): the ego's wheelbase (L) and steering limit.
    - ``pedals`` (``PedalModel()``): inverted to turn the acceleration into throttle or brake.
    - ``q_longitudinal`` (10,), ``r_longitudinal`` (1,): speed-error and acceleration weights.
    - ``q_lateral`` (1, 10, 0): weights of the lateral error (1/m²), heading error and steering
      angle (1/rad²) at the horizon; ``r_lateral`` (1,): weight of the steering rate.
    - ``discretization_time_s`` (0.1) and ``tracking_horizon`` (10, > 1): the horizon's step and
      length; the reference speed is read ``tracking_horizon · discretization_time_s`` ahead.
    - ``jerk_penalty`` (1e-4), ``curvature_rate_penalty`` (1e-2): regularisation of the fits.
    - ``stopping_proportional_gain`` (0.5, 1/s) and ``stopping_velocity_mps`` (0.2): the stopping
      controller and the speed at or below which (ego and reference) it takes over.
    """

    name = "lqr"

    def __init__(
        self,
        *,
        geometry: EgoGeometry | None = None,
        pedals: PedalModel | None = None,
        q_longitudinal: tuple[float, ...] = LQR_DEFAULTS["q_longitudinal"],
        r_longitudinal: tuple[float, ...] = LQR_DEFAULTS["r_longitudinal"],
        q_lateral: tuple[float, ...] = LQR_DEFAULTS["q_lateral"],
        r_lateral: tuple[float, ...] = LQR_DEFAULTS["r_lateral"],
        discretization_time_s: float = LQR_DEFAULTS["discretization_time_s"],
        tracking_horizon: int = LQR_DEFAULTS["tracking_horizon"],
        jerk_penalty: float = LQR_DEFAULTS["jerk_penalty"],
        curvature_rate_penalty: float = LQR_DEFAULTS["curvature_rate_penalty"],
        stopping_proportional_gain: float = LQR_DEFAULTS["stopping_proportional_gain"],
        stopping_velocity_mps: float = LQR_DEFAULTS["stopping_velocity_mps"],
    ) -> None:
        self.geometry = geometry if geometry is not None else EgoGeometry()
        self.pedals = pedals if pedals is not None else PedalModel()
        self._q_lon = _weights("q_longitudinal", tuple(q_longitudinal), 1, positive=False)
        self._r_lon = _weights("r_longitudinal", tuple(r_longitudinal), 1, positive=True)
        self._q_lat = _weights("q_lateral", tuple(q_lateral), 3, positive=False)
        self._r_lat = _weights("r_lateral", tuple(r_lateral), 1, positive=True)
        for key, value in (
            ("discretization_time_s", discretization_time_s),
            ("jerk_penalty", jerk_penalty),
            ("curvature_rate_penalty", curvature_rate_penalty),
            ("stopping_proportional_gain", stopping_proportional_gain),
            ("stopping_velocity_mps", stopping_velocity_mps),
        ):
            if not (math.isfinite(value) and value > 0.0):
                msg = f"LqrTracker: {key} must be a positive number, got {value}"
                raise ValueError(msg)
        if isinstance(tracking_horizon, bool) or int(tracking_horizon) != tracking_horizon:
            msg = f"LqrTracker: tracking_horizon is a number of steps, got {tracking_horizon!r}"
            raise ValueError(msg)
        if tracking_horizon <= 1:
            msg = (
                "LqrTracker: tracking_horizon must be greater than 1 (with one Euler step the "
                f"steering rate cannot move the lateral error), got {tracking_horizon}"
            )
            raise ValueError(msg)
        self.params: dict[str, Any] = {
            "q_longitudinal": [float(v) for v in q_longitudinal],
            "r_longitudinal": [float(v) for v in r_longitudinal],
            "q_lateral": [float(v) for v in q_lateral],
            "r_lateral": [float(v) for v in r_lateral],
            "discretization_time_s": float(discretization_time_s),
            "tracking_horizon": int(tracking_horizon),
            "jerk_penalty": float(jerk_penalty),
            "curvature_rate_penalty": float(curvature_rate_penalty),
            "stopping_proportional_gain": float(stopping_proportional_gain),
            "stopping_velocity_mps": float(stopping_velocity_mps),
        }
        self._dt = float(discretization_time_s)
        self._n = int(tracking_horizon)
        #: the horizon's step numbers 0 … n−1 and the lateral Q's diagonal (made once)
        self._steps = np.arange(self._n, dtype=np.float64)
        self._q_lat_diagonal = np.ascontiguousarray(np.diag(self._q_lat))

    def reset(self) -> None:
        """Nothing to forget: the tracker keeps no state between calls (nuPlan's neither)."""

    def describe(self) -> dict[str, Any]:
        """The tracker's name, source and every parameter, for the run manifest."""
        return {
            "name": self.name,
            "source": SOURCE,
            "longitudinal": "one-step LQR on speed toward the reference 1 horizon ahead; "
            "a P controller when stopping",
            "lateral": "one-step LQR on (lateral error, heading error, steering angle) over the "
            "horizon, steering-rate input",
            "wheelbase_m": self.geometry.wheelbase_m,
            "max_steer_rad": self.geometry.max_steer_rad,
            "pedals": asdict(self.pedals),
            **self.params,
        }

    # -- the commands ------------------------------------------------------------------------

    def commands(
        self,
        state: VehicleState,
        path: PlannedPath,
        dt_s: float,
        *,
        stamp_ns: int,
        steer_rad: float | None = None,
    ) -> ControlCommands:
        """Commands for the next ``dt_s`` seconds from ``stamp_ns``.

        ``state`` is the ego in ``path.frame_id``; for a ``base_link`` path the ego is at its
        origin heading +x (the path is in base_link of ``path.stamp_ns``) and only its speed is
        read.  The path is read at ``stamp_ns − path.stamp_ns`` seconds into it.  ``steer_rad``
        is the ego's road-wheel angle (the lateral state's third entry); None: estimated from
        the yaw rate and speed (``atan(L · ω / v)``, 0 at rest).

        Raises:
            ValueError: an empty path, one with non-finite values, one that jumps (two places
                at one time), one shorter than the discretisation step, a frame it cannot
                relate to ``state``, or ``dt_s`` not > 0.
        """
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            msg = f"LqrTracker.commands: dt_s must be a positive number of seconds, got {dt_s}"
            raise ValueError(msg)
        wp = np.ascontiguousarray(path.waypoints, dtype=np.float64)
        if wp.shape[0] == 0 or not path_is_trackable(wp):
            _check_path(path)  # raises, saying what is wrong
        if path.frame_id == "base_link":
            x, y, yaw = 0.0, 0.0, 0.0
        elif path.frame_id == state.frame_id:
            x, y, yaw = float(state.position[0]), float(state.position[1]), float(state.heading_rad)
        else:
            msg = (
                f"the planned path of stamp {path.stamp_ns} is in frame {path.frame_id!r} but the "
                f"ego state is in {state.frame_id!r}: give the path in base_link or in the "
                "state's frame"
            )
            raise ValueError(msg)
        speed = state.speed_mps
        if steer_rad is None:
            steer_rad = 0.0
            if speed > 0.1:
                steer_rad = math.atan(self.geometry.wheelbase_m * state.yaw_rate_rad_s / speed)
        t_s = (stamp_ns - path.stamp_ns) * 1e-9
        if self._n > MAX_HORIZON:  # numpy's summation order past its block: the numpy functions
            times, poses = resample_poses(
                path.waypoints, discretization_time_s=self._dt, standing_heading_rad=yaw
            )
            profiles = fit_profiles(
                times,
                poses,
                discretization_time_s=self._dt,
                jerk_penalty=self.params["jerk_penalty"],
                curvature_rate_penalty=self.params["curvature_rate_penalty"],
            )
            accel, rate = self.track(
                profiles, pose=(x, y, yaw), speed_mps=speed, steer_rad=steer_rad, t_s=t_s
            )
        else:
            accel, rate = self._track_compiled(wp, (x, y, yaw), speed, steer_rad, t_s)
        g = self.geometry
        steer = min(max(steer_rad + rate * dt_s, -g.max_steer_rad), g.max_steer_rad)
        throttle, brake = self._pedals(accel, speed)
        return ControlCommands(throttle=throttle, brake=brake, steering_angle_rad=steer)

    def _track_compiled(
        self,
        wp: F64,
        pose: tuple[float, float, float],
        speed: float,
        steer_rad: float,
        t_s: float,
    ) -> tuple[float, float]:
        """resample_poses + fit_profiles + track in one compiled call
        (closedloop._tracker_kernels: the same doubles) for the waypoints ``wp`` (K, 4)."""
        start_us, step_us, count = resample_grid(float(wp[0, 3]), float(wp[-1, 3]), self._dt)
        m = max(count, 2) - 1
        params = self.params
        return track_path(
            wp,
            start_us,
            step_us,
            count,
            pose[0],
            pose[1],
            pose[2],
            float(speed),
            float(steer_rad),
            t_s,
            self._dt,
            self._n,
            jerk_gram(m, params["jerk_penalty"]),
            curvature_gram(m, params["curvature_rate_penalty"]),
            params["stopping_velocity_mps"],
            params["stopping_proportional_gain"],
            float(self._q_lon[0, 0]),
            float(self._r_lon[0, 0]),
            self._q_lat_diagonal,
            float(self._r_lat[0, 0]),
            float(self.geometry.wheelbase_m),
        )

    def track(
        self,
        profiles: ReferenceProfiles,
        *,
        pose: tuple[float, float, float],
        speed_mps: float,
        steer_rad: float,
        t_s: float,
    ) -> tuple[float, float]:
        """nuPlan's ``track_trajectory``: the acceleration (m/s²) and steering rate (rad/s) for
        the ego at ``pose`` (x m, y m, yaw rad in the path's frame) with ``speed_mps`` and the
        road-wheel angle ``steer_rad``, ``t_s`` seconds into the path."""
        n, dt = self._n, self._dt
        v_ref = profiles.speed_at(t_s + n * dt)
        kappa = profiles.curvature_at(t_s + dt * self._steps)
        stop = self.params["stopping_velocity_mps"]
        if v_ref <= stop and speed_mps <= stop:
            return self.params["stopping_proportional_gain"] * (v_ref - speed_mps), 0.0
        accel = self.longitudinal(speed_mps, v_ref)
        speeds: F64 = speed_mps + accel * dt * self._steps
        x_ref, y_ref, h_ref = profiles.pose_at(t_s)
        dx, dy = pose[0] - x_ref, pose[1] - y_ref
        lateral = -dx * math.sin(h_ref) + dy * math.cos(h_ref)
        initial = np.array([lateral, _wrap(pose[2] - h_ref), steer_rad])
        return accel, self.lateral(initial, speeds_mps=speeds, curvatures_1pm=kappa)

    def longitudinal(self, speed_mps: float, reference_mps: float) -> float:
        """The acceleration (m/s²) of the one-step longitudinal LQR: ``v_N = v + N·dt·a``."""
        accel = longitudinal_lqr(
            np.array([speed_mps]),
            np.array([reference_mps]),
            horizon_s=self._n * self._dt,
            q=float(self._q_lon[0, 0]),
            r=float(self._r_lon[0, 0]),
        )
        return float(accel[0])

    def lateral(self, initial: F64, *, speeds_mps: F64, curvatures_1pm: F64) -> float:
        """The steering rate (rad/s) of the one-step lateral LQR from ``initial`` (lateral error
        m, heading error rad, steering angle rad) over the horizon's speeds and curvatures."""
        rate = lateral_lqr(
            initial[None],
            speeds_mps[None],
            curvatures_1pm=curvatures_1pm[None],
            dt_s=self._dt,
            wheelbase_m=self.geometry.wheelbase_m,
            q=self._q_lat_diagonal,
            r=float(self._r_lat[0, 0]),
        )
        return float(rate[0])

    def _pedals(self, accel_mps2: float, speed_mps: float) -> tuple[float, float]:
        """Throttle and brake for ``accel_mps2`` at ``speed_mps`` (standing: a deceleration
        needs no pedal)."""
        if speed_mps <= 0.0 and accel_mps2 <= 0.0:
            return 0.0, 0.0
        return self.pedals.pedals(accel_mps2, speed_mps)


def _check_path(path: PlannedPath) -> None:
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
    jump = (np.diff(t) <= 0.0) & (seg > 1e-6)
    if jump.any():
        i = int(np.flatnonzero(jump)[0])
        msg = (
            f"the planned path of stamp {path.stamp_ns} puts waypoints {i} and {i + 1} "
            f"{seg[i]:.3f} m apart at the same time t_s={t[i]}: the speed would be infinite"
        )
        raise ValueError(msg)
    if (np.diff(t) < 0.0).any():
        i = int(np.flatnonzero(np.diff(t) < 0.0)[0])
        msg = (
            f"the planned path of stamp {path.stamp_ns} goes back in time at waypoint {i + 1} "
            f"(t_s {t[i]} then {t[i + 1]}): waypoints must be in time order"
        )
        raise ValueError(msg)
