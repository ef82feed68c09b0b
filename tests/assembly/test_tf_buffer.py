"""TransformBuffer: frame tree, interpolation, tolerances, bounded memory."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from redrive.assembly.tf_buffer import TransformBuffer, TransformLookupError
from redrive.errors import LogError, RedriveError
from redrive.types import Transform

S = 1_000_000_000


def _yaw_q(yaw_rad: float) -> np.ndarray:
    return np.array([0.0, 0.0, math.sin(yaw_rad / 2), math.cos(yaw_rad / 2)])


def _tf(
    parent: str,
    child: str,
    xyz: tuple[float, float, float],
    yaw_rad: float = 0.0,
    stamp_ns: int = 0,
) -> Transform:
    return Transform(
        parent_frame=parent,
        child_frame=child,
        translation=np.array(xyz),
        rotation=_yaw_q(yaw_rad),
        stamp_ns=stamp_ns,
    )


def _buffer() -> TransformBuffer:
    tf = TransformBuffer()
    tf.add(_tf("base_link", "lidar", (1.0, 0.0, 2.0)))  # static (stamp 0)
    tf.add(_tf("base_link", "camera", (2.0, 0.5, 1.5), yaw_rad=-math.pi / 2), static=True)
    tf.add(_tf("map", "odom", (100.0, 0.0, 0.0), stamp_ns=5), static=True)
    tf.add(_tf("odom", "base_link", (0.0, 0.0, 0.0), 0.0, stamp_ns=10 * S))
    tf.add(_tf("odom", "base_link", (10.0, 0.0, 0.0), math.pi / 2, stamp_ns=11 * S))
    return tf


def test_lookup_through_the_tree_with_interpolation() -> None:
    tf = _buffer()
    map_from_lidar = tf.lookup("map", "lidar", 10 * S + S // 2)
    yaw = math.pi / 4  # slerp midway
    expected = np.array([105.0 + math.cos(yaw), math.sin(yaw), 2.0])
    np.testing.assert_allclose(map_from_lidar[:3, 3], expected, atol=1e-12)
    np.testing.assert_allclose(map_from_lidar[:2, 0], [math.cos(yaw), math.sin(yaw)], atol=1e-12)
    exact = tf.lookup("odom", "base_link", 11 * S)
    np.testing.assert_allclose(
        exact, _tf("odom", "base_link", (10.0, 0.0, 0.0), math.pi / 2).matrix, atol=1e-12
    )


def test_lookup_between_siblings_and_inverse() -> None:
    tf = _buffer()
    camera_from_lidar = tf.lookup("camera", "lidar", 0)  # static path: any stamp
    point_in_lidar = np.array([0.0, 0.0, 0.0, 1.0])
    # lidar origin in base_link is (1, 0, 2); camera at (2, 0.5, 1.5) yawed -90°
    np.testing.assert_allclose(
        camera_from_lidar @ point_in_lidar, [0.5, -1.0, 0.5, 1.0], atol=1e-12
    )
    lidar_from_camera = tf.lookup("lidar", "camera", 0)
    np.testing.assert_allclose(lidar_from_camera @ camera_from_lidar, np.eye(4), atol=1e-12)
    np.testing.assert_array_equal(tf.lookup("lidar", "/lidar", 0), np.eye(4))
    np.testing.assert_allclose(tf.lookup("/map", "/odom", 0), tf.lookup("map", "odom", 0))


def test_stamp_tolerance_and_errors() -> None:
    tf = _buffer()
    np.testing.assert_allclose(
        tf.lookup("odom", "base_link", 11 * S + 40_000_000)[:3, 3], [10.0, 0.0, 0.0]
    )
    with pytest.raises(TransformLookupError, match="outside") as info:
        tf.lookup("odom", "base_link", 11 * S + 60_000_000)
    assert isinstance(info.value, LogError)
    assert isinstance(info.value, LookupError)
    assert isinstance(info.value, RedriveError)
    with pytest.raises(TransformLookupError, match="outside"):
        tf.lookup("map", "lidar", 9 * S)
    tf.add(_tf("world", "gps", (0.0, 0.0, 0.0)))
    with pytest.raises(TransformLookupError, match="no transform path"):
        tf.lookup("gps", "lidar", 10 * S)
    with pytest.raises(TransformLookupError, match="no transform path"):
        tf.lookup("nowhere", "lidar", 10 * S)


def test_memory_is_bounded_by_the_window() -> None:
    tf = TransformBuffer(window_ns=2 * S, tolerance_ns=0)
    for i in range(1000):
        tf.add(_tf("odom", "base_link", (float(i), 0.0, 0.0), stamp_ns=i * S // 10))
    edge = tf._edges["base_link"]
    assert len(edge.samples) == 21  # 2 s at 10 Hz, both ends included
    with pytest.raises(TransformLookupError):
        tf.lookup("odom", "base_link", 90 * S)
    np.testing.assert_allclose(
        tf.lookup("odom", "base_link", 99 * S + S // 20)[:3, 3], [990.5, 0.0, 0.0]
    )


def test_out_of_order_and_duplicate_samples() -> None:
    tf = TransformBuffer(tolerance_ns=0)
    tf.add(_tf("a", "b", (2.0, 0.0, 0.0), stamp_ns=2 * S))
    tf.add(_tf("a", "b", (0.0, 0.0, 0.0), stamp_ns=S))
    tf.add(_tf("a", "b", (4.0, 0.0, 0.0), stamp_ns=2 * S))  # replaces
    assert tf.lookup("a", "b", S + S // 2)[0, 3] == pytest.approx(2.0)
    assert tf.frames == {"a", "b"}


@settings(max_examples=50, deadline=None)
@given(
    yaws=st.lists(st.floats(-3.1, 3.1), min_size=3, max_size=3),
    xs=st.lists(st.floats(-50, 50), min_size=3, max_size=3),
)
def test_chain_composition_property(yaws: list[float], xs: list[float]) -> None:
    tf = TransformBuffer()
    frames = ["map", "odom", "base_link", "lidar"]
    matrices = []
    for parent, child, yaw, x in zip(frames, frames[1:], yaws, xs, strict=False):
        t = _tf(parent, child, (x, -x / 2, 0.3), yaw)
        tf.add(t)
        matrices.append(t.matrix)
    expected = matrices[0] @ matrices[1] @ matrices[2]
    np.testing.assert_allclose(tf.lookup("map", "lidar", 123), expected, atol=1e-9)
    np.testing.assert_allclose(tf.lookup("lidar", "map", 123) @ expected, np.eye(4), atol=1e-9)


def test_static_lookups_are_reused_until_a_static_transform_or_the_tree_changes() -> None:
    buf = TransformBuffer()
    buf.add(_tf("base_link", "lidar", (1.0, 0.0, 2.0)))  # static (stamp 0)
    buf.add(_tf("map", "base_link", (10.0, 0.0, 0.0), stamp_ns=100))  # dynamic
    buf.add(_tf("map", "base_link", (20.0, 0.0, 0.0), stamp_ns=200))
    first = buf.lookup("base_link", "lidar", 150)
    first[0, 3] = 99.0  # a caller's copy: the next lookup is not changed by it
    assert buf.lookup("base_link", "lidar", 0)[:3, 3].tolist() == [1.0, 0.0, 2.0]
    buf.add(_tf("map", "base_link", (30.0, 0.0, 0.0), stamp_ns=300))  # a dynamic sample
    assert buf.lookup("base_link", "lidar", 0)[:3, 3].tolist() == [1.0, 0.0, 2.0]
    # a path with a dynamic edge is looked up at its stamp every time
    assert buf.lookup("map", "lidar", 150)[:3, 3].tolist() == pytest.approx([16.0, 0.0, 2.0])
    assert buf.lookup("map", "lidar", 250)[:3, 3].tolist() == pytest.approx([26.0, 0.0, 2.0])
    buf.add(_tf("base_link", "lidar", (1.5, 0.0, 2.0)))  # the static transform changed
    assert buf.lookup("base_link", "lidar", 0)[:3, 3].tolist() == [1.5, 0.0, 2.0]
    buf.add(_tf("base_link", "lidar", (1.5, 0.0, 2.0), stamp_ns=400))  # now a dynamic edge
    buf.add(_tf("base_link", "lidar", (2.5, 0.0, 2.0), stamp_ns=500))
    assert buf.lookup("base_link", "lidar", 450)[:3, 3].tolist() == pytest.approx([2.0, 0.0, 2.0])
    buf.add(_tf("mount", "lidar", (0.0, 1.0, 0.0)))  # re-attached to another parent
    buf.add(_tf("base_link", "mount", (0.0, 0.0, 1.0)))
    assert buf.lookup("base_link", "lidar", 0)[:3, 3].tolist() == [0.0, 1.0, 1.0]
