"""Property tests for redrive.geometry.se3."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from redrive.geometry.quaternion import (
    euler_from_quaternion,
    rotation_matrix_from_quaternion,
    yaw_from_quaternion,
)
from redrive.geometry.se3 import (
    compose,
    invert,
    matrix_from_transform,
    normalize_angle,
    quaternion_from_euler,
    quaternion_from_rotation_matrix,
    quaternion_from_yaw,
    rotation_matrix_from_yaw,
    se3_from_rotation_translation,
    transform_from_matrix,
    transform_points,
    transform_vectors,
    yaw_from_rotation_matrix,
)

finite = st.floats(min_value=-100.0, max_value=100.0, allow_nan=False)
angles = st.floats(min_value=-10.0, max_value=10.0, allow_nan=False)


@st.composite
def quaternions(draw: st.DrawFn) -> npt.NDArray[np.float64]:
    q = np.array([draw(st.floats(-1.0, 1.0)) for _ in range(4)])
    if np.linalg.norm(q) < 1e-3:
        q = np.array([0.0, 0.0, 0.0, 1.0])
    out: npt.NDArray[np.float64] = q / np.linalg.norm(q)
    return out


@st.composite
def poses(draw: st.DrawFn) -> npt.NDArray[np.float64]:
    rot = rotation_matrix_from_quaternion(draw(quaternions()))
    return se3_from_rotation_translation(rot, [draw(finite) for _ in range(3)])


@st.composite
def clouds(draw: st.DrawFn) -> npt.NDArray[np.float64]:
    n = draw(st.integers(0, 20))
    return np.array([[draw(finite) for _ in range(3)] for _ in range(n)]).reshape(n, 3)


@given(poses(), clouds())
def test_inverse_undoes_transform(
    dst_from_src: npt.NDArray[np.float64], pts: npt.NDArray[np.float64]
) -> None:
    back = transform_points(invert(dst_from_src), transform_points(dst_from_src, pts))
    np.testing.assert_allclose(back, pts, atol=1e-9)


@given(poses())
def test_compose_with_inverse_is_identity(pose: npt.NDArray[np.float64]) -> None:
    np.testing.assert_allclose(compose(pose, invert(pose)), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(invert(pose), np.linalg.inv(pose), atol=1e-9)


@given(poses(), poses(), clouds())
def test_compose_is_sequential_application(
    a_from_b: npt.NDArray[np.float64],
    b_from_c: npt.NDArray[np.float64],
    pts: npt.NDArray[np.float64],
) -> None:
    direct = transform_points(compose(a_from_b, b_from_c), pts)
    stepwise = transform_points(a_from_b, transform_points(b_from_c, pts))
    np.testing.assert_allclose(direct, stepwise, atol=1e-9)


@given(quaternions())
def test_quaternion_matrix_round_trip(q: npt.NDArray[np.float64]) -> None:
    back = quaternion_from_rotation_matrix(rotation_matrix_from_quaternion(q))
    # q and -q are the same rotation; the result has w >= 0
    sign = 1.0 if q[3] >= 0 else -1.0
    if abs(q[3]) < 1e-9:
        sign = float(np.sign(np.dot(back, q))) or 1.0
    np.testing.assert_allclose(back, sign * q, atol=1e-9)
    assert back[3] >= 0.0


@given(angles)
def test_yaw_round_trips(yaw_rad: float) -> None:
    expected = normalize_angle(yaw_rad)
    got_q = yaw_from_quaternion(quaternion_from_yaw(yaw_rad))
    got_m = yaw_from_rotation_matrix(rotation_matrix_from_yaw(yaw_rad))
    for got in (got_q, got_m):
        assert abs(normalize_angle(got - expected)) < 1e-9
    np.testing.assert_allclose(
        rotation_matrix_from_quaternion(quaternion_from_yaw(yaw_rad)),
        rotation_matrix_from_yaw(yaw_rad),
        atol=1e-12,
    )


@given(st.floats(min_value=-1e4, max_value=1e4, allow_nan=False))
def test_normalize_angle_range(angle_rad: float) -> None:
    out = normalize_angle(angle_rad)
    assert -math.pi <= out < math.pi
    assert abs(math.sin(out) - math.sin(angle_rad)) < 1e-6
    assert abs(math.cos(out) - math.cos(angle_rad)) < 1e-6


@settings(max_examples=50)
@given(poses())
def test_transform_matrix_round_trip(pose: npt.NDArray[np.float64]) -> None:
    tf = transform_from_matrix(pose, parent_frame="map", child_frame="lidar", stamp_ns=5)
    assert (tf.parent_frame, tf.child_frame, tf.stamp_ns) == ("map", "lidar", 5)
    np.testing.assert_allclose(matrix_from_transform(tf), pose, atol=1e-9)
    np.testing.assert_allclose(tf.matrix, pose, atol=1e-9)


def test_float32_points_stay_float32_and_precise() -> None:
    pts = np.array([[1.0, 2.0, 3.0], [-4.5, 0.25, 8.0]], dtype=np.float32)
    pose = se3_from_rotation_translation(rotation_matrix_from_yaw(math.pi / 2), [1e5, 0.0, 0.0])
    out = transform_points(pose, pts)
    assert out.dtype == np.float32
    assert out.flags.c_contiguous
    np.testing.assert_allclose(out, [[1e5 - 2.0, 1.0, 3.0], [1e5 - 0.25, -4.5, 8.0]], rtol=1e-7)
    back = transform_points(invert(pose), out.astype(np.float64))
    np.testing.assert_allclose(back, pts, atol=1e-2)


def test_vectors_ignore_translation() -> None:
    pose = se3_from_rotation_translation(rotation_matrix_from_yaw(math.pi), [5.0, 5.0, 5.0])
    np.testing.assert_allclose(
        transform_vectors(pose, [1.0, 0.0, 0.0]), [-1.0, 0.0, 0.0], atol=1e-12
    )


def test_bad_shapes_are_rejected() -> None:
    with pytest.raises(ValueError, match="4x4"):
        invert(np.eye(3))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        transform_points(np.eye(4), np.zeros((4, 4)))
    assert np.array_equal(compose(), np.eye(4))


@given(st.floats(-3.1, 3.1), st.floats(-1.5, 1.5), st.floats(-3.1, 3.1))
def test_euler_round_trip(roll_rad: float, pitch_rad: float, yaw_rad: float) -> None:
    got = euler_from_quaternion(quaternion_from_euler(roll_rad, pitch_rad, yaw_rad))
    np.testing.assert_allclose(got, (roll_rad, pitch_rad, yaw_rad), atol=1e-7)
    q = quaternion_from_euler(0.0, 0.0, yaw_rad)
    np.testing.assert_allclose(q, quaternion_from_yaw(yaw_rad), atol=1e-15)
