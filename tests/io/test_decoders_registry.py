"""The decoder registry, decode(), and decoder plugins of the redrive.decoders group."""

from __future__ import annotations

import pytest

from redrive.errors import PluginError, UnsupportedMessageError
from redrive.io.base import LogMessage
from redrive.io.ros.decoders import (
    DEFAULT_DECODERS,
    Decoded,
    DecodedKind,
    ImuDecoder,
    PointCloud2Decoder,
    TFMessageDecoder,
    build_registry,
    decode,
    decoder_for,
    normalize_msgtype,
)
from redrive.types import GnssFix
from tests.io._decoder_helpers import deserializer, log_message

LOGGER = "redrive.io.ros.decoders.registry"


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("sensor_msgs/PointCloud2", "sensor_msgs/msg/PointCloud2"),
        ("sensor_msgs/msg/PointCloud2", "sensor_msgs/msg/PointCloud2"),
        ("/tf/tfMessage", "tf/msg/tfMessage"),
    ],
)
def test_normalize_msgtype(name: str, expected: str) -> None:
    assert normalize_msgtype(name) == expected


def test_decoder_for_accepts_ros1_and_ros2_names() -> None:
    assert isinstance(decoder_for("sensor_msgs/PointCloud2"), PointCloud2Decoder)
    assert isinstance(decoder_for("sensor_msgs/msg/PointCloud2"), PointCloud2Decoder)
    assert isinstance(decoder_for("tf/tfMessage"), TFMessageDecoder)
    assert isinstance(decoder_for("tf2_msgs/msg/TFMessage"), TFMessageDecoder)
    assert decoder_for("std_msgs/msg/String") is None


def test_default_registry_is_complete_and_consistent() -> None:
    expected = {
        "sensor_msgs/msg/PointCloud2",
        "velodyne_msgs/msg/VelodyneScan",
        "sensor_msgs/msg/Image",
        "sensor_msgs/msg/CompressedImage",
        "sensor_msgs/msg/CameraInfo",
        "sensor_msgs/msg/Imu",
        "sensor_msgs/msg/LaserScan",
        "sensor_msgs/msg/NavSatFix",
        "nav_msgs/msg/Odometry",
        "geometry_msgs/msg/PoseStamped",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "geometry_msgs/msg/TwistStamped",
        "tf2_msgs/msg/TFMessage",
        "tf/msg/tfMessage",
        "visualization_msgs/msg/MarkerArray",
        "vision_msgs/msg/Detection3DArray",
        "derived_object_msgs/msg/ObjectArray",
        "redrive_msgs/msg/GroundTruthObjectArray",
        "redrive_msgs/msg/TrafficLightStateArray",
    }
    assert set(DEFAULT_DECODERS) == expected
    for msgtype, decoder in DEFAULT_DECODERS.items():
        assert msgtype in decoder.msgtypes
        assert (decoder.sensor_type is not None) == (
            decoder.kind in (DecodedKind.SENSOR, DecodedKind.VEHICLE_STATE)
        )
    with pytest.raises(TypeError):
        DEFAULT_DECODERS["x/msg/Y"] = ImuDecoder()  # type: ignore[index]


def test_build_registry_refuses_duplicates() -> None:
    with pytest.raises(PluginError, match="both claim sensor_msgs/msg/Imu"):
        build_registry([ImuDecoder(), ImuDecoder()])


def test_decode_dispatches_and_rejects_unknown_types() -> None:
    message = log_message(2, "sensor_msgs/msg/NavSatFix", latitude=1.5, topic="/gps")
    assert isinstance(decode(message, deserializer()).value, GnssFix)
    unknown = LogMessage(
        topic="/chatter", msgtype="std_msgs/msg/String", log_time_ns=5, encoding="cdr"
    )
    with pytest.raises(
        UnsupportedMessageError, match=r"no decoder for std_msgs/msg/String on topic '/chatter'"
    ):
        decode(unknown, deserializer())


def test_native_messages_pass_through() -> None:
    payload = Decoded(
        stamp_ns=3, frame_id="gps", value=GnssFix(latitude_deg=1, longitude_deg=2, altitude_m=3)
    )
    native = LogMessage(
        topic="/kitti/oxts",
        msgtype="sensor_msgs/msg/NavSatFix",
        log_time_ns=3,
        encoding="native",
        payload=payload,
    )
    assert decode(native, deserializer()) is payload
    bad = LogMessage(
        topic="/x",
        msgtype="sensor_msgs/msg/NavSatFix",
        log_time_ns=3,
        encoding="native",
        payload=42,
    )
    with pytest.raises(UnsupportedMessageError, match="carries a int"):
        decode(bad, deserializer())
