"""Every non-cloud decoder, on real ROS 1 and ROS 2 serialisations built with rosbags."""

from __future__ import annotations

import io
import math
from typing import Any

import numpy as np
import pytest
from PIL import Image as PILImage

from redrive.errors import UnsupportedMessageError
from redrive.io.ros.decoders import (
    CompressedImageDecoder,
    Detection3DArrayDecoder,
    ImageDecoder,
    ImuDecoder,
    LaserScanDecoder,
    MarkerArrayDecoder,
    NavSatFixDecoder,
    ObjectArrayDecoder,
    OdometryDecoder,
    PoseDecoder,
    TFMessageDecoder,
    TwistDecoder,
    object_class_from_text,
)
from redrive.io.ros.typestore import typestore_for
from redrive.types import ObjectClass
from tests.io._decoder_helpers import deserializer, header, log_message

STAMP_NS = 1_650_000_000_250_000_000
VERSIONS = pytest.mark.parametrize("ros_version", [1, 2])
DESERIALIZE = deserializer()


def _quat_yaw(yaw_rad: float) -> dict[str, float]:
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw_rad / 2), "w": math.cos(yaw_rad / 2)}


# ---------------------------------------------------------------- Image


def _image_message(
    ros_version: int, pixels: np.ndarray, encoding: str, *, step: int, big: bool = False
) -> Any:
    height = pixels.shape[0]
    width = pixels.shape[1]
    row = pixels.reshape(height, -1).view(np.uint8).reshape(height, -1)
    padded = np.zeros((height, step), dtype=np.uint8)
    padded[:, : row.shape[1]] = row
    return log_message(
        ros_version,
        "sensor_msgs/msg/Image",
        header=header(ros_version, STAMP_NS, "cam_front"),
        height=height,
        width=width,
        encoding=encoding,
        is_bigendian=int(big),
        step=step,
        data=padded.reshape(-1),
    )


@VERSIONS
@pytest.mark.parametrize(
    ("encoding", "dtype", "channels"),
    [
        ("rgb8", "u1", 3),
        ("bgr8", "u1", 3),
        ("rgba8", "u1", 4),
        ("bgra8", "u1", 4),
        ("mono8", "u1", 1),
        ("mono16", "<u2", 1),
        ("16UC1", ">u2", 1),
        ("32FC1", ">f4", 1),
        ("32FC1", "<f4", 1),
    ],
)
def test_image_encodings_with_row_padding(
    ros_version: int, encoding: str, dtype: str, channels: int
) -> None:
    rng = np.random.default_rng(3)
    shape = (5, 7) if channels == 1 else (5, 7, channels)
    pixels = (rng.random(shape) * 200).astype(dtype)
    row_bytes = 7 * channels * np.dtype(dtype).itemsize
    message = _image_message(
        ros_version, pixels, encoding, step=row_bytes + 6, big=dtype.startswith(">")
    )
    decoded = ImageDecoder().decode(message, DESERIALIZE)
    assert decoded.stamp_ns == STAMP_NS
    assert decoded.frame_id == "cam_front"
    image = decoded.value
    assert image.encoding == encoding
    assert image.pixels.dtype.isnative
    assert image.pixels.shape == shape
    np.testing.assert_array_equal(image.pixels, pixels.astype(pixels.dtype.newbyteorder("=")))


def test_image_unsupported_encoding_names_it() -> None:
    message = _image_message(2, np.zeros((2, 2, 3), np.uint8), "yuv422", step=6)
    with pytest.raises(UnsupportedMessageError, match="yuv422"):
        ImageDecoder().decode(message, DESERIALIZE)


def test_image_short_data_is_rejected() -> None:
    message = _image_message(2, np.zeros((2, 2, 3), np.uint8), "rgb8", step=6)
    bad = log_message(
        2,
        "sensor_msgs/msg/Image",
        height=4,
        width=2,
        encoding="rgb8",
        step=6,
        data=np.zeros(12, np.uint8),
    )
    ImageDecoder().decode(message, DESERIALIZE)
    with pytest.raises(UnsupportedMessageError, match="data holds 12 bytes"):
        ImageDecoder().decode(bad, DESERIALIZE)


