"""Which shared-memory stream carries which topic, in one live session.

A live session has a name (``live-<pid>`` by default); each source topic goes through its own
stream ``<session>.<topic>`` (``/velodyne_points`` → ``live-123.velodyne_points``). Whoever
starts the sources (the engine, a test, the loss benchmark) knows the topics and their types and
hands the list of :class:`StreamSpec` to the Sensor Dispatcher and the Data Logger.

Three payload kinds travel (see :mod:`redrive.transport.codec`): ``ros1`` streams carry ROS 1
messages as serialised bytes (the ROS scraper forwards what rospy received), ``cdr`` streams ROS 2
messages as CDR bytes (the ROS 2 scraper forwards what DDS received), ``sensor`` streams carry
typed data-model samples (the replay and synthetic sources).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Literal

__all__ = [
    "PAYLOAD_MSGTYPE",
    "StreamSpec",
    "ring_slots",
    "ros1_type",
    "ros2_type",
    "stream_name",
]

_BAD = re.compile(r"[^A-Za-z0-9_.-]+")

#: the ROS message type a typed sample stands for (what the sensor map infers sensors from).
PAYLOAD_MSGTYPE = {
    "PointCloud": "sensor_msgs/msg/PointCloud2",
    "Image": "sensor_msgs/msg/Image",
    "Imu": "sensor_msgs/msg/Imu",
    "GnssFix": "sensor_msgs/msg/NavSatFix",
    "VehicleState": "nav_msgs/msg/Odometry",
}


#: A stream of small messages gets more slots than ``slots``, up to this many bytes of ring ...
SMALL_RING_BYTES = 4 << 20
#: ... and at most this many slots.
MAX_RING_SLOTS = 256


def ring_slots(capacity_bytes: int, slots: int) -> int:
    """The slots of a stream whose largest message is ``capacity_bytes``: ``slots``, or more for
    small messages (up to :data:`SMALL_RING_BYTES` of ring, :data:`MAX_RING_SLOTS` slots).

    A keep-latest reader (the Sensor Dispatcher, the Foxglove view) loses what the writer
    publishes while it is more than a ring behind. A source that falls behind publishes its
    backlog in a burst — a 100-Hz odometry stream ten messages at once after a sweep — and a ring
    of a few slots laps the reader within that burst: the frames then miss the ego states on one
    side of their stamp. Slots of small messages cost little, so those streams hold seconds.
    """
    if capacity_bytes <= 0:
        return slots
    return max(slots, min(MAX_RING_SLOTS, SMALL_RING_BYTES // capacity_bytes))


def stream_name(session: str, topic: str) -> str:
    """``<session>.<topic without slashes>``: a name :class:`redrive.transport.Writer` takes."""
    cleaned = _BAD.sub("_", topic.strip("/").replace("/", "."))
    return f"{session}.{cleaned or 'root'}"


def ros2_type(msgtype: str) -> str:
    """``sensor_msgs/PointCloud2`` → ``sensor_msgs/msg/PointCloud2`` (unchanged if already so)."""
    parts = msgtype.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else msgtype


def ros1_type(msgtype: str) -> str:
    """``sensor_msgs/msg/PointCloud2`` → ``sensor_msgs/PointCloud2``."""
    parts = msgtype.split("/")
    return f"{parts[0]}/{parts[2]}" if len(parts) == 3 else msgtype


@dataclass(frozen=True, slots=True, kw_only=True)
class StreamSpec:
    """One topic of a live session.

    Attributes:
        topic: the source topic (``/velodyne_points``).
        msgtype: its ROS 2 style type (``sensor_msgs/msg/PointCloud2``); for ``sensor`` streams
            the type the sample stands for (:data:`PAYLOAD_MSGTYPE`).
        stream: the shared-memory stream name (:func:`stream_name`).
        payload: ``ros1`` (serialised ROS 1 bytes), ``cdr`` (ROS 2 CDR bytes) or ``sensor``
            (typed samples).
        capacity_bytes: the largest message the stream takes.
        qos: ``cdr`` streams: what the publishers offer, as rosbag2's ``offered_qos_profiles``
            YAML (recorded on the topic's channel); "" otherwise.
    """

    topic: str
    msgtype: str
    stream: str
    payload: Literal["ros1", "cdr", "sensor"]
    capacity_bytes: int
    qos: str = ""
