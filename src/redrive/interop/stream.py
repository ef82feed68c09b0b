"""One time-ordered stream of a log and a run's results, as the channels Foxglove reads.

:func:`open_scene_stream` opens a run directory or a log and gives a :class:`SceneStream`: its
channels (known before the first message, so a server can advertise them) and
``messages(start_ns=…)``, every message in log-time order.  The MCAP export
(:mod:`.mcap_export`) writes it to a file, ``redrive serve`` (:mod:`.serve`) to a WebSocket.

What a stream holds:

* the log's own messages, as they are, on their own topics (ROS 2 ``cdr`` with ``ros2msg``
  schemas; a ROS 1 log's ``ros1`` with ``ros1msg``) — except, for a run, the log's ``/tf``:
  the run's ego places ``base_link`` (``/redrive/transforms``), and a frame has one parent (in
  a closed loop the log's ``/tf`` moves the logged ego, not the driven one).  With
  ``log_tf=True`` (the MCAP export) an open-loop run, whose ego is the logged ego, keeps the
  log's ``/tf`` when it places ``base_link`` under the ego's frame, and ``/redrive/transforms``
  then holds the static transforms only (:attr:`SceneStream.log_tf`);
* with ``sensor_copies`` (``redrive serve``; ``export --sensor-copies``) every LiDAR cloud
  again as ``foxglove.PointCloud`` and every camera image as ``foxglove.CompressedImage`` on
  ``/foxglove/<topic>``;
* for a run: ``/redrive/transforms`` (``foxglove.FrameTransforms``) and the SceneUpdate topics
  of :mod:`.run_scene` at each frame's log time (the log time of the sample that drove it,
  :mod:`.log_time`; the messages keep the frame's stamp), each also as a MarkerArray on
  ``/redrive/markers/<topic without /redrive/>``; each sensor frame the log does not connect to
  ``base_link`` gets the mount the run used (:mod:`.sensor_frames`);
* for a log without a run: its ground-truth and object topics as SceneUpdates on
  ``/foxglove/<topic>`` and its static transforms on ``/redrive/transforms``.
"""

from __future__ import annotations

import functools
import heapq
import logging
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any, Self

from foxglove import messages as fm

from redrive.assembly.sensor_map import SensorMapOverrides
from redrive.errors import LogError, UnsupportedMessageError
from redrive.interop import foxglove_msgs as fx
from redrive.interop.log_time import LogTimeAxis, frame_log_times
from redrive.interop.markers import MARKER_ARRAY, marker_array_cdr
from redrive.interop.run_scene import (
    BODY_FRAME,
    FrameScene,
    log_object_shapes,
    run_scenes,
    scene_topics,
)
from redrive.interop.sensor_frames import sensor_mount_transforms
from redrive.io import open_log
from redrive.io.base import LogMessage, LogReader, TopicInfo
from redrive.io.mcap.qos import offered_qos_profiles
from redrive.io.ros.decoders import DecodedKind, decode, topic_kind
from redrive.io.ros.decoders.base import Decoded
from redrive.io.ros.typestore import typestore_for
from redrive.results import Run, open_run
from redrive.types import DetectedObject, Image, PointCloud, SensorType, Transform

__all__ = [
    "TRANSFORMS_TOPIC",
    "ChannelSpec",
    "OutMessage",
    "SceneStream",
    "TopicRoute",
    "foxglove_message",
    "open_scene_stream",
    "route_topic",
    "scene_channels",
    "scene_messages",
    "transforms_channel",
    "transforms_message",
]

logger = logging.getLogger(__name__)

TRANSFORMS_TOPIC = "/redrive/transforms"
_LATCHED = "transient_local"


@dataclass(frozen=True, slots=True, kw_only=True)
class ChannelSpec:
    """A channel: its topic, message encoding and schema (name, encoding, definition)."""

    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    metadata: Mapping[str, str] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class OutMessage:
    """One message: its topic, log time (int ns) and encoded bytes."""

    topic: str
    log_time_ns: int
    data: bytes


def _foxglove_spec(topic: str, message_type: Any) -> ChannelSpec:
    schema = message_type.get_schema()
    return ChannelSpec(
        topic=topic,
        message_encoding=schema.encoding,
        schema_name=schema.name,
        schema_encoding=schema.encoding,
        schema_data=bytes(schema.data),
    )


