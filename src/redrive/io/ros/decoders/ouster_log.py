"""A log with a point-cloud topic beside each of its Ouster lidar packet topics.

``ouster_ros`` records the sensor's UDP packets as they came (``ouster_ros/PacketMsg``, ROS 2
``ouster_sensor_msgs/msg/PacketMsg``: one ``uint8[] buf``) on ``…/lidar_packets`` and the sensor
metadata JSON once on ``…/metadata`` (``std_msgs/String``, latched).  A packet holds 16 columns of
a frame, so no single message decodes to a cloud: :func:`with_packet_clouds` wraps a reader so
that beside each such topic whose metadata is in the log there is a ``native`` LiDAR topic
``<namespace>/points`` (``/os_node0/points`` for ``/os_node0/lidar_packets``: the name ouster-ros
gives its own clouds; type ``redrive/PointCloud``) yielding one
:class:`~redrive.types.PointCloud` per frame (the packets of one frame id, see
:mod:`~redrive.io.ros.decoders.ouster_packets`).  The packet topic stays as it is, so nothing
of the log is hidden (an export copies the packets too); a log that has a topic of that name
already (the driver's clouds recorded as well) gets no second one.

* A frame's message is yielded when its last packet is read (the metadata's packet count
  reached) or when a packet of another frame id comes; its log time is that moment's, its stamp
  the log time of its first packet, its frame ``os_sensor`` (ouster-ros's sensor frame; the
  points are in it).
* The cloud topic's ``count`` is the packets' count over the packets a frame takes, rounded up
  (the frames the log holds when none lost packets).
* A packet of the wrong size is damage: it is left out (its columns stay empty), a warning names
  the topic, the log time, its size and the size the metadata makes, and
  ``packet_damage[topic]`` counts them.  A packet topic whose metadata is missing or does not
  parse gets no cloud topic, with a warning saying why.

Everything else — the other topics, ``deserialize``, the damage report, ``road_map`` … — is the
wrapped reader's.  ``open_log(path, packets="raw")`` skips the wrapping (converting, repairing
and counting what was recorded see the file's own topics only).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType, TracebackType
from typing import Any, Self

from redrive.errors import LogError, UnsupportedMessageError
from redrive.io.base import (
    DecodedKind,
    LogMessage,
    LogReader,
    ReaderCapabilities,
    TopicInfo,
    normalize_msgtype,
)
from redrive.io.ros.decoders.base import Decoded
from redrive.io.ros.decoders.ouster_metadata import parse_metadata
from redrive.io.ros.decoders.ouster_packets import OusterPacketFormat
from redrive.types import SensorType

__all__ = ["CLOUD_MSGTYPE", "PACKET_MSGTYPES", "PacketCloudsReader", "with_packet_clouds"]

logger = logging.getLogger(__name__)

#: The ouster-ros packet message types (ROS 1 and ROS 2 names).
PACKET_MSGTYPES = frozenset({"ouster_ros/msg/PacketMsg", "ouster_sensor_msgs/msg/PacketMsg"})
#: The type name of the cloud topics (as the dataset readers name their native clouds).
CLOUD_MSGTYPE = "redrive/PointCloud"
_STRING = "std_msgs/msg/String"
_SENSOR_FRAME = "os_sensor"
#: read this long before a seek's start so the frame running at the start is whole.
_SEEK_MARGIN_NS = 200_000_000


@dataclass(slots=True)
class _Source:
    topic: str  # the packets'
    cloud_topic: str
    metadata_topic: str
    fmt: OusterPacketFormat


@dataclass(slots=True)
class _Pending:
    frame_id: int
    first_log_ns: int
    packets: list[bytes] = field(default_factory=list)


def _metadata_topic(log: LogReader, topic: str) -> str | None:
    namespace = topic.rsplit("/", 1)[0]
    for name in (f"{namespace}/metadata", f"{namespace}/os_node/metadata"):
        info = log.topics.get(name)
        if info is not None and normalize_msgtype(info.msgtype) == _STRING:
            return name
    return None


def _find_sources(log: LogReader) -> dict[str, _Source]:
    sources: dict[str, _Source] = {}
    for topic, info in log.topics.items():
        if normalize_msgtype(info.msgtype) not in PACKET_MSGTYPES or info.encoding == "native":
            continue
        if not topic.endswith("lidar_packets"):
            continue  # imu_packets: the same type, not lidar data
        meta_topic = _metadata_topic(log, topic)
        if meta_topic is None:
            logger.warning(
                "%s: %s holds Ouster lidar packets but the log has no metadata topic "
                "(std_msgs/String …/metadata) beside it: it is not decoded",
                log.path,
                topic,
            )
            continue
        try:
            text = _first_string(log, meta_topic)
            fmt = OusterPacketFormat(parse_metadata(text))
        except (ValueError, UnsupportedMessageError, LogError) as err:
            logger.warning(
                "%s: %s is not decoded: its metadata (%s) cannot be used: %s",
                log.path,
                topic,
                meta_topic,
                err,
            )
            continue
        cloud_topic = f"{topic.rsplit('/', 1)[0]}/points"
        if cloud_topic in log.topics:
            logger.info(
                "%s: %s is in the log already: %s is not decoded", log.path, cloud_topic, topic
            )
            continue
        sources[cloud_topic] = _Source(topic, cloud_topic, meta_topic, fmt)
    return sources


def _first_string(log: LogReader, topic: str) -> str:
    for message in log.messages(topics=[topic]):
        value: Any = log.deserialize(message)
        return str(value.data)
    msg = f"{topic} has no message"
    raise ValueError(msg)


def with_packet_clouds(log: LogReader) -> LogReader:
    """``log`` with a cloud topic beside each of its Ouster lidar packet topics; ``log`` itself
    when it has none that can be decoded."""
    if not any(normalize_msgtype(i.msgtype) in PACKET_MSGTYPES for i in log.topics.values()):
        return log
    sources = _find_sources(log)
    return PacketCloudsReader(log, sources) if sources else log


class PacketCloudsReader:
    """A reader with cloud topics made of Ouster packet topics (see the module docstring).

    Attributes:
        cloud_topics: cloud topic → the packet topic it is made of.
        packet_damage: packet topic → damaged packets met.
    """

    def __init__(self, inner: LogReader, sources: Mapping[str, _Source]) -> None:
        self.inner = inner
        self.path = inner.path
        self.format = inner.format
        self._sources = dict(sources)
        self.packet_damage: dict[str, int] = {}
        topics = dict(inner.topics)
        for cloud_topic, source in self._sources.items():
            info = topics[source.topic]
            frames = math.ceil(info.count / source.fmt.packets_per_frame) if info.count else 0
            topics[cloud_topic] = TopicInfo(
                topic=cloud_topic,
                msgtype=CLOUD_MSGTYPE,
                count=frames,
                encoding="native",
                has_definition=True,
                kind=DecodedKind.SENSOR,
                sensor_type=SensorType.LIDAR,
            )
        self.cloud_topics = {c: s.topic for c, s in self._sources.items()}
        self._topics = MappingProxyType(topics)

    # --- what the wrapped reader says -------------------------------------------------------
    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    @property
    def capabilities(self) -> ReaderCapabilities:
        return self.inner.capabilities

    @property
    def topics(self) -> Mapping[str, TopicInfo]:
        return self._topics

    @property
    def start_ns(self) -> int:
        return self.inner.start_ns

    @property
    def end_ns(self) -> int:
        return self.inner.end_ns

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    def deserialize(self, message: LogMessage) -> object:
        if message.encoding == "native":
            msg = f"{message.topic}: its messages are decoded clouds (payload), not ROS messages"
            raise UnsupportedMessageError(msg)
        return self.inner.deserialize(message)

    def close(self) -> None:
        self.inner.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # --- the frames -----------------------------------------------------------------------------
    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        wanted = set(self._topics) if topics is None else set(topics)
        clouds = {c: self._sources[c] for c in wanted if c in self._sources}
        by_packets = {s.topic: s for s in clouds.values()}
        to_read = (wanted - set(clouds)) | set(by_packets)
        read_from = None if start_ns is None or not clouds else start_ns - _SEEK_MARGIN_NS
        pending: dict[str, _Pending] = {}
        for message in self.inner.messages(topics=to_read, start_ns=read_from, stop_ns=stop_ns):
            if message.topic in wanted and (start_ns is None or message.log_time_ns >= start_ns):
                yield message
            source = by_packets.get(message.topic)
            if source is None:
                continue
            for frame in self._add(source, pending, message):
                if start_ns is None or frame.log_time_ns >= start_ns:
                    yield frame
        for cloud_topic, open_frame in pending.items():
            source = self._sources[cloud_topic]
            last = self.inner.end_ns if stop_ns is None else min(self.inner.end_ns, stop_ns - 1)
            yield self._frame(source, open_frame, max(last, open_frame.first_log_ns))

    def _add(
        self, source: _Source, pending: dict[str, _Pending], message: LogMessage
    ) -> list[LogMessage]:
        fmt = source.fmt
        buf = _packet_buf(message, self.inner)
        if buf is None or (problem := fmt.check(buf)) is not None:
            what = "a packet message that does not deserialise" if buf is None else problem
            self._damaged(source.topic, f"{what}, at log time {message.log_time_ns} ns")
            return []
        out: list[LogMessage] = []
        frame_id = fmt.frame_id(buf)
        current = pending.get(source.cloud_topic)
        if current is not None and current.frame_id != frame_id:
            out.append(self._frame(source, current, message.log_time_ns))
            current = None
        if current is None:
            current = pending[source.cloud_topic] = _Pending(frame_id, message.log_time_ns)
        current.packets.append(buf)
        if len(current.packets) >= fmt.packets_per_frame:
            out.append(self._frame(source, current, message.log_time_ns))
            del pending[source.cloud_topic]
        return out

    def _frame(self, source: _Source, frame: _Pending, log_time_ns: int) -> LogMessage:
        cloud = source.fmt.cloud(source.fmt.decode(frame.packets))
        decoded = Decoded(stamp_ns=frame.first_log_ns, frame_id=_SENSOR_FRAME, value=cloud)
        return LogMessage(
            topic=source.cloud_topic,
            msgtype=CLOUD_MSGTYPE,
            log_time_ns=log_time_ns,
            encoding="native",
            payload=decoded,
        )

    def _damaged(self, topic: str, what: str) -> None:
        count = self.packet_damage.get(topic, 0) + 1
        self.packet_damage[topic] = count
        if count == 1:
            logger.warning(
                "%s: %s: %s; the packet is left out (further damaged packets on this topic are "
                "counted in packet_damage, not logged)",
                self.inner.path,
                topic,
                what,
            )


def _packet_buf(message: LogMessage, log: LogReader) -> bytes | None:
    """The ``buf`` of a PacketMsg, or None when the message does not deserialise."""
    try:
        value: Any = log.deserialize(message)
    except UnsupportedMessageError:
        return None
    return bytes(memoryview(value.buf).cast("B"))
