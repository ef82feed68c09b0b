"""Compiled per-point loop of :meth:`LidarModel.scan <redrive.sim.lidar.LidarModel.scan>`
(numba, ``nogil``): the kept returns' points, intensity, ring, time offset and object.

The arithmetic is the one the numpy code did, in the same precision and order (float32 where it
was float32; the ground point's map x, y in float64 as numpy promoted them), so a sweep is the
same bytes.  The random draws (dropout, range noise) stay with numpy's generator, before.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["returns"]


@numba.njit(cache=True, nogil=True)
def returns(  # noqa: PLR0917  # pragma: no cover - compiled
    idx: npt.NDArray[np.int64],
    r: npt.NDArray[np.float32],
    num_lasers: int,
    unit_x: npt.NDArray[np.float32],
    unit_y: npt.NDArray[np.float32],
    unit_z: npt.NDArray[np.float32],
    box: npt.NDArray[np.int64],
    dist: npt.NDArray[np.float32],
    dx: npt.NDArray[np.float32],
    dy: npt.NDArray[np.float32],
    dz: npt.NDArray[np.float32],
    where_in_sel: npt.NDArray[np.int64],
    normals: npt.NDArray[np.float32],
    reflectivity: npt.NDArray[np.float32],
    object_ids: npt.NDArray[np.int64],
    pos: npt.NDArray[np.float64],
    labels: npt.NDArray[np.uint8],
    ground_origin: npt.NDArray[np.float64],
    ground_inv_res: float,
    grass: int,
    ground_lut: npt.NDArray[np.float32],
    ring_of: npt.NDArray[np.uint16],
    t_off_of: npt.NDArray[np.uint32],
    xyz: npt.NDArray[np.float32],
    intensity: npt.NDArray[np.float32],
    ring: npt.NDArray[np.uint16],
    t_off: npt.NDArray[np.uint32],
    point_ids: npt.NDArray[np.int64],
    counts: npt.NDArray[np.int64],
) -> None:
    """Fill the outputs (one row per kept ray ``idx[k]``, range ``r[k]`` with its noise).

    A box return's intensity is reflectivity × |cos(incidence)| from the Embree normal
    (``normals[where_in_sel[ray]]``); a ground return's is the ground label's reflectivity ×
    |ray z|, the label looked up where the ray met z = 0 (from the column's origin ``pos``).
    ``counts`` gets the returns per object (index into the scene's objects).
    """
    h_lab, w_lab = labels.shape
    tiny = np.float32(1e-12)
    full = np.float32(255.0)
    for k in range(idx.shape[0]):
        ray = idx[k]
        rk = r[k]
        xyz[k, 0] = unit_x[ray] * rk
        xyz[k, 1] = unit_y[ray] * rk
        xyz[k, 2] = unit_z[ray] * rk
        ring[k] = ring_of[ray]
        t_off[k] = t_off_of[ray]
        b = box[ray]
        if b >= 0:
            refl = reflectivity[b]
            j = where_in_sel[ray]
            nx, ny, nz = normals[j, 0], normals[j, 1], normals[j, 2]
            dot = nx * dx[ray] + ny * dy[ray] + nz * dz[ray]
            norm = np.float32(math.sqrt(nx * nx + ny * ny + nz * nz))
            cos_i = abs(dot) / (norm if (norm >= tiny or math.isnan(norm)) else tiny)
            point_ids[k] = object_ids[b]
            counts[b] += 1
        else:
            col = ray // num_lasers
            d = dist[ray]
            gx = pos[col, 0] + np.float64(dx[ray] * d)
            gy = pos[col, 1] + np.float64(dy[ray] * d)
            c = math.floor((gx - ground_origin[0]) * ground_inv_res)
            rw = math.floor((gy - ground_origin[1]) * ground_inv_res)
            lab = grass
            if c >= 0 and c < w_lab and rw >= 0 and rw < h_lab:
                lab = labels[rw, c]
            refl = ground_lut[lab]
            cos_i = abs(dz[ray])
            point_ids[k] = -1
        value = full * refl * cos_i
        intensity[k] = value if (value <= full or math.isnan(value)) else full
