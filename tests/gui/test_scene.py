"""The views' numpy side (no Qt): raster cells, decimation, segment clipping, point splats."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("PySide6")  # redrive.gui's package imports need the GUI extra

from redrive.gui.scene import (
    ColorMode,
    RasterSpec,
    decimate,
    project_segments,
    rasterize_top_down,
    splat_points,
)


@pytest.mark.parametrize("mode", list(ColorMode))
def test_raster_cell_of_a_point(mode: ColorMode) -> None:
    """x ahead is up (row 0 = +half extent), y left is left (column 0 = +half extent)."""
    spec = RasterSpec(half_extent_m=10.0, cell_m=1.0)
    xyz = np.array([[8.5, 6.5, 0.0], [-3.5, -2.5, 1.0]], dtype=np.float32)
    out = rasterize_top_down(xyz, mode, spec, intensity=np.array([5.0, 50.0]))
    lit = {(int(r), int(c)) for r, c in zip(*np.nonzero(np.any(out != 24, axis=2)), strict=True)}
    grid = {(r, c) for r, c in lit if 44 in out[r, c]}
    assert lit - grid == {(1, 3), (13, 12)}  # row = 10 − x, column = 10 − y (floored)
    assert out.shape == (20, 20, 3)


def test_height_colours_the_highest_point() -> None:
    spec = RasterSpec(half_extent_m=5.0, cell_m=1.0)
    low = rasterize_top_down(np.array([[0.5, 0.5, -2.0]], np.float32), ColorMode.HEIGHT, spec)
    both = rasterize_top_down(
        np.array([[0.5, 0.5, -2.0], [0.5, 0.5, 3.0]], np.float32), ColorMode.HEIGHT, spec
    )
    high = rasterize_top_down(np.array([[0.5, 0.5, 3.0]], np.float32), ColorMode.HEIGHT, spec)
    assert not np.array_equal(low[4, 4], high[4, 4])
    assert np.array_equal(both[4, 4], high[4, 4])


def test_decimate_keeps_at_most_the_limit_evenly() -> None:
    assert decimate(10, 20) == slice(None)
    idx = decimate(1000, 100)
    assert isinstance(idx, np.ndarray)
    assert len(idx) == 100
    assert idx[0] == 0
    assert np.all(np.diff(idx) == 10)


def test_project_segments_clips_at_the_near_plane() -> None:
    k = np.array([[100.0, 0, 50, 0], [0, 100.0, 50, 0], [0, 0, 1, 0]])  # camera = base, z ahead
    segments = np.array([[0, 0, 5.0], [1, 0, 5.0], [0, 0, -5.0], [0, 0, 10.0]])
    uv = project_segments(k, segments, near_m=1.0)
    assert uv.shape == (4, 2)
    np.testing.assert_allclose(uv[0:2], [[50, 50], [70, 50]])
    np.testing.assert_allclose(uv[2], [50, 50])  # clipped to z = 1 on the optical axis
    behind = project_segments(k, np.array([[0, 0, -1.0], [1, 0, -2.0]]))
    assert len(behind) == 0


def test_splat_colours_the_nearest_point_and_skips_what_is_behind() -> None:
    k = np.array([[100.0, 0, 50, 0], [0, 100.0, 50, 0], [0, 0, 1, 0]])
    image = np.zeros((100, 100, 3), np.uint8)
    pts = np.array([[0, 0, 50.0], [0, 0, 2.0], [0, 0, -3.0]], np.float32)  # far, near, behind
    landed = splat_points(image, k, pts, radius_px=1)
    assert landed == 2
    near_only = np.zeros_like(image)
    splat_points(near_only, k, pts[1:2], radius_px=1)
    assert np.array_equal(image[50, 50], near_only[50, 50])
    assert np.count_nonzero(image.any(axis=2)) == 4  # one 2×2 splat (radius 1)
