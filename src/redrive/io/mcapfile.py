"""Standalone MCAP files with ROS 2 (CDR) or ROS 1 message encodings, read with ``mcap``.

Message bytes are deserialised with ``rosbags`` typestores built from the schemas the file embeds
(``ros2msg``, ``ros2idl`` or ``ros1msg``), so one deserialiser serves every log format.
"""

from __future__ import annotations

import logging
from collections.abc import Collection, Iterator, Mapping
from pathlib import Path
from typing import IO, Any, Literal

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader

from redrive.errors import LogError, LogTruncatedError
from redrive.io._deserialize import Deserializer
from redrive.io._reader_base import RosReaderBase
from redrive.io.base import Encoding, LogMessage, TopicInfo, normalize_msgtype
from redrive.io.recognise import starts_with
from redrive.io.typestore import typestore_for

__all__ = ["McapFileReader"]

logger = logging.getLogger(__name__)


_MAGIC = b"\x89MCAP0\r\n"
_ENCODINGS: Mapping[str, Encoding] = {"cdr": "cdr", "ros1": "ros1"}


class McapFileReader(RosReaderBase):
    """A standalone ``.mcap`` file.

    Uses the summary section (indexes, statistics) when present; a file without one — cut off, or
    written without it — is read linearly, and a cut-off file yields every message before the cut.
    """

    format = "mcap"
    description = "an MCAP file (ROS 2 CDR or ROS 1 messages)"

    @classmethod
    def recognises(cls, path: Path) -> bool:
        return starts_with(path, _MAGIC[:5])  # not the version byte: __init__ explains a wrong one

    def __init__(self, path: Path, *, strict: bool = True) -> None:
        self.path = Path(path)
        self.strict = strict
        self.damage: str | None = None
        try:
            self._fh: IO[bytes] = self.path.open("rb")
        except OSError as err:
            msg = f"{self.path}: cannot open ({err.strerror}); check the path and permissions"
            raise LogError(msg) from err
        if self._fh.read(len(_MAGIC)) != _MAGIC:
            self._fh.close()
            msg = f"{self.path}: not an MCAP file (the magic bytes are missing)"
            raise LogError(msg)
        self._fh.seek(0)
        self._reader = make_reader(self._fh)
        try:
            self._summary = self._reader.get_summary()
        except (McapError, ValueError, OSError, EOFError) as err:
            self._summary = None
            self.damage = f"no readable summary section ({err})"
            logger.warning(
                "%s: %s; reading it linearly (a cut-off file yields what is before the cut)",
                self.path,
                self.damage,
            )
        self._channels: dict[int, tuple[str, str, Encoding]] = {}
        self._counts: dict[int, int] = {}
        self._sizes: dict[int, int] = {}
        self._start_ns = self._end_ns = 0
        defs: dict[Literal[1, 2], dict[str, tuple[str, str]]] = {1: {}, 2: {}}
        if self._summary is not None and self._summary.statistics is not None:
            for schema in self._summary.schemas.values():
                self._add_schema(defs, schema)
            for channel in self._summary.channels.values():
                self._add_channel(channel, self._summary.schemas.get(channel.schema_id))
            stats = self._summary.statistics
            self._counts = dict(stats.channel_message_counts)
            self._start_ns, self._end_ns = (
                int(stats.message_start_time),
                int(stats.message_end_time),
            )
        else:
            self._scan(defs)
        used = {
            enc: {t for _, t, e in self._channels.values() if e == enc} for enc in ("ros1", "cdr")
        }
        self._deserializer = Deserializer(
            self.path,
            ros1=typestore_for(1, defs[1], needed=used["ros1"])[0] if defs[1] else None,
            cdr=(
                typestore_for(2, defs[2], needed=used["cdr"])[0] if defs[2] or not defs[1] else None
            ),
        )
        self._topics = self._summarise()

    def _add_schema(
        self, defs: dict[Literal[1, 2], dict[str, tuple[str, str]]], schema: Any
    ) -> None:
        text = bytes(schema.data).decode("utf-8", "replace")
        name = normalize_msgtype(schema.name)
        if schema.encoding == "ros2msg":
            defs[2][name] = ("msg", text)
        elif schema.encoding == "ros2idl":
            defs[2][name] = ("idl", text)
        elif schema.encoding == "ros1msg":
            defs[1][name] = ("msg", text)

    def _add_channel(self, channel: Any, schema: Any) -> None:
        encoding = _ENCODINGS.get(channel.message_encoding)
        if encoding is None:
            logger.warning(
                "%s: topic %s uses message encoding %r, which redrive does not read; skipping it",
                self.path,
                channel.topic,
                channel.message_encoding,
            )
            return
        msgtype = normalize_msgtype(schema.name) if schema is not None else "unknown"
        self._channels[channel.id] = (channel.topic, msgtype, encoding)

    def _scan(self, defs: dict[Literal[1, 2], dict[str, tuple[str, str]]]) -> None:
        """One linear pass for a file without a summary: channels, counts, time range."""
        seen_schemas: set[int] = set()
        for schema, channel, message in self._linear():
            if channel.id not in self._channels:
                if schema is not None and schema.id not in seen_schemas:
                    seen_schemas.add(schema.id)
                    self._add_schema(defs, schema)
                self._add_channel(channel, schema)
            self._counts[channel.id] = self._counts.get(channel.id, 0) + 1
            self._sizes[channel.id] = self._sizes.get(channel.id, 0) + len(message.data)
            t = int(message.log_time)
            self._start_ns = (
                t
                if not any(self._counts.values()) or self._start_ns == 0
                else min(self._start_ns, t)
            )
            self._end_ns = max(self._end_ns, t)

    def _linear(self) -> Iterator[tuple[Any, Any, Any]]:
        self._fh.seek(0)
        try:
            yield from NonSeekingReader(self._fh).iter_messages(log_time_order=False)
        except (McapError, ValueError, OSError, EOFError) as err:
            at = self._fh.tell()
            self.damage = f"cut off or damaged near byte {at} ({type(err).__name__}: {err})"
            logger.warning("%s: %s; messages from there on are lost", self.path, self.damage)

    def _summarise(self) -> dict[str, TopicInfo]:
        out: dict[str, TopicInfo] = {}
        for cid, (topic, msgtype, encoding) in self._channels.items():
            prev = out.get(topic)
            out[topic] = TopicInfo(
                topic=topic,
                msgtype=msgtype,
                count=self._counts.get(cid, 0) + (prev.count if prev else 0),
                size_bytes=self._sizes.get(cid, -1) if self._sizes else -1,
                encoding=encoding,
                has_definition=self._deserializer.knows(msgtype, encoding),
            )
        return dict(sorted(out.items()))

    @property
    def start_ns(self) -> int:
        return self._start_ns

    @property
    def end_ns(self) -> int:
        return self._end_ns

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        wanted = None if topics is None else set(topics)
        count = 0
        if self._summary is not None and self._summary.chunk_indexes:
            source = self._reader.iter_messages(
                topics=None if wanted is None else sorted(wanted),
                starting_at=start_ns,
                ending_before=stop_ns,
                log_time_order=True,
            )
        else:
            source = self._linear()
        try:
            for _, channel, message in source:
                info = self._channels.get(channel.id)
                if info is None:
                    continue
                topic, msgtype, encoding = info
                t = int(message.log_time)
                if (wanted is not None and topic not in wanted) or (
                    (start_ns is not None and t < start_ns)
                    or (stop_ns is not None and t >= stop_ns)
                ):
                    continue
                count += 1
                yield LogMessage(
                    topic=topic, msgtype=msgtype, log_time_ns=t, encoding=encoding, raw=message.data
                )
        except (McapError, ValueError, OSError, EOFError) as err:
            self.damage = f"reading stopped after {count} messages ({type(err).__name__}: {err})"
            if self.strict:
                msg = f"{self.path}: {self.damage}; the file may be damaged"
                raise LogTruncatedError(msg, messages_read=count) from err
            logger.warning("%s: %s", self.path, self.damage)
        if (
            self.strict
            and self.damage is not None
            and self._summary is None
            and "cut off" in self.damage
        ):
            msg = f"{self.path}: {self.damage}; {count} messages were read before it"
            raise LogTruncatedError(msg, messages_read=count)

    def metadata(self, name: str) -> Mapping[str, str] | None:
        """The first metadata record called ``name`` (MCAP ``Metadata``: string pairs), or None.

        A reader of a format without named metadata has no such method (callers use
        ``getattr``); a damaged file's unreadable records count as absent.
        """
        try:
            for record in self._reader.iter_metadata():
                if record.name == name:
                    return dict(record.metadata)
        except Exception as err:  # the index or record is damaged: there is no such metadata
            logger.warning("%s: metadata %r unreadable (%s)", self.path, name, err)
        return None

    def close(self) -> None:
        self._fh.close()
