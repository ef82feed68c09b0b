"""``redrive live … --foxglove``: a live session on Foxglove's WebSocket protocol.

:class:`LiveView` starts foxglove-sdk's WebSocket server (loopback unless told otherwise) and
publishes what it is handed:

* :meth:`LiveView.feed` — a session's messages as they arrive, each on the channels ``redrive
  serve`` and the MCAP export advertise for its type (:func:`~redrive.interop.stream.route_topic`):
  its own ROS channel (ROS 1 bytes with a ``ros1msg`` schema, ROS 2 CDR with ``ros2msg``; a
  replay or synthetic source's typed samples encoded as their standard ROS 2 message, as the
  recording stores them), plus ``/foxglove<topic>`` as ``foxglove.PointCloud`` of a LiDAR,
  ``foxglove.CompressedImage`` of a camera and ``foxglove.SceneUpdate`` of an object topic;
* :meth:`LiveView.on_frame` — each finished frame's results: the SceneUpdate and MarkerArray
  topics of :func:`~redrive.interop.run_scene.record_scene` (ground truth, detections and
  tracks, paths, ego) and the ego on ``/redrive/transforms`` (unless the source has a ``/tf``
  of its own, which then places ``base_link``).

Nothing here makes a session wait: the engine's thread only hands a frame's record over (the
view's own thread converts it, and when it is behind only the newest frame waits — the others
are counted in :attr:`LiveView.frames_skipped`); a message is converted only while a client
subscribes to its channel; the server keeps a bounded backlog per client and drops a slow
client's oldest messages.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import foxglove

from redrive.errors import ConfigError, RedriveError
from redrive.interop.run_scene import live_topics, record_scene
from redrive.interop.serve_defaults import DEFAULT_HOST, DEFAULT_PORT
from redrive.interop.stream import (
    TRANSFORMS_TOPIC,
    ChannelSpec,
    OutMessage,
    foxglove_message,
    route_topic,
    scene_channels,
    scene_messages,
    transforms_channel,
)
from redrive.io.base import LogMessage, TopicInfo
from redrive.io.mcap.qos import offered_qos_profiles
from redrive.io.ros.decoders import decode
from redrive.io.ros.decoders.base import Decoded
from redrive.io.ros.encode import encode_value
from redrive.io.ros.typestore import typestore_for
from redrive.results.records import FrameRecord

__all__ = ["LiveView"]

logger = logging.getLogger(__name__)

Deserialize = Callable[[LogMessage], object]


@dataclass(frozen=True, slots=True)
class _Route:
    raw: foxglove.Channel | None  # the topic's own channel
    converted: foxglove.Channel | None  # /foxglove<topic>
    store: Any  # native samples: the ROS 2 typestore they are encoded with


class LiveView:
    """A WebSocket server that shows a live session in Foxglove (see the module text).

    Args:
        host, port: where to listen (port 0 picks a free one: :attr:`port` says which).
        name: the server's name, shown by the app.

    Raises:
        ConfigError: the port cannot be bound (the message says what to do).
    """

    def __init__(
        self, *, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, name: str = "redrive live"
    ) -> None:
        self.host = host
        self.context = foxglove.Context()
        try:
            self.server = foxglove.start_server(
                name=name, host=host, port=port, context=self.context
            )
        except RuntimeError as err:
            msg = (
                f"cannot serve the live view on {host}:{port} ({err}); another program may use "
                "the port: choose another with --foxglove-port (0 picks a free one)"
            )
            raise ConfigError(msg) from err
        self._lock = threading.Lock()
        self._channels: dict[str, foxglove.Channel] = {}
        self._routes: dict[str, _Route] = {}
        self._ego_transform = True
        self._scene_specs: dict[str, dict[str, ChannelSpec]] = {}
        #: messages sent per channel (each to every client subscribed to it)
        self.sent: dict[str, int] = {}
        #: messages that could not be converted (logged at DEBUG)
        self.unconvertible = 0
        #: results of frames converted and of frames passed over while the view was behind
        self.frames_shown = 0
        self.frames_skipped = 0
        self._cond = threading.Condition()
        self._pending: FrameRecord | None = None
        self._closed = False
        self._results = threading.Thread(
            target=self._show_results, name="redrive-foxglove-results", daemon=True
        )
        self._results.start()

    @property
    def port(self) -> int:
        return int(self.server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    @property
    def channel_count(self) -> int:
        with self._lock:
            return len(self._channels)

    def _channel(self, spec: ChannelSpec) -> foxglove.Channel:
        with self._lock:
            channel = self._channels.get(spec.topic)
            if channel is None:
                channel = foxglove.Channel(
                    spec.topic,
                    schema=foxglove.Schema(
                        name=spec.schema_name,
                        encoding=spec.schema_encoding,
                        data=spec.schema_data,
                    ),
                    message_encoding=spec.message_encoding,
                    context=self.context,
                    metadata=dict(spec.metadata),
                )
                self._channels[spec.topic] = channel
                self.sent[spec.topic] = 0
            return channel

    def _log(self, channel: foxglove.Channel, topic: str, data: bytes, log_time_ns: int) -> None:
        channel.log(data, log_time=log_time_ns)
        with self._lock:
            self.sent[topic] += 1

    # -- sensor messages -------------------------------------------------------------------------

    def add_topics(self, topics: Iterable[TopicInfo], stores: Mapping[str, Any]) -> None:
        """Advertise the channels of ``topics`` (a live log's; ``stores``: its typestores by
        encoding, which the ROS schemas are written from).  Topics already added are kept."""
        topics = [t for t in topics if t.topic not in self._routes]
        natives = sorted({t.msgtype for t in topics if t.encoding == "native"})
        native_store = typestore_for(2, needed=natives)[0] if natives else None
        for info in topics:
            if info.topic.rstrip("/").endswith("/tf"):
                self._ego_transform = False  # the source places base_link
            route = route_topic(info, stores, objects=True)
            by_topic = {c.topic: c for c in route.channels}
            raw = self._channel(by_topic[info.topic]) if route.raw else None
            store = None
            if (
                info.encoding == "native"
                and native_store is not None
                and info.msgtype in native_store.fielddefs
            ):
                definition, _ = native_store.generate_msgdef(info.msgtype, ros_version=2)
                store = native_store
                raw = self._channel(
                    ChannelSpec(
                        topic=info.topic,
                        message_encoding="cdr",
                        schema_name=info.msgtype,
                        schema_encoding="ros2msg",
                        schema_data=definition.encode("utf-8"),
                        metadata={"offered_qos_profiles": offered_qos_profiles(info.topic)},
                    )
                )
            converted_topic = f"/foxglove{info.topic}"
            converted = (
                self._channel(by_topic[converted_topic]) if converted_topic in by_topic else None
            )
            self._routes[info.topic] = _Route(raw=raw, converted=converted, store=store)

    def publish(self, message: LogMessage, deserialize: Deserialize) -> None:
        """Send one message on its channels that a client subscribes to; never raises for a
        message that does not convert (it is counted in :attr:`unconvertible`)."""
        route = self._routes.get(message.topic)
        if route is None:
            return
        try:
            raw, converted = route.raw, route.converted
            if raw is not None and raw.has_sinks():
                if message.encoding == "native":
                    data = self._encode_native(message, route.store)
                else:
                    data = bytes(message.raw)
                self._log(raw, message.topic, data, message.log_time_ns)
            if converted is not None and converted.has_sinks():
                out = foxglove_message(
                    message.topic, message.log_time_ns, decode(message, deserialize)
                )
                if out is not None:
                    self._log(converted, out.topic, out.data, out.log_time_ns)
        except (RedriveError, ValueError, TypeError, KeyError) as err:
            with self._lock:
                self.unconvertible += 1
            logger.debug(
                "foxglove live view: %s at %d: %s", message.topic, message.log_time_ns, err
            )

    @staticmethod
    def _encode_native(message: LogMessage, store: Any) -> bytes:
        payload = message.payload
        assert isinstance(payload, Decoded)
        msgtype, ros = encode_value(
            payload.value, store, frame_id=payload.frame_id, stamp_ns=payload.stamp_ns
        )
        return bytes(store.serialize_cdr(ros, msgtype))

    def feed(self, messages: Iterable[LogMessage], deserialize: Deserialize) -> None:
        """:meth:`publish` every message of ``messages`` (a live log's; blocks until it ends)."""
        for message in messages:
            self.publish(message, deserialize)

    # -- results ---------------------------------------------------------------------------------

    def add_results(self, algorithms: Iterable[tuple[str, str]]) -> None:
        """Advertise the results channels of a run of ``algorithms`` ((name, role) pairs) before
        its first frame, so a client finds them when it connects (channels of algorithms not
        named here appear with their first frame)."""
        for topic in live_topics(algorithms):
            self._scene_specs.setdefault(topic, scene_channels(topic))
            for spec in self._scene_specs[topic].values():
                self._channel(spec)
        if self._ego_transform:
            self._channel(transforms_channel())

    def on_frame(self, record: FrameRecord) -> None:
        """Hand over a finished frame (the engine's ``on_frame``); returns at once."""
        with self._cond:
            if self._pending is not None:
                self.frames_skipped += 1
            self._pending = record
            self._cond.notify_all()

    def _show_results(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                record, self._pending = self._pending, None
            if record is None:
                return
            try:
                self._show(record)
            except (RedriveError, ValueError, TypeError, KeyError) as err:
                logger.warning("foxglove live view: frame %d: %s", record.frame_index, err)

    def _show(self, record: FrameRecord) -> None:
        scene = record_scene(record, ego_transform=self._ego_transform)
        channels: dict[str, foxglove.Channel] = {}
        for topic in scene.shapes:
            specs = self._scene_specs.get(topic)
            if specs is None:
                specs = self._scene_specs[topic] = scene_channels(topic)
            for spec in specs.values():
                channels[spec.topic] = self._channel(spec)
        if scene.transforms:
            channels[TRANSFORMS_TOPIC] = self._channel(transforms_channel())
        if not any(c.has_sinks() for c in channels.values()):
            return
        out: OutMessage
        for out in scene_messages(scene):
            channel = channels[out.topic]
            if channel.has_sinks():
                self._log(channel, out.topic, out.data, out.log_time_ns)
        with self._lock:
            self.frames_shown += 1

    # -- stopping --------------------------------------------------------------------------------

    def close(self) -> None:
        """Show the frame still waiting, then stop the server."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._results.join(10.0)
        self.server.stop()
