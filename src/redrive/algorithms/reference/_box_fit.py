"""Oriented 2D box fitting of point clusters in bird's-eye view, all clusters at once.

Search-based rectangle fitting after Zhang et al. (2017), "Efficient L-Shape Fitting for Vehicle
Detection Using Laser Scanners" (IEEE IV): for each candidate heading θ in [0, π/2) the points are
projected on the axes e1 = (cos θ, sin θ) and e2 = (-sin θ, cos θ), and a criterion scores the
rectangle spanned by the projections:

``"closeness"`` (the paper's Algorithm 4, the default)
    each point's distance to its nearer rectangle edge d = max(min(d1, d2), d0), score Σ 1/d;
    rewards rectangles whose edges carry the points, which is what an L-shaped or I-shaped
    view of a car looks like.
``"area"``
    score = -area: the minimum-area bounding rectangle (to the search resolution).

The search is coarse to fine (``coarse_step_rad`` over [0, π/2), then ``fine_step_rad`` around the
best coarse heading), vectorized over clusters with ``numpy.ufunc.reduceat`` on points sorted by
cluster: no Python loop over clusters or points.

A rectangle has four-fold symmetry, so the fit gives the heading modulo π/2; the box's length is
its longer side and its yaw is the direction of that side, folded into (-π/2, π/2] (the sign of
travel cannot be seen in one sweep; a tracker can flip it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.algorithms.reference._kernels import closeness_terms, grow_boxes

__all__ = ["BoxFit", "collinear_walls", "complete_boxes", "fit_boxes"]

_F64 = npt.NDArray[np.float64]
_I = npt.NDArray[np.intp]

#: the closeness criterion's lower bound on a point's edge distance, metres (paper: 0.01 m).
_D0_M = 0.01
#: a point "lies on an edge" (for the fit quality) when it is this close to one, metres.
_EDGE_BAND_M = 0.2


@dataclass(frozen=True, slots=True, kw_only=True)
class BoxFit:
    """Rectangles fitted to K clusters (bird's-eye view, metres and radians in the points' frame).

    Attributes:
        center_xy: (K, 2) rectangle centres.
        length_m: (K,) the longer side.
        width_m: (K,) the shorter side.
        yaw_rad: (K,) direction of the longer side, in (-π/2, π/2].
        edge_fraction: (K,) share of the points within 0.2 m of the rectangle's nearer edge
            (1 = all points on the outline, the expected look of a solid object).
    """

    center_xy: _F64
    length_m: _F64
    width_m: _F64
    yaw_rad: _F64
    edge_fraction: _F64


def _project(xy: _F64, cid: _I, theta: _F64) -> tuple[_F64, _F64]:
    """Coordinates of each point on e1, e2 of its cluster's candidate headings: (M, A) each."""
    cos = np.cos(theta)[cid]
    sin = np.sin(theta)[cid]
    x = xy[:, 0:1]
    y = xy[:, 1:2]
    return x * cos + y * sin, y * cos - x * sin


def _extents(c: _F64, starts: _I) -> tuple[_F64, _F64]:
    return np.minimum.reduceat(c, starts, axis=0), np.maximum.reduceat(c, starts, axis=0)


def _edge_distance(
    c1: _F64, c2: _F64, cid: _I, starts: _I
) -> tuple[_F64, tuple[_F64, _F64, _F64, _F64]]:
    lo1, hi1 = _extents(c1, starts)
    lo2, hi2 = _extents(c2, starts)
    d1 = np.minimum(hi1[cid] - c1, c1 - lo1[cid])
    d2 = np.minimum(hi2[cid] - c2, c2 - lo2[cid])
    return np.minimum(d1, d2), (lo1, hi1, lo2, hi2)


def _scores(xy: _F64, cid: _I, starts: _I, theta: _F64, criterion: str) -> _F64:
    """Criterion value of every (cluster, candidate heading): (K, A), larger is better."""
    if criterion == "area":
        c1, c2 = _project(xy, cid, theta)
        lo1, hi1 = _extents(c1, starts)
        lo2, hi2 = _extents(c2, starts)
        return -((hi1 - lo1) * (hi2 - lo2))
    # the per-point terms in one pass (a numba kernel); their sums stay numpy's
    terms = closeness_terms(
        xy, starts.astype(np.int64, copy=False), np.cos(theta), np.sin(theta), _D0_M
    )
    return np.add.reduceat(terms, starts, axis=0)


