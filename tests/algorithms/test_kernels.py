"""The reference algorithms' numba kernels give what the numpy/scipy code they replaced gave,
bit for bit.

The references below are that former code — the detector's front end (crop, ground-cell minima,
obstacle split, :func:`scipy.ndimage.label` clustering) and the planner's projection onto its
path — kept here as the specification of the kernels.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest
from scipy import ndimage

from redrive.algorithms.reference import _box_fit
from redrive.algorithms.reference._clusters import Clusters, cluster_points
from redrive.algorithms.reference._ground import GroundGrid
from redrive.algorithms.reference._kernels import (
    label_clusters,
    plane_hypotheses,
    subsample_clusters,
)
from redrive.algorithms.reference.detector import ClusterDetector
from redrive.algorithms.reference.planner import Polyline

_F32 = npt.NDArray[np.float32]


def _sweep(seed: int) -> _F32:
    """A sweep-like cloud in the sensor frame (1.9 m above a sloped, noisy ground): ground rings,
    boxes, poles and walls, some points out of range, some NaN."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(1.0, 90.0, 20000)
    a = rng.uniform(-np.pi, np.pi, r.size)
    gx, gy = r * np.cos(a), r * np.sin(a)
    ground = np.column_stack([gx, gy, 0.01 * gx + rng.normal(0.0, 0.03, r.size)])
    parts = [ground]
    for _ in range(int(rng.integers(10, 30))):
        cx, cy = rng.uniform(-60.0, 60.0, 2)
        length, width = rng.uniform(0.3, 12.0), rng.uniform(0.1, 3.0)
        height = rng.choice([1.5, 2.2, 3.5, 6.0])
        yaw = rng.uniform(-np.pi, np.pi)
        n = int(rng.integers(5, 800))
        u, v = rng.uniform(-0.5, 0.5, (2, n))
        px = cx + length * u * np.cos(yaw) - width * v * np.sin(yaw)
        py = cy + length * u * np.sin(yaw) + width * v * np.cos(yaw)
        parts.append(np.column_stack([px, py, 0.01 * px + rng.uniform(0.0, height, n)]))
    xyz = np.concatenate(parts) - np.array([1.2, 0.0, 1.9])
    xyz[rng.integers(0, len(xyz), 20), rng.integers(0, 3, 20)] = np.nan
    out: _F32 = xyz.astype(np.float32)
    return out