def _compressed(ros_version: int, data: bytes, fmt: str) -> Any:
    return log_message(
        ros_version,
        "sensor_msgs/msg/CompressedImage",
        header=header(ros_version, STAMP_NS, "cam"),
        format=fmt,
        data=np.frombuffer(data, np.uint8),
    )


def _encode(array: np.ndarray, fmt: str, mode: str | None = None) -> bytes:
    out = io.BytesIO()
    PILImage.fromarray(array, mode=mode).save(out, format=fmt) if mode else PILImage.fromarray(
        array
    ).save(out, format=fmt)
    return out.getvalue()


@VERSIONS
def test_compressed_png_rgb_rgba_mono(ros_version: int) -> None:
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 255, (6, 9, 3), dtype=np.uint8)
    got = CompressedImageDecoder().decode(
        _compressed(ros_version, _encode(rgb, "PNG"), "png"), DESERIALIZE
    )
    assert got.stamp_ns == STAMP_NS
    assert got.value.encoding == "rgb8"
    np.testing.assert_array_equal(got.value.pixels, rgb)

    rgba = rng.integers(0, 255, (6, 9, 4), dtype=np.uint8)
    got = CompressedImageDecoder().decode(
        _compressed(ros_version, _encode(rgba, "PNG"), "rgba8; png compressed"), DESERIALIZE
    )
    assert got.value.encoding == "rgb8"
    np.testing.assert_array_equal(got.value.pixels, rgba[..., :3])

    mono = rng.integers(0, 255, (6, 9), dtype=np.uint8)
    got = CompressedImageDecoder().decode(
        _compressed(ros_version, _encode(mono, "PNG"), "png"), DESERIALIZE
    )
    assert got.value.encoding == "mono8"
    np.testing.assert_array_equal(got.value.pixels, mono)

    deep = rng.integers(0, 65535, (6, 9), dtype=np.uint16)
    got = CompressedImageDecoder().decode(
        _compressed(ros_version, _encode(deep, "PNG"), "16UC1; png compressed"), DESERIALIZE
    )
    assert got.value.encoding == "mono16"
    assert got.value.pixels.dtype == np.uint16
    np.testing.assert_array_equal(got.value.pixels, deep)


def test_compressed_jpeg_and_bad_formats() -> None:
    rgb = np.full((16, 16, 3), (200, 40, 90), dtype=np.uint8)
    got = CompressedImageDecoder().decode(_compressed(2, _encode(rgb, "JPEG"), "jpeg"), DESERIALIZE)
    assert got.value.encoding == "rgb8"
    assert got.value.pixels.shape == (16, 16, 3)
    assert np.abs(got.value.pixels.astype(int) - rgb).max() <= 3
    with pytest.raises(UnsupportedMessageError, match="'h264'"):
        CompressedImageDecoder().decode(_compressed(2, b"\0\0\0\1", "h264"), DESERIALIZE)
    with pytest.raises(UnsupportedMessageError, match="does not decode"):
        CompressedImageDecoder().decode(_compressed(2, b"not a png", "png"), DESERIALIZE)


# ---------------------------------------------------------------- IMU, GNSS, LaserScan


@VERSIONS
def test_imu_with_and_without_orientation(ros_version: int) -> None:
    values = {
        "header": header(ros_version, STAMP_NS, "imu_link"),
        "orientation": {"x": 0.0, "y": 0.0, "z": 0.6, "w": 0.8},
        "angular_velocity": {"x": 0.1, "y": -0.2, "z": 0.3},
        "linear_acceleration": {"x": 0.5, "y": 0.0, "z": 9.81},
    }
    got = ImuDecoder().decode(
        log_message(ros_version, "sensor_msgs/msg/Imu", **values), DESERIALIZE
    )
    assert got.stamp_ns == STAMP_NS
    assert got.frame_id == "imu_link"
    np.testing.assert_array_equal(got.value.orientation, [0.0, 0.0, 0.6, 0.8])
    np.testing.assert_array_equal(got.value.angular_velocity, [0.1, -0.2, 0.3])
    np.testing.assert_array_equal(got.value.linear_acceleration, [0.5, 0.0, 9.81])
    cov = np.zeros(9)
    cov[0] = -1.0
    got = ImuDecoder().decode(
        log_message(ros_version, "sensor_msgs/msg/Imu", orientation_covariance=cov, **values),
        DESERIALIZE,
    )
    assert np.isnan(got.value.orientation).all()