def _marker_topic(topic: str) -> str:
    return "/redrive/markers/" + topic.removeprefix("/redrive/").removeprefix("/")


@dataclass(frozen=True, slots=True, kw_only=True)
class TopicRoute:
    """How one log topic reaches Foxglove (:func:`route_topic`).

    Attributes:
        raw: passed on as it is, on its own topic (its ROS bytes and schema).
        decoded: (kind, sensor type) when it is also converted to a Foxglove message on
            ``/foxglove<topic>`` (:func:`foxglove_message`); None otherwise.
        static: static transforms (``/tf_static``): gathered onto ``/redrive/transforms``.
        channels: the channels the topic fills.
    """

    raw: bool
    decoded: tuple[DecodedKind, SensorType | None] | None
    static: bool
    channels: tuple[ChannelSpec, ...]


def route_topic(
    info: TopicInfo, stores: Mapping[str, Any], *, objects: bool, sensor_copies: bool = True
) -> TopicRoute:
    """The channels of a log topic: its own (ROS 1 ``ros1msg`` / ROS 2 ``ros2msg`` schema, when
    its type is known to the log's typestore in ``stores``), when ``sensor_copies`` a
    ``foxglove.PointCloud`` of a LiDAR and a ``foxglove.CompressedImage`` of a camera, and —
    when ``objects`` — a ``foxglove.SceneUpdate`` of an object topic (ground truth or
    detections)."""
    topic = info.topic
    channels: list[ChannelSpec] = []
    store = stores.get(info.encoding) if info.encoding != "native" else None
    raw = False
    if store is not None and info.has_definition and info.msgtype in store.fielddefs:
        version = 1 if info.encoding == "ros1" else 2
        name = info.msgtype
        if version == 1:
            pkg, _, typ = info.msgtype.split("/")
            name = f"{pkg}/{typ}"
        text, _ = store.generate_msgdef(info.msgtype, ros_version=version)
        metadata = {}
        if version == 2:
            metadata["offered_qos_profiles"] = offered_qos_profiles(topic)
        channels.append(
            ChannelSpec(
                topic=topic,
                message_encoding=info.encoding,
                schema_name=name,
                schema_encoding="ros1msg" if version == 1 else "ros2msg",
                schema_data=text.encode("utf-8"),
                metadata=metadata,
            )
        )
        raw = True
    kind = topic_kind(info)
    decoded: tuple[DecodedKind, SensorType | None] | None = None
    static = False
    if kind is not None:
        message_type: Any = None
        if kind[0] == DecodedKind.SENSOR and kind[1] == SensorType.LIDAR:
            message_type = fm.PointCloud if sensor_copies else None
        elif kind[0] == DecodedKind.SENSOR and kind[1] == SensorType.CAMERA:
            message_type = fm.CompressedImage if sensor_copies else None
        elif kind[0] == DecodedKind.OBJECTS and objects:
            message_type = fm.SceneUpdate
        elif kind[0] == DecodedKind.TRANSFORMS and topic.endswith("tf_static"):
            static = True
        if message_type is not None:
            channels.append(_foxglove_spec(f"/foxglove{topic}", message_type))
            decoded = kind
    return TopicRoute(raw=raw, decoded=decoded, static=static, channels=tuple(channels))


def foxglove_message(topic: str, log_time_ns: int, decoded: Decoded) -> OutMessage | None:
    """A decoded LiDAR cloud, camera image or object list of ``topic`` as its Foxglove message
    on ``/foxglove<topic>``; None for other values (and float images, which neither JPEG nor
    PNG holds)."""
    value = decoded.value
    encoded: Any = None
    if isinstance(value, PointCloud):
        encoded = fx.point_cloud(value, frame_id=decoded.frame_id, stamp_ns=decoded.stamp_ns)
    elif isinstance(value, Image):
        encoded = fx.compressed_image(value, frame_id=decoded.frame_id, stamp_ns=decoded.stamp_ns)
    elif isinstance(value, tuple):
        found = [o for o in value if isinstance(o, DetectedObject)]
        encoded = fx.scene_update(
            log_object_shapes(
                found, frame_id=decoded.frame_id or BODY_FRAME, stamp_ns=decoded.stamp_ns
            )
        )
    if encoded is None:
        return None
    return OutMessage(f"/foxglove{topic}", log_time_ns, encoded.encode())


