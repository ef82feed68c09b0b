"""Compiled route geometry shared by the world's kernels (numba, no ``fastmath``).

Each function gives bit for bit what its Python counterpart in :mod:`redrive.sim.roads` gives:
the same float64 operations in the same order, ties to the first segment.  The routes of a
network are read from one array of samples (``GapSearch.net``: rows s, x, y, …, heading, tangent
norm) in which each route is a run of ``n`` samples from ``off``.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["bisect_left", "bisect_right", "hypot", "project_point", "route_pose"]

F64 = npt.NDArray[np.float64]


@numba.njit(cache=True, nogil=True)
def bisect_right(a: F64, lo: int, hi: int, x: float) -> int:  # pragma: no cover - compiled
    """``bisect.bisect_right(a[lo:hi], x)`` (an index into the slice)."""
    left, right = lo, hi
    while left < right:
        mid = (left + right) // 2
        if x < a[mid]:
            right = mid
        else:
            left = mid + 1
    return left - lo


@numba.njit(cache=True, nogil=True)
def bisect_left(a: F64, lo: int, hi: int, x: float) -> int:  # pragma: no cover - compiled
    """``bisect.bisect_left(a[lo:hi], x)`` (an index into the slice)."""
    left, right = lo, hi
    while left < right:
        mid = (left + right) // 2
        if a[mid] < x:
            left = mid + 1
        else:
            right = mid
    return left - lo


@numba.njit(cache=True, nogil=True, error_model="numpy")
def route_pose(
    net: F64, off: int, n: int, s_m: float, d_m: float
) -> tuple[float, float, float]:  # pragma: no cover - compiled
    """:meth:`Route.pose_at` of the route of samples ``off … off + n - 1`` in ``net``."""
    s_arr, xs, ys, hs, norms = net[0], net[1], net[2], net[7], net[8]
    j = min(max(bisect_right(s_arr, off, off + n, s_m) - 1, 0), n - 2) + off
    ds = s_arr[j + 1] - s_arr[j]
    t = (s_m - s_arr[j]) / ds
    x0, y0 = xs[j], ys[j]
    tx, ty = (xs[j + 1] - x0) / ds, (ys[j + 1] - y0) / ds
    norm = norms[j]
    heading = hs[j] + min(max(t, 0.0), 1.0) * (hs[j + 1] - hs[j])
    x = x0 + t * ds * tx - d_m * ty / norm
    y = y0 + t * ds * ty + d_m * tx / norm
    return x, y, heading


@numba.njit(cache=True, nogil=True, error_model="numpy")
def project_point(  # noqa: PLR0917 (numba has no keyword-only parameters)
    s_arr: F64, xs: F64, ys: F64, lo: int, hi: int, x_m: float, y_m: float
) -> tuple[float, float, bool]:  # pragma: no cover - compiled
    """:meth:`Route.project_point` onto the segments ``lo … hi - 1``: arclength, signed
    distance, and False when a segment has zero length (the caller then asks numpy)."""
    best = np.inf
    best_t = best_rx = best_ry = best_sx = best_sy = 0.0
    best_j = lo
    for i in range(lo, hi):
        ax, ay = xs[i], ys[i]
        sx, sy = xs[i + 1] - ax, ys[i + 1] - ay
        seg_len = s_arr[i + 1] - s_arr[i]
        if seg_len * seg_len == 0.0:
            return 0.0, 0.0, False
        rx, ry = x_m - ax, y_m - ay
        t = ((rx * sx + ry * sy) + 0.0) / (seg_len * seg_len)
        if t < 0.0:
            t = 0.0
        elif t > 1.0:
            t = 1.0
        dx, dy = rx - t * sx, ry - t * sy
        dist2 = dx * dx + dy * dy
        if i == lo or dist2 < best or (not dist2 >= best and not math.isnan(best)):
            best, best_j, best_t = dist2, i, t
            best_rx, best_ry, best_sx, best_sy = rx, ry, sx, sy
    s = s_arr[best_j] + best_t * (s_arr[best_j + 1] - s_arr[best_j])
    cross = best_sx * best_ry - best_sy * best_rx
    return s, (-1.0 if cross < 0.0 else 1.0) * math.sqrt(best), True


@numba.njit(cache=True, nogil=True)
def _dl_mul(x: float, y: float) -> tuple[float, float]:  # pragma: no cover - compiled
    """``x * y`` as a sum of two floats, exactly (Dekker's product with Veltkamp's split)."""
    t = x * 134217729.0
    xh = t - (t - x)
    xl = x - xh
    t = y * 134217729.0
    yh = t - (t - y)
    yl = y - yh
    p = xh * yh
    q = xh * yl + xl * yh
    z = p + q
    return z, p - z + q + xl * yl


@numba.njit(cache=True, nogil=True)
def hypot(a: float, b: float) -> float:  # pragma: no cover - compiled
    """Python's ``math.hypot(a, b)`` bit for bit (CPython 3.11's ``vector_norm``: scaled,
    lossless squares, a corrected square root) — libm's ``hypot``, which numba calls, differs
    from it in the last bit for about one pair in 200."""
    x, y = abs(a), abs(b)
    m = max(x, y)
    if math.isinf(m):
        return m
    if math.isnan(x) or math.isnan(y):
        return math.nan
    if m == 0.0:
        return m
    _, e = math.frexp(m)
    if e < -1023:  # deep in the subnormals: never for metres (CPython rescales by DBL_MIN)
        return math.sqrt(x * x + y * y)
    scale = math.ldexp(1.0, -e)
    csum, frac1, frac2 = 1.0, 0.0, 0.0
    for v in (a * scale, b * scale):
        hi, lo = _dl_mul(v, v)
        s = csum + hi
        frac2 += hi - (s - csum)
        csum = s
        frac1 += lo
    h = math.sqrt(csum - 1.0 + (frac1 + frac2))
    hi, lo = _dl_mul(-h, h)
    s = csum + hi
    frac2 += hi - (s - csum)
    csum = s
    frac1 += lo
    h += (csum - 1.0 + (frac1 + frac2)) / (2.0 * h)
    return h / scale
