"""Compiled loops of :meth:`LidarModel.scan <redrive.sim.lidar.LidarModel.scan>` (numba,
``nogil``): the columns' positions between the slice poses and how near a box may come to each
(:func:`columns`, :func:`reach`); the rays in the map frame, where they meet the ground and which
of them Embree must cast (:func:`rays`); which returns are kept (:func:`kept`); the kept
returns' points, intensity, ring, time offset and object (:func:`returns`).

The arithmetic is the one the numpy code did, in the same precision and order (float32 where it
was float32; the ground point's map x, y in float64 as numpy promoted them), so a sweep is the
same bytes.  The random draws (dropout, range noise) stay with numpy's generator, before.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import numpy.typing as npt

__all__ = ["columns", "kept", "rays", "reach", "returns"]


@numba.njit(cache=True, nogil=True)
def columns(  # pragma: no cover - compiled
    slice_pos: npt.NDArray[np.float64],
    slice_of_col: npt.NDArray[np.int64],
    frac_of_col: npt.NDArray[np.float64],
    pos: npt.NDArray[np.float64],
) -> None:
    """Each column's sensor position (C, 3): its slice's start and end positions
    ``slice_pos`` (S + 1, 3) mixed as ``start·(1 − f) + end·f`` (numpy's float64 order)."""
    for c in range(pos.shape[0]):
        s = slice_of_col[c]
        f = frac_of_col[c]
        g = 1.0 - f
        for a in range(3):
            pos[c, a] = slice_pos[s, a] * g + slice_pos[s + 1, a] * f


@numba.njit(cache=True, nogil=True)
def reach(  # noqa: PLR0917  # pragma: no cover - compiled
    starts: npt.NDArray[np.int64],
    pos: npt.NDArray[np.float64],
    rot: npt.NDArray[np.float64],
    centers: npt.NDArray[np.float64],
    sizes: npt.NDArray[np.float64],
    slice_mid_az: npt.NDArray[np.float64],
    slice_half_az: npt.NDArray[np.float64],
    slice_of_col: npt.NDArray[np.int64],
    r_col: npt.NDArray[np.float64],
    top_col: npt.NDArray[np.float64],
) -> float:
    """The LiDAR's cull figures (:meth:`LidarModel._box_reach
    <redrive.sim.lidar.LidarModel._box_reach>`), per slice × box in one loop: writes each
    column's nearest horizontal distance of a box overlapping its slice (+inf: none) to
    ``r_col`` and the highest top among them (−inf) to ``top_col``; returns the margin (0.05 m +
    the sensor's longest travel within a slice).  ``starts`` are the slices' first columns."""
    num_slices = starts.shape[0]
    last = pos.shape[0] - 1
    margin = 0.0
    for s in range(num_slices):
        a = starts[s]
        b = starts[s + 1] if s + 1 < num_slices else last
        d0 = pos[b, 0] - pos[a, 0]
        d1 = pos[b, 1] - pos[a, 1]
        d2 = pos[b, 2] - pos[a, 2]
        margin = max(margin, math.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
    margin += 0.05
    r_slice = np.full(num_slices, np.inf)
    top_slice = np.full(num_slices, -np.inf)
    for s in range(num_slices):
        a = starts[s]
        az_s = math.atan2(rot[s, 1, 0], rot[s, 0, 0]) + slice_mid_az[s]
        for k in range(centers.shape[0]):
            rx = centers[k, 0] - pos[a, 0]
            ry = centers[k, 1] - pos[a, 1]
            half_diag = 0.5 * math.hypot(sizes[k, 0], sizes[k, 1]) + margin
            dist_c = math.hypot(rx, ry)
            half_width = math.pi  # the sensor stands in the box's circle: every azimuth
            if dist_c > half_diag:
                half_width = math.asin(min(half_diag / dist_c, 1.0))
            diff = abs((az_s - math.atan2(ry, rx) + math.pi) % (2.0 * math.pi) - math.pi)
            if diff <= half_width + slice_half_az[s] + 1e-3:
                r_slice[s] = min(r_slice[s], max(dist_c - half_diag, 0.0))
                top_slice[s] = max(top_slice[s], centers[k, 2] + 0.5 * sizes[k, 2])
    for c in range(slice_of_col.shape[0]):
        r_col[c] = r_slice[slice_of_col[c]]
        top_col[c] = top_slice[slice_of_col[c]]
    return margin


@numba.njit(cache=True, nogil=True)
def rays(  # noqa: PLR0917  # pragma: no cover - compiled
    slice_of_col: npt.NDArray[np.int64],
    rot: npt.NDArray[np.float64],
    local_x: npt.NDArray[np.float32],
    local_y: npt.NDArray[np.float32],
    local_z: npt.NDArray[np.float32],
    pos: npt.NDArray[np.float64],
    origin: npt.NDArray[np.float64],
    upright: bool,
    max_limit: np.float32,
    cull: bool,
    cos_elev: npt.NDArray[np.float32],
    tan_elev: npt.NDArray[np.float64],
    r_col: npt.NDArray[np.float64],
    top_col: npt.NDArray[np.float64],
    margin: float,
    dx: npt.NDArray[np.float32],
    dy: npt.NDArray[np.float32],
    dz: npt.NDArray[np.float32],
    t_ground: npt.NDArray[np.float32],
    limit: npt.NDArray[np.float32],
    sel: npt.NDArray[np.int64],
    sel_orig: npt.NDArray[np.float32],
    sel_dirs: npt.NDArray[np.float32],
    sel_limit: npt.NDArray[np.float32],
) -> int:
    """Every ray of a sweep (C columns × L lasers, flat index ``c·L + l``) in the map frame.

    Direction = the column's slice rotation (``rot[slice_of_col[c]]`` cast to float32) times the
    sensor-frame unit vector, summed in the order numpy did (``(r0·x + r1·y) + r2·z``; z taken
    as it is for an ``upright`` sensor); ``t_ground`` the distance to z = 0 (+inf for rays that
    do not go down from above it), ``limit`` its minimum with ``max_limit``.  With ``cull``, a
    ray goes to Embree only if a box may lie on it before ``limit`` (horizontal reach at least
    ``r_col[c]``; an upward ray also not yet above ``top_col[c] + margin`` there), else every
    ray does.  The rays cast are written to ``sel`` and gathered into ``sel_orig`` (the column's
    position relative to ``origin``, float32), ``sel_dirs`` and ``sel_limit``; returns how many.
    """
    num_cols, num_lasers = local_x.shape
    inf32 = np.float32(np.inf)
    zero32 = np.float32(0.0)
    n = 0
    for c in range(num_cols):
        s = slice_of_col[c]
        r00, r01, r02 = np.float32(rot[s, 0, 0]), np.float32(rot[s, 0, 1]), np.float32(rot[s, 0, 2])
        r10, r11, r12 = np.float32(rot[s, 1, 0]), np.float32(rot[s, 1, 1]), np.float32(rot[s, 1, 2])
        r20, r21, r22 = np.float32(rot[s, 2, 0]), np.float32(rot[s, 2, 1]), np.float32(rot[s, 2, 2])
        oz = np.float32(pos[c, 2])
        ox = np.float32(pos[c, 0] - origin[0])
        oy = np.float32(pos[c, 1] - origin[1])
        oz_local = np.float32(pos[c, 2] - origin[2])
        rc = r_col[c]
        top = top_col[c] + margin
        r_fin = rc if math.isfinite(rc) else 0.0
        for ll in range(num_lasers):
            i = c * num_lasers + ll
            lx, ly, lz = local_x[c, ll], local_y[c, ll], local_z[c, ll]
            x = r00 * lx + r01 * ly + r02 * lz
            y = r10 * lx + r11 * ly + r12 * lz
            z = lz if upright else r20 * lx + r21 * ly + r22 * lz
            dx[i], dy[i], dz[i] = x, y, z
            tg = (-oz) / z if (z < zero32 and oz > zero32) else inf32
            t_ground[i] = tg
            lim = tg if tg < max_limit else max_limit
            limit[i] = lim
            if cull:
                if not np.float64(lim * cos_elev[ll]) >= rc:
                    continue
                if tan_elev[ll] > 0.0 and not tan_elev[ll] * r_fin + pos[c, 2] <= top:
                    continue
            sel[n] = i
            sel_orig[n, 0], sel_orig[n, 1], sel_orig[n, 2] = ox, oy, oz_local
            sel_dirs[n, 0], sel_dirs[n, 1], sel_dirs[n, 2] = x, y, z
            sel_limit[n] = lim
            n += 1
    return n


@numba.njit(cache=True, nogil=True)
def kept(  # noqa: PLR0917  # pragma: no cover - compiled
    sel: npt.NDArray[np.int64],
    sel_dist: npt.NDArray[np.float32],
    sel_prim: npt.NDArray[np.int32],
    triangles_per_box: int,
    box_of_mesh: npt.NDArray[np.int64],
    t_ground: npt.NDArray[np.float32],
    min_range: np.float32,
    max_range: np.float32,
    dist: npt.NDArray[np.float32],
    box: npt.NDArray[np.int64],
    where_in_sel: npt.NDArray[np.int64],
    keep: npt.NDArray[np.bool_],
) -> None:
    """Embree's answers put back per ray, and which rays return.

    ``dist`` comes in holding each ray's limit; a ray Embree hit (``sel_prim ≥ 0``) gets its
    distance and box (``box_of_mesh[prim // triangles_per_box]``: the scene's index of the
    meshed box; −1 elsewhere), ``where_in_sel`` its place
    in ``sel``.  A ray returns if it hit a box or meets the ground within ``max_range``, and its
    distance lies in [``min_range``, ``max_range``] (float32 comparisons, as numpy made them).
    """
    box[:] = -1
    for k in range(sel.shape[0]):
        i = sel[k]
        where_in_sel[i] = k
        p = sel_prim[k]
        if p >= 0:
            dist[i] = sel_dist[k]
            box[i] = box_of_mesh[p // triangles_per_box]
    for i in range(dist.shape[0]):
        d = dist[i]
        keep[i] = (box[i] >= 0 or t_ground[i] <= max_range) and d >= min_range and d <= max_range


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