@functools.cache
def _marker_definition() -> str:
    store = typestore_for(2, needed=[MARKER_ARRAY])[0]
    text: str = store.generate_msgdef(MARKER_ARRAY, ros_version=2)[0]
    return text


def scene_channels(topic: str) -> dict[str, ChannelSpec]:
    """A results topic's channels: its ``foxglove.SceneUpdate`` and the same shapes as a
    ``visualization_msgs/msg/MarkerArray`` on ``/redrive/markers/…``."""
    marker_def = _marker_definition()
    return {
        topic: _foxglove_spec(topic, fm.SceneUpdate),
        _marker_topic(topic): ChannelSpec(
            topic=_marker_topic(topic),
            message_encoding="cdr",
            schema_name=MARKER_ARRAY,
            schema_encoding="ros2msg",
            schema_data=marker_def.encode("utf-8"),
            metadata={"offered_qos_profiles": offered_qos_profiles(topic)},
        ),
    }


def transforms_channel() -> ChannelSpec:
    """``/redrive/transforms``: ``foxglove.FrameTransforms``."""
    return _foxglove_spec(TRANSFORMS_TOPIC, fm.FrameTransforms)


def transforms_message(transforms: tuple[Transform, ...], stamp_ns: int) -> OutMessage:
    data = fx.frame_transforms(transforms, stamp_ns=stamp_ns).encode()
    return OutMessage(TRANSFORMS_TOPIC, stamp_ns, data)


def scene_messages(scene: FrameScene, *, log_time_ns: int | None = None) -> Iterator[OutMessage]:
    """One frame's results: its transforms, then each topic's SceneUpdate and MarkerArray, at
    ``log_time_ns`` (default: the frame's stamp; the messages hold the stamp either way)."""
    stamp = scene.stamp_ns
    at = stamp if log_time_ns is None else log_time_ns
    if scene.transforms:
        data = fx.frame_transforms(scene.transforms, stamp_ns=stamp).encode()
        yield OutMessage(TRANSFORMS_TOPIC, at, data)
    for topic, shapes in sorted(scene.shapes.items()):
        yield OutMessage(topic, at, fx.scene_update(shapes).encode())
        yield OutMessage(_marker_topic(topic), at, marker_array_cdr(shapes))


def find_run_log(run: Run) -> Path | None:
    """The log a run is shown over: a sensor-level closed loop's recording of its rendered
    sensors (in the run directory), else the log the manifest names; None when it is gone."""
    recorded = run.manifest.closed_loop.get("sensor_log")
    if isinstance(recorded, str) and recorded:
        path = run.path / recorded
        return path if path.is_file() else None
    named = run.manifest.log.path
    return Path(named) if named and Path(named).exists() else None


def _is_open_loop(run: Run) -> bool:
    return not run.manifest.closed_loop and "ego_logged" not in run.tables()


def _tf_topics(reader: LogReader) -> list[str]:
    return [t for t in reader.topics if t.rstrip("/").endswith("/tf") or t == "tf"]


def _first_message(reader: LogReader, topic: str) -> LogMessage | None:
    """The first message of ``topic``, looked for in the log's first 10 ms, then its first
    second, then all of it (a reader decompresses the chunks of the span asked for)."""
    start = reader.start_ns
    for stop in (start + 10_000_000, start + 1_000_000_000, None):
        for message in reader.messages(topics=[topic], stop_ns=stop):
            return message
    return None


def _log_places_ego(reader: LogReader, run: Run) -> bool:
    """Whether the first message of the log's ``/tf`` places ``base_link`` under the frame of
    the run's ego (so the log's ``/tf`` moves the run's ego, as in an open-loop run)."""
    ego = run.table("ego").slice(0, 1).to_pylist() if "ego" in run.tables() else []
    ego_frame = (str(ego[0]["frame_id"]) or "map") if ego else None
    parents: dict[str, str] = {}
    for topic in _tf_topics(reader):
        message = _first_message(reader, topic)
        if message is None:
            continue
        try:
            value = decode(message, reader.deserialize).value
        except UnsupportedMessageError:
            return False
        if isinstance(value, tuple):
            parents.update(
                (t.child_frame, t.parent_frame) for t in value if isinstance(t, Transform)
            )
    if BODY_FRAME not in parents:
        return False
    frame, seen = BODY_FRAME, set()
    while frame in parents and frame not in seen:
        seen.add(frame)
        frame = parents[frame]
        if frame == ego_frame:
            return True
    return ego_frame is None