@VERSIONS
def test_navsatfix(ros_version: int) -> None:
    cov = np.diag([1.0, 2.0, 4.0]).reshape(-1)
    message = log_message(
        ros_version,
        "sensor_msgs/msg/NavSatFix",
        header=header(ros_version, STAMP_NS, "gps"),
        status={"status": 1, "service": 1},
        latitude=42.3758,
        longitude=-71.1474,
        altitude=12.5,
        position_covariance=cov,
        position_covariance_type=2,
    )
    got = NavSatFixDecoder().decode(message, DESERIALIZE)
    assert (got.value.latitude_deg, got.value.longitude_deg, got.value.altitude_m) == (
        42.3758,
        -71.1474,
        12.5,
    )
    assert got.value.status == 1
    np.testing.assert_array_equal(got.value.position_covariance_m2, np.diag([1.0, 2.0, 4.0]))
    unknown = log_message(ros_version, "sensor_msgs/msg/NavSatFix", position_covariance_type=0)
    got = NavSatFixDecoder().decode(unknown, DESERIALIZE)
    assert np.isnan(got.value.position_covariance_m2).all()
    assert got.stamp_ns == unknown.log_time_ns  # zero header stamp → log time


@VERSIONS
def test_laserscan_keeps_invalid_beams_as_nan(ros_version: int) -> None:
    ranges = np.array([1.0, np.inf, 0.05, 2.0, np.nan, 50.0], dtype=np.float32)
    message = log_message(
        ros_version,
        "sensor_msgs/msg/LaserScan",
        header=header(ros_version, STAMP_NS, "laser"),
        angle_min=-math.pi / 2,
        angle_max=math.pi / 2,
        angle_increment=math.pi / 2,
        range_min=0.1,
        range_max=30.0,
        ranges=ranges,
        intensities=np.arange(6, dtype=np.float32),
    )
    got = LaserScanDecoder().decode(message, DESERIALIZE)
    cloud = got.value
    assert cloud.num_points == 6
    valid = ~np.isnan(cloud.xyz).any(axis=1)
    assert valid.tolist() == [True, False, False, True, False, False]
    angle_min = np.float32(-math.pi / 2)
    increment = np.float32(math.pi / 2)
    np.testing.assert_allclose(
        cloud.xyz[0], [math.cos(angle_min), math.sin(angle_min), 0.0], atol=1e-6
    )
    a3 = float(angle_min) + 3 * float(increment)
    np.testing.assert_allclose(cloud.xyz[3], [2 * math.cos(a3), 2 * math.sin(a3), 0.0], atol=1e-6)
    np.testing.assert_array_equal(cloud.channels["range"], ranges)
    np.testing.assert_array_equal(cloud.channels["intensity"], np.arange(6))
    no_intensity = log_message(
        ros_version, "sensor_msgs/msg/LaserScan", ranges=ranges, range_max=100.0
    )
    assert set(LaserScanDecoder().decode(no_intensity, DESERIALIZE).value.channels) == {"range"}


# ---------------------------------------------------------------- ego motion


@VERSIONS
def test_odometry_twist_rotated_into_header_frame(ros_version: int) -> None:
    yaw = math.pi / 2
    message = log_message(
        ros_version,
        "nav_msgs/msg/Odometry",
        header=header(ros_version, STAMP_NS, "odom"),
        child_frame_id="base_link",
        pose={
            "pose": {"position": {"x": 10.0, "y": -3.0, "z": 0.5}, "orientation": _quat_yaw(yaw)}
        },
        twist={"twist": {"linear": {"x": 2.0, "y": 0.0, "z": 0.0}, "angular": {"z": 0.25}}},
    )
    got = OdometryDecoder().decode(message, DESERIALIZE)
    state = got.value
    assert got.frame_id == state.frame_id == "odom"
    assert state.stamp_ns == STAMP_NS
    np.testing.assert_array_equal(state.position, [10.0, -3.0, 0.5])
    assert state.heading_rad == pytest.approx(yaw)
    np.testing.assert_allclose(state.velocity, [0.0, 2.0, 0.0], atol=1e-12)  # body +x → odom +y
    assert state.yaw_rate_rad_s == pytest.approx(0.25)
    assert state.speed_mps == pytest.approx(2.0)


