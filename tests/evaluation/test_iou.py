"""Oriented BEV / 3D IoU: hand-computed cases and shapely as the oracle on random boxes."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from redrive.evaluation.detection.iou import (
    bev_corners,
    bev_intersection_area,
    bev_iou_matrix,
    iou_3d_matrix,
)


def _box(x: float, y: float, length: float, width: float, yaw: float) -> np.ndarray:
    return np.array([[x, y, length, width, yaw]])


def test_axis_aligned_by_hand() -> None:
    # a: 4×2 at the origin; b: 4×2 shifted 1 m along x → overlap 3×2 = 6; union 8 + 8 − 6 = 10
    iou = bev_iou_matrix(_box(0, 0, 4, 2, 0), _box(1, 0, 4, 2, 0))
    assert iou[0, 0] == pytest.approx(0.6, abs=1e-12)
    # contained: 2×1 inside 4×2 → 2 / 8
    iou = bev_iou_matrix(_box(0, 0, 4, 2, 0), _box(0, 0, 2, 1, 0))
    assert iou[0, 0] == pytest.approx(0.25, abs=1e-12)
    # touching edges → 0; apart → 0
    assert bev_iou_matrix(_box(0, 0, 4, 2, 0), _box(4, 0, 4, 2, 0))[0, 0] == 0.0
    assert bev_iou_matrix(_box(0, 0, 4, 2, 0), _box(9, 9, 4, 2, 0))[0, 0] == 0.0


def test_rotated_by_hand() -> None:
    # a 2×2 square and the same square turned 45°: the intersection is a regular octagon with
    # side s where 2 = s + 2·s/√2 → s = 2/(1+√2); area = 2(1+√2)s² = 8/(1+√2) = 8(√2−1)
    inter = 8 * (math.sqrt(2) - 1)
    iou = bev_iou_matrix(_box(0, 0, 2, 2, 0), _box(0, 0, 2, 2, math.pi / 4))
    assert iou[0, 0] == pytest.approx(inter / (8 - inter), abs=1e-12)
    # a 4×2 box and the same box turned 90°: 2×2 square in common; 4 / (8 + 8 − 4)
    iou = bev_iou_matrix(_box(0, 0, 4, 2, 0), _box(0, 0, 4, 2, math.pi / 2))
    assert iou[0, 0] == pytest.approx(4 / 12, abs=1e-12)


def test_yaw_wrap_around_identical() -> None:
    # yaw π−ε and −π+ε differ by 2ε: for ε = 1e-6 the IoU is 1 to ~1e-6
    eps = 1e-6
    iou = bev_iou_matrix(*_box(3, 1, 4.5, 1.9, math.pi - eps), _box(3, 1, 4.5, 1.9, -math.pi + eps))
    assert iou[0, 0] == pytest.approx(1.0, abs=1e-5)
    # yaw π and −π are the same box exactly
    iou = bev_iou_matrix(_box(3, 1, 4.5, 1.9, math.pi), _box(3, 1, 4.5, 1.9, -math.pi))
    assert iou[0, 0] == pytest.approx(1.0, abs=1e-12)


def test_3d_by_hand() -> None:
    # 4×2×2 boxes, the second 1 m forward and 1 m up: BEV 3×2 = 6, heights overlap 1 → 6;
    # volumes 16 + 16 − 6 = 26
    a = np.array([[0.0, 0.0, 0.0, 4.0, 2.0, 2.0, 0.0]])
    iou = iou_3d_matrix(a, a + np.array([[1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0]]))
    assert iou[0, 0] == pytest.approx(6 / 26, abs=1e-12)
    # stacked exactly on top: heights touch → 0
    assert iou_3d_matrix(a, a + np.array([[0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0]]))[0, 0] == 0.0


def test_matrix_shapes_and_empty() -> None:
    b = np.array([[0.0, 0.0, 1.0, 1.0, 0.0]] * 3)
    assert bev_iou_matrix(b, b[:0]).shape == (3, 0)
    np.testing.assert_allclose(bev_iou_matrix(b, b[:2]), np.ones((3, 2)))


coord = st.floats(-5, 5, allow_nan=False)
extent = st.floats(0.05, 6, allow_nan=False)
angle = st.floats(-7, 7, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(coord, coord, extent, extent, angle, coord, coord, extent, extent, angle),
        min_size=1,
        max_size=20,
    )
)
def test_intersection_equals_shapely(boxes: list[tuple[float, ...]]) -> None:
    a = np.array(boxes)
    ca = bev_corners(a[:, 0:5])
    cb = bev_corners(a[:, 5:10])
    ours = bev_intersection_area(ca, cb)
    ref = shapely.area(shapely.intersection(shapely.polygons(ca), shapely.polygons(cb)))
    np.testing.assert_allclose(ours, ref, rtol=1e-9, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.tuples(coord, coord, extent, extent, angle), st.floats(-1, 1), st.floats(-1, 1))
def test_shared_edges_and_corners(box: tuple[float, ...], dx: float, dy: float) -> None:
    """Boxes that share edge directions (the degenerate case of the clipping) against shapely."""
    x, y, length, width, yaw = box
    ca = bev_corners(np.array([[x, y, length, width, yaw]]))
    # same heading, shifted along it by dx·length, narrower or wider: edges collinear or parallel
    sx, sy = x + math.cos(yaw) * dx * length, y + math.sin(yaw) * dx * length
    cb = bev_corners(np.array([[sx, sy, length, width * (1 + dy) / 2 + 0.01, yaw]]))
    ref = shapely.area(shapely.intersection(shapely.polygons(ca), shapely.polygons(cb)))
    np.testing.assert_allclose(bev_intersection_area(ca, cb), ref, rtol=1e-9, atol=1e-9)
