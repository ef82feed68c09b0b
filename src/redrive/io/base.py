"""What every log reader offers: topics, a time range and a stream of messages.

A reader yields :class:`LogMessage` records in log-time order.  Messages from ROS logs carry their
serialised bytes (``encoding`` ``ros1`` or ``cdr``) and are decoded on demand by
:mod:`redrive.io.ros.decoders`; readers of non-ROS layouts (KITTI) yield already-decoded payloads
(``encoding == "native"``).
"""

from __future__ import annotations

import enum
from collections.abc import Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Literal, Protocol, Self, runtime_checkable

import numpy as np
import numpy.typing as npt

from redrive.types import SensorType

__all__ = [
    "DecodedKind",
    "Encoding",
    "LogMessage",
    "LogReader",
    "MessageBatch",
    "ReaderCapabilities",
    "TopicInfo",
    "normalize_msgtype",
]

#: How a message's bytes are serialised: ROS 1, ROS 2 CDR, or already decoded (``native``).
Encoding = Literal["ros1", "cdr", "native"]


def normalize_msgtype(msgtype: str) -> str:
    """The one spelling of a message type: ``pkg/msg/Type``.

    ROS 1 names (``sensor_msgs/PointCloud2``, as ROS 1 bags and the MCAP ``ros1`` profile write
    them) gain the ``msg`` part; ROS 2 names come back as they are, without surrounding slashes or
    spaces.
    """
    parts = msgtype.strip().strip("/").split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return "/".join(parts)


class DecodedKind(enum.Enum):
    """How the Sensor Dispatcher uses a decoded value."""

    SENSOR = "sensor"  # a SensorData payload of ``Decoder.sensor_type``
    VEHICLE_STATE = "vehicle_state"  # ego motion (Odometry, PoseStamped, TwistStamped)
    OBJECTS = "objects"  # tuple[DetectedObject, ...]: ground truth or detections
    TRANSFORMS = "transforms"  # tuple[Transform, ...]: tf / tf_static
    CAMERA_INFO = "camera_info"  # CameraInfo: a camera's calibration, never a sensor of frames
    TRAFFIC_LIGHTS = "traffic_lights"  # TrafficData: the lights' states (Frame.traffic)


@dataclass(frozen=True, slots=True, kw_only=True)
class TopicInfo:
    """Summary of one topic of a log.

    Attributes:
        topic: the topic name.
        msgtype: the ROS 2 style type name, ``sensor_msgs/msg/PointCloud2``.
        count: number of messages.
        size_bytes: serialised bytes of all its messages; -1 when the index does not say.
        encoding: how its messages are serialised.
        has_definition: False when the log carries no definition of the type and redrive knows
            none either (its messages pass through raw and cannot be deserialised).
        kind: for a ``native`` topic, how its values are used (its reader says; it has no ROS
            type a decoder could tell it from); None for message-typed topics, whose decoder
            says (:func:`redrive.io.ros.decoders.topic_kind` answers for both).
        sensor_type: for a ``native`` topic of kind SENSOR, the sensor it feeds.
    """

    topic: str
    msgtype: str
    count: int
    size_bytes: int = -1
    encoding: Encoding
    has_definition: bool = True
    kind: DecodedKind | None = None
    sensor_type: SensorType | None = None


class MessageBatch:
    """Messages of one connection that a reader read together (a ROS 1 chunk's), for decoders
    that decode many messages with a few array operations instead of one at a time.

    A reader that yields messages from one buffer links each to its batch
    (:attr:`LogMessage.batch`); a decoder may then decode the whole batch the first time one
    of its messages is asked for, keep the results in :attr:`memo` and hand each message its
    own.  Decoders that do not know batches ignore the link: every message stays complete.

    Attributes:
        buffer: the bytes the messages lie in (immutable, or a read-only file map).
        starts, stops: each message's byte span in ``buffer`` (``raw`` is
            ``buffer[starts[i]:stops[i]]``), in the order they are yielded; int sequences or
            int64 arrays (the ROS 1 reader hands over its arrays, no list per chunk).
        log_times_ns: each message's log time (same kinds).
        encoding: the messages' encoding (all the same).
        stride: when the reader found the messages to lie at a fixed distance and to have one
            size (``starts[i] == starts[0] + i * stride``, ``stops - starts`` all equal: a
            chunk of one sensor's messages), that distance; else None (nothing is known).
        memo: per-decoder results (keyed by the decoder object); empty until one decodes.
    """

    __slots__ = ("buffer", "encoding", "log_times_ns", "memo", "starts", "stops", "stride")

    def __init__(
        self,
        buffer: bytes | memoryview,
        *,
        starts: Sequence[int] | npt.NDArray[np.int64],
        stops: Sequence[int] | npt.NDArray[np.int64],
        log_times_ns: Sequence[int] | npt.NDArray[np.int64],
        encoding: Encoding,
        stride: int | None = None,
    ) -> None:
        self.buffer = buffer
        self.stride = stride
        self.starts = starts
        self.stops = stops
        self.log_times_ns = log_times_ns
        self.encoding = encoding
        self.memo: dict[object, Any] = {}

    def __len__(self) -> int:
        return len(self.starts)


