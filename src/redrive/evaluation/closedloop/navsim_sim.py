"""NAVSIM's simulation of a proposal: an LQR tracker driving a kinematic bicycle at 10 Hz.

Follows ``navsim/planning/simulation/planner/pdm_planner/simulation/`` (``pdm_simulator.py``
``PDMSimulator.simulate_proposals``, ``batch_lqr.py`` ``BatchLQRTracker``, ``batch_lqr_utils.py``,
``batch_kinematic_bicycle.py`` ``BatchKinematicBicycleModel``), NAVSIM v1.1 and v2 alike (the
two versions' simulators are the same), vectorised over proposals.  The state array has
NAVSIM's ``StateIndex`` layout (:data:`X` … :data:`ANGULAR_ACCELERATION`), the rear axle as
reference point, velocity and acceleration in the body frame.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.motion.lqr import (
    fit_curvature_profiles,
    fit_speed_profiles,
    integrate_profiles,
    lateral_lqr,
    longitudinal_lqr,
)

F64 = npt.NDArray[np.float64]

__all__ = [
    "SIM_DEFAULTS",
    "interpolate_poses",
    "simulate_proposals",
]

# NAVSIM's StateIndex (pdm_enums.py)
X, Y, HEADING, VELOCITY_X, VELOCITY_Y, ACCELERATION_X, ACCELERATION_Y = range(7)
STEERING_ANGLE, STEERING_RATE, ANGULAR_VELOCITY, ANGULAR_ACCELERATION = range(7, 11)
STATE_SIZE = 11

#: NAVSIM's simulation parameters: ``BatchLQRTracker.__init__`` and
#: ``BatchKinematicBicycleModel.__init__`` defaults, ``proposal_sampling`` (40 poses at 0.1 s,
#: ``default_common.yaml``) and the Chrysler Pacifica's wheel base (nuPlan
#: ``get_pacifica_parameters``: NAVSIM's ego).
SIM_DEFAULTS: Mapping[str, Any] = MappingProxyType(
    {
        "interval_s": 0.1,
        "num_poses": 40,
        "wheel_base_m": 3.089,
        "q_longitudinal": 10.0,
        "r_longitudinal": 1.0,
        "q_lateral": (1.0, 10.0, 0.0),
        "r_lateral": 1.0,
        "tracking_horizon": 10,
        "jerk_penalty": 1e-4,
        "curvature_rate_penalty": 1e-2,
        "stopping_proportional_gain": 0.5,
        "stopping_velocity_mps": 0.2,
        "max_steering_angle_rad": math.pi / 3.0,
        "accel_time_constant_s": 0.2,
        "steering_angle_time_constant_s": 0.05,
    }
)


def normalize_angle(a: npt.ArrayLike) -> F64:
    """NAVSIM's ``normalize_angle``: arctan2(sin, cos)."""
    arr = np.asarray(a, dtype=np.float64)
    return np.asarray(np.arctan2(np.sin(arr), np.cos(arr)), dtype=np.float64)


def interpolate_poses(times_s: F64, poses: F64, *, query_s: F64) -> F64:
    """(K, 3) x, y, heading at ``query_s`` from poses (N, 3) at increasing ``times_s``: linear,
    headings unwrapped first, queries clipped to the span (nuPlan ``InterpolatedTrajectory``
    with its ``AngularInterpolator``, as NAVSIM's ``get_trajectory_as_array`` samples it)."""
    t = np.asarray(times_s, dtype=np.float64)
    q = np.clip(np.asarray(query_s, dtype=np.float64), t[0], t[-1])
    heading = np.unwrap(poses[:, 2])
    out = np.empty((q.size, 3), dtype=np.float64)
    out[:, 0] = np.interp(q, t, poses[:, 0])
    out[:, 1] = np.interp(q, t, poses[:, 1])
    out[:, 2] = normalize_angle(np.interp(q, t, heading))
    return out


# -- batch_lqr_utils (the fits are redrive.motion.lqr's, shared with nuPlan's LQRTracker) ----


def _reference_profiles(poses: F64, p: Mapping[str, Any]) -> tuple[F64, F64]:
    """``get_velocity_curvature_profiles_with_derivatives_from_poses``: velocity and curvature
    profiles (B, N-1) of the proposals' poses (B, N, 3)."""
    dt = float(p["interval_s"])
    diff = np.diff(poses, axis=1)
    xy_disp = diff[..., :2]
    heading_disp = normalize_angle(diff[..., 2])
    v0, accel = fit_speed_profiles(
        xy_disp, poses[:, :-1, 2], dt_s=dt, jerk_penalty=float(p["jerk_penalty"])
    )
    velocity = integrate_profiles(v0, accel, dt)
    k0, k_rate = fit_curvature_profiles(
        heading_disp, velocity, dt_s=dt, curvature_rate_penalty=float(p["curvature_rate_penalty"])
    )
    return velocity, integrate_profiles(k0, k_rate, dt)


# -- BatchLQRTracker ---------------------------------------------------------------------------


