"""The Data Logger: records a live session's streams to MCAP while it runs.

It reads every stream as a *lossless* reader (the sources wait for it rather than drop a message
it has not recorded) in its own thread, so the algorithm pipeline never waits for the disk.

* A session of ROS 1 topics only (the scraper's ``ros1`` streams) is written with the MCAP
  ``ros1`` profile: each message's bytes exactly as the publisher sent them, schemas in
  ``ros1msg`` encoding — the full definition the publisher sent in its connection header (as
  ``rosbag record`` stores it; so types redrive has no decoder or definition of are recorded
  too), else ROS Noetic's. ``redrive info``/``open_log``, rosbags, Foxglove and Lichtblick read
  it. It may be split into numbered files (:mod:`redrive.io.mcap.split`).
* Otherwise (ROS 2 topics, typed samples from the replay or synthetic sources, possibly mixed
  with ROS 1 topics) it is redrive's native format (:class:`redrive.io.mcap.writer.McapWriter`: ROS 2
  CDR of standard types); ROS 2 messages are written byte for byte as DDS delivered them, with
  the QoS their publishers offer as ``offered_qos_profiles``; ROS 1 messages are decoded and
  re-encoded as their standard type. It may be split too, each file declaring every channel.

The file appears atomically when the logger stops (temporary ``.part`` file + rename). What was
recorded is never dropped: an error in the session keeps it (:meth:`DataLogger.abort` drops only
a recording that holds no message), and a full disk ends the recording with every chunk that
reached the file, closed with its index when there is room (:attr:`DataLogger.failure` says so;
the session's ``on_failure`` ends it). A process killed outright leaves the part, and the next
recording in that folder names it (:func:`redrive.io.partfiles.orphaned_parts`).
"""

from __future__ import annotations

import logging
import select
import threading
from collections.abc import Callable, Sequence
from pathlib import Path

from redrive.errors import DiskFullError, LogError, TransportError, UnsupportedMessageError
from redrive.io.base import LogMessage
from redrive.io.mcap.split import Ros1Schema, SplitMcapWriter, SplitNativeWriter
from redrive.io.mcap.writer import Compression
from redrive.io.ros.decoders import decode
from redrive.io.ros.typestore import typestore_for
from redrive.live.scraper_state import Ros1Definition
from redrive.live.streams import StreamSpec, ros1_type
from redrive.transport import Message, Policy, ProducerGoneError, Reader
from redrive.transport.codec import KIND_CDR, KIND_ROS1, KIND_SENSOR, decode_ros1, decode_sample
from redrive.transport.heap import keep_freed_memory

__all__ = ["DataLogger"]

logger = logging.getLogger(__name__)

#: messages read from one stream before the recorder turns to the next
_BATCH = 4


