"""An MCAP made of a log's chunks, copied as they are, and new messages in chunks of their own.

The Foxglove export of a run over an MCAP log (:mod:`.mcap_export`) does not decode the log:
each of its chunk records — compressed bytes, CRC — and the message indexes after it are
copied byte for byte (``os.copy_file_range``: the kernel copies, no byte passes through Python),
and the output's chunk indexes and statistics are built from the log's summary and those
message indexes.  The log's schema and channel records keep their ids, so the copied chunks need
no rewrite; the export's own channels get ids the log does not use.  A chunk that must change
(it holds a channel the export leaves out) is decompressed and its other messages are written
again, with their log time, publish time and sequence.  The new messages (the run's scenes,
Foxglove copies of sensor data) are written as LZ4 chunks beside the copied ones; MCAP allows
chunks that overlap in time, and readers of the summary read messages in log-time order over
all chunks.

:class:`SpliceWriter` writes the file; :func:`read_layout` reads what a log's summary says.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import lz4.frame
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import (
    Channel,
    ChunkIndex,
    DataEnd,
    Header,
    Schema,
    Statistics,
)

from redrive.errors import LogError
from redrive.io.mcap.scan import MAGIC, Message, RecordError, chunk_head, read_chunk
from redrive.io.mcap.stream import encode_chunk, record_bytes, summary_section, write_all
from redrive.io.recognise import starts_with

__all__ = ["MAGIC", "LogLayout", "SpliceWriter", "is_mcap_file", "read_layout"]

_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, length
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, length, channel, records length
_COPY_PIECE = 64 << 20


@dataclass(frozen=True, slots=True, kw_only=True)
class LogLayout:
    """What an MCAP log's summary says: its profile, schemas and channels by id, and its chunk
    indexes in the order of their first message."""

    path: Path
    profile: str
    schemas: Mapping[int, Schema]
    channels: Mapping[int, Channel]
    chunks: tuple[ChunkIndex, ...]


def is_mcap_file(path: Path) -> bool:
    """Whether ``path`` is a file that starts with the MCAP magic."""
    return starts_with(path, MAGIC)


def read_layout(path: Path) -> LogLayout | None:
    """The layout of the MCAP file at ``path`` from its summary; None when it has no summary
    or no chunk index (a file cut short, or written without chunks): such a log is decoded."""
    try:
        with path.open("rb") as fh:
            reader = make_reader(fh)
            header = reader.get_header()
            summary = reader.get_summary()
    except (McapError, OSError, ValueError, struct.error):
        return None
    if summary is None or not summary.chunk_indexes:
        return None
    chunks = sorted(
        summary.chunk_indexes, key=lambda c: (c.message_start_time, c.chunk_start_offset)
    )
    return LogLayout(
        path=path,
        profile=header.profile,
        schemas=dict(summary.schemas),
        channels=dict(summary.channels),
        chunks=tuple(chunks),
    )


def _index_counts(data: bytes, *, where: str) -> dict[int, int]:
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


def _copy_range(src_fd: int, dst_fd: int, offset: int, size: int, *, where: str) -> None:
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


class SpliceWriter:
    """Write one MCAP to ``fd`` (positioned at 0; the caller closes it): schemas and channels
    with the ids given, chunks copied from a log (:meth:`copy_chunk`), new messages in LZ4
    chunks of about ``chunk_size_bytes`` (:meth:`add_message`), then the summary."""

    def __init__(self, fd: int, *, chunk_size_bytes: int = 1 << 20) -> None:
        self._fd = fd
        self._chunk_size = max(1024, chunk_size_bytes)
        self.position = 0
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._counts: dict[int, int] = {}
        self._messages = 0
        self._start_ns = 0
        self._end_ns = 0
        self._records = bytearray()
        self._index: dict[int, list[int]] = {}
        self._chunk_start_ns = 0
        self._chunk_end_ns = 0
        self._chunk_messages = 0

    def _put(self, *pieces: bytes | bytearray | memoryview) -> int:
        start = self.position
        self.position += write_all(self._fd, pieces)
        return start

    def _count(self, channel_id: int, n: int, start_ns: int, end_ns: int) -> None:
        if not n:
            return
        self._counts[channel_id] = self._counts.get(channel_id, 0) + n
        if self._messages == 0:
            self._start_ns, self._end_ns = start_ns, end_ns
        else:
            self._start_ns = min(self._start_ns, start_ns)
            self._end_ns = max(self._end_ns, end_ns)
        self._messages += n

    # -- records outside chunks -----------------------------------------------------------------
    def start(self, *, profile: str, library: str) -> None:
        """The magic and the header record."""
        self._put(MAGIC + record_bytes(Header(profile=profile, library=library)))

    def add_schema(self, schema: Schema) -> None:
        """A schema record, with its own id, in the data section (before any chunk needs it)."""
        self._schemas[schema.id] = schema
        self._put(record_bytes(schema))

    def add_channel(self, channel: Channel) -> None:
        """A channel record, with its own id, in the data section."""
        self._channels[channel.id] = channel
        self._counts.setdefault(channel.id, 0)
        self._put(record_bytes(channel))

    # -- copied chunks ---------------------------------------------------------------------------
    def copy_chunk(self, src_fd: int, index: ChunkIndex, *, where: str) -> int:
        """Append the chunk of ``index`` (of the file ``src_fd``) and its message indexes as
        they are; returns its message count.  ``where`` names the log in errors.

        Raises:
            LogError: the bytes are not what the log's summary says (repair the log)."""
        self.end_chunk()
        start = index.chunk_start_offset
        head = os.pread(src_fd, _RECORD_HEAD.size, start)
        opcode, length = _RECORD_HEAD.unpack(head) if len(head) == 9 else (0, 0)
        if opcode != Opcode.CHUNK or _RECORD_HEAD.size + length != index.chunk_length:
            msg = (
                f"{where}: no chunk at offset {start} where its summary says; repair the log "
                "(`redrive repair`)"
            )
            raise LogError(msg)
        counts = _index_counts(
            os.pread(src_fd, index.message_index_length, start + index.chunk_length),
            where=f"{where} (chunk at offset {start})",
        )
        if set(counts) != set(index.message_index_offsets):
            msg = f"{where}: the chunk at offset {start} does not match its index; repair the log"
            raise LogError(msg)
        new_start = self.position
        _copy_range(
            src_fd,
            self._fd,
            start,
            index.chunk_length + index.message_index_length,
            where=where,
        )
        self.position += index.chunk_length + index.message_index_length
        shift = new_start - start
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=index.message_start_time,
                message_end_time=index.message_end_time,
                chunk_start_offset=new_start,
                chunk_length=index.chunk_length,
                message_index_offsets={
                    c: at + shift for c, at in index.message_index_offsets.items()
                },
                message_index_length=index.message_index_length,
                compression=index.compression,
                compressed_size=index.compressed_size,
                uncompressed_size=index.uncompressed_size,
            )
        )
        for channel_id, n in counts.items():
            self._count(channel_id, n, index.message_start_time, index.message_end_time)
        return sum(counts.values())

    @staticmethod
    def chunk_messages(src_fd: int, index: ChunkIndex, *, where: str) -> list[Message]:
        """The messages of the chunk of ``index`` (decompressed, CRC checked), in their order in
        it: (channel id, sequence, log time, publish time, data)."""
        data = memoryview(os.pread(src_fd, index.chunk_length, index.chunk_start_offset))
        try:
            head = chunk_head(data, 0, len(data))
        except RecordError as err:
            msg = f"{where}: the chunk at offset {index.chunk_start_offset}: {err}; repair the log"
            raise LogError(msg) from err
        messages, _, why = read_chunk(data, head)
        if why is not None:
            msg = f"{where}: the chunk at offset {index.chunk_start_offset}: {why}; repair the log"
            raise LogError(msg)
        return messages

    # -- new messages ----------------------------------------------------------------------------
    def add_message(
        self,
        channel_id: int,
        *,
        log_time: int,
        publish_time: int,
        sequence: int,
        data: bytes | bytearray | memoryview,
    ) -> None:
        """One message into the open chunk (finished once it reaches the chunk size)."""
        size = len(data) if isinstance(data, bytes | bytearray) else memoryview(data).nbytes
        if self._chunk_messages == 0:
            self._chunk_start_ns = self._chunk_end_ns = log_time
        else:
            self._chunk_start_ns = min(self._chunk_start_ns, log_time)
            self._chunk_end_ns = max(self._chunk_end_ns, log_time)
        self._chunk_messages += 1
        self._index.setdefault(channel_id, []).extend((log_time, len(self._records)))
        self._count(channel_id, 1, log_time, log_time)
        self._records += _MESSAGE.pack(
            Opcode.MESSAGE,
            22 + size,
            channel_id,
            sequence & 0xFFFFFFFF,
            log_time,
            publish_time,
        )
        self._records += data
        if len(self._records) >= self._chunk_size:
            self.end_chunk()

    def end_chunk(self) -> None:
        """Write the open chunk (LZ4) and its message indexes, if it holds a message."""
        if not self._chunk_messages:
            return
        records = bytes(self._records)
        chunk = encode_chunk(
            [records],
            self._chunk_start_ns,
            self._chunk_end_ns,
            self._index,
            ("lz4", lz4.frame.compress(records)),
        )
        self._chunk_indexes.append(chunk.index_at(self._put(*chunk.pieces)))
        self._records = bytearray()
        self._index = {}
        self._chunk_messages = 0

    # -- the end ---------------------------------------------------------------------------------
    def finish(self) -> None:
        """The open chunk, the data end, the summary (schemas, channels, statistics, chunk
        indexes, summary offsets) and the footer with the summary's CRC."""
        self.end_chunk()
        self._put(record_bytes(DataEnd(data_section_crc=0)))
        statistics = Statistics(
            message_count=self._messages,
            schema_count=len(self._schemas),
            channel_count=len(self._channels),
            attachment_count=0,
            metadata_count=0,
            chunk_count=len(self._chunk_indexes),
            message_start_time=self._start_ns,
            message_end_time=self._end_ns,
            channel_message_counts=dict(self._counts),
        )
        self._put(
            summary_section(
                self.position,
                schemas=list(self._schemas.values()),
                channels=list(self._channels.values()),
                statistics=statistics,
                chunk_indexes=self._chunk_indexes,
            )
        )
