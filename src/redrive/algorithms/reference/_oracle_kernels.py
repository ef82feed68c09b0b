"""The noisy oracle's perturbation of the kept ground-truth rows as one numba kernel (compiled
once, cached next to the module): the float64 operations of the numpy code it replaced
(``NoisyOracle._perturb`` before issue 15's h-objcols6), in the same order, so the detections
are bit for bit the same (no ``fastmath``; :func:`redrive.geometry.se3.normalize_angle`
written out with ``np.fmod``: numba has no ``math.fmod``, and fmod is exact, so every
implementation gives the same bits).  The sizes' ``np.maximum`` stays numpy's: which of two
equal zeros of opposite signs it returns depends on its SIMD loop."""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["perturb_rows"]

_F64 = npt.NDArray[np.float64]
_I64 = npt.NDArray[np.int64]
_BOOL = npt.NDArray[np.bool_]


@numba.njit(cache=True, nogil=True)
def _normalize_angle(angle_rad: float) -> float:  # pragma: no cover - compiled
    wrapped: float = np.fmod(angle_rad + math.pi, 2.0 * math.pi)  # exact: any fmod, these bits
    if wrapped < 0.0:
        wrapped += 2.0 * math.pi
    return wrapped - math.pi


@numba.njit(cache=True, nogil=True)
def perturb_rows(  # noqa: PLR0917 - numba takes no keyword-only parameters
    centers: _F64,
    yaws: _F64,
    velocities: _F64,
    orientations: _F64,
    rows: _I64,
    missed: _BOOL,
    n_center: _F64,
    noisy_sizes: _F64,
    n_yaw: _F64,
    n_vel: _F64,
    stds: _F64,
) -> tuple[_I64, _F64, _F64, _F64, _F64, _F64]:  # pragma: no cover - compiled
    """Ground-truth rows ``rows`` (n,) of the columns, each not ``missed``, with noise: the
    standard normals ``n_center`` (n, 3), ``n_yaw`` (n,), ``n_vel`` (n, 2) times ``stds`` =
    (centre, size, yaw, velocity) std (the size's is unused: ``noisy_sizes`` (n, 3) are the
    rows' sizes already perturbed).  Returns the indices into ``rows`` of the kept ones (k,),
    their centres (k, 3) ``c + δ``, sizes (k, 3), yaws ``normalize_angle(yaw + δ)`` (k,),
    velocities (vx, vy + δ; vz kept) and orientations (yaw + δ normalised; pitch, roll kept)."""
    n = rows.shape[0]
    k = 0
    for i in range(n):
        if not missed[i]:
            k += 1
    kept = np.empty(k, dtype=np.int64)
    out_c = np.empty((k, 3))
    out_s = np.empty((k, 3))
    out_y = np.empty(k)
    out_v = np.empty((k, 3))
    out_o = np.empty((k, 3))
    s_center, s_yaw, s_vel = stds[0], stds[2], stds[3]
    j = 0
    for i in range(n):
        if missed[i]:
            continue
        r = rows[i]
        kept[j] = i
        for a in range(3):
            out_c[j, a] = centers[r, a] + n_center[i, a] * s_center
            out_s[j, a] = noisy_sizes[i, a]
            out_v[j, a] = velocities[r, a]
            out_o[j, a] = orientations[r, a]
        out_v[j, 0] += n_vel[i, 0] * s_vel
        out_v[j, 1] += n_vel[i, 1] * s_vel
        d_yaw = n_yaw[i] * s_yaw
        out_y[j] = _normalize_angle(yaws[r] + d_yaw)
        out_o[j, 0] = _normalize_angle(orientations[r, 0] + d_yaw)
        j += 1
    return kept, out_c, out_s, out_y, out_v, out_o