class DataLogger:
    """Record ``specs`` to ``path`` until :meth:`stop`; more streams join with :meth:`add`.

    Args:
        specs: the streams to record.
        path: the MCAP file (with a split limit: the name the numbered files are made from).
        definitions: topic → the type's full definition from the publisher (ROS 1 sessions:
            :meth:`redrive.live.session.LiveSession.definition`); without one, ROS Noetic's.
        split_size_bytes, split_duration_s: split the recording into numbered files.
        max_size_bytes: :attr:`full` is set once this many bytes of messages are recorded.
        compression: chunk compression, ``zstd`` (default), ``lz4`` or ``none`` (as ``rosbag
            record`` writes by default: the cheapest in CPU).
        native: write redrive's native format (ROS 2 CDR) even when ``specs`` is empty — a ROS 2
            recording whose topics all join later through :meth:`add`.
        on_failure: called (from the recorder's thread) when the recording had to end — the
            disk is full: the session should end too, since its lossless sources now wait.

    Raises:
        ProducerGoneError: a stream has no writer within ``attach_timeout_s``.
        LogError: the file cannot be created.
    """

    def __init__(
        self,
        specs: Sequence[StreamSpec],
        path: str | Path,
        *,
        attach_timeout_s: float = 10.0,
        definitions: Callable[[str], Ros1Definition | None] | None = None,
        split_size_bytes: int | None = None,
        split_duration_s: float | None = None,
        max_size_bytes: int | None = None,
        compression: Compression = "zstd",
        native: bool = False,
        on_failure: Callable[[], None] | None = None,
    ) -> None:
        self.path = Path(path)
        #: why the recording ended before :meth:`stop` (a full disk), else None
        self.failure: str | None = None
        #: set with :attr:`failure`
        self.failed = threading.Event()
        self._on_failure = on_failure
        self.specs = list(specs)
        self.recorded: dict[str, int] = {s.topic: 0 for s in specs}
        #: bytes of message data recorded per topic
        self.recorded_bytes: dict[str, int] = {s.topic: 0 for s in specs}
        self._msgtype = {s.topic: s.msgtype for s in specs}
        self.errors: list[str] = []
        self.raw_ros1 = not native and all(s.payload == "ros1" for s in specs)
        self.max_size_bytes = max_size_bytes
        #: set when the recording reached ``max_size_bytes``
        self.full = threading.Event()
        #: the files written, once stopped (more than one when split)
        self.files: list[Path] = []
        self._definitions = definitions
        self._schemas: dict[str, Ros1Schema] = {}
        self._attach_timeout_s = attach_timeout_s
        self._readers: dict[str, Reader] = {}
        self._pending: list[tuple[StreamSpec, Reader]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        try:
            for spec in specs:
                self._readers[spec.topic] = Reader(
                    spec.stream, timeout_s=attach_timeout_s, policy=Policy.LOSSLESS
                )
        except BaseException:
            self._close_readers()
            raise
        ros1_types = sorted({s.msgtype for s in specs if s.payload == "ros1"})
        self._ros1_store = (
            typestore_for(1, needed=ros1_types)[0] if ros1_types and not self.raw_ros1 else None
        )
        self._native: SplitNativeWriter | None = None
        self._files: SplitMcapWriter | None = None
        try:
            if self.raw_ros1:
                self._files = SplitMcapWriter(
                    self.path,
                    split_size_bytes=split_size_bytes,
                    split_duration_s=split_duration_s,
                    compression=compression,
                )
            else:
                self._native = SplitNativeWriter(
                    self.path,
                    split_size_bytes=split_size_bytes,
                    split_duration_s=split_duration_s,
                    compression=compression,
                )
                for spec in self.specs:
                    if spec.payload == "cdr":  # ROS 2 topics: the QoS their publishers offer
                        self._native.add_channel(spec.topic, spec.msgtype, offered_qos=spec.qos)
        except BaseException:
            self._close_readers()
            raise
        keep_freed_memory()  # the MCAP writer's chunk buffers reuse warm pages
        self._thread = threading.Thread(target=self._run, name="redrive-recorder", daemon=True)
        self._thread.start()

    def add(self, spec: StreamSpec) -> None:
        """Record one more stream (a topic that appeared while recording): ROS 1 bytes on a ROS 1
        recording, ROS 2 CDR on a native one.

        Raises:
            ProducerGoneError: the stream has no writer within the attach timeout.
        """
        reader = Reader(spec.stream, timeout_s=self._attach_timeout_s, policy=Policy.LOSSLESS)
        with self._lock:
            self.specs.append(spec)
            self._msgtype[spec.topic] = spec.msgtype
            self.recorded.setdefault(spec.topic, 0)
            self.recorded_bytes.setdefault(spec.topic, 0)
            self._pending.append((spec, reader))

    @property
    def bytes_written(self) -> int:
        """Bytes of the recording on disk so far (ROS 1 recordings; else message bytes)."""
        if self._files is not None:
            return self._files.bytes_written
        return sum(self.recorded_bytes.values())

    @property
    def chunks(self) -> tuple[int, int]:
        """MCAP chunks of the recording: (written, written uncompressed because the compressor
        was behind)."""
        if self._files is not None:
            return self._files.chunks
        return self._native.chunks if self._native is not None else (0, 0)

    # -- the thread --------------------------------------------------------------------------
    def _run(self) -> None:
        gone: set[str] = set()
        idle = True
        while True:
            with self._lock:
                for spec, reader in self._pending:
                    self._readers[spec.topic] = reader
                    if self._native is not None and spec.payload == "cdr":
                        try:  # in this thread: the writer is not shared
                            self._native.add_channel(spec.topic, spec.msgtype, offered_qos=spec.qos)
                        except (LogError, UnsupportedMessageError) as err:
                            self.errors.append(f"{spec.topic}: {err}")
                            gone.add(spec.topic)
                self._pending.clear()
            fds = [r.fileno() for t, r in self._readers.items() if t not in gone]
            stopping = self._stop.is_set()
            if not fds and stopping:
                return
            if not stopping:  # after a round that read something, look again without waiting
                select.select(fds, [], [], 0.1 if idle else 0.0)
            idle = True
            for topic, reader in self._readers.items():
                if topic in gone:
                    continue
                try:
                    # zero-copy views: the one copy is the file's own (bytes or CDR encoding);
                    # a few messages of each stream in turn: a busy stream does not hold up the
                    # others (their sources wait for the recorder, and their publishers drop)
                    for _ in range(_BATCH):
                        with reader.view(timeout_s=0.0) as msg:
                            if msg is None:
                                break
                            idle = False
                            self._write(topic, msg)
                except DiskFullError as err:
                    self._fail(str(err))
                    return
                except OSError as err:  # the disk itself failed: end with the reason
                    self._fail(f"{self.path}: cannot write: {err}")
                    return
                except ProducerGoneError:
                    gone.add(topic)
                except (TransportError, LogError, UnsupportedMessageError) as err:
                    self.errors.append(f"{topic}: {err}")
                    logger.warning("recording %s: %s", topic, err)
            if (
                self.max_size_bytes is not None
                and not self.full.is_set()
                and sum(self.recorded_bytes.values()) >= self.max_size_bytes
            ):
                self.full.set()
            if stopping and idle:
                return

    def _fail(self, reason: str) -> None:
        """The recording cannot go on: say why, and end the session (its sources wait)."""
        if self.failure is None:
            self.failure = reason
            logger.info("recording stopped: %s", reason)
        self.failed.set()
        if self._on_failure is not None:
            self._on_failure()

    def _schema(self, topic: str, msg_type: str, md5sum: str) -> Ros1Schema:
        schema = self._schemas.get(topic)
        if schema is not None:
            return schema
        found = self._definitions(topic) if self._definitions is not None else None
        if found is not None and found.text:
            schema = Ros1Schema(msg_type=found.msg_type, md5sum=found.md5sum, text=found.text)
        else:
            msgtype = self._msgtype[topic]
            store = typestore_for(1, needed=[msgtype])[0]
            if msgtype not in store.fielddefs:
                text = (
                    f"no definition of {msg_type}: its publisher sent none and redrive knows "
                    "none; the topic is not recorded"
                )
                raise UnsupportedMessageError(text)
            text_def, md5 = store.generate_msgdef(msgtype, ros_version=1)
            schema = Ros1Schema(msg_type=ros1_type(msgtype), md5sum=md5sum or md5, text=text_def)
        self._schemas[topic] = schema
        return schema

    def _write(self, topic: str, msg: Message) -> None:
        kind, meta, data = msg.kind, msg.meta, msg.payload
        log_ns, stamp_ns = msg.publish_ns, msg.stamp_ns
        if self._files is not None:
            if kind != KIND_ROS1:
                text = f"message of kind {kind} on a ROS 1 recording"
                raise TransportError(text)
            head = decode_ros1(bytes(meta), data)
            self._files.write(
                topic,
                self._schema(topic, head.msg_type, head.md5sum),
                log_ns=log_ns,
                publish_ns=stamp_ns or log_ns,
                data=data.data,  # the view: the MCAP chunk copies it, once
            )
        elif kind == KIND_CDR:  # ROS 2: recorded as it came off the wire
            assert self._native is not None
            self._native.write_raw(topic, self._msgtype[topic], log_ns, data.data)
        elif kind == KIND_SENSOR:
            assert self._native is not None
            sample = decode_sample(meta, data)
            self._native.write(
                topic, log_ns, sample.data, frame_id=sample.frame_id, stamp_ns=sample.stamp_ns
            )
        else:
            assert self._ros1_store is not None
            assert self._native is not None
            decoded = decode(
                LogMessage(
                    topic=topic,
                    msgtype=self._msgtype[topic],
                    log_time_ns=log_ns,
                    encoding="ros1",
                    raw=data.data,
                ),
                lambda m: self._ros1_store.deserialize_ros1(m.raw, m.msgtype),  # type: ignore[union-attr]
            )
            self._native.write(topic, log_ns, decoded)
        self.recorded[topic] += 1
        self.recorded_bytes[topic] += len(data)

    # -- stopping ----------------------------------------------------------------------------
    def stop(self, *, timeout_s: float = 30.0) -> Path:
        """Record what the streams still hold, close the file; returns its path (the first of
        split files: :attr:`files` has them all). A full disk while closing it keeps what was
        written (:attr:`failure` says so) rather than raising."""
        self._stop.set()
        self._thread.join(timeout=timeout_s)
        self._close_readers()
        writer: SplitNativeWriter | SplitMcapWriter | None = self._native or self._files
        assert writer is not None
        try:
            self.files = writer.close()
        except DiskFullError as err:
            self._fail(str(err))
            self.files = list(writer.finished)
        if self.failure is not None:
            self._count_files()
        return self.files[0] if self.files else self.path

    def _count_files(self) -> None:
        """After a failure: what the files hold, read back from them (the counts of messages
        received include those the disk had no room for), and a check that they read."""
        from redrive.io import open_log

        recorded = dict.fromkeys(self.recorded, 0)
        sizes = dict.fromkeys(self.recorded, 0)
        for path in self.files:
            try:
                with open_log(path, packets="raw") as log:
                    for topic, info in log.topics.items():
                        recorded[topic] = recorded.get(topic, 0) + info.count
                        sizes[topic] = sizes.get(topic, 0) + max(info.size_bytes, 0)
            except LogError as err:
                self.errors.append(f"{path}: does not read back: {err}")
        self.recorded, self.recorded_bytes = recorded, sizes

    def abort(self) -> None:
        """Stop after an error. What was recorded is kept (a recording is the only copy of what
        its sources sent, :meth:`stop`); a file that holds no message yet is dropped (split
        files finished before stay)."""
        if any(self.recorded.values()):
            self.stop(timeout_s=5.0)
            return
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._close_readers()
        if self._native is not None:
            self._native.abort()
        elif self._files is not None:
            self._files.abort()

    def _close_readers(self) -> None:
        with self._lock:
            for _, reader in self._pending:
                reader.close()
            self._pending.clear()
        for reader in self._readers.values():
            reader.close()
        self._readers.clear()
