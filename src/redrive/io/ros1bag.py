"""ROS 1 bags (format 2.0): indexed reading through ``rosbags``, sequential salvage when the index
is missing.

An intact bag is opened with ``rosbags.rosbag1.Reader``, which reads the connection and chunk
index at the end of the file; messages are then read chunk by chunk from that index, so a time
range seeks straight to the first chunk that holds it and a topic filter never decompresses a
chunk that holds none of its messages.

A bag whose index is missing or unreadable — a recording that was killed, a copy that was cut
short — is read *sequentially* from the start instead (what ``rosbag reindex`` does), and every
message before the damage is delivered.  rosbags offers no such salvage, which is why the
record walking below exists.  It relies on rosbags 0.11's reader internals (``chunks``,
``indexes``, decompressors), pinned in ``pyproject.toml``.
"""

from __future__ import annotations

import heapq
import logging
import mmap
import struct
from bisect import bisect_left
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

from rosbags.rosbag1 import Reader as RosbagsReader
from rosbags.rosbag1 import ReaderError as RosbagsReaderError
from rosbags.rosbag1.reader import decompressors as rosbags_decompressors

from redrive.errors import LogError, LogTruncatedError
from redrive.io._deserialize import Deserializer
from redrive.io._reader_base import RosReaderBase
from redrive.io.base import LogMessage, TopicInfo, normalize_msgtype
from redrive.io.recognise import starts_with
from redrive.io.ros1bag_records import (
    DECOMPRESSORS,
    MAGIC,
    OP_CHUNK,
    OP_CONNECTION,
    OP_MSGDATA,
    U32,
    DamageError,
    data_span,
    decode_time,
    decompress_prefix,
    op_of,
    parse_header,
    record_op,
)
from redrive.io.typestore import typestore_for

__all__ = ["Ros1BagReader"]

logger = logging.getLogger(__name__)


@dataclass(slots=True)
class _Conn:
    id: int
    topic: str
    msgtype: str
    msgdef: str
    count: int = 0
    size_bytes: int = 0


@dataclass(slots=True)
class _ChunkSpan:
    """Where a chunk's compressed bytes are, for the sequential (salvage) path."""

    pos: int
    datapos: int
    datasize: int
    compression: str
    start_ns: int = 0
    end_ns: int = 0
    damaged: str | None = None
    cut: bool = False  # the file ends inside this chunk: only a prefix of it is readable


