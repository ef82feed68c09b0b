"""The closed loop's collision check: the compiled test is the collision metrics' geometry."""

from __future__ import annotations

import math

import numpy as np

from redrive.closedloop._contact_kernels import touching
from redrive.evaluation._kinematics import rectangle_corners, rectangles_overlap
from redrive.sim.ego import EgoGeometry


def _numpy_touching(centers: np.ndarray, sizes: np.ndarray, yaws: np.ndarray) -> list[int]:
    """The numpy check the kernel replaced: the boxes whose centre is within the two
    half-diagonals (a NaN centre is not), through rectangles_overlap."""
    g = EgoGeometry()
    reach = 0.5 * (math.hypot(g.length_m, g.width_m) + np.hypot(sizes[:, 0], sizes[:, 1]))
    near = np.flatnonzero(
        np.hypot(centers[:, 0] - g.center_offset_m, centers[:, 1]) <= reach * (1.0 + 1e-9)
    )
    ego = rectangle_corners((g.center_offset_m, 0.0), 0.0, g.length_m, g.width_m)
    boxes = rectangle_corners(centers[near, :2], yaws[near], sizes[near, 0], sizes[near, 1])
    return near[rectangles_overlap(ego, boxes)].tolist()


def _kernel(centers: np.ndarray, sizes: np.ndarray, yaws: np.ndarray) -> list[int]:
    g = EgoGeometry()
    return touching(centers, sizes, yaws, g.center_offset_m, g.length_m, g.width_m).tolist()


def test_random_boxes_touch_as_the_separating_axis_test_says() -> None:
    rng = np.random.default_rng(3)
    n = 4000
    centers = np.column_stack([rng.uniform(-12, 14, n), rng.uniform(-8, 8, n), np.zeros(n)])
    sizes = np.column_stack([rng.uniform(0.3, 12, n), rng.uniform(0.3, 3, n), np.ones(n)])
    yaws = rng.uniform(-math.pi, math.pi, n)
    expected = _numpy_touching(centers, sizes, yaws)
    assert 0 < len(expected) < n  # some touch, some do not
    g = EgoGeometry()  # the pre-filter skips no box that touches
    ego = rectangle_corners((g.center_offset_m, 0.0), 0.0, g.length_m, g.width_m)
    every = rectangle_corners(centers[:, :2], yaws, sizes[:, 0], sizes[:, 1])
    assert np.flatnonzero(rectangles_overlap(ego, every)).tolist() == expected
    assert _kernel(centers, sizes, yaws) == expected


def test_boxes_just_touching_or_just_apart() -> None:
    g = EgoGeometry()
    front = g.center_offset_m + g.length_m / 2
    # a 4 m box, axis-aligned, its rear exactly at the ego's front bumper, then 1 mm further
    gaps = [0.0, 1e-3, -1e-3]
    centers = np.array([[front + 2.0 + gap, 0.0, 0.0] for gap in gaps])
    sizes = np.tile([4.0, 2.0, 1.5], (len(gaps), 1))
    yaws = np.zeros(len(gaps))
    assert _kernel(centers, sizes, yaws) == _numpy_touching(centers, sizes, yaws) == [0, 2]


def test_nan_and_no_boxes() -> None:
    centers = np.array([[3.0, 0.0, 0.0], [math.nan, 0.0, 0.0]])
    sizes = np.tile([4.0, 2.0, 1.5], (2, 1))
    yaws = np.array([math.nan, 0.0])
    assert _kernel(centers, sizes, yaws) == _numpy_touching(centers, sizes, yaws)
    empty = np.zeros((0, 3))
    assert _kernel(empty, empty, np.zeros(0)) == []
