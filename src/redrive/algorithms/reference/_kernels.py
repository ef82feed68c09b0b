"""The reference algorithms' hot loops as numba kernels (compiled once, cached on disk).

Each kernel is one pass over the points doing what a chain of numpy calls did before, with the
same float32 operations in the same order, so the outputs are bit for bit the ones of the numpy
version (numba compiles without ``fastmath``: no reassociation, no fused multiply-add).  They
release the GIL (``nogil``), so a detector step can overlap another thread's work.

* :func:`crop_cell_minima` — move the sweep to base_link, crop it, key it on the ground grid and
  take the lowest z per ground cell.
* :func:`split_obstacles` — classify each point against the ground height of its cell
  (obstacle band, tall band) and gather the obstacle points and the tall points' x, y.
* :func:`label_clusters` — 8-connected components of the occupied cells of the BEV clustering
  grid, numbered in raster order of their first cell as :func:`scipy.ndimage.label` numbers
  them, filtered by size and tall points, with the points grouped by cluster in index order.
* :func:`ground_sample`, :func:`ground_fill`, :func:`plane_hypotheses`, :func:`ransac_best`,
  :func:`plane_inliers` — the ground step (:mod:`._ground`).
* :func:`subsample_clusters` — the even subsample of each cluster the box search fits.
* :func:`closeness_terms` — the box search's per-point criterion terms, and :func:`grow_boxes`,
  the growing of partly seen boxes to their class's size (:mod:`._box_fit`).
* :func:`project_on_segments` — the planner's projection of points onto its path.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba
import numpy as np
import numpy.typing as npt

__all__ = [
    "closeness_terms",
    "crop_cell_minima",
    "ground_fill",
    "ground_sample",
    "grow_boxes",
    "label_clusters",
    "plane_hypotheses",
    "plane_inliers",
    "project_on_segments",
    "ransac_best",
    "split_obstacles",
    "subsample_clusters",
]

_F = TypeVar("_F", bound=Callable[..., Any])
_F32 = npt.NDArray[np.float32]
_I64 = npt.NDArray[np.int64]
_F64 = npt.NDArray[np.float64]
_IP = npt.NDArray[np.intp]


def _jit(fn: _F) -> _F:
    return cast(_F, numba.njit(cache=True, nogil=True)(fn))


@_jit
def crop_cell_minima(  # noqa: PLR0917 - numba takes no keyword-only parameters
    xyz: _F32,
    sx: np.float32,
    sy: np.float32,
    sz: np.float32,
    crop: np.float32,
    min_range_sq: np.float32,
    half: np.float32,
    inv_cell: np.float32,
    n: int,
) -> tuple[_F32, _F32, _F32, _I64, _F32]:
    """Points (N, 3) float32 of the sensor moved by (sx, sy, sz) to base_link, kept when
    |x|, |y| < ``crop``, farther than √``min_range_sq`` from the sensor in x-y and z finite.

    Returns x, y, z of the kept points (in order), their flat ground-cell keys
    ``int((x + half) · inv_cell) · n + int((y + half) · inv_cell)``, and the lowest z per cell
    (n·n,) (+inf where empty).
    """
    m = xyz.shape[0]
    ox = np.empty(m, dtype=np.float32)
    oy = np.empty(m, dtype=np.float32)
    oz = np.empty(m, dtype=np.float32)
    keys = np.empty(m, dtype=np.int64)
    minima = np.full(n * n, np.inf, dtype=np.float32)
    k = 0
    for p in range(m):
        x = xyz[p, 0] + sx
        y = xyz[p, 1] + sy
        z = xyz[p, 2] + sz
        dx = x - sx
        dy = y - sy
        if not (abs(x) < crop and abs(y) < crop and dx * dx + dy * dy > min_range_sq):
            continue
        if not np.isfinite(z):
            continue
        key = np.int64((x + half) * inv_cell) * n + np.int64((y + half) * inv_cell)
        ox[k] = x
        oy[k] = y
        oz[k] = z
        keys[k] = key
        minima[key] = min(minima[key], z)
        k += 1
    return ox[:k], oy[:k], oz[:k], keys[:k], minima


@_jit
def split_obstacles(  # noqa: PLR0917
    x: _F32,
    y: _F32,
    z: _F32,
    keys: _I64,
    ground: _F32,
    low: np.float32,
    high: np.float32,
    tall_high: np.float32,
) -> tuple[_F32, _F32, _F32, _F32, _F32, _F32]:
    """Obstacle points (``low`` < z - ground < ``high``): their x, y, z and ground z; and the
    x, y of the tall points (``high`` ≤ z - ground < ``tall_high``).  ``ground`` is the flat
    ground height per cell, indexed by ``keys``."""
    m = x.shape[0]
    ox = np.empty(m, dtype=np.float32)
    oy = np.empty(m, dtype=np.float32)
    oz = np.empty(m, dtype=np.float32)
    og = np.empty(m, dtype=np.float32)
    tx = np.empty(m, dtype=np.float32)
    ty = np.empty(m, dtype=np.float32)
    k = 0
    t = 0
    for p in range(m):
        g = ground[keys[p]]
        above = z[p] - g
        if above > low and above < high:
            ox[k] = x[p]
            oy[k] = y[p]
            oz[k] = z[p]
            og[k] = g
            k += 1
        elif above >= high and above < tall_high:
            tx[t] = x[p]
            ty[t] = y[p]
            t += 1
    return ox[:k], oy[:k], oz[:k], og[:k], tx[:t], ty[:t]


@_jit
def _find(parent: _I64, i: int) -> int:
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:  # path compression
        nxt = parent[i]
        parent[i] = root
        i = nxt
    return root


@_jit
def label_clusters(  # noqa: PLR0917
    x: _F32,
    y: _F32,
    tall_x: _F32,
    tall_y: _F32,
    half: np.float32,
    inv_cell: np.float32,
    n: int,
    min_points: int,
    max_points: int,
    scratch: _I64,
) -> tuple[_I64, _I64, _I64]:
    """Clusters of points (metres, strictly inside the n × n grid of cells ``1 / inv_cell``
    centred on the origin): 8-connected components of the occupied cells, in raster order of
    each component's first cell; kept when they hold ``min_points`` … ``max_points`` points and
    no tall point falls in their cells.

    ``scratch`` is an (n·n,) int64 array of -1; it is left as it was found.  Returns the point
    indices grouped by kept cluster (in index order within a cluster), the clusters' starts in
    that array and their point counts.
    """
    m = x.shape[0]
    point_cell = np.empty(m, dtype=np.int64)
    cell_key = np.empty(m, dtype=np.int64)
    n_cells = 0
    for p in range(m):
        key = np.int64((x[p] + half) * inv_cell) * n + np.int64((y[p] + half) * inv_cell)
        c = scratch[key]
        if c < 0:
            c = n_cells
            scratch[key] = c
            cell_key[c] = key
            n_cells += 1
        point_cell[p] = c
    parent = np.arange(n_cells)
    for c in range(n_cells):
        key = cell_key[c]
        i = key // n
        j = key - i * n
        for di, dj in ((-1, -1), (-1, 0), (-1, 1), (0, -1)):
            ii = i + di
            jj = j + dj
            if ii < 0 or jj < 0 or jj >= n:
                continue
            other = scratch[ii * n + jj]
            if other >= 0:
                ra = _find(parent, c)
                rb = _find(parent, other)
                if ra != rb:
                    # the root keeps the component's smallest key: its first cell in raster order
                    if cell_key[ra] < cell_key[rb]:
                        parent[rb] = ra
                    else:
                        parent[ra] = rb
    # components → counts and tall marks (indexed by root cell)
    counts = np.zeros(n_cells, dtype=np.int64)
    for p in range(m):
        counts[_find(parent, point_cell[p])] += 1
    tall = np.zeros(n_cells, dtype=np.bool_)
    for p in range(tall_x.shape[0]):
        key = np.int64((tall_x[p] + half) * inv_cell) * n + np.int64((tall_y[p] + half) * inv_cell)
        c = scratch[key]
        if c >= 0:
            tall[_find(parent, c)] = True
    for c in range(n_cells):
        scratch[cell_key[c]] = -1
    # kept roots in raster order of their first cell
    roots = np.empty(n_cells, dtype=np.int64)
    r = 0
    for c in range(n_cells):
        if parent[c] == c and not tall[c] and min_points <= counts[c] <= max_points:
            roots[r] = c
            r += 1
    roots = roots[:r]
    order = np.argsort(cell_key[roots], kind="mergesort")
    cluster_of_root = np.full(n_cells, -1, dtype=np.int64)
    kept_counts = np.empty(r, dtype=np.int64)
    for k in range(r):
        root = roots[order[k]]
        cluster_of_root[root] = k
        kept_counts[k] = counts[root]
    starts = np.empty(r, dtype=np.int64)
    total = 0
    for k in range(r):
        starts[k] = total
        total += kept_counts[k]
    fill = starts.copy()
    index = np.empty(total, dtype=np.int64)
    for p in range(m):
        k = cluster_of_root[parent[point_cell[p]]]
        if k >= 0:
            index[fill[k]] = p
            fill[k] += 1
    return index, starts, kept_counts


@_jit
def project_on_segments(
    p: _F64,
    a: _F64,
    ab: _F64,
    seg_len: _F64,
    s_start: _F64,
) -> tuple[_F64, _F64, _F64]:
    """Nearest points of ``p`` (P, 2) on the segments ``a + t·ab`` (S ≥ 1; lengths ``seg_len``,
    arc length ``s_start`` at ``a``), metres: arc length of the foot, signed lateral offset (left
    positive) and distance, each (P,).  The numpy broadcasting of :meth:`Polyline.project` as a
    loop: the same float64 operations in the same order (numpy's sum over two elements starts
    from +0.0; ``clip`` keeps -0.0 and NaN; the first minimum wins, a NaN before it).
    """
    n_p = p.shape[0]
    n_s = a.shape[0]
    s_out = np.empty(n_p)
    lateral = np.empty(n_p)
    dist = np.empty(n_p)
    for i in range(n_p):
        px = p[i, 0]
        py = p[i, 1]
        best = 0
        best_d2 = np.inf
        best_t = 0.0
        for k in range(n_s):
            apx = px - a[k, 0]
            apy = py - a[k, 1]
            t = ((0.0 + apx * ab[k, 0]) + apy * ab[k, 1]) / (seg_len[k] * seg_len[k])
            # numpy's clip: -0.0 and NaN pass (min/max would not promise that)
            if t < 0.0:  # noqa: PLR1730
                t = 0.0
            if t > 1.0:  # noqa: PLR1730
                t = 1.0
            ex = px - (a[k, 0] + t * ab[k, 0])
            ey = py - (a[k, 1] + t * ab[k, 1])
            d2 = (0.0 + ex * ex) + ey * ey
            if np.isnan(d2):
                if not np.isnan(best_d2):
                    best, best_d2, best_t = k, d2, t
                break
            if k == 0 or d2 < best_d2:
                best, best_d2, best_t = k, d2, t
        s_out[i] = s_start[best] + best_t * seg_len[best]
        cross = ab[best, 0] * (py - a[best, 1]) - ab[best, 1] * (px - a[best, 0])
        lateral[i] = cross / seg_len[best]
        dist[i] = np.sqrt(best_d2)
    return s_out, lateral, dist


@_jit
def ground_sample(
    low: _F32, cx: _F64, cy: _F64, margin: np.float32
) -> tuple[_F32, _F64, _F64, _F64]:
    """The lowest z of each cell's 3 × 3 neighbourhood (``low`` (n, n) float32, +inf outside and
    where empty), and the x, y, z of the occupied cells whose own minimum is within ``margin`` of
    it (the plane's sample points, in row-major order; x, y the cell centres ``cx``, ``cy``)."""
    n0, n1 = low.shape
    # the 3 × 3 minimum as a minimum over rows of the minimum over columns: the same set of
    # values (no NaN: +inf where empty), so the same value, in 6 comparisons a cell, not 9
    row = np.empty((n0, n1), dtype=np.float32)
    for i in range(n0):
        for j in range(n1):
            m = low[i, j]
            if j > 0:
                m = min(m, low[i, j - 1])
            if j + 1 < n1:
                m = min(m, low[i, j + 1])
            row[i, j] = m
    local = np.empty((n0, n1), dtype=np.float32)
    sx = np.empty(n0 * n1)
    sy = np.empty(n0 * n1)
    sz = np.empty(n0 * n1)
    k = 0
    for i in range(n0):
        for j in range(n1):
            m = row[i, j]
            if i > 0:
                m = min(m, row[i - 1, j])
            if i + 1 < n0:
                m = min(m, row[i + 1, j])
            local[i, j] = m
            v = low[i, j]
            if np.isfinite(v) and v <= m + margin:
                sx[k] = cx[i, j]
                sy[k] = cy[i, j]
                sz[k] = np.float64(v)
                k += 1
    return local, sx[:k], sy[:k], sz[:k]


@_jit
def ground_fill(  # noqa: PLR0917 - numba takes no keyword-only parameters
    local: _F32,
    cx: _F64,
    cy: _F64,
    plane: tuple[float, float, float],
    max_step: np.float32,
    plane_only: bool,
) -> _F32:
    """Ground height per cell (n, n) float32: the plane ``a·x + b·y + c`` at the cell centre,
    or (unless ``plane_only``) the neighbourhood minimum ``local`` where it is finite and at most
    ``max_step`` above the plane."""
    a, b, c = plane
    n0, n1 = local.shape
    out = np.empty((n0, n1), dtype=np.float32)
    for i in range(n0):
        for j in range(n1):
            plane_z = np.float32(a * cx[i, j] + b * cy[i, j] + c)
            v = local[i, j]
            if not plane_only and np.isfinite(v) and v <= plane_z + max_step:
                out[i, j] = v
            else:
                out[i, j] = plane_z
    return out


@_jit
def plane_hypotheses(x: _F64, y: _F64, z: _F64, tri: _I64) -> tuple[_F64, _F64, _F64]:
    """The planes ``z = a·x + b·y + c`` through the point triples ``tri`` (H, 3) whose normal is
    within ~25° of +z, in order: ``a``, ``b``, ``c`` (each ≤ H,).  The numpy steps they replace,
    operation for operation: ``np.cross`` of the two edge vectors (each component a difference
    of two rounded products), ``np.linalg.norm`` of the normal ((n0² + n1²) + n2²), the test
    ``|n2| > 0.9·max(norm, 1e-12)``, ``a = -n0/n2``, ``b = -n1/n2``, ``c = (z0 - a·x0) - b·y0``."""
    h = tri.shape[0]
    a_h = np.empty(h)
    b_h = np.empty(h)
    c_h = np.empty(h)
    k = 0
    for i in range(h):
        i0, i1, i2 = tri[i, 0], tri[i, 1], tri[i, 2]
        x0, y0, z0 = x[i0], y[i0], z[i0]
        ux, uy, uz = x[i1] - x0, y[i1] - y0, z[i1] - z0
        vx, vy, vz = x[i2] - x0, y[i2] - y0, z[i2] - z0
        n0 = uy * vz - uz * vy
        n1 = uz * vx - ux * vz
        n2 = ux * vy - uy * vx
        norm = np.sqrt((n0 * n0 + n1 * n1) + n2 * n2)
        if abs(n2) > 0.9 * (norm if norm > 1e-12 else 1e-12):
            a = -n0 / n2
            b = -n1 / n2
            a_h[k] = a
            b_h[k] = b
            c_h[k] = (z0 - a * x0) - b * y0
            k += 1
    return a_h[:k], b_h[:k], c_h[:k]


@_jit
def ransac_best(  # noqa: PLR0917
    a_h: _F64, b_h: _F64, c_h: _F64, xs: _F64, ys: _F64, zs: _F64, band: float
) -> int:
    """Index of the plane hypothesis ``z = a·x + b·y + c`` with the most sample points within
    ``band`` of it (the first of equals)."""
    best = 0
    best_count = -1
    for h in range(a_h.shape[0]):
        count = 0
        for k in range(xs.shape[0]):
            if abs(zs[k] - (a_h[h] * xs[k] + b_h[h] * ys[k] + c_h[h])) < band:
                count += 1
        if count > best_count:
            best, best_count = h, count
    return best


@_jit
def plane_inliers(  # noqa: PLR0917
    x: _F64, y: _F64, z: _F64, a: float, b: float, c: float, band: float
) -> npt.NDArray[np.bool_]:
    """Which points lie within ``band`` of the plane ``z = a·x + b·y + c``."""
    out = np.empty(x.shape[0], dtype=np.bool_)
    for k in range(x.shape[0]):
        out[k] = abs(z[k] - (a * x[k] + b * y[k] + c)) < band
    return out


@_jit
def subsample_clusters(  # noqa: PLR0917
    x: _F32, y: _F32, index: _IP, starts: _IP, counts: _IP, max_points: int
) -> tuple[_F64, _IP]:
    """An even subsample of at most ``max_points`` points per cluster: every ``stride``-th point
    of cluster ``c`` (``stride = max(1, ceil(counts[c] / max_points))``; its points are
    ``index[p]`` for the positions ``p`` of the cluster, ranked from ``starts[c]``), as float64
    x, y (S, 2) grouped by cluster, and each cluster's first row."""
    k = counts.shape[0]
    total = 0
    for c in range(k):
        stride = max(1, -(-counts[c] // max_points))
        total += -(-counts[c] // stride)
    xy = np.empty((total, 2))
    sub_starts = np.empty(k, dtype=np.intp)
    p = 0
    s = 0
    for c in range(k):
        stride = max(1, -(-counts[c] // max_points))
        sub_starts[c] = s
        for _ in range(counts[c]):
            if (p - starts[c]) % stride == 0:
                i = index[p]
                xy[s, 0] = np.float64(x[i])
                xy[s, 1] = np.float64(y[i])
                s += 1
            p += 1
    return xy, sub_starts


@_jit
def grow_boxes(  # noqa: PLR0917
    center_xy: _F64,
    length_m: _F64,
    width_m: _F64,
    yaw_rad: _F64,
    prior_length_m: _F64,
    prior_width_m: _F64,
    away: _F64,
    cos: _F64,
    sin: _F64,
    distance: _F64,
) -> tuple[_F64, _F64, _F64, _F64]:
    """:func:`._box_fit.complete_boxes`' arithmetic per box, in the numpy version's order
    (``away`` = centre − sensor, ``cos``/``sin`` of the yaw and ``distance`` = max(|away|, 1e-9)
    come from numpy)."""
    k = length_m.shape[0]
    center = center_xy.copy()
    length = length_m.copy()
    width = width_m.copy()
    turned = yaw_rad.copy()
    half_pi = 0.5 * np.pi
    for i in range(k):
        pl, pw = prior_length_m[i], prior_width_m[i]
        seen_l, seen_w = length_m[i], width_m[i]
        has = np.isfinite(pl) and np.isfinite(pw)
        end_view = has and seen_l <= pw + 0.4 and pl > seen_l
        side_view = has and not end_view and seen_w < pw
        ax, ay = away[i, 0], away[i, 1]
        c, s = cos[i], sin[i]
        n0 = -s
        sign = 1.0 if (n0 * ax) + (c * ay) >= 0.0 else -1.0
        grow_end = pl - seen_w if end_view else 0.0
        grow_side = pw - seen_w if side_view else 0.0
        grow = 0.5 * (grow_end + grow_side)
        center[i, 0] += (sign * n0) * grow
        center[i, 1] += (sign * c) * grow
        along = (c * ax) + (s * ay)
        oblique = has and not end_view and seen_l < pl and abs(along) >= 0.5 * distance[i]
        grow_len = 0.5 * (pl - seen_l if oblique else 0.0)
        ahead = 1.0 if along >= 0.0 else -1.0
        center[i, 0] += (ahead * c) * grow_len
        center[i, 1] += (ahead * s) * grow_len
        if end_view or oblique:
            length[i] = pl
        if end_view:
            width[i] = seen_l
        elif side_view:
            width[i] = pw
        t = yaw_rad[i] + half_pi if end_view else yaw_rad[i]
        turned[i] = t - np.pi if t > half_pi else t
    return center, length, width, turned


@_jit
def closeness_terms(xy: _F64, starts: _I64, cos: _F64, sin: _F64, d0: float) -> _F64:
    """The closeness criterion's per-point terms 1 / max(d, d0), (M, A): d is a point's distance
    to the nearer edge of its cluster's rectangle at each candidate heading (``cos``, ``sin``
    (K, A) of the headings; ``xy`` (M, 2) sorted by cluster, clusters starting at ``starts``).
    The caller sums them per cluster (numpy's order of summation stays the caller's)."""
    m = xy.shape[0]
    k_n, a_n = cos.shape
    out = np.empty((m, a_n))
    for k in range(k_n):
        begin = starts[k]
        end = starts[k + 1] if k + 1 < k_n else m
        for a in range(a_n):
            c, s = cos[k, a], sin[k, a]
            lo1 = hi1 = xy[begin, 0] * c + xy[begin, 1] * s
            lo2 = hi2 = xy[begin, 1] * c - xy[begin, 0] * s
            for p in range(begin + 1, end):
                c1 = xy[p, 0] * c + xy[p, 1] * s
                c2 = xy[p, 1] * c - xy[p, 0] * s
                lo1, hi1 = min(lo1, c1), max(hi1, c1)
                lo2, hi2 = min(lo2, c2), max(hi2, c2)
            for p in range(begin, end):
                c1 = xy[p, 0] * c + xy[p, 1] * s
                c2 = xy[p, 1] * c - xy[p, 0] * s
                d = min(hi1 - c1, c1 - lo1, hi2 - c2, c2 - lo2)
                out[p, a] = 1.0 / max(d, d0)
    return out
