"""The compiled part of :func:`redrive.sim.ground_truth.boxes_in_base` (numba, no ``fastmath``).

:func:`rows_in_base` picks the rows within range of the ego and gives their columns in
base_link, in one call instead of the ≈ 15 numpy calls of a few rows each it replaces.  The
rotations stay numpy's (its BLAS product is not the elementwise one: a fused multiply-add on
some hosts, not on others); what is compiled is exactly representable or the same float64
operation: the range test on ``np.hypot`` (libm's ``hypot``, what numba calls too), the rows
copied, and ``math.remainder`` (numba has neither it nor ``math.fmod``) as CPython computes it
(:func:`remainder`).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["remainder", "rows_in_base", "rows_in_base_packed"]

_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]


@numba.njit(cache=True, nogil=True)
def remainder(x: float, y: float) -> float:  # pragma: no cover - compiled
    """``math.remainder(x, y)`` for finite ``x`` and finite, non-zero ``y``: CPython's
    ``m_remainder``, operation for operation (its ``fmod`` of non-negative operands is ``%``,
    exact; so is every step after it)."""
    absx, absy = abs(x), abs(y)
    m = absx % absy
    c = absy - m
    if m < c:
        r = m
    elif m > c:
        r = -c
    else:  # half way: round to even
        r = m - 2.0 * ((0.5 * (absx - m)) % absy)
    return math.copysign(1.0, x) * r


@numba.njit(cache=True, nogil=True)
def rows_in_base(  # noqa: PLR0917 - numba takes no keyword-only parameters
    centers: _F64,
    velocities: _F64,
    object_ids: _I64,
    sizes: _F64,
    yaws: _F64,
    keep: npt.NDArray[np.bool_],
    yaw_ego: float,
    range_m: float,
) -> tuple[_I64, _I64, _F64, _F64, _F64, _F64, _F64]:  # pragma: no cover - compiled
    """The rows (``keep``'s, every row when ``keep`` is empty) whose centre (``centers``, (N, 3)
    already in base_link) is not farther than ``range_m`` in x-y from the origin (a NaN
    distance is kept), in order: their indices, ids, centres, sizes, yaws relative to
    ``yaw_ego`` (``math.remainder(yaw - yaw_ego, τ)``), velocities (``velocities``, in
    base_link) and orientations (yaw, 0, 0)."""
    n = centers.shape[0]
    every = keep.shape[0] == 0
    idx = np.empty(n, dtype=np.int64)
    m = 0
    for i in range(n):
        if (every or keep[i]) and not np.hypot(centers[i, 0], centers[i, 1]) > range_m:
            idx[m] = i
            m += 1
    idx = idx[:m].copy()
    ids = np.empty(m, dtype=np.int64)
    c_out = np.empty((m, 3))
    s_out = np.empty((m, 3))
    yaw_out = np.empty(m)
    v_out = np.empty((m, 3))
    o_out = np.zeros((m, 3))
    for k in range(m):
        i = idx[k]
        ids[k] = object_ids[i]
        for j in range(3):
            c_out[k, j] = centers[i, j]
            s_out[k, j] = sizes[i, j]
            v_out[k, j] = velocities[i, j]
        yaw = remainder(yaws[i] - yaw_ego, 2.0 * math.pi)
        yaw_out[k] = yaw
        o_out[k, 0] = yaw
    return idx, ids, c_out, s_out, yaw_out, v_out, o_out


@numba.njit(cache=True, nogil=True)
def rows_in_base_packed(  # noqa: PLR0917 - numba takes no keyword-only parameters
    centers: _F64,
    velocities: _F64,
    object_ids: _I64,
    sizes: _F64,
    yaws: _F64,
    keep: npt.NDArray[np.bool_],
    yaw_ego: float,
    range_m: float,
) -> tuple[int, _I64, _F64]:  # pragma: no cover - compiled
    """:func:`rows_in_base`'s seven arrays in two (numba boxes every array it returns at a cost
    of its own, a pickled type read back each time): the m rows, the ints (m indices, then m
    ids) and the floats one after another (centres 3m, sizes 3m, yaws m, velocities 3m,
    orientations 3m) — the same values."""
    idx, ids, c, s, y, v, o = rows_in_base(
        centers, velocities, object_ids, sizes, yaws, keep, yaw_ego, range_m
    )
    m = idx.shape[0]
    ints = np.empty(2 * m, dtype=np.int64)
    ints[:m] = idx
    ints[m:] = ids
    floats = np.empty(13 * m)
    at = 0
    for part in (c.ravel(), s.ravel(), y, v.ravel(), o.ravel()):
        floats[at : at + part.shape[0]] = part
        at += part.shape[0]
    return m, ints, floats
