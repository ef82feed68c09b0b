"""The replay source: a log's messages published at their recorded rate."""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

from redrive.assembly.sensor_map import infer_sensor_map, sensor_id_for
from redrive.errors import ConfigError, TransportError, UnsupportedMessageError
from redrive.io import LogMessage, LogReader, open_log
from redrive.io.ros.decoders import decode, topic_kind
from redrive.io.ros.decoders.base import Decoded, DecodedKind
from redrive.live.sources._common import (
    _PAGE,
    _SENSOR_PAYLOAD,
    DEFAULT_MAX_READERS,
    DEFAULT_SLOTS,
    Location,
    StopEvent,
    _check_rate,
    _check_streams,
    _Clock,
    _Publisher,
    _Route,
    _spec,
    _stopped,
)
from redrive.live.streams import StreamSpec
from redrive.transport import Policy
from redrive.transport.codec import encoded_size
from redrive.types import SensorData, SensorType, Transform, VehicleState

logger = logging.getLogger(__name__)

#: Headroom on the largest decoded sample of a replayed topic (a message that is smaller on the
#: wire may still decode larger: fewer invalid points dropped, a compressed image).
CAPACITY_HEADROOM = 1.25
#: On ``loop``, each pass's stamps are shifted by the log's span plus this gap.
LOOP_GAP_NS = 100_000_000


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
class _ReplayPlan:
    routes: dict[str, _Route]
    locations: dict[str, Location]  # frame id → position in base_link, from static transforms
    start_ns: int
    end_ns: int


def _replayable(log: LogReader) -> dict[str, tuple[type, SensorType]]:
    """Topic → (payload class, sensor type) for every topic a replay can publish."""
    out: dict[str, tuple[type, SensorType]] = {}
    for topic, info in log.topics.items():
        found = topic_kind(info)
        if found is None:
            continue
        kind, sensor_type = found
        stype: SensorType | None = None
        if kind is DecodedKind.SENSOR and sensor_type in _SENSOR_PAYLOAD:
            stype = sensor_type
        elif kind is DecodedKind.VEHICLE_STATE:
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
        and (k := topic_kind(info)) is not None
        and k[0] is DecodedKind.TRANSFORMS
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
    (:func:`~redrive.assembly.sensor_map.infer_sensor_map`, as the replay frames use) and the sensor
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
