"""The compiled body of :meth:`redrive.closedloop.tracker.LqrTracker.commands`: the path resampled,
its speed and curvature profiles fitted, the two one-step LQR laws — one call a frame instead of
≈ 200 numpy calls on arrays of 10–80 values (≈ 0.5 ms a frame of a closed loop's tracker).

It is the float64 arithmetic of :func:`redrive.closedloop.profiles.resample_poses`,
:func:`~redrive.closedloop.profiles.fit_profiles` and :meth:`LqrTracker.track
<redrive.closedloop.tracker.LqrTracker.track>` (with :mod:`redrive.motion.lqr`'s fits and laws)
in their order, so that it gives the same doubles: numpy's ``interp`` (its branches and its
slope formula), ``unwrap``, ``mod`` (float ``%``: numpy's ``npy_divmod`` and Python's
``float_rem`` are one algorithm, numba's ``%`` is Python's), the sequential ``cumsum`` and the pairwise summation of
``sum`` (numpy's ``pairwise_sum`` of its float add loop) — the written-out forms of
:mod:`redrive.algorithms.reference._numeric_kernels` — and LAPACK's
``gesv`` for the normal equations (numpy's ``linalg.solve`` calls it too).
tests/closedloop/test_tracker.py compares every value with the numpy functions, which stay
the readable reference.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

from redrive.algorithms.reference._numeric_kernels import (
    MAX_PAIRWISE,
    interp_at,
    interp_knot,
    interp_on,
    pairwise_sum,
    unwrap,
)
from redrive.closedloop.profiles import SAME_POINT_M

__all__ = ["MAX_HORIZON", "path_is_trackable", "resample_grid", "track_path"]

#: the longest horizon :func:`track_path` sums as numpy does (numpy's pairwise block)
MAX_HORIZON = MAX_PAIRWISE

_F64 = npt.NDArray[np.float64]
_PERIOD = 2.0 * math.pi


def resample_grid(t_first_s: float, t_last_s: float, step_s: float) -> tuple[int, int, int]:
    """The start and step (µs) and the number of samples of resample_poses' grid for a path
    from ``t_first_s`` to ``t_last_s``: ``arange(start, end, step)`` in integer microseconds,
    one sample when that is empty, plus one more when it does not pass the end."""
    start_us, end_us, step_us = round(t_first_s * 1e6), round(t_last_s * 1e6), int(step_s * 1e6)
    count = max(-(-(end_us - start_us) // step_us), 1)
    if start_us + count * step_us <= end_us:
        count += 1
    return start_us, step_us, count


@numba.njit(cache=True, nogil=True)
def path_is_trackable(wp: _F64) -> bool:  # pragma: no cover - compiled
    """Whether the tracker's path check (tracker._check_path) passes the waypoints ``wp``
    (K ≥ 1, 4): every value finite, no two places at one time (consecutive waypoints more than
    1 µm apart with no time between them), time never going back."""
    n = wp.shape[0]
    for i in range(n):
        for c in range(4):
            if not math.isfinite(wp[i, c]):
                return False
    for i in range(n - 1):
        step = wp[i + 1, 3] - wp[i, 3]
        if step < 0.0:
            return False
        if step <= 0.0 and math.hypot(wp[i + 1, 0] - wp[i, 0], wp[i + 1, 1] - wp[i, 1]) > 1e-6:
            return False
    return True


@numba.njit(cache=True, nogil=True)
def _headings(x: _F64, y: _F64, k: int, standing: float) -> _F64:  # pragma: no cover
    """profiles.waypoint_headings of the first ``k`` points (x, y)."""
    out = np.empty(k)
    m = k - 1
    seg_h = np.empty(max(m, 0))
    moving = np.zeros(max(m, 0), dtype=np.bool_)
    first = -1
    for i in range(m):
        if math.hypot(x[i + 1] - x[i], y[i + 1] - y[i]) > SAME_POINT_M:
            moving[i] = True
            if first < 0:
                first = i
    if first < 0:
        out[:] = standing
        return out
    # np.unwrap of the moving segments' directions
    raw = np.empty(m)
    count = 0
    for i in range(first, m):
        if moving[i]:
            raw[count] = math.atan2(y[i + 1] - y[i], x[i + 1] - x[i])
            count += 1
    unwrapped = np.empty(count)
    unwrap(raw, count, unwrapped)
    count = 0
    for i in range(first, m):
        if moving[i]:
            seg_h[i] = unwrapped[count]
            count += 1
    # a standing segment takes the heading of the motion before it, else of the motion after it
    filled = np.empty(m)
    last = first
    for i in range(m):
        if moving[i]:
            last = i
        filled[i] = seg_h[last]  # before the first motion: the first motion's
    for i in range(1, k - 1):
        out[i] = 0.5 * (filled[i - 1] + filled[i])
    out[0], out[k - 1] = filled[0], filled[m - 1]
    if k >= 3:
        out[0] -= 0.5 * (filled[1] - filled[0])
        out[k - 1] += 0.5 * (filled[m - 1] - filled[m - 2])
    return out


@numba.njit(cache=True, nogil=True)
def _resample(
    wp: _F64, start_us: int, step_us: int, count: int, standing: float
) -> tuple[_F64, _F64]:  # pragma: no cover - compiled
    """profiles.resample_poses on the grid of ``count`` samples ``start_us + i · step_us``:
    times (N,) and poses (N, 3)."""
    k_all = wp.shape[0]
    x = np.empty(k_all)
    y = np.empty(k_all)
    t = np.empty(k_all)
    k = 0
    for i in range(k_all):
        if i == 0 or wp[i, 3] - wp[i - 1, 3] > 0.0:
            x[k], y[k], t[k] = wp[i, 0], wp[i, 1], wp[i, 3]
            k += 1
    heading = _headings(x, y, k, standing)
    n = max(count, 2)
    times = np.empty(n)
    poses = np.empty((n, 3))
    tk = t[:k]
    j = 0
    for i in range(count):  # the grid ascends: each knot search starts from the last one's
        ti = (start_us + i * step_us) / 1e6
        times[i] = ti
        j_i = interp_knot(ti, tk, j)
        if j_i >= 0:
            j = j_i
        poses[i, 0] = interp_on(ti, tk, x[:k], j_i)
        poses[i, 1] = interp_on(ti, tk, y[:k], j_i)
        poses[i, 2] = interp_on(ti, tk, heading, j_i)
    if count == 1:  # a path shorter than one step stands: its pose again one step later
        times[1] = times[0] + step_us / 1e6
        poses[1, :] = poses[0, :]
    return times, poses


@numba.njit(cache=True, nogil=True)
def _fit(weights: _F64, products: _F64, dt: float, penalty: _F64) -> _F64:  # pragma: no cover
    """motion.lqr's ``_normal_equations`` of one path plus ``penalty`` (m, m), solved."""
    m = weights.shape[0]
    sw = np.empty(m)
    sp = np.empty(m)
    acc_w = 0.0
    acc_p = 0.0
    for i in range(m - 1, -1, -1):  # cumsum of the reversed values, reversed
        acc_w = weights[i] if i == m - 1 else acc_w + weights[i]
        acc_p = products[i] if i == m - 1 else acc_p + products[i]
        sw[i], sp[i] = acc_w, acc_p
    scale = np.full(m, dt * dt)
    scale[0] = dt
    lhs = np.empty((m, m))
    rhs = np.empty(m)
    for i in range(m):
        rhs[i] = sp[i] * scale[i]
        for j in range(m):
            lhs[i, j] = sw[max(i, j)] * (scale[i] * scale[j]) + penalty[i, j]
    out: _F64 = np.linalg.solve(lhs, rhs)  # type: ignore[assignment]  # float64 in, float64 out
    return out