def fit_boxes(
    xy: _F64,
    starts: _I,
    *,
    criterion: str = "closeness",
    coarse_step_rad: float = np.deg2rad(5.0),
    fine_step_rad: float = np.deg2rad(1.0),
) -> BoxFit:
    """Fit one rectangle per cluster.

    Args:
        xy: (M, 2) float64 points in metres, **sorted by cluster**; each cluster ≥ 1 point.
        starts: (K,) index in ``xy`` of each cluster's first point, increasing, ``starts[0] == 0``.
        criterion: ``"closeness"`` or ``"area"`` (module docstring).
        coarse_step_rad, fine_step_rad: search resolution.
    """
    k = int(starts.size)
    if k == 0:
        empty = np.zeros(0)
        return BoxFit(
            center_xy=np.zeros((0, 2)),
            length_m=empty,
            width_m=empty,
            yaw_rad=empty,
            edge_fraction=empty,
        )
    counts = np.diff(np.r_[starts, xy.shape[0]])
    cid = np.repeat(np.arange(k), counts)
    # Cluster-centred coordinates keep the criterion well conditioned far from the origin.
    mean = np.add.reduceat(xy, starts, axis=0) / counts[:, None]
    local = xy - mean[cid]

    coarse = np.arange(0.0, 0.5 * np.pi, coarse_step_rad)
    theta = np.broadcast_to(coarse, (k, coarse.size))
    best = coarse[np.argmax(_scores(local, cid, starts, theta, criterion), axis=1)]
    half = int(np.ceil(coarse_step_rad / fine_step_rad))
    offsets = np.arange(-half, half + 1) * fine_step_rad
    theta = best[:, None] + offsets[None, :]
    pick = np.argmax(_scores(local, cid, starts, theta, criterion), axis=1)
    yaw = theta[np.arange(k), pick]

    c1, c2 = _project(local, cid, yaw[:, None])
    d, (lo1, hi1, lo2, hi2) = _edge_distance(c1, c2, cid, starts)
    lo1, hi1, lo2, hi2 = lo1[:, 0], hi1[:, 0], lo2[:, 0], hi2[:, 0]
    on_edge = np.add.reduceat((d[:, 0] <= _EDGE_BAND_M).astype(np.float64), starts) / counts
    m1, m2 = 0.5 * (lo1 + hi1), 0.5 * (lo2 + hi2)
    cos, sin = np.cos(yaw), np.sin(yaw)
    center = mean + np.stack([m1 * cos - m2 * sin, m1 * sin + m2 * cos], axis=1)
    len1, len2 = hi1 - lo1, hi2 - lo2
    swap = len2 > len1
    length = np.where(swap, len2, len1)
    width = np.where(swap, len1, len2)
    heading = np.where(swap, yaw + 0.5 * np.pi, yaw)
    heading = np.mod(heading + 0.5 * np.pi, np.pi) - 0.5 * np.pi  # [-π/2, π/2)
    heading = np.where(heading <= -0.5 * np.pi + 1e-12, heading + np.pi, heading)
    return BoxFit(
        center_xy=center,
        length_m=length,
        width_m=width,
        yaw_rad=heading,
        edge_fraction=on_edge,
    )


def complete_boxes(
    center_xy: _F64,
    length_m: _F64,
    width_m: _F64,
    yaw_rad: _F64,
    *,
    prior_length_m: _F64,
    prior_width_m: _F64,
    sensor_xy: tuple[float, float],
) -> tuple[_F64, _F64, _F64, _F64]:
    """Grow boxes that show only the near side of an object to its class's prior size.

    A LiDAR sees the faces turned towards it, so a car from behind is a 1.8 m × 0.2 m sliver
    whose centre is ~2 m short of the car's.  Per box (arrays (K,), priors NaN = no prior):

    * **end view** — the seen long side is no longer than the prior width (+0.4 m): it is the
      object's back or front; the box turns by π/2 and its length grows to the prior length,
      away from the sensor;
    * **side view** — the seen short side is narrower than the prior width: the width grows to
      the prior width, away from the sensor;
    * and, not an end view, the seen long side shorter than the prior length while it points
      within 60° of the line of sight (a corner seen from behind, the far end hidden): the
      length grows to the prior length, away from the sensor.  Across the line of sight the
      hidden end cannot be told, and the length is left as seen.

    Returns centre (K, 2), length, width, yaw (-π/2, π/2], in the input's frame and units.
    """
    away = center_xy - np.asarray(sensor_xy, dtype=np.float64)
    # sin, cos and hypot stay numpy's (a kernel's libm could round them otherwise)
    distance = np.maximum(np.hypot(away[:, 0], away[:, 1]), 1e-9)
    return grow_boxes(
        center_xy,
        length_m,
        width_m,
        yaw_rad,
        np.ascontiguousarray(prior_length_m, dtype=np.float64),
        np.ascontiguousarray(prior_width_m, dtype=np.float64),
        away,
        np.cos(yaw_rad),
        np.sin(yaw_rad),
        distance,
    )


def collinear_walls(
    center_xy: _F64,
    yaw_rad: _F64,
    candidate: npt.NDArray[np.bool_],
    *,
    max_angle_rad: float = np.deg2rad(3.0),
    max_offset_m: float = 0.3,
) -> npt.NDArray[np.bool_]:
    """(K,) which candidate boxes lie on one line with another candidate: pieces of one wall.

    A wall, fence or barrier seen past parked cars, poles and its own far end falls apart into
    thin fragments that each look like a truck's flank; fragments of one wall share a line.  Two
    candidates (the caller picks thin, tall boxes) are collinear when their directions differ by
    less than ``max_angle_rad`` and each centre lies within ``max_offset_m`` of the other's line.
    Pairwise over the candidates only (there are few).
    """
    idx = np.flatnonzero(candidate)
    out = np.zeros(candidate.shape, dtype=bool)
    if idx.size < 2:
        return out
    c, yaw = center_xy[idx], yaw_rad[idx]
    diff = np.abs(np.mod(yaw[:, None] - yaw[None, :] + 0.5 * np.pi, np.pi) - 0.5 * np.pi)
    normal = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)  # (C, 2)
    rel = c[None, :, :] - c[:, None, :]  # (C, C, 2): j relative to i
    offset = np.abs(np.sum(rel * normal[:, None, :], axis=2))  # j from i's line
    near = offset < max_offset_m
    pair = (diff < max_angle_rad) & near & near.T
    np.fill_diagonal(pair, False)
    out[idx] = pair.any(axis=1)
    return out
