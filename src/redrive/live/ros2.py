"""Live ROS 2: a session fed by the ROS 2 scraper, and results published back over DDS.

>>> with ros2_session(["/points", "/imu"], domain_id=0) as live:       # doctest: +SKIP
...     log = LiveLog(live.specs, live.name)

:func:`ros2_session` finds the topics' types and offered QoS on the DDS domain
(``DCPSPublication``, :func:`redrive.live.ros2_dds.discover`), starts one scraper process
(:mod:`redrive.live.ros2_scraper`) and returns a :class:`~redrive.live.session.LiveSession` whose
streams carry CDR bytes (``payload="cdr"``): the dispatcher decodes them, the Data Logger records
them as they came with their QoS.

:class:`ResultPublisher` publishes what a run produces, frame by frame, as ROS 2 messages any
ROS 2 node subscribes to: each perception algorithm's objects as ``vision_msgs/msg/Detection3DArray``
on ``/redrive/<algorithm>/detections``, each planner's path as ``nav_msgs/msg/Path`` on
``/redrive/<algorithm>/path`` (default QoS: reliable, volatile, keep last 10).
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from redrive.errors import ConfigError, TransportError, UnsupportedMessageError
from redrive.io.ros.encode import encode_value
from redrive.io.ros.typestore import typestore_for
from redrive.live.ros2_dds import (
    DEFAULT,
    Publication,
    QosProfile,
    RawWriter,
    discover,
    participant,
    require_cyclonedds,
)
from redrive.live.scraper_state import Offered, Ros2Reports
from redrive.live.session import (
    _OTHER_CAPACITY,
    DEFAULT_CAPACITY,
    LiveSession,
    _wait_ready,
    default_session_name,
)
from redrive.live.streams import StreamSpec, stream_name
from redrive.results.records import FrameRecord
from redrive.transport import remove_stale
from redrive.types import PlannedPath

__all__ = ["RESULT_PREFIX", "ResultPublisher", "Ros2Session", "find_publications", "ros2_session"]

logger = logging.getLogger(__name__)

#: results are published under ``/redrive/<algorithm>/…``.
RESULT_PREFIX = "/redrive"
_NAME = re.compile(r"[^A-Za-z0-9_]+")


def find_publications(
    topics: Sequence[str], *, domain_id: int, wait_for_topics_s: float = 2.0
) -> dict[str, Publication]:
    """Topic → its publication (type, offered QoS) of each of ``topics`` on DDS domain
    ``domain_id``, looked up for ``wait_for_topics_s`` (at least the ~1 s DDS discovery takes).

    Raises:
        ConfigError: a topic has no publisher on the domain.
        TransportError: cyclonedds is missing or the domain cannot be joined.
    """
    if not topics:
        return {}
    dp = participant(domain_id)
    try:
        found = discover(dp, topics, timeout_s=max(wait_for_topics_s, 1.0))
    finally:
        del dp  # leave the domain before the scraper joins it
    missing = [t for t in topics if t not in found]
    if missing:
        msg = (
            f"no publisher of {', '.join(missing)} on ROS 2 (DDS) domain {domain_id}; it has "
            f"{', '.join(sorted(found)) or 'no topics'}. Check ROS_DOMAIN_ID / --domain, "
            "CYCLONEDDS_URI, and raise --wait if the publishers start later"
        )
        raise ConfigError(msg)
    return {topic: found[topic] for topic in topics}


class Ros2Session(LiveSession):
    """A live session fed by the one ROS 2 scraper process (see :func:`ros2_session`).

    :attr:`scrapers` has a state per topic (its publishers are the DDS writers its reader is
    matched with); :attr:`offered` every ROS 2 topic published on the domain when the scraper
    was started with ``discover_new``; :meth:`add_ros2` records more topics while it runs.
    """

    def __init__(
        self,
        name: str,
        specs: Sequence[StreamSpec],
        proc: subprocess.Popen[str],
        *,
        capacity: Mapping[str, int] | None,
        ready_timeout_s: float,
    ) -> None:
        super().__init__(name, specs, [proc])
        self.reports = Ros2Reports(proc, self.scrapers)
        for spec in specs:
            self.reports.state(spec.topic)
        self._capacity = dict(capacity or {})
        self._ready_timeout_s = ready_timeout_s
        self._store: Any = None

    @property
    def offered(self) -> dict[str, Offered]:
        return self.reports.offered

    def known_type(self, msgtype: str) -> bool:
        """True when redrive has a definition of ``msgtype`` (a DDS reader needs one)."""
        if self._store is None:
            self._store = typestore_for(2)[0]
        return msgtype in self._store.fielddefs

    def spec(self, topic: str, msgtype: str, qos: QosProfile) -> StreamSpec:
        size = self._capacity.get(topic) or DEFAULT_CAPACITY.get(msgtype, _OTHER_CAPACITY)
        return StreamSpec(
            topic=topic, msgtype=msgtype, stream=stream_name(self.name, topic), payload="cdr",
            capacity_bytes=size, qos=qos.to_yaml(),
        )  # fmt: skip

    def add_ros2(
        self,
        publications: Mapping[str, Publication],
        *,
        on_stream: Callable[[StreamSpec], None] | None = None,
    ) -> list[StreamSpec]:
        """Have the scraper read ``publications`` too; returns their streams (also appended to
        :attr:`specs`). With ``on_stream`` (a recorder's ``add``), each topic's DDS reader is
        created only once ``on_stream`` was called with its stream and a lossless reader
        attached: no sample is forwarded before the recorder reads the stream.

        Raises:
            TransportError: the scraper could not add a topic (those before it stay added).
        """
        proc = self.processes[0]
        added = []
        for topic, pub in publications.items():
            spec = self.spec(topic, pub.msgtype, pub.qos)
            command = {
                **_spec_json(spec, pub.qos), "await": on_stream is not None,
            }  # fmt: skip
            self.reports.state(topic)
            try:
                assert proc.stdin is not None
                proc.stdin.write("ADD " + json.dumps(command) + "\n")
                proc.stdin.flush()
            except (OSError, ValueError) as err:
                msg = f"the ROS 2 scraper does not take {topic} ({err}): it has exited"
                raise TransportError(msg) from err
            try:
                error = None
                if on_stream is not None:
                    error = self.reports.wait_answer(topic, self._ready_timeout_s, stream=True)
                    if error is None:
                        on_stream(spec)
                if error is None:
                    error = self.reports.wait_answer(topic, self._ready_timeout_s)
            except BaseException:
                remove_stale(spec.stream)
                raise
            if error is not None:
                msg = f"the ROS 2 scraper cannot read {topic} ({pub.msgtype}): {error}"
                raise TransportError(msg)
            self.specs.append(spec)
            added.append(spec)
        return added

    def close(self, *, timeout_s: float = 5.0) -> None:
        proc = self.processes[0]
        if proc.stdin is not None:
            with contextlib.suppress(OSError, ValueError):
                proc.stdin.close()
        super().close(timeout_s=timeout_s)
        self.reports.ended.wait(1.0)


def _spec_json(spec: StreamSpec, qos: QosProfile) -> dict[str, Any]:
    return {
        "topic": spec.topic, "msgtype": spec.msgtype, "stream": spec.stream,
        "capacity": spec.capacity_bytes, "reliability": qos.reliability,
        "durability": qos.durability,
    }  # fmt: skip


def ros2_session(
    topics: Sequence[str],
    *,
    domain_id: int,
    name: str | None = None,
    capacity: Mapping[str, int] | None = None,
    slots: int = 8,
    ready_timeout_s: float = 30.0,
    wait_for_topics_s: float = 2.0,
    discover_new: bool = False,
) -> Ros2Session:
    """Start the ROS 2 scraper for ``topics`` on DDS domain ``domain_id`` and wait until it reads.

    Topics are looked up among the domain's publications for ``wait_for_topics_s`` (at least
    the time DDS discovery takes, ~1 s). With ``discover_new`` the scraper reports every topic
    published on the domain (:attr:`Ros2Session.offered`), those that appear later too.

    Raises:
        ConfigError: a topic has no publisher on the domain.
        TransportError: cyclonedds is missing, or the scraper failed to start.
    """
    require_cyclonedds()
    name = name or default_session_name()
    remove_stale()  # segments of killed earlier sessions
    found = find_publications(topics, domain_id=domain_id, wait_for_topics_s=wait_for_topics_s)
    size_of = dict(capacity or {})
    specs = []
    for topic, pub in found.items():
        size = size_of.get(topic) or DEFAULT_CAPACITY.get(pub.msgtype, _OTHER_CAPACITY)
        specs.append(
            StreamSpec(
                topic=topic,
                msgtype=pub.msgtype,
                stream=stream_name(name, topic),
                payload="cdr",
                capacity_bytes=size,
                qos=pub.qos.to_yaml(),
            )
        )
    spec_json = json.dumps([_spec_json(s, found[s.topic].qos) for s in specs])
    argv = [
        sys.executable, "-m", "redrive.live.ros2_scraper", "--domain", str(domain_id),
        "--spec", spec_json, "--slots", str(slots), *(["--discover"] if discover_new else []),
    ]  # fmt: skip
    proc = subprocess.Popen(
        argv,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    session = Ros2Session(name, specs, proc, capacity=capacity, ready_timeout_s=ready_timeout_s)
    try:
        _wait_ready(proc, "the ROS 2 scraper", time.monotonic() + ready_timeout_s)
    except BaseException:
        session.close()
        raise
    threading.Thread(target=session.reports.follow, name="ros2-scraper", daemon=True).start()
    return session


def result_topic(algorithm: str, what: str) -> str:
    """``/redrive/<algorithm>/<what>`` (the algorithm name made a valid ROS name)."""
    clean = _NAME.sub("_", algorithm).strip("_") or "algorithm"
    if clean[0].isdigit():
        clean = f"a_{clean}"
    return f"{RESULT_PREFIX}/{clean}/{what}"


class ResultPublisher:
    """Publishes each finished frame's results on DDS (see the module text); call it with every
    :class:`~redrive.results.FrameRecord` (``run_reader(..., on_frame=publisher)``).

    Args:
        domain_id: the DDS domain (ROS_DOMAIN_ID).
        frame_id: the frame the detections are in (the vehicle's, REP-105 ``base_link``);
            a path is in its own ``frame_id``, stamped when it was planned.

    Raises:
        TransportError: cyclonedds is missing or the domain cannot be joined.
    """

    def __init__(self, domain_id: int, *, frame_id: str = "base_link") -> None:
        self._dp = participant(domain_id)
        self._store = typestore_for(2)[0]
        self._writers: dict[str, RawWriter] = {}
        self.frame_id = frame_id
        self.published: dict[str, int] = {}

    def _writer(self, topic: str, msgtype: str) -> RawWriter:
        writer = self._writers.get(topic)
        if writer is None:
            writer = RawWriter(self._dp, topic, msgtype, store=self._store, qos=DEFAULT)
            self._writers[topic] = writer
            self.published[topic] = 0
        return writer

    def messages(self, record: FrameRecord) -> list[tuple[str, str, Any]]:
        """(topic, msgtype, rosbags message) of everything ``record`` has to publish."""
        out: list[tuple[str, str, Any]] = []
        for step in record.steps:
            if step.output is None:
                continue
            if isinstance(step.output, tuple):
                objects = tuple(step.output)
                if objects:
                    msgtype, message = encode_value(
                        objects, self._store, frame_id=self.frame_id, stamp_ns=record.stamp_ns
                    )
                else:  # nothing detected is an empty array (encode_value can't tell its type)
                    msgtype = "vision_msgs/msg/Detection3DArray"
                    message = self._store.types[msgtype](
                        header=self._header(record.stamp_ns, self.frame_id), detections=[]
                    )
                out.append((result_topic(step.algorithm, "detections"), msgtype, message))
            elif isinstance(step.output, PlannedPath):
                msg = self._path(step.output)
                out.append((result_topic(step.algorithm, "path"), "nav_msgs/msg/Path", msg))
        return out

    def _header(self, stamp_ns: int, frame_id: str) -> Any:
        types = self._store.types
        sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
        stamp = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)
        return types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def _path(self, path: PlannedPath) -> Any:
        types = self._store.types
        stamp_ns = path.stamp_ns

        def header(ns: int) -> Any:
            return self._header(ns, path.frame_id)

        poses = []
        identity = types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
        for x, y, z, t_s in path.waypoints.tolist():
            position = types["geometry_msgs/msg/Point"](x=x, y=y, z=z)
            pose = types["geometry_msgs/msg/Pose"](position=position, orientation=identity)
            poses.append(
                types["geometry_msgs/msg/PoseStamped"](
                    header=header(stamp_ns + round(t_s * 1e9)), pose=pose
                )
            )
        return types["nav_msgs/msg/Path"](header=header(stamp_ns), poses=poses)

    def __call__(self, record: FrameRecord) -> None:
        for topic, msgtype, message in self.messages(record):
            try:
                cdr = self._store.serialize_cdr(message, msgtype)
            except Exception as err:  # rosbags raises plain errors on values it cannot pack
                text = f"frame {record.frame_index}: {msgtype} for {topic} cannot be serialised ({err})"
                raise UnsupportedMessageError(text) from err
            self._writer(topic, msgtype).write(bytes(cdr), stamp_ns=record.stamp_ns)
            self.published[topic] += 1

    def close(self) -> None:
        self._writers.clear()
        self._dp = None