class SceneStream:
    """A log and (optionally) a run as Foxglove channels; a context manager (closes the log).

    Args:
        reader: the log (None: the run's results only).
        run: the run (None: the log only).
        sensor_copies: also ``foxglove.PointCloud`` / ``foxglove.CompressedImage`` copies of
            the log's LiDAR clouds and camera images on ``/foxglove/<topic>``.
        log_tf: keep the log's ``/tf`` for an open-loop run when it places ``base_link`` under
            the ego's frame (:attr:`log_tf` says whether it was kept); the run's ego transform
            is then left out of ``/redrive/transforms``.
        sensor_map: what the run's ``--sensor-map`` file said (its driver and sensor
            locations), for the run's time axis and sensor mounts; None: inferred as the run
            inferred it.
    """

    def __init__(
        self,
        *,
        reader: LogReader | None,
        run: Run | None,
        sensor_copies: bool = True,
        log_tf: bool = False,
        sensor_map: SensorMapOverrides | None = None,
    ) -> None:
        self.reader = reader
        self.run = run
        self.sensor_copies = sensor_copies
        #: the log's ``/tf`` is passed on and places the run's ego (an open-loop run)
        self.log_tf = (
            log_tf
            and reader is not None
            and run is not None
            and _is_open_loop(run)
            and _log_places_ego(reader, run)
        )
        self.channels: dict[str, ChannelSpec] = {}
        #: log topics left out of the stream (a run's ``/tf`` unless :attr:`log_tf`)
        self.dropped_topics: frozenset[str] = frozenset()
        self._raw: dict[str, str] = {}  # log topic → how to pass it on
        self._decoded: dict[str, tuple[DecodedKind, SensorType | None]] = {}
        self._static: tuple[Transform, ...] = ()
        #: a run's frame stamp → log time (:mod:`.log_time`)
        self.axis = LogTimeAxis()
        if reader is not None:
            self._add_log_channels(reader)
        if run is not None and reader is not None:
            self._static += sensor_mount_transforms(
                reader, static=self._static, log_tf_kept=self.log_tf, overrides=sensor_map
            )
            stamps = run.table("frames").column("stamp_ns").to_pylist()
            self.axis = frame_log_times(reader, stamps, overrides=sensor_map)
        if run is not None:
            self._add_run_channels(run)
        elif self._static:
            self.channels[TRANSFORMS_TOPIC] = _foxglove_spec(TRANSFORMS_TOPIC, fm.FrameTransforms)

    # -- channels --------------------------------------------------------------------------------

    def _add_log_channels(self, reader: LogReader) -> None:
        stores: Mapping[str, Any] = getattr(reader, "typestores", {})
        if self.run is not None and not self.log_tf:
            # the run's ego places base_link (/redrive/transforms): one parent
            self.dropped_topics = frozenset(_tf_topics(reader))
        for topic, info in sorted(reader.topics.items()):
            if topic in self.dropped_topics:
                continue
            route = route_topic(
                info, stores, objects=self.run is None, sensor_copies=self.sensor_copies
            )
            self.channels.update((c.topic, c) for c in route.channels)
            if route.raw:
                self._raw[topic] = info.encoding
            if route.decoded is not None:
                self._decoded[topic] = route.decoded
            if route.static:
                self._static += self._read_static(reader, topic)

    @staticmethod
    def _read_static(reader: LogReader, topic: str) -> tuple[Transform, ...]:
        found: dict[tuple[str, str], Transform] = {}
        for message in reader.messages(topics=[topic]):
            try:
                value = decode(message, reader.deserialize).value
            except UnsupportedMessageError as err:
                logger.warning("%s: %s", reader.path, err)
                continue
            if isinstance(value, tuple):
                for t in value:
                    if isinstance(t, Transform):
                        found[(t.parent_frame, t.child_frame)] = t
        return tuple(found.values())

    def _add_run_channels(self, run: Run) -> None:
        self.channels[TRANSFORMS_TOPIC] = _foxglove_spec(TRANSFORMS_TOPIC, fm.FrameTransforms)
        for topic in scene_topics(run):
            self.channels.update(scene_channels(topic))

    # -- messages --------------------------------------------------------------------------------

    @property
    def start_ns(self) -> int:
        starts = []
        if self.reader is not None and self.reader.message_count:
            starts.append(self.reader.start_ns)
        if self.run is not None:
            frames = self.run.table("frames").column("stamp_ns")
            if len(frames):
                starts.append(self.axis.log_time_ns(int(frames[0].as_py())))
        return min(starts, default=0)

    @property
    def end_ns(self) -> int:
        ends = []
        if self.reader is not None and self.reader.message_count:
            ends.append(self.reader.end_ns)
        if self.run is not None:
            frames = self.run.table("frames").column("stamp_ns")
            if len(frames):
                ends.append(self.axis.log_time_ns(int(frames[-1].as_py())))
        return max(ends, default=0)

    @property
    def log_topics(self) -> frozenset[str]:
        """The log topics passed on as they are (their messages' own bytes)."""
        return frozenset(self._raw)

    def messages(self, *, start_ns: int | None = None, raw: bool = True) -> Iterator[OutMessage]:
        """Every message with log time ≥ ``start_ns`` (all when None), in log-time order;
        without the log's own messages (:attr:`log_topics`) when ``raw`` is False."""
        parts: list[Iterator[OutMessage]] = []
        if self.reader is not None and (raw or self._decoded):
            parts.append(self._log_messages(start_ns, raw=raw))
        if self.run is not None:
            parts.append(self._run_messages(start_ns))
        elif self._static:
            t0 = self.start_ns if start_ns is None else start_ns
            parts.append(iter([transforms_message(self._static, t0)]))
        return heapq.merge(*parts, key=lambda m: m.log_time_ns)

    def _log_messages(self, start_ns: int | None, *, raw: bool) -> Iterator[OutMessage]:
        assert self.reader is not None
        reader = self.reader
        passed = set(self._raw) if raw else set()
        wanted = passed | set(self._decoded)
        for message in reader.messages(topics=wanted, start_ns=start_ns):
            if message.topic in passed:
                yield OutMessage(message.topic, message.log_time_ns, bytes(message.raw))
            if message.topic in self._decoded:
                out = self._decoded_message(reader, message)
                if out is not None:
                    yield out

    def _decoded_message(self, reader: LogReader, message: LogMessage) -> OutMessage | None:
        try:
            decoded = decode(message, reader.deserialize)
        except UnsupportedMessageError as err:
            logger.debug("%s: %s", reader.path, err)
            return None
        return foxglove_message(message.topic, message.log_time_ns, decoded)

    def _run_messages(self, start_ns: int | None) -> Iterator[OutMessage]:
        assert self.run is not None
        scenes = run_scenes(self.run, static_transforms=self._static, ego_transform=not self.log_tf)
        for scene in scenes:
            at = self.axis.log_time_ns(scene.stamp_ns)
            if start_ns is not None and at < start_ns:
                continue
            yield from scene_messages(scene, log_time_ns=at)

    # -- closing ---------------------------------------------------------------------------------

    def close(self) -> None:
        if self.reader is not None:
            self.reader.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _is_run_dir(path: Path) -> bool:
    return path.is_dir() and (path / "manifest.json").is_file() and (path / "frames").is_dir()