@VERSIONS
def test_pose_pose_with_covariance_and_twist(ros_version: int) -> None:
    pose = {"position": {"x": 1.0, "y": 2.0, "z": 3.0}, "orientation": _quat_yaw(-0.3)}
    stamped = log_message(
        ros_version,
        "geometry_msgs/msg/PoseStamped",
        header=header(ros_version, STAMP_NS, "map"),
        pose=pose,
    )
    with_cov = log_message(
        ros_version,
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        header=header(ros_version, STAMP_NS, "map"),
        pose={"pose": pose},
    )
    for message in (stamped, with_cov):
        state = PoseDecoder().decode(message, DESERIALIZE).value
        np.testing.assert_array_equal(state.position, [1.0, 2.0, 3.0])
        assert state.heading_rad == pytest.approx(-0.3)
        assert state.frame_id == "map"
    twist = log_message(
        ros_version,
        "geometry_msgs/msg/TwistStamped",
        header=header(ros_version, STAMP_NS, "base_link"),
        twist={"linear": {"x": 4.0, "y": 0.5}, "angular": {"z": -0.1}},
    )
    state = TwistDecoder().decode(twist, DESERIALIZE).value
    np.testing.assert_array_equal(state.velocity, [4.0, 0.5, 0.0])
    assert state.yaw_rate_rad_s == -0.1
    assert state.frame_id == "base_link"


# ---------------------------------------------------------------- tf


def _tf_items(ros_version: int) -> list[dict[str, Any]]:
    return [
        {
            "header": header(ros_version, STAMP_NS, "map"),
            "child_frame_id": "odom",
            "transform": {
                "translation": {"x": 1.0, "y": 2.0, "z": 0.0},
                "rotation": _quat_yaw(0.5),
            },
        },
        {
            "header": header(ros_version, STAMP_NS + 5, "odom"),
            "child_frame_id": "base_link",
            "transform": {"translation": {"x": 0.5}, "rotation": {"w": 1.0}},
        },
    ]


TF_ROS1 = {"tf2_msgs/msg/TFMessage": ("msg", "geometry_msgs/TransformStamped[] transforms")}


@VERSIONS
def test_tf_message_and_static_topic(ros_version: int) -> None:
    ts = typestore_for(ros_version, TF_ROS1 if ros_version == 1 else None)[0]
    deserialize = deserializer({ros_version: ts})
    message = log_message(
        ros_version, "tf2_msgs/msg/TFMessage", ts=ts, topic="/tf", transforms=_tf_items(ros_version)
    )
    got = TFMessageDecoder().decode(message, deserialize)
    first, second = got.value
    assert (first.parent_frame, first.child_frame, first.stamp_ns) == ("map", "odom", STAMP_NS)
    np.testing.assert_array_equal(first.translation, [1.0, 2.0, 0.0])
    np.testing.assert_allclose(first.rotation, list(_quat_yaw(0.5).values()))
    assert second.stamp_ns == STAMP_NS + 5
    assert got.stamp_ns == STAMP_NS
    static = log_message(
        ros_version,
        "tf2_msgs/msg/TFMessage",
        ts=ts,
        topic="/tf_static",
        transforms=_tf_items(ros_version),
    )
    assert [t.stamp_ns for t in TFMessageDecoder().decode(static, deserialize).value] == [0, 0]


def test_ros1_tf_tfmessage() -> None:
    ts, failed = typestore_for(
        1, {"tf/msg/tfMessage": ("msg", "geometry_msgs/TransformStamped[] transforms")}
    )
    assert not failed
    message = log_message(1, "tf/msg/tfMessage", ts=ts, topic="/tf", transforms=_tf_items(1))
    got = TFMessageDecoder().decode(message, deserializer({1: ts}))
    assert [(t.parent_frame, t.child_frame) for t in got.value] == [
        ("map", "odom"),
        ("odom", "base_link"),
    ]


