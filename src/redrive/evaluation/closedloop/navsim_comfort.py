"""NAVSIM's comfort of simulated proposals: v1.1's ``ego_is_comfortable``, v2's history comfort
(the same six bounds on other windows, on the ego's centre) and v2's two-frame extended
comfort, from ``navsim/planning/simulation/planner/pdm_planner/scoring/pdm_comfort_metrics.py``
of each version, quirks kept (see ``docs/metrics.md``).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from types import MappingProxyType

import numpy as np
import numpy.typing as npt
from scipy.signal import savgol_filter

from redrive.evaluation.closedloop.navsim_sim import (
    ACCELERATION_X,
    ACCELERATION_Y,
    ANGULAR_ACCELERATION,
    ANGULAR_VELOCITY,
    HEADING,
)

F64 = npt.NDArray[np.float64]

__all__ = ["COMFORT_BOUNDS", "EC_THRESHOLDS", "comfortable", "two_frame_extended_comfort"]

#: the module's bounds (both versions): strict, ``_within_bound``.
COMFORT_BOUNDS: Mapping[str, float] = MappingProxyType(
    {
        "max_abs_mag_jerk": 8.37,
        "max_abs_lat_accel": 4.89,
        "max_lon_accel": 2.40,
        "min_lon_accel": -4.05,
        "max_abs_yaw_accel": 1.93,
        "max_abs_lon_jerk": 4.13,
        "max_abs_yaw_rate": 0.95,
    }
)
#: v2's extended-comfort thresholds on the RMS of the difference (inclusive).
EC_THRESHOLDS: Mapping[str, float] = MappingProxyType(
    {"acceleration": 0.7, "jerk": 0.5, "yaw_rate": 0.1, "yaw_accel": 0.1}
)


@functools.lru_cache(maxsize=64)
def _savgol_matrix(n: int, window: int, poly: int, deriv: int, delta: float) -> F64:
    """scipy's ``savgol_filter`` (mode ``interp``) on n samples as the linear map it is: column
    j is the filter of the j-th unit vector."""
    eye = np.eye(n, dtype=np.float64)
    k = savgol_filter(eye, window_length=window, polyorder=poly, deriv=deriv, delta=delta, axis=0)
    out = np.asarray(k, dtype=np.float64)
    out.flags.writeable = False
    return out


def _savgol(y: F64, window: int, poly: int, *, deriv: int = 0, delta: float = 1.0) -> F64:
    """``savgol_filter(y, window, poly, deriv=, delta=, axis=-1)``."""
    k = _savgol_matrix(y.shape[-1], window, poly, deriv, round(delta, 12))
    return np.asarray(y @ k.T, dtype=np.float64)


def _acceleration(signal: F64, window: int) -> F64:
    """``_extract_ego_acceleration``: Savitzky–Golay (order 2) of the signal, rounded to 8."""
    return np.round(_savgol(signal, min(window, signal.shape[-1]), 2), 8)


def _derivative(y: F64, t: F64, *, window: int, poly: int, deriv: int) -> F64:
    """``_approximate_derivatives``: window capped at the length, spacing the mean step."""
    w = min(window, t.size)
    if not poly < w:
        msg = f"NAVSIM comfort: polynomial order {poly} needs a window > {poly}, got {w} samples"
        raise ValueError(msg)
    dx = np.diff(t)
    return _savgol(y, w, poly, deriv=deriv, delta=float(dx.mean()))


def _unwrap(headings: F64) -> F64:
    """``_phase_unwrap``."""
    two_pi = 2.0 * np.pi
    adj = np.zeros_like(headings)
    adj[..., 1:] = np.cumsum(np.round(np.diff(headings, axis=-1) / two_pi), axis=-1)
    return np.asarray(headings - two_pi * adj, dtype=np.float64)


def _yaw(states: F64, t: F64, *, deriv: int, poly: int) -> F64:
    """``_extract_ego_yaw_rate``: the window argument is not passed on, so it is always the
    default 5 of ``_approximate_derivatives``."""
    return np.round(
        _derivative(_unwrap(states[..., HEADING]), t, window=5, poly=poly, deriv=deriv), 8
    )


def _jerk(acc: F64, t: F64, window: int) -> F64:
    return np.round(_derivative(acc, t, window=window, poly=2, deriv=1), 8)


def _within(x: F64, lo: float, hi: float) -> npt.NDArray[np.bool_]:
    return np.asarray(((x > lo) & (x < hi)).all(axis=-1), dtype=bool)


def _center_acceleration(states: F64, rear_axle_to_center_m: float) -> tuple[F64, F64]:
    """v2 ``state_array_to_center_state_array``'s acceleration: NAVSIM's
    ``get_acceleration_shifted`` adds ``d·ω²`` and ``d·α`` to x (the displacement times each
    term, both along x) and nothing to y."""
    d = rear_axle_to_center_m
    w = states[..., ANGULAR_VELOCITY]
    a = states[..., ANGULAR_ACCELERATION]
    return states[..., ACCELERATION_X] + d * w**2 + d * a, states[..., ACCELERATION_Y].copy()


def comfortable(
    states: F64,
    t: F64,
    *,
    version: str,
    rear_axle_to_center_m: float,
    bounds: Mapping[str, float] = COMFORT_BOUNDS,
) -> npt.NDArray[np.bool_]:
    """(B,) all six comfort bounds hold for each of ``states`` (B, T, 11) at times ``t`` (T,).

    ``version`` "v1" (NAVSIM v1.1: accelerations on the rear axle, acceleration windows the
    whole horizon, jerks' inner window 8 and outer the horizon) or "v2" (rear-axle magnitude,
    centre x / y, acceleration window 8, jerk window 15)."""
    n = states.shape[1]
    ax_rear, ay_rear = states[..., ACCELERATION_X], states[..., ACCELERATION_Y]
    mag = np.hypot(ax_rear, ay_rear)
    if version == "v1":
        lon = _acceleration(ax_rear, n)
        lat = _acceleration(ay_rear, n)
        jerk = _jerk(_acceleration(mag, 8), t, n)
        lon_jerk = _jerk(_acceleration(ax_rear, 8), t, n)
    elif version == "v2":
        ax_c, ay_c = _center_acceleration(states, rear_axle_to_center_m)
        lon = _acceleration(ax_c, 8)
        lat = _acceleration(ay_c, 8)
        jerk = _jerk(_acceleration(mag, 8), t, 15)
        lon_jerk = _jerk(_acceleration(ax_c, 8), t, 15)
    else:
        msg = f"NAVSIM comfort: version must be 'v1' or 'v2', got {version!r}"
        raise ValueError(msg)
    b = bounds
    ok = _within(lon, b["min_lon_accel"], b["max_lon_accel"])
    ok &= _within(lat, -b["max_abs_lat_accel"], b["max_abs_lat_accel"])
    ok &= _within(jerk, -b["max_abs_mag_jerk"], b["max_abs_mag_jerk"])
    ok &= _within(lon_jerk, -b["max_abs_lon_jerk"], b["max_abs_lon_jerk"])
    yaw_acc = _yaw(states, t, deriv=2, poly=3)
    ok &= _within(yaw_acc, -b["max_abs_yaw_accel"], b["max_abs_yaw_accel"])
    yaw_rate = _yaw(states, t, deriv=1, poly=2)
    ok &= _within(yaw_rate, -b["max_abs_yaw_rate"], b["max_abs_yaw_rate"])
    return ok


def _features(states: F64, t: F64) -> dict[str, F64]:
    """v2 ``extract_features``: rear-axle acceleration magnitude (window 8), its jerk (window
    15), yaw rate and yaw acceleration (window 5, order 2)."""
    mag = np.hypot(states[..., ACCELERATION_X], states[..., ACCELERATION_Y])
    acc = _acceleration(mag, 8)
    return {
        "acceleration": acc,
        "jerk": _jerk(acc, t, 15),
        "yaw_rate": _yaw(states, t, deriv=1, poly=2),
        "yaw_accel": _yaw(states, t, deriv=2, poly=2),
    }


def two_frame_extended_comfort(
    current: F64,
    previous: F64,
    *,
    interval_s: float,
    gap_s: float,
    thresholds: Mapping[str, float] = EC_THRESHOLDS,
) -> float:
    """v2 ``SceneAggregator._compute_two_frame_comfort`` + ``ego_is_two_frame_extended_comfort``:
    1.0 when the RMS of the difference of each feature over the overlap of the current
    simulated proposal (T, 11) and the previous one (``gap_s`` earlier) is within its threshold,
    else 0.0."""
    overlap = round(gap_s / interval_s)
    if overlap <= 0 or overlap >= current.shape[0]:
        msg = f"two-frame extended comfort: gap {gap_s} s does not overlap the horizon"
        raise ValueError(msg)
    cur = current[:-overlap][None]
    prev = previous[overlap:][None]
    t = np.arange(cur.shape[1], dtype=np.float64) * interval_s
    f1, f2 = _features(cur, t), _features(prev, t)
    ok = True
    for key, limit in thresholds.items():
        rms = float(np.sqrt(np.mean((f1[key] - f2[key]) ** 2, axis=1))[0])
        ok = ok and rms <= limit
    return 1.0 if ok else 0.0