def _reference_ground(
    grid: GroundGrid, minima: _F32, *, method: str, max_step_m: float, fallback_z_m: float
) -> _F32:
    """The former numpy version of _ground.ground_heights and fit_plane."""
    low = minima.reshape(grid.n, grid.n)
    padded = np.pad(low, 1, constant_values=np.inf)
    local = low.copy()
    for di in (0, 1, 2):
        for dj in (0, 1, 2):
            np.minimum(local, padded[di : di + grid.n, dj : dj + grid.n], out=local)
    cx, cy = grid.centres()
    sample = np.isfinite(low) & (low <= local + np.float32(0.05))
    x, y, z = cx[sample], cy[sample], low[sample].astype(np.float64)
    if z.size < 3:
        return np.full((grid.n, grid.n), fallback_z_m, dtype=np.float32)
    tri = np.random.default_rng(0).integers(0, z.size, size=(32, 3))
    every = max(1, z.size // 800)
    xs, ys, zs = x[::every], y[::every], z[::every]
    p = np.stack([x[tri], y[tri], z[tri]], axis=-1)
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    ok = np.abs(normal[:, 2]) > 0.9 * np.maximum(np.linalg.norm(normal, axis=1), 1e-12)
    if not np.any(ok):
        a, b, c = 0.0, 0.0, float(np.median(z))
    else:
        normal, p0 = normal[ok], p[ok, 0]
        a_h = -normal[:, 0] / normal[:, 2]
        b_h = -normal[:, 1] / normal[:, 2]
        c_h = p0[:, 2] - a_h * p0[:, 0] - b_h * p0[:, 1]
        resid = np.abs(zs[None, :] - (a_h[:, None] * xs + b_h[:, None] * ys + c_h[:, None]))
        best = int(np.argmax((resid < 0.15).sum(axis=1)))
        a, b, c = float(a_h[best]), float(b_h[best]), float(c_h[best])
    inliers = np.abs(z - (a * x + b * y + c)) < 0.15
    if int(inliers.sum()) >= 3:
        design = np.stack([x[inliers], y[inliers], np.ones(int(inliers.sum()))], axis=1)
        a, b, c = (float(v) for v in np.linalg.lstsq(design, z[inliers], rcond=None)[0])
    plane_z = (a * cx + b * cy + c).astype(np.float32)
    if method == "plane":
        return plane_z
    usable = np.isfinite(local) & (local <= plane_z + np.float32(max_step_m))
    out: _F32 = np.where(usable, local, plane_z).astype(np.float32)
    return out


def _reference_front_end(
    det: ClusterDetector, xyz: _F32, sensor_location: tuple[float, float, float]
) -> tuple[tuple[_F32, _F32, _F32, _F32], Clusters]:
    """The former numpy version of ClusterDetector.detect up to the box fit."""
    cfg = det.config
    sx, sy, sz = (np.float32(v) for v in sensor_location)
    x, y, z = np.ascontiguousarray(xyz.T, dtype=np.float32)
    x, y, z = x + sx, y + sy, z + sz
    grid = det._ground_grid
    r, r0 = np.float32(grid.crop_m), np.float32(cfg["min_range_m"])
    dx, dy = x - sx, y - sy
    keep = (np.abs(x) < r) & (np.abs(y) < r) & (dx * dx + dy * dy > r0 * r0) & np.isfinite(z)
    x, y, z = x[keep], y[keep], z[keep]
    inv, half = np.float32(1.0 / grid.cell_m), np.float32(grid.half_extent_m)
    keys = ((x + half) * inv).astype(np.intp) * grid.n + ((y + half) * inv).astype(np.intp)
    minima = np.full(grid.n * grid.n, np.inf, dtype=np.float32)
    np.minimum.at(minima, keys, z)
    ground = _reference_ground(
        grid,
        minima,
        method=str(cfg["ground_method"]),
        max_step_m=float(cfg["ground_max_step_m"]),
        fallback_z_m=float(sz) - 1.8,
    ).ravel()
    gz = ground[keys]
    above = z - gz
    max_h = np.float32(cfg["max_height_m"])
    obstacle = (above > np.float32(cfg["ground_threshold_m"])) & (above < max_h)
    tall = (above >= max_h) & (above < max_h + np.float32(det._drop["tall_band_m"]))
    ox, oy = x[obstacle], y[obstacle]
    # clustering with scipy.ndimage.label, as _clusters.cluster_points did
    cell = float(cfg["cluster_tolerance_m"])
    n = int(np.ceil(2.0 * grid.half_extent_m / cell))
    c_inv, c_half = np.float32(1.0 / cell), np.float32(0.5 * n * cell)

    def cell_keys(px: _F32, py: _F32) -> npt.NDArray[np.intp]:
        return ((px + c_half) * c_inv).astype(np.intp) * n + ((py + c_half) * c_inv).astype(np.intp)

    ckeys = cell_keys(ox, oy)
    occupied = np.zeros(n * n, dtype=bool)
    occupied[ckeys] = True
    labels, n_labels = ndimage.label(occupied.reshape(n, n), structure=np.ones((3, 3), bool))
    point_label = labels.ravel()[ckeys]
    counts = np.bincount(point_label, minlength=n_labels + 1)
    counts[0] = 0
    kept = (counts >= int(cfg["min_points"])) & (counts <= int(cfg["max_points"]))
    if np.any(tall):
        kept[labels.ravel()[cell_keys(x[tall], y[tall])]] = False
    ids = np.flatnonzero(kept)
    new_id = np.full(n_labels + 1, -1)
    new_id[ids] = np.arange(ids.size)
    pid = new_id[point_label]
    chosen = np.flatnonzero(pid >= 0)
    order = np.argsort(pid[chosen], kind="stable")
    kept_counts = counts[ids].astype(np.intp)
    starts = np.r_[0, np.cumsum(kept_counts)[:-1]].astype(np.intp)
    clusters = Clusters(index=chosen[order], starts=starts[: ids.size], counts=kept_counts)
    return (ox, oy, z[obstacle], gz[obstacle]), clusters


@pytest.mark.parametrize(("seed", "method"), [(s, "grid") for s in range(6)] + [(6, "plane")])
def test_detect_equals_the_former_numpy_steps(seed: int, method: str) -> None:
    det = ClusterDetector()
    det.configure({"ground_method": method})
    xyz = _sweep(seed)
    location = (1.2, 0.0, 1.9)
    points, clusters = _reference_front_end(det, xyz, location)
    assert clusters.starts.size > 3  # the sweep has something to find
    expected = det._boxes(points, clusters, sensor_xy=(1.2, 0.0))
    got = det.detect(xyz, sensor_location=location)
    assert len(got) == len(expected) > 0
    for a, b in zip(got, expected, strict=True):
        assert a.object_class is b.object_class
        assert a.confidence == b.confidence
        assert a.box.yaw_rad == b.box.yaw_rad
        np.testing.assert_array_equal(a.box.center, b.box.center)
        np.testing.assert_array_equal(a.box.size, b.box.size)


@pytest.mark.parametrize("seed", range(20))
def test_label_clusters_numbers_components_as_ndimage_label(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(3, 40))
    cell = 0.5
    half = 0.5 * n * cell
    m = int(rng.integers(0, 6 * n))
    x = rng.uniform(-half + 1e-3, half - 1e-3, m).astype(np.float32)
    y = rng.uniform(-half + 1e-3, half - 1e-3, m).astype(np.float32)
    tall = rng.uniform(-half + 1e-3, half - 1e-3, (2, int(rng.integers(0, 4)))).astype(np.float32)
    got = cluster_points(
        x, y, half_extent_m=half, cell_m=cell, min_points=1, max_points=10**6, tall_xy=(*tall,)
    )
    i = ((x + np.float32(half)) * np.float32(1 / cell)).astype(np.intp)
    j = ((y + np.float32(half)) * np.float32(1 / cell)).astype(np.intp)
    grid = np.zeros((n, n), dtype=bool)
    grid[i, j] = True
    labels, count = ndimage.label(grid, structure=np.ones((3, 3), bool))
    ti = ((tall[0] + np.float32(half)) * np.float32(1 / cell)).astype(np.intp)
    tj = ((tall[1] + np.float32(half)) * np.float32(1 / cell)).astype(np.intp)
    dropped = set(labels[ti, tj].tolist())
    point_label = labels[i, j]
    want = [np.flatnonzero(point_label == k) for k in range(1, count + 1) if k not in dropped]
    got_groups = [
        got.index[s : s + c] for s, c in zip(got.starts.tolist(), got.counts.tolist(), strict=True)
    ]
    assert len(got_groups) == len(want)
    for a, b in zip(got_groups, want, strict=True):
        np.testing.assert_array_equal(a, b)


def test_label_clusters_leaves_its_scratch_grid_as_it_found_it() -> None:
    scratch = np.full(100, -1, dtype=np.int64)
    xy = np.array([0.1, 0.2, 3.0], dtype=np.float32)
    none = np.zeros(0, dtype=np.float32)
    index, starts, counts = label_clusters(
        xy, xy, none, none, np.float32(5.0), np.float32(1.0), 10, 1, 10, scratch
    )
    assert index.tolist() == [0, 1, 2]
    assert starts.tolist() == [0, 2]
    assert counts.tolist() == [2, 1]
    assert np.all(scratch == -1)


def _reference_project(
    line: Polyline, p: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.float64], ...]:
    """The former numpy broadcasting of Polyline.project (all segments)."""
    a = line.xy[:-1]
    ab = line.xy[1:] - a
    seg_len = np.hypot(ab[:, 0], ab[:, 1])
    ap = p[:, None, :] - a[None, :, :]
    t = np.clip((ap * ab[None]).sum(axis=2) / seg_len**2, 0.0, 1.0)
    foot = a[None] + t[..., None] * ab[None]
    d2 = ((p[:, None, :] - foot) ** 2).sum(axis=2)
    j = np.argmin(d2, axis=1)
    rows = np.arange(len(p))
    s = line.s[j] + t[rows, j] * seg_len[j]
    lateral = (ab[j, 0] * ap[rows, j, 1] - ab[j, 1] * ap[rows, j, 0]) / seg_len[j]
    return s, lateral, np.sqrt(d2[rows, j])


