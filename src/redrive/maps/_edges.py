"""Exact distances from many points to many segments (the road edge), fast: a KD-tree of points
spaced along the segments bounds each distance from above, an STRtree of the segments' boxes
gives the segments within that bound, and numpy measures those exactly.

GEOS's own nearest-neighbour query (``STRtree.query_nearest`` over the segments as line
strings) took ~5 µs a point on the Argoverse 2 map's 1,454 edge segments; this takes 0.41-0.46 of
that (thread CPU, 100 points at a time, measured side by side at load 10).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import shapely
from scipy.spatial import cKDTree

__all__ = ["SegmentDistance"]

F64 = npt.NDArray[np.float64]


class SegmentDistance:
    """Distance of points to the nearest of ``segments`` (M, 2, 2): start and end x, y, metres.

    Args:
        spacing_m: the KD-tree's points are at most this far apart along each segment (the
            upper bound is then at most ``spacing_m / 2`` above the distance).
    """

    def __init__(self, segments: F64, *, spacing_m: float = 2.0) -> None:
        seg = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
        self._a = np.ascontiguousarray(seg[:, 0])
        self._d = np.ascontiguousarray(seg[:, 1] - seg[:, 0])
        self._len2 = (self._d**2).sum(axis=1)
        self.count = seg.shape[0]
        if self.count == 0:
            return
        length = np.sqrt(self._len2)
        n = np.maximum(np.ceil(length / spacing_m).astype(np.int64), 1) + 1
        which = np.repeat(np.arange(self.count), n)
        first = np.repeat(np.cumsum(n) - n, n)
        t = (np.arange(which.size) - first) / np.repeat(n - 1, n)
        self._kd = cKDTree(self._a[which] + t[:, None] * self._d[which])
        low, high = seg.min(axis=1), seg.max(axis=1)
        self._tree = shapely.STRtree(shapely.box(low[:, 0], low[:, 1], high[:, 0], high[:, 1]))

    def __call__(self, xy: F64) -> F64:
        """(N,) distance of each point (N, 2) to the nearest segment; inf without segments."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.count == 0:
            return np.full(p.shape[0], math.inf)
        bound, _ = self._kd.query(p)
        r = np.asarray(bound, dtype=np.float64) * (1.0 + 1e-12) + 1e-9
        boxes = shapely.box(p[:, 0] - r, p[:, 1] - r, p[:, 0] + r, p[:, 1] + r)
        point, seg = self._tree.query(boxes)
        rel = p[point] - self._a[seg]
        d = self._d[seg]
        t = np.clip((rel * d).sum(axis=1) / np.maximum(self._len2[seg], 1e-300), 0.0, 1.0)
        diff = rel - t[:, None] * d
        out = np.array(bound, dtype=np.float64)
        np.minimum.at(out, point, np.hypot(diff[:, 0], diff[:, 1]))
        return out
