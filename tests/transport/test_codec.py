"""Typed payloads: every data-model sensor type round-trips exactly through a channel."""

from __future__ import annotations

import uuid
from collections.abc import Mapping

import numpy as np
import pytest

from redrive.errors import TransportError
from redrive.transport import Reader, Writer
from redrive.transport.codec import (
    KIND_ROS1,
    decode_ros1,
    decode_sample,
    encode_ros1_meta,
    encoded_size,
)
from redrive.types import GnssFix, Image, Imu, PointCloud, SensorData, SensorType, VehicleState


def _samples() -> list[SensorData]:
    rng = np.random.default_rng(0)
    n = 1234
    cloud = PointCloud(
        xyz=rng.normal(size=(n, 3)).astype(np.float32),
        channels={
            "intensity": rng.random(n).astype(np.float32),
            "ring": rng.integers(0, 32, n).astype(np.uint16),
            "t_offset_ns": rng.integers(0, 10**8, n).astype(np.int64),
        },
    )
    return [
        SensorData(
            sensor_id="lidar_top",
            sensor_type=SensorType.LIDAR,
            stamp_ns=1_700_000_000_123_456_789,
            frame_id="velodyne",
            frame_rate_hz=10.0,
            resolution=(1024, 32),
            sensor_location=(1.0, 0.0, 1.8),
            data=cloud,
        ),
        SensorData(
            sensor_id="cam_front",
            sensor_type=SensorType.CAMERA,
            stamp_ns=5,
            frame_id="camera",
            data=Image(pixels=rng.integers(0, 256, (72, 128, 3), dtype=np.uint8), encoding="rgb8"),
        ),
        SensorData(
            sensor_id="depth",
            sensor_type=SensorType.CAMERA,
            stamp_ns=6,
            data=Image(pixels=rng.integers(0, 65535, (4, 5), dtype=np.uint16), encoding="mono16"),
        ),
        SensorData(
            sensor_id="imu",
            sensor_type=SensorType.IMU,
            stamp_ns=7,
            data=Imu(linear_acceleration=[0.1, 0.2, 9.8], angular_velocity=[0, 0, 0.3]),
        ),
        SensorData(
            sensor_id="gnss",
            sensor_type=SensorType.GNSS,
            stamp_ns=8,
            data=GnssFix(latitude_deg=42.37, longitude_deg=-71.14, altitude_m=10.5, status=2),
        ),
        SensorData(
            sensor_id="odom",
            sensor_type=SensorType.ODOMETRY,
            stamp_ns=9,
            data=VehicleState(
                stamp_ns=9,
                frame_id="odom",
                position=[1e6, 2e6, 3.0],
                velocity=[1, 2, 0],
                heading_rad=0.5,
                yaw_rate_rad_s=0.01,
            ),
        ),
    ]


def _equal(a: object, b: object) -> bool:
    if isinstance(a, np.ndarray):
        return (
            isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and np.array_equal(a, b, equal_nan=True)
        )
    if isinstance(a, Mapping):
        assert isinstance(b, Mapping)
        return set(a) == set(b) and all(_equal(a[k], b[k]) for k in a)
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(
            _equal(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__
        )
    return a == b


def test_every_sensor_type_round_trips() -> None:
    name = f"test.codec{uuid.uuid4().hex[:8]}"
    samples = _samples()
    with (
        Writer(name, capacity_bytes=max(map(encoded_size, samples)), slots=8) as w,
        Reader(name) as r,
    ):
        for sample in samples:
            w.publish_sample(sample)
            got = r.read_sample(timeout_s=1.0)
            assert got is not None
            msg, back = got
            assert msg.stamp_ns == sample.stamp_ns
            assert _equal(back, sample), sample.sensor_id
        # a zero-copy decode inside a view
        w.publish_sample(samples[0])
        with r.view(timeout_s=1.0) as view:
            assert view is not None
            cloud = decode_sample(view.meta, view.payload).data
            assert isinstance(cloud, PointCloud)
            assert np.shares_memory(cloud.xyz, view.payload)
            assert np.array_equal(cloud.xyz, samples[0].data.xyz)  # type: ignore[union-attr]
        w.publish(b"raw bytes")
        with pytest.raises(TransportError, match="not a sensor sample"):
            r.read_sample(timeout_s=1.0)


def test_ros1_meta() -> None:
    meta = encode_ros1_meta(
        "/velodyne_points", "sensor_msgs/PointCloud2", "1158d486dd51d683ce2f1be655c3c181"
    )
    msg = decode_ros1(meta, np.frombuffer(b"\x01\x02", np.uint8))
    assert (msg.topic, msg.msg_type, msg.md5sum) == (
        "/velodyne_points",
        "sensor_msgs/PointCloud2",
        "1158d486dd51d683ce2f1be655c3c181",
    )
    assert KIND_ROS1 == 2
    with pytest.raises(TransportError, match="unreadable header"):
        decode_ros1(b"\x05", np.zeros(0, np.uint8))
    with pytest.raises(TransportError, match="unreadable header"):
        decode_sample(b"\x01\x02", np.zeros(0, np.uint8))
