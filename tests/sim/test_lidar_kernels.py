"""The LiDAR's compiled ray set-up and return selection give numpy's answers bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from redrive.sim import lidar_kernels

COLS, LASERS, SLICES = 40, 16, 4


def _rotations(rng: np.random.Generator, *, upright: bool) -> np.ndarray:
    yaw = rng.uniform(-np.pi, np.pi, SLICES)
    rot = np.zeros((SLICES, 3, 3))
    rot[:, 0, 0], rot[:, 0, 1] = np.cos(yaw), -np.sin(yaw)
    rot[:, 1, 0], rot[:, 1, 1] = np.sin(yaw), np.cos(yaw)
    rot[:, 2, 2] = 1.0
    if not upright:  # a small roll about x
        roll = np.array(
            [[1.0, 0.0, 0.0], [0.0, np.cos(0.1), -np.sin(0.1)], [0.0, np.sin(0.1), np.cos(0.1)]]
        )
        rot = rot @ roll
    return rot


def _numpy_rays(  # noqa: PLR0917
    slice_of_col,
    rot,
    local,
    pos,
    max_limit,
    cos_elev,
    tan_elev,
    r_col,
    top_col,
    margin,
    *,
    upright,
    cull,
):
    """What ``LidarModel.scan`` computed with numpy before the kernel."""
    lx, ly, lz = local
    r = rot[slice_of_col].astype(np.float32)
    dx = r[:, 0, 0:1] * lx + r[:, 0, 1:2] * ly + r[:, 0, 2:3] * lz
    dy = r[:, 1, 0:1] * lx + r[:, 1, 1:2] * ly + r[:, 1, 2:3] * lz
    dz = lz if upright else r[:, 2, 0:1] * lx + r[:, 2, 1:2] * ly + r[:, 2, 2:3] * lz
    oz = pos[:, 2:3].astype(np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = np.where((dz < 0.0) & (oz > 0.0), -oz / dz, np.float32(np.inf))
    limit = np.minimum(t_ground, max_limit)
    if cull:
        need = limit * cos_elev[None, :] >= r_col[:, None]
        up = tan_elev > 0.0
        r_fin = np.where(np.isfinite(r_col), r_col, 0.0)[:, None]
        need[:, up] &= tan_elev[None, up] * r_fin + pos[:, 2:3] <= top_col[:, None] + margin
    else:
        need = np.ones(dz.shape, dtype=bool)
    return (
        dx.reshape(-1),
        dy.reshape(-1),
        dz.reshape(-1),
        t_ground.reshape(-1),
        limit.reshape(-1),
        np.flatnonzero(need),
    )


@pytest.mark.parametrize(("upright", "cull"), [(True, True), (True, False), (False, False)])
def test_rays_equal_numpy(upright: bool, cull: bool) -> None:
    rng = np.random.default_rng(7)
    slice_of_col = np.repeat(np.arange(SLICES), COLS // SLICES).astype(np.int64)
    rot = _rotations(rng, upright=upright)
    elev = np.linspace(-0.4, 0.2, LASERS)
    az = np.linspace(np.pi, -np.pi, COLS, endpoint=False)
    local = tuple(
        np.ascontiguousarray(a.astype(np.float32))
        for a in (
            np.cos(az)[:, None] * np.cos(elev)[None, :],
            np.sin(az)[:, None] * np.cos(elev)[None, :],
            np.broadcast_to(np.sin(elev)[None, :], (COLS, LASERS)),
        )
    )
    pos = np.column_stack(
        [1200.0 + rng.uniform(0, 2, COLS), -800.0 + rng.uniform(0, 2, COLS), np.full(COLS, 1.8)]
    )
    origin = pos[0].copy()
    cos_elev, tan_elev = np.cos(elev).astype(np.float32), np.tan(elev)
    r_col = np.where(rng.random(COLS) < 0.3, np.inf, rng.uniform(0.0, 30.0, COLS))
    top_col = rng.uniform(0.5, 4.0, COLS)
    max_limit = np.float32(100.0 * 1.01)
    want = _numpy_rays(
        slice_of_col,
        rot,
        local,
        pos,
        max_limit,
        cos_elev,
        tan_elev,
        r_col,
        top_col,
        0.07,
        upright=upright,
        cull=cull,
    )
    n_rays = COLS * LASERS
    got = [np.empty(n_rays, np.float32) for _ in range(5)]
    sel = np.empty(n_rays, np.int64)
    sel_orig, sel_dirs = np.empty((n_rays, 3), np.float32), np.empty((n_rays, 3), np.float32)
    sel_limit = np.empty(n_rays, np.float32)
    n = lidar_kernels.rays(
        slice_of_col,
        rot,
        *local,
        pos,
        origin,
        upright,
        max_limit,
        cull,
        cos_elev,
        tan_elev,
        r_col,
        top_col,
        0.07,
        *got,
        sel,
        sel_orig,
        sel_dirs,
        sel_limit,
    )
    for a, b in zip(got, want[:5], strict=True):
        assert np.array_equal(a, b)
    assert np.array_equal(sel[:n], want[5])
    if cull:
        assert 0 < n < n_rays  # the cull dropped some rays and kept others
    cols = want[5] // LASERS
    assert np.array_equal(sel_orig[:n], (pos - origin).astype(np.float32)[cols])
    assert np.array_equal(sel_dirs[:n], np.column_stack([w[want[5]] for w in want[:3]]))
    assert np.array_equal(sel_limit[:n], want[4][want[5]])


def test_kept_equal_numpy() -> None:
    rng = np.random.default_rng(3)
    n_rays = 500
    limit = rng.uniform(0.0, 130.0, n_rays).astype(np.float32)
    t_ground = np.where(rng.random(n_rays) < 0.5, np.float32(np.inf), limit)
    sel = np.sort(rng.choice(n_rays, 200, replace=False)).astype(np.int64)
    prim = np.where(rng.random(200) < 0.5, -1, rng.integers(0, 120, 200)).astype(
        np.int32
    )  # 10 boxes
    sel_dist = np.where(prim >= 0, limit[sel] * np.float32(0.5), limit[sel]).astype(np.float32)
    sel_dist[:3] = [
        np.float32(0.9),
        np.nextafter(np.float32(0.9), np.float32(0)),
        np.float32(120.0),
    ]
    prim[:3] = 5
    box_of_mesh = np.sort(rng.choice(40, 10, replace=False)).astype(np.int64)  # meshed boxes
    # numpy, as scan did it (min/max range compared in float32, as numpy 2 does with a float)
    dist_np = limit.copy()
    box_np = np.full(n_rays, -1, np.int64)
    dist_np[sel] = np.where(prim >= 0, sel_dist, limit[sel])
    box_np[sel] = np.where(prim >= 0, box_of_mesh[prim // 12], -1)
    keep_np = (box_np >= 0) | (t_ground <= 120.0)
    keep_np &= (dist_np >= 0.9) & (dist_np <= 120.0)
    dist, box = limit.copy(), np.empty(n_rays, np.int64)
    where, keep = np.empty(n_rays, np.int64), np.empty(n_rays, np.bool_)
    lidar_kernels.kept(
        sel,
        sel_dist,
        prim,
        12,
        box_of_mesh,
        t_ground,
        np.float32(0.9),
        np.float32(120.0),
        dist,
        box,
        where,
        keep,
    )
    assert np.array_equal(dist, dist_np)
    assert np.array_equal(box, box_np)
    assert np.array_equal(keep, keep_np)
    assert np.array_equal(where[sel], np.arange(sel.size))


def test_columns_and_reach_equal_numpy() -> None:
    """The slice poses mixed per column and the cull's figures, as ``scan`` made them in numpy."""
    rng = np.random.default_rng(11)
    slice_of_col = np.repeat(np.arange(SLICES), COLS // SLICES).astype(np.int64)
    frac = np.tile(np.arange(COLS // SLICES) / (COLS // SLICES), SLICES)
    start = np.array([512.3, -77.1, 1.8])
    slice_pos = start + np.cumsum(rng.uniform(0.0, 0.8, (SLICES + 1, 3)), axis=0)
    pos = np.empty((COLS, 3))
    lidar_kernels.columns(slice_pos, slice_of_col, frac, pos)
    f = frac[:, None]
    want = slice_pos[slice_of_col] * (1.0 - f) + slice_pos[slice_of_col + 1] * f
    assert np.array_equal(pos, want)

    rot = _rotations(rng, upright=True)
    n_box = 60
    centers = np.c_[pos[0, :2] + rng.uniform(-30.0, 30.0, (n_box, 2)), rng.uniform(0, 4, n_box)]
    centers[:3, :2] = pos[0, :2] + [0.5, -0.4]  # boxes around the sensor: every azimuth
    sizes = rng.uniform(0.3, 9.0, (n_box, 3))
    starts = np.arange(0, COLS, COLS // SLICES, dtype=np.int64)
    mid_az = rng.uniform(-np.pi, np.pi, SLICES)
    half_az = np.full(SLICES, 0.4)
    # numpy, as LidarModel._box_reach did it
    step = np.linalg.norm(np.diff(pos[np.r_[starts, -1]], axis=0), axis=1)
    margin_np = 0.05 + float(np.max(step, initial=0.0))
    rel = centers[None, :, :2] - pos[starts, None, :2]
    half_diag = 0.5 * np.hypot(sizes[:, 0], sizes[:, 1]) + margin_np
    dist_c = np.hypot(rel[..., 0], rel[..., 1])
    r_min = np.maximum(dist_c - half_diag, 0.0)
    az_c = np.arctan2(rel[..., 1], rel[..., 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        half_width = np.where(
            dist_c > half_diag, np.arcsin(np.minimum(half_diag / dist_c, 1.0)), np.pi
        )
    az_s = np.arctan2(rot[:, 1, 0], rot[:, 0, 0]) + mid_az
    diff = np.abs((az_s[:, None] - az_c + np.pi) % (2.0 * np.pi) - np.pi)
    covers = diff <= half_width + half_az[:, None] + 1e-3
    assert 0 < covers.sum() < covers.size
    r_np = np.where(covers, r_min, np.inf).min(axis=1)[slice_of_col]
    top = centers[:, 2] + 0.5 * sizes[:, 2]
    top_np = np.where(covers, top[None, :], -np.inf).max(axis=1)[slice_of_col]
    r_col, top_col = np.empty(COLS), np.empty(COLS)
    margin = lidar_kernels.reach(
        starts, pos, rot, centers, sizes, mid_az, half_az, slice_of_col, r_col, top_col
    )
    assert margin == margin_np
    assert np.array_equal(r_col, r_np)
    assert np.array_equal(top_col, top_np)
    # nothing near: no slice is covered
    far = lidar_kernels.reach(
        starts, pos, rot, centers[:0], sizes[:0], mid_az, half_az, slice_of_col, r_col, top_col
    )
    assert far == margin_np
    assert np.all(r_col == np.inf)
    assert np.all(top_col == -np.inf)