# ---------------------------------------------------------------- objects


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("car", ObjectClass.VEHICLE),
        ("Car", ObjectClass.VEHICLE),
        ("vehicle", ObjectClass.VEHICLE),
        ("vehicle.truck", ObjectClass.TRUCK),
        ("pedestrian", ObjectClass.PEDESTRIAN),
        ("Person_sitting", ObjectClass.PEDESTRIAN),
        ("Cyclist", ObjectClass.BICYCLE),
        ("motorcycle", ObjectClass.MOTORCYCLE),
        ("gt/cars", ObjectClass.VEHICLE),
        ("traffic_cone", ObjectClass.STATIC),
        ("7", ObjectClass.UNKNOWN),
        ("", ObjectClass.UNKNOWN),
        ("DontCare", ObjectClass.UNKNOWN),
    ],
)
def test_object_class_from_text(text: str, expected: ObjectClass) -> None:
    assert object_class_from_text(text) is expected


@VERSIONS
def test_marker_array_cubes_only(ros_version: int) -> None:
    def marker(mid: int, mtype: int, action: int, ns: str) -> dict[str, Any]:
        return {
            "header": header(ros_version, STAMP_NS, "base_link"),
            "ns": ns,
            "id": mid,
            "type": mtype,
            "action": action,
            "pose": {"position": {"x": 5.0, "y": 1.0, "z": 0.8}, "orientation": _quat_yaw(0.2)},
            "scale": {"x": 4.5, "y": 1.9, "z": 1.6},
        }

    message = log_message(
        ros_version,
        "visualization_msgs/msg/MarkerArray",
        markers=[
            marker(3, 1, 0, "gt_car"),
            marker(4, 2, 0, "car"),
            marker(5, 1, 2, "car"),
            marker(6, 1, 0, "pedestrians"),
        ],
    )
    got = MarkerArrayDecoder().decode(message, DESERIALIZE)
    assert got.frame_id == "base_link"
    assert [(o.object_id, o.object_class) for o in got.value] == [
        (3, ObjectClass.VEHICLE),
        (6, ObjectClass.PEDESTRIAN),
    ]
    box = got.value[0].box
    np.testing.assert_array_equal(box.center, [5.0, 1.0, 0.8])
    np.testing.assert_array_equal(box.size, [4.5, 1.9, 1.6])
    assert box.yaw_rad == pytest.approx(0.2)
    assert got.value[0].orientation[0] == pytest.approx(0.2)


def _detection_pose(yaw: float) -> dict[str, Any]:
    return {"position": {"x": 12.0, "y": -4.0, "z": 1.0}, "orientation": _quat_yaw(yaw)}


def test_detection3d_array_ros2_vision_msgs_4() -> None:
    detections = [
        {
            "header": header(2, STAMP_NS, "lidar"),
            "results": [
                {"hypothesis": {"class_id": "pedestrian", "score": 0.3}},
                {"hypothesis": {"class_id": "Car", "score": 0.9}},
            ],
            "bbox": {"center": _detection_pose(1.0), "size": {"x": 4.0, "y": 2.0, "z": 1.5}},
            "id": "42",
        },
        {
            "results": [{"hypothesis": {"class_id": "3", "score": 1.7}}],
            "bbox": {"center": _detection_pose(0.0), "size": {"x": 1.0, "y": 1.0, "z": 1.0}},
            "id": "track-a",
        },
    ]
    message = log_message(
        2,
        "vision_msgs/msg/Detection3DArray",
        header=header(2, STAMP_NS, "lidar"),
        detections=detections,
    )
    got = Detection3DArrayDecoder().decode(message, DESERIALIZE)
    assert got.frame_id == "lidar"
    car, other = got.value
    assert (car.object_id, car.object_class, car.confidence) == (42, ObjectClass.VEHICLE, 0.9)
    np.testing.assert_array_equal(car.box.center, [12.0, -4.0, 1.0])
    np.testing.assert_array_equal(car.box.size, [4.0, 2.0, 1.5])
    assert car.box.yaw_rad == pytest.approx(1.0)
    assert other.object_class is ObjectClass.UNKNOWN  # numeric class ids have no name
    assert other.confidence == 1.0  # clamped
    assert other.object_id >= 0
    again = Detection3DArrayDecoder().decode(message, DESERIALIZE).value[1]
    assert again.object_id == other.object_id  # stable id for a string


