"""The synthetic source: the :mod:`redrive.sim` world played, its rig published in real time."""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

from redrive.assembly.sensor_map import sensor_id_for
from redrive.live.sources._common import (
    _PAGE,
    _POLL_S,
    _SENSOR_PAYLOAD,
    DEFAULT_MAX_READERS,
    DEFAULT_SLOTS,
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
from redrive.sim.lidar_presets import lidar_preset
from redrive.sim.rig import Rig, rig_from_mapping
from redrive.sim.scenario import Scenario, load_scenario
from redrive.sim.sinks import SampleSink
from redrive.sim.synth import SensorSimulation, sensor_topic
from redrive.transport import Policy
from redrive.types import SensorData, SensorType, VehicleState

logger = logging.getLogger(__name__)

# Upper bound per simulated LiDAR point: xyz float32 + up to four channels of 8 bytes.
_POINT_BOUND_BYTES = 48


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


class _SampleBuffer(SampleSink):
    """A :class:`~redrive.sim.sinks.MessageSink` that keeps the samples of the rig's streams
    (LaserScans decoded as a replay would) and drops the rest (ground truth, transforms)."""

    def __init__(self, routes: Mapping[str, _Route]) -> None:
        self.routes = routes
        self.pending: list[tuple[str, SensorData]] = []

    def keeps(self, topic: str) -> bool:
        return topic in self.routes

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