def _track(
    index: int,
    states: F64,
    poses: F64,
    profiles: tuple[F64, F64],
    p: Mapping[str, Any],
) -> tuple[F64, F64]:
    """``BatchLQRTracker.track_trajectory`` at iteration ``index``: (acceleration,
    steering-rate) commands (B,) for the current states (B, 11)."""
    dt = float(p["interval_s"])
    horizon = int(p["tracking_horizon"])
    wheel_base = float(p["wheel_base_m"])
    velocity_profile, curvature_profile = profiles
    ref = poses[:, index]
    dx = states[:, X] - ref[:, 0]
    dy = states[:, Y] - ref[:, 1]
    lateral = -dx * np.sin(ref[:, 2]) + dy * np.cos(ref[:, 2])
    heading_err = normalize_angle(states[:, HEADING] - ref[:, 2])
    v0 = states[:, VELOCITY_X]
    lat0 = np.stack([lateral, heading_err, states[:, STEERING_ANGLE]], axis=-1)

    n_profile = velocity_profile.shape[1]
    ref_idx = min(index + horizon, n_profile - 1)
    v_ref = velocity_profile[:, ref_idx]
    curvature = np.zeros((states.shape[0], horizon), dtype=np.float64)
    length = ref_idx - index
    curvature[:, :length] = curvature_profile[:, index:ref_idx]
    if length < horizon:
        curvature[:, length:] = curvature_profile[:, ref_idx, None]

    stop_v = float(p["stopping_velocity_mps"])
    stop = (v_ref <= stop_v) & (v0 <= stop_v)
    accel = np.zeros_like(v0)
    steer_rate = np.zeros_like(v0)
    accel[stop] = -float(p["stopping_proportional_gain"]) * (v0[stop] - v_ref[stop])
    go = ~stop
    if go.any():
        accel[go] = longitudinal_lqr(
            v0[go],
            v_ref[go],
            horizon_s=horizon * dt,
            q=float(p["q_longitudinal"]),
            r=float(p["r_longitudinal"]),
        )
        # _generate_profile_from_initial_condition_and_derivatives of a constant acceleration
        v_prof = v0[go, None] + accel[go, None] * dt * np.arange(horizon, dtype=np.float64)
        steer_rate[go] = lateral_lqr(  # _lateral_lqr_controller
            lat0[go],
            v_prof,
            curvatures_1pm=curvature[go],
            dt_s=dt,
            wheelbase_m=wheel_base,
            q=np.asarray(p["q_lateral"], dtype=np.float64),
            r=float(p["r_lateral"]),
        )
    return accel, steer_rate


# -- BatchKinematicBicycleModel ----------------------------------------------------------------


def _propagate(states: F64, accel_cmd: F64, steer_rate_cmd: F64, p: Mapping[str, Any]) -> F64:
    """``BatchKinematicBicycleModel.propagate_state`` (with ``_update_commands``' first-order
    delays) over one interval."""
    dt = float(p["interval_s"])
    wheel_base = float(p["wheel_base_m"])
    accel = states[:, ACCELERATION_X]
    steer = states[:, STEERING_ANGLE]
    ideal_steer = dt * steer_rate_cmd + steer
    new_accel = dt / (dt + float(p["accel_time_constant_s"])) * (accel_cmd - accel) + accel
    tau = float(p["steering_angle_time_constant_s"])
    new_steer = dt / (dt + tau) * (ideal_steer - steer) + steer
    new_rate = (new_steer - steer) / dt
    v = states[:, VELOCITY_X]
    out = states.copy()
    out[:, X] = states[:, X] + v * np.cos(states[:, HEADING]) * dt
    out[:, Y] = states[:, Y] + v * np.sin(states[:, HEADING]) * dt
    heading = states[:, HEADING] + v * np.tan(steer) / wheel_base * dt
    out[:, HEADING] = normalize_angle(heading)  # nuPlan principal_value
    out[:, VELOCITY_X] = v + new_accel * dt
    out[:, VELOCITY_Y] = 0.0
    max_steer = float(p["max_steering_angle_rad"])
    out[:, STEERING_ANGLE] = np.clip(steer + new_rate * dt, -max_steer, max_steer)
    out[:, ANGULAR_VELOCITY] = out[:, VELOCITY_X] * np.tan(out[:, STEERING_ANGLE]) / wheel_base
    out[:, ACCELERATION_X] = new_accel
    out[:, ACCELERATION_Y] = 0.0
    out[:, ANGULAR_ACCELERATION] = (out[:, ANGULAR_VELOCITY] - states[:, ANGULAR_VELOCITY]) / dt
    out[:, STEERING_RATE] = new_rate
    return out


def simulate_proposals(poses: F64, initial_state: F64, *, p: Mapping[str, Any]) -> F64:
    """``PDMSimulator.simulate_proposals``: proposals' poses (B, N+1, 3) tracked from
    ``initial_state`` (11,) → simulated states (B, N+1, 11), the first row the initial state."""
    batch, n = poses.shape[:2]
    profiles = _reference_profiles(poses, p)
    out = np.zeros((batch, n, STATE_SIZE), dtype=np.float64)
    out[:, 0] = initial_state
    for i in range(1, n):
        accel, rate = _track(i - 1, out[:, i - 1], poses, profiles, p)
        out[:, i] = _propagate(out[:, i - 1], accel, rate, p)
    return out
