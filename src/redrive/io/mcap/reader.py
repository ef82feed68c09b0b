"""Standalone MCAP files with ROS 2 (CDR) or ROS 1 message encodings.

The summary section (schemas, channels, statistics, chunk indexes) is read with ``mcap``; chunks
are read and checked with :mod:`redrive.io.mcap.scan`, so a damaged chunk is skipped (and
reported) rather than ending the read.  A file without a usable summary — cut off, or written
without one — is read with a forward scan of its records, which resumes after any damage.

Message bytes are deserialised with ``rosbags`` typestores built from the schemas the file embeds
(``ros2msg``, ``ros2idl`` or ``ros1msg``), so one deserialiser serves every log format.
"""

from __future__ import annotations

import heapq
import logging
import mmap
from collections.abc import Collection, Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import IO, Any, Literal, cast

from mcap.reader import make_reader
from mcap.summary import Summary

from redrive.errors import LogError
from redrive.io.base import Encoding, LogMessage, ReaderCapabilities, TopicInfo, normalize_msgtype
from redrive.io.content import LogScenario
from redrive.io.damage import DamageLog, LogDamage
from redrive.io.limits import max_chunk_bytes as chunk_budget
from redrive.io.mcap._prefetch import prefetched
from redrive.io.mcap.forward import McapScan
from redrive.io.mcap.metadata import MAP_METADATA, SCENARIO_METADATA, road_map_in, scenario_in
from redrive.io.mcap.records import summary_crc_ok
from redrive.io.mcap.scan import (
    OP_CHUNK,
    ChunkHead,
    McapChannel,
    McapMetadata,
    McapSchema,
    Message,
    RecordError,
    ScanEvent,
    chunk_head,
    message_index_count,
    read_chunk,
)
from redrive.io.recognise import starts_with
from redrive.io.ros._reader_base import RosReaderBase
from redrive.io.ros.deserialize import Deserializer
from redrive.io.ros.typestore import typestore_for
from redrive.types import RoadMap

__all__ = ["McapFileReader"]

logger = logging.getLogger(__name__)


_MAGIC = b"\x89MCAP0\r\n"
_ENCODINGS: Mapping[str, Encoding] = {"cdr": "cdr", "ros1": "ros1"}


