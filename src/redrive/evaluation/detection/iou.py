"""Exact oriented-box overlap in bird's-eye view and in 3D, vectorised over box pairs.

The intersection of two rotated rectangles is convex; its vertices are the corners of each box
inside the other plus the crossings of their edges.  Those ≤ 24 candidates per pair are sorted by
angle around their mean and the area follows from the shoelace formula — the method of KITTI's
``rotate_iou`` kernel (second.pytorch ``core/non_max_suppression/nms_gpu.py`` /
mmdetection3d ``kitti_utils/rotate_iou.py``: ``quadrilateral_intersection``, ``sort_vertex_in_convex_polygon``,
``area``), here in numpy for all pairs at once.  Tested against ``shapely``.

3D overlap follows KITTI's ``d3_box_overlap_kernel``: BEV intersection × overlap of the vertical
extents, over the union of the volumes.

Boxes are rows ``x, y, length, width, yaw`` (BEV, (N, 5)) or ``x, y, z, length, width, height,
yaw`` (3D, (N, 7), z the centre): metres and radians (yaw about +z, counter-clockwise from +x), in
one frame.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

__all__ = [
    "bev_corners",
    "bev_intersection_area",
    "bev_iou_matrix",
    "bev_iou_pairs",
    "iou_3d_matrix",
    "iou_3d_pairs",
]

F64 = npt.NDArray[np.float64]

#: pairs per chunk (memory: ~24 candidates × a few float64 each).
_CHUNK = 200_000


def bev_corners(boxes_bev: F64) -> F64:
    """(N, 4, 2) corners of (N, 5) boxes ``x, y, length, width, yaw``, counter-clockwise:
    front-left, rear-left, rear-right, front-right."""
    b = np.asarray(boxes_bev, dtype=np.float64).reshape(-1, 5)
    hx, hy = b[:, 2] / 2.0, b[:, 3] / 2.0
    local = np.stack(
        [
            np.stack([hx, hy], -1),
            np.stack([-hx, hy], -1),
            np.stack([-hx, -hy], -1),
            np.stack([hx, -hy], -1),
        ],
        axis=1,
    )  # (N, 4, 2)
    cos, sin = np.cos(b[:, 4])[:, None], np.sin(b[:, 4])[:, None]
    x = local[..., 0] * cos - local[..., 1] * sin + b[:, None, 0]
    y = local[..., 0] * sin + local[..., 1] * cos + b[:, None, 1]
    return np.stack([x, y], axis=-1)


def _inside(points: F64, corners: F64) -> npt.NDArray[np.bool_]:
    """points (N, K, 2) inside (or on the border of) the rectangles ``corners`` (N, 4, 2)."""
    origin = corners[:, 1]  # rear-left
    ex = corners[:, 0] - origin  # along the length
    ey = corners[:, 2] - origin  # across (towards the right side)
    d = points - origin[:, None, :]
    lx = np.einsum("nkd,nd->nk", d, ex)
    ly = np.einsum("nkd,nd->nk", d, ey)
    nx = np.einsum("nd,nd->n", ex, ex)[:, None]
    ny = np.einsum("nd,nd->n", ey, ey)[:, None]
    # borders count as inside, to 1e-10 of the box's size (rounding of rotated corners is ~1e-16)
    tol_x = 1e-10 * nx
    tol_y = 1e-10 * ny
    inside = (lx >= -tol_x) & (lx <= nx + tol_x) & (ly >= -tol_y) & (ly <= ny + tol_y)
    return np.asarray(inside, dtype=bool)


def _area_pairs(a: F64, b: F64) -> F64:
    n = a.shape[0]
    in_a = _inside(a, b)  # corners of a inside b
    in_b = _inside(b, a)
    # edges i of a (a_i → a_{i+1}) against edges j of b
    a0 = a[:, :, None, :]
    da = (np.roll(a, -1, axis=1) - a)[:, :, None, :]
    b0 = b[:, None, :, :]
    db = (np.roll(b, -1, axis=1) - b)[:, None, :, :]
    denom = da[..., 0] * db[..., 1] - da[..., 1] * db[..., 0]  # (n, 4, 4)
    w = b0 - a0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * db[..., 1] - w[..., 1] * db[..., 0]) / denom
        u = (w[..., 0] * da[..., 1] - w[..., 1] * da[..., 0]) / denom
    # (near-)parallel edges give no crossing; where such edges overlap, the corners on them are
    # found by the inside tests (borders count as inside)
    scale = np.hypot(da[..., 0], da[..., 1]) * np.hypot(db[..., 0], db[..., 1])
    ok = (np.abs(denom) > 1e-12 * scale) & (t >= 0.0) & (t <= 1.0) & (u >= 0.0) & (u <= 1.0)
    cross_pts = a0 + np.where(ok, t, 0.0)[..., None] * da  # (n, 4, 4, 2)
    pts = np.concatenate([a, b, cross_pts.reshape(n, 16, 2)], axis=1)  # (n, 24, 2)
    valid = np.concatenate([in_a, in_b, ok.reshape(n, 16)], axis=1)
    count = valid.sum(axis=1)
    centre = np.einsum("nk,nkd->nd", valid.astype(np.float64), pts) / np.maximum(count, 1)[:, None]
    rel = pts - centre[:, None, :]
    angle = np.where(valid, np.arctan2(rel[..., 1], rel[..., 0]), np.inf)
    order = np.argsort(angle, axis=1, kind="stable")
    sorted_pts = np.take_along_axis(rel, order[..., None], axis=1)
    sorted_valid = np.take_along_axis(valid, order, axis=1)
    # invalid slots (at the end) repeat the first vertex: they add no area to the shoelace sum
    sorted_pts = np.where(sorted_valid[..., None], sorted_pts, sorted_pts[:, :1, :])
    nxt = np.roll(sorted_pts, -1, axis=1)
    cross = sorted_pts[..., 0] * nxt[..., 1] - sorted_pts[..., 1] * nxt[..., 0]
    area = 0.5 * np.abs(cross.sum(axis=1))
    return np.where(count >= 3, area, 0.0)


def bev_intersection_area(corners_a: F64, corners_b: F64) -> F64:
    """Intersection areas (N,) of the rectangles ``corners_a[i]`` and ``corners_b[i]`` (N, 4, 2),
    m² (corners from :func:`bev_corners`)."""
    a = np.asarray(corners_a, dtype=np.float64).reshape(-1, 4, 2)
    b = np.asarray(corners_b, dtype=np.float64).reshape(-1, 4, 2)
    if a.shape != b.shape:
        msg = f"bev_intersection_area: {a.shape[0]} boxes against {b.shape[0]}; pass pairs"
        raise ValueError(msg)
    out = np.empty(a.shape[0], dtype=np.float64)
    for start in range(0, a.shape[0], _CHUNK):
        stop = start + _CHUNK
        out[start:stop] = _area_pairs(a[start:stop], b[start:stop])
    return out


def bev_iou_pairs(boxes_a: F64, boxes_b: F64) -> F64:
    """(N,) BEV IoU of the pairs (a[i], b[i]) of (N, 5) boxes ``x, y, length, width, yaw``:
    intersection / (area_a + area_b − intersection); 0 where the union is 0 (KITTI
    ``rotate_iou_eval``, criterion −1)."""
    a = np.asarray(boxes_a, dtype=np.float64).reshape(-1, 5)
    b = np.asarray(boxes_b, dtype=np.float64).reshape(-1, 5)
    inter = bev_intersection_area(bev_corners(a), bev_corners(b))
    union = a[:, 2] * a[:, 3] + b[:, 2] * b[:, 3] - inter
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(union > 0.0, inter / union, 0.0)


def iou_3d_pairs(boxes_a: F64, boxes_b: F64) -> F64:
    """(N,) 3D IoU of the pairs (a[i], b[i]) of (N, 7) boxes ``x, y, z, length, width, height,
    yaw`` (z the centre): BEV intersection × overlap of [z − h/2, z + h/2], over
    vol_a + vol_b − that (KITTI ``d3_box_overlap``, criterion −1); 0 where they do not overlap or
    the union is 0."""
    a = np.asarray(boxes_a, dtype=np.float64).reshape(-1, 7)
    b = np.asarray(boxes_b, dtype=np.float64).reshape(-1, 7)
    inter = bev_intersection_area(
        bev_corners(a[:, [0, 1, 3, 4, 6]]), bev_corners(b[:, [0, 1, 3, 4, 6]])
    )
    top = np.minimum(a[:, 2] + a[:, 5] / 2, b[:, 2] + b[:, 5] / 2)
    bottom = np.maximum(a[:, 2] - a[:, 5] / 2, b[:, 2] - b[:, 5] / 2)
    iw = top - bottom
    inc = np.where((inter > 0.0) & (iw > 0.0), inter * iw, 0.0)
    union = np.prod(a[:, 3:6], axis=1) + np.prod(b[:, 3:6], axis=1) - inc
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((inc > 0.0) & (union > 0.0), inc / union, 0.0)


def _pairs(n: int, m: int) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    return i.reshape(-1), j.reshape(-1)


def bev_iou_matrix(boxes_a: F64, boxes_b: F64) -> F64:
    """(N, M) BEV IoU of every box of a (N, 5) with every box of b (M, 5) (:func:`bev_iou_pairs`)."""
    a = np.asarray(boxes_a, dtype=np.float64).reshape(-1, 5)
    b = np.asarray(boxes_b, dtype=np.float64).reshape(-1, 5)
    i, j = _pairs(a.shape[0], b.shape[0])
    return bev_iou_pairs(a[i], b[j]).reshape(a.shape[0], b.shape[0])


def iou_3d_matrix(boxes_a: F64, boxes_b: F64) -> F64:
    """(N, M) 3D IoU of every box of a (N, 7) with every box of b (M, 7) (:func:`iou_3d_pairs`)."""
    a = np.asarray(boxes_a, dtype=np.float64).reshape(-1, 7)
    b = np.asarray(boxes_b, dtype=np.float64).reshape(-1, 7)
    i, j = _pairs(a.shape[0], b.shape[0])
    return iou_3d_pairs(a[i], b[j]).reshape(a.shape[0], b.shape[0])
