"""The Sensor Dispatcher for replay: a log becomes a stream of synchronised :class:`Frame`s.

Every sample of the *driver* sensor makes one frame; a log without a sensor to drive frames
but with ground truth (recorded traffic: Waymo Open Motion, CommonRoad) makes one frame per
ground-truth message instead.  Each other sensor contributes the sample
whose header stamp is nearest the driver's, if it is within that input's tolerance (the sensor
map's: 50 ms, or half the period of an input slower than ~8 Hz); the ego state is interpolated
to the driver's stamp; ground truth is the nearest objects message within its tolerance, the
traffic lights' states (``Frame.traffic``) the nearest light-states message within its.  What
no sample within its tolerance provides is named in ``Frame.missing``.  Reading is streaming:
only a window of the widest tolerance + lookahead around the frame being assembled is held,
whatever the log's length.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import partial
from itertools import repeat
from typing import cast

from redrive.assembly.clocks import OTHER_CLOCK_NS
from redrive.assembly.mounts import SensorMounts, mount_tf_topics
from redrive.assembly.non_finite import NonFiniteCounter
from redrive.assembly.sensor_map import SensorMap, SensorMapOverrides, infer_sensor_map
from redrive.errors import ConfigError, UnsupportedMessageError
from redrive.io.base import LogMessage, LogReader
from redrive.io.ros.decoders import decode, decoder_for
from redrive.io.ros.decoders.base import Decoded
from redrive.io.ros.decoders.motion import OdometryDecoder, PendingState
from redrive.io.ros.decoders.tf import is_static_tf_topic
from redrive.types import (
    DetectedObject,
    Frame,
    Image,
    PointCloud,
    SensorData,
    SensorType,
    TrafficData,
    Transform,
    VehicleState,
)

__all__ = ["FrameAssembler", "interpolate_state", "iter_frames"]

logger = logging.getLogger(__name__)

_DEFAULT_LOOKAHEAD_NS = 200_000_000
_STATE_WINDOW_NS = 2_000_000_000
#: the clouds whose non-finite points are counted (a 2D scan marks a beam without return NaN)
_COUNTED = frozenset({SensorType.LIDAR, SensorType.RADAR})


@dataclass(frozen=True, slots=True)
class _Sample:
    stamp_ns: int
    decoded: Decoded


def _objects_of(value: tuple[object, ...]) -> tuple[DetectedObject, ...]:
    """The :class:`DetectedObject` items of a decoded tuple, in order: the tuple itself when
    every item is one (the common case, tested in one C-level pass; tuples are immutable)."""
    if type(value) is tuple and all(map(isinstance, value, repeat(DetectedObject))):
        return cast("tuple[DetectedObject, ...]", value)
    return tuple(o for o in value if isinstance(o, DetectedObject))


def interpolate_state(before: VehicleState, after: VehicleState, stamp_ns: int) -> VehicleState:
    """Linear in position, velocity and acceleration; shortest-arc in heading."""
    span = after.stamp_ns - before.stamp_ns
    a = 0.0 if span <= 0 else (stamp_ns - before.stamp_ns) / span
    dh = math.remainder(after.heading_rad - before.heading_rad, math.tau)
    return VehicleState(
        stamp_ns=stamp_ns,
        frame_id=before.frame_id,
        position=before.position + a * (after.position - before.position),
        velocity=before.velocity + a * (after.velocity - before.velocity),
        acceleration=before.acceleration + a * (after.acceleration - before.acceleration),
        heading_rad=math.remainder(before.heading_rad + a * dh, math.tau),
        yaw_rate_rad_s=before.yaw_rate_rad_s + a * (after.yaw_rate_rad_s - before.yaw_rate_rad_s),
    )


class FrameAssembler:
    """Turn a log into frames.

    Args:
        log: an open log.
        sensor_map: which topic is which sensor; inferred from the log when None.
        overrides: what a sensor map file says (used only when ``sensor_map`` is None).
        lookahead_ns: how much further the log is read (record time) after a driver sample
            arrives before its frame is assembled: the other inputs' samples of that stamp may
            be recorded later (recorder latency).  Header stamps are matched with header
            stamps and record times with record times, never one with the other: on real bags
            the two clocks can be days apart.

    Raises:
        ConfigError: the log has neither a sensor nor ground truth to drive frames.
    """

    def __init__(
        self,
        log: LogReader,
        *,
        sensor_map: SensorMap | None = None,
        overrides: SensorMapOverrides | None = None,
        lookahead_ns: int = _DEFAULT_LOOKAHEAD_NS,
    ) -> None:
        self.log = log
        self.sensor_map = sensor_map or infer_sensor_map(
            log.topics, duration_ns=log.end_ns - log.start_ns, overrides=overrides
        )
        if self.sensor_map.driver is None and self.sensor_map.ground_truth_topic is None:
            msg = (
                f"{log.path}: no sensor to drive frames (no LiDAR, camera or radar topic with a "
                "decoder) and no ground truth; name one with `driver` in a sensor map file"
            )
            raise ConfigError(msg)
        self.lookahead_ns = lookahead_ns
        self.undecodable: dict[str, int] = {}
        #: the non-finite points of each 3D cloud topic (counted, never filtered)
        self.non_finite = NonFiniteCounter(log.path)
        self._warned: set[str] = set()
        self._unplaced: set[str] = set()
        self._clock_warned: set[str] = set()

    def frames(self, *, start_ns: int | None = None, stop_ns: int | None = None) -> Iterator[Frame]:
        """Frames in order, from driver samples with log time in ``[start_ns, stop_ns)``."""
        smap = self.sensor_map
        # no driver sensor: the ground-truth messages drive the frames (checked at __init__)
        driver_id = smap.sensor(smap.driver).sensor_id if smap.driver is not None else None
        by_topic = smap.by_topic()
        tol = smap.widest_tolerance_ns  # frames wait this long for the slowest input's samples
        buffers: dict[str, deque[_Sample]] = {s.sensor_id: deque() for s in smap.sensors}
        states: deque[VehicleState | PendingState] = deque()
        objects: deque[_Sample] = deque()
        lights: deque[_Sample] = deque()
        mounts = SensorMounts()
        # driver samples waiting for the other inputs, with the log time each arrived at: a frame
        # is assembled once the log has moved on ``tol + lookahead`` past its driver's arrival.
        # Header stamps and log times are never compared (on real bags they are far apart).
        pending: deque[tuple[_Sample, int]] = deque()
        last_driver_ns: int | None = None  # the newest driver stamp: the reference for pruning
        assemble = partial(
            self._assemble,
            buffers=buffers,
            states=states,
            objects=objects,
            lights=lights,
            mounts=mounts,
        )
        index = 0
        read_from = None if start_ns is None else start_ns - tol - self.lookahead_ns
        # The tf topics are read for the sensor mounts only: /tf (often 100 Hz+) just when the
        # static transforms leave a sensor unplaced.
        tf_topics = mount_tf_topics(
            self.log,
            tf_topics=smap.tf_topics,
            sensor_topics=[s.topic for s in smap.sensors if s.location is None],
        )
        topics = [t for t in smap.topics() if t not in smap.tf_topics] + tf_topics
        # /tf_static is latched at the start of a log: read it whole even when seeking.
        static_tf = [t for t in tf_topics if is_static_tf_topic(t)]
        if read_from is not None and static_tf:
            for message in self.log.messages(topics=static_tf, stop_ns=read_from):
                decoded = self._decode(message)
                if decoded is not None and isinstance(decoded.value, tuple):
                    mounts.add(message.topic, _transforms(decoded))
        # The ego state (often 100 Hz odometry) is read, and built only for the frames' stamps.
        state_topic = smap.vehicle_state_topic if smap.vehicle_state_topic not in by_topic else None
        for message in self.log.messages(topics=list(dict.fromkeys(topics)), start_ns=read_from):
            pending_state = None
            if message.topic == state_topic:
                decoder = decoder_for(message.msgtype)
                if type(decoder) is OdometryDecoder:
                    try:
                        pending_state = decoder.read_pending(message)
                    except UnsupportedMessageError as err:
                        self._undecodable(message, err)
                        continue
            now = message.log_time_ns
            if pending_state is not None:
                states.append(pending_state)
            else:
                decoded = self._decode(message)
                if decoded is None:
                    continue
                spec = by_topic.get(message.topic)
                if spec is not None:
                    if type(decoded.value) is PointCloud and spec.sensor_type in _COUNTED:
                        self.non_finite.check(message.topic, spec.sensor_id, decoded.value)
                    sample = _Sample(decoded.stamp_ns, decoded)
                    buffers[spec.sensor_id].append(sample)
                    if spec.sensor_id == driver_id:
                        last_driver_ns = decoded.stamp_ns
                        if start_ns is not None and now < start_ns:
                            pass
                        elif stop_ns is not None and now >= stop_ns:
                            break
                        else:
                            pending.append((sample, now))
                elif message.topic == smap.vehicle_state_topic and isinstance(
                    decoded.value, VehicleState
                ):
                    states.append(decoded.value)
                elif message.topic == smap.ground_truth_topic:
                    sample = _Sample(decoded.stamp_ns, decoded)
                    objects.append(sample)
                    if driver_id is None:
                        last_driver_ns = decoded.stamp_ns
                        if start_ns is not None and now < start_ns:
                            pass
                        elif stop_ns is not None and now >= stop_ns:
                            break
                        else:
                            pending.append((sample, now))
                elif message.topic == smap.traffic_lights_topic:
                    lights.append(_Sample(decoded.stamp_ns, decoded))
                elif message.topic in smap.tf_topics and isinstance(decoded.value, tuple):
                    mounts.add(message.topic, _transforms(decoded))
            while pending and now - pending[0][1] > tol + self.lookahead_ns:
                yield assemble(pending.popleft()[0], index=index)
                index += 1
            reference = pending[0][0].stamp_ns if pending else last_driver_ns
            _prune(
                (*buffers.values(), objects, lights),
                states,
                reference_ns=reference,
                window_ns=tol + self.lookahead_ns,
            )
        while pending:
            yield assemble(pending.popleft()[0], index=index)
            index += 1

    def ego_states(self, *, stop_ns: int | None = None) -> Iterator[VehicleState]:
        """Every ego state of the log's vehicle-state topic, in log order (log time before
        ``stop_ns``), without assembling frames (the closed loop's route from the logged
        path); none when the sensor map has no such topic."""
        topic = self.sensor_map.vehicle_state_topic
        if topic is None:
            return
        for message in self.log.messages(topics=[topic], stop_ns=stop_ns):
            decoded = self._decode(message)
            if decoded is not None and isinstance(decoded.value, VehicleState):
                yield decoded.value

    def ground_truth(
        self, *, stop_ns: int | None = None
    ) -> Iterator[tuple[int, tuple[DetectedObject, ...]]]:
        """Every ground-truth message of the log as (stamp_ns, objects in base_link of the
        logged ego), in log order (log time before ``stop_ns``), without assembling frames (the
        closed loop's reactive agents read their whole logged tracks first)."""
        topic = self.sensor_map.ground_truth_topic
        if topic is None:
            return
        for message in self.log.messages(topics=[topic], stop_ns=stop_ns):
            decoded = self._decode(message)
            if decoded is not None and isinstance(decoded.value, tuple):
                yield (
                    decoded.stamp_ns,
                    _objects_of(decoded.value),
                )

    def _decode(self, message: LogMessage) -> Decoded | None:
        if decoder_for(message.msgtype) is None and message.encoding != "native":
            return None
        try:
            return decode(message, self.log.deserialize)
        except UnsupportedMessageError as err:
            self._undecodable(message, err)
            return None

    def _other_clock(self, name: str, stamps: Iterable[int], frame_ns: int) -> None:
        """Warn once when ``name`` is missing from a frame because its header stamps follow
        another clock: its nearest sample is more than a minute from the frame's stamp."""
        gap = min((abs(s - frame_ns) for s in stamps), default=None)
        if gap is None or gap <= OTHER_CLOCK_NS or name in self._clock_warned:
            return
        self._clock_warned.add(name)
        days = gap / 86_400e9
        span = f"{days:.1f} days" if days >= 1.0 else f"{gap / 1e9:.0f} s"
        logger.warning(
            "%s: the header stamps of %s lie %s from the frames' (the %s's): they follow another "
            "clock (simulated time, or a clock that was not set), so no frame gets a sample of "
            "it; the frames say it is missing — fix the stamps, or leave it out with a sensor map",
            self.log.path,
            name,
            span,
            self.sensor_map.driver or "ground truth",
        )

    def _undecodable(self, message: LogMessage, err: UnsupportedMessageError) -> None:
        self.undecodable[message.topic] = self.undecodable.get(message.topic, 0) + 1
        if message.topic not in self._warned:
            self._warned.add(message.topic)
            logger.warning("%s (further failures on this topic are counted, not logged)", err)

    def _assemble(
        self,
        driver: _Sample,
        *,
        index: int,
        buffers: dict[str, deque[_Sample]],
        states: deque[VehicleState | PendingState],
        objects: deque[_Sample],
        lights: deque[_Sample],
        mounts: SensorMounts,
    ) -> Frame:
        smap = self.sensor_map
        t = driver.stamp_ns
        sensors: dict[str, SensorData] = {}
        missing: list[str] = []
        for spec in smap.sensors:
            sample = (
                driver
                if spec.sensor_id == smap.driver
                else _nearest(buffers[spec.sensor_id], t, smap.tolerance_for(spec.sensor_id))
            )
            if sample is None:
                missing.append(spec.sensor_id)
                self._other_clock(spec.sensor_id, (b.stamp_ns for b in buffers[spec.sensor_id]), t)
                continue
            value = sample.decoded.value
            location = spec.location
            if location is None:
                location = mounts.location(sample.decoded.frame_id, sample.stamp_ns)
                if location is None and spec.sensor_id not in self._unplaced:
                    self._unplaced.add(spec.sensor_id)
                    logger.info(
                        "%s: no transform from %r to base_link: sensor %s is taken to sit at "
                        "base_link's origin",
                        self.log.path,
                        sample.decoded.frame_id,
                        spec.sensor_id,
                    )
            resolution = (value.width, value.height) if isinstance(value, Image) else None
            try:
                sensors[spec.sensor_id] = SensorData(
                    sensor_id=spec.sensor_id,
                    sensor_type=spec.sensor_type,
                    stamp_ns=sample.stamp_ns,
                    frame_id=sample.decoded.frame_id,
                    frame_rate_hz=spec.rate_hz,
                    resolution=resolution,
                    sensor_location=location or (0.0, 0.0, 0.0),
                    data=value,  # type: ignore[arg-type]
                )
            except ValueError as err:
                logger.debug("sensor %s: %s", spec.sensor_id, err)
        gt_sample = _nearest(objects, t, smap.tolerance_for("ground_truth"))
        ground_truth: tuple[DetectedObject, ...] | None = None
        if gt_sample is not None and isinstance(gt_sample.decoded.value, tuple):
            ground_truth = _objects_of(gt_sample.decoded.value)
        elif smap.ground_truth_topic is not None:
            ground_truth = ()
            missing.append("ground_truth")  # the log has labels, none near this frame
        traffic = TrafficData()
        lights_sample = _nearest(lights, t, smap.tolerance_for("traffic_lights"))
        if lights_sample is not None and isinstance(lights_sample.decoded.value, TrafficData):
            traffic = lights_sample.decoded.value
        elif smap.traffic_lights_topic is not None:
            missing.append("traffic_lights")  # the log has light states, none near this frame
        state = _state_at(states, t, smap.tolerance_for("vehicle_state"))
        if state is None and smap.vehicle_state_topic is not None:
            missing.append("vehicle_state")
            self._other_clock("vehicle_state", (st.stamp_ns for st in states), t)
        return Frame(
            stamp_ns=t,
            index=index,
            sensors=sensors,
            vehicle_state=state,
            traffic=traffic,
            ground_truth=ground_truth,
            missing=tuple(missing),
        )


def _transforms(decoded: Decoded) -> Iterator[Transform]:
    assert isinstance(decoded.value, tuple)
    return (t for t in decoded.value if isinstance(t, Transform))


def _prune(
    buffers: Iterable[deque[_Sample]],
    states: deque[VehicleState | PendingState],
    *,
    reference_ns: int | None,
    window_ns: int,
) -> None:
    """Drop the samples no frame can use any more: those more than ``window_ns`` before the
    oldest waiting driver stamp (or the newest one seen, ``reference_ns``), the newest of each
    kept.  Before any driver sample a buffer keeps the ``window_ns`` before its own newest
    sample (bounded memory; a driver stamp further behind it finds that input missing)."""
    for buf in buffers:
        if not buf:
            continue
        horizon = (buf[-1].stamp_ns if reference_ns is None else reference_ns) - window_ns
        while len(buf) > 1 and buf[0].stamp_ns < horizon:
            buf.popleft()
    if states:
        horizon = (states[-1].stamp_ns if reference_ns is None else reference_ns) - window_ns
        while len(states) > 2 and states[1].stamp_ns < horizon - _STATE_WINDOW_NS:
            states.popleft()


def _nearest(buf: deque[_Sample], stamp_ns: int, tolerance_ns: int) -> _Sample | None:
    best: _Sample | None = None
    best_dt = tolerance_ns + 1
    for sample in buf:
        dt = abs(sample.stamp_ns - stamp_ns)
        if dt < best_dt:
            best, best_dt = sample, dt
    return best


def _state_at(
    states: deque[VehicleState | PendingState], stamp_ns: int, tolerance_ns: int
) -> VehicleState | None:
    before = after = None
    for state in states:
        if state.stamp_ns <= stamp_ns:
            before = state
        elif after is None:
            after = state
    if before is not None and after is not None:
        return interpolate_state(_built(before), _built(after), stamp_ns)
    near = before or after
    if near is not None and abs(near.stamp_ns - stamp_ns) <= tolerance_ns:
        return _built(near)
    return None


def _built(state: VehicleState | PendingState) -> VehicleState:
    return state if isinstance(state, VehicleState) else state.value


def iter_frames(
    log: LogReader,
    *,
    overrides: SensorMapOverrides | None = None,
    start_ns: int | None = None,
    stop_ns: int | None = None,
) -> Iterator[Frame]:
    """Shorthand: ``FrameAssembler(log, overrides=...).frames(start_ns=..., stop_ns=...)``."""
    return FrameAssembler(log, overrides=overrides).frames(start_ns=start_ns, stop_ns=stop_ns)
