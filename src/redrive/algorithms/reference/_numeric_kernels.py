"""numpy's scalar special cases written out for the planner's and controller's numba kernels
(``_plan_kernels``, ``_control_kernels``) and the closed loop's LQR tracker
(``redrive.closedloop._tracker_kernels``): the same float64 operations in the same order, so the
kernels stay bit for bit equal to the numpy code they replaced."""

# clip written out, the first argument kept as numpy's clip does
# ruff: noqa: PLR1730

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

__all__ = [
    "MAX_PAIRWISE",
    "interp_at",
    "interp_knot",
    "interp_on",
    "nan_span",
    "pairwise_sum",
    "segment_at",
    "unwrap",
]

_F64 = npt.NDArray[np.float64]


@numba.njit(cache=True, nogil=True)
def interp_knot(x: float, xp: _F64, j0: int) -> int:  # pragma: no cover - compiled
    """The knot :func:`interp_at` ends its search on for ``x`` (-1 where it returns before
    searching: ``x`` NaN or beyond an end), its scan started at knot ``j0`` instead of 0 — the
    same knot when ``j0`` is 0 or the knot of a search for some ``x0 <= x`` (every knot the scan
    from 0 steps past, ``x0 >= xp[j + 1]``, it steps past for ``x`` too: whatever ``xp`` holds).
    """
    n = xp.shape[0]
    if math.isnan(x) or x > xp[n - 1] or x < xp[0]:
        return -1
    j = j0
    while j + 1 < n and x >= xp[j + 1]:
        j += 1
    return j


@numba.njit(cache=True, nogil=True)
def interp_on(x: float, xp: _F64, fp: _F64, j: int) -> float:  # pragma: no cover - compiled
    """:func:`interp_at` of ``x`` whose search ended on knot ``j`` (:func:`interp_knot`'s,
    -1: one of its early returns) — the same float64 operations."""
    n = xp.shape[0]
    if j < 0:
        if math.isnan(x):
            return x
        if x > xp[n - 1]:
            return float(fp[n - 1])
        return float(fp[0])
    if j == n - 1 or xp[j] == x:
        return float(fp[j])
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    out: float = slope * (x - xp[j]) + fp[j]
    if math.isnan(out):
        out = slope * (x - xp[j + 1]) + fp[j + 1]
        if math.isnan(out) and fp[j] == fp[j + 1]:
            out = fp[j]
    return out


@numba.njit(cache=True, nogil=True)
def interp_at(x: float, xp: _F64, fp: _F64) -> float:  # pragma: no cover - compiled
    """``np.interp`` at one point (``xp`` ascending): an end point, a knot hit exactly, a NaN
    slope product retried from the right knot — :func:`interp_on` of :func:`interp_knot`'s
    search from knot 0."""
    return interp_on(x, xp, fp, interp_knot(x, xp, 0))


@numba.njit(cache=True, nogil=True)
def segment_at(v: float, starts: _F64, m: int, last: int) -> int:  # pragma: no cover - compiled
    """``np.searchsorted(starts[:m], v, side="right") - 1`` clipped to ``[0, last]`` (a NaN
    key sorts last)."""
    k = m
    if not math.isnan(v):
        k = 0
        while k < m and not v < starts[k]:
            k += 1
    k -= 1
    if k < 0:
        k = 0
    if k > last:
        k = last
    return k


@numba.njit(cache=True, nogil=True)
def nan_span(values: _F64, start: int, count: int) -> tuple[float, float]:  # pragma: no cover
    """``values[start:start + count]``'s minimum and maximum as numpy's (a NaN wins both)."""
    lo = values[start]
    hi = lo
    for c in range(1, count):
        v = values[start + c]
        if math.isnan(lo) or math.isnan(v):
            lo = math.nan
            hi = math.nan
        else:
            if v < lo:
                lo = v
            if v > hi:
                hi = v
    return lo, hi


#: the longest sum :func:`pairwise_sum` adds as numpy does (numpy's ``PW_BLOCKSIZE``; past it
#: numpy recurses, which a cached numba kernel cannot)
MAX_PAIRWISE = 128


@numba.njit(cache=True, nogil=True)
def pairwise_sum(a: _F64, n: int) -> float:  # pragma: no cover - compiled
    """``a[:n].sum()`` as numpy adds it (its float64 add reduction, ``pairwise_sum``: from the
    identity 0.0, eight accumulators from eight values on), ``n`` ≤ :data:`MAX_PAIRWISE`."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return res
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = 8
    while i < n - n % 8:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = 0.0 + (((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)))
    while i < n:
        res += a[i]
        i += 1
    return float(res)


@numba.njit(cache=True, nogil=True)
def unwrap(p: _F64, n: int, out: _F64) -> None:  # pragma: no cover - compiled
    """``out[:n] = np.unwrap(p[:n])`` (period 2π, discont π): each step's principal value
    (``mod(d + π, 2π) − π``, +π for a step of exactly +π), its correction where the step is at
    least π, the corrections' cumulative sum added."""
    if n == 0:
        return
    out[0] = p[0]
    correction = 0.0
    for i in range(1, n):
        dd = p[i] - p[i - 1]
        ddmod = (dd - (-math.pi)) % (2.0 * math.pi) + (-math.pi)
        if ddmod == -math.pi and dd > 0.0:
            ddmod = math.pi
        ph = ddmod - dd
        if abs(dd) < math.pi:
            ph = 0.0
        correction = ph if i == 1 else correction + ph
        out[i] = p[i] + correction
