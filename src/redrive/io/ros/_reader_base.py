"""What the ROS log readers share: topic summary, typestores, deserialising, context manager."""

from __future__ import annotations

from collections.abc import Mapping
from types import TracebackType
from typing import Self

from rosbags.typesys.store import Typestore

from redrive.io.base import LogMessage, ReaderCapabilities, TopicInfo
from redrive.io.ros.deserialize import Deserializer

__all__ = ["RosReaderBase"]


class RosReaderBase:
    """Subclasses set ``_topics`` and ``_deserializer`` while opening and implement ``close``."""

    _topics: Mapping[str, TopicInfo]
    _deserializer: Deserializer

    @property
    def topics(self) -> Mapping[str, TopicInfo]:
        return self._topics

    @property
    def capabilities(self) -> ReaderCapabilities:
        """From the topics: transforms, objects (ground truth) and ego motion it carries."""
        from redrive.io.ros.decoders import capabilities_of  # decoders import the readers' base

        return capabilities_of(self._topics.values(), message_typed=True)

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self._topics.values())

    @property
    def typestores(self) -> Mapping[str, Typestore]:
        """Encoding → the rosbags typestore this log's messages are deserialised with."""
        return self._deserializer.typestores

    def deserialize(self, message: LogMessage) -> object:
        return self._deserializer(message)

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
