"""MCAP records as bytes: one record, a chunk with its message indexes, the summary section to
the footer, and the raw moves of chunk bytes (``os.writev`` of pieces, ``copy_file_range`` of a
log's chunk into another file). :class:`~redrive.io.mcap.stream.McapStream` writes files with
them; they write the same bytes as the ``mcap`` library's writer.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from isal.isal_zlib import crc32
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    AttachmentIndex,
    Channel,
    ChunkIndex,
    Footer,
    McapRecord,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from redrive.errors import LogError
from redrive.io.mcap.scan import MAGIC

__all__ = [
    "EncodedChunk",
    "copy_range",
    "encode_chunk",
    "index_counts",
    "record_bytes",
    "summary_crc_ok",
    "summary_section",
    "write_all",
]

_CHUNK_HEAD = struct.Struct("<BQQQQI")  # opcode, length, start, end, uncompressed size, crc
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, length, channel, records length
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length
_IOV_MAX = 512  # os.writev takes at most IOV_MAX (1024 on Linux) pieces at once
_COPY_PIECE = 64 << 20


def record_bytes(record: McapRecord) -> bytes:
    """One record's bytes, as the mcap library writes it."""
    builder = RecordBuilder()
    record.write(builder)
    data: bytes = builder.end()  # type: ignore[no-untyped-call]
    return data


def write_all(fd: int, pieces: Sequence[bytes | bytearray | memoryview]) -> int:
    """``os.writev`` until every byte of ``pieces`` is written; returns their length."""
    views = [memoryview(p).cast("B") for p in pieces if len(p)]
    total = sum(v.nbytes for v in views)
    while views:
        written = os.writev(fd, views[:_IOV_MAX])
        while views and written >= views[0].nbytes:
            written -= views[0].nbytes
            views.pop(0)
        if written:
            views[0] = views[0][written:]
    return total


@dataclass(frozen=True, slots=True)
class EncodedChunk:
    """A chunk record and the message index records after it, ready to write: ``pieces`` in
    order, then :meth:`index_at` the offset they were written at for the summary."""

    pieces: list[bytes | bytearray | memoryview]
    start_ns: int
    end_ns: int
    chunk_length: int  # the chunk record, opcode and length included
    index_length: int  # its message index records
    index_offsets: dict[int, int]  # channel → its message index record, from the chunk's end
    compression: str
    compressed_size: int
    uncompressed_size: int

    def index_at(self, chunk_start: int) -> ChunkIndex:
        """The summary's chunk index of this chunk written at byte ``chunk_start``."""
        index_start = chunk_start + self.chunk_length
        return ChunkIndex(
            message_start_time=self.start_ns,
            message_end_time=self.end_ns,
            chunk_start_offset=chunk_start,
            chunk_length=self.chunk_length,
            message_index_offsets={c: index_start + at for c, at in self.index_offsets.items()},
            message_index_length=self.index_length,
            compression=self.compression,
            compressed_size=self.compressed_size,
            uncompressed_size=self.uncompressed_size,
        )


def encode_chunk(
    records: Sequence[bytes | bytearray | memoryview],
    start_ns: int,
    end_ns: int,
    index: Mapping[int, list[int]],
    compressed: tuple[str, bytes] | None,
) -> EncodedChunk:
    """A chunk of the message records ``records`` (their CRC is taken here), stored as they are
    or as ``compressed`` (compression name, compressed bytes), and the message index records of
    ``index`` (channel → [log time, offset in the records, …])."""
    crc = 0
    size = 0
    for piece in records:
        crc = crc32(piece, crc)
        size += len(piece)
    name, body = ("", list(records)) if compressed is None else (compressed[0], [compressed[1]])
    body_size = size if compressed is None else len(compressed[1])
    name_bytes = name.encode()
    record_length = 8 + 8 + 8 + 4 + 4 + len(name_bytes) + 8 + body_size
    head = (
        _CHUNK_HEAD.pack(Opcode.CHUNK, record_length, start_ns, end_ns, size, crc)
        + _U32.pack(len(name_bytes))
        + name_bytes
        + _U64.pack(body_size)
    )
    relative: dict[int, int] = {}
    indexes = bytearray()
    for channel_id, entries in index.items():
        relative[channel_id] = len(indexes)
        pairs = len(entries) // 2
        indexes += _INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 6 + 16 * pairs, channel_id, 16 * pairs)
        indexes += struct.pack(f"<{len(entries)}Q", *entries)
    return EncodedChunk(
        pieces=[head, *body, indexes],
        start_ns=start_ns,
        end_ns=end_ns,
        chunk_length=len(head) + body_size,
        index_length=len(indexes),
        index_offsets=relative,
        compression=name,
        compressed_size=body_size,
        uncompressed_size=size,
    )


