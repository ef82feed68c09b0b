"""The pure-pursuit-pid controller's path lookups as numba kernels (compiled once, cached).

:func:`lookahead_point` is the pure-pursuit target (the foot of the rear axle on the path, then
``lookahead_m`` of arc length along it) and :func:`path_speeds` the speeds the waypoints imply
around given times — each one compiled pass over the waypoints instead of a dozen numpy calls on
arrays of ~60 rows.  They do the float64 operations of the numpy code they replaced in the same
order, so the commands are bit for bit the same (numba compiles without ``fastmath``):

* ``np.hypot`` and numba's ``math.hypot`` are the same C ``hypot``; the norm of a row of three
  is ``sqrt(((0 + x²) + y²) + z²)`` and a dot product of two ``(0 + x·x') + y·y'``, as numpy's
  reductions over a short last axis add them;
* ``np.clip`` keeps -0.0 and NaN (the comparisons below do too); the first minimum wins unless a
  NaN comes first (as ``np.argmin``); ``np.searchsorted(side="right")`` puts a NaN key last;
* ``np.interp`` is written out with its special cases (an end point, a knot hit exactly, a NaN
  slope product retried from the right knot), ``np.median`` as the middle of the sorted values
  (the mean of the two middle ones for an even count).
"""

# clip / max / min written out, the first argument kept as numpy's clip and Python's builtins do
# ruff: noqa: PLR1730

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba
import numpy as np
import numpy.typing as npt

from redrive.algorithms.reference._numeric_kernels import interp_at, segment_at

__all__ = ["lookahead_point", "path_speeds"]

_F = TypeVar("_F", bound=Callable[..., Any])
_F64 = npt.NDArray[np.float64]


def _jit(fn: _F) -> _F:
    return cast(_F, numba.njit(cache=True, nogil=True)(fn))


@_jit
def lookahead_point(
    xy: _F64, lookahead_m: float
) -> tuple[bool, float, float]:  # pragma: no cover - compiled
    """The point ``lookahead_m`` of arc length along the path ``xy`` (K, ≥ 2: x, y first) from the foot of the
    origin on it, the last segment extended past the end: ``(True, x, y)``; ``(False, 0, 0)``
    when the path has no length (every segment ≤ 1 nm)."""
    k_pts = xy.shape[0]
    n_seg = k_pts - 1 if k_pts > 0 else 0
    ax = np.empty(n_seg)
    ay = np.empty(n_seg)
    abx = np.empty(n_seg)
    aby = np.empty(n_seg)
    seg_len = np.empty(n_seg)
    m = 0
    for i in range(n_seg):
        dx = xy[i + 1, 0] - xy[i, 0]
        dy = xy[i + 1, 1] - xy[i, 1]
        length = math.hypot(dx, dy)
        if length > 1e-9:
            ax[m] = xy[i, 0]
            ay[m] = xy[i, 1]
            abx[m] = dx
            aby[m] = dy
            seg_len[m] = length
            m += 1
    if m == 0:
        return False, 0.0, 0.0
    s_start = np.empty(m)
    s_start[0] = 0.0
    total = 0.0
    for i in range(m - 1):
        total = total + seg_len[i]
        s_start[i + 1] = total
    best = 0
    best_d = 0.0
    best_t = 0.0
    for i in range(m):
        t = -((0.0 + ax[i] * abx[i]) + ay[i] * aby[i]) / (seg_len[i] * seg_len[i])
        if t < 0.0:
            t = 0.0
        if t > 1.0:
            t = 1.0
        d = math.hypot(ax[i] + t * abx[i], ay[i] + t * aby[i])
        if i == 0:
            best_d, best_t = d, t
            if math.isnan(d):
                break
        elif math.isnan(d):
            best, best_d, best_t = i, d, t
            break
        elif d < best_d:
            best, best_d, best_t = i, d, t
    s_target = s_start[best] + best_t * seg_len[best] + lookahead_m
    # searchsorted(side="right") - 1, clipped to the segments; a NaN key sorts last
    k = segment_at(s_target, s_start, m, m - 1)
    f = (s_target - s_start[k]) / seg_len[k]
    return True, ax[k] + f * abx[k], ay[k] + f * aby[k]


@_jit
def path_speeds(waypoints: _F64, times_s: _F64) -> _F64:  # pragma: no cover - compiled
    """The speed (m/s) the waypoints (K, 4: x, y, z, t_s) imply around each of ``times_s``:
    arc length over time across one median waypoint step centred on the time (clipped to the
    path's times); zeros for a path of fewer than two distinct times."""
    n_t = times_s.shape[0]
    out = np.zeros(n_t)
    k_pts = waypoints.shape[0]
    if k_pts < 2 or waypoints[k_pts - 1, 3] - waypoints[0, 3] <= 0.0:
        return out
    times = np.empty(k_pts)
    s = np.empty(k_pts)
    s[0] = 0.0
    total = 0.0
    steps = np.empty(k_pts - 1)
    n_pos = 0
    for i in range(k_pts):
        times[i] = waypoints[i, 3]
        if i > 0:
            dx = waypoints[i, 0] - waypoints[i - 1, 0]
            dy = waypoints[i, 1] - waypoints[i - 1, 1]
            dz = waypoints[i, 2] - waypoints[i - 1, 2]
            total = total + math.sqrt(((0.0 + dx * dx) + dy * dy) + dz * dz)
            s[i] = total
            step = times[i] - times[i - 1]
            if step > 0.0:
                steps[n_pos] = step
                n_pos += 1
    if n_pos == 0:
        median = math.nan
    else:
        ordered = np.sort(steps[:n_pos])
        mid = n_pos // 2
        median = ordered[mid] if n_pos % 2 else (ordered[mid - 1] + ordered[mid]) / 2.0
    half = 0.5 * median
    first = times[0]
    last = times[k_pts - 1]
    for i in range(n_t):
        # max/min as Python's builtins: the first argument unless the other compares greater
        t0 = times_s[i] - half
        if first > t0:
            t0 = first
        upper = last - 2.0 * half
        if upper < t0:
            t0 = upper
        if first > t0:
            t0 = first
        t1 = t0 + 2.0 * half
        if last < t1:
            t1 = last
        if t1 > t0:
            out[i] = (interp_at(t1, times, s) - interp_at(t0, times, s)) / (t1 - t0)
    return out