def open_scene_stream(
    path: str | Path,
    *,
    sensor_copies: bool = True,
    log_tf: bool = False,
    sensor_map: SensorMapOverrides | None = None,
) -> SceneStream:
    """The stream of a run directory (its log, found as the GUI finds it, plus its results) or
    of a log alone; ``sensor_copies``, ``log_tf`` and ``sensor_map`` as :class:`SceneStream`
    takes them.

    Raises:
        LogError: the log cannot be opened (the message names the file and what to do).
        ConfigError: the run directory cannot be read.
    """
    path = Path(path)
    if _is_run_dir(path):
        run = open_run(path)
        log = find_run_log(run)
        if log is None:
            logger.warning(
                "%s: the run's log (%s) is not there; only the run's results are included",
                path,
                run.manifest.closed_loop.get("sensor_log") or run.manifest.log.path,
            )
            return SceneStream(reader=None, run=run, sensor_copies=sensor_copies)
        reader = open_log(log)
        try:
            return SceneStream(
                reader=reader,
                run=run,
                sensor_copies=sensor_copies,
                log_tf=log_tf,
                sensor_map=sensor_map,
            )
        except BaseException:
            reader.close()
            raise
    if not path.exists():
        msg = f"{path}: no such log or run directory; give a log file or the --out of a run"
        raise LogError(msg)
    return SceneStream(reader=open_log(path), run=None, sensor_copies=sensor_copies)
