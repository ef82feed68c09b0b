"""Record to MCAP with ROS 2 CDR messages of standard types (the native redrive format).

The file uses profile ``ros2``, message encoding ``cdr`` and schemas in ``ros2msg`` encoding with
the full concatenated definition (the type, then ``MSG: pkg/Type`` sections for every nested
type), so Foxglove, Lichtblick and ``ros2 bag`` open it.  Every channel carries rosbag2's
``offered_qos_profiles`` (:mod:`redrive.io.mcap.qos`): ``/tf_static`` transient local, so ``ros2 bag
play`` replays it latched; every other topic reliable and volatile.

Writes are atomic: everything goes to a hidden temporary file in the target directory, which is
renamed over ``path`` only when the writer closes normally; an exception inside the ``with``
block (or :meth:`McapWriter.abort`) removes it, so no half-written file is ever left — except
when the disk is full: then every chunk that reached the file is kept, closed with its index
when there is room, at ``path`` (or beside it, never over an existing file), and
:class:`~redrive.errors.DiskFullError` says where (:mod:`redrive.io.mcap.part`).

Writes survive a crash: each chunk is written to the file (and the file flushed) as soon as it
is complete — at ``chunk_size_bytes`` of messages, or once it spans ``chunk_span_s`` of log
time — so a process killed with SIGKILL leaves ``.NAME.*.part`` holding every chunk before the
last, which ``redrive info`` / ``run`` read and ``redrive repair`` turns into a valid MCAP
(docs/damaged_logs.md).

>>> with McapWriter("run.mcap") as out:                              # doctest: +SKIP
...     out.write("/lidar", stamp_ns, cloud, frame_id="velodyne")
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from types import MappingProxyType, TracebackType
from typing import Literal, Self

from mcap.writer import CompressionType
from rosbags.typesys.store import Typestore

from redrive.errors import LogError, UnsupportedMessageError, is_no_space
from redrive.io.mcap.part import McapPart
from redrive.io.mcap.qos import offered_qos_profiles
from redrive.io.ros.decoders.base import Decoded
from redrive.io.ros.encode import encode_value
from redrive.io.ros.typestore import typestore_for
from redrive.types import Frame, TrafficData, VehicleState

__all__ = ["COMPRESSION", "Compression", "McapWriter"]

logger = logging.getLogger(__name__)

Compression = Literal["zstd", "lz4", "none"]
COMPRESSION: Mapping[str, CompressionType] = MappingProxyType(
    {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
)


class McapWriter:
    """An MCAP file being written (a context manager; see the module text).

    Args:
        path: the ``.mcap`` file to create (replaced on success if it exists).
        compression: chunk compression, ``zstd`` (default), ``lz4`` or ``none``.
        typestore: the ROS 2 store whose definitions become the schemas; default
            ``typestore_for(2)`` (Humble + the types redrive ships).  Types registered on it later
            are picked up when first written.
        chunk_size_bytes: uncompressed bytes per chunk (at most: what a crash can lose).
        chunk_span_s: log time after which a chunk is closed even if it is smaller, so slow
            topics reach the disk too.
        live: a live recording: a compressor that is behind gets chunks written uncompressed
            rather than holding up the recording (:class:`~redrive.io.mcap.stream.McapStream`).
        zstd_level: the zstd level (default: 1 for a live recording, else 3); level 1 costs about
            a third of level 3's CPU for a few % more bytes, and reads back the same.

    Raises:
        LogError: the directory cannot be written.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        compression: Compression = "zstd",
        typestore: Typestore | None = None,
        chunk_size_bytes: int = 4 * 1024 * 1024,
        chunk_span_s: float = 2.0,
        live: bool = False,
        zstd_level: int | None = None,
    ) -> None:
        if compression not in COMPRESSION:
            msg = f"compression must be one of {sorted(COMPRESSION)}, got {compression!r}"
            raise ValueError(msg)
        self.path = Path(path)
        self.typestore = typestore if typestore is not None else typestore_for(2)[0]
        self.message_count = 0
        self._part = McapPart(
            self.path,
            profile="ros2",
            compression=compression,
            chunk_size_bytes=chunk_size_bytes,
            live=live,
            zstd_level=zstd_level,
        )
        self._writer = self._part.stream
        self._chunk_span_ns = round(chunk_span_s * 1e9)
        self._chunk_first_ns: int | None = None  # log time of the open chunk's first message
        self._finished = 0  # chunks finished so far
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[str, int]] = {}
        self._sequences: dict[int, int] = {}

    # -- schemas and channels ------------------------------------------------------------------

    def _schema_id(self, msgtype: str) -> int:
        schema_id = self._schemas.get(msgtype)
        if schema_id is None:
            if msgtype not in self.typestore.fielddefs:
                msg = (
                    f"{self.path}: no definition of {msgtype} is known, so no schema can be "
                    "written; register it on the writer's typestore first"
                )
                raise UnsupportedMessageError(msg)
            text, _ = self.typestore.generate_msgdef(msgtype, ros_version=2)
            schema_id = self._writer.register_schema(
                name=msgtype, encoding="ros2msg", data=text.encode("utf-8")
            )
            self._schemas[msgtype] = schema_id
        return schema_id

    def add_channel(self, topic: str, msgtype: str, *, offered_qos: str = "") -> None:
        """Declare ``topic`` of ``msgtype`` before its first message, with the QoS its publishers
        offered (rosbag2's ``offered_qos_profiles`` YAML; "" for redrive's default: reliable, latched for
        ``/tf_static``).

        Raises:
            LogError: the topic already carries another type.
            UnsupportedMessageError: no definition of ``msgtype`` is known.
        """
        self._check_open()
        self._channel_id(topic, msgtype, offered_qos=offered_qos or None)

    def _channel_id(self, topic: str, msgtype: str, *, offered_qos: str | None = None) -> int:
        known = self._channels.get(topic)
        if known is not None:
            if known[0] != msgtype:
                msg = (
                    f"{self.path}: topic {topic} already carries {known[0]}, cannot also write "
                    f"{msgtype} on it; use another topic name"
                )
                raise LogError(msg)
            return known[1]
        if offered_qos is None:
            offered_qos = offered_qos_profiles(topic)
        metadata = {"offered_qos_profiles": offered_qos}
        channel_id = self._writer.register_channel(
            topic=topic,
            message_encoding="cdr",
            schema_id=self._schema_id(msgtype),
            metadata=metadata,
        )
        self._channels[topic] = (msgtype, channel_id)
        self._sequences[channel_id] = 0
        return channel_id

    @property
    def topics(self) -> Mapping[str, str]:
        """topic → msgtype of every channel written so far."""
        return MappingProxyType({t: m for t, (m, _) in self._channels.items()})

    # -- writing -------------------------------------------------------------------------------

    @property
    def chunks(self) -> tuple[int, int]:
        """Chunks written so far: (all, those written uncompressed because a live recording's
        compressor was behind)."""
        return int(self._writer.chunks), int(self._writer.uncompressed_chunks)

    @property
    def size_estimate(self) -> int:
        """Bytes of the file so far (written chunks and the open chunk's messages)."""
        return int(self._writer.size_estimate)

    def _check_open(self) -> None:
        if not self._part.is_open:
            msg = f"{self.path}: the writer is closed"
            raise LogError(msg)

    @contextmanager
    def _space(self) -> Iterator[None]:
        """Writes to the file: a full disk ends the file with what reached it, kept
        (:meth:`McapPart.out_of_space`), and raises :class:`~redrive.errors.DiskFullError`."""
        try:
            yield
        except OSError as err:
            if is_no_space(err) and self._part.is_open:
                raise self._part.out_of_space(err) from err
            raise

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A named metadata record of string pairs (MCAP ``Metadata``): facts about the whole log
        that are no message stream, e.g. the road map of a synthetic scenario."""
        self._check_open()
        with self._space():
            self._writer.add_metadata(name=name, data=dict(data))

    def write_raw(
        self,
        topic: str,
        msgtype: str,
        log_time_ns: int,
        cdr_bytes: bytes | memoryview,
        *,
        publish_time_ns: int | None = None,
    ) -> None:
        """Write one already-serialised ROS 2 CDR message of type ``msgtype`` (``pkg/msg/Type``).

        ``cdr_bytes`` may be a view into a buffer that is reused afterwards (a shared-memory slot):
        it is copied into the chunk before this returns, once."""
        self._check_open()
        channel_id = self._channel_id(topic, msgtype)
        sequence = self._sequences[channel_id]
        self._sequences[channel_id] = sequence + 1
        try:
            self._writer.add_message(  # written or copied before it returns
                channel_id,
                log_time=int(log_time_ns),
                publish_time=int(log_time_ns if publish_time_ns is None else publish_time_ns),
                sequence=sequence,
                data=cdr_bytes,
            )
            self.message_count += 1
            self._keep_chunks_on_disk(int(log_time_ns))
        except OSError as err:  # not `with self._space()`: this is the per-message path
            if is_no_space(err) and self._part.is_open:
                raise self._part.out_of_space(err) from err
            raise

    def _keep_chunks_on_disk(self, log_time_ns: int) -> None:
        """Close a chunk that spans ``chunk_span_s`` (each finished chunk goes to the file at
        once: :class:`~redrive.io.mcap.stream.McapStream` keeps no file buffer)."""
        if self._writer.finished_chunks != self._finished:  # this message ended a chunk (size)
            self._finished = self._writer.finished_chunks
            self._chunk_first_ns = None
        elif self._chunk_first_ns is None:
            self._chunk_first_ns = log_time_ns
        elif abs(log_time_ns - self._chunk_first_ns) > self._chunk_span_ns:
            self._writer.end_chunk()
            self._finished = self._writer.finished_chunks
            self._chunk_first_ns = None

    def write(
        self,
        topic: str,
        log_time_ns: int,
        value: object,
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> None:
        """Serialise a data-model value as its standard ROS 2 message and write it.

        Args:
            value: PointCloud, Image, CameraInfo, Imu, GnssFix, VehicleState, TrafficData (its
                lights), tuple[Transform], tuple[DetectedObject] (see :mod:`redrive.io.ros.encode`), or a
                :class:`~redrive.io.ros.decoders.base.Decoded` holding one (its frame and stamp are
                then the defaults).
            frame_id: header frame; default the Decoded's / VehicleState's frame, else "".
            stamp_ns: header stamp; default the Decoded's / VehicleState's stamp, else
                ``log_time_ns``.

        Raises:
            UnsupportedMessageError: the value has no standard message.
        """
        if isinstance(value, Decoded):
            frame_id = value.frame_id if frame_id is None else frame_id
            stamp_ns = value.stamp_ns if stamp_ns is None else stamp_ns
            value = value.value
        if isinstance(value, VehicleState):
            frame_id = value.frame_id if frame_id is None else frame_id
            stamp_ns = value.stamp_ns if stamp_ns is None else stamp_ns
        msgtype, message = encode_value(
            value,
            self.typestore,
            frame_id="" if frame_id is None else frame_id,
            stamp_ns=log_time_ns if stamp_ns is None else stamp_ns,
        )
        self.write_raw(topic, msgtype, log_time_ns, self.typestore.serialize_cdr(message, msgtype))

    def write_frame(
        self,
        frame: Frame,
        *,
        topics: Mapping[str, str] | None = None,
        ground_truth_frame: str = "base_link",
    ) -> None:
        """Write the samples of a :class:`~redrive.types.Frame`.

        Every sensor goes to ``topics[sensor_id]`` (default ``/<sensor_id>``) at its own stamp
        (log time = header stamp) in its ``frame_id``; the vehicle state to
        ``topics["vehicle_state"]`` (default ``/odom``); ground truth to
        ``topics["ground_truth"]`` (default ``/ground_truth``) at the frame stamp, in
        ``ground_truth_frame``; the traffic lights' states, when the frame has any, to
        ``topics["traffic_lights"]`` (default ``/traffic_lights``) at the frame stamp.
        """
        names = topics or {}
        for sensor_id, sample in sorted(frame.sensors.items()):
            self.write(
                names.get(sensor_id, f"/{sensor_id}"),
                sample.stamp_ns,
                sample.data,
                frame_id=sample.frame_id,
                stamp_ns=sample.stamp_ns,
            )
        if frame.vehicle_state is not None:
            state = frame.vehicle_state
            self.write(names.get("vehicle_state", "/odom"), state.stamp_ns, state)
        if frame.ground_truth is not None:
            self.write(
                names.get("ground_truth", "/ground_truth"),
                frame.stamp_ns,
                frame.ground_truth,
                frame_id=ground_truth_frame,
                stamp_ns=frame.stamp_ns,
            )
        if frame.traffic.traffic_lights:
            lights = TrafficData(traffic_lights=frame.traffic.traffic_lights)
            self.write(
                names.get("traffic_lights", "/traffic_lights"),
                frame.stamp_ns,
                lights,
                stamp_ns=frame.stamp_ns,
            )

    # -- finishing -----------------------------------------------------------------------------

    def close(self) -> None:
        """Finish the file (summary, indexes) and move it into place.  Idempotent.

        Raises:
            DiskFullError: the disk filled (what was written is kept; the error says where).
        """
        if not self._part.is_open:
            return
        self._part.close()
        logger.debug("%s: %d messages written", self.path, self.message_count)

    def abort(self) -> None:
        """Drop the file being written (nothing appears at ``path``).  Idempotent."""
        self._part.abort()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    def __del__(self) -> None:
        # A writer dropped without close() leaves no temporary file behind.
        part = getattr(self, "_part", None)
        if part is not None:
            part.abort()
