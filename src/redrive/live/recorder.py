"""The Data Logger: records a live session's streams to MCAP while it runs.

It reads every stream as a *lossless* reader (the sources wait for it rather than drop a message
it has not recorded) in its own thread, so the algorithm pipeline never waits for the disk.

* A session of ROS 1 topics only (the scraper's ``ros1`` streams) is written with the MCAP
  ``ros1`` profile: each message's bytes exactly as the publisher sent them, schemas in
  ``ros1msg`` encoding from ROS Noetic's definitions (``rosbag``-compatible md5sums). ``redrive
  info``/``open_log``, Foxglove and Lichtblick read it.
* Otherwise (ROS 2 topics, typed samples from the replay or synthetic sources, possibly mixed
  with ROS 1 topics) it is redrive's native format (:class:`redrive.io.writer.McapWriter`: ROS 2
  CDR of standard types); ROS 2 messages are written byte for byte as DDS delivered them, with
  the QoS their publishers offer as ``offered_qos_profiles``; ROS 1 messages are decoded and
  re-encoded as their standard type.

The file appears atomically when the logger stops (temporary file + rename); a crash leaves no
half-written file at the target path.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import tempfile
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import IO

from mcap.writer import CompressionType
from mcap.writer import Writer as McapRawWriter

from redrive.errors import LogError, TransportError, UnsupportedMessageError
from redrive.io.base import LogMessage
from redrive.io.decoders import decode
from redrive.io.typestore import typestore_for
from redrive.io.writer import McapWriter
from redrive.live.streams import StreamSpec, ros1_type
from redrive.transport import Message, Policy, ProducerGoneError, Reader
from redrive.transport.codec import KIND_CDR, KIND_ROS1, KIND_SENSOR, decode_sample

__all__ = ["DataLogger"]

logger = logging.getLogger(__name__)


class DataLogger:
    """Record ``specs`` to ``path`` until :meth:`stop`.

    Raises:
        ProducerGoneError: a stream has no writer within ``attach_timeout_s``.
        LogError: the file cannot be created.
    """

    def __init__(
        self, specs: Sequence[StreamSpec], path: str | Path, *, attach_timeout_s: float = 10.0
    ) -> None:
        self.path = Path(path)
        self.specs = list(specs)
        self.recorded: dict[str, int] = {s.topic: 0 for s in specs}
        self._msgtype = {s.topic: s.msgtype for s in specs}
        self.errors: list[str] = []
        self.raw_ros1 = all(s.payload == "ros1" for s in specs)
        self._readers: dict[str, Reader] = {}
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
        self._ros1_store = typestore_for(1, needed=ros1_types)[0] if ros1_types else None
        self._thread = threading.Thread(target=self._run, name="redrive-recorder", daemon=True)
        self._open()
        self._thread.start()

    # -- files -------------------------------------------------------------------------------
    def _open(self) -> None:
        if not self.raw_ros1:
            self._native: McapWriter | None = McapWriter(self.path)
            for spec in self.specs:
                if spec.payload == "cdr":  # ROS 2 topics: the QoS their publishers offer
                    self._native.add_channel(spec.topic, spec.msgtype, offered_qos=spec.qos)
            return
        self._native = None
        try:
            fd, tmp = tempfile.mkstemp(
                dir=self.path.parent, prefix=f".{self.path.name}.", suffix=".part"
            )
        except OSError as err:
            msg = f"{self.path}: cannot create a file in {self.path.parent} ({err.strerror})"
            raise LogError(msg) from err
        os.chmod(tmp, 0o644)
        self._tmp = Path(tmp)
        self._fh: IO[bytes] = os.fdopen(fd, "wb")
        self._raw = McapRawWriter(self._fh, compression=CompressionType.ZSTD)
        self._raw.start(profile="ros1", library="redrive")
        self._channels: dict[str, int] = {}
        self._seq: dict[str, int] = {}
        assert self._ros1_store is not None
        schemas: dict[str, int] = {}
        md5s: dict[str, str] = {}
        for spec in self.specs:
            if spec.msgtype not in schemas:
                text, md5 = self._ros1_store.generate_msgdef(spec.msgtype, ros_version=1)
                schema_id = self._raw.register_schema(
                    name=ros1_type(spec.msgtype), encoding="ros1msg", data=text.encode()
                )
                schemas[spec.msgtype] = schema_id
                md5s[spec.msgtype] = md5
            self._channels[spec.topic] = self._raw.register_channel(
                topic=spec.topic,
                message_encoding="ros1",
                schema_id=schemas[spec.msgtype],
                metadata={"md5sum": md5s[spec.msgtype]},
            )
            self._seq[spec.topic] = 0

    # -- the thread --------------------------------------------------------------------------
    def _run(self) -> None:
        fds = {r.fileno(): t for t, r in self._readers.items()}
        gone: set[str] = set()
        while len(gone) < len(fds):
            stopping = self._stop.is_set()
            if not stopping:
                select.select(list(fds), [], [], 0.1)
            idle = True
            for topic, reader in self._readers.items():
                if topic in gone:
                    continue
                try:
                    # zero-copy views: the one copy is the file's own (bytes or CDR encoding)
                    while True:
                        with reader.view(timeout_s=0.0) as msg:
                            if msg is None:
                                break
                            idle = False
                            self._write(topic, msg)
                except ProducerGoneError:
                    gone.add(topic)
                except (TransportError, LogError, UnsupportedMessageError) as err:
                    self.errors.append(f"{topic}: {err}")
                    logger.warning("recording %s: %s", topic, err)
            if stopping and idle:
                return

    def _write(self, topic: str, msg: Message) -> None:
        kind, meta, data = msg.kind, msg.meta, msg.payload
        log_ns, stamp_ns = msg.publish_ns, msg.stamp_ns
        if self._native is None:
            if kind != KIND_ROS1:
                text = f"message of kind {kind} on a ROS 1 recording"
                raise TransportError(text)
            seq = self._seq[topic]
            self._seq[topic] = seq + 1
            self._raw.add_message(
                channel_id=self._channels[topic],
                log_time=log_ns,
                publish_time=stamp_ns or log_ns,
                data=data.tobytes(),
                sequence=seq,
            )
        elif kind == KIND_CDR:  # ROS 2: recorded as it came off the wire
            self._native.write_raw(topic, self._msgtype[topic], log_ns, data.data)
        elif kind == KIND_SENSOR:
            sample = decode_sample(meta, data)
            self._native.write(
                topic, log_ns, sample.data, frame_id=sample.frame_id, stamp_ns=sample.stamp_ns
            )
        else:
            assert self._ros1_store is not None
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

    # -- stopping ----------------------------------------------------------------------------
    def stop(self, *, timeout_s: float = 30.0) -> Path:
        """Record what the streams still hold, close the file; returns its path."""
        self._stop.set()
        self._thread.join(timeout=timeout_s)
        self._close_readers()
        if self._native is not None:
            self._native.close()
        else:
            self._raw.finish()  # type: ignore[no-untyped-call]
            self._fh.close()
            os.replace(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        """Stop without keeping the file."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        self._close_readers()
        if self._native is not None:
            self._native.abort()
        else:
            with contextlib.suppress(OSError):
                self._fh.close()
            self._tmp.unlink(missing_ok=True)

    def _close_readers(self) -> None:
        for reader in self._readers.values():
            reader.close()
        self._readers.clear()
