"""ROS 1 messages into MCAP files (``ros1`` profile), optionally split into numbered files.

Each file is written to a ``.part`` (:mod:`redrive.io.partfiles`) and moved into place when it is
finished, so every file that appears is complete and valid alone. Split files are named
``<stem>_0000.mcap``, ``<stem>_0001.mcap`` … beside the target; each holds the schemas and
channels of the topics it has messages of. Together they hold exactly what one unsplit file would.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

from redrive.errors import DiskFullError, LogError, is_no_space
from redrive.io.mcap.part import McapPart
from redrive.io.mcap.writer import COMPRESSION as _COMPRESSION
from redrive.io.mcap.writer import Compression, McapWriter

__all__ = ["Ros1Schema", "SplitMcapWriter", "split_name"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class Ros1Schema:
    """A topic's ROS 1 type as the file records it: ``msg_type`` (``sensor_msgs/Imu``), its
    ``md5sum`` and the full ``ros1msg`` definition ``text``."""

    msg_type: str
    md5sum: str
    text: str


def split_name(path: Path, index: int) -> Path:
    """``drive.mcap`` → ``drive_0003.mcap`` for ``index`` 3."""
    return path.with_name(f"{path.stem}_{index:04d}{path.suffix or '.mcap'}")


class _SplitParts:
    """What both split writers share: the file the current part goes to, when it is full, the
    chunk size a split limit allows, and the chunk counts of the parts finished so far."""

    def __init__(
        self,
        path: Path,
        *,
        split_size_bytes: int | None,
        split_duration_s: float | None,
        compression: Compression,
    ) -> None:
        self.path = path
        if compression not in _COMPRESSION:
            msg = f"compression must be one of {sorted(_COMPRESSION)}, got {compression!r}"
            raise ValueError(msg)
        self.compression: Compression = compression
        self.split_size_bytes = split_size_bytes
        self.split_duration_s = split_duration_s
        self.split = split_size_bytes is not None or split_duration_s is not None
        #: the files finished so far, in order
        self.finished: list[Path] = []
        self._chunks_done = (0, 0)  # chunks of the finished files: all, written uncompressed
        self._index = 0
        self._opened_s = 0.0

    def _target(self) -> Path:
        return split_name(self.path, self._index) if self.split else self.path

    def _chunk_size(self) -> int:
        """1 MiB chunks (a message bigger than a chunk goes to the file without a copy), smaller
        when a split size asks for it."""
        chunk = 1 << 20
        if self.split_size_bytes is not None:
            chunk = max(4 << 10, min(chunk, self.split_size_bytes // 4))
        return chunk

    def _full(self, size_estimate: int) -> bool:
        if self.split_size_bytes is not None and size_estimate >= self.split_size_bytes:
            return True
        return (
            self.split_duration_s is not None
            and time.monotonic() - self._opened_s >= self.split_duration_s
        )

    def _chunks_with(self, current: tuple[int, int] | None) -> tuple[int, int]:
        """The finished parts' chunk counts (all, written uncompressed) plus ``current``'s."""
        done, behind = self._chunks_done
        if current is not None:
            done, behind = done + current[0], behind + current[1]
        return done, behind

    def _part_finished(self, path: Path, chunks: tuple[int, int]) -> None:
        self.finished.append(path)
        self._chunks_done = self._chunks_with(chunks)

    def _cut_short(self, err: DiskFullError, chunks: tuple[int, int]) -> DiskFullError:
        """The current file ended by a full disk: what it holds is kept where ``err`` says."""
        if err.kept is not None and Path(err.kept) not in self.finished:
            self._part_finished(Path(err.kept), chunks)
        return err


class SplitMcapWriter(_SplitParts):
    """Write ROS 1 messages to ``path`` — or, when a split limit is given, to numbered files.

    Args:
        path: the target file (``--record``).
        split_size_bytes: start a new file once the current one holds this many bytes.
        split_duration_s: start a new file after this many seconds of wall time.
        compression: chunk compression, ``zstd`` (default), ``lz4`` or ``none``.

    Raises:
        LogError: the folder cannot be written.
    """

    def __init__(
        self,
        path: Path,
        *,
        split_size_bytes: int | None = None,
        split_duration_s: float | None = None,
        compression: Compression = "zstd",
    ) -> None:
        super().__init__(
            path,
            split_size_bytes=split_size_bytes,
            split_duration_s=split_duration_s,
            compression=compression,
        )
        #: bytes of the finished files
        self.finished_bytes = 0
        self._part: McapPart | None = None
        self._open()

    @property
    def bytes_written(self) -> int:
        """Bytes on disk so far, every file (the current one up to its last written chunk)."""
        current = self._part.stream.size_estimate if self._part is not None else 0
        return self.finished_bytes + current

    @property
    def chunks(self) -> tuple[int, int]:
        """Chunks written so far, every file: (all, those written uncompressed because the
        compressor was behind — see :class:`~redrive.io.mcap.stream.McapStream`)."""
        part = self._part
        current = None if part is None else (part.stream.chunks, part.stream.uncompressed_chunks)
        return self._chunks_with(current)

    def _open(self) -> None:
        self._part = McapPart(
            self._target(),
            profile="ros1",
            compression=self.compression,
            chunk_size_bytes=self._chunk_size(),
            live=True,
        )
        self._writer = self._part.stream
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._opened_s = time.monotonic()

    def write(
        self,
        topic: str,
        schema: Ros1Schema,
        *,
        log_ns: int,
        publish_ns: int,
        data: bytes | memoryview,
    ) -> None:
        """Add one message (its bytes as published) to the current file, splitting first when the
        current file is full. ``data`` is copied before this returns (a view may be released).

        Raises:
            DiskFullError: the disk is full: the current file ends with what reached it (kept,
                in :attr:`finished`), and the recording is closed.
        """
        if self._part is None:
            msg = f"{self.path}: the recording is closed"
            raise LogError(msg)
        try:
            self._write(topic, schema, log_ns=log_ns, publish_ns=publish_ns, data=data)
        except OSError as err:
            part, self._part = self._part, None
            if part is None or not is_no_space(err):
                raise
            stream = part.stream
            full = part.out_of_space(err)
            raise self._cut_short(full, (stream.chunks, stream.uncompressed_chunks)) from err
        except DiskFullError as err:  # a split's next file found no space
            self._part = None
            raise self._cut_short(err, (0, 0)) from err

    def _write(
        self,
        topic: str,
        schema: Ros1Schema,
        *,
        log_ns: int,
        publish_ns: int,
        data: bytes | memoryview,
    ) -> None:
        if self.split and self._channels and self._full(self._writer.size_estimate):
            self._finish_current()
            self._index += 1
            self._open()
        channel = self._channels.get(topic)
        if channel is None:
            schema_id = self._schemas.get(schema.msg_type)
            if schema_id is None:
                schema_id = self._writer.register_schema(
                    name=schema.msg_type, encoding="ros1msg", data=schema.text.encode()
                )
                self._schemas[schema.msg_type] = schema_id
            channel = self._writer.register_channel(
                topic=topic,
                message_encoding="ros1",
                schema_id=schema_id,
                metadata={"md5sum": schema.md5sum},
            )
            self._channels[topic] = channel
        seq = self._sequence.get(topic, 0)
        self._sequence[topic] = seq + 1
        self._writer.add_message(  # written or copied before it returns
            channel, log_time=log_ns, publish_time=publish_ns, sequence=seq, data=data
        )

    def _finish_current(self) -> None:
        part, self._part = self._part, None
        assert part is not None
        stream = part.stream
        try:
            target = part.close()
        except DiskFullError as err:
            raise self._cut_short(err, (stream.chunks, stream.uncompressed_chunks)) from err
        self._part_finished(target, (stream.chunks, stream.uncompressed_chunks))
        self.finished_bytes += target.stat().st_size
        logger.debug("recorded %s", target)

    def close(self) -> list[Path]:
        """Finish the current file; returns every file written, in order.

        Raises:
            DiskFullError: the disk filled while finishing it (it is kept, in the list).
        """
        if self._part is not None:
            self._finish_current()
        return list(self.finished)

    def abort(self) -> None:
        """Drop the file being written (files already finished stay)."""
        part, self._part = self._part, None
        if part is not None:
            part.abort()


class SplitNativeWriter(_SplitParts):
    """A ROS 2 recording (CDR as it came off the wire, or data-model values serialised as ROS 2
    messages) to ``path`` — or, with a split limit, to numbered files as
    :class:`SplitMcapWriter` writes ROS 1 ones: each a complete :class:`~redrive.io.mcap.writer.McapWriter`
    file, every channel (with the QoS its publishers offer) declared again in each.

    Args:
        path, split_size_bytes, split_duration_s, compression: as :class:`SplitMcapWriter`.

    Raises:
        LogError: the folder cannot be written.
    """

    def __init__(
        self,
        path: Path,
        *,
        split_size_bytes: int | None = None,
        split_duration_s: float | None = None,
        compression: Compression = "zstd",
    ) -> None:
        super().__init__(
            path,
            split_size_bytes=split_size_bytes,
            split_duration_s=split_duration_s,
            compression=compression,
        )
        self._channels: dict[str, tuple[str, str]] = {}  # topic: (type, offered QoS)
        self._current: McapWriter | None = None
        self._open()

    def _open(self) -> None:
        self._current = McapWriter(
            self._target(),
            compression=self.compression,
            chunk_size_bytes=self._chunk_size(),
            live=True,
        )
        self._opened_s = time.monotonic()
        for topic, (msgtype, qos) in self._channels.items():
            self._current.add_channel(topic, msgtype, offered_qos=qos)

    @property
    def chunks(self) -> tuple[int, int]:
        """Chunks written so far, every file: (all, written uncompressed), as
        :attr:`SplitMcapWriter.chunks`."""
        return self._chunks_with(None if self._current is None else self._current.chunks)

    def add_channel(self, topic: str, msgtype: str, *, offered_qos: str = "") -> None:
        """Declare a ROS 2 topic before its first message (in this file and every later one)."""
        self._channels[topic] = (msgtype, offered_qos)
        self._writer().add_channel(topic, msgtype, offered_qos=offered_qos)

    def _writer(self) -> McapWriter:
        if self._current is None:
            msg = f"{self.path}: the recording is closed"
            raise LogError(msg)
        if self.split and self._current.message_count and self._full(self._current.size_estimate):
            self._finish_current()
            self._index += 1
            self._open()
            assert self._current is not None
        return self._current

    def _no_space(self, err: DiskFullError) -> DiskFullError:
        current, self._current = self._current, None
        return self._cut_short(err, (0, 0) if current is None else current.chunks)

    def write_raw(
        self, topic: str, msgtype: str, log_time_ns: int, cdr_bytes: bytes | memoryview
    ) -> None:
        """One ROS 2 CDR message, as :meth:`McapWriter.write_raw <redrive.io.mcap.writer.McapWriter.write_raw>`.

        Raises:
            DiskFullError: as :meth:`SplitMcapWriter.write`.
        """
        try:
            self._writer().write_raw(topic, msgtype, log_time_ns, cdr_bytes)
        except DiskFullError as err:
            raise self._no_space(err) from err

    def write(
        self,
        topic: str,
        log_time_ns: int,
        value: object,
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> None:
        """A data-model value, as :meth:`McapWriter.write <redrive.io.mcap.writer.McapWriter.write>`."""
        try:
            self._writer().write(topic, log_time_ns, value, frame_id=frame_id, stamp_ns=stamp_ns)
        except DiskFullError as err:
            raise self._no_space(err) from err

    def close(self) -> list[Path]:
        """Finish the current file; returns every file written, in order."""
        if self._current is not None:
            self._finish_current()
        return list(self.finished)

    def _finish_current(self) -> None:
        current = self._current
        assert current is not None
        try:
            current.close()
        except DiskFullError as err:
            raise self._no_space(err) from err
        self._current = None
        self._part_finished(current.path, current.chunks)

    def abort(self) -> None:
        """Drop the file being written (files already finished stay)."""
        if self._current is not None:
            self._current.abort()
            self._current = None
