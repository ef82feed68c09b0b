"""What the readers of recorded-traffic datasets share (Argoverse 2, Waymo Open Motion,
CommonRoad): a schedule of native messages streamed as a log.

A reader builds, at open, one :class:`NativeStep` per time step — its stamp and the
``(topic, loader)`` of each message in the order they are yielded — and the
:class:`~redrive.io.base.TopicInfo` of every topic; :class:`NativeLogBase` streams them
(``messages`` with topic and time filters, the summary properties, the context manager).  A
loader runs only when its message is yielded, so a reader may keep its files closed until then.

A loader that meets a damaged file (a cut LiDAR sweep) raises :class:`~redrive.errors.LogError`;
opened with ``strict=True`` the stream then ends with :class:`~redrive.errors.LogDamagedError`
after every message before it, with ``strict=False`` the message is skipped, a warning logged
and the first such damage kept in ``damage`` (which ``redrive info`` reports).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType, TracebackType
from typing import Self

from redrive.errors import LogDamagedError, LogError, UnsupportedMessageError
from redrive.io.base import DecodedKind, LogMessage, ReaderCapabilities, TopicInfo
from redrive.io.ros.decoders.base import Decoded, DecodedValue
from redrive.types import SensorType

__all__ = ["NativeLogBase", "NativeStep", "decoded", "native_topics"]

logger = logging.getLogger(__name__)

#: (topic, loader of its Decoded value)
Loader = Callable[[], Decoded]


@dataclass(frozen=True, slots=True, kw_only=True)
class NativeStep:
    """The messages of one time step: their log time and (topic, loader) in yield order."""

    stamp_ns: int
    messages: tuple[tuple[str, Loader], ...]


def decoded(stamp_ns: int, frame_id: str, value: DecodedValue) -> Decoded:
    """A native message's payload."""
    return Decoded(stamp_ns=stamp_ns, frame_id=frame_id, value=value)


#: the topics of a recorded-traffic log (WOMD, CommonRoad): the ego, every agent as ground
#: truth, the signals' states
TOPIC_EGO_POSE = "/ego_pose"
TOPIC_OBJECTS = "/objects"
TOPIC_TRAFFIC_LIGHTS = "/traffic_lights"
#: their ``native_topics`` table
TRAFFIC_TOPIC_KINDS: Mapping[str, tuple[str, DecodedKind, SensorType | None]] = MappingProxyType(
    {
        TOPIC_EGO_POSE: ("redrive/VehicleState", DecodedKind.VEHICLE_STATE, None),
        TOPIC_OBJECTS: ("redrive/GroundTruthObjects", DecodedKind.OBJECTS, None),
        TOPIC_TRAFFIC_LIGHTS: ("redrive/TrafficData", DecodedKind.TRAFFIC_LIGHTS, None),
    }
)


def native_topics(
    steps: Sequence[NativeStep],
    kinds: Mapping[str, tuple[str, DecodedKind, SensorType | None]],
) -> Mapping[str, TopicInfo]:
    """The TopicInfo of every topic of ``kinds`` (topic → msgtype, kind, sensor type) that the
    steps hold, counted, in the order of ``kinds``."""
    counts: dict[str, int] = dict.fromkeys(kinds, 0)
    for step in steps:
        for topic, _ in step.messages:
            counts[topic] += 1
    return MappingProxyType(
        {
            topic: TopicInfo(
                topic=topic,
                msgtype=m,
                count=counts[topic],
                encoding="native",
                kind=k,
                sensor_type=st,
            )
            for topic, (m, k, st) in kinds.items()
            if counts[topic]
        }
    )


class NativeLogBase:
    """Streams :class:`NativeStep` values as a native log.  Subclasses set ``path``,
    ``format``, ``description``, ``_steps`` (stamp order), ``_topics`` and ``capabilities``."""

    format: str
    description: str
    path: Path
    capabilities: ReaderCapabilities
    strict: bool = True
    #: the first damage a ``strict=False`` read skipped, else None
    damage: str | None = None
    _steps: Sequence[NativeStep]
    _topics: Mapping[str, TopicInfo]

    @property
    def topics(self) -> Mapping[str, TopicInfo]:
        return self._topics

    @property
    def start_ns(self) -> int:
        return self._steps[0].stamp_ns if self._steps else 0

    @property
    def end_ns(self) -> int:
        return self._steps[-1].stamp_ns if self._steps else 0

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        wanted = None if topics is None else set(topics)
        yielded = 0
        for step in self._steps:
            stamp_ns = step.stamp_ns
            if start_ns is not None and stamp_ns < start_ns:
                continue
            if stop_ns is not None and stamp_ns >= stop_ns:
                break
            for topic, load in step.messages:
                if wanted is not None and topic not in wanted:
                    continue
                try:
                    payload = load()
                except LogError as err:
                    if self.strict:
                        raise LogDamagedError(str(err), messages_read=yielded) from err
                    logger.warning("%s; the message is skipped", err)
                    self.damage = self.damage or str(err)
                    continue
                yielded += 1
                yield LogMessage(
                    topic=topic,
                    msgtype=self._topics[topic].msgtype,
                    log_time_ns=stamp_ns,
                    encoding="native",
                    payload=payload,
                )

    def deserialize(self, message: LogMessage) -> object:
        """These messages are already decoded (``message.payload``); there are no ROS bytes.

        Raises:
            UnsupportedMessageError: always.
        """
        msg = (
            f"{self.path}: topic {message.topic} at {message.log_time_ns} ns is a native "
            f"{self.format} message; use message.payload (a Decoded) instead of deserialize()"
        )
        raise UnsupportedMessageError(msg)

    def close(self) -> None:
        """Nothing is held open."""

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
