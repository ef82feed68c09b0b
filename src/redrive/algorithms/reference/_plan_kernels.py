"""The IDM planner's speed profile as a numba kernel (compiled once, cached on disk).

:func:`idm_profile` is the planner's forward integration — every leader's gap, the IDM
acceleration, the ballistic update and the ``s0`` guard, one waypoint per step — as one compiled
call instead of ~60 Python steps over Python lists.  It does the float64 operations of the Python
loop it replaced in the same order, so the plans are bit for bit the same (numba compiles without
``fastmath``: no reassociation, no fused multiply-add):

* ``max``/``min`` are written out as Python's builtins choose (the first argument unless the other
  compares greater / smaller), so -0.0 and NaN go the same way;
* the powers go through ``pow`` with the exponent passed in at run time (as Python's ``**`` on
  floats; a literal ``2.0`` would let LLVM turn ``pow(x, 2.0)`` into ``x * x``);
* the nearest leader is the first minimum, or the first NaN when there is one (as ``np.argmin``).
"""

# max/min written out, the constant first, as Python's builtins compare (see above)
# ruff: noqa: PLR1730, SIM300

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["idm_profile"]

_F64 = npt.NDArray[np.float64]


@numba.njit(cache=True, nogil=True)
def _first_min(values: _F64, n: int) -> int:  # pragma: no cover - compiled
    best = 0
    for i in range(n):
        value = values[i]
        if math.isnan(value):
            return i
        if value < values[best]:
            best = i
    return best


@numba.njit(cache=True, nogil=True)
def idm_profile(  # noqa: PLR0917 - numba takes no keyword-only parameters
    speed_mps: float,
    lead_s: _F64,
    lead_v: _F64,
    n: int,
    dt: float,
    front: float,
    s0: float,
    v0: float,
    delta: float,
    headway: float,
    a_max: float,
    b: float,
    max_decel: float,
    two: float,
) -> _F64:  # pragma: no cover - compiled
    """Arc lengths (n + 1,) of the rear axle along the path, metres, at t = k·dt: the IDM plan
    from ``speed_mps`` behind the leaders (rear arc lengths ``lead_s``, speeds ``lead_v``, each
    moving at constant speed).  ``front`` is the rear-axle-to-front-bumper offset; ``two`` must
    be 2.0 (a run-time exponent, see the module docstring)."""
    m = lead_s.shape[0]
    gaps = np.empty(max(m, 1))
    s_out = np.zeros(n + 1)
    s = 0.0
    v = speed_mps
    if 0.0 > v:
        v = 0.0
    sqrt_ab = 2.0 * math.sqrt(a_max * b)
    for k in range(n):
        t = k * dt
        gap = math.inf
        v_lead = 0.0
        j = -1
        if m > 0:
            for i in range(m):
                gaps[i] = lead_s[i] + lead_v[i] * t - (s + front)
            j = _first_min(gaps, m)
            gap = gaps[j]
            v_lead = lead_v[j]
        # the IDM acceleration
        vv = v
        if 0.0 > vv:
            vv = 0.0
        free = 1.0 - (vv / v0) ** delta
        interaction = 0.0
        if math.isfinite(gap):
            dyn = v * headway + v * (v - v_lead) / sqrt_ab
            s_star = s0 + (dyn if dyn > 0.0 else 0.0)
            g = gap
            if 1e-3 > g:
                g = 1e-3
            interaction = (s_star / g) ** two
        accel = a_max * (free - interaction)
        if -max_decel > accel:
            accel = -max_decel
        if a_max < accel:
            accel = a_max
        # the ballistic update, never reversing
        if v + accel * dt < 0.0:
            s_new = s - v * v / (2.0 * accel)
            v_new = 0.0
        else:
            s_new = s + v * dt + 0.5 * accel * dt * dt
            v_new = v + accel * dt
        if j >= 0:  # never closer than s0 to any obstacle
            for i in range(m):
                gaps[i] = lead_s[i] + lead_v[i] * (t + dt) - front - s0
            jj = _first_min(gaps, m)
            limit = gaps[jj]
            if s > limit:
                limit = s
            if s_new > limit:
                s_new = limit
                if lead_v[jj] < v_new:
                    v_new = lead_v[jj]
        s = s_new
        v = v_new
        s_out[k + 1] = s
    return s_out