class McapFileReader(RosReaderBase):
    """A standalone ``.mcap`` file (see the module text).

    Args:
        path: the file.
        strict: when True, reading stops at the first damage with
            :class:`~redrive.errors.LogDamagedError` (every message before it was yielded); when
            False the damage is skipped and listed in :attr:`damage_report`.
        max_chunk_bytes: the most bytes one chunk is decompressed to; one declaring more is
            damage, its first messages read (default: :func:`redrive.io.limits.max_chunk_bytes`,
            256 MiB or ``REDRIVE_MAX_CHUNK_BYTES``).

    Attributes:
        damage_report: the damage met so far (found while opening a file without a summary, or
            while reading).
        indexed: whether the summary's chunk indexes are used (False: forward scan).
    """

    format = "mcap"
    description = "an MCAP file (ROS 2 CDR or ROS 1 messages)"

    @classmethod
    def recognises(cls, path: Path) -> bool:
        return starts_with(path, _MAGIC[:5])  # not the version byte: __init__ explains a wrong one

    def __init__(
        self, path: Path, *, strict: bool = True, max_chunk_bytes: int | None = None
    ) -> None:
        self.path = Path(path)
        self.strict = strict
        self._budget = chunk_budget(max_chunk_bytes)
        self._damage = DamageLog(self.path, strict=strict)
        try:
            self._fh: IO[bytes] = self.path.open("rb")
            self._size = self.path.stat().st_size
        except OSError as err:
            msg = f"{self.path}: cannot open ({err.strerror}); check the path and permissions"
            raise LogError(msg) from err
        if self._fh.read(len(_MAGIC)) != _MAGIC:
            self._fh.close()
            msg = f"{self.path}: not an MCAP file (the magic bytes are missing)"
            raise LogError(msg)
        if self._size <= len(_MAGIC):
            self._fh.close()
            msg = (
                f"{self.path}: the file holds only the {self._size}-byte MCAP magic: no header, "
                "no record, no message — an empty log (a recorder that stopped right after "
                "opening it, or a copy cut off at its start); there is nothing to read or repair"
            )
            raise LogError(msg)
        self._map = mmap.mmap(self._fh.fileno(), 0, access=mmap.ACCESS_READ)
        self._buf = memoryview(self._map)
        self._summary = self._read_summary()
        self.indexed = self._summary is not None and bool(self._summary.chunk_indexes)
        self._channels: dict[int, tuple[str, str, Encoding]] = {}
        self._counts: dict[int, int] = {}
        # a file read by a forward scan: chunk position → the earliest start time of it and of
        # every chunk after it in the file (how a scan restores log-time order)
        self._chunk_floors: dict[int, int] = {}
        self._sizes: dict[int, int] = {}
        self._metadata: list[McapMetadata] | None = None
        # the schemas and channels a forward scan met (a file read without its summary)
        self._scan_records: tuple[dict[int, McapSchema], dict[int, McapChannel]] = ({}, {})
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
            ros1=typestore_for(1, defs[1], needed=used["ros1"], source=self.path)[0]
            if defs[1]
            else None,
            cdr=(
                typestore_for(2, defs[2], needed=used["cdr"], source=self.path)[0]
                if defs[2] or not defs[1]
                else None
            ),
        )
        self._topics = self._summarise()

    def scan(self) -> Iterator[ScanEvent]:
        """Every intact record of the file and every damage, in file order (a forward scan:
        see :class:`~redrive.io.mcap.forward.McapScan`); ``redrive repair`` copies from it."""
        return McapScan(self._buf, self._budget).events()

    def known_records(self) -> tuple[dict[int, McapSchema], dict[int, McapChannel]]:
        """The schemas and channels of the summary section (of the whole file's forward scan when
        the summary is not used): what a message means when the schema or channel record before
        it is damaged."""
        if self._summary is None:
            return dict(self._scan_records[0]), dict(self._scan_records[1])
        schemas = {
            sid: McapSchema(sid, s.name, s.encoding, bytes(s.data))
            for sid, s in self._summary.schemas.items()
        }
        channels = {
            cid: McapChannel(cid, c.schema_id, c.topic, c.message_encoding, dict(c.metadata))
            for cid, c in self._summary.channels.items()
        }
        return schemas, channels

    @property
    def damage_report(self) -> tuple[LogDamage, ...]:
        return tuple(self._damage.items)

    @property
    def damage(self) -> str | None:
        """The damage met so far, as one line (None while none was met)."""
        return "; ".join(str(d) for d in self._damage.items) or None

    def _read_summary(self) -> Summary | None:
        """The summary section, or None when it is missing or does not fit the file."""
        self._fh.seek(0)
        try:
            summary = make_reader(self._fh).get_summary()
        except Exception as err:  # mcap raises struct.error, EndOfFile, McapError … on damage
            logger.debug("%s: no summary (%s: %s)", self.path, type(err).__name__, err)
            self._damage.add(
                LogDamage(
                    what="the summary section (the index at the end) is missing or unreadable; "
                    "the file was read with a forward scan",
                    messages_lost=0,
                )
            )
            return None
        if summary is None:
            return None  # written without one: nothing is damaged
        if not summary_crc_ok(self._buf):
            self._damage.add(
                LogDamage(
                    what="the summary section (the index at the end) fails its CRC check; the "
                    "file was read with a forward scan",
                    messages_lost=0,
                )
            )
            return None
        for index in summary.chunk_indexes:
            end = index.chunk_start_offset + index.chunk_length
            if end > self._size or self._buf[index.chunk_start_offset] != OP_CHUNK:
                self._damage.add(
                    LogDamage(
                        what=f"the summary's chunk index points at byte "
                        f"{index.chunk_start_offset}, where no chunk is; the file was read "
                        "with a forward scan",
                        messages_lost=0,
                    )
                )
                return None
        return summary

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
        """One forward pass for a file without a usable summary: channels, counts, time range,
        metadata and damage."""
        schemas: dict[int, McapSchema] = {}
        seen_channels: dict[int, McapChannel] = {}
        self._scan_records = (schemas, seen_channels)
        self._metadata = []
        unsized: set[int] = set()
        first = True
        starts: list[tuple[int, int]] = []  # (position, start time) of each chunk, file order
        for kind, item in McapScan(self._buf, self._budget).events(counts_only=True):
            if kind == "chunk":
                head = cast("ChunkHead", item)
                starts.append((head.pos, head.start_time))
            elif kind == "message":
                cid, _, t, _, data = cast("Message", item)
                self._counts[cid] = self._counts.get(cid, 0) + 1
                self._sizes[cid] = self._sizes.get(cid, 0) + len(data)
                self._start_ns = t if first else min(self._start_ns, t)
                self._end_ns = max(self._end_ns, t)
                first = False
            elif kind == "counts":  # a chunk not decompressed: its index's counts and times
                listed, t0, t1 = cast("tuple[dict[int, int], int, int]", item)
                for cid, n in listed.items():
                    self._counts[cid] = self._counts.get(cid, 0) + n
                    unsized.add(cid)
                self._start_ns = t0 if first else min(self._start_ns, t0)
                self._end_ns = max(self._end_ns, t1)
                first = False
            elif kind == "schema":
                assert isinstance(item, McapSchema)
                if item.id not in schemas:
                    schemas[item.id] = item
                    self._add_schema(defs, item)
            elif kind == "channel":
                assert isinstance(item, McapChannel)
                if item.id not in seen_channels:
                    seen_channels[item.id] = item
                    self._add_channel(item, schemas.get(item.schema_id))
            elif kind == "metadata":
                assert isinstance(item, McapMetadata)
                self._metadata.append(item)
            elif kind == "damage":
                assert isinstance(item, LogDamage)
                self._damage.add(item)
        floor = None
        for pos, start in reversed(starts):
            floor = start if floor is None else min(floor, start)
            self._chunk_floors[pos] = floor
        for cid in unsized:  # bytes unknown without decompressing (-1 in the topic info)
            self._sizes.pop(cid, None)
        for cid in list(self._counts):
            if cid not in self._channels:  # messages of an unknown or unread channel
                del self._counts[cid]

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
        asked = None if topics is None else set(topics)  # a list of 50k topics: quadratic
        ids = {
            cid for cid, (topic, _, _) in self._channels.items() if asked is None or topic in asked
        }
        source = (
            self._indexed(ids, start_ns, stop_ns)
            if self.indexed
            else self._scanned(ids, start_ns, stop_ns)
        )
        channels = self._channels
        for cid, t, data in source:
            topic, msgtype, encoding = channels[cid]
            yield LogMessage(
                topic=topic, msgtype=msgtype, log_time_ns=t, encoding=encoding, raw=data
            )

    def _scanned(
        self, ids: set[int], start_ns: int | None, stop_ns: int | None
    ) -> Iterator[tuple[int, int, memoryview]]:
        """Messages from a forward scan (no summary), in log-time order.

        A file's chunks need not be in time order: a recorder compressing on a thread writes a
        chunk uncompressed while earlier ones still wait for the compressor
        (:class:`~redrive.io.mcap.stream.McapStream`), and a killed one leaves no summary. At
        each chunk the messages read so far that are earlier than any chunk still to come
        (:attr:`_chunk_floors`, from the pass that opened the file) are yielded, in time order;
        the rest wait for the chunks that may hold earlier ones.
        """
        floors = self._chunk_floors
        heap: list[tuple[int, int, int, memoryview]] = []
        order = count = 0
        for kind, item in McapScan(self._buf, self._budget).events():
            if kind == "message":
                cid, _, t, _, data = cast("Message", item)
                if (
                    cid in ids
                    and (start_ns is None or t >= start_ns)
                    and (stop_ns is None or t < stop_ns)
                ):
                    heapq.heappush(heap, (t, order, cid, data))
                    order += 1
            elif kind == "chunk":
                head = cast("ChunkHead", item)
                floor = floors.get(head.pos, head.start_time)
                while heap and heap[0][0] < floor:
                    t, _, cid, data = heapq.heappop(heap)
                    count += 1
                    yield cid, t, data
            elif kind == "damage":
                assert isinstance(item, LogDamage)
                if self._damage.strict:  # reading stops here: what was read before it comes first
                    while heap:
                        t, _, cid, data = heapq.heappop(heap)
                        count += 1
                        yield cid, t, data
                self._damage.hit(item, messages_read=count)
        while heap:
            t, _, cid, data = heapq.heappop(heap)
            count += 1
            yield cid, t, data

    def _indexed(
        self, ids: set[int], start_ns: int | None, stop_ns: int | None
    ) -> Iterator[tuple[int, int, memoryview]]:
        """Messages in log-time order, chunk by chunk from the summary's chunk indexes.

        Chunks are taken in order of their first message; a message is yielded once no chunk
        still to be read can hold an earlier one (chunks whose times overlap are merged).
        """
        assert self._summary is not None
        chunks = sorted(
            self._summary.chunk_indexes,
            key=lambda c: (c.message_start_time, c.chunk_start_offset),
        )
        wanted: list[Any] = []
        for index in chunks:
            if stop_ns is not None and index.message_start_time >= stop_ns:
                break
            if (start_ns is not None and index.message_end_time < start_ns) or (
                len(ids) < len(self._channels)  # a topic filter: skip chunks without its topics
                and index.message_index_offsets
                and not ids.intersection(index.message_index_offsets)
            ):
                continue
            wanted.append(index)
        heap: list[tuple[int, int, int, memoryview]] = []
        order = count = 0
        # The next chunks are decompressed and checked in a thread (zstd, lz4 and crc32 release
        # the GIL) while this one's messages are decoded and used.
        loads = prefetched(self._load_chunk, wanted)
        try:
            for index, loaded in zip(wanted, loads, strict=True):
                while heap and heap[0][0] < index.message_start_time:
                    t, _, cid, data = heapq.heappop(heap)
                    count += 1
                    yield cid, t, data
                for cid, _, t, _, data in self._chunk_messages(index, loaded, count):
                    if (
                        cid in ids
                        and (start_ns is None or t >= start_ns)
                        and (stop_ns is None or t < stop_ns)
                    ):
                        heapq.heappush(heap, (t, order, cid, data))
                        order += 1
        finally:
            loads.close()  # stops the thread when the caller stops early
        while heap:
            t, _, cid, data = heapq.heappop(heap)
            count += 1
            yield cid, t, data

    def _load_chunk(self, index: Any) -> tuple[list[Message], str | None, int]:
        """The messages of the chunk ``index`` points at (its intact prefix when damaged), why
        it stopped early (None when whole) and the chunk's end; no side effects, so it may run
        in the prefetch thread."""
        pos = int(index.chunk_start_offset)
        try:
            head = chunk_head(self._buf, pos, self._size)
        except RecordError as err:
            from redrive.io.mcap.salvage import repaired_chunk_head  # the failure path only

            fixed = repaired_chunk_head(self._buf, pos, self._size)
            if fixed is None:
                return [], str(err), pos + int(index.chunk_length)
            messages = read_chunk(self._buf, fixed, self._budget)[0]  # whole: its CRC checks
            return messages, f"the chunk record's length is damaged ({err}); read whole", fixed.stop
        messages, _, why = read_chunk(self._buf, head, self._budget)
        return messages, why, head.stop

    def _chunk_messages(
        self, index: Any, loaded: tuple[list[Message], str | None, int], count: int
    ) -> list[Message]:
        """The messages of a loaded chunk; damage there is hit (raised or recorded) and its
        intact prefix, if any, returned."""
        messages, why, stop = loaded
        if why is not None:
            pos = int(index.chunk_start_offset)
            listed = [
                message_index_count(self._buf, int(at), self._size)
                for at in index.message_index_offsets.values()
            ]
            lost = None if None in listed else sum(n or 0 for n in listed) - len(messages)
            self._damage.hit(
                LogDamage(what=why, start_byte=pos, stop_byte=stop, messages_lost=lost),
                messages_read=count,
            )
        return messages

    @property
    def capabilities(self) -> ReaderCapabilities:
        """As every ROS log's (from the topics), and a road map and a scenario: the metadata
        records a ``redrive synth`` log carries (:mod:`redrive.io.mcap.metadata`)."""
        return replace(super().capabilities, road_map=True, scenario=True)

    def road_map(self) -> RoadMap | None:
        """The road map of the log's :data:`~redrive.io.mcap.metadata.MAP_METADATA` record."""
        return road_map_in(self.metadata(MAP_METADATA), path=self.path)

    def scenario(self) -> LogScenario | None:
        """What the log was synthesized from (its ``SCENARIO_METADATA`` record)."""
        return scenario_in(self.metadata(SCENARIO_METADATA), path=self.path)

    def metadata(self, name: str) -> Mapping[str, str] | None:
        """The first metadata record called ``name`` (MCAP ``Metadata``: string pairs), or None;
        a damaged file's unreadable records count as absent."""
        if self._metadata is not None:  # read by the forward scan
            return next((dict(m.metadata) for m in self._metadata if m.name == name), None)
        try:
            self._fh.seek(0)
            for record in make_reader(self._fh).iter_metadata():
                if record.name == name:
                    return dict(record.metadata)
        except Exception as err:  # the index or record is damaged: there is no such metadata
            logger.warning("%s: metadata %r unreadable (%s)", self.path, name, err)
        return None

    def close(self) -> None:
        self._buf.release()
        # the map is not closed: messages handed out may still view it (dropped with the last)
        self._fh.close()
