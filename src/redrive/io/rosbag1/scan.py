"""The sequential (salvage) reading of a ROS 1 bag whose index is missing or unreadable.

:class:`BagWalk` walks every record from the start, as ``rosbag reindex`` does: connection
records, chunk spans (with the time range and message count of each), the counts the index data
records after a chunk list.  A chunk that does not decompress or holds a malformed record, a
malformed connection record, or bytes that are no record at all become a
:class:`~redrive.io.damage.LogDamage` each; after bytes that are no record the walk *resyncs* at
the next chunk or connection record header, so one damaged record does not lose the rest of the
bag.  A file that ends inside its last chunk still yields the messages that chunk's first bytes
hold.
"""

from __future__ import annotations

import logging
import mmap
import re
import struct
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

from redrive.io.base import normalize_msgtype
from redrive.io.damage import LogDamage
from redrive.io.limits import decompress_bounded, max_chunk_bytes
from redrive.io.rosbag1.records import (
    DECOMPRESSORS,
    MAGIC,
    OP_CHUNK,
    OP_CONNECTION,
    OP_MSGDATA,
    U32,
    DamageError,
    data_span,
    declared_size,
    decode_time,
    decompress_prefix,
    op_of,
    parse_header,
    size_lie,
)

__all__ = ["BagWalk", "ChunkSpan", "Conn"]

logger = logging.getLogger(__name__)

OP_INDEX_DATA = 0x04
#: the ``op`` field of a chunk or connection record header, as written (length 4, "op=", byte)
_OP_FIELD = re.compile(rb"\x04\x00\x00\x00op=[\x05\x07]")
_MAX_HEADER = 1 << 16


@dataclass(slots=True)
class Conn:
    id: int
    topic: str
    msgtype: str
    msgdef: str
    count: int = 0
    size_bytes: int = 0


@dataclass(slots=True)
class ChunkSpan:
    """Where a chunk's compressed bytes are, what it holds and whether it is damaged."""

    pos: int
    datapos: int
    datasize: int
    compression: str
    start_ns: int = 0
    end_ns: int = 0
    read: int = 0  # messages read from it
    listed: int | None = None  # messages the index data records after it list
    damaged: str | None = None
    cut: bool = False  # the file ends inside this chunk: only a prefix of it is readable
    declared: int | None = None  # the uncompressed size its header's ``size`` field says
    size_lie: str | None = None  # why that size is wrong (its messages were read anyway)

    def lie(self) -> LogDamage:
        """The damage of a chunk with ``size_lie`` set: no message lost."""
        return LogDamage(
            what=f"the {self.compression} chunk's {self.size_lie}",
            start_byte=self.pos,
            stop_byte=self.datapos + self.datasize,
            messages_lost=0,
        )

    def damage(self) -> LogDamage:
        """The damage of a chunk with ``damaged`` set."""
        lost = None if self.listed is None else max(self.listed - self.read, 0)
        return LogDamage(
            what=f"the {self.compression} chunk {self.damaged}",
            start_byte=self.pos,
            stop_byte=self.datapos + self.datasize,
            messages_lost=lost,
        )


