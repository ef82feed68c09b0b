"""Clustering of above-ground LiDAR points by connected components of a bird's-eye-view grid.

The points are binned into square cells of ``cell_m`` in x-y; the occupied cells are joined into
8-connected components (union-find over the occupied cells only, a numba kernel in
:mod:`._kernels`; components numbered in raster order of their first cell, as
:func:`scipy.ndimage.label` numbers them); a point's cluster is its cell's component.

How this relates to Euclidean clustering (PCL's ``EuclideanClusterExtraction``, single linkage
with tolerance r): two points closer than ``cell_m`` in x-y always land in the same or in
8-adjacent cells, so they always share a cluster — like Euclidean clustering with r = ``cell_m``.
Two points in adjacent cells may be up to 2·√2·``cell_m`` apart, so some pairs up to that distance
are linked too: the grid is Euclidean clustering with a tolerance between ``cell_m`` and
2.83·``cell_m`` depending on where the points fall in their cells.  It also ignores z, so an object
under an overhang (a car under a tree) joins it; the caller limits z to a band above the ground.
In exchange it costs one pass over the points and their occupied cells instead of a k-d tree
build and a radius search over all points.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.algorithms.reference._kernels import label_clusters

__all__ = ["Clusters", "cluster_points"]

#: per-thread scratch grids of :func:`label_clusters` (two detectors may run in two threads)
_SCRATCH = threading.local()


@dataclass(frozen=True, slots=True, kw_only=True)
class Clusters:
    """Point clusters, points sorted by cluster.

    Attributes:
        index: (M,) indices into the caller's point arrays, grouped by cluster.
        starts: (K,) position in ``index`` where each cluster begins (increasing, first 0).
        counts: (K,) points per cluster (all within the caller's [min, max]).
    """

    index: npt.NDArray[np.intp]
    starts: npt.NDArray[np.intp]
    counts: npt.NDArray[np.intp]


def cluster_points(
    x: npt.NDArray[np.float32],
    y: npt.NDArray[np.float32],
    *,
    half_extent_m: float,
    cell_m: float,
    min_points: int,
    max_points: int,
    tall_xy: tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]] | None = None,
) -> Clusters:
    """Group points (metres; all strictly within ±``half_extent_m`` in x and y) into BEV-connected clusters
    of ``min_points`` … ``max_points`` points.

    ``tall_xy`` are the x, y of points above the caller's height band: a cluster with one of them
    in its cells is the lower part of something taller (a façade, a tree, a lamp post) and is
    dropped here, before any per-cluster work.
    """
    n = int(np.ceil(2.0 * half_extent_m / cell_m))
    inv = np.float32(1.0 / cell_m)
    half = np.float32(0.5 * n * cell_m)
    scratch = _scratch(n * n)
    empty = np.zeros(0, dtype=np.float32)
    tall_x, tall_y = tall_xy if tall_xy is not None else (empty, empty)
    index, starts, counts = label_clusters(
        np.ascontiguousarray(x, dtype=np.float32),
        np.ascontiguousarray(y, dtype=np.float32),
        np.ascontiguousarray(tall_x, dtype=np.float32),
        np.ascontiguousarray(tall_y, dtype=np.float32),
        half,
        inv,
        n,
        min_points,
        max_points,
        scratch,
    )
    return Clusters(
        index=index.astype(np.intp, copy=False),
        starts=starts.astype(np.intp, copy=False),
        counts=counts.astype(np.intp, copy=False),
    )


def _scratch(size: int) -> npt.NDArray[np.int64]:
    """A grid of -1 of ``size`` cells for :func:`label_clusters`, one per thread and size (the
    kernel leaves it as it found it)."""
    cache: dict[int, npt.NDArray[np.int64]] = _SCRATCH.__dict__.setdefault("grids", {})
    grid = cache.get(size)
    if grid is None:
        grid = np.full(size, -1, dtype=np.int64)
        cache[size] = grid
    return grid
