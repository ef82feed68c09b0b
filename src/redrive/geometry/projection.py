"""Pinhole projection of 3D points with a 3×4 camera matrix (``P @ [x y z 1]ᵀ``)."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["project_points"]


def project_points(
    image_from_src: npt.ArrayLike, points: npt.NDArray[Any]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Project (N, 3) points of ``src`` into an image.

    Args:
        image_from_src: 3×4 projection matrix (e.g. KITTI ``P2 @ R0_rect @ Tr_velo_to_cam``), or
            3×3 intrinsics for points already in the camera frame.
        points: (N, 3) metres in ``src``.

    Returns:
        ``(uv_px, depth_m)``: (N, 2) pixel coordinates (column, row) and (N,) depth along the
        optical axis.  Points with depth ≤ 0 are behind the camera; their ``uv_px`` is NaN.
    """
    mat = np.asarray(image_from_src, dtype=np.float64)
    if mat.shape == (3, 3):
        mat = np.hstack([mat, np.zeros((3, 1))])
    if mat.shape != (3, 4):
        msg = f"project_points: expected a 3x4 (or 3x3) matrix, got shape {mat.shape}"
        raise ValueError(msg)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        msg = f"project_points: points must have shape (N, 3), got {pts.shape}"
        raise ValueError(msg)
    homog = pts @ mat[:, :3].T + mat[:, 3]
    depth = homog[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = homog[:, :2] / depth[:, None]
    uv[depth <= 0.0] = np.nan
    return uv, depth
