"""A planned path as the LQR tracker reads it: poses resampled in time, and the speed and curvature
profiles fitted to them by regularised least squares.

This follows nuplan-devkit's ``nuplan/planning/simulation/controller/tracker/tracker_utils.py``
(``get_interpolated_reference_trajectory_poses`` and
``get_velocity_curvature_profiles_with_derivatives_from_poses``); the facts are theirs, the code
is written here:

1. The path is resampled every ``discretization_time_s`` from its first waypoint's time up to its
   last (the last sample included when it falls on the end): ``N`` poses (x, y, heading).
2. Speed: with the ``M = N − 1`` displacements ``d_k`` and the headings ``h_k`` of the poses they
   start from, the initial speed ``v_0`` and the accelerations ``a_0 … a_{M−2}`` minimise::

       Σ_k ‖d_k − v_k·dt·(cos h_k, sin h_k)‖²  +  jerk_penalty · Σ_j (a_{j+1} − a_j)²,
       v_k = v_0 + dt · Σ_{j<k} a_j

   (``_fit_initial_velocity_and_acceleration_profile``).  The speed profile is ``v_0 … v_{M−1}``.
3. Curvature: with the heading changes ``Δh_k`` (principal value) and that speed profile, the
   initial curvature ``κ_0`` and the curvature rates ``κ̇_0 … κ̇_{M−2}`` minimise::

       Σ_k (Δh_k − κ_k·v_k·dt)²  +  curvature_rate_penalty · Σ_j κ̇_j²  +  10⁻¹⁰ · κ_0²,
       κ_k = κ_0 + dt · Σ_{j<k} κ̇_j

   (``_fit_initial_curvature_and_curvature_rate_profile``; the tiny weight on ``κ_0`` keeps the
   problem well posed when the path stands still).

A ``PlannedPath`` carries positions and times, not headings: the heading of a waypoint is that
of the path through it (the mean of the directions of the segments before and after it; at the
ends, the end segment's direction turned on by half the turn to its neighbour), a point the path stands still at keeps the heading of
the motion before it (or, before any motion, after it), and a path that never moves has the
heading ``standing_heading_rad`` it is given (the ego's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.motion.lqr import (
    INITIAL_CURVATURE_PENALTY,
    fit_curvature_profiles,
    fit_speed_profiles,
    integrate_profiles,
)

__all__ = ["INITIAL_CURVATURE_PENALTY", "ReferenceProfiles", "fit_profiles", "resample_poses"]

F64 = npt.NDArray[np.float64]

#: consecutive waypoints closer than this are one point of the path's geometry (m).
SAME_POINT_M = 1e-6


@dataclass(frozen=True, slots=True, kw_only=True)
class ReferenceProfiles:
    """The fitted reference of one path.

    ``times_s`` (N,) are the resampled poses' times (seconds relative to the path's stamp),
    ``poses`` (N, 3) their x, y (m, the path's frame) and unwrapped heading (rad);
    ``speed_mps`` (M,) and ``curvature_1pm`` (M,) hold at ``times_s[:-1]`` (M = N − 1 ≥ 1), and
    ``accel_mps2`` (M − 1,) between them.
    """

    times_s: F64
    poses: F64
    speed_mps: F64
    accel_mps2: F64
    curvature_1pm: F64

    def speed_at(self, t_s: float) -> float:
        """The fitted speed at ``t_s`` (held beyond the ends, as ``np.interp``)."""
        return float(np.interp(t_s, self.times_s[:-1], self.speed_mps))

    def curvature_at(self, t_s: F64) -> F64:
        """The fitted curvature at the times ``t_s`` (held beyond the ends)."""
        out: F64 = np.interp(t_s, self.times_s[:-1], self.curvature_1pm)
        return out

    def pose_at(self, t_s: float) -> tuple[float, float, float]:
        """x, y, heading of the path at ``t_s`` (linear between the resampled poses, held
        beyond the ends)."""
        t = self.times_s
        return (
            float(np.interp(t_s, t, self.poses[:, 0])),
            float(np.interp(t_s, t, self.poses[:, 1])),
            float(np.interp(t_s, t, self.poses[:, 2])),
        )


def waypoint_headings(xy: F64, *, standing_heading_rad: float) -> F64:
    """(K,) unwrapped heading of the path through each of the ``xy`` (K, 2) points (module
    text)."""
    k = xy.shape[0]
    seg = np.diff(xy, axis=0)
    moving = np.hypot(seg[:, 0], seg[:, 1]) > SAME_POINT_M
    if not moving.any():
        return np.full(k, float(standing_heading_rad))
    seg_heading = np.full(k - 1, np.nan)
    seg_heading[moving] = np.unwrap(np.arctan2(seg[moving, 1], seg[moving, 0]))
    # a standing segment takes the heading of the motion before it, else of the motion after it
    idx = np.where(moving, np.arange(k - 1), -1)
    before = np.maximum.accumulate(idx)
    first = int(np.flatnonzero(moving)[0])
    filled = np.where(before >= 0, seg_heading[np.maximum(before, 0)], seg_heading[first])
    out = np.empty(k)
    out[1:-1] = 0.5 * (filled[:-1] + filled[1:])
    out[0], out[-1] = filled[0], filled[-1]
    if k >= 3:  # the ends: the tangent of a path that keeps turning as it did next to them
        out[0] -= 0.5 * (filled[1] - filled[0])
        out[-1] += 0.5 * (filled[-1] - filled[-2])
    return out


def resample_poses(
    waypoints: F64, *, discretization_time_s: float, standing_heading_rad: float
) -> tuple[F64, F64]:
    """Times (N,) and poses (N, 3) of ``waypoints`` (K, 4: x, y, z, t_s) every
    ``discretization_time_s`` from the first waypoint's time (nuPlan's
    ``get_interpolated_reference_trajectory_poses``: the samples in [t_0, t_end), plus t_end's
    when it falls on the grid).  Waypoints at one time keep the first.  A path shorter than one
    step (one waypoint: "be here") stands: its first pose is repeated one step later, so N ≥ 2."""
    t = waypoints[:, 3]
    later = np.concatenate([[True], np.diff(t) > 0.0])
    wp = waypoints[later]
    t = wp[:, 3]
    heading = waypoint_headings(wp[:, :2], standing_heading_rad=standing_heading_rad)
    # nuPlan works in integer microseconds: arange(start_us, end_us, step_us), plus one more
    # sample when it does not pass the end
    start_us, end_us = round(t[0] * 1e6), round(t[-1] * 1e6)
    step_us = int(discretization_time_s * 1e6)
    grid_us = np.arange(start_us, end_us, step_us, dtype=np.int64)
    if grid_us.size == 0:
        grid_us = np.array([start_us], dtype=np.int64)
    if grid_us[-1] + step_us <= end_us:
        grid_us = np.append(grid_us, grid_us[-1] + step_us)
    times = grid_us / 1e6
    poses = np.column_stack(
        [np.interp(times, t, wp[:, 0]), np.interp(times, t, wp[:, 1]), np.interp(times, t, heading)]
    )
    if times.shape[0] == 1:
        times = np.array([times[0], times[0] + step_us / 1e6])
        poses = np.vstack([poses, poses])
    return times, poses


def fit_profiles(
    times_s: F64,
    poses: F64,
    *,
    discretization_time_s: float,
    jerk_penalty: float,
    curvature_rate_penalty: float,
) -> ReferenceProfiles:
    """The speed and curvature profiles of the resampled ``poses`` (module text; the fits are
    :mod:`redrive.motion.lqr`'s, shared with NAVSIM's batch tracker).

    Raises:
        ValueError: fewer than two poses (a path shorter than one discretisation step).
    """
    n = poses.shape[0]
    if n < 2:
        msg = (
            f"the path spans less than the tracker's discretisation step "
            f"({discretization_time_s} s): at least two poses are needed to fit its speed"
        )
        raise ValueError(msg)
    dt = discretization_time_s
    d_heading = np.diff(poses[:, 2])
    d_heading = (d_heading + np.pi) % (2.0 * np.pi) - np.pi  # principal value
    v0, accel = fit_speed_profiles(
        np.diff(poses[None, :, :2], axis=1), poses[None, :-1, 2], dt_s=dt, jerk_penalty=jerk_penalty
    )
    speed = integrate_profiles(v0, accel, dt)
    k0, k_rate = fit_curvature_profiles(
        d_heading[None], speed, dt_s=dt, curvature_rate_penalty=curvature_rate_penalty
    )
    curvature = integrate_profiles(k0, k_rate, dt)[0]
    speed, accel = speed[0], accel[0]
    return ReferenceProfiles(
        times_s=times_s,
        poses=poses,
        speed_mps=speed,
        accel_mps2=accel,
        curvature_1pm=curvature,
    )
