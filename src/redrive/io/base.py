"""What every log reader offers: topics, a time range and a stream of messages.

A reader yields :class:`LogMessage` records in log-time order.  Messages from ROS logs carry their
serialised bytes (``encoding`` ``ros1`` or ``cdr``) and are decoded on demand by
:mod:`redrive.io.decoders`; readers of non-ROS layouts (KITTI) yield already-decoded payloads
(``encoding == "native"``).
"""

from __future__ import annotations

from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Literal, Protocol, Self, runtime_checkable

__all__ = ["Encoding", "LogMessage", "LogReader", "TopicInfo", "normalize_msgtype"]

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
    """

    topic: str
    msgtype: str
    count: int
    size_bytes: int = -1
    encoding: Encoding
    has_definition: bool = True


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
    """

    topic: str
    msgtype: str
    log_time_ns: int
    encoding: Encoding
    raw: bytes | memoryview = b""
    payload: object | None = None

    @property
    def size_bytes(self) -> int:
        return len(self.raw)


@runtime_checkable
class LogReader(Protocol):
    """The interface of every reader :func:`redrive.io.open_log` returns.

    Readers are context managers; ``messages`` streams with bounded memory whatever the log size.
    """

    path: Path
    #: short format name: ``ros1``, ``ros2-sqlite3``, ``ros2-mcap``, ``mcap``, ``kitti``.
    format: str

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
