"""Sources for live mode: a log replayed, or the simulator played, in real time into shared memory.

Each topic goes through its own :class:`~redrive.transport.Writer` (stream
``<session>.<topic>``, see :mod:`redrive.live.streams`) as typed
:class:`~redrive.types.SensorData` samples — a stand-in for a sensor rig:

* :func:`run_replay_source` publishes a log's messages at their recorded rate (log time scaled
  by ``rate``); :func:`replay_streams` says which streams that makes.
* :func:`run_synthetic_source` steps the :mod:`redrive.sim` world in real time and publishes
  each sensor sample when it is due; :func:`synthetic_streams` says which streams that makes.

Both create every writer first (``on_ready`` is called then), publish, and close (unlink) their
writers on every way out.  Samples are prepared (decoded, rendered) ahead and published at their
due time; one published more than 10 ms after it was due is counted as *late*, never dropped.
``stop`` (a ``threading.Event`` or a ``multiprocessing`` event) ends a source within ~50 ms of
the sample being prepared.

Run one as its own process (it prints ``READY`` once its writers exist, and stops cleanly —
segments unlinked — on SIGTERM or SIGINT)::

    python -m redrive.live.sources replay drive.mcap --session live-1 --rate 1.0
    python -m redrive.live.sources synthetic urban --session live-1
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import FrameType, TracebackType
from typing import Protocol

from rosbags.typesys.store import Typestore

from redrive.errors import ConfigError, RedriveError, TransportError, UnsupportedMessageError
from redrive.io import LogMessage, LogReader, open_log
from redrive.io.decoders import decode, decoder_for
from redrive.io.decoders.base import Decoded, DecodedKind
from redrive.io.sensor_map import infer_sensor_map, sensor_id_for
from redrive.io.typestore import typestore_for
from redrive.live.streams import PAYLOAD_MSGTYPE, StreamSpec, stream_name
from redrive.sim.lidar_presets import lidar_preset
from redrive.sim.rig import Rig, rig_from_mapping
from redrive.sim.scenario import Scenario, load_scenario
from redrive.sim.synth import SensorSimulation, sensor_topic
from redrive.transport import Policy, ReaderGoneError, Writer
from redrive.transport.codec import encoded_size
from redrive.types import (
    GnssFix,
    Image,
    Imu,
    PointCloud,
    SensorData,
    SensorType,
    Transform,
    VehicleState,
)

__all__ = [
    "ReplayStats",
    "StopEvent",
    "SyntheticStats",
    "main",
    "replay_streams",
    "run_replay_source",
    "run_synthetic_source",
    "synthetic_streams",
]

logger = logging.getLogger(__name__)

#: A sample published later than this after it was due counts as late.
LATE_AFTER_NS = 10_000_000
#: Headroom on the largest decoded sample of a replayed topic (a message that is smaller on the
#: wire may still decode larger: fewer invalid points dropped, a compressed image).
CAPACITY_HEADROOM = 1.25
#: On ``loop``, each pass's stamps are shifted by the log's span plus this gap.
LOOP_GAP_NS = 100_000_000
#: Defaults for every writer: slots in its ring, reader processes it accepts.
DEFAULT_SLOTS = 8
DEFAULT_MAX_READERS = 3

_PAGE = 4096
_POLL_S = 0.05
# Upper bound per simulated LiDAR point: xyz float32 + up to four channels of 8 bytes.
_POINT_BOUND_BYTES = 48
_SENSOR_PAYLOAD: Mapping[SensorType, type] = {
    SensorType.LIDAR: PointCloud,
    SensorType.LIDAR_2D: PointCloud,
    SensorType.RADAR: PointCloud,
    SensorType.CAMERA: Image,
    SensorType.IMU: Imu,
    SensorType.GNSS: GnssFix,
    SensorType.ODOMETRY: VehicleState,
}

Location = tuple[float, float, float]


class StopEvent(Protocol):
    """What ``stop`` must offer: ``threading.Event`` and ``multiprocessing`` events do."""

    def is_set(self) -> bool: ...

    def wait(self, timeout: float | None = None) -> bool: ...


@dataclass(frozen=True, slots=True, kw_only=True)
class ReplayStats:
    """What :func:`run_replay_source` published.

    Attributes:
        published: topic → samples published (every stream's topic is a key).
        skipped: topic → messages skipped as undecodable.
        late: topic → samples published more than :data:`LATE_AFTER_NS` after they were due.
        max_late_s: the largest delay past due of any sample (0.0 when unpaced).
        loops: complete passes over the log.
        wall_s: wall time from the first publication's start to the end.
        stopped: True when ``stop`` ended it (not the end of the log).
    """

    published: Mapping[str, int]
    skipped: Mapping[str, int]
    late: Mapping[str, int]
    max_late_s: float = 0.0
    loops: int = 0
    wall_s: float = 0.0
    stopped: bool = False


@dataclass(frozen=True, slots=True, kw_only=True)
class SyntheticStats:
    """What :func:`run_synthetic_source` published.

    Attributes:
        published: topic → samples published (every stream's topic is a key).
        late: topic → samples published more than :data:`LATE_AFTER_NS` after they were due.
        max_late_s: the largest delay past due of any sample (0.0 when unpaced).
        sim_s: simulated time covered.
        busy_s: wall time the simulation spent stepping the world and rendering (in its
            thread; waiting excluded).
        wall_s: wall time from the first event to the end.
        stopped: True when ``stop`` ended it (not the end of the scenario).
    """

    published: Mapping[str, int]
    late: Mapping[str, int]
    max_late_s: float = 0.0
    sim_s: float = 0.0
    busy_s: float = 0.0
    wall_s: float = 0.0
    stopped: bool = False

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per second of simulation work: above ``rate`` it keeps up."""
        return self.sim_s / self.busy_s if self.busy_s > 0 else float("inf")


# -- shared: routes, writers, waiting ---------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class _Route:
    """How one topic's values become samples of its stream."""

    spec: StreamSpec
    sensor_id: str
    sensor_type: SensorType
    rate_hz: float
    location: Location | None = None  # None: look the frame up in the log's static transforms

    def sample(
        self,
        value: object,
        *,
        stamp_ns: int,
        frame_id: str,
        locations: Mapping[str, Location] | None = None,
    ) -> SensorData:
        """Raises ValueError when ``value`` is not this sensor's payload."""
        location = self.location or (locations or {}).get(frame_id) or (0.0, 0.0, 0.0)
        resolution = (value.width, value.height) if isinstance(value, Image) else None
        return SensorData(
            sensor_id=self.sensor_id,
            sensor_type=self.sensor_type,
            stamp_ns=stamp_ns,
            frame_id=frame_id,
            frame_rate_hz=self.rate_hz,
            resolution=resolution,
            sensor_location=location,
            data=value,  # type: ignore[arg-type]  # checked by SensorData
        )


def _spec(
    session: str, topic: str, *, payload: type, sensor_type: SensorType, capacity_bytes: int
) -> StreamSpec:
    # a 2D scan travels as a PointCloud but stands for a LaserScan (so the sensor map does not
    # take a 20 Hz 2D LiDAR for the 3D LiDAR that drives frames)
    msgtype = (
        "sensor_msgs/msg/LaserScan"
        if sensor_type is SensorType.LIDAR_2D
        else PAYLOAD_MSGTYPE[payload.__name__]
    )
    return StreamSpec(
        topic=topic,
        msgtype=msgtype,
        stream=stream_name(session, topic),
        payload="sensor",
        capacity_bytes=-(-int(capacity_bytes) // _PAGE) * _PAGE,
    )


def _check_streams(routes: Mapping[str, _Route], where: str) -> None:
    seen: dict[str, str] = {}
    for topic, route in routes.items():
        other = seen.setdefault(route.spec.stream, topic)
        if other != topic:
            msg = (
                f"{where}: topics {other!r} and {topic!r} both map to stream "
                f"{route.spec.stream!r}; replay only one of them (topics=...)"
            )
            raise ConfigError(msg)


def _check_rate(rate: float | None) -> float | None:
    if rate is not None and not rate > 0:
        msg = f"rate must be > 0 (1.0 = real time), or None for as fast as possible; got {rate}"
        raise ConfigError(msg)
    return None if rate is None else float(rate)


def _stopped(stop: StopEvent | None) -> bool:
    return stop is not None and stop.is_set()


def _sleep_until(deadline_ns: int, stop: StopEvent | None) -> bool:
    """Wait until ``time.monotonic_ns()`` reaches ``deadline_ns``; False when ``stop`` came first."""
    while True:
        if _stopped(stop):
            return False
        remaining_s = (deadline_ns - time.monotonic_ns()) / 1e9
        if remaining_s <= 0:
            return True
        if stop is None:
            time.sleep(remaining_s)
        else:
            stop.wait(min(remaining_s, _POLL_S))


class _Clock:
    """When each sample is due: its offset (data time since the start) divided by ``rate``, from
    the moment the first sample is ready (so the first decode or render is not counted late)."""

    def __init__(self, rate: float | None, stop: StopEvent | None) -> None:
        self.rate, self.stop = rate, stop
        self._t0_ns: int | None = None

    def wait(self, offset_ns: int) -> int | None:
        """Wait until ``offset_ns`` is due; how late it is then (ns), or None when stopped."""
        if self.rate is None:
            return None if _stopped(self.stop) else 0
        due_ns = round(offset_ns / self.rate)
        if self._t0_ns is None:
            self._t0_ns = time.monotonic_ns() - due_ns
        due_ns += self._t0_ns
        if not _sleep_until(due_ns, self.stop):
            return None
        return time.monotonic_ns() - due_ns


class _Publisher:
    """The writers of one source, what went through them, and lossless back-pressure."""

    def __init__(
        self,
        routes: Mapping[str, _Route],
        *,
        policy: Policy,
        slots: int,
        max_readers: int,
        stop: StopEvent | None,
        timeout_s: float | None,
    ) -> None:
        self.routes = routes
        self.stop = stop
        self.timeout_s = timeout_s
        self.published = dict.fromkeys(routes, 0)
        self.late = dict.fromkeys(routes, 0)
        self.max_late_ns = 0
        self.writers: dict[str, Writer] = {}
        try:
            for topic, route in routes.items():
                self.writers[topic] = Writer(
                    route.spec.stream,
                    capacity_bytes=route.spec.capacity_bytes,
                    slots=slots,
                    policy=policy,
                    max_readers=max_readers,
                )
        except BaseException:
            self.close()
            raise
        logger.debug("writers ready: %s", ", ".join(r.spec.stream for r in routes.values()))

    def publish(self, topic: str, sample: SensorData, *, late_ns: int, where: str) -> bool:
        """Publish ``sample`` on ``topic``'s stream; False when ``stop`` was set while it waited
        for a lossless reader.

        Raises:
            TransportError: the sample does not fit the stream, or lossless back-pressure lasted
                longer than the timeout.
        """
        writer = self.writers[topic]
        size = encoded_size(sample)
        if size > writer.capacity:
            msg = (
                f"{where}: a {size}-byte {type(sample.data).__name__} sample on {topic} does not "
                f"fit stream {writer.name!r} ({writer.capacity}-byte slots, sized before the "
                "start); the source stops — give the stream a larger capacity_bytes"
            )
            raise TransportError(msg)
        deadline = None if self.timeout_s is None else time.monotonic() + self.timeout_s
        while True:
            try:
                writer.publish_sample(sample, timeout_s=_POLL_S)
                break
            except ReaderGoneError as err:  # its entry is freed: publishing goes on without it
                logger.warning("%s", err)
            except TransportError:
                if _stopped(self.stop):
                    return False
                if deadline is not None and time.monotonic() >= deadline:
                    raise
        self.published[topic] += 1
        if late_ns > LATE_AFTER_NS:
            self.late[topic] += 1
        self.max_late_ns = max(self.max_late_ns, late_ns)
        return True

    def close(self) -> None:
        """Close (unlink) every writer, in parallel: each waits up to ~0.2 s for its attach
        thread."""

        def close_one(writer: Writer) -> None:
            try:
                writer.close()
            except (OSError, TransportError) as err:  # pragma: no cover - best effort
                logger.warning("stream %s: closing failed: %s", writer.name, err)

        threads = [threading.Thread(target=close_one, args=(w,)) for w in self.writers.values()]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        self.writers = {}

    def __enter__(self) -> _Publisher:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


# -- replay -----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class _ReplayPlan:
    routes: dict[str, _Route]
    locations: dict[str, Location]  # frame id → position in base_link, from static transforms
    start_ns: int
    end_ns: int


def _replayable(log: LogReader) -> dict[str, tuple[type, SensorType]]:
    """Topic → (payload class, sensor type) for every topic a replay can publish."""
    out: dict[str, tuple[type, SensorType]] = {}
    for topic, info in log.topics.items():
        decoder = decoder_for(info.msgtype)
        if decoder is None:
            continue
        stype: SensorType | None = None
        if decoder.kind is DecodedKind.SENSOR and decoder.sensor_type in _SENSOR_PAYLOAD:
            stype = decoder.sensor_type
        elif decoder.kind is DecodedKind.VEHICLE_STATE:
            stype = SensorType.ODOMETRY
        if stype is None:
            continue  # objects, transforms: no sensor payload
        if not info.has_definition or info.count == 0:
            logger.info("%s: %s is not replayed (no definition or no messages)", log.path, topic)
            continue
        out[topic] = (_SENSOR_PAYLOAD[stype], stype)
    return out


def _payload_size(value: object, stype: SensorType) -> int:
    sample = SensorData(sensor_id="size", sensor_type=stype, stamp_ns=0, data=value)  # type: ignore[arg-type]
    return encoded_size(sample)


def _add_locations(decoded: Decoded, locations: dict[str, Location]) -> None:
    if not isinstance(decoded.value, tuple):
        return
    for tf in decoded.value:
        if isinstance(tf, Transform) and tf.stamp_ns == 0 and tf.parent_frame == "base_link":
            xyz = tf.translation
            locations[tf.child_frame] = (float(xyz[0]), float(xyz[1]), float(xyz[2]))


def _scan(
    log: LogReader, topics: Mapping[str, tuple[type, SensorType]]
) -> tuple[dict[str, int], dict[str, Location]]:
    """One pass over the log without decoding (but the static transforms): each topic's largest
    sample size, from its largest message on the wire, decoded."""
    tf_static = [
        t
        for t, info in log.topics.items()
        if t.rstrip("/").endswith("tf_static")
        and (d := decoder_for(info.msgtype)) is not None
        and d.kind is DecodedKind.TRANSFORMS
    ]
    largest: dict[str, LogMessage] = {}
    sizes: dict[str, int] = {}
    locations: dict[str, Location] = {}
    for message in log.messages(topics=[*topics, *tf_static]):
        if message.topic in tf_static:
            try:
                _add_locations(decode(message, log.deserialize), locations)
            except UnsupportedMessageError as err:
                logger.debug("%s", err)
        elif message.encoding == "native":  # already decoded: its exact size
            try:
                size = _payload_size(
                    decode(message, log.deserialize).value, topics[message.topic][1]
                )
            except (UnsupportedMessageError, ValueError, TransportError) as err:
                logger.debug("%s", err)
                continue
            sizes[message.topic] = max(sizes.get(message.topic, 0), size)
        else:
            best = largest.get(message.topic)
            if best is None or message.size_bytes > best.size_bytes:  # raw may be a view: copy
                largest[message.topic] = dataclasses.replace(message, raw=bytes(message.raw))
    for topic, message in largest.items():
        try:
            size = _payload_size(decode(message, log.deserialize).value, topics[topic][1])
            sizes[topic] = round(size * CAPACITY_HEADROOM) + _PAGE
        except (UnsupportedMessageError, ValueError, TransportError) as err:
            sizes[topic] = 2 * message.size_bytes + 16 * _PAGE
            logger.warning(
                "%s: the largest message on %s does not decode (%s); its stream takes %d bytes, "
                "a larger sample will stop the replay with a TransportError",
                log.path,
                topic,
                err,
                sizes[topic],
            )
    return sizes, locations


def _plan_replay(log: LogReader, session: str, topics: Collection[str] | None) -> _ReplayPlan:
    replayable = _replayable(log)
    if topics is not None:
        wanted = list(dict.fromkeys(topics))
        if missing := [t for t in wanted if t not in replayable]:
            msg = (
                f"{log.path}: cannot replay {', '.join(missing)}: not in the log or not a "
                f"sensor/vehicle-state topic; replayable: {', '.join(sorted(replayable)) or 'none'}"
            )
            raise ConfigError(msg)
        replayable = {t: replayable[t] for t in wanted}
    if not replayable:
        msg = f"{log.path}: no topic to replay (no sensor or vehicle-state topic with a decoder)"
        raise ConfigError(msg)
    sizes, locations = _scan(log, replayable)
    duration_ns = log.end_ns - log.start_ns
    smap = infer_sensor_map(log.topics, duration_ns=duration_ns)
    by_topic = smap.by_topic()
    used = {s.sensor_id for s in smap.sensors}
    routes: dict[str, _Route] = {}
    for topic in sorted(replayable):
        payload, stype = replayable[topic]
        if topic not in sizes:
            logger.info("%s: no decodable message on %s; not replayed", log.path, topic)
            continue
        if topic in by_topic:
            sensor_id, rate_hz = by_topic[topic].sensor_id, by_topic[topic].rate_hz
        else:
            sensor_id = sensor_id_for(topic)
            while sensor_id in used:
                sensor_id += "_"
            count = log.topics[topic].count
            rate_hz = (count - 1) / (duration_ns / 1e9) if count > 1 and duration_ns > 0 else 0.0
        used.add(sensor_id)
        routes[topic] = _Route(
            spec=_spec(
                session, topic, payload=payload, sensor_type=stype, capacity_bytes=sizes[topic]
            ),
            sensor_id=sensor_id,
            sensor_type=stype,
            rate_hz=rate_hz,
        )
    _check_streams(routes, str(log.path))
    return _ReplayPlan(routes=routes, locations=locations, start_ns=log.start_ns, end_ns=log.end_ns)


def replay_streams(
    log_path: str | Path, session: str, *, topics: Collection[str] | None = None
) -> list[StreamSpec]:
    """The streams :func:`run_replay_source` publishes for this log, by topic.

    One stream per topic whose messages decode to a payload the transport carries: sensors
    (PointCloud2 and LaserScan → PointCloud, Image and CompressedImage → Image, Imu, NavSatFix →
    GnssFix) and vehicle state (Odometry, PoseStamped, TwistStamped → VehicleState, sensor type
    ODOMETRY; a ground-truth ego state topic is one of them).  Objects and transforms are not
    published.  ``msgtype`` is the type the payload stands for (:data:`PAYLOAD_MSGTYPE`).

    ``capacity_bytes``: the log is read once without decoding to find each topic's largest
    message on the wire; that message is decoded, and its sample's size
    (:func:`~redrive.transport.codec.encoded_size`) times :data:`CAPACITY_HEADROOM` plus a page
    is the capacity (native KITTI messages are already decoded: their largest exact size).  The
    read costs about a pass over the file (0.4 s for 80 MB of MCAP here).

    Raises:
        LogError: the log cannot be read.
        ConfigError: a topic in ``topics`` cannot be replayed, or nothing can.
    """
    with open_log(log_path) as log:
        return [r.spec for r in _plan_replay(log, session, topics).routes.values()]


def _shifted(sample: SensorData, shift_ns: int) -> SensorData:
    data = sample.data
    if isinstance(data, VehicleState):
        data = dataclasses.replace(data, stamp_ns=data.stamp_ns + shift_ns)
    return dataclasses.replace(sample, stamp_ns=sample.stamp_ns + shift_ns, data=data)


def run_replay_source(
    log_path: str | Path,
    session: str,
    *,
    rate: float | None = 1.0,
    topics: Collection[str] | None = None,
    policy: Policy = Policy.KEEP_LATEST,
    stop: StopEvent | None = None,
    loop: bool = False,
    on_ready: Callable[[], None] | None = None,
    slots: int = DEFAULT_SLOTS,
    max_readers: int = DEFAULT_MAX_READERS,
    publish_timeout_s: float | None = None,
) -> ReplayStats:
    """Publish a log's messages as typed samples into the streams of :func:`replay_streams`.

    A message is due at its log time (recorder time) since the log's start divided by ``rate``
    (``None``: as fast as possible); it is decoded ahead and published at that moment, with its
    header stamp as the sample's stamp, its frame, the sensor id the sensor map infers
    (:func:`~redrive.io.sensor_map.infer_sensor_map`, as the replay frames use) and the sensor
    location from the log's ``/tf_static`` (zeros without one).  Undecodable messages are
    skipped and counted.  With ``loop`` the log plays again and again until ``stop``, stamps
    shifted each pass by the log's span plus :data:`LOOP_GAP_NS` so time keeps increasing.

    Args:
        rate: playback speed (2.0 = twice real time), or None for as fast as possible.
        topics: replay only these (default: every replayable topic).
        policy: of every writer; LOSSLESS waits for slow lossless readers (back-pressure).
        stop: set it to end the source early (checked at least every 50 ms while waiting).
        on_ready: called once every writer exists, before the first publication.
        slots, max_readers: of every writer.
        publish_timeout_s: how long lossless back-pressure may hold one sample (None: no limit;
            ``stop`` still ends the wait).  A lossless reader that dies is logged and dropped.

    Raises:
        LogError: the log cannot be read.
        ConfigError: bad ``rate`` or ``topics``.
        TransportError: a writer cannot be created, a sample does not fit its stream, or
            back-pressure outlasted ``publish_timeout_s``.  The writers are closed in any case.
    """
    rate = _check_rate(rate)
    with open_log(log_path) as log:
        plan = _plan_replay(log, session, topics)
        skipped = dict.fromkeys(plan.routes, 0)
        if _stopped(stop):
            return ReplayStats(
                published=dict.fromkeys(plan.routes, 0), skipped=skipped, late={}, stopped=True
            )
        with _Publisher(
            plan.routes,
            policy=policy,
            slots=slots,
            max_readers=max_readers,
            stop=stop,
            timeout_s=publish_timeout_s,
        ) as pub:
            if on_ready is not None:
                on_ready()
            t0_ns, clock = time.monotonic_ns(), _Clock(rate, stop)
            cycle_ns = plan.end_ns - plan.start_ns + LOOP_GAP_NS
            loops, stopped = 0, False
            while not stopped:
                before = sum(pub.published.values())
                messages = log.messages(topics=list(plan.routes))
                stopped = _replay_pass(
                    log,
                    plan,
                    messages=messages,
                    pub=pub,
                    skipped=skipped,
                    clock=clock,
                    shift_ns=loops * cycle_ns,
                    stop=stop,
                )
                if stopped:
                    break
                loops += 1
                if not loop or sum(pub.published.values()) == before:
                    break
            wall_s = (time.monotonic_ns() - t0_ns) / 1e9
            stats = ReplayStats(
                published=dict(pub.published),
                skipped=skipped,
                late=dict(pub.late),
                max_late_s=pub.max_late_ns / 1e9,
                loops=loops,
                wall_s=wall_s,
                stopped=stopped,
            )
    logger.info("replay of %s: %s", log_path, stats)
    return stats


def _replay_pass(
    log: LogReader,
    plan: _ReplayPlan,
    *,
    messages: Iterator[LogMessage],
    pub: _Publisher,
    skipped: dict[str, int],
    clock: _Clock,
    shift_ns: int,
    stop: StopEvent | None,
) -> bool:
    """One pass over the log; True when ``stop`` ended it."""
    for message in messages:
        if _stopped(stop):
            return True
        topic = message.topic
        route = plan.routes[topic]
        try:
            decoded = decode(message, log.deserialize)
            sample = route.sample(
                decoded.value,
                stamp_ns=decoded.stamp_ns,
                frame_id=decoded.frame_id,
                locations=plan.locations,
            )
        except (UnsupportedMessageError, ValueError) as err:
            skipped[topic] += 1
            level = logging.WARNING if skipped[topic] == 1 else logging.DEBUG
            logger.log(level, "%s: skipping an undecodable message on %s: %s", log.path, topic, err)
            continue
        if shift_ns:
            sample = _shifted(sample, shift_ns)
        late_ns = clock.wait(message.log_time_ns - plan.start_ns + shift_ns)
        if late_ns is None:
            return True
        where = f"{log.path} at log time {message.log_time_ns}"
        if not pub.publish(topic, sample, late_ns=late_ns, where=where):
            return True
    return False


# -- synthetic --------------------------------------------------------------------------------


def _scenario(scenario: Scenario | str | Path) -> Scenario:
    return scenario if isinstance(scenario, Scenario) else load_scenario(scenario)


def _synthetic_routes(rig: Rig, session: str) -> dict[str, _Route]:
    """Topic → route for every sensor of the rig, sized from the rig (not by rendering)."""
    routes: dict[str, _Route] = {}
    for spec in rig:
        kind = spec.kind
        payload = _SENSOR_PAYLOAD[kind]
        if kind in (SensorType.LIDAR, SensorType.LIDAR_2D):
            preset = lidar_preset(spec.preset or "")
            capacity = preset.columns * preset.num_lasers * _POINT_BOUND_BYTES + 8 * 64
        elif kind is SensorType.CAMERA and spec.camera is not None:
            capacity = spec.camera.width * spec.camera.height * 3 + 64
        else:
            capacity = _PAGE
        topic = sensor_topic(spec)
        routes[topic] = _Route(
            spec=_spec(session, topic, payload=payload, sensor_type=kind, capacity_bytes=capacity),
            sensor_id=sensor_id_for(topic),
            sensor_type=kind,
            rate_hz=spec.rate_hz,
            location=spec.xyz_m,
        )
    _check_streams(routes, f"rig of {session}")
    return routes


def synthetic_streams(scenario: Scenario | str | Path, session: str) -> list[StreamSpec]:
    """The streams :func:`run_synthetic_source` publishes for this scenario, in rig order.

    One per rig sensor, on the topic :func:`~redrive.sim.synth.synthesize` writes it to: LiDAR
    and 2D LiDAR → PointCloud, camera (``/<name>/image_raw``) → Image, IMU, GNSS → GnssFix,
    wheel odometry → VehicleState.  Capacities come from the rig: a LiDAR's beams × columns ×
    48 bytes, a camera's rgb8 frame, a page for the rest.

    Raises:
        ConfigError: the scenario (a name or a TOML path, or a Scenario) or its rig is invalid.
    """
    scen = _scenario(scenario)
    rig = rig_from_mapping(scen.rig, source=scen.source)
    return [r.spec for r in _synthetic_routes(rig, session).values()]


class _SampleBuffer:
    """A :class:`~redrive.sim.synth.MessageSink` that keeps the samples of the rig's streams
    (LaserScans decoded as a replay would) and drops the rest (ground truth, transforms)."""

    def __init__(self, routes: Mapping[str, _Route]) -> None:
        self.routes = routes
        self.pending: list[tuple[str, SensorData]] = []
        self._typestore: Typestore | None = None

    @property
    def typestore(self) -> Typestore:
        if self._typestore is None:
            self._typestore = typestore_for(2, needed=("sensor_msgs/msg/LaserScan",))[0]
        return self._typestore

    def write(
        self,
        topic: str,
        log_time_ns: int,
        value: object,
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> None:
        route = self.routes.get(topic)
        if route is None:
            return
        if isinstance(value, VehicleState):  # as McapWriter.write: the state's own frame, stamp
            frame_id = value.frame_id if frame_id is None else frame_id
            stamp_ns = value.stamp_ns if stamp_ns is None else stamp_ns
        sample = route.sample(
            value,
            stamp_ns=log_time_ns if stamp_ns is None else stamp_ns,
            frame_id=frame_id or "",
        )
        self.pending.append((topic, sample))

    def write_raw(
        self, topic: str, msgtype: str, log_time_ns: int, cdr_bytes: bytes | memoryview
    ) -> None:
        if topic not in self.routes:
            return
        message = LogMessage(
            topic=topic, msgtype=msgtype, log_time_ns=log_time_ns, encoding="cdr", raw=cdr_bytes
        )
        ts = self.typestore
        decoded = decode(message, lambda m: ts.deserialize_cdr(bytes(m.raw), m.msgtype))
        self.write(
            topic, log_time_ns, decoded.value, frame_id=decoded.frame_id, stamp_ns=decoded.stamp_ns
        )


_Batch = tuple[int, list[tuple[str, SensorData]]]  # event offset (ns since start), samples


class _RenderAhead:
    """Runs the simulation in a thread, at most ``lookahead_ns`` of simulated time ahead of what
    has been published, so a long render (a camera frame, a LiDAR sweep) overlaps the waiting
    instead of making the samples due meanwhile late."""

    def __init__(self, sim: SensorSimulation, sink: _SampleBuffer, *, lookahead_ns: int) -> None:
        self.sim, self.sink, self.lookahead_ns = sim, sink, lookahead_ns
        self.render_ns = 0
        self._cond = threading.Condition()
        self._batches: deque[_Batch] = deque()
        self._published_ns = 0
        self._done = False
        self._halt = False
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="redrive-sim-ahead", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            events = self.sim.run(self.sink)
            while True:
                tick_ns = time.monotonic_ns()
                event_ns = next(events, None)
                self.render_ns += time.monotonic_ns() - tick_ns
                if event_ns is None:
                    break
                if not self.sink.pending:
                    continue
                offset_ns = event_ns - self.sim.start_ns
                batch = (offset_ns, list(self.sink.pending))
                self.sink.pending.clear()
                with self._cond:
                    while not self._halt and offset_ns - self._published_ns > self.lookahead_ns:
                        self._cond.wait(_POLL_S)
                    if self._halt:
                        return
                    self._batches.append(batch)
                    self._cond.notify_all()
        except BaseException as err:  # handed to the publishing loop
            self._error = err
        finally:
            with self._cond:
                self._done = True
                self._cond.notify_all()

    def next(self, stop: StopEvent | None) -> _Batch | None:
        """The next batch in time order; None at the end or when ``stop`` is set.

        Raises:
            whatever the simulation raised.
        """
        with self._cond:
            while not self._batches and not self._done and not _stopped(stop):
                self._cond.wait(_POLL_S)
            if self._batches and not _stopped(stop):
                return self._batches.popleft()
            if self._error is not None:
                raise self._error
            return None

    def published(self, offset_ns: int) -> None:
        with self._cond:
            self._published_ns = offset_ns
            self._cond.notify_all()

    def close(self) -> None:
        with self._cond:
            self._halt = True
            self._cond.notify_all()
        self._thread.join(timeout=10)


def run_synthetic_source(
    scenario: Scenario | str | Path,
    session: str,
    *,
    duration_s: float | None = None,
    seed: int | None = None,
    rate: float | None = 1.0,
    stop: StopEvent | None = None,
    policy: Policy = Policy.KEEP_LATEST,
    on_ready: Callable[[], None] | None = None,
    slots: int = DEFAULT_SLOTS,
    max_readers: int = DEFAULT_MAX_READERS,
    publish_timeout_s: float | None = None,
    lookahead_s: float = 0.5,
) -> SyntheticStats:
    """Play the scenario's world in real time into the streams of :func:`synthetic_streams`.

    The world is stepped and the rig rendered event by event exactly as
    :func:`~redrive.sim.synth.synthesize` does (same seed, same samples), but each sample is
    published as a typed ``SensorData`` when its event is due — simulated time since the start
    divided by ``rate`` (None: as fast as possible) — instead of being written to an MCAP.  A
    LiDAR sweep is due when it ends and is stamped when it starts; the 2D LiDAR's scan is
    published as its decoded LaserScan (what a replay of the synthesized log gives); odometry is
    the noisy wheel odometry (``odom`` frame).  Ground truth (objects, the true ego state) and
    transforms are not sensor payloads and are not published.

    The simulation runs in a thread up to ``lookahead_s`` of simulated time ahead of the
    publications, which wait for their moment; when the simulator is slower than ``rate`` asks,
    samples go out late — counted in ``late``, never dropped.

    Args:
        scenario: a Scenario, a catalogue name (``urban``) or a scenario TOML path.
        duration_s, seed: override the scenario's.
        stop, on_ready, policy, slots, max_readers, publish_timeout_s: as
            :func:`run_replay_source`.
        lookahead_s: how far (simulated time) the simulation may run ahead.

    Raises:
        ConfigError: bad scenario, rig or ``rate``.
        SimulationError: the scenario cannot be simulated.
        TransportError: as :func:`run_replay_source`; the writers are closed in any case.
    """
    rate = _check_rate(rate)
    sim = SensorSimulation(_scenario(scenario), duration_s=duration_s, seed=seed)
    routes = _synthetic_routes(sim.rig, session)
    if _stopped(stop):
        return SyntheticStats(published=dict.fromkeys(routes, 0), late={}, stopped=True)
    with _Publisher(
        routes,
        policy=policy,
        slots=slots,
        max_readers=max_readers,
        stop=stop,
        timeout_s=publish_timeout_s,
    ) as pub:
        if on_ready is not None:
            on_ready()
        t0_ns, clock = time.monotonic_ns(), _Clock(rate, stop)
        ahead = _RenderAhead(sim, _SampleBuffer(routes), lookahead_ns=round(lookahead_s * 1e9))
        last_ns, stopped = 0, False
        try:
            while (batch := ahead.next(stop)) is not None:
                offset_ns, samples = batch
                late_ns = clock.wait(offset_ns)
                if late_ns is None:
                    break
                where = f"scenario {sim.scenario.name} at {offset_ns / 1e9:.3f} s"
                if not all(pub.publish(t, x, late_ns=late_ns, where=where) for t, x in samples):
                    break
                last_ns = offset_ns
                ahead.published(offset_ns)
            stopped = _stopped(stop)
        finally:
            ahead.close()
        stats = SyntheticStats(
            published=dict(pub.published),
            late=dict(pub.late),
            max_late_s=pub.max_late_ns / 1e9,
            sim_s=last_ns / 1e9,
            busy_s=ahead.render_ns / 1e9,
            wall_s=(time.monotonic_ns() - t0_ns) / 1e9,
            stopped=stopped,
        )
    logger.info("synthetic %s: %s", sim.scenario.name, stats)
    return stats


# -- as a process -----------------------------------------------------------------------------


class _SignalStop:
    """A stop flag set from a signal handler (a ``threading.Event`` set there may deadlock)."""

    def __init__(self) -> None:
        self._set = False

    def handle(self, signum: int, frame: FrameType | None) -> None:
        del frame
        logger.info("signal %d: stopping", signum)
        self._set = True

    def is_set(self) -> bool:
        return self._set

    def wait(self, timeout: float | None = None) -> bool:
        if not self._set:
            time.sleep(_POLL_S if timeout is None else max(0.0, min(timeout, _POLL_S)))
        return self._set


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m redrive.live.sources",
        description="Publish a log or a simulated scenario into shared memory, in real time.",
    )
    sub = parser.add_subparsers(dest="source", required=True)
    replay = sub.add_parser("replay", help="replay a log (bag, MCAP, KITTI)")
    replay.add_argument("log", type=Path)
    replay.add_argument("--topics", nargs="+", default=None, help="only these topics")
    replay.add_argument("--loop", action="store_true", help="play the log again and again")
    synthetic = sub.add_parser("synthetic", help="play a redrive.sim scenario")
    synthetic.add_argument("scenario", help="a catalogue name (urban) or a scenario .toml")
    synthetic.add_argument("--duration", type=float, default=None, help="seconds simulated")
    synthetic.add_argument("--seed", type=int, default=None)
    for p in (replay, synthetic):
        p.add_argument("--session", required=True, help="stream names are <session>.<topic>")
        p.add_argument("--rate", type=float, default=1.0, help="speed; 0 = as fast as possible")
        p.add_argument("--lossless", action="store_true", help="lossless writers (back-pressure)")
        p.add_argument("-v", "--verbose", action="store_true", help="log at INFO")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """The ``python -m redrive.live.sources`` entry: prints ``READY`` once the writers exist."""
    args = _parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    stop = _SignalStop()
    previous = {sig: signal.signal(sig, stop.handle) for sig in (signal.SIGTERM, signal.SIGINT)}

    def ready() -> None:
        print("READY", flush=True)  # the one line a parent process waits for

    rate = None if args.rate == 0 else args.rate
    policy = Policy.LOSSLESS if args.lossless else Policy.KEEP_LATEST
    try:
        if args.source == "replay":
            run_replay_source(
                args.log,
                args.session,
                rate=rate,
                topics=args.topics,
                policy=policy,
                stop=stop,
                loop=args.loop,
                on_ready=ready,
            )
        else:
            run_synthetic_source(
                args.scenario,
                args.session,
                duration_s=args.duration,
                seed=args.seed,
                rate=rate,
                stop=stop,
                policy=policy,
                on_ready=ready,
            )
    except RedriveError as err:
        logger.error("%s", err)
        return 1
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0


if __name__ == "__main__":
    sys.exit(main())
