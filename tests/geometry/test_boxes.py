"""Tests for redrive.geometry.boxes and projection."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from hypothesis import given
from hypothesis import strategies as st

from redrive.geometry.boxes import box_corners, points_in_box, transform_box, transform_object
from redrive.geometry.projection import project_points
from redrive.geometry.quaternion import rotation_matrix_from_quaternion
from redrive.geometry.se3 import (
    invert,
    normalize_angle,
    rotation_matrix_from_yaw,
    se3_from_rotation_translation,
    transform_points,
)
from redrive.types import Box3D, DetectedObject, ObjectClass

finite = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False)
sizes = st.floats(min_value=0.1, max_value=20.0, allow_nan=False)
yaws = st.floats(min_value=-4.0, max_value=4.0, allow_nan=False)


@st.composite
def boxes(draw: st.DrawFn) -> Box3D:
    return Box3D(
        center=np.array([draw(finite) for _ in range(3)]),
        size=np.array([draw(sizes) for _ in range(3)]),
        yaw_rad=draw(yaws),
    )


@st.composite
def planar_poses(draw: st.DrawFn) -> npt.NDArray[np.float64]:
    """Poses that keep +z up (yaw only): boxes stay exactly upright."""
    return se3_from_rotation_translation(
        rotation_matrix_from_yaw(draw(yaws)), [draw(finite) for _ in range(3)]
    )


@given(boxes(), planar_poses())
def test_transform_box_inverse_is_identity(
    box: Box3D, dst_from_src: npt.NDArray[np.float64]
) -> None:
    back = transform_box(invert(dst_from_src), transform_box(dst_from_src, box))
    np.testing.assert_allclose(back.center, box.center, atol=1e-9)
    np.testing.assert_array_equal(back.size, box.size)
    assert abs(normalize_angle(back.yaw_rad - box.yaw_rad)) < 1e-9


@given(boxes(), planar_poses())
def test_corners_move_with_the_box(box: Box3D, dst_from_src: npt.NDArray[np.float64]) -> None:
    moved = box_corners(transform_box(dst_from_src, box))
    np.testing.assert_allclose(moved, transform_points(dst_from_src, box_corners(box)), atol=1e-9)


@given(boxes(), planar_poses())
def test_membership_is_frame_independent(box: Box3D, dst_from_src: npt.NDArray[np.float64]) -> None:
    rng = np.random.default_rng(0)
    pts = box.center + rng.uniform(-1.0, 1.0, size=(200, 3)) * box.size
    inside = points_in_box(pts, box)
    moved = points_in_box(transform_points(dst_from_src, pts), transform_box(dst_from_src, box))
    # Points right on a face may flip by rounding; none of the random ones is that close.
    assert np.array_equal(inside, moved)


def test_corners_and_membership_of_a_known_box() -> None:
    box = Box3D(
        center=np.array([10.0, 0.0, 1.0]), size=np.array([4.0, 2.0, 1.5]), yaw_rad=math.pi / 2
    )
    corners = box_corners(box)
    assert corners.shape == (8, 3)
    np.testing.assert_allclose(corners[0], [9.0, 2.0, 0.25], atol=1e-12)  # front-left bottom
    np.testing.assert_allclose(corners[6], [11.0, -2.0, 1.75], atol=1e-12)  # rear-right top
    assert points_in_box(corners, box, margin_m=1e-9).all()  # faces count, up to rounding
    pts = np.array([[10.0, 1.9, 1.0], [11.1, 0.0, 1.0], [10.0, 0.0, 1.8], [10.0, 0.0, 1.0]])
    assert points_in_box(pts, box).tolist() == [True, False, False, True]
    assert points_in_box(pts, box, margin_m=0.2).tolist() == [True, True, True, True]
    assert points_in_box(pts.astype(np.float32), box).dtype == np.bool_


def test_tilted_transform_keeps_box_upright() -> None:
    # camera-like frame (z forward, x right, y down) → lidar-like frame (x forward, z up)
    lidar_from_cam = se3_from_rotation_translation(
        np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]), [0.3, 0.0, -0.1]
    )
    # in the camera frame, heading is about -y (up); yaw there is about +z (optical axis)
    box = Box3D(center=np.array([1.0, 0.5, 10.0]), size=np.array([4.0, 2.0, 1.5]), yaw_rad=0.0)
    out = transform_box(lidar_from_cam, box)
    np.testing.assert_allclose(out.center, [10.3, -1.0, -0.6], atol=1e-12)
    assert abs(normalize_angle(out.yaw_rad - (-math.pi / 2))) < 1e-12


def test_transform_object_rotates_velocity() -> None:
    obj = DetectedObject(
        object_id=3,
        object_class=ObjectClass.VEHICLE,
        box=Box3D(center=np.array([1.0, 0.0, 0.0]), size=np.array([1.0, 1.0, 1.0]), yaw_rad=0.1),
        velocity=np.array([1.0, 0.0, 0.0]),
        orientation=np.array([0.1, 0.0, 0.0]),
    )
    pose = se3_from_rotation_translation(rotation_matrix_from_yaw(math.pi / 2), [0.0, 0.0, 2.0])
    out = transform_object(pose, obj)
    np.testing.assert_allclose(out.box.center, [0.0, 1.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(out.velocity, [0.0, 1.0, 0.0], atol=1e-12)
    assert abs(out.box.yaw_rad - (0.1 + math.pi / 2)) < 1e-12
    assert abs(out.orientation[0] - (0.1 + math.pi / 2)) < 1e-12
    assert out.object_id == 3


def test_project_points() -> None:
    intrinsics = np.array([[100.0, 0.0, 50.0], [0.0, 100.0, 40.0], [0.0, 0.0, 1.0]])
    pts = np.array([[0.0, 0.0, 2.0], [1.0, -1.0, 2.0], [0.0, 0.0, -1.0]])
    uv, depth = project_points(intrinsics, pts)
    np.testing.assert_allclose(uv[:2], [[50.0, 40.0], [100.0, -10.0]])
    assert np.isnan(uv[2]).all()
    np.testing.assert_allclose(depth, [2.0, 2.0, -1.0])
    q = rotation_matrix_from_quaternion([0.0, 0.0, 0.0, 1.0])
    assert np.array_equal(q, np.eye(3))


def test_points_in_a_pitched_and_rolled_box() -> None:
    from scipy.spatial.transform import Rotation

    from redrive.geometry import yaw_pitch_roll_from_rotation_matrices

    rng = np.random.default_rng(3)
    yaw, pitch, roll = 0.7, 0.05, -0.08
    rotation = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    np.testing.assert_allclose(
        yaw_pitch_roll_from_rotation_matrices(rotation[None])[0], [yaw, pitch, roll], atol=1e-12
    )
    box = Box3D(center=np.array([4.0, -2.0, 1.0]), size=np.array([6.0, 2.0, 3.0]), yaw_rad=yaw)
    local = rng.uniform(-1.2, 1.2, (2000, 3)) * (box.size / 2)
    world = local @ rotation.T + box.center
    expected = np.all(np.abs(local) <= box.size / 2, axis=1)
    got = points_in_box(world, box, pitch_rad=pitch, roll_rad=roll)
    assert got.tolist() == expected.tolist()
    assert 0 < expected.sum() < len(expected)
    # heading only: the tilt moves points at the box's ends across its faces
    assert (points_in_box(world, box) != expected).sum() > 10


def test_transform_columns_is_the_row_by_row_transform_bit_for_bit() -> None:
    """transform_columns' elementwise angles are normalize_angle's arithmetic on each row (the
    same doubles), its positions and vectors the matrix product; close to transform_object."""
    from redrive.geometry.boxes import transform_columns
    from redrive.types import ObjectColumns

    rng = np.random.default_rng(11)
    n = 37
    columns = ObjectColumns.of(
        object_class=[ObjectClass.VEHICLE] * n,
        center_m=rng.normal(size=(n, 3)) * 40.0,
        size_m=rng.uniform(0.5, 5.0, (n, 3)),
        yaw_rad=np.r_[rng.uniform(-9.0, 9.0, n - 3), [math.pi, -math.pi, 0.0]],
        velocity_mps=rng.normal(size=(n, 3)),
        acceleration_mps2=rng.normal(size=(n, 3)),
        orientation_rad=rng.uniform(-4.0, 4.0, (n, 3)),
    )
    mat = se3_from_rotation_translation(rotation_matrix_from_yaw(2.7), [15.0, -3.0, 0.5])
    got = transform_columns(mat, columns)
    rot = mat[:3, :3]
    yaws = columns.yaw_rad.tolist()
    heading = np.array([[math.cos(y), math.sin(y), 0.0] for y in yaws]) @ rot.T
    want_yaw = [normalize_angle(math.atan2(hy, hx)) for hx, hy in heading[:, :2].tolist()]
    want_orient = [
        normalize_angle(o + w - y)
        for o, w, y in zip(columns.orientation_rad[:, 0].tolist(), want_yaw, yaws, strict=True)
    ]
    assert got.yaw_rad.tolist() == want_yaw
    assert got.orientation_rad[:, 0].tolist() == want_orient
    assert got.orientation_rad[:, 1:].tolist() == columns.orientation_rad[:, 1:].tolist()
    assert not got.yaw_rad.flags.writeable
    assert not got.center_m.flags.writeable
    for i, obj in enumerate(columns.objects()):
        one = transform_object(mat, obj)
        assert np.allclose(got.center_m[i], one.box.center, atol=1e-9)
        assert math.isclose(got.yaw_rad[i], one.box.yaw_rad, abs_tol=1e-9)