class BagWalk:
    """One sequential walk over a bag (see the module text).

    Attributes:
        conns: connection id → connection, as found.
        items: the chunks and the damage, in file order (a damaged chunk is followed by its
            damage).
    """

    def __init__(self, path: Path, size: int, budget: int | None = None) -> None:
        self.path = path
        self.size = size
        self.budget = max_chunk_bytes(budget)
        self.conns: dict[int, Conn] = {}
        self.items: list[ChunkSpan | LogDamage] = []

    @property
    def spans(self) -> list[ChunkSpan]:
        return [s for s in self.items if isinstance(s, ChunkSpan)]

    def walk(self) -> None:
        """Walk every record from the start: connections, chunk spans, counts, damage."""
        with self.path.open("rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as buf:
            pos = len(MAGIC)
            last: ChunkSpan | None = None
            while pos < self.size:
                try:
                    fields, hstop = parse_header(buf, pos, min(self.size, pos + _MAX_HEADER))
                    op = op_of(fields, pos)
                    if hstop + 4 > self.size:
                        raise DamageError(pos, "record data length is cut off")
                    (dsize,) = U32.unpack_from(buf, hstop)
                    datapos = hstop + 4
                    if datapos + dsize > self.size:
                        salvaged = (  # the last chunk was cut off: salvage its first bytes
                            self._salvage_cut_chunk(buf, fields, pos, datapos)
                            if op == OP_CHUNK
                            else 0
                        )
                        self.items.append(
                            LogDamage(
                                what=f"the bag is cut off inside a record of {dsize} bytes"
                                + (
                                    f" (a chunk: the {salvaged} messages its first bytes hold "
                                    "were read)"
                                    if op == OP_CHUNK
                                    else ""
                                ),
                                start_byte=pos,
                                stop_byte=self.size,
                            )
                        )
                        break
                except DamageError as err:
                    resume = _resync(buf, pos + 1, self.size)
                    cut = resume >= self.size
                    self.items.append(
                        LogDamage(
                            what=(
                                f"the bag is cut off or damaged ({err.reason}); nothing after it "
                                "is readable"
                                if cut
                                else f"bytes that are no record ({err.reason})"
                            ),
                            start_byte=pos,
                            stop_byte=resume,
                        )
                    )
                    pos, last = resume, None
                    continue
                if op == OP_CHUNK:
                    compression = fields.get("compression", b"none").decode("ascii", "replace")
                    last = ChunkSpan(pos, datapos, dsize, compression)
                    last.declared = declared_size(fields)
                    self.items.append(last)
                    times = [t for _, t, _ in self.records(buf, last, None, first=True)]
                    if times:
                        last.start_ns, last.end_ns = min(times), max(times)
                elif op == OP_CONNECTION:
                    try:
                        self._add_connection(fields, bytes(buf[datapos : datapos + dsize]), pos)
                    except DamageError as err:
                        self.items.append(
                            LogDamage(
                                what=f"a connection record is malformed ({err.reason}); its "
                                "topic's messages are lost unless a copy of it is intact",
                                start_byte=pos,
                                stop_byte=datapos + dsize,
                            )
                        )
                elif op == OP_INDEX_DATA and last is not None:
                    count = fields.get("count", b"")
                    if len(count) == 4:
                        last.listed = (last.listed or 0) + U32.unpack(count)[0]
                else:
                    last = None if op != OP_INDEX_DATA else last
                pos = datapos + dsize
        self._place_chunk_damage()

    def _place_chunk_damage(self) -> None:
        out: list[ChunkSpan | LogDamage] = []
        for item in self.items:
            out.append(item)
            if isinstance(item, ChunkSpan) and item.damaged is not None:
                out.append(item.damage())
            elif isinstance(item, ChunkSpan) and item.size_lie is not None:
                out.append(item.lie())
        self.items = out

    def _salvage_cut_chunk(
        self, buf: mmap.mmap, fields: Mapping[str, bytes], pos: int, datapos: int
    ) -> int:
        """Read what the first bytes of a cut-off chunk hold; returns how many messages."""
        compression = fields.get("compression", b"none").decode("ascii", "replace")
        span = ChunkSpan(pos, datapos, self.size - datapos, compression, cut=True)
        times = [t for _, t, _ in self.records(buf, span, None, first=True)]
        if times:
            span.start_ns, span.end_ns = min(times), max(times)
            self.items.append(span)
        return len(times)

    def records(
        self, buf: mmap.mmap, span: ChunkSpan, wanted: set[int] | None, *, first: bool
    ) -> Iterator[tuple[int, int, memoryview]]:
        """(connection id, time ns, data) of the messages of ``span``, up to any damage in it.

        ``first``: the walk's pass, which counts messages and notes the damage.
        """
        raw = bytes(buf[span.datapos : span.datapos + span.datasize])
        try:
            if span.cut:
                chunk = memoryview(decompress_prefix(span.compression, raw, self.budget))
            else:
                chunk = memoryview(decompress_bounded(span.compression, raw, self.budget))
        except KeyError:
            span.damaged = f"uses an unknown compression {span.compression!r}"
            return
        except (OSError, ValueError, RuntimeError, EOFError, MemoryError) as err:
            if first:
                span.damaged = f"does not decompress ({err})"
            return
        pos, end = 0, len(chunk)
        if first and not span.cut:
            span.size_lie = size_lie(span.compression, span.declared, end)
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
                    conn = self.conns.get(conn_id)
                    if first and conn is not None:
                        conn.count += 1
                        conn.size_bytes += stop - start
                        span.read += 1
                    if conn is not None and (wanted is None or conn_id in wanted):
                        yield conn_id, time_ns, chunk[start:stop]
            except (DamageError, KeyError, struct.error) as err:
                if first and not span.cut:
                    span.damaged = f"holds a damaged record at offset {pos} ({err})"
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
        if conn_id not in self.conns:
            self.conns[conn_id] = Conn(id=conn_id, topic=topic, msgtype=msgtype, msgdef=msgdef)


def _resync(buf: mmap.mmap, start: int, size: int) -> int:
    """The start of the next chunk or connection record at or after ``start`` (``size`` if none)."""
    for found in _OP_FIELD.finditer(buf, start):
        at = found.start()
        for pos in range(max(start, at - 512), at - 3):
            (hlen,) = U32.unpack_from(buf, pos)
            if hlen > _MAX_HEADER or pos + 4 + hlen < at + 8:
                continue
            try:
                fields, hstop = parse_header(buf, pos, size)
                op = op_of(fields, pos)
                data_span(buf, hstop, size)
            except DamageError:
                continue
            compression = fields.get("compression", b"none").decode("ascii", "replace")
            if op == OP_CONNECTION or compression in DECOMPRESSORS:
                return pos
    return size
