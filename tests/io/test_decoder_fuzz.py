"""Decoders given lying messages raise redrive's errors, never IndexError/ValueError/struct.error.

PointCloud2 whose point_step, row_step, width, height or field offsets do not fit its data;
images whose step, size or encoding do not fit; any message whose CDR / ROS 1 bytes are cut or
have a length field changed.  Decoded through the reader's deserialiser
(:class:`redrive.io.ros.deserialize.Deserializer`), as every reader does.
"""

from __future__ import annotations

import contextlib
import struct
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from redrive.errors import RedriveError
from redrive.io.base import LogMessage
from redrive.io.ros.decoders import decode
from redrive.io.ros.deserialize import Deserializer

from ._decoder_helpers import header, log_message, store

_DESERIALIZE = Deserializer(Path("fuzz.bag"), ros1=store(1), cdr=store(2))
_SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _decodes_or_refuses(message: LogMessage) -> None:
    with contextlib.suppress(RedriveError):  # what the readers' callers catch and report
        decode(message, _DESERIALIZE)


@_SETTINGS
@given(
    ros_version=st.sampled_from([1, 2]),
    width=st.integers(0, 40),
    height=st.integers(0, 4),
    point_step=st.integers(0, 40),
    row_step=st.integers(0, 400),
    offsets=st.lists(st.integers(0, 48), min_size=3, max_size=3),
    datatype=st.integers(0, 10),
    count=st.integers(0, 3),
    size=st.integers(0, 500),
)
def test_pointcloud2_with_lying_layout(
    *,
    ros_version: int,
    width: int,
    height: int,
    point_step: int,
    row_step: int,
    offsets: list[int],
    datatype: int,
    count: int,
    size: int,
) -> None:
    fields = [
        {"name": axis, "offset": off, "datatype": datatype, "count": count}
        for axis, off in zip("xyz", offsets, strict=True)
    ]
    message = log_message(
        ros_version,  # type: ignore[arg-type]
        "sensor_msgs/msg/PointCloud2",
        header=header(ros_version, 1_700_000_000_000_000_000, "lidar"),  # type: ignore[arg-type]
        fields=fields,
        data=[7] * size,
        width=width,
        height=height,
        point_step=point_step,
        row_step=row_step,
        is_dense=True,
    )
    _decodes_or_refuses(message)


@_SETTINGS
@given(
    ros_version=st.sampled_from([1, 2]),
    encoding=st.sampled_from(["rgb8", "mono8", "mono16", "32FC1", "bgra8", "yuv422", ""]),
    width=st.integers(0, 30),
    height=st.integers(0, 30),
    step=st.integers(0, 200),
    size=st.integers(0, 3000),
    big=st.booleans(),
)
def test_image_whose_step_does_not_fit(
    *, ros_version: int, encoding: str, width: int, height: int, step: int, size: int, big: bool
) -> None:
    message = log_message(
        ros_version,  # type: ignore[arg-type]
        "sensor_msgs/msg/Image",
        header=header(ros_version, 1_700_000_000_000_000_000, "cam"),  # type: ignore[arg-type]
        encoding=encoding,
        width=width,
        height=height,
        step=step,
        is_bigendian=big,
        data=[7] * size,
    )
    _decodes_or_refuses(message)


def _velodyne_packet() -> list[int]:
    """A VLP-16 strongest-return packet: 12 blocks 0xFFEE, azimuths 0.00° … 2.20°, every return
    at 2 m with intensity 9, then a timestamp and the factory bytes 0x37 0x22."""
    out: list[int] = []
    for block in range(12):
        out += [0xFF, 0xEE, (block * 20) & 0xFF, (block * 20) >> 8]
        out += [0xE8, 0x03, 9] * 32  # 1000 × 2 mm
    return [*out, 0, 0, 0, 0, 0x37, 0x22]


_TYPES: dict[str, dict[str, Any]] = {
    "velodyne_msgs/msg/VelodyneScan": {"packets": [{"data": _velodyne_packet()}] * 2},
    "sensor_msgs/msg/Imu": {},
    "nav_msgs/msg/Odometry": {"child_frame_id": "base_link"},
    "sensor_msgs/msg/NavSatFix": {},
    "sensor_msgs/msg/CameraInfo": {"distortion_model": "plumb_bob"},
    "sensor_msgs/msg/PointCloud2": {
        "fields": [
            {"name": a, "offset": 4 * i, "datatype": 7, "count": 1} for i, a in enumerate("xyz")
        ],
        "width": 2,
        "height": 1,
        "point_step": 12,
        "row_step": 24,
        "data": [0] * 24,
    },
    "sensor_msgs/msg/Image": {
        "encoding": "mono8",
        "width": 4,
        "height": 2,
        "step": 4,
        "data": [0] * 8,
    },
    "tf2_msgs/msg/TFMessage": {
        "transforms": [{"child_frame_id": "a", "header": {"frame_id": "b"}}]
    },
}


@_SETTINGS
@given(
    ros_version=st.sampled_from([1, 2]),
    msgtype=st.sampled_from(sorted(_TYPES)),
    cut=st.integers(0, 400),
    at=st.integers(0, 400),
    value=st.sampled_from([0, 1, 7, 0xFFFF, 0x7FFFFFFF, 0xFFFFFFFF]),
)
def test_serialised_bytes_with_wrong_lengths(
    ros_version: int, msgtype: str, cut: int, at: int, value: int
) -> None:
    if msgtype not in store(ros_version).fielddefs:  # TFMessage: ROS 2 only in the stores
        ros_version = 2
    good = log_message(ros_version, msgtype, **_TYPES[msgtype])  # type: ignore[arg-type]
    raw = bytearray(good.raw)
    if at + 4 <= len(raw):
        struct.pack_into("<I", raw, at, value)  # a length (or any u32) that lies
    raw = raw[: max(len(raw) - cut, 0)]
    message = LogMessage(
        topic=good.topic,
        msgtype=msgtype,
        log_time_ns=good.log_time_ns,
        encoding=good.encoding,
        raw=bytes(raw),
    )
    _decodes_or_refuses(message)
