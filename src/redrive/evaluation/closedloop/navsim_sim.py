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

_INITIAL_CURVATURE_PENALTY = 1e-10  # batch_lqr_utils.INITIAL_CURVATURE_PENALTY


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


# -- batch_lqr_utils -------------------------------------------------------------------------


def _profile(initial: F64, derivatives: F64, dt: float) -> F64:
    """``_generate_profile_from_initial_condition_and_derivatives``: (B, N+1)."""
    cumsum = np.cumsum(derivatives * dt, axis=-1)
    return np.asarray(initial[..., None] + np.pad(cumsum, [(0, 0), (1, 0)]), dtype=np.float64)


def _velocity_fit(xy_disp: F64, headings: F64, dt: float, jerk_penalty: float) -> tuple[F64, F64]:
    """``_fit_initial_velocity_and_acceleration_profile`` (regularised least squares)."""
    batch, m = xy_disp.shape[:2]
    y = xy_disp.reshape(batch, -1)
    a_col = np.zeros(y.shape, dtype=np.float64)
    a_col[:, 0::2] = np.cos(headings)
    a_col[:, 1::2] = np.sin(headings)
    a = np.repeat(a_col[..., None] * dt**2, m, axis=2)
    a[..., 0] = a_col * dt
    upper = np.repeat(np.triu(np.ones((m, m), dtype=bool), k=1), 2, axis=0)
    a[:, upper] = 0.0
    band = np.zeros((m - 2, m - 1), dtype=np.float64)
    eye = np.eye(m - 2)
    band[:, 1:] = eye
    band[:, :-1] = -eye
    r = np.block([np.zeros((m - 2, 1)), band])
    a_t = a.transpose(0, 2, 1)
    lhs = np.einsum("bij,bjk->bik", a_t, a) + jerk_penalty * (r.T @ r)[None]
    x = _solve(lhs, np.einsum("bij,bj->bi", a_t, y))
    return x[:, 0], x[:, 1:]


def _solve(lhs: F64, rhs: F64) -> F64:
    """``pinv(lhs) @ rhs`` for the regularised (positive definite) normal equations of
    ``batch_lqr_utils``: solved directly, the same solution to rounding."""
    return np.asarray(np.linalg.solve(lhs, rhs[..., None])[..., 0], dtype=np.float64)


def _curvature_fit(heading_disp: F64, velocity: F64, dt: float, penalty: float) -> tuple[F64, F64]:
    """``_fit_initial_curvature_and_curvature_rate_profile``."""
    batch, dim = heading_disp.shape
    a = np.repeat(np.tri(dim, dtype=np.float64)[None], batch, axis=0)
    a[:, :, 0] = velocity * dt
    v2 = velocity * dt**2
    a[:, 1:, 1:] *= v2[:, None, 1:].transpose(0, 2, 1)
    q = penalty * np.eye(dim)
    q[0, 0] = _INITIAL_CURVATURE_PENALTY
    a_t = a.transpose(0, 2, 1)
    lhs = np.einsum("bij,bjk->bik", a_t, a) + q[None]
    x = _solve(lhs, np.einsum("bij,bj->bi", a_t, heading_disp))
    return x[:, 0], x[:, 1:]


def _reference_profiles(poses: F64, p: Mapping[str, Any]) -> tuple[F64, F64]:
    """``get_velocity_curvature_profiles_with_derivatives_from_poses``: velocity and curvature
    profiles (B, N-1) of the proposals' poses (B, N, 3)."""
    dt = float(p["interval_s"])
    diff = np.diff(poses, axis=1)
    xy_disp = diff[..., :2]
    heading_disp = normalize_angle(diff[..., 2])
    v0, accel = _velocity_fit(xy_disp, poses[:, :-1, 2], dt, float(p["jerk_penalty"]))
    velocity = _profile(v0, accel, dt)
    k0, k_rate = _curvature_fit(heading_disp, velocity, dt, float(p["curvature_rate_penalty"]))
    return velocity, _profile(k0, k_rate, dt)


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
        q_lon, r_lon = float(p["q_longitudinal"]), float(p["r_longitudinal"])
        b = horizon * dt
        accel[go] = -1.0 / (b * q_lon * b + r_lon) * b * q_lon * (v0[go] - v_ref[go])
        # _generate_profile_from_initial_condition_and_derivatives of a constant acceleration
        v_prof = v0[go, None] + accel[go, None] * dt * np.arange(horizon, dtype=np.float64)
        steer_rate[go] = _lateral_lqr(
            lat0[go], v_prof, curvature=curvature[go], dt=dt, wheel_base=wheel_base, p=p
        )
    return accel, steer_rate


def _lateral_lqr(
    x0: F64,
    velocity: F64,
    *,
    curvature: F64,
    dt: float,
    wheel_base: float,
    p: Mapping[str, Any],
) -> F64:
    """``_lateral_lqr_controller`` + ``_solve_one_step_lateral_lqr``."""
    # A = Π M_k, B, g accumulated over the horizon with M_k = [[1, v dt, 0], [0, 1, v dt / L],
    # [0, 0, 1]] (NAVSIM multiplies the matrices step by step): A stays unit upper-triangular,
    # so each entry is a sum over the steps of what the earlier steps accumulated
    batch = x0.shape[0]
    m01 = velocity * dt  # (B, H)
    m12 = velocity * dt / wheel_base
    steps = np.arange(velocity.shape[1], dtype=np.float64)

    def before(x: F64) -> F64:  # Σ_{j<k} x_j
        return np.asarray(np.cumsum(x, axis=1) - x, dtype=np.float64)

    a01 = m01.sum(axis=1)
    a12 = m12.sum(axis=1)
    a02 = (m01 * before(m12)).sum(axis=1)
    b1_terms = m12 * steps * dt  # b2 before step k is k·dt
    b1 = b1_terms.sum(axis=1)
    b0 = (m01 * before(b1_terms)).sum(axis=1)
    b2 = np.full(batch, velocity.shape[1] * dt)
    g1_terms = -velocity * curvature * dt
    g1 = g1_terms.sum(axis=1)
    g0 = (m01 * before(g1_terms)).sum(axis=1)
    a = np.zeros((batch, 3, 3))
    a[:, 0, 0] = a[:, 1, 1] = a[:, 2, 2] = 1.0
    a[:, 0, 1], a[:, 0, 2], a[:, 1, 2] = a01, a02, a12
    b = np.stack([b0, b1, b2], axis=-1)
    g = np.stack([g0, g1, np.zeros(batch)], axis=-1)
    err = np.einsum("bij,bj->bi", a, x0) + g
    err[:, 1:] = np.arctan2(np.sin(err[:, 1:]), np.cos(err[:, 1:]))
    q = np.asarray(p["q_lateral"], dtype=np.float64)
    r = float(p["r_lateral"])
    bq = b * q[None]
    return np.asarray(-(bq * err).sum(-1) / ((bq * b).sum(-1) + r), dtype=np.float64)


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