@pytest.mark.parametrize("seed", range(10))
def test_project_equals_the_former_numpy_broadcasting(seed: int) -> None:
    rng = np.random.default_rng(200 + seed)
    k = int(rng.integers(2, 300))
    heading = np.cumsum(rng.normal(0.0, 0.2, k))
    xy = np.cumsum(np.column_stack([np.cos(heading), np.sin(heading)]) * 0.5, axis=0)
    line = Polyline(xy)
    p = rng.uniform(-20.0, 80.0, (int(rng.integers(0, 40)), 2))
    p[: min(2, len(p))] = line.xy[rng.integers(0, len(line.xy), min(2, len(p)))]  # on a vertex
    if seed % 3 == 0 and len(p):
        p[-1, 0] = np.nan
    got = line.project(p)
    for a, b in zip(got, _reference_project(line, p), strict=True):
        np.testing.assert_array_equal(a, b)
        assert np.array_equal(np.signbit(a), np.signbit(b))


@pytest.mark.parametrize("seed", range(8))
def test_closeness_scores_equal_the_former_numpy_broadcasting(seed: int) -> None:
    rng = np.random.default_rng(300 + seed)
    counts = rng.integers(1, 120, int(rng.integers(1, 15)))
    starts = np.r_[0, np.cumsum(counts)[:-1]].astype(np.intp)
    xy = rng.normal(0.0, 2.0, (int(counts.sum()), 2))
    xy[rng.integers(0, len(xy), 3)] = xy[0]  # repeated points
    cid = np.repeat(np.arange(counts.size), counts)
    coarse = np.arange(0.0, 0.5 * np.pi, np.deg2rad(5.0))
    for theta in (
        np.broadcast_to(coarse, (counts.size, coarse.size)),
        rng.uniform(0.0, np.pi, (counts.size, 11)),
    ):
        cos, sin = np.cos(theta)[cid], np.sin(theta)[cid]
        c1 = xy[:, 0:1] * cos + xy[:, 1:2] * sin
        c2 = xy[:, 1:2] * cos - xy[:, 0:1] * sin
        lo1, hi1 = np.minimum.reduceat(c1, starts), np.maximum.reduceat(c1, starts)
        lo2, hi2 = np.minimum.reduceat(c2, starts), np.maximum.reduceat(c2, starts)
        d = np.minimum(
            np.minimum(hi1[cid] - c1, c1 - lo1[cid]), np.minimum(hi2[cid] - c2, c2 - lo2[cid])
        )
        np.maximum(d, 0.01, out=d)
        expected = np.add.reduceat(1.0 / d, starts, axis=0)
        np.testing.assert_array_equal(
            _box_fit._scores(xy, cid, starts, theta, "closeness"), expected
        )