@numba.njit(cache=True, nogil=True)
def _integrate(initial: float, rates: _F64, dt: float) -> _F64:  # pragma: no cover - compiled
    """motion.lqr.integrate_profiles of one path."""
    out = np.empty(rates.shape[0] + 1)
    out[0] = initial + 0.0
    acc = 0.0
    for i in range(rates.shape[0]):
        acc = rates[i] * dt if i == 0 else acc + rates[i] * dt
        out[i + 1] = initial + acc
    return out


@numba.njit(cache=True, nogil=True)
def _sum_of(a: _F64) -> float:  # pragma: no cover - compiled
    """``a.sum()`` as numpy adds it."""
    return pairwise_sum(a, a.shape[0])


@numba.njit(cache=True, nogil=True)
def _before(x: _F64) -> _F64:  # pragma: no cover - compiled
    """motion.lqr.lateral_lqr's ``before``: cumsum(x) − x."""
    out = np.empty(x.shape[0])
    acc = 0.0
    for i in range(x.shape[0]):
        acc = x[i] if i == 0 else acc + x[i]
        out[i] = acc - x[i]
    return out


@numba.njit(cache=True, nogil=True)
def track_path(  # noqa: PLR0917 - numba takes no keyword-only parameters
    wp: _F64,
    start_us: int,
    step_us: int,
    count: int,
    pose_x: float,
    pose_y: float,
    pose_yaw: float,
    speed: float,
    steer: float,
    t_s: float,
    dt: float,
    horizon: int,
    jerk_gram: _F64,
    curvature_penalty: _F64,
    stopping_velocity: float,
    stopping_gain: float,
    q_lon: float,
    r_lon: float,
    q_lat: _F64,
    r_lat: float,
    wheelbase: float,
) -> tuple[float, float]:  # pragma: no cover - compiled
    """The acceleration (m/s²) and steering rate (rad/s) of LqrTracker.commands for the
    waypoints ``wp`` (K, 4) resampled on ``count`` samples every ``step_us`` from ``start_us``
    (µs; :func:`resample_grid`) — ``jerk_gram`` and ``curvature_penalty`` are the fits' (M, M)
    penalty matrices, M = max(count, 2) − 1."""
    times, poses = _resample(wp, start_us, step_us, count, pose_yaw)
    n = times.shape[0]
    m = n - 1
    if jerk_gram.shape != (m, m) or curvature_penalty.shape != (m, m):
        raise ValueError("track_path: the penalty matrices do not fit the grid")
    if horizon > MAX_HORIZON:
        raise ValueError("track_path: the horizon is longer than MAX_HORIZON")
    # the speed fit
    weights = np.empty(m)
    products = np.empty(m)
    d_heading = np.empty(m)
    for k in range(m):
        c, s = math.cos(poses[k, 2]), math.sin(poses[k, 2])
        weights[k] = c * c + s * s
        products[k] = c * (poses[k + 1, 0] - poses[k, 0]) + s * (poses[k + 1, 1] - poses[k, 1])
        d_heading[k] = (poses[k + 1, 2] - poses[k, 2] + math.pi) % _PERIOD - math.pi
    x = _fit(weights, products, dt, jerk_gram)
    speed_ref = _integrate(x[0], x[1:], dt)
    # the curvature fit on that speed profile
    for k in range(m):
        weights[k] = speed_ref[k] * speed_ref[k]
        products[k] = speed_ref[k] * d_heading[k]
    x = _fit(weights, products, dt, curvature_penalty)
    curvature = _integrate(x[0], x[1:], dt)
    # LqrTracker.track
    fitted_at = times[:m]  # the profiles hold at the poses' times but the last
    v_ref = interp_at(t_s + horizon * dt, fitted_at, speed_ref)
    kappa = np.empty(horizon)
    for i in range(horizon):
        kappa[i] = interp_at(t_s + dt * float(i), fitted_at, curvature)
    if v_ref <= stopping_velocity and speed <= stopping_velocity:
        return stopping_gain * (v_ref - speed), 0.0
    b = horizon * dt
    accel = -(b * q_lon) / (b * q_lon * b + r_lon) * (speed - v_ref)
    x_ref = interp_at(t_s, times, poses[:, 0])
    y_ref = interp_at(t_s, times, poses[:, 1])
    h_ref = interp_at(t_s, times, poses[:, 2])
    dx, dy = pose_x - x_ref, pose_y - y_ref
    lateral = -dx * math.sin(h_ref) + dy * math.cos(h_ref)
    heading_error = (pose_yaw - h_ref + math.pi) % _PERIOD - math.pi
    # motion.lqr.lateral_lqr of one state
    m01 = np.empty(horizon)
    m12 = np.empty(horizon)
    b1_terms = np.empty(horizon)
    g1_terms = np.empty(horizon)
    for i in range(horizon):
        v = speed + accel * dt * float(i)
        m01[i] = v * dt
        m12[i] = v * dt / wheelbase
        b1_terms[i] = m12[i] * float(i) * dt
        g1_terms[i] = -v * kappa[i] * dt
    a01 = _sum_of(m01)
    a02 = _sum_of(m01 * _before(m12))
    a12 = _sum_of(m12)
    b0 = _sum_of(m01 * _before(b1_terms))
    b1 = _sum_of(b1_terms)
    b2 = horizon * dt
    g0 = _sum_of(m01 * _before(g1_terms))
    g1 = _sum_of(g1_terms)
    # A x_0 + g: numpy's einsum adds a row's three products as (p_0 + p_2) + p_1
    e0 = ((1.0 * lateral + a02 * steer) + a01 * heading_error) + g0
    e1 = ((0.0 * lateral + a12 * steer) + 1.0 * heading_error) + g1
    e2 = ((0.0 * lateral + 1.0 * steer) + 0.0 * heading_error) + 0.0
    e1 = math.atan2(math.sin(e1), math.cos(e1))
    e2 = math.atan2(math.sin(e2), math.cos(e2))
    bq0, bq1, bq2 = b0 * q_lat[0], b1 * q_lat[1], b2 * q_lat[2]
    num = ((0.0 + bq0 * e0) + bq1 * e1) + bq2 * e2
    den = ((0.0 + bq0 * b0) + bq1 * b1) + bq2 * b2
    return accel, -num / (den + r_lat)