@dataclass(frozen=True, slots=True, kw_only=True)
class LogMessage:
    """One message of a log.

    Attributes:
        topic: the topic.
        msgtype: ROS 2 style type name.
        log_time_ns: when the recorder received it (bag / MCAP log time), int ns.
        encoding: ``ros1`` / ``cdr`` for serialised bytes in ``raw``; ``native`` when ``payload``
            already holds the decoded value (KITTI).
        raw: the serialised message (empty for native messages).  May be a view into a chunk
            buffer: copy it if you keep it beyond the next message.
        payload: the decoded value for native messages, else None.
        batch: (the batch, this message's index in it) when the reader read it together with
            others (:class:`MessageBatch`); set by the reader, never by ``__init__``, and not
            carried over by ``dataclasses.replace`` (a changed copy is decoded on its own).
    """

    topic: str
    msgtype: str
    log_time_ns: int
    encoding: Encoding
    raw: bytes | memoryview = b""
    payload: object | None = None
    batch: tuple[MessageBatch, int] | None = field(
        default=None, init=False, repr=False, compare=False
    )

    @property
    def size_bytes(self) -> int:
        return len(self.raw)


@dataclass(frozen=True, slots=True, kw_only=True)
class ReaderCapabilities:
    """What an opened log can provide.

    Attributes:
        message_typed: its messages are serialised ROS messages (``deserialize`` gives ROS
            message objects, topics have ROS types); False: it yields redrive data-model values
            directly (``native`` messages holding a :class:`~redrive.io.ros.decoders.Decoded`).
        has_tf: it carries transforms (``/tf_static``, ``/tf`` or a calibration the reader turns
            into them): sensors can be placed on the vehicle.
        has_ground_truth: it carries ground-truth objects (labels, a simulator's objects).
        has_ego_pose: it carries the ego vehicle's motion (odometry, poses).
        calibration_per_frame: its sensor calibration may change from frame to frame (KITTI's
            object set: every frame its own calib file), so calibrations are looked up by stamp.
        road_map: the reader can be asked for the log's road map (it has ``road_map()``, which
            gives None when this log holds none): :func:`redrive.io.content.log_road_map`.
        scenario: the reader can say what the log was synthesized from (``scenario()``):
            :func:`redrive.io.content.log_scenario`.
        traffic_lights: it carries the states of traffic lights (``TrafficData`` messages).
        contents: the reader can count what the log holds beside its topics (annotated sweeps,
            tracks, lanes …: ``contents()``): :func:`redrive.io.content.log_contents`, which
            ``redrive info`` prints.
        goal: the log sets the ego a goal on its road map (a CommonRoad planning problem: the
            lanes to reach, ``goal_lane_ids()``): :func:`redrive.io.content.log_goal_lanes`.
    """

    message_typed: bool
    has_tf: bool
    has_ground_truth: bool
    has_ego_pose: bool
    calibration_per_frame: bool = False
    road_map: bool = False
    scenario: bool = False
    traffic_lights: bool = False
    contents: bool = False
    goal: bool = False


@runtime_checkable
class LogReader(Protocol):
    """The interface of every reader :func:`redrive.io.open_log` returns.

    Readers are context managers; ``messages`` streams with bounded memory whatever the log size.
    """

    path: Path
    #: the format's name in the reader registry (:mod:`redrive.io.readers`): ``ros1``, ``ros2``,
    #: ``mcap``, ``kitti``, ``nuscenes``, ``nuscenes-mmdet3d`` or a plugin's.
    format: str

    @property
    def capabilities(self) -> ReaderCapabilities:
        """What this log can provide (ask this, not the format name)."""
        ...

    @property
    def topics(self) -> Mapping[str, TopicInfo]: ...

    @property
    def start_ns(self) -> int: ...

    @property
    def end_ns(self) -> int:
        """Log time of the last message (inclusive)."""
        ...

    @property
    def message_count(self) -> int: ...

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        """Messages in log-time order, only ``topics`` (all when None), ``start_ns <= t < stop_ns``.

        Starting at ``start_ns`` seeks through the log's index; it does not read what comes before.
        """
        ...

    def deserialize(self, message: LogMessage) -> object:
        """The ROS message object (a rosbags dataclass) of a serialised message.

        Raises:
            UnsupportedMessageError: the type has no definition, or the bytes do not parse.
        """
        ...

    def close(self) -> None: ...

    def __enter__(self) -> Self: ...

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None: ...
