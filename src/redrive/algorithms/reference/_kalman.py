"""A planar constant-velocity Kalman filter, the motion model of the reference tracker.

State ``x = (px, py, vx, vy)`` — metres and m/s in whatever fixed frame the caller tracks in —
with covariance ``P`` (4×4).  The measurement is a position ``z = (px, py)`` with isotropic noise
``R = σ_z² I``.  Process noise is the discrete white-noise-acceleration model: an unknown
acceleration of standard deviation ``σ_a`` (m/s²), constant over a step, on each axis.

The ``*_all`` functions do the same for T tracks at once, states stacked as ``x`` (T, 4) and
``p`` (T, 4, 4): every track's values are bit-equal to the one-track function's (numpy's stacked
``matmul`` and ``inv`` work item by item with the routine the single call takes; the einsum of
the distances stays one call a track, since a stacked einsum may sum in another order).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = [
    "KalmanState",
    "initial_state",
    "mahalanobis_sq",
    "mahalanobis_sq_all",
    "predict",
    "predict_all",
    "update",
    "update_all",
]

Array = npt.NDArray[np.float64]

#: measurement matrix: the position part of the state.
_H: Array = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])


@dataclass(slots=True)
class KalmanState:
    """Mean ``x`` (4,) = px, py (m), vx, vy (m/s) and covariance ``p`` (4, 4); mutable."""

    x: Array
    p: Array


def initial_state(
    position_m: Array, *, position_std_m: float, velocity_std_mps: float
) -> KalmanState:
    """A track born at ``position_m`` (2,) with unknown velocity (mean zero, ``velocity_std_mps``)."""
    x = np.array([position_m[0], position_m[1], 0.0, 0.0], dtype=np.float64)
    p = np.diag([position_std_m**2] * 2 + [velocity_std_mps**2] * 2).astype(np.float64)
    return KalmanState(x=x, p=p)


_EYE2: Array = np.eye(2)
_EYE4: Array = np.eye(4)
for _a in (_H, _EYE2, _EYE4):
    _a.flags.writeable = False


@functools.lru_cache(maxsize=16)
def _motion(dt_s: float, accel_std_mps2: float) -> tuple[Array, Array, Array]:
    """Transition F, its transpose and process noise Q of a step (read-only; a tracker's steps
    mostly share one dt, so they are built once)."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt_s
    q1 = np.array([[dt_s**4 / 4.0, dt_s**3 / 2.0], [dt_s**3 / 2.0, dt_s**2]], dtype=np.float64) * (
        accel_std_mps2**2
    )
    q = np.zeros((4, 4))
    q[np.ix_([0, 2], [0, 2])] = q1
    q[np.ix_([1, 3], [1, 3])] = q1
    f_t = f.T
    for a in (f, f_t, q):
        a.flags.writeable = False
    return f, f_t, q


@functools.lru_cache(maxsize=16)
def _measurement_noise(meas_std_m: float) -> Array:
    r = _EYE2 * meas_std_m**2
    r.flags.writeable = False
    return r


def predict(state: KalmanState, dt_s: float, *, accel_std_mps2: float) -> None:
    """Advance ``state`` by ``dt_s`` seconds in place (no-op for ``dt_s == 0``)."""
    if dt_s == 0.0:
        return
    f, f_t, q = _motion(dt_s, accel_std_mps2)
    state.x = f @ state.x
    state.p = f @ state.p @ f_t + q


def mahalanobis_sq(state: KalmanState, z_m: Array, *, meas_std_m: float) -> Array:
    """Squared Mahalanobis distances (M,) of positions ``z_m`` (M, 2) from the predicted
    measurement, under the innovation covariance ``S = H P Hᵀ + R``."""
    s = state.p[:2, :2] + _measurement_noise(meas_std_m)
    d = z_m - state.x[:2]
    out: Array = np.einsum("mi,ij,mj->m", d, np.linalg.inv(s), d)
    return out


def update(state: KalmanState, z_m: Array, *, meas_std_m: float) -> None:
    """Correct ``state`` in place with the position measurement ``z_m`` (2,) (Joseph form, so
    ``P`` stays symmetric positive definite)."""
    r = _measurement_noise(meas_std_m)
    s = _H @ state.p @ _H.T + r
    k = state.p @ _H.T @ np.linalg.inv(s)
    state.x = state.x + k @ (z_m - _H @ state.x)
    i_kh = _EYE4 - k @ _H
    p = i_kh @ state.p @ i_kh.T + k @ r @ k.T
    state.p = 0.5 * (p + p.T)


def predict_all(x: Array, p: Array, dt_s: float, *, accel_std_mps2: float) -> tuple[Array, Array]:
    """:func:`predict` of T stacked states: the new ``(x, p)`` (the inputs when ``dt_s == 0``)."""
    if dt_s == 0.0:
        return x, p
    f, f_t, q = _motion(dt_s, accel_std_mps2)
    return (f @ x[:, :, None])[:, :, 0], f @ p @ f_t + q


def mahalanobis_sq_all(x: Array, p: Array, z_m: Array, *, meas_std_m: float) -> Array:
    """:func:`mahalanobis_sq` of T stacked states against the same M positions: (T, M)."""
    s_inv = np.linalg.inv(p[:, :2, :2] + _measurement_noise(meas_std_m))
    d = z_m[None, :, :] - x[:, None, :2]
    out = np.empty((len(x), len(z_m)))
    for i in range(len(x)):
        out[i] = np.einsum("mi,ij,mj->m", d[i], s_inv[i], d[i])
    return out


def update_all(x: Array, p: Array, z_m: Array, *, meas_std_m: float) -> tuple[Array, Array]:
    """:func:`update` of T stacked states, state i with the measurement ``z_m[i]`` (T, 2): the
    new ``(x, p)``."""
    r = _measurement_noise(meas_std_m)
    s = _H @ p @ _H.T + r
    k = p @ _H.T @ np.linalg.inv(s)
    k_t = k.transpose(0, 2, 1)
    x = x + (k @ (z_m - (_H @ x[:, :, None])[:, :, 0])[:, :, None])[:, :, 0]
    i_kh = _EYE4 - k @ _H
    p = i_kh @ p @ i_kh.transpose(0, 2, 1) + k @ r @ k_t
    return x, 0.5 * (p + p.transpose(0, 2, 1))
