"""What a log holds, read once: per topic its type, message count, bytes, rate from the real
stamps, the decoder redrive uses and the sensor (or role) it maps to — ``redrive info`` prints it.

>>> from redrive.io import open_log
>>> from redrive.assembly.summary import summarize_log
>>> with open_log("drive.bag", strict=False) as log:              # doctest: +SKIP
...     summary = summarize_log(log)
>>> summary.duration_s, [t.topic for t in summary.topics]        # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from redrive.assembly.calibration import camera_info_topics
from redrive.assembly.sensor_map import SensorSpec, infer_sensor_map, load_sensor_map_overrides
from redrive.errors import ConfigError, LogTruncatedError
from redrive.io.base import LogReader, ReaderCapabilities
from redrive.io.content import log_contents
from redrive.io.damage import LogDamage, damage_report
from redrive.io.ros.decoders import decoder_for
from redrive.io.ros.decoders.ouster_log import PacketCloudsReader

__all__ = ["LogSummary", "TopicSummary", "summarize_log"]


@dataclass(frozen=True, slots=True, kw_only=True)
class TopicSummary:
    """One topic of a log, as read."""

    topic: str
    msgtype: str
    count: int
    #: messages per second from the first and last log time; None with fewer than two messages
    rate_hz: float | None
    #: serialized bytes; None for topics without a wire encoding (KITTI's native files)
    size_bytes: int | None
    #: the name of the decoder redrive uses; None when the messages stay raw
    decoder: str | None
    has_definition: bool
    #: ``"<sensor id> (<sensor type>[, driver])"`` or a role (vehicle state, ground truth, tf,
    #: camera info of …); None when the topic maps to nothing
    maps_to: str | None

    def to_json(self) -> dict[str, Any]:
        return {
            "topic": self.topic,
            "type": self.msgtype,
            "count": self.count,
            "rate_hz": self.rate_hz,
            "bytes": self.size_bytes,
            "decoder": self.decoder,
            "has_definition": self.has_definition,
            "maps_to": self.maps_to,
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class LogSummary:
    """A whole log: its time range, its topics (in the log's order) and the damage, if any (the
    log was read up to it)."""

    path: Path
    format: str
    start_ns: int
    end_ns: int
    topics: tuple[TopicSummary, ...]
    damage: str | None
    capabilities: ReaderCapabilities
    damage_report: tuple[LogDamage, ...] = ()
    #: what the log holds beside its topics, counted (its reader's ``contents()``)
    contents: tuple[tuple[str, int | str], ...] = ()

    @property
    def provides(self) -> list[str]:
        """What the log can provide, in words (``tf``, ``ground truth``, ``ego pose``)."""
        caps = self.capabilities
        out = [
            name
            for name, has in (
                ("tf", caps.has_tf),
                ("ground truth", caps.has_ground_truth),
                ("ego pose", caps.has_ego_pose),
                ("road map", caps.road_map),
                ("traffic lights", caps.traffic_lights),
            )
            if has
        ]
        out.append("ROS messages" if caps.message_typed else "native values")
        if caps.calibration_per_frame:
            out.append("a calibration per frame")
        return out

    @property
    def messages_lost(self) -> tuple[int, bool]:
        """Messages the damage lost as far as the log says, and whether some part lost an
        unknown number more."""
        known = sum(d.messages_lost or 0 for d in self.damage_report)
        return known, any(d.messages_lost is None for d in self.damage_report)

    @property
    def duration_s(self) -> float:
        return round((self.end_ns - self.start_ns) / 1e9, 6)

    @property
    def messages(self) -> int:
        return sum(t.count for t in self.topics)

    @property
    def size_bytes(self) -> int:
        return sum(t.size_bytes or 0 for t in self.topics)

    @property
    def start_utc(self) -> str:
        """The start as ISO 8601 in UTC, to the millisecond."""
        return _iso_utc(self.start_ns)

    @property
    def end_utc(self) -> str:
        return _iso_utc(self.end_ns)

    def to_json(self) -> dict[str, Any]:
        """The summary as ``redrive info --json`` prints it."""
        return {
            "path": str(self.path),
            "format": self.format,
            "start_ns": self.start_ns,
            "end_ns": self.end_ns,
            "start": self.start_utc,
            "end": self.end_utc,
            "duration_s": self.duration_s,
            "messages": self.messages,
            "bytes": self.size_bytes,
            "topics": [t.to_json() for t in self.topics],
            "damage": self.damage,
            "damage_report": [d.to_json() for d in self.damage_report],
            "contents": dict(self.contents),
            "capabilities": {
                "message_typed": self.capabilities.message_typed,
                "has_tf": self.capabilities.has_tf,
                "has_ground_truth": self.capabilities.has_ground_truth,
                "has_ego_pose": self.capabilities.has_ego_pose,
                "calibration_per_frame": self.capabilities.calibration_per_frame,
                "road_map": self.capabilities.road_map,
                "traffic_lights": self.capabilities.traffic_lights,
            },
        }


@dataclass(slots=True)
class _TopicStats:
    count: int = 0
    size_bytes: int = 0
    first_ns: int | None = None
    last_ns: int = 0


def _iso_utc(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, tz=UTC).isoformat(timespec="milliseconds")


def _camera_info_roles(log: LogReader, sensors: dict[str, SensorSpec]) -> dict[str, str]:
    """camera info topic → ``camera info of <sensor ids>`` (the cameras of its namespace)."""
    served: dict[str, list[str]] = {}
    for image_topic, info_topic in camera_info_topics(log.topics).items():
        spec = sensors.get(image_topic)
        served.setdefault(info_topic, []).append(spec.sensor_id if spec else image_topic)
    return {topic: f"camera info of {', '.join(names)}" for topic, names in served.items()}


def _read_stats(log: LogReader) -> tuple[dict[str, _TopicStats], str | None]:
    """Counts, bytes and first/last log time per topic; the damage that ended the read, if any."""
    stats: dict[str, _TopicStats] = {t: _TopicStats() for t in log.topics}
    damage: str | None = None
    try:
        for message in log.messages():
            st = stats.setdefault(message.topic, _TopicStats())
            st.count += 1
            st.size_bytes += message.size_bytes
            if st.first_ns is None:
                st.first_ns = message.log_time_ns
            st.last_ns = message.log_time_ns
    except LogTruncatedError as err:
        damage = str(err)
    return stats, damage or getattr(log, "damage", None)


def summarize_log(log: LogReader, *, sensor_map_path: Path | None = None) -> LogSummary:
    """Read the whole log once and summarise it (counts, bytes, rates from the real stamps).

    A damaged log (opened with ``strict=False``) is read up to the damage, which the summary
    names.  The topic → sensor mapping is inferred (``sensor_map_path``: a TOML file of
    overrides); when it cannot be inferred the topics map to nothing, unless overrides were given
    (then the ConfigError is raised).
    """
    stats, damage = _read_stats(log)
    overrides = load_sensor_map_overrides(sensor_map_path) if sensor_map_path else None
    try:
        smap = infer_sensor_map(
            log.topics, duration_ns=log.end_ns - log.start_ns, overrides=overrides
        )
        sensors = {s.topic: s for s in smap.sensors}
        driver = smap.driver
        roles = {smap.vehicle_state_topic: "vehicle state", smap.ground_truth_topic: "ground truth"}
        roles.update(dict.fromkeys(smap.tf_topics, "tf"))
        roles.update(_camera_info_roles(log, sensors))
        if driver is None and smap.ground_truth_topic is not None:
            roles[smap.ground_truth_topic] = "ground truth (drives frames)"
        if smap.traffic_lights_topic is not None:
            roles[smap.traffic_lights_topic] = "traffic lights"
        roles.update(
            {packets: f"packets of {cloud}" for cloud, packets in _cloud_topics(log).items()}
        )
    except ConfigError:
        if sensor_map_path:
            raise
        sensors, driver, roles = {}, None, {}
    topics = []
    for topic, info in log.topics.items():
        st = stats[topic]
        decoder = decoder_for(info.msgtype) if info.encoding != "native" else None
        span_s = (st.last_ns - (st.first_ns or 0)) / 1e9
        spec = sensors.get(topic)
        maps_to = (
            f"{spec.sensor_id} ({spec.sensor_type.value}{', driver' if spec.sensor_id == driver else ''})"
            if spec
            else roles.get(topic, "")
        )
        topics.append(
            TopicSummary(
                topic=topic,
                msgtype=info.msgtype,
                count=st.count,
                rate_hz=round((st.count - 1) / span_s, 3) if st.count > 1 and span_s > 0 else None,
                size_bytes=st.size_bytes if info.encoding != "native" else None,
                # a native topic holds data-model values already: its reader decodes it
                decoder=decoder.name
                if decoder
                else _native_decoder(log, topic)
                if info.kind is not None
                else None,
                has_definition=info.has_definition,
                maps_to=maps_to or None,
            )
        )
    return LogSummary(
        path=log.path,
        format=log.format,
        start_ns=log.start_ns,
        end_ns=log.end_ns,
        topics=tuple(topics),
        damage=damage,
        capabilities=log.capabilities,
        damage_report=damage_report(log),
        contents=tuple(log_contents(log).items()),
    )


def _native_decoder(log: LogReader, topic: str) -> str:
    """What a native topic's decoder column says: ``ouster-packets`` for the clouds made of
    Ouster packets (:mod:`redrive.io.ros.decoders.ouster_log`), else ``native``."""
    return "ouster-packets" if topic in _cloud_topics(log) else "native"


def _cloud_topics(log: LogReader) -> dict[str, str]:
    """Cloud topic → the packet topic it is made of (empty for a log without)."""
    return dict(log.cloud_topics) if isinstance(log, PacketCloudsReader) else {}