def test_plane_hypotheses_equal_the_former_numpy_steps() -> None:
    """Random triples, repeated points (no plane) and steep planes included."""
    rng = np.random.default_rng(42)
    kept = []
    for n in (3, 50, 1200):
        x, y = rng.normal(0.0, 30.0, (2, n))
        z = np.where(rng.random(n) < 0.2, rng.normal(0.0, 30.0, n), rng.normal(0.0, 0.3, n))
        tri = rng.integers(0, n, size=(64, 3))
        tri[:4, 1] = tri[:4, 0]
        p = np.stack([x[tri], y[tri], z[tri]], axis=-1)
        normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        ok = np.abs(normal[:, 2]) > 0.9 * np.maximum(np.linalg.norm(normal, axis=1), 1e-12)
        normal, p0 = normal[ok], p[ok, 0]
        a_h = -normal[:, 0] / normal[:, 2]
        b_h = -normal[:, 1] / normal[:, 2]
        c_h = p0[:, 2] - a_h * p0[:, 0] - b_h * p0[:, 1]
        got = plane_hypotheses(x, y, z, tri)
        kept.append(got[0].size)
        for have, want in zip(got, (a_h, b_h, c_h), strict=True):
            np.testing.assert_array_equal(have, want)
    assert 0 < kept[-1] < 64  # some planes kept, some refused