def summary_section(
    summary_start: int,
    *,
    schemas: Sequence[Schema],
    channels: Sequence[Channel],
    statistics: Statistics,
    chunk_indexes: Sequence[ChunkIndex],
    metadata_indexes: Sequence[MetadataIndex] = (),
    attachment_indexes: Sequence[AttachmentIndex] = (),
) -> bytes:
    """The bytes from the summary section to the end of a file whose summary starts at byte
    ``summary_start``: schemas, channels, statistics, chunk, attachment and metadata indexes, a summary
    offset record for each group that has records, the footer with the summary's CRC, and the
    closing magic."""
    summary = RecordBuilder()
    offsets: list[SummaryOffset] = []
    groups: list[
        tuple[
            Opcode,
            Sequence[Schema | Channel | Statistics | ChunkIndex | AttachmentIndex | MetadataIndex],
        ]
    ] = [
        (Opcode.SCHEMA, schemas),
        (Opcode.CHANNEL, channels),
        (Opcode.STATISTICS, [statistics]),
        (Opcode.CHUNK_INDEX, chunk_indexes),
        (Opcode.ATTACHMENT_INDEX, attachment_indexes),
        (Opcode.METADATA_INDEX, metadata_indexes),
    ]
    for opcode, records in groups:
        start = summary.count
        for record in records:
            record.write(summary)
        if records:
            offsets.append(SummaryOffset(opcode, summary_start + start, summary.count - start))
    offset_start = summary_start + summary.count
    for offset in offsets:
        offset.write(summary)
    data: bytes = summary.end()  # type: ignore[no-untyped-call]
    footer_head = struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offset_start)
    crc = crc32(footer_head, crc32(data))
    footer = Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc)
    return b"".join((data, record_bytes(footer), MAGIC))


def index_counts(data: bytes, *, where: str) -> dict[int, int]:
    """channel → messages, from the message index records after a chunk."""
    counts: dict[int, int] = {}
    at = 0
    while at < len(data):
        if len(data) - at < _INDEX_HEAD.size:
            msg = f"{where}: a message index is cut short; repair the log (`redrive repair`)"
            raise LogError(msg)
        opcode, length, channel, records = _INDEX_HEAD.unpack_from(data, at)
        if opcode != Opcode.MESSAGE_INDEX or records % 16 or 6 + records > length:
            msg = f"{where}: not a message index; repair the log (`redrive repair`)"
            raise LogError(msg)
        counts[channel] = counts.get(channel, 0) + records // 16
        at += _RECORD_HEAD.size + length
    return counts


def copy_range(src_fd: int, dst_fd: int, offset: int, size: int, *, where: str) -> None:
    """``size`` bytes of ``src_fd`` from ``offset`` appended at ``dst_fd``'s position."""
    done = 0
    try:
        while done < size:
            n = os.copy_file_range(src_fd, dst_fd, min(size - done, _COPY_PIECE), offset + done)
            if n == 0:
                break
            done += n
    except OSError:  # a file system or kernel without copy_file_range: copy through memory
        pass
    while done < size:
        piece = os.pread(src_fd, min(size - done, _COPY_PIECE), offset + done)
        if not piece:
            msg = f"{where}: the file ends inside a chunk; repair the log (`redrive repair`)"
            raise LogError(msg)
        write_all(dst_fd, [piece])
        done += len(piece)


def summary_crc_ok(buf: memoryview) -> bool:
    """Whether the summary section matches the CRC its footer records (True when it records
    none, or the file has no footer to check against)."""
    size = len(buf)
    footer = size - len(MAGIC) - 9 - 20
    if footer < len(MAGIC) or bytes(buf[size - len(MAGIC) :]) != MAGIC:
        return True
    op, length = _RECORD_HEAD.unpack_from(buf, footer)
    if op != Opcode.FOOTER or length != 20:
        return True
    summary_start, _, crc = struct.unpack_from("<QQI", buf, footer + 9)
    if crc == 0:
        return True
    start = summary_start if 0 < summary_start <= footer else footer
    return bool(crc32(buf[start : size - len(MAGIC) - 4]) == crc)
