"""Decoders on real logs from ../shared/data, read straight with rosbags (skipped when absent)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image as PILImage
from rosbags.rosbag1 import Reader as Reader1
from rosbags.rosbag2 import Reader as Reader2

from redrive.assembly.tf_buffer import TransformBuffer, TransformLookupError
from redrive.io.base import LogMessage
from redrive.io.ros.decoders import Deserialize, decode, decoder_for
from redrive.io.ros.typestore import typestore_for
from redrive.types import GnssFix, Image, Imu, PointCloud, SensorType, VehicleState

pytestmark = pytest.mark.shared_data


def ros1_messages(
    path: Path, topics: set[str] | None = None, *, limit: int | None = None
) -> Iterator[tuple[LogMessage, Deserialize]]:
    """LogMessages of a ROS 1 bag with a deserializer built from its embedded definitions."""
    with Reader1(path) as reader:
        defs = {c.msgtype: ("msg", c.msgdef.data) for c in reader.connections}
        ts, failed = typestore_for(1, defs)
        assert not failed

        def deserialize(message: LogMessage) -> object:
            return ts.deserialize_ros1(message.raw, message.msgtype)

        conns = [c for c in reader.connections if topics is None or c.topic in topics]
        for i, (conn, t_ns, raw) in enumerate(reader.messages(connections=conns)):
            if limit is not None and i >= limit:
                return
            yield (
                LogMessage(
                    topic=conn.topic,
                    msgtype=conn.msgtype,
                    log_time_ns=t_ns,
                    encoding="ros1",
                    raw=raw,
                ),
                deserialize,
            )


def ros2_messages(path: Path) -> Iterator[tuple[LogMessage, Deserialize]]:
    ts, _ = typestore_for(2)

    def deserialize(message: LogMessage) -> object:
        return ts.deserialize_cdr(message.raw, message.msgtype)

    with Reader2(path) as reader:
        for conn, t_ns, raw in reader.messages():
            yield (
                LogMessage(
                    topic=conn.topic,
                    msgtype=conn.msgtype,
                    log_time_ns=t_ns,
                    encoding="cdr",
                    raw=raw,
                ),
                deserialize,
            )


def test_luminar_pointcloud2(shared_data: Path) -> None:
    bag = shared_data / "rosbag1_real" / "embag_luminar_test.bag"
    counts = []
    for message, deserialize in ros1_messages(bag, {"/luminar_pointcloud"}):
        decoded = decode(message, deserialize)
        cloud = decoded.value
        assert isinstance(cloud, PointCloud)
        ref: Any = deserialize(message)
        counts.append(cloud.num_points)
        assert decoded.frame_id == "luminar_lidar"
        assert decoded.stamp_ns == ref.header.stamp.sec * 10**9 + ref.header.stamp.nanosec
        assert cloud.num_points == ref.width * ref.height
        dtype = np.dtype(
            {
                "names": ["x", "y", "z", "intensity", "time_sec", "time_nsec", "laser_id"],
                "formats": ["<f4", "<f4", "<f4", "<f4", "<u4", "<u4", "<u2"],
                "offsets": [0, 4, 8, 16, 20, 24, 28],
                "itemsize": ref.point_step,
            }
        )
        expected = np.frombuffer(ref.data, dtype=dtype)
        np.testing.assert_array_equal(cloud.xyz, np.stack([expected[a] for a in "xyz"], axis=1))
        assert set(cloud.channels) == {"intensity", "time_sec", "time_nsec", "laser_id"}
        assert cloud.channels["laser_id"].dtype == np.uint16
        np.testing.assert_array_equal(cloud.channels["laser_id"], expected["laser_id"])
        np.testing.assert_array_equal(cloud.channels["time_nsec"], expected["time_nsec"])
        assert 150.0 < np.nanmax(np.abs(cloud.xyz[:, 0])) < 250.0  # long-range lidar, ±200 m
    assert counts == [35707, 36055, 36267, 36457, 36336]


def test_luminar_bag_laserscan_and_odometry(shared_data: Path) -> None:
    bag = shared_data / "rosbag1_real" / "embag_luminar_test.bag"
    scans = odoms = 0
    for message, deserialize in ros1_messages(bag, {"/base_scan", "/base_pose_ground_truth"}):
        decoded = decode(message, deserialize)
        ref: Any = deserialize(message)
        if message.topic == "/base_scan":
            scans += 1
            cloud = decoded.value
            assert isinstance(cloud, PointCloud)
            assert cloud.num_points == len(ref.ranges) == 90
            np.testing.assert_array_equal(cloud.channels["range"], ref.ranges)
            valid = ~np.isnan(cloud.xyz[:, 0])
            r = np.hypot(cloud.xyz[valid, 0], cloud.xyz[valid, 1])
            np.testing.assert_allclose(r, np.asarray(ref.ranges)[valid], rtol=1e-5)
            assert np.all(r <= ref.range_max + 1e-5)
        else:
            odoms += 1
            state = decoded.value
            assert isinstance(state, VehicleState)
            assert state.position[0] == pytest.approx(1.0)
            assert state.frame_id == ref.header.frame_id
    assert (scans, odoms) == (5, 5)


def test_husky_imu_odometry_navsatfix(shared_data: Path) -> None:
    bag = shared_data / "rosbag1_real" / "robot_localization_test1_husky.bag"
    seen: dict[str, int] = {}
    fixes: list[GnssFix] = []
    for message, deserialize in ros1_messages(bag, limit=3000):
        decoded = decode(message, deserialize)
        seen[message.topic] = seen.get(message.topic, 0) + 1
        value = decoded.value
        ref: Any = deserialize(message)
        if message.topic == "/imu/data":
            assert isinstance(value, Imu)
            assert value.linear_acceleration[0] == ref.linear_acceleration.x
            assert value.angular_velocity[2] == ref.angular_velocity.z
            if not np.isnan(value.orientation).any():
                assert np.linalg.norm(value.orientation) == pytest.approx(1.0, abs=1e-3)
        elif message.topic == "/fix":
            assert isinstance(value, GnssFix)
            fixes.append(value)
        else:
            assert isinstance(value, VehicleState)
            assert value.frame_id == ref.header.frame_id
            q = ref.pose.pose.orientation
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
            assert value.heading_rad == pytest.approx(yaw)
            body_speed = math.hypot(ref.twist.twist.linear.x, ref.twist.twist.linear.y)
            assert np.linalg.norm(value.velocity) == pytest.approx(body_speed, abs=1e-9)
        assert decoded.stamp_ns > 1_432_000_000 * 10**9  # 2015-05
    assert set(seen) == {"/imu/data", "/husky_velocity_controller/odom", "/fix"}
    assert fixes
    assert fixes[0].latitude_deg == pytest.approx(42.3758, abs=0.01)
    assert fixes[0].longitude_deg == pytest.approx(-71.1474, abs=0.01)


def test_kitti_bag_against_original_files(shared_data: Path) -> None:
    bag = shared_data / "rosbag1_recorded_here" / "kitti_3frames_rosbag_record_lz4.bag"
    training = shared_data / "kitti_object" / "training"
    bins = [
        np.fromfile(training / "velodyne" / f"00000{i}.bin", dtype=np.float32).reshape(-1, 4)
        for i in range(3)
    ]
    pngs = [
        np.asarray(PILImage.open(training / "image_2" / f"00000{i}.png").convert("RGB"))
        for i in range(3)
    ]
    clouds: list[PointCloud] = []
    images: dict[str, list[Image]] = {"raw": [], "compressed": []}
    for message, deserialize in ros1_messages(bag):
        decoded = decode(message, deserialize)
        if message.msgtype.endswith("PointCloud2"):
            assert decoded.frame_id == "velodyne"
            assert isinstance(decoded.value, PointCloud)
            clouds.append(decoded.value)
        else:
            assert isinstance(decoded.value, Image)
            images["compressed" if "Compressed" in message.msgtype else "raw"].append(decoded.value)
    assert [c.num_points for c in clouds] == [115384, 120268, 126891]
    for cloud, ref_points in zip(clouds, bins, strict=True):
        np.testing.assert_array_equal(cloud.xyz, ref_points[:, :3])
        np.testing.assert_array_equal(cloud.channels["intensity"], ref_points[:, 3])
    for kind in ("raw", "compressed"):
        assert [(im.width, im.height) for im in images[kind]] == [
            (1224, 370),
            (1242, 375),
            (1242, 375),
        ]
        for image, png in zip(images[kind], pngs, strict=True):
            assert image.encoding == "rgb8"
            np.testing.assert_array_equal(image.pixels, png)


@pytest.mark.parametrize("fmt", ["ros1", "ros2"])
def test_evo_tf_into_transform_buffer(shared_data: Path, fmt: str) -> None:
    root = shared_data / "rosbag_fixtures"
    stream = (
        ros1_messages(root / "evo_tf_example.bag")
        if fmt == "ros1"
        else ros2_messages(root / "evo_tf_example_ros2")
    )
    tf = TransformBuffer()
    previous = None
    count = 0
    for message, deserialize in stream:
        decoded = decode(message, deserialize)
        transforms = decoded.value
        assert isinstance(transforms, tuple)
        tf.add_all(transforms)  # type: ignore[arg-type]
        for transform in transforms:
            if message.topic == "/tf_static":
                assert transform.stamp_ns == 0
                continue
            count += 1
            got = tf.lookup("odom", "base_link", transform.stamp_ns)
            np.testing.assert_allclose(got, transform.matrix, atol=1e-12)
            if previous is not None:
                middle = (previous.stamp_ns + transform.stamp_ns) // 2
                got = tf.lookup("odom", "base_link", middle)
                fraction = (middle - previous.stamp_ns) / (transform.stamp_ns - previous.stamp_ns)
                expected = previous.translation + fraction * (
                    transform.translation - previous.translation
                )
                np.testing.assert_allclose(got[:3, 3], expected, atol=1e-9)
                back = tf.lookup("base_link", "odom", middle)
                np.testing.assert_allclose(back @ got, np.eye(4), atol=1e-9)
            previous = transform
    assert count == 517
    assert previous is not None
    with pytest.raises(TransformLookupError, match="outside"):
        tf.lookup("odom", "base_link", previous.stamp_ns - 30 * 10**9)  # pruned: 10 s window


def test_turtlesim_ros1_tf_tfmessage(shared_data: Path) -> None:
    bag = shared_data / "rosbag_fixtures" / "rosbagjs_turtlesim_lz4.bag"
    msgtypes = set()
    for message, deserialize in ros1_messages(bag, {"/tf", "/tf_static"}, limit=50):
        msgtypes.add(message.msgtype)
        decoded = decode(message, deserialize)
        assert decoded.value
    assert "tf/msg/tfMessage" in msgtypes


def test_velodyne_definitions_and_decoder(
    shared_data: Path,
) -> None:
    """VelodyneScan deserialises with the shipped definition and decodes to a LiDAR cloud
    (issue 35 item 11; tests/io/test_decoders_velodyne.py compares the clouds with nebula's)."""
    bag = shared_data / "velodyne_nebula_ros2" / "vlp16" / "1673400471837873222"
    scans = 0
    for message, deserialize in ros2_messages(bag):
        assert decoder_for(message.msgtype) is not None
        cloud = decode(message, deserialize).value
        assert isinstance(cloud, PointCloud)
        assert cloud.xyz.shape[0] > 14_000
        scan: Any = deserialize(message)
        assert scan.packets
        assert all(len(p.data) == 1206 for p in scan.packets)
        assert all(bytes(p.data[:2]) == b"\xff\xee" for p in scan.packets)
        scans += 1
    assert scans == 4


def test_sensor_types_of_real_decoders(shared_data: Path) -> None:
    from redrive.io.ros.decoders import decoder_for

    expected = {
        "sensor_msgs/PointCloud2": SensorType.LIDAR,
        "sensor_msgs/LaserScan": SensorType.LIDAR_2D,
        "sensor_msgs/Image": SensorType.CAMERA,
        "sensor_msgs/Imu": SensorType.IMU,
        "sensor_msgs/NavSatFix": SensorType.GNSS,
        "nav_msgs/Odometry": SensorType.ODOMETRY,
    }
    for msgtype, sensor_type in expected.items():
        decoder = decoder_for(msgtype)
        assert decoder is not None
        assert decoder.sensor_type is sensor_type
