"""A chunked MCAP writer that writes message bytes to the file without copying them in Python.

:class:`McapStream` writes the same records as ``mcap.writer.Writer`` (chunks with their message
indexes, then the summary: schemas, channels, statistics, chunk indexes, summary offsets; CRCs of
each chunk and of the summary), so the ``mcap`` reader reads its files with summary and index. It
differs in how the bytes move:

* a message is copied once, into a reused chunk buffer — or, when it fills the chunk or is large
  (a point cloud or an image: a quarter of ``chunk_size_bytes`` or more), not at all: the chunk is handed to the kernel with
  ``os.writev`` as [chunk header, buffered records, the message's header, *the caller's view*,
  message indexes], and its CRC is computed over the same pieces (incrementally, with ISA-L's
  ``crc32``: the same CRC-32 as zlib's at several times its speed);
* a large message gets a chunk of its own (the open chunk of small messages is finished before
  it), so a reader that asks for some topics skips the chunks of the others unread — a LiDAR-only
  pipeline never decompresses the camera's images (the chunk index says which channels a chunk
  holds);
  the ``mcap`` writer copies each message about four times (its chunk buffer, the chunk's
  bytes, the chunk record, the file's buffer);
* each chunk goes to the file descriptor as soon as it is complete (no user-space buffer), so a
  process killed with SIGKILL leaves every chunk before the open one on disk;
* with compression (``lz4``/``zstd``) the finished chunks are compressed and written by a
  background thread (compressors and ``os.writev`` release the GIL), so the caller — a recorder
  reading live streams — does not wait for the compressor; at most ``queue_chunks`` chunks wait
  for it, then :meth:`add_message` blocks (back-pressure) — or, for a live recording
  (``live=True``), the chunk is written uncompressed, so a compressor that cannot keep up with
  the sensors costs file size, never messages.

Use (``fd`` from ``os.open``; the caller fsyncs and closes it)::

    out = McapStream(fd, compression="none")
    out.start(profile="ros1", library="redrive")
    schema = out.register_schema("sensor_msgs/Imu", "ros1msg", definition)
    channel = out.register_channel("/imu", "ros1", schema, {"md5sum": md5sum})
    out.add_message(channel, log_time=t_ns, publish_time=t_ns, sequence=0, data=view)
    out.finish()  # the open chunk, data end, summary, footer
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import queue
import struct
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
)

from redrive.errors import LogError
from redrive.io.mcap.records import (
    copy_range,
    encode_chunk,
    index_counts,
    record_bytes,
    summary_section,
    write_all,
)
from redrive.io.mcap.scan import MAGIC

__all__ = ["MAGIC", "McapStream", "StreamCompression"]

StreamCompression = Literal["zstd", "lz4", "none"]

_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
#: live recordings: the compression thread's niceness (above the receiving threads' 0, so on a
#: busy machine compression yields and more chunks are written uncompressed, no message lost)
_COMPRESS_NICE = 10


@dataclass(slots=True)
class _OpenChunk:
    """What a chunk being filled knows besides its bytes."""

    start_ns: int = 0
    end_ns: int = 0
    messages: int = 0
    index: dict[int, list[int]] = field(default_factory=dict)  # channel → [log, offset, …]
    defines: bool = False  # holds schema or channel records


@dataclass(frozen=True, slots=True)
class _ChunkJob:
    """A finished chunk waiting for the compression thread (its own copies of the bytes)."""

    records: bytes
    start_ns: int
    end_ns: int
    index: dict[int, list[int]]
    defines: bool


def _compressor(
    compression: StreamCompression, *, live: bool, zstd_level: int | None = None
) -> Callable[[bytes], bytes]:
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.compress  # type: ignore[no-any-return]
    if compression == "zstd":
        import zstandard

        # live: level 1, ~2x the speed of the default level 3 at a few % larger chunks (a
        # recording must keep up with its sensors)
        level = zstd_level if zstd_level is not None else (1 if live else 3)
        return zstandard.ZstdCompressor(level=level).compress
    msg = f"compression must be zstd, lz4 or none, got {compression!r}"
    raise ValueError(msg)


class McapStream:
    """Write one MCAP file to ``fd`` (see the module text).

    Args:
        fd: an open file descriptor positioned at 0 (the caller closes it).
        compression: chunk compression: ``none``, ``lz4`` or ``zstd``.
        chunk_size_bytes: a chunk is finished once its records reach this size.
        queue_chunks: compressed files: chunks that may wait for the compression thread.
        live: a live recording: zstd at level 1 (else 3), and when ``queue_chunks`` wait for the
            compression thread the next chunk is written uncompressed rather than waiting
            (:attr:`uncompressed_chunks`); otherwise :meth:`add_message` waits for the thread.
        zstd_level: the zstd level (default: 1 live, else 3); any zstd reader reads any level.

    Raises:
        ValueError: an unknown compression.
    """

    def __init__(
        self,
        fd: int,
        *,
        compression: StreamCompression = "zstd",
        chunk_size_bytes: int = 1 << 20,
        queue_chunks: int = 8,
        live: bool = False,
        zstd_level: int | None = None,
    ) -> None:
        self._fd = fd
        self.compression: StreamCompression = compression
        self._compress = (
            None
            if compression == "none"
            else _compressor(compression, live=live, zstd_level=zstd_level)
        )
        self._live = live
        self._chunk_size = max(1024, chunk_size_bytes)
        self._large = self._chunk_size // 4  # a message this big gets a chunk of its own
        self._buffer = bytearray(2 * self._chunk_size + 4096)
        self._view = memoryview(self._buffer)
        self._used = 0
        self._chunk = _OpenChunk()
        #: bytes handed to the file so far (compressed files: once the thread wrote them)
        self.position = 0
        self._queued = 0  # uncompressed bytes of chunks waiting for the compression thread
        self._defining = 0  # chunks with schema/channel records waiting for the thread
        self._lock = threading.Lock()  # one writer of the file (and its offsets) at a time
        #: chunks written uncompressed because the compression thread was behind
        self.uncompressed_chunks = 0
        #: chunks finished so far (written, or queued for the compression thread)
        self.finished_chunks = 0
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        #: what the file holds (the chunks written whole): messages, per channel, first and last
        #: log time — a file cut short by a full disk is closed with these (:meth:`salvage`)
        self.written_messages = 0
        self._written_counts: dict[int, int] = {}
        self._written_span: tuple[int, int] | None = None
        self._failed: BaseException | None = None
        self._jobs: queue.Queue[_ChunkJob | None] | None = None
        self._thread: threading.Thread | None = None
        if self._compress is not None:
            self._jobs = queue.Queue(maxsize=max(1, queue_chunks))
            self._thread = threading.Thread(
                target=self._compress_loop, name="redrive-mcap-compress", daemon=True
            )
            self._thread.start()

    # -- records before and between chunks -------------------------------------------------
    def start(self, *, profile: str, library: str) -> None:
        """The magic and the header record."""
        self._put(MAGIC + record_bytes(Header(profile=profile, library=library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        """A new schema (written into the open chunk); returns its id."""
        schema = Schema(
            id=max(self._schemas, default=0) + 1, name=name, encoding=encoding, data=data
        )
        self._schemas[schema.id] = schema
        self._append_record(schema)
        return schema.id

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: Mapping[str, str]
    ) -> int:
        """A new channel (written into the open chunk); returns its id."""
        channel = Channel(
            id=max(self._channels, default=0) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata),
        )
        self._channels[channel.id] = channel
        self._append_record(channel)
        return channel.id

    def add_schema(self, schema: Schema) -> None:
        """A schema record with the id it has (another file's), in the data section after the
        open chunk (which is finished first)."""
        self.end_chunk()
        self._schemas[schema.id] = schema
        self._put(record_bytes(schema))

    def add_channel(self, channel: Channel) -> None:
        """A channel record with the id it has, as :meth:`add_schema`."""
        self.end_chunk()
        self._channels[channel.id] = channel
        self._put(record_bytes(channel))

    def add_attachment(
        self, *, name: str, media_type: str, data: bytes, log_time: int, create_time: int
    ) -> None:
        """An attachment record (after the open chunk, which is finished first)."""
        self.end_chunk()
        record = record_bytes(
            Attachment(
                log_time=log_time,
                create_time=create_time,
                name=name,
                media_type=media_type,
                data=data,
            )
        )
        offset = self._put(record)
        self._attachment_indexes.append(
            AttachmentIndex(
                offset=offset,
                length=len(record),
                log_time=log_time,
                create_time=create_time,
                data_size=len(data),
                name=name,
                media_type=media_type,
            )
        )

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A metadata record (after the open chunk, which is finished first)."""
        self.end_chunk()
        record = record_bytes(Metadata(name=name, metadata=dict(data)))
        self._metadata_indexes.append(
            MetadataIndex(offset=self._put(record), length=len(record), name=name)
        )

    def _append_record(self, record: Schema | Channel) -> None:
        data = record_bytes(record)
        self._chunk.defines = True
        self._reserve(len(data))
        self._view[self._used : self._used + len(data)] = data
        self._used += len(data)

    # -- messages ------------------------------------------------------------------------------
    def add_message(
        self,
        channel_id: int,
        *,
        log_time: int,
        publish_time: int,
        sequence: int,
        data: bytes | bytearray | memoryview,
    ) -> None:
        """Add one message. ``data`` is written or copied before this returns (a view of a
        buffer that is reused afterwards is fine)."""
        self._raise_failure()
        size = len(data) if isinstance(data, bytes | bytearray) else data.nbytes
        large = size >= self._large
        if large and self._chunk.messages:  # the small messages before it: a chunk of their own
            self._finish_chunk(None)
        chunk = self._chunk
        if chunk.messages == 0:
            chunk.start_ns = chunk.end_ns = log_time
        else:
            chunk.start_ns = min(chunk.start_ns, log_time)
            chunk.end_ns = max(chunk.end_ns, log_time)
        chunk.messages += 1
        chunk.index.setdefault(channel_id, []).extend((log_time, self._used))
        self._reserve(_MESSAGE.size)
        _MESSAGE.pack_into(
            self._buffer,
            self._used,
            Opcode.MESSAGE,
            22 + size,
            channel_id,
            sequence & 0xFFFFFFFF,
            log_time,
            publish_time,
        )
        self._used += _MESSAGE.size
        if large or self._used + size >= self._chunk_size:  # it ends the chunk: no copy
            self._finish_chunk(data)
            return
        self._view[self._used : self._used + size] = memoryview(data).cast("B")
        self._used += size

    def copy_chunk(self, src_fd: int, index: ChunkIndex, *, where: str) -> int:
        """Append the chunk of ``index`` (in the MCAP file ``src_fd``) and its message indexes
        byte for byte (``copy_file_range``: the kernel copies), after the open chunk; returns its
        message count. Its schemas and channels must be added with their ids. ``where`` names
        the source in errors.

        Raises:
            LogError: the bytes are not what the source's summary says (repair it).
        """
        self.end_chunk()
        if self._jobs is not None:
            self._jobs.join()  # the chunks queued before it are written
        self._raise_failure()
        start = index.chunk_start_offset
        head = os.pread(src_fd, 9, start)
        opcode, length = struct.unpack("<BQ", head) if len(head) == 9 else (0, 0)
        if opcode != Opcode.CHUNK or 9 + length != index.chunk_length:
            msg = f"{where}: no chunk at offset {start} where its summary says; repair the log (`redrive repair`)"
            raise LogError(msg)
        counts = index_counts(
            os.pread(src_fd, index.message_index_length, start + index.chunk_length),
            where=f"{where} (chunk at offset {start})",
        )
        if set(counts) != set(index.message_index_offsets):
            msg = f"{where}: the chunk at offset {start} does not match its index; repair the log"
            raise LogError(msg)
        size = index.chunk_length + index.message_index_length
        with self._lock:
            new_start = self.position
            try:
                copy_range(src_fd, self._fd, start, size, where=where)
            except BaseException as err:
                self._failed = err
                raise
            self.position += size
            shift = new_start - start
            self._chunk_indexes.append(
                dataclasses.replace(
                    index,
                    chunk_start_offset=new_start,
                    message_index_offsets={
                        c: at + shift for c, at in index.message_index_offsets.items()
                    },
                )
            )
            self._count_written(counts, index.message_start_time, index.message_end_time)
        return sum(counts.values())

    def _count_written(self, counts: Mapping[int, int], start_ns: int, end_ns: int) -> None:
        """Messages (channel → count) of a chunk that reached the file (under the lock)."""
        written = self._written_counts
        for channel_id, n in counts.items():
            written[channel_id] = written.get(channel_id, 0) + n
            self.written_messages += n
        span = self._written_span
        self._written_span = (
            (start_ns, end_ns) if span is None else (min(span[0], start_ns), max(span[1], end_ns))
        )

    def end_chunk(self) -> None:
        """Finish the open chunk now (if it holds a message), so it reaches the file."""
        self._raise_failure()
        if self._chunk.messages:
            self._finish_chunk(None)

    def _reserve(self, size: int) -> None:
        if self._used + size > len(self._buffer):
            grown = bytearray(max(2 * len(self._buffer), self._used + size))
            grown[: self._used] = self._view[: self._used]
            self._view.release()
            self._buffer = grown
            self._view = memoryview(grown)

    def _finish_chunk(self, tail: bytes | bytearray | memoryview | None) -> None:
        head = self._view[: self._used]
        chunk = self._chunk
        self.finished_chunks += 1
        # compressed: the thread gets its own copy of the bytes — unless it is behind (its queue
        # full): then the chunk is written now, uncompressed, rather than the recording waiting
        # (and its live sources dropping messages); not while a chunk defining schemas or
        # channels is queued, so no message reaches the file before its channel
        jobs = self._jobs
        behind = self._live and jobs is not None and jobs.full() and not self._defining
        if self._jobs is not None and not behind:
            records = bytes(head) if tail is None else b"".join((head, tail))
            with self._lock:
                self._queued += len(records)
                self._defining += chunk.defines
            job = _ChunkJob(records, chunk.start_ns, chunk.end_ns, chunk.index, chunk.defines)
            self._submit(job)
        else:
            self.uncompressed_chunks += behind
            pieces = [head] if tail is None else [head, memoryview(tail).cast("B")]
            self._write_chunk(pieces, chunk.start_ns, chunk.end_ns, chunk.index, None)
        del head
        self._used = 0
        self._chunk = _OpenChunk()

    def _write_chunk(
        self,
        records: Sequence[bytes | memoryview],
        start_ns: int,
        end_ns: int,
        index: dict[int, list[int]],
        compressed: tuple[str, bytes] | None,
    ) -> None:
        """Chunk record + its message indexes at :attr:`position` (one ``writev``)."""
        chunk = encode_chunk(records, start_ns, end_ns, index, compressed)
        with self._lock:  # the compression thread and the caller may both write chunks
            if self._failed is not None:  # nothing after a failed write: it may be cut in two
                raise self._failed
            chunk_start = self.position
            try:
                self.position += write_all(self._fd, chunk.pieces)
            except BaseException as err:
                self._failed = err
                raise
            self._chunk_indexes.append(chunk.index_at(chunk_start))
            counts = self._written_counts
            for channel_id, entries in index.items():
                counts[channel_id] = counts.get(channel_id, 0) + len(entries) // 2
                self.written_messages += len(entries) // 2
            span = self._written_span
            self._written_span = (
                (start_ns, end_ns)
                if span is None
                else (min(span[0], start_ns), max(span[1], end_ns))
            )

    # -- the compression thread ----------------------------------------------------------------
    def _submit(self, job: _ChunkJob | None) -> None:
        assert self._jobs is not None
        while True:  # a bounded wait, so a failed thread is noticed
            try:
                self._jobs.put(job, timeout=0.5)
                return
            except queue.Full:
                self._raise_failure()

    def _compress_loop(self) -> None:
        jobs, compress = self._jobs, self._compress
        assert jobs is not None
        assert compress is not None
        if self._live:  # compress with the CPU receiving leaves over (Linux: nice per thread)
            with contextlib.suppress(OSError, AttributeError):
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), _COMPRESS_NICE)
        name = self.compression
        while True:
            job = jobs.get()
            if job is None:
                jobs.task_done()
                return
            if self._failed is not None:
                jobs.task_done()
                continue  # drain: the caller raises the failure
            try:
                packed = compress(job.records)
                self._write_chunk(
                    [job.records], job.start_ns, job.end_ns, job.index, (name, packed)
                )
                with self._lock:
                    self._queued -= len(job.records)
                    self._defining -= job.defines
            except BaseException as err:  # handed to the caller's thread
                self._failed = err
            jobs.task_done()

    def _raise_failure(self) -> None:
        if self._failed is not None:
            raise self._failed

    @property
    def chunks(self) -> int:
        """Chunks written so far."""
        return len(self._chunk_indexes)

    @property
    def size_estimate(self) -> int:
        """The file's size once what is queued is written (queued chunks counted uncompressed,
        the open chunk not at all)."""
        return self.position + self._queued

    def _put(self, record: bytes) -> int:
        """Write ``record`` after everything queued; returns where it starts in the file."""
        if self._jobs is not None:
            self._jobs.join()  # the thread wrote every chunk queued before it
            self._raise_failure()
        with self._lock:
            if self._failed is not None:
                raise self._failed
            start = self.position
            try:
                self.position += write_all(self._fd, [record])
            except BaseException as err:
                self._failed = err
                raise
        return start

    def _drain(self) -> None:
        """Wait until the compression thread wrote everything queued (and stop it)."""
        if self._thread is None:
            return
        self._submit(None)
        self._thread.join()
        self._thread = None
        self._jobs = None
        self._raise_failure()

    # -- the end -----------------------------------------------------------------------------
    def finish(self) -> None:
        """Write the open chunk, the data end, the summary and the footer (the caller closes
        and syncs ``fd``)."""
        self.end_chunk()
        self._drain()
        self._put(self._tail(self.position))

    def _tail(self, start: int) -> bytes:
        """The data end, summary and footer of a file whose data section ends at ``start``: the
        schemas, channels and chunks written so far and the statistics of their messages."""
        data_end = record_bytes(DataEnd(data_section_crc=0))
        first, last = self._written_span or (0, 0)
        statistics = Statistics(
            message_count=self.written_messages,
            schema_count=len(self._schemas),
            channel_count=len(self._channels),
            attachment_count=len(self._attachment_indexes),
            metadata_count=len(self._metadata_indexes),
            chunk_count=len(self._chunk_indexes),
            message_start_time=first,
            message_end_time=last,
            channel_message_counts={c: self._written_counts.get(c, 0) for c in self._channels},
        )
        return data_end + summary_section(
            start + len(data_end),
            schemas=list(self._schemas.values()),
            channels=list(self._channels.values()),
            statistics=statistics,
            chunk_indexes=self._chunk_indexes,
            metadata_indexes=self._metadata_indexes,
            attachment_indexes=self._attachment_indexes,
        )

    def salvage(self) -> bool:
        """After a write failed (a full disk): drop what did not reach the file whole — the
        record being written, the open chunk, the chunks queued for compression — cut the file
        back to its last whole record, and close it with the summary of the chunks it holds
        when there is room for that. Returns whether the summary was written; without it the
        file reads as one cut off after its last chunk (``redrive info`` and ``run`` read it,
        ``redrive repair`` indexes it). The caller syncs and closes ``fd``."""
        self.abandon()
        with self._lock:
            end = self.position
            self._failed = None
        os.ftruncate(self._fd, end)
        os.lseek(self._fd, end, os.SEEK_SET)
        tail = self._tail(end)
        try:
            write_all(self._fd, [tail])
            os.fsync(self._fd)
        except OSError:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, end)
            return False
        self.position = end + len(tail)
        return True

    def abandon(self) -> None:
        """Stop the compression thread without writing what it still holds (an aborted file)."""
        if self._thread is not None and self._jobs is not None:
            self._failed = self._failed or LookupError("the file was abandoned")
            self._jobs.put(None)  # the thread skips what is queued, so there is room soon
            self._thread.join()
            self._thread = None
            self._jobs = None
