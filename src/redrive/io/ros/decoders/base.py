"""The decoder contract: a serialised ROS message in, a data-model value out."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from redrive.io.base import DecodedKind, LogMessage
from redrive.types import (
    CameraInfo,
    DetectedObject,
    ExtensionPayload,
    GnssFix,
    Image,
    Imu,
    PointCloud,
    SensorType,
    TrafficData,
    Transform,
    VehicleState,
)

__all__ = ["Decoded", "DecodedKind", "DecodedValue", "Decoder", "Deserialize"]

#: What a decoder may produce.
DecodedValue = (
    PointCloud
    | Image
    | Imu
    | GnssFix
    | VehicleState
    | ExtensionPayload
    | tuple[DetectedObject, ...]
    | tuple[Transform, ...]
    | CameraInfo
    | TrafficData
)

#: ``reader.deserialize``: LogMessage → rosbags message object.
Deserialize = Callable[[LogMessage], object]


@dataclass(frozen=True, slots=True, kw_only=True)
class Decoded:
    """A decoded message.

    Attributes:
        stamp_ns: the header stamp; the log time when the message has no header or a zero stamp.
        frame_id: the header frame; "" when the message has none.
        value: the data-model value.
    """

    stamp_ns: int
    frame_id: str
    value: DecodedValue


class Decoder(Protocol):
    """Turns messages of some ROS types into data-model values.

    ``msgtypes`` are ROS 2 style names (``sensor_msgs/msg/PointCloud2``); the same decoder serves
    ROS 1 and ROS 2 encodings of the type.
    """

    name: str
    msgtypes: tuple[str, ...]
    kind: DecodedKind
    #: the sensor it feeds when ``kind`` is SENSOR (VehicleState decoders: ODOMETRY), else None.
    sensor_type: SensorType | None

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        """Decode one message.

        Raises:
            UnsupportedMessageError: the message cannot be represented (unknown encoding, bad
                layout); the text names the topic, type and what is wrong.
        """
        ...