class Ros1BagReader(RosReaderBase):
    """A ROS 1 bag (plain, bz2 or lz4 chunks).

    Args:
        path: the ``.bag`` file.
        strict: when True (default) damage met while reading (a corrupt chunk, a cut-off end)
            raises :class:`~redrive.errors.LogTruncatedError` after every message before it was
            yielded; when False it is logged as a warning and reading goes on with the next
            readable chunk.

    Attributes:
        damage: a description of the damage found while opening (None for an intact bag).
        indexed: False when the bag had to be read sequentially.
    """

    format = "ros1"
    description = "a ROS 1 bag (format 2.0, indexed or not)"

    @classmethod
    def recognises(cls, path: Path) -> bool:
        return starts_with(path, b"#ROSBAG V")

    def __init__(self, path: Path, *, strict: bool = True) -> None:
        self.path = Path(path)
        self.strict = strict
        self.damage: str | None = None
        self.indexed = True
        self._conns: dict[int, _Conn] = {}
        self._rosbags: RosbagsReader | None = None
        self._spans: list[_ChunkSpan] = []
        self._tail_damage: str | None = None
        self._file_size = 0
        self._map: mmap.mmap | None = None
        self._open()
        definitions = {c.msgtype: ("msg", c.msgdef) for c in self._conns.values()}
        self._typestore, self._bad_definitions = typestore_for(
            1, definitions, needed={c.msgtype for c in self._conns.values()}
        )
        self._deserializer = Deserializer(self.path, ros1=self._typestore, cdr=None)
        self._topics = self._summarise()

    # -- opening -------------------------------------------------------------------------------

    def _open(self) -> None:
        try:
            self._file_size = self.path.stat().st_size
        except OSError as err:
            msg = f"{self.path}: cannot open ({err.strerror}); check the path and permissions"
            raise LogError(msg) from err
        if self._file_size == 0:
            msg = f"{self.path}: the file is empty (0 bytes); it holds no ROS 1 bag"
            raise LogError(msg)
        with self.path.open("rb") as fh:
            if fh.read(len(MAGIC)) != MAGIC:
                msg = (
                    f"{self.path}: not a ROS 1 bag (no '#ROSBAG V2.0' magic at the start); "
                    "only bag format 2.0 is supported"
                )
                raise LogError(msg)
        reader = RosbagsReader(self.path)
        try:
            reader.open()
        except (RosbagsReaderError, OSError, ValueError, AssertionError, struct.error) as err:
            self.indexed = False
            self._scan_open(str(err))
            return
        self._rosbags = reader
        if not reader.connections and self._file_size > 4096:
            # An index that lists nothing in a non-trivial file: trust the records instead.
            reader.close()
            self._rosbags = None
            self.indexed = False
            self._scan_open("the index lists no chunks")
            return
        for conn in reader.connections:
            self._conns[conn.id] = _Conn(
                id=conn.id,
                topic=conn.topic,
                msgtype=conn.msgtype,
                msgdef=conn.msgdef.data,
                count=conn.msgcount,
            )

    def _scan_open(self, why: str) -> None:
        logger.warning(
            "%s: the bag index is unreadable (%s); reading the bag sequentially — messages after "
            "any damage are lost (the file itself is not changed)",
            self.path,
            why,
        )
        self._walk()
        lost = [s for s in self._spans if s.damaged is not None]
        parts = [f"no usable index ({why})"]
        if self._tail_damage is not None:
            parts.append(self._tail_damage)
        parts += [f"the chunk at byte {s.pos} {s.damaged}" for s in lost]
        self.damage = "; ".join(parts)

    # -- summary -------------------------------------------------------------------------------

    def _summarise(self) -> dict[str, TopicInfo]:
        by_topic: dict[str, list[_Conn]] = {}
        for conn in self._conns.values():
            by_topic.setdefault(conn.topic, []).append(conn)
        out: dict[str, TopicInfo] = {}
        for topic, conns in sorted(by_topic.items()):
            msgtype = conns[0].msgtype
            if len({c.msgtype for c in conns}) > 1:
                logger.warning(
                    "%s: topic %s has several types; using %s", self.path, topic, msgtype
                )
            out[topic] = TopicInfo(
                topic=topic,
                msgtype=msgtype,
                count=sum(c.count for c in conns),
                size_bytes=sum(c.size_bytes for c in conns) if not self.indexed else -1,
                encoding="ros1",
                has_definition=msgtype in self._typestore.fielddefs,
            )
        return out

    @property
    def start_ns(self) -> int:
        if self._rosbags is not None:
            return int(self._rosbags.start_time) if self.message_count else 0
        return min((s.start_ns for s in self._spans), default=0)

    @property
    def end_ns(self) -> int:
        if self._rosbags is not None:
            return max(int(self._rosbags.end_time) - 1, 0) if self.message_count else 0
        return max((s.end_ns for s in self._spans), default=0)

    # -- reading -------------------------------------------------------------------------------

    def messages(
        self,
        *,
        topics: Collection[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[LogMessage]:
        conns = self._conns
        source = (
            self._indexed_messages(topics=topics, start_ns=start_ns, stop_ns=stop_ns)
            if self._rosbags is not None
            else self._scan(topics=topics, start_ns=start_ns, stop_ns=stop_ns)
        )
        for conn_id, time_ns, data in source:
            conn = conns[conn_id]
            yield LogMessage(
                topic=conn.topic,
                msgtype=conn.msgtype,
                log_time_ns=time_ns,
                encoding="ros1",
                raw=data,
            )

    def _selected_ids(self, topics: Collection[str] | None) -> set[int]:
        if topics is None:
            return set(self._conns)
        wanted = set(topics)
        return {c.id for c in self._conns.values() if c.topic in wanted}

    def _indexed_messages(
        self, *, topics: Collection[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[tuple[int, int, memoryview]]:
        reader = self._rosbags
        assert reader is not None
        assert reader.bio is not None
        streams = []
        for conn_id in sorted(self._selected_ids(topics)):
            index = reader.indexes.get(conn_id, [])
            first = 0 if start_ns is None else bisect_left([e.time for e in index], start_ns)
            streams.append(_entries(index, first, conn_id))
        current_pos = -1
        chunk: memoryview = memoryview(b"")
        bad_chunk = -1
        yielded = 0
        mapped: tuple[int, int] | None = None  # page-aligned span of the map the last chunk used
        for time_ns, chunk_pos, offset, conn_id in heapq.merge(*streams):
            if stop_ns is not None and time_ns >= stop_ns:
                return
            if chunk_pos == bad_chunk:
                continue
            if chunk_pos != current_pos:
                if mapped is not None:
                    self._release(*mapped)
                    mapped = None
                header = reader.chunks[chunk_pos]
                try:
                    chunk, mapped = self._chunk_bytes(header)
                except (OSError, ValueError, RuntimeError, EOFError) as err:
                    self._chunk_damage(chunk_pos, err, yielded)
                    bad_chunk = chunk_pos
                    continue
                current_pos = chunk_pos
            try:
                data = self._message_at(chunk, offset)
            except DamageError as err:
                self._chunk_damage(chunk_pos, err, yielded)
                bad_chunk = chunk_pos
                continue
            yielded += 1
            yield conn_id, time_ns, data
        if mapped is not None:
            self._release(*mapped)

    def _chunk_bytes(self, header: Any) -> tuple[memoryview, tuple[int, int] | None]:
        """The decompressed records of one chunk, and the map span they occupy (if mapped).

        An uncompressed chunk is a slice of a read-only map of the file: messages are then
        views of the page cache, with no copy at all.  A compressed chunk is read and
        decompressed into a new ``bytes``.
        """
        end = header.datapos + header.datasize
        if end > self._file_size:
            msg = "the chunk is cut off"
            raise ValueError(msg)
        if header.decompressor is rosbags_decompressors["none"]:
            view = self._file_map()
            first_page = header.datapos - header.datapos % mmap.PAGESIZE
            return view[header.datapos : end], (first_page, end - first_page)
        bio = self._rosbags.bio if self._rosbags is not None else None
        assert bio is not None
        bio.seek(header.datapos)
        compressed = bio.read(header.datasize)
        if len(compressed) != header.datasize:
            msg = "the chunk is cut off"
            raise ValueError(msg)
        return memoryview(header.decompressor(compressed)), None

    def _file_map(self) -> memoryview:
        if self._map is None:
            with self.path.open("rb") as fh:
                self._map = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        return memoryview(self._map)

    def _release(self, start: int, length: int) -> None:
        """Drop the pages of a chunk already read from this process's resident set.

        The map is read-only and file-backed, so views still held by consumers stay valid: their
        pages fault back in from the page cache when touched.  This keeps RSS bounded by one
        chunk whatever the length of the log.
        """
        if self._map is not None and hasattr(mmap, "MADV_DONTNEED"):
            self._map.madvise(mmap.MADV_DONTNEED, start, length)

    def _chunk_damage(self, chunk_pos: int, err: Exception, yielded: int) -> None:
        lost = {
            self._conns[c].topic: n
            for c, n in _chunk_counts(self._rosbags, chunk_pos).items()
            if c in self._conns
        }
        text = (
            f"the chunk at byte {chunk_pos} is damaged ({err}); it held {sum(lost.values())} "
            f"messages ({', '.join(f'{t}: {n}' for t, n in sorted(lost.items()))})"
        )
        if self.strict:
            msg = (
                f"{self.path}: {text}; {yielded} messages were read before it. Open the log with "
                "strict=False (CLI: --skip-damaged) to read past it."
            )
            raise LogTruncatedError(msg, messages_read=yielded)
        logger.warning("%s: %s; skipping it", self.path, text)

    @staticmethod
    def _message_at(chunk: memoryview, offset: int) -> memoryview:
        end = len(chunk)
        pos = offset
        while True:
            op, pos = record_op(chunk, pos, end)
            start, stop = data_span(chunk, pos, end)
            if op < 0:
                raise DamageError(offset, "record has no op field")
            if op == OP_MSGDATA:
                return chunk[start:stop]
            if op != OP_CONNECTION:
                raise DamageError(offset, f"expected a message record, found op {op:#x}")
            pos = stop

    def _scan(
        self, *, topics: Collection[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[tuple[int, int, memoryview]]:
        """Read the chunks found by the sequential walk at open (the salvage path)."""
        wanted = self._selected_ids(topics)
        yielded = 0
        with self.path.open("rb") as fh:
            for span in self._spans:
                if span.damaged is not None:
                    self._salvage_damage(f"the chunk at byte {span.pos} {span.damaged}", yielded)
                    continue
                if start_ns is not None and span.end_ns < start_ns:
                    continue
                if stop_ns is not None and span.start_ns >= stop_ns:
                    return
                for item in self._chunk_records(fh, span, wanted, first=False):
                    if (start_ns is None or item[1] >= start_ns) and (
                        stop_ns is None or item[1] < stop_ns
                    ):
                        yielded += 1
                        yield item
        if self._tail_damage is not None:
            self._salvage_damage(self._tail_damage, yielded)

    def _salvage_damage(self, text: str, yielded: int) -> None:
        if self.strict:
            msg = (
                f"{self.path}: {text}; {yielded} messages were read before it. Open the log "
                "with strict=False (CLI: --skip-damaged) to read what is readable."
            )
            raise LogTruncatedError(msg, messages_read=yielded)

    def _walk(self) -> None:
        """Walk every record from the start: connections, chunk spans, counts, damage."""
        pos = len(MAGIC)
        with self.path.open("rb") as fh:
            while pos < self._file_size:
                try:
                    fh.seek(pos)
                    head = fh.read(min(self._file_size - pos, 1 << 16))
                    fields, hstop = parse_header(head, 0, len(head))
                    op = op_of(fields, pos)
                    if hstop + 4 > len(head):
                        raise DamageError(pos, "record data length is cut off")
                    (dsize,) = U32.unpack_from(head, hstop)
                    cut = pos + hstop + 4 + dsize > self._file_size
                    if cut and op == OP_CHUNK:
                        # The last chunk was cut off: salvage the messages its first bytes hold.
                        self._salvage_cut_chunk(fh, fields, pos, pos + hstop + 4)
                    if cut:
                        raise DamageError(pos, f"a record of {dsize} bytes runs past the end")
                except DamageError as err:
                    self._tail_damage = (
                        f"the bag is cut off or damaged at byte {pos} of {self._file_size} "
                        f"({err.reason}); the {self._file_size - pos} bytes from there on are lost"
                    )
                    logger.warning("%s: %s", self.path, self._tail_damage)
                    return
                datapos = pos + hstop + 4
                if op == OP_CHUNK:
                    compression = fields.get("compression", b"none").decode("ascii", "replace")
                    span = _ChunkSpan(pos, datapos, dsize, compression)
                    times = [t for _, t, _ in self._chunk_records(fh, span, None, first=True)]
                    if times:
                        span.start_ns, span.end_ns = min(times), max(times)
                    self._spans.append(span)
                elif op == OP_CONNECTION:
                    fh.seek(datapos)
                    self._add_connection(fields, fh.read(dsize), pos)
                pos = datapos + dsize

    def _salvage_cut_chunk(
        self, fh: BinaryIO, fields: Mapping[str, bytes], pos: int, datapos: int
    ) -> None:
        compression = fields.get("compression", b"none").decode("ascii", "replace")
        span = _ChunkSpan(pos, datapos, self._file_size - datapos, compression, cut=True)
        times = [t for _, t, _ in self._chunk_records(fh, span, None, first=True)]
        if times:
            span.start_ns, span.end_ns = min(times), max(times)
            self._spans.append(span)

    def _chunk_records(
        self,
        fh: BinaryIO,
        span: _ChunkSpan,
        wanted: set[int] | None,
        *,
        first: bool,
    ) -> Iterator[tuple[int, int, memoryview]]:
        fh.seek(span.datapos)
        try:
            if span.cut:
                chunk = memoryview(decompress_prefix(span.compression, fh.read(span.datasize)))
            else:
                decompress = DECOMPRESSORS[span.compression]
                chunk = memoryview(decompress(fh.read(span.datasize)))
        except KeyError:
            span.damaged = f"uses an unknown compression {span.compression!r}"
            return
        except (OSError, ValueError, RuntimeError, EOFError) as err:
            span.damaged = f"does not decompress ({err})"
            logger.warning("%s: the chunk at byte %d %s", self.path, span.pos, span.damaged)
            return
        pos, end = 0, len(chunk)
        while pos < end:
            try:
                fields, hstop = parse_header(chunk, pos, end)
                start, stop = data_span(chunk, hstop, end)
                op = op_of(fields, pos)
                if op == OP_CONNECTION and first:
                    self._add_connection(fields, bytes(chunk[start:stop]), span.pos)
                elif op == OP_MSGDATA:
                    conn_id = U32.unpack(fields["conn"])[0]
                    time_ns = decode_time(fields["time"])
                    if first and conn_id in self._conns:
                        conn = self._conns[conn_id]
                        conn.count += 1
                        conn.size_bytes += stop - start
                    if conn_id in self._conns and (wanted is None or conn_id in wanted):
                        yield conn_id, time_ns, chunk[start:stop]
            except (DamageError, KeyError, struct.error) as err:
                if first and not span.cut:
                    span.damaged = f"holds a damaged record at offset {pos} ({err})"
                    logger.warning("%s: the chunk at byte %d %s", self.path, span.pos, span.damaged)
                return
            pos = stop

    def _add_connection(self, fields: Mapping[str, bytes], data: bytes, offset: int) -> None:
        try:
            conn_id = U32.unpack(fields["conn"])[0]
            topic = fields["topic"].decode()
            conn_fields, _ = parse_header(U32.pack(len(data)) + data, 0, len(data) + 4)
            msgtype = normalize_msgtype(conn_fields["type"].decode())
            msgdef = conn_fields.get("message_definition", b"").decode()
        except (KeyError, UnicodeDecodeError, DamageError, struct.error) as err:
            raise DamageError(offset, f"connection record is malformed ({err})") from err
        if conn_id not in self._conns:
            self._conns[conn_id] = _Conn(id=conn_id, topic=topic, msgtype=msgtype, msgdef=msgdef)

    # -- deserialising -------------------------------------------------------------------------

    def close(self) -> None:
        if self._rosbags is not None and self._rosbags.bio is not None:
            self._rosbags.close()
        # The file map is not closed here: arrays decoded from its messages (numpy keeps a
        # reference to the map, not a buffer export, so ``mmap.close`` would not refuse) may
        # still view it.  Dropping our reference unmaps it once the last of them is gone.
        self._map = None


def _entries(index: list[Any], first: int, conn_id: int) -> Iterator[tuple[int, int, int, int]]:
    """(time, chunk position, offset in chunk, connection id) of one connection's index."""
    for entry in index[first:]:
        yield entry.time, entry.chunk_pos, entry.offset, conn_id


def _chunk_counts(reader: RosbagsReader | None, chunk_pos: int) -> dict[int, int]:
    if reader is None:
        return {}
    for info in reader.chunk_infos:
        if info.pos == chunk_pos:
            return dict(info.connection_counts)
    return {}
