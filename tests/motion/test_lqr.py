"""The shared LQR math (redrive.motion.lqr) equals the devkits' step-by-step forms."""

from __future__ import annotations

import numpy as np

from redrive.motion.lqr import (
    fit_curvature_profiles,
    fit_speed_profiles,
    integrate_profiles,
    lateral_lqr,
    longitudinal_lqr,
)


def _speed_fit_dense(
    xy_disp: np.ndarray, headings: np.ndarray, *, dt: float, jerk_penalty: float
) -> tuple[np.ndarray, np.ndarray]:
    """nuPlan tracker_utils ``_fit_initial_velocity_and_acceleration_profile`` as the devkits
    write it: the 2M × M design A, then ``pinv(AᵀA + jerk_penalty·JᵀJ) Aᵀy`` (one path)."""
    m = headings.size
    y = xy_disp.reshape(-1)
    a = np.zeros((2 * m, m))
    for k in range(m):
        direction = np.array([np.cos(headings[k]), np.sin(headings[k])])
        a[2 * k : 2 * k + 2, 0] = direction * dt
        for j in range(1, k + 1):
            a[2 * k : 2 * k + 2, j] = direction * dt**2
    jerk = np.zeros((max(m - 2, 0), m))
    for j in range(m - 2):
        jerk[j, j + 1], jerk[j, j + 2] = -1.0, 1.0
    x = np.linalg.pinv(a.T @ a + jerk_penalty * jerk.T @ jerk) @ a.T @ y
    return x[0], x[1:]


def _curvature_fit_dense(
    heading_disp: np.ndarray, speeds: np.ndarray, *, dt: float, penalty: float
) -> tuple[float, np.ndarray]:
    """nuPlan tracker_utils ``_fit_initial_curvature_and_curvature_rate_profile``: the M × M
    design A, then ``pinv(AᵀA + Q) Aᵀy`` (one path)."""
    m = speeds.size
    a = np.tri(m)
    a[:, 0] = speeds * dt
    a[1:, 1:] *= (speeds[1:] * dt**2)[:, None]
    q = penalty * np.eye(m)
    q[0, 0] = 1e-10
    x = np.linalg.pinv(a.T @ a + q) @ a.T @ heading_disp
    return float(x[0]), x[1:]


def test_the_fits_equal_the_devkits_dense_normal_equations() -> None:
    """The fits build AᵀA and Aᵀy from suffix sums; on random paths (standing, slow, fast,
    turning; one to 80 displacements) they equal the devkits' dense pinv solution to rounding."""
    rng = np.random.default_rng(3)
    dt = 0.1
    for _ in range(60):
        m = int(rng.integers(1, 81))
        speed = np.abs(rng.normal(8.0, 5.0, size=m)) * (rng.random() > 0.2)
        heading = np.cumsum(rng.normal(0.0, 0.05, size=m)) + rng.uniform(-3.0, 3.0)
        disp = np.c_[np.cos(heading), np.sin(heading)] * speed[:, None] * dt
        disp += rng.normal(0.0, 0.01, size=(m, 2))
        v0, accel = fit_speed_profiles(disp[None], heading[None], dt_s=dt, jerk_penalty=1e-4)
        want_v0, want_accel = _speed_fit_dense(disp, heading, dt=dt, jerk_penalty=1e-4)
        np.testing.assert_allclose(v0[0], want_v0, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(accel[0], want_accel, rtol=1e-9, atol=1e-9)
        speeds = integrate_profiles(v0, accel, dt)[0]
        turn = rng.normal(0.0, 0.03, size=m)
        k0, rates = fit_curvature_profiles(
            turn[None], speeds[None], dt_s=dt, curvature_rate_penalty=1e-2
        )
        want_k0, want_rates = _curvature_fit_dense(turn, speeds, dt=dt, penalty=1e-2)
        np.testing.assert_allclose(k0[0], want_k0, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(rates[0], want_rates, rtol=1e-9, atol=1e-9)


def _lateral_by_matrix_products(
    x0: np.ndarray,
    *,
    speeds: np.ndarray,
    kappas: np.ndarray,
    dt: float,
    wheelbase: float,
    q: np.ndarray,
    r: float,
) -> float:
    """nuPlan lqr.py ``_lateral_lqr_controller``: A, B, g multiplied out step by step."""
    a, b, g = np.eye(3), np.zeros(3), np.zeros(3)
    for v, kappa in zip(speeds, kappas, strict=True):
        step = np.array([[1.0, v * dt, 0.0], [0.0, 1.0, v * dt / wheelbase], [0.0, 0.0, 1.0]])
        a, b = step @ a, step @ b + np.array([0.0, 0.0, dt])
        g = step @ g + np.array([0.0, -v * kappa * dt, 0.0])
    err = a @ x0 + g
    err[1:] = np.arctan2(np.sin(err[1:]), np.cos(err[1:]))
    qm = np.diag(q)
    return float(-(b @ qm @ err) / (b @ qm @ b + r))


def test_the_closed_form_lateral_law_equals_the_matrix_products() -> None:
    rng = np.random.default_rng(7)
    x0 = rng.normal(size=(6, 3)) * [1.0, 0.2, 0.1]
    speeds = rng.uniform(0.0, 20.0, size=(6, 10))
    kappas = rng.normal(size=(6, 10)) * 0.02
    q = np.array([1.0, 10.0, 0.0])
    got = lateral_lqr(x0, speeds, curvatures_1pm=kappas, dt_s=0.1, wheelbase_m=3.089, q=q, r=1.0)
    want = [
        _lateral_by_matrix_products(
            x0[i], speeds=speeds[i], kappas=kappas[i], dt=0.1, wheelbase=3.089, q=q, r=1.0
        )
        for i in range(6)
    ]
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_the_longitudinal_law_with_nuplans_defaults_is_ten_elevenths() -> None:
    accel = longitudinal_lqr(np.array([5.0]), np.array([6.0]), horizon_s=1.0, q=10.0, r=1.0)
    assert accel[0] == 10.0 / 11.0


def test_a_constant_speed_straight_path_fits_that_speed_and_no_curvature() -> None:
    dt, speed = 0.1, 8.0
    xy = np.column_stack([np.arange(21) * speed * dt, np.zeros(21)])
    v0, accel = fit_speed_profiles(
        np.diff(xy, axis=0)[None], np.zeros((1, 20)), dt_s=dt, jerk_penalty=1e-4
    )
    speeds = integrate_profiles(v0, accel, dt)
    np.testing.assert_allclose(speeds, speed, atol=1e-9)
    k0, rates = fit_curvature_profiles(
        np.zeros((1, 20)), speeds, dt_s=dt, curvature_rate_penalty=1e-2
    )
    np.testing.assert_allclose(integrate_profiles(k0, rates, dt), 0.0, atol=1e-12)


def test_a_circle_fits_its_curvature() -> None:
    dt, speed, radius = 0.1, 10.0, 40.0
    theta = np.arange(31) * speed * dt / radius
    xy = radius * np.column_stack([np.sin(theta), 1.0 - np.cos(theta)])
    v0, accel = fit_speed_profiles(
        np.diff(xy, axis=0)[None], theta[None, :-1], dt_s=dt, jerk_penalty=1e-4
    )
    speeds = integrate_profiles(v0, accel, dt)
    k0, rates = fit_curvature_profiles(
        np.diff(theta)[None], speeds, dt_s=dt, curvature_rate_penalty=1e-2
    )
    curvature = integrate_profiles(k0, rates, dt)
    np.testing.assert_allclose(curvature[0, 5:-5], 1.0 / radius, rtol=2e-3)
