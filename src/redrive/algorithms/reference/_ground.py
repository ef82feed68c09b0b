"""Ground estimation for the reference LiDAR detector: a height field on a bird's-eye-view grid.

Two methods, both working on the **lowest z per ground cell** (square cells of ``cell_m``,
typically 1 m), which the detector takes in its one pass over the points
(:func:`._kernels.crop_cell_minima`).

``"grid"`` (the default)
    Ground height of a cell = the lowest point in its 3 × 3 neighbourhood.  A local minimum follows
    sloped and curved ground (KITTI streets rise and fall by a metre or more over 50 m).  Where the
    neighbourhood has no points, or its lowest point sits more than ``max_step_m`` above a robust
    plane (a cell seen only on a car's side or a truck's flank, common beyond ~40 m where HDL-64
    ground rings are 10-20 m apart), the plane is used instead.
``"plane"``
    One plane for the whole sweep, fitted by RANSAC to the cell minima (deterministic: a fixed
    seed) and refined by least squares on its inliers.  Simpler, but one plane misses the
    curvature of real roads; on the KITTI frames it leaks more ground into the obstacles (see
    the detector's module docstring for the numbers).

Both return the ground height per cell of the grid; points are classified by the caller.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.algorithms.reference._kernels import (
    ground_fill,
    ground_sample,
    plane_hypotheses,
    plane_inliers,
    ransac_best,
)

__all__ = ["GroundGrid", "fit_plane", "ground_heights"]

_F32 = npt.NDArray[np.float32]
_F64 = npt.NDArray[np.float64]

#: RANSAC settings for :func:`fit_plane` (hypotheses, inlier band in metres, RNG seed, at most
#: this many sample points scored per hypothesis — an even subsample).
_RANSAC_HYPOTHESES = 32
_RANSAC_MAX_SAMPLES = 800
_RANSAC_INLIER_M = 0.15
_RANSAC_SEED = 0
_RNG = threading.local()


class GroundGrid:
    """A square BEV grid centred on the base_link origin: ``n × n`` cells of ``cell_m``.

    Cell ``(i, j)`` covers x ∈ [-half + i·cell, -half + (i+1)·cell), y likewise with ``j``;
    its flat key is ``i·n + j``.
    """

    def __init__(self, *, half_extent_m: float, cell_m: float) -> None:
        self.cell_m = float(cell_m)
        self.n = int(np.ceil(2.0 * half_extent_m / cell_m))
        self.half_extent_m = 0.5 * self.n * self.cell_m
        c = (np.arange(self.n) + 0.5) * self.cell_m - self.half_extent_m
        cx, cy = np.meshgrid(c, c, indexing="ij")
        cx.flags.writeable = False
        cy.flags.writeable = False
        self._centres = (cx, cy)

    @property
    def crop_m(self) -> float:
        """Points with |x| and |y| below this (metres) are inside the grid, float32 rounding
        included."""
        return self.half_extent_m - 1e-3 * self.cell_m

    def centres(self) -> tuple[_F64, _F64]:
        """(n, n) x and y of the cell centres, metres (read-only)."""
        return self._centres


def _generator() -> np.random.Generator:
    """The RANSAC generator at its seed: made once per thread, its state reset on every use
    (making one costs more than the rest of the hypothesis sampling)."""
    cached: tuple[np.random.Generator, Mapping[str, Any]] | None = getattr(_RNG, "pair", None)
    if cached is None:
        made = np.random.default_rng(_RANSAC_SEED)
        cached = (made, made.bit_generator.state)
        _RNG.pair = cached
    rng, state = cached
    rng.bit_generator.state = state
    return rng


def fit_plane(x: _F64, y: _F64, z: _F64) -> tuple[float, float, float] | None:
    """RANSAC plane ``z = a·x + b·y + c`` through sample points (metres), refined by least
    squares on its inliers; None with fewer than 3 points.  Deterministic (fixed seed)."""
    n = z.size
    if n < 3:
        return None
    tri = _generator().integers(0, n, size=(_RANSAC_HYPOTHESES, 3))
    every = max(1, n // _RANSAC_MAX_SAMPLES)
    xs, ys, zs = x[::every], y[::every], z[::every]
    # Only near-horizontal planes can be ground (normal within ~25° of +z).
    a_h, b_h, c_h = plane_hypotheses(x, y, z, tri)
    if a_h.size == 0:
        a, b, c = 0.0, 0.0, float(np.median(z))
    else:
        best = ransac_best(a_h, b_h, c_h, xs, ys, zs, _RANSAC_INLIER_M)
        a, b, c = float(a_h[best]), float(b_h[best]), float(c_h[best])
    inliers = plane_inliers(x, y, z, a, b, c, _RANSAC_INLIER_M)
    if int(inliers.sum()) >= 3:
        design = np.stack([x[inliers], y[inliers], np.ones(int(inliers.sum()))], axis=1)
        sol = np.linalg.lstsq(design, z[inliers], rcond=None)[0]
        a, b, c = float(sol[0]), float(sol[1]), float(sol[2])
    return a, b, c


def ground_heights(
    grid: GroundGrid,
    minima: _F32,
    *,
    method: str,
    max_step_m: float,
    fallback_z_m: float,
) -> _F32:
    """Ground height per cell, (n, n) float32 metres in base_link.

    Args:
        grid: the ground grid.
        minima: lowest z per cell, (n·n,) float32 (+inf when empty).
        method: ``"grid"`` or ``"plane"`` (see the module docstring).
        max_step_m: ``grid`` only: a local minimum more than this above the plane is not ground.
        fallback_z_m: ground height when nothing can be fitted (fewer than 3 occupied cells).
    """
    low = minima.reshape(grid.n, grid.n)
    cx, cy = grid.centres()
    # The plane is fitted to the cell minima that are local minima of their 3 × 3 neighbourhood:
    # most are ground, few are the flank of a car or a wall.
    local, sx, sy, sz = ground_sample(low, cx, cy, np.float32(0.05))
    plane = fit_plane(sx, sy, sz)
    if plane is None:
        return np.full((grid.n, grid.n), fallback_z_m, dtype=np.float32)
    return ground_fill(local, cx, cy, plane, np.float32(max_step_m), method == "plane")
