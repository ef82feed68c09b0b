"""An MCAP made of a log's chunks, copied as they are, and new messages in chunks of their own.

The Foxglove export of a run over an MCAP log (:mod:`.mcap_export`) does not decode the log:
through :meth:`McapStream.copy_chunk <redrive.io.mcap.stream.McapStream.copy_chunk>` each of its
chunk records — compressed bytes, CRC — and the message indexes after it are
copied byte for byte (``os.copy_file_range``: the kernel copies, no byte passes through Python),
and the output's chunk indexes and statistics are built from the log's summary and those
message indexes.  The log's schema and channel records keep their ids, so the copied chunks need
no rewrite; the export's own channels get ids the log does not use.  A chunk that must change
(it holds a channel the export leaves out) is decompressed and its other messages are written
again, with their log time, publish time and sequence.  The new messages (the run's scenes,
Foxglove copies of sensor data) are written as LZ4 chunks beside the copied ones; MCAP allows
chunks that overlap in time, and readers of the summary read messages in log-time order over
all chunks.

:func:`read_layout` reads what a log's summary says; :func:`chunk_messages` the messages of a
chunk that must be rewritten; :class:`~redrive.io.mcap.stream.McapStream` writes the file.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import (
    Channel,
    ChunkIndex,
    Schema,
)

from redrive.errors import LogError
from redrive.io.mcap.scan import MAGIC, Message, RecordError, chunk_head, read_chunk
from redrive.io.recognise import starts_with

__all__ = ["MAGIC", "LogLayout", "chunk_messages", "is_mcap_file", "read_layout"]


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


def chunk_messages(src_fd: int, index: ChunkIndex, *, where: str) -> list[Message]:
    """The messages of the chunk of ``index`` (decompressed, CRC checked), in their order in it:
    (channel id, sequence, log time, publish time, data) — for a chunk that must be rewritten.

    Raises:
        LogError: the chunk is damaged (repair the log)."""
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