def test_subsample_clusters_equals_the_former_numpy_steps() -> None:
    rng = np.random.default_rng(7)
    counts = rng.integers(1, 400, 30).astype(np.intp)
    counts[:3] = (96, 97, 192)
    starts = np.r_[0, np.cumsum(counts)[:-1]].astype(np.intp)
    m = int(counts.sum()) + 50
    index = rng.permutation(m)[: counts.sum()].astype(np.intp)
    ox, oy = rng.normal(0.0, 20.0, (2, m)).astype(np.float32)
    cid = np.repeat(np.arange(counts.size), counts)
    rank = np.arange(index.size) - starts[cid]
    stride = np.maximum(1, -(-counts // 96))
    sub = index[rank % stride[cid] == 0]
    sub_counts = -(-counts // stride)
    want_starts = np.r_[0, np.cumsum(sub_counts)[:-1]].astype(np.intp)
    want_xy = np.stack([ox[sub], oy[sub]], axis=1).astype(np.float64)
    xy, sub_starts = subsample_clusters(ox, oy, index, starts, counts, 96)
    np.testing.assert_array_equal(xy, want_xy)
    np.testing.assert_array_equal(sub_starts, want_starts)
    assert xy.dtype == np.float64
    assert xy.shape[0] < index.size  # some clusters were thinned


def _reference_complete_boxes(
    center_xy: npt.NDArray[np.float64],
    length_m: npt.NDArray[np.float64],
    width_m: npt.NDArray[np.float64],
    yaw_rad: npt.NDArray[np.float64],
    *,
    prior_length_m: npt.NDArray[np.float64],
    prior_width_m: npt.NDArray[np.float64],
    sensor_xy: tuple[float, float],
) -> tuple[npt.NDArray[np.float64], ...]:
    """The former numpy version of _box_fit.complete_boxes."""
    center = center_xy.copy()
    length, width, yaw = length_m.copy(), width_m.copy(), yaw_rad.copy()
    has = np.isfinite(prior_length_m) & np.isfinite(prior_width_m)
    end_view = has & (length_m <= prior_width_m + 0.4) & (prior_length_m > length_m)
    side_view = has & ~end_view & (width_m < prior_width_m)
    away = center_xy - np.asarray(sensor_xy, dtype=np.float64)
    normal = np.stack([-np.sin(yaw_rad), np.cos(yaw_rad)], axis=1)
    sign = np.where(np.sum(normal * away, axis=1) >= 0.0, 1.0, -1.0)[:, None]
    grow_end = np.where(end_view, prior_length_m - width_m, 0.0)
    grow_side = np.where(side_view, prior_width_m - width_m, 0.0)
    center += sign * normal * (0.5 * (grow_end + grow_side))[:, None]
    axis = np.stack([np.cos(yaw_rad), np.sin(yaw_rad)], axis=1)
    along = np.sum(axis * away, axis=1)
    distance = np.maximum(np.hypot(away[:, 0], away[:, 1]), 1e-9)
    oblique = has & ~end_view & (length_m < prior_length_m) & (np.abs(along) >= 0.5 * distance)
    grow_len = np.where(oblique, prior_length_m - length_m, 0.0)
    center += np.where(along >= 0.0, 1.0, -1.0)[:, None] * axis * (0.5 * grow_len)[:, None]
    length = np.where(end_view | oblique, prior_length_m, length)
    width = np.where(end_view, length_m, np.where(side_view, prior_width_m, width))
    turned = np.where(end_view, yaw + 0.5 * np.pi, yaw)
    turned = np.where(turned > 0.5 * np.pi, turned - np.pi, turned)
    return center, length, width, turned


def test_complete_boxes_equals_the_former_numpy_steps() -> None:
    rng = np.random.default_rng(11)
    k = 400
    center = rng.normal(0.0, 30.0, (k, 2))
    length = rng.uniform(0.1, 12.0, k)
    width = np.minimum(length, rng.uniform(0.05, 3.0, k))
    yaw = rng.uniform(-0.5 * np.pi, 0.5 * np.pi, k)
    prior = np.array([[4.5, 1.8], [10.0, 2.5], [np.nan, np.nan]])[rng.integers(0, 3, k)]
    center[:4] = (1.2, 0.0)  # at the sensor
    sensor = (1.2, 0.0)
    got = _box_fit.complete_boxes(
        center,
        length,
        width,
        yaw,
        prior_length_m=prior[:, 0],
        prior_width_m=prior[:, 1],
        sensor_xy=sensor,
    )
    want = _reference_complete_boxes(
        center,
        length,
        width,
        yaw,
        prior_length_m=prior[:, 0],
        prior_width_m=prior[:, 1],
        sensor_xy=sensor,
    )
    for have, ref in zip(got, want, strict=True):
        np.testing.assert_array_equal(have, ref)
    assert (got[1] != length).sum() > 20  # some boxes grew
    assert (got[3] != yaw).sum() > 5  # some turned
