"""The compiled collision check of :func:`redrive.closedloop.contact.contacts`.

:func:`touching` is the pre-filter and the separating axis test of
:func:`redrive.evaluation._kinematics.rectangles_overlap` on the boxes of
:func:`~redrive.evaluation._kinematics.rectangle_corners`, in one call and without the arrays
numpy builds for them (a frame with objects near the ego: ≈ 30 numpy calls of a few objects
each).  The corners and the projections are the float64 operations of those functions, in
their order; a NaN coordinate separates nothing (numpy's max and min propagate it, and every
comparison with it is false).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["touching"]

_F64 = npt.NDArray[np.float64]
#: the corners' order of rectangle_corners: front-left, rear-left, rear-right, front-right
_SIGNS = ((1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0))


@numba.njit(cache=True, nogil=True)
def _corners(  # noqa: PLR0917 - numba takes no keyword-only parameters
    out: _F64, cx: float, cy: float, yaw: float, length: float, width: float
) -> None:  # pragma: no cover - compiled
    """``out`` (4, 2): rectangle_corners' corners of one rectangle."""
    half_l = length / 2
    half_w = width / 2
    c = math.cos(yaw)
    s = math.sin(yaw)
    for k in range(4):
        lx = _SIGNS[k][0] * half_l
        ly = _SIGNS[k][1] * half_w
        out[k, 0] = (c * lx - s * ly) + cx
        out[k, 1] = (s * lx + c * ly) + cy


@numba.njit(cache=True, nogil=True)
def _extent(corners: _F64, ax: float, ay: float) -> tuple[float, float]:  # pragma: no cover
    """numpy's max and min of the corners' projections on (ax, ay) (a NaN wins)."""
    hi = lo = corners[0, 0] * ax + corners[0, 1] * ay
    for k in range(1, 4):
        v = corners[k, 0] * ax + corners[k, 1] * ay
        if math.isnan(hi) or math.isnan(v):
            hi = lo = math.nan
        else:
            hi = max(hi, v)
            lo = min(lo, v)
    return hi, lo


@numba.njit(cache=True, nogil=True)
def _overlap(ca: _F64, cb: _F64) -> bool:  # pragma: no cover - compiled
    """rectangles_overlap of two rectangles' corners (4, 2)."""
    for which in range(2):
        corners = ca if which == 0 else cb
        for e0 in range(2):
            ex = corners[e0 + 1, 0] - corners[e0, 0]
            ey = corners[e0 + 1, 1] - corners[e0, 1]
            ax, ay = -ey, ex
            a_hi, a_lo = _extent(ca, ax, ay)
            b_hi, b_lo = _extent(cb, ax, ay)
            scale = math.hypot(ax, ay) * 1e-12
            if a_hi < b_lo - scale or b_hi < a_lo - scale:
                return False
    return True


@numba.njit(cache=True, nogil=True)
def touching(  # noqa: PLR0917 - numba takes no keyword-only parameters
    centers: _F64,
    sizes: _F64,
    yaws: _F64,
    ego_offset_m: float,
    ego_length_m: float,
    ego_width_m: float,
) -> npt.NDArray[np.int64]:  # pragma: no cover - compiled
    """The rows (ascending) of the boxes (centres (n, ≥ 2), sizes (n, ≥ 2), yaws (n,); the
    ego's base_link) that the ego rectangle ``ego_length_m × ego_width_m`` centred
    ``ego_offset_m`` ahead of the origin touches.  Boxes whose centre is farther from the
    ego's than the two half-diagonals (with a 1e-9 relative margin) cannot touch and skip the
    separating axis test (exact, not an approximation)."""
    n = centers.shape[0]
    ego = np.empty((4, 2))
    _corners(ego, ego_offset_m, 0.0, 0.0, ego_length_m, ego_width_m)
    box = np.empty((4, 2))
    ego_reach = math.hypot(ego_length_m, ego_width_m)
    out = np.empty(n, dtype=np.int64)
    count = 0
    for i in range(n):
        reach = 0.5 * (ego_reach + math.hypot(sizes[i, 0], sizes[i, 1]))
        if not math.hypot(centers[i, 0] - ego_offset_m, centers[i, 1]) <= reach * (1.0 + 1e-9):
            continue
        _corners(box, centers[i, 0], centers[i, 1], yaws[i], sizes[i, 0], sizes[i, 1])
        if _overlap(ego, box):
            out[count] = i
            count += 1
    return out[:count].copy()
