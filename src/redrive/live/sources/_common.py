"""What both sources share: stream specs and routes, the pacing clock, the writers, ``stop``."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass
from types import TracebackType
from typing import Protocol

from redrive.errors import ConfigError, TransportError
from redrive.live.streams import PAYLOAD_MSGTYPE, StreamSpec, ring_slots, stream_name
from redrive.transport import Policy, ReaderGoneError, Writer
from redrive.transport.codec import encoded_size
from redrive.types import GnssFix, Image, Imu, PointCloud, SensorData, SensorType, VehicleState

logger = logging.getLogger(__name__)

#: A sample published later than this after it was due counts as late.
LATE_AFTER_NS = 10_000_000
#: Defaults for every writer: slots in its ring, reader processes it accepts.
DEFAULT_SLOTS = 8
DEFAULT_MAX_READERS = 3

_PAGE = 4096
_POLL_S = 0.05
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
                    slots=ring_slots(route.spec.capacity_bytes, slots),
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
