"""sensor_msgs/CameraInfo: encode → McapWriter → open_log → decode, ROS 1 bags, sensor map, info."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Bag1Writer

from redrive.assembly.sensor_map import infer_sensor_map
from redrive.assembly.summary import summarize_log
from redrive.io import open_log
from redrive.io.base import TopicInfo
from redrive.io.convert import convert_log
from redrive.io.mcap.writer import McapWriter
from redrive.io.ros.decoders import CameraInfoDecoder, Decoded, DecodedKind, decode, decoder_for
from redrive.types import CameraInfo, Image
from tests.io._decoder_helpers import deserializer, header, log_message, store

STAMP_NS = 1_700_000_000_123_456_789
K = np.array([[612.5, 0.0, 320.25], [0.0, 611.0, 241.5], [0.0, 0.0, 1.0]])
D = np.array([-0.28, 0.07, 0.0002, -0.0001, 0.0])
R = np.array([[0.9998, -0.02, 0.0], [0.02, 0.9998, 0.0], [0.0, 0.0, 1.0]])
P = np.array([[600.0, 0.0, 318.0, -36.0], [0.0, 600.0, 240.0, 0.0], [0.0, 0.0, 1.0, 0.0]])


def _info() -> CameraInfo:
    return CameraInfo(width=640, height=480, k=K, d=D, distortion_model="plumb_bob", r=R, p=P)


def _assert_same(got: object, want: CameraInfo) -> None:
    assert isinstance(got, CameraInfo)
    assert (got.width, got.height, got.distortion_model) == (640, 480, want.distortion_model)
    for name in ("k", "d", "r", "p"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
        assert not getattr(got, name).flags.writeable


def test_decoder_is_registered_and_not_a_sensor() -> None:
    for name in ("sensor_msgs/CameraInfo", "sensor_msgs/msg/CameraInfo"):
        decoder = decoder_for(name)
        assert isinstance(decoder, CameraInfoDecoder)
        assert decoder.kind is DecodedKind.CAMERA_INFO
        assert decoder.sensor_type is None


@pytest.mark.parametrize("ros_version", [1, 2])
def test_decodes_ros1_and_ros2_field_names(ros_version: int) -> None:
    # ROS 1 spells the matrices K, D, R, P; ROS 2 k, d, r, p
    names = ("K", "D", "R", "P") if ros_version == 1 else ("k", "d", "r", "p")
    message = log_message(
        ros_version,  # type: ignore[arg-type]
        "sensor_msgs/msg/CameraInfo",
        topic="/cam/camera_info",
        header=header(ros_version, STAMP_NS, "cam_optical"),  # type: ignore[arg-type]
        width=640,
        height=480,
        distortion_model="plumb_bob",
        **dict(zip(names, (K.reshape(9), D, R.reshape(9), P.reshape(12)), strict=True)),
    )
    decoded = decode(message, deserializer())
    assert (decoded.stamp_ns, decoded.frame_id) == (STAMP_NS, "cam_optical")
    _assert_same(decoded.value, _info())


def test_mcap_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "cam.mcap"
    with McapWriter(path) as out:
        out.write("/cam/camera_info", STAMP_NS, _info(), frame_id="cam_optical")
        # a Decoded is written with its own frame and stamp
        out.write(
            "/cam/camera_info",
            STAMP_NS + 100,
            Decoded(stamp_ns=STAMP_NS + 50, frame_id="cam_optical", value=_info()),
        )
        assert out.topics["/cam/camera_info"] == "sensor_msgs/msg/CameraInfo"
    with open_log(path) as log:
        assert log.topics["/cam/camera_info"].msgtype == "sensor_msgs/msg/CameraInfo"
        decoded = [decode(m, log.deserialize) for m in log.messages()]
    assert [(d.stamp_ns, d.frame_id) for d in decoded] == [
        (STAMP_NS, "cam_optical"),
        (STAMP_NS + 50, "cam_optical"),
    ]
    for d in decoded:
        _assert_same(d.value, _info())


def test_ros1_bag_round_trip(tmp_path: Path) -> None:
    """A bag written by rosbags' ROS 1 writer (Noetic definition: K, D, R, P)."""
    path = tmp_path / "cam.bag"
    ts = store(1)
    msgtype = "sensor_msgs/msg/CameraInfo"
    message = log_message(
        1,
        msgtype,
        header=header(1, STAMP_NS, "cam_optical"),
        width=640,
        height=480,
        distortion_model="plumb_bob",
        K=K.reshape(9),
        D=D,
        R=R.reshape(9),
        P=P.reshape(12),
    )
    with Bag1Writer(path) as writer:
        conn = writer.add_connection("/cam/camera_info", msgtype, typestore=ts)
        writer.write(conn, STAMP_NS, bytes(message.raw))
    with open_log(path) as log:
        assert log.format == "ros1"
        decoded = [decode(m, log.deserialize) for m in log.messages()]
    assert [(d.stamp_ns, d.frame_id) for d in decoded] == [(STAMP_NS, "cam_optical")]
    _assert_same(decoded[0].value, _info())


def test_mcap_to_ros1_bag_keeps_the_calibration(tmp_path: Path) -> None:
    """convert_log re-encodes the CDR message as ROS 1 (keeping the MCAP's definition)."""
    mcap, bag = tmp_path / "cam.mcap", tmp_path / "cam.bag"
    with McapWriter(mcap) as out:
        out.write("/cam/camera_info", STAMP_NS, _info(), frame_id="cam_optical")
    assert convert_log(mcap, bag).messages_written == 1
    with open_log(bag) as log:
        (message,) = log.messages()
        assert message.encoding == "ros1"
        decoded = decode(message, log.deserialize)
    assert decoded.frame_id == "cam_optical"
    _assert_same(decoded.value, _info())


def _camera_log(path: Path) -> Path:
    image = Image(pixels=np.zeros((4, 6, 3), dtype=np.uint8), encoding="rgb8")
    with McapWriter(path) as out:
        for i in range(3):
            stamp = STAMP_NS + i * 100_000_000
            out.write("/cam/image_raw", stamp, image, frame_id="cam_optical")
            out.write("/cam/camera_info", stamp, _info(), frame_id="cam_optical")
    return path


def test_camera_info_is_no_sensor_and_never_the_driver(tmp_path: Path) -> None:
    topics = {
        "/cam/camera_info": TopicInfo(
            topic="/cam/camera_info", msgtype="sensor_msgs/CameraInfo", count=100, encoding="ros1"
        ),
        "/cam/image_raw": TopicInfo(
            topic="/cam/image_raw", msgtype="sensor_msgs/Image", count=10, encoding="ros1"
        ),
    }
    smap = infer_sensor_map(topics, duration_ns=1_000_000_000)
    assert [s.topic for s in smap.sensors] == ["/cam/image_raw"]
    assert smap.driver == "cam_image_raw"
    assert "/cam/camera_info" not in smap.topics()
    # `redrive info` names the camera it calibrates
    with open_log(_camera_log(tmp_path / "cam.mcap")) as log:
        summary = summarize_log(log)
    rows = {t.topic: t for t in summary.topics}
    assert rows["/cam/camera_info"].decoder == "camera_info"
    assert rows["/cam/camera_info"].count == 3
    assert rows["/cam/camera_info"].maps_to == "camera info of cam_image_raw"
    assert rows["/cam/image_raw"].maps_to == "cam_image_raw (camera, driver)"
