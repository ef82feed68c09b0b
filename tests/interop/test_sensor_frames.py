"""The sensor frames an export places on ``base_link`` (``interop/sensor_frames.py``): the
sensor map's location, else the log's ``/tf`` mount, else the identity — never a second parent."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from redrive.assembly.sensor_map import SensorMapOverrides
from redrive.interop.sensor_frames import sensor_mount_transforms
from redrive.io import open_log
from redrive.types import Transform

_T0_NS = 1_600_000_000_000_000_000


def _bag(path: Path, *, mount_on_tf: bool) -> Path:
    """0.5 s of a LiDAR in frame ``lidar`` at 10 Hz; with ``mount_on_tf`` a 50 Hz ``/tf`` that
    holds ``base_link → lidar`` (1.2, 0, 1.8), turned 90° about z."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    # tf2_msgs is not in rosbags' ROS 1 store: its one-line definition, as rosbag embeds it
    definition = "geometry_msgs/TransformStamped[] transforms"
    ts.register(get_types_from_msg(definition, "tf2_msgs/msg/TFMessage"))
    g = ts.types
    field = g["sensor_msgs/msg/PointField"]
    fields = [
        field(name=n, offset=o, datatype=7, count=1) for n, o in (("x", 0), ("y", 4), ("z", 8))
    ]
    points = np.array([[5.0, 0.0, 0.0], [6.0, 1.0, 0.5]], dtype=np.float32)
    with Writer(path) as bag:
        lidar = bag.add_connection("/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
        tf = bag.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
        for step in range(25):
            t_ns = _T0_NS + step * 20_000_000
            stamp = g["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
            if mount_on_tf:
                mount = g["geometry_msgs/msg/TransformStamped"](
                    header=g["std_msgs/msg/Header"](seq=step, stamp=stamp, frame_id="base_link"),
                    child_frame_id="lidar",
                    transform=g["geometry_msgs/msg/Transform"](
                        translation=g["geometry_msgs/msg/Vector3"](x=1.2, y=0.0, z=1.8),
                        rotation=g["geometry_msgs/msg/Quaternion"](
                            x=0.0, y=0.0, z=math.sin(math.pi / 4), w=math.cos(math.pi / 4)
                        ),
                    ),
                )
                message = g["tf2_msgs/msg/TFMessage"](transforms=[mount])
                bag.write(tf, t_ns, ts.serialize_ros1(message, "tf2_msgs/msg/TFMessage"))
            if step % 5 == 0:
                cloud = g["sensor_msgs/msg/PointCloud2"](
                    header=g["std_msgs/msg/Header"](seq=step, stamp=stamp, frame_id="lidar"),
                    height=1,
                    width=len(points),
                    fields=fields,
                    is_bigendian=False,
                    point_step=12,
                    row_step=12 * len(points),
                    data=np.frombuffer(points.tobytes(), dtype=np.uint8),
                    is_dense=True,
                )
                data = ts.serialize_ros1(cloud, "sensor_msgs/msg/PointCloud2")
                bag.write(lidar, t_ns + 5_000_000, data)
    return path


def _one(found: tuple[Transform, ...]) -> Transform:
    (tf,) = found
    assert (tf.parent_frame, tf.child_frame) == ("base_link", "lidar")
    return tf


def test_the_tf_mount_is_given_when_the_export_leaves_tf_out(tmp_path: Path) -> None:
    with open_log(_bag(tmp_path / "tf.bag", mount_on_tf=True)) as log:
        tf = _one(sensor_mount_transforms(log, static=(), log_tf_kept=False))
        assert tf.translation.tolist() == pytest.approx([1.2, 0.0, 1.8])
        assert tf.rotation.tolist() == pytest.approx(
            [0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)]
        )
        # the log's /tf, kept in the export, places it itself: no second parent
        assert sensor_mount_transforms(log, static=(), log_tf_kept=True) == ()
        # a sensor map's location is what the run used first
        overrides = SensorMapOverrides(
            sensors={"lidar": {"topic": "/points", "type": "lidar", "location": [0.5, 0.0, 2.0]}}
        )
        tf = _one(sensor_mount_transforms(log, static=(), log_tf_kept=False, overrides=overrides))
        assert tf.translation.tolist() == [0.5, 0.0, 2.0]
        assert tf.rotation.tolist() == [0.0, 0.0, 0.0, 1.0]
        # a static transform of the log connects it: nothing added, whatever the sensor map says
        static = (Transform(parent_frame="base_link", child_frame="lidar"),)
        assert sensor_mount_transforms(log, static=static, log_tf_kept=False) == ()


def test_without_a_mount_the_identity_is_given_and_said(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    bag = _bag(tmp_path / "bare.bag", mount_on_tf=False)
    with open_log(bag) as log, caplog.at_level(logging.WARNING, "redrive.interop.sensor_frames"):
        tf = _one(sensor_mount_transforms(log, static=(), log_tf_kept=False))
    assert tf.translation.tolist() == [0.0, 0.0, 0.0]
    assert tf.rotation.tolist() == [0.0, 0.0, 0.0, 1.0]
    (said,) = [r.getMessage() for r in caplog.records]
    assert "'lidar'" in said
    assert "identity assumed" in said
