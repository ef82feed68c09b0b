"""redrive.geometry.quaternion, which the decoders and the tf buffer rely on."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from redrive.geometry.quaternion import (
    euler_from_quaternion,
    quaternion_slerp,
    rotation_matrix_from_quaternion,
    yaw_from_quaternion,
)
from redrive.types import Transform

quaternions = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1
)


@given(q=quaternions)
def test_rotation_matrix_is_orthonormal_and_matches_transform(q: list[float]) -> None:
    rot = rotation_matrix_from_quaternion(q)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rot) == pytest.approx(1.0)
    np.testing.assert_allclose(
        rot,
        Transform(parent_frame="a", child_frame="b", rotation=np.array(q)).matrix[:3, :3],
        atol=1e-12,
    )


@given(q=quaternions)
@example(q=[1.0, 0.0, 1.0, 0.0])  # gimbal lock, pitch -90°
@example(q=[-0.2090, 0.6755, 0.2090, 0.6755])  # yaw 0.6 then pitch +90°: gimbal lock
@example(q=[1.0, 0.0, 1.0, 1e-06])  # just off the lock: roll and yaw are ill-conditioned there
@example(q=[1.0, 0.0, 0.99999, 0.0])  # sin(pitch) 2.5e-11 from the lock: no longer snapped to it
def test_euler_angles_rebuild_the_rotation(q: list[float]) -> None:
    roll, pitch, yaw = euler_from_quaternion(q)
    cr, sr, cp, sp, cy, sy = (
        math.cos(roll),
        math.sin(roll),
        math.cos(pitch),
        math.sin(pitch),
        math.cos(yaw),
        math.sin(yaw),
    )
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    # 1e-5: within ~1e-10 of gimbal lock, atan2 of two near-zero terms leaves ~1e-6 in the matrix
    np.testing.assert_allclose(rz @ ry @ rx, rotation_matrix_from_quaternion(q), atol=1e-5)


@given(yaw=st.floats(-math.pi + 1e-6, math.pi))
def test_yaw_round_trip(yaw: float) -> None:
    assert yaw_from_quaternion([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]) == pytest.approx(
        yaw, abs=1e-9
    )


@given(a=st.floats(-3.0, 3.0), b=st.floats(-3.0, 3.0), t=st.floats(0.0, 1.0))
def test_slerp_about_one_axis_interpolates_the_angle(a: float, b: float, t: float) -> None:
    qa = [0.0, 0.0, math.sin(a / 2), math.cos(a / 2)]
    qb = [0.0, 0.0, math.sin(b / 2), math.cos(b / 2)]
    delta = math.remainder(b - a, 2 * math.pi)  # shortest arc
    expected = math.remainder(a + t * delta, 2 * math.pi)
    got = yaw_from_quaternion(quaternion_slerp(qa, qb, t))
    assert math.remainder(got - expected, 2 * math.pi) == pytest.approx(0.0, abs=1e-6)


def test_bad_quaternion_is_rejected() -> None:
    with pytest.raises(ValueError, match="not a usable quaternion"):
        rotation_matrix_from_quaternion([0.0, 0.0, 0.0, 0.0])
