"""The IDM planner's speed profile and path geometry as numba kernels (compiled once, cached).

:func:`polyline_arc`, :func:`points_at` and :func:`leaders_on_path` (with :func:`project_pruned`)
are :class:`~redrive.algorithms.reference.planner.Polyline`'s arc lengths and points and the
planner's choice of leaders, each one compiled call doing the numpy code's float64 operations
(``hypot``, ``np.interp`` written out, numpy's minimum, maximum and ``searchsorted`` choices).

:func:`idm_profile` is the planner's forward integration — every leader's gap, the IDM
acceleration (:func:`redrive.motion.idm.idm_kernel`, the one IDM the world's agents use too), the
ballistic update and the ``s0`` guard, one waypoint per step — as one compiled call instead of ~60
Python steps over Python lists (numba caches this file's kernels by this file alone: after an
edit of ``motion/idm.py``, run ``make clean-kernels``).  It does the float64 operations of the Python
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

from redrive.algorithms.reference._kernels import project_on_segments
from redrive.algorithms.reference._numeric_kernels import (
    interp_knot,
    interp_on,
    nan_span,
    segment_at,
    unwrap,
)
from redrive.motion.idm import idm_kernel

__all__ = [
    "box_frames",
    "curve_speed",
    "gate_crossing",
    "idm_profile",
    "leaders_on_path",
    "points_at",
    "polyline_arc",
    "project_pruned",
]

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
        # the IDM acceleration (v0 as given, the gap at least 1 mm)
        accel = idm_kernel(
            v, gap, v_lead, v0, delta, headway, s0, a_max, b, max_decel, -math.inf, 1e-3, two
        )
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


@numba.njit(cache=True, nogil=True)
def polyline_arc(xy: _F64) -> tuple[_F64, _F64]:  # pragma: no cover - compiled
    """:class:`~redrive.algorithms.reference.planner.Polyline`'s vertices and arc lengths from
    ``xy`` (M, 2), M ≥ 2: a vertex is dropped when it lies within 1 nm (``hypot``) of the
    vertex before it in ``xy``; the arc lengths are the running sum of the kept segments'
    ``hypot`` from 0 (as ``np.cumsum``)."""
    m = xy.shape[0]
    keep = np.empty(m, dtype=np.bool_)
    keep[0] = True
    count = 1
    for i in range(1, m):
        keep[i] = math.hypot(xy[i, 0] - xy[i - 1, 0], xy[i, 1] - xy[i - 1, 1]) > 1e-9
        if keep[i]:
            count += 1
    pts = np.empty((count, 2))
    s = np.empty(count)
    k = 0
    total = 0.0
    for i in range(m):
        if keep[i]:
            pts[k, 0] = xy[i, 0]
            pts[k, 1] = xy[i, 1]
            if k == 0:
                s[0] = 0.0
            else:
                total = total + math.hypot(pts[k, 0] - pts[k - 1, 0], pts[k, 1] - pts[k - 1, 1])
                s[k] = total
            k += 1
    return pts, s


@numba.njit(cache=True, nogil=True)
def points_at(xy: _F64, s: _F64, s_m: _F64) -> _F64:  # pragma: no cover - compiled
    """:meth:`Polyline.points_at`: (K, 2) points of the polyline (vertices ``xy`` (M, 2), arc
    lengths ``s``) at arc lengths ``s_m`` (K,) — ``np.interp`` of x and y, and beyond either end
    the end segment extended straight (its direction ``d / hypot(d)``)."""
    k_out = s_m.shape[0]
    m = xy.shape[0]
    out = np.empty((k_out, 2))
    if m == 1:
        for i in range(k_out):
            out[i, 0] = xy[0, 0]
            out[i, 1] = xy[0, 1]
        return out
    end = s[m - 1]
    ex = xy[m - 1, 0] - xy[m - 2, 0]
    ey = xy[m - 1, 1] - xy[m - 2, 1]
    norm = math.hypot(ex, ey)
    ex, ey = ex / norm, ey / norm
    bx = xy[1, 0] - xy[0, 0]
    by = xy[1, 1] - xy[0, 1]
    norm = math.hypot(bx, by)
    bx, by = bx / norm, by / norm
    # np.interp's knot search (interp_at's scan) once for x and y, and from the last search's
    # knot while the arc lengths do not decrease (a plan's: one pass over the knots, not one
    # from the start per point and coordinate) — the same knots, the same values
    last_v = math.nan
    last_j = 0
    for i in range(k_out):
        v = s_m[i]
        if v > end:
            out[i, 0] = xy[m - 1, 0] + (v - end) * ex
            out[i, 1] = xy[m - 1, 1] + (v - end) * ey
        elif v < 0.0:
            out[i, 0] = xy[0, 0] + (v - 0.0) * bx
            out[i, 1] = xy[0, 1] + (v - 0.0) * by
        else:
            j = interp_knot(v, s, last_j if v >= last_v else 0)
            if j >= 0:
                last_v, last_j = v, j
            out[i, 0] = interp_on(v, s, xy[:, 0], j)
            out[i, 1] = interp_on(v, s, xy[:, 1], j)
    return out


#: a segment is skipped only when it is provably farther than the best one by this much (metres,
#: scaled by 1 + the distance), far above float64 rounding of path coordinates
_PRUNE_MARGIN = 1e-6
#: a point of project_pruned this near the one before it (squared metres) takes the distance of
#: that one's nearest segment as its first bound
_NEAR_M2 = 100.0
#: segments per block of project_pruned (each block's first gives the first bound of a point's
#: distance; a block whose box is farther than the bound is skipped)
_PRUNE_STRIDE = 16


@numba.njit(cache=True, nogil=True)
def _segment_d2(  # noqa: PLR0917 - numba takes no keyword-only parameters
    px: float, py: float, a: _F64, ab: _F64, seg_len: _F64, k: int
) -> tuple[float, float]:  # pragma: no cover - compiled
    """Squared distance of (px, py) from segment k and the foot's fraction along it, as
    :func:`._kernels.project_on_segments` computes them."""
    apx = px - a[k, 0]
    apy = py - a[k, 1]
    t = ((0.0 + apx * ab[k, 0]) + apy * ab[k, 1]) / (seg_len[k] * seg_len[k])
    if t < 0.0:
        t = 0.0
    if t > 1.0:
        t = 1.0
    ex = px - (a[k, 0] + t * ab[k, 0])
    ey = py - (a[k, 1] + t * ab[k, 1])
    return (0.0 + ex * ex) + ey * ey, t


@numba.njit(cache=True, nogil=True)
def project_pruned(  # noqa: PLR0917 - numba takes no keyword-only parameters
    p: _F64, a: _F64, ab: _F64, seg_len: _F64, s_start: _F64, s_end: float
) -> tuple[_F64, _F64]:  # pragma: no cover - compiled
    """Arc length and signed lateral offset of each point ``p`` (P, 2) on the polyline of
    segments ``a + t·ab`` (arc length ``s_start`` at ``a``; the last ends at ``s_end``): the
    values :func:`._kernels.project_on_segments` gives, without looking at every segment.

    The segments go in blocks of ``_PRUNE_STRIDE``, each with the bounding box of its segments'
    ends.  For each point, the first segment of every block (and the last segment) gives a
    bound of the least distance; then every segment of the blocks in order, but for the blocks
    whose box is farther from the point than the bound (plus a margin: each of their segments
    is strictly farther than the bound even after rounding, so the first minimum of the
    segments looked at is the first of all).  Non-finite inputs take the full search.
    """
    n_p = p.shape[0]
    n_s = a.shape[0]
    finite = math.isfinite(s_end)
    for k in range(n_s):
        if not (
            math.isfinite(a[k, 0])
            and math.isfinite(a[k, 1])
            and math.isfinite(ab[k, 0])
            and math.isfinite(ab[k, 1])
            and math.isfinite(seg_len[k])
            and math.isfinite(s_start[k])
        ):
            finite = False
    for i in range(n_p):
        if not (math.isfinite(p[i, 0]) and math.isfinite(p[i, 1])):
            finite = False
    if not finite:
        s_full, lateral_full, _ = project_on_segments(p, a, ab, seg_len, s_start)
        return s_full, lateral_full
    s_out = np.empty(n_p)
    lateral = np.empty(n_p)
    stride = _PRUNE_STRIDE
    n_b = (n_s + stride - 1) // stride
    # every block's box: (x min, x max, y min, y max) of its segments' two ends
    box = np.empty((n_b, 4))
    for j in range(n_b):
        box[j, 0] = box[j, 2] = np.inf
        box[j, 1] = box[j, 3] = -np.inf
    for k in range(n_s):
        j = k // stride
        for x in (a[k, 0], a[k, 0] + ab[k, 0]):
            box[j, 0] = min(box[j, 0], x)
            box[j, 1] = max(box[j, 1], x)
        for y in (a[k, 1], a[k, 1] + ab[k, 1]):
            box[j, 2] = min(box[j, 2], y)
            box[j, 3] = max(box[j, 3], y)
    best = 0
    for i in range(n_p):
        px = p[i, 0]
        py = p[i, 1]
        # an upper bound of the least distance: the distance of the last point's nearest
        # segment, for a point near the last one (the corners of one box); else every block's
        # first segment's (and the last's) — any segment's distance bounds it
        if i > 0 and (px - p[i - 1, 0]) ** 2 + (py - p[i - 1, 1]) ** 2 < _NEAR_M2:
            ub_d2, _ = _segment_d2(px, py, a, ab, seg_len, best)
        else:
            ub_d2 = np.inf
            k = 0
            while k < n_s:
                d2, _ = _segment_d2(px, py, a, ab, seg_len, k)
                if d2 < ub_d2:
                    ub_d2 = d2
                k = n_s - 1 if stride + k >= n_s and k < n_s - 1 else k + stride
        bound = math.sqrt(ub_d2)
        reach = bound + _PRUNE_MARGIN * (1.0 + bound)
        reach2 = reach * reach
        best = 0
        best_d2 = np.inf
        best_t = 0.0
        for j in range(n_b):
            dx = max(box[j, 0] - px, 0.0, px - box[j, 1])
            dy = max(box[j, 2] - py, 0.0, py - box[j, 3])
            if dx * dx + dy * dy > reach2:
                continue  # every segment of the block is farther than the bound
            for k in range(j * stride, min(n_s, (j + 1) * stride)):
                d2, t = _segment_d2(px, py, a, ab, seg_len, k)
                if d2 < best_d2:
                    best, best_d2, best_t = k, d2, t
        s_out[i] = s_start[best] + best_t * seg_len[best]
        cross = ab[best, 0] * (py - a[best, 1]) - ab[best, 1] * (px - a[best, 0])
        lateral[i] = cross / seg_len[best]
    return s_out, lateral


@numba.njit(cache=True, nogil=True)
def leaders_on_path(  # noqa: PLR0917 - numba takes no keyword-only parameters
    local: _F64,
    centers: _F64,
    velocities: _F64,
    xy: _F64,
    s: _F64,
    half_width_m: float,
    front_m: float,
    far_m: float,
) -> tuple[_F64, _F64]:  # pragma: no cover - compiled
    """:meth:`IdmPlanner._leaders` after the boxes' rotated corners: the objects (``local`` (n,
    ≥ 4, ≥ 2): the corners about the centre, the bottom four first — a corner is ``local +
    centre``, the float64 sum numpy's ``local @ rotations + centers[:, None, :]`` was; centres
    (n, ≥ 2); velocities (n, ≥ 2)) whose corners projected on
    the path (vertices ``xy`` (M ≥ 2, 2), arc lengths ``s``) overlap the corridor ±
    ``half_width_m`` and reach past ``front_m`` and before ``far_m``; for each, in order, the
    arc length of its rear (the least corner's) and its speed along the path tangent at its
    centre's foot, floored at 0 (``np.maximum``: -0.0 and NaN pass).  The projection is
    :func:`project_pruned` (what :func:`._kernels.project_on_segments` gives); the minimum and maximum of the four
    corners are numpy's (a NaN wins)."""
    n = centers.shape[0]
    m = xy.shape[0]
    a = np.empty((m - 1, 2))
    ab = np.empty((m - 1, 2))
    seg_len = np.empty(m - 1)
    for k in range(m - 1):
        a[k, 0] = xy[k, 0]
        a[k, 1] = xy[k, 1]
        ab[k, 0] = xy[k + 1, 0] - xy[k, 0]
        ab[k, 1] = xy[k + 1, 1] - xy[k, 1]
        seg_len[k] = math.hypot(ab[k, 0], ab[k, 1])
    # each object's four bottom corners, then its centre (neighbours: project_pruned's bound)
    points = np.empty((5 * n, 2))
    for i in range(n):
        for c in range(4):
            points[5 * i + c, 0] = local[i, c, 0] + centers[i, 0]
            points[5 * i + c, 1] = local[i, c, 1] + centers[i, 1]
        points[5 * i + 4, 0] = centers[i, 0]
        points[5 * i + 4, 1] = centers[i, 1]
    s_all, lat_all = project_pruned(points, a, ab, seg_len, s[: m - 1], s[m - 1])
    out_s = np.empty(n)
    out_v = np.empty(n)
    count = 0
    for i in range(n):
        s_lo, s_hi = nan_span(s_all, 5 * i, 4)
        lat_lo, lat_hi = nan_span(lat_all, 5 * i, 4)
        in_corridor = lat_lo < half_width_m and lat_hi > -half_width_m
        ahead = s_hi > front_m and s_lo < far_m
        if not (in_corridor and ahead):
            continue
        # the tangent of the segment holding the centre's foot (searchsorted right - 1,
        # clipped to the segments; a NaN sorts last)
        foot = s_all[5 * i + 4]
        j = segment_at(foot, s, m, m - 2)
        dx = xy[j + 1, 0] - xy[j, 0]
        dy = xy[j + 1, 1] - xy[j, 1]
        h = math.hypot(dx, dy)
        speed = (0.0 + velocities[i, 0] * (dx / h)) + velocities[i, 1] * (dy / h)
        if not (speed >= 0.0 or math.isnan(speed)):
            speed = 0.0
        out_s[count] = s_lo
        out_v[count] = speed
        count += 1
    return out_s[:count].copy(), out_v[:count].copy()


@numba.njit(cache=True, nogil=True)
def box_frames(
    yaws: _F64, sizes: _F64, signs: _F64
) -> tuple[_F64, _F64]:  # pragma: no cover - compiled
    """:meth:`IdmPlanner._leaders`' operands of the boxes' corners (yaws (n,), sizes (n, 3),
    ``signs`` :data:`~redrive.geometry.boxes.BOX_CORNER_SIGNS` (8, 3)): the corners unrotated,
    ``signs * (0.5 * size)`` (n, 8, 3), and the rotations (n, 3, 3) the corners are multiplied
    by, rows (cos, sin, 0), (-sin, cos, 0), (0, 0, 1) (``math.cos`` and ``math.sin``: libm's, as
    Python's)."""
    n = yaws.shape[0]
    local = np.empty((n, 8, 3))
    rotations = np.zeros((n, 3, 3))
    for i in range(n):
        for k in range(3):
            half = 0.5 * sizes[i, k]
            for j in range(8):
                local[i, j, k] = signs[j, k] * half
        c = math.cos(yaws[i])
        sn = math.sin(yaws[i])
        rotations[i, 0, 0] = c
        rotations[i, 0, 1] = sn
        rotations[i, 1, 0] = -sn
        rotations[i, 1, 1] = c
        rotations[i, 2, 2] = 1.0
    return local, rotations


@numba.njit(cache=True, nogil=True)
def path_bounds(xy: _F64) -> tuple[float, float, float, float]:  # pragma: no cover - compiled
    """numpy's ``xy.min(axis=0)`` and ``xy.max(axis=0)`` of vertices (M ≥ 1, 2) — a NaN wins
    — in one pass (numpy's reductions along the first axis of a two-column array walk it
    with a buffered iterator: ≈ 100× the comparisons' cost), as four floats: x min, y min,
    x max, y max (numba boxes every array it returns at a cost of its own)."""
    x_lo, x_hi = _column_bounds(xy, 0)
    y_lo, y_hi = _column_bounds(xy, 1)
    return x_lo, y_lo, x_hi, y_hi


@numba.njit(cache=True, nogil=True)
def _column_bounds(xy: _F64, d: int) -> tuple[float, float]:  # pragma: no cover - compiled
    """numpy's min and max of column ``d`` of ``xy`` (a NaN wins both)."""
    lo = hi = xy[0, d]
    for k in range(1, xy.shape[0]):
        v = xy[k, d]
        if math.isnan(lo) or math.isnan(v):
            lo = hi = math.nan
        else:
            lo = min(lo, v)
            hi = max(hi, v)
    return lo, hi


@numba.njit(cache=True, nogil=True)
def gate_crossing(  # noqa: PLR0917 - numba takes no keyword-only parameters
    path_xy: _F64,
    path_s: _F64,
    line: _F64,
    x_lo: float,
    y_lo: float,
    x_hi: float,
    y_hi: float,
) -> tuple[bool, float, float, float]:  # pragma: no cover - compiled
    """:func:`._lights.stop_arcs`'s test of one stop line (``line`` (K, 2), base_link) against
    the path (vertices ``path_xy`` (M ≥ 2, 2), arc lengths ``path_s``, bounding box ``x_lo``,
    ``y_lo`` / ``x_hi``, ``y_hi``: numpy's min and max of the vertices, :func:`path_bounds`): (False, …) when the line's bounding box
    (numpy's max and min: a NaN wins, and then does not exclude) misses the path's, or the path
    does not cross the line; else (True, the arc length of the first crossing, the path's unit
    direction there).  The float64 operations of the numpy code it replaced, in its order: per
    line segment, every path segment's ``denom``, ``t`` and ``u`` (rows with ``|denom| ≤ 1e-12``
    skipped, as their ``ok`` was false), the first hit of each line segment, the least arc
    length over the line's segments (the first on a tie)."""
    k_n = line.shape[0]
    for d in range(2):
        top = line[0, d]
        bottom = line[0, d]
        for k in range(1, k_n):
            v = line[k, d]
            if math.isnan(top) or math.isnan(v):
                top = math.nan
            elif v > top:
                top = v
            if math.isnan(bottom) or math.isnan(v):
                bottom = math.nan
            elif v < bottom:
                bottom = v
        low = x_lo if d == 0 else y_lo
        high = x_hi if d == 0 else y_hi
        if top < low or bottom > high:
            return False, 0.0, 0.0, 0.0
    m = path_xy.shape[0]
    found = False
    best_s = 0.0
    best_x = 0.0
    best_y = 0.0
    for k in range(k_n - 1):
        px = line[k, 0]
        py = line[k, 1]
        pq0 = line[k + 1, 0] - px
        pq1 = line[k + 1, 1] - py
        for j in range(m - 1):
            ab0 = path_xy[j + 1, 0] - path_xy[j, 0]
            ab1 = path_xy[j + 1, 1] - path_xy[j, 1]
            denom = ab0 * pq1 - ab1 * pq0
            if not abs(denom) > 1e-12:
                continue
            ap0 = px - path_xy[j, 0]
            ap1 = py - path_xy[j, 1]
            t = (ap0 * pq1 - ap1 * pq0) / denom
            u = (ap0 * ab1 - ap1 * ab0) / denom
            if not (t >= 0.0 and t <= 1.0 and u >= 0.0 and u <= 1.0):
                continue
            s = path_s[j] + t * (path_s[j + 1] - path_s[j])
            if not found or s < best_s:
                h = math.hypot(ab0, ab1)
                if 1e-12 > h:  # max(h, 1e-12): the first argument unless the other is greater
                    h = 1e-12
                found = True
                best_s = s
                best_x = ab0 / h
                best_y = ab1 / h
            break  # the first hit of this line segment
    return found, best_s, best_x, best_y


@numba.njit(cache=True, nogil=True)
def curve_speed(  # noqa: PLR0917 - numba takes no keyword-only parameters
    xy: _F64,
    s: _F64,
    length_m: float,
    sample_m: float,
    window: int,
    max_lateral_accel_mps2: float,
    decel_mps2: float,
    front_offset_m: float,
) -> float:  # pragma: no cover - compiled
    """IdmPlanner._curve_speed_mps after its length test: the path (``xy``, arc lengths ``s``)
    sampled every ``sample_m`` over [0, ``length_m``) (``np.arange``'s samples), the headings of
    the samples' steps unwrapped (``np.unwrap`` of ``arctan2``), the curvature over ``window``
    steps, and ``min_j sqrt(a_lat / max(|κ_j|, 1e-9) + 2 b · max(s_j − front, 0))`` (inf when
    the headings are not more than ``window``) — numpy's operations in its order (a NaN wins the
    minimum, as ``np.min``), the headings libm's ``atan2`` (numpy's ``arctan2`` but on AVX-512
    hosts, where numpy's SIMD loop may differ from it in the last bit)."""
    count = math.ceil((length_m - 0.0) / sample_m)
    samples = np.empty(count)
    for i in range(count):
        samples[i] = 0.0 + i * sample_m
    pts = points_at(xy, s, samples)
    n = count - 1
    if n <= window:
        return math.inf
    raw = np.empty(n)
    for i in range(n):
        raw[i] = math.atan2(pts[i + 1, 1] - pts[i, 1], pts[i + 1, 0] - pts[i, 0])
    heading = np.empty(n)
    unwrap(raw, n, heading)
    span = window * sample_m
    twice_b = 2.0 * decel_mps2
    out = math.nan
    for j in range(n - window):
        kappa = abs(heading[j + window] - heading[j]) / span
        if not (kappa >= 1e-9 or math.isnan(kappa)):  # np.maximum(kappa, 1e-9)
            kappa = 1e-9
        curve = math.sqrt(max_lateral_accel_mps2 / kappa)
        ahead = samples[j + window] - front_offset_m
        if not (ahead >= 0.0 or math.isnan(ahead)):  # np.maximum(ahead, 0.0)
            ahead = 0.0
        v = math.sqrt(curve * curve + twice_b * ahead)
        if j == 0 or math.isnan(v) or (not math.isnan(out) and v < out):
            out = v
    return out