NOETIC_VISION_MSGS = {
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "msg",
        "int64 id\nfloat64 score\ngeometry_msgs/PoseWithCovariance pose",
    ),
    "vision_msgs/msg/BoundingBox3D": (
        "msg",
        "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size",
    ),
    "vision_msgs/msg/Detection3D": (
        "msg",
        "Header header\nObjectHypothesisWithPose[] results\nBoundingBox3D bbox\nsensor_msgs/PointCloud2 source_cloud",
    ),
    "vision_msgs/msg/Detection3DArray": ("msg", "Header header\nDetection3D[] detections"),
}


def test_detection3d_array_ros1_noetic_layout() -> None:
    ts, failed = typestore_for(1, NOETIC_VISION_MSGS)
    assert not failed
    detections = [
        {
            "results": [{"id": 2, "score": 0.4}, {"id": 5, "score": 0.8}],
            "bbox": {"center": _detection_pose(0.5), "size": {"x": 3.0, "y": 1.5, "z": 1.2}},
        }
    ]
    message = log_message(
        1,
        "vision_msgs/msg/Detection3DArray",
        ts=ts,
        header=header(1, STAMP_NS, "velo"),
        detections=detections,
    )
    (obj,) = Detection3DArrayDecoder().decode(message, deserializer({1: ts})).value
    assert (obj.object_id, obj.object_class, obj.confidence) == (-1, ObjectClass.UNKNOWN, 0.8)
    np.testing.assert_array_equal(obj.box.size, [3.0, 1.5, 1.2])


@VERSIONS
def test_derived_object_array_carla(ros_version: int) -> None:
    def obj(oid: int, classification: int, shape: dict[str, Any]) -> dict[str, Any]:
        return {
            "header": header(ros_version, STAMP_NS, "map"),
            "id": oid,
            "detection_level": 1,
            "object_classified": True,
            "pose": {"position": {"x": 100.0, "y": 50.0, "z": 0.7}, "orientation": _quat_yaw(-1.0)},
            "twist": {"linear": {"x": 3.0, "y": -1.0}},
            "accel": {"linear": {"x": 0.5}},
            "shape": shape,
            "classification": classification,
            "classification_certainty": 255,
        }

    objects = [
        obj(101, 6, {"type": 1, "dimensions": [4.8, 2.1, 1.5]}),
        obj(102, 4, {"type": 3, "dimensions": [1.8, 0.3]}),
        obj(103, 7, {"type": 1, "dimensions": [9.0, 2.5, 3.5]}),
        obj(104, 10, {"type": 1, "dimensions": [1.0, 0.2, 1.0]}),
    ]
    message = log_message(
        ros_version,
        "derived_object_msgs/msg/ObjectArray",
        header=header(ros_version, STAMP_NS, "map"),
        objects=objects,
    )
    got = ObjectArrayDecoder().decode(message, DESERIALIZE)
    assert [(o.object_id, o.object_class) for o in got.value] == [
        (101, ObjectClass.VEHICLE),
        (102, ObjectClass.PEDESTRIAN),
        (103, ObjectClass.TRUCK),
        (104, ObjectClass.STATIC),
    ]
    car = got.value[0]
    assert car.confidence == 1.0
    np.testing.assert_array_equal(car.box.size, [4.8, 2.1, 1.5])
    np.testing.assert_array_equal(car.box.center, [100.0, 50.0, 0.7])
    assert car.box.yaw_rad == pytest.approx(-1.0)
    np.testing.assert_array_equal(car.velocity, [3.0, -1.0, 0.0])
    np.testing.assert_array_equal(car.acceleration, [0.5, 0.0, 0.0])
    np.testing.assert_array_equal(got.value[1].box.size, [0.6, 0.6, 1.8])  # cylinder: 2r, 2r, h
