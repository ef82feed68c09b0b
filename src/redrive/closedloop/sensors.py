"""Sensor-level closed loop on the synthetic backend: the scenario's rig rendered from the driven ego.

The rendering is :class:`redrive.sim.synth.SensorSimulation` — the events, sensor models and
random streams ``redrive synth`` records with — run one frame at a time over a
:class:`LockstepWorlds` view: the *scene* (agents, scenery, lights) of one world, the *ego* (its
pose for every sensor, the LiDARs' ego-motion skew, IMU, GNSS) of the closed-loop world.  The
messages go to a :class:`FrameSensors` sink that keeps the latest sample of each sensor as the
Frame Assembler would read it back from a log: the same sensor ids (the log's topic names), types,
frame ids, header stamps; the 2D LiDAR's LaserScan decoded as a replay decodes it.

Timing: a frame at time ``t`` holds the sensors' latest samples — the camera image, IMU and GNSS
of ``t``, and each LiDAR's last *finished* sweep, stamped at its start (``t − 1/rate``): a sweep
needs the ego's motion over its whole period, and that motion depends on the commands of the
frame.  The first frame is therefore one (slowest) LiDAR period after the scenario's start.

A :class:`SensorTee` hands every message to more than one sink: the run's ``sensors.mcap``
(a :class:`~redrive.io.mcap.writer.McapWriter`) records what the algorithms saw, through a
:class:`RecordingThread` that serialises and compresses on its own thread (zstd releases the
GIL), off the frame loop.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Mapping
from functools import partial

import numpy as np
import numpy.typing as npt
from rosbags.typesys.store import Typestore

from redrive.assembly.sensor_map import infer_sensor_map
from redrive.errors import SimulationError
from redrive.io.base import TopicInfo
from redrive.io.mcap.writer import McapWriter
from redrive.io.ros.decoders.base import Decoded
from redrive.sim.rig import Rig, SensorSpec
from redrive.sim.scene import Scene
from redrive.sim.sinks import MessageSink, SampleSink
from redrive.sim.synth import sensor_topic
from redrive.sim.world import World
from redrive.types import Image, SensorData, SensorType, VehicleState

__all__ = ["FrameSensors", "LockstepWorlds", "RecordingThread", "SensorTee", "warmup_ns"]

#: The message each kind of rig sensor is recorded as (``redrive synth``), for the sensor map.
_MSGTYPES: Mapping[SensorType, str] = {
    SensorType.LIDAR: "sensor_msgs/msg/PointCloud2",
    SensorType.LIDAR_2D: "sensor_msgs/msg/LaserScan",
    SensorType.CAMERA: "sensor_msgs/msg/Image",
    SensorType.IMU: "sensor_msgs/msg/Imu",
    SensorType.GNSS: "sensor_msgs/msg/NavSatFix",
    SensorType.ODOMETRY: "nav_msgs/msg/Odometry",
}


def warmup_ns(rig: Rig) -> int:
    """How long after the start the first frame comes: the longest LiDAR period (every sensor
    then has a sample); 0 without a LiDAR."""
    periods = [
        round(1e9 / s.rate_hz) for s in rig if s.kind in (SensorType.LIDAR, SensorType.LIDAR_2D)
    ]
    return max(periods, default=0)


class LockstepWorlds:
    """The :class:`~redrive.sim.sinks.SensorWorld` of a closed loop: the scene of
    ``scene_world`` seen from the ego of ``ego_world``; stepping steps every world of
    ``worlds`` (which holds both), so they stay in lockstep.

    :attr:`step_s` adds up the wall time spent stepping the worlds, in seconds (the rest of a
    :meth:`SensorSimulation.advance_to <redrive.sim.synth.SensorSimulation.advance_to>` is
    rendering)."""

    def __init__(self, *, scene_world: World, ego_world: World, worlds: tuple[World, ...]) -> None:
        if scene_world not in worlds or ego_world not in worlds:
            msg = "LockstepWorlds: scene_world and ego_world must be among worlds"
            raise ValueError(msg)
        self.scene_world, self.ego_world, self.worlds = scene_world, ego_world, worlds
        self.step_s = 0.0

    @property
    def time_ns(self) -> int:
        return self.ego_world.time_ns

    def step_to(self, stamp_ns: int) -> None:
        t0 = time.perf_counter()
        for world in self.worlds:
            world.step_to(stamp_ns)
        self.step_s += time.perf_counter() - t0

    def scene(self) -> Scene:
        scene = self.scene_world.scene()
        if self.scene_world is self.ego_world:
            return scene
        return Scene(
            stamp_ns=scene.stamp_ns,
            ground=scene.ground,
            objects=scene.objects,
            looks=scene.looks,
            traffic_lights=scene.traffic_lights,
            map_from_base=self.ego_world.map_from_base(),
        )

    def ego_state(self) -> VehicleState:
        return self.ego_world.ego_state()

    def map_from_base(self) -> npt.NDArray[np.float64]:
        return self.ego_world.map_from_base()

    def map_from_base_at(self, stamp_ns: int) -> npt.NDArray[np.float64]:
        return self.ego_world.map_from_base_at(stamp_ns)


class FrameSensors(SampleSink):
    """A :class:`~redrive.sim.sinks.MessageSink` that keeps each rig sensor's latest sample as a
    :class:`~redrive.types.SensorData` (what a replay of the recorded log would put in a frame).

    Sensor ids and types come from the log's own rule
    (:func:`~redrive.assembly.sensor_map.infer_sensor_map` on the topics ``redrive synth`` writes):
    ``lidar_top``, ``camera_front_image_raw``, …; wheel odometry is ego motion there, not a
    sensor.  The rate is
    the rig's; the location the sensor's mount in base_link.
    """

    def __init__(self, rig: Rig) -> None:
        topics = {
            sensor_topic(s): TopicInfo(
                topic=sensor_topic(s), msgtype=_MSGTYPES[s.kind], count=0, encoding="cdr"
            )
            for s in rig
        }
        smap = infer_sensor_map(topics, duration_ns=0)
        by_topic = {sensor_topic(s): s for s in rig}
        #: topic → (sensor id, type, rig sensor)
        self._routes: dict[str, tuple[str, SensorType, SensorSpec]] = {
            m.topic: (m.sensor_id, m.sensor_type, by_topic[m.topic]) for m in smap.sensors
        }
        self.sensors: Mapping[str, SensorType] = {
            sid: stype for sid, stype, _ in self._routes.values()
        }
        self._latest: dict[str, Decoded] = {}

    def keeps(self, topic: str) -> bool:
        return topic in self._routes  # not ground truth, transforms, the ego pose, camera info

    def write(
        self,
        topic: str,
        log_time_ns: int,
        value: object,
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> None:
        if topic not in self._routes:
            return  # ground truth, transforms, the true ego pose, camera info: not sensors
        self._latest[topic] = Decoded(
            stamp_ns=log_time_ns if stamp_ns is None else stamp_ns,
            frame_id=frame_id or "",
            value=value,  # type: ignore[arg-type]  # a sensor payload: the rig's kinds only
        )

    def sensor_data(self) -> dict[str, SensorData]:
        """Every sensor's latest sample (sensors without one yet are left out)."""
        out: dict[str, SensorData] = {}
        for topic, (sensor_id, sensor_type, spec) in self._routes.items():
            decoded = self._latest.get(topic)
            if decoded is None:
                continue
            value = decoded.value
            x, y, z = spec.xyz_m
            out[sensor_id] = SensorData(
                sensor_id=sensor_id,
                sensor_type=sensor_type,
                stamp_ns=decoded.stamp_ns,
                frame_id=decoded.frame_id,
                frame_rate_hz=spec.rate_hz,
                resolution=(value.width, value.height) if isinstance(value, Image) else None,
                sensor_location=(x, y, z),
                data=value,  # type: ignore[arg-type]
            )
        return dict(sorted(out.items()))


class SensorTee:
    """A :class:`~redrive.sim.sinks.MessageSink` that hands every message to each of ``sinks``,
    in order (a closed loop's :class:`FrameSensors`, and the recording of the run).

    Raw messages are serialised with the first sink's :attr:`typestore` (ROS 2 CDR of the
    standard types is the same bytes whichever store made it)."""

    def __init__(self, first: MessageSink, *rest: MessageSink) -> None:
        self.sinks: tuple[MessageSink, ...] = (first, *rest)

    @property
    def typestore(self) -> Typestore:
        return self.sinks[0].typestore

    def write(
        self,
        topic: str,
        log_time_ns: int,
        value: object,
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> None:
        for sink in self.sinks:
            sink.write(topic, log_time_ns, value, frame_id=frame_id, stamp_ns=stamp_ns)

    def write_raw(
        self, topic: str, msgtype: str, log_time_ns: int, cdr_bytes: bytes | memoryview
    ) -> None:
        for sink in self.sinks:
            sink.write_raw(topic, msgtype, log_time_ns, cdr_bytes)


class RecordingThread:
    """A :class:`~redrive.sim.sinks.MessageSink` that hands every message to ``writer`` on a
    thread of its own, in the order they came: the file is the one writing them in place would
    give, while serialising and compressing (zstd of the LiDAR sweeps is the costly part) run
    beside the frame loop.

    At most ``max_pending`` messages wait (the frame loop blocks beyond).  An error of the writer
    is raised by the next :meth:`write` / :meth:`write_raw` or by :meth:`stop`; the messages after
    it are dropped.
    """

    def __init__(self, writer: McapWriter, *, max_pending: int = 256) -> None:
        self.writer = writer
        self._queue: queue.Queue[Callable[[], None] | None] = queue.Queue(max_pending)
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._drain, name="sensors-mcap", daemon=True)
        self._thread.start()

    @property
    def typestore(self) -> Typestore:
        return self.writer.typestore

    def write(
        self,
        topic: str,
        log_time_ns: int,
        value: object,
        *,
        frame_id: str | None = None,
        stamp_ns: int | None = None,
    ) -> None:
        self._put(
            partial(
                self.writer.write, topic, log_time_ns, value, frame_id=frame_id, stamp_ns=stamp_ns
            )
        )

    def write_raw(
        self, topic: str, msgtype: str, log_time_ns: int, cdr_bytes: bytes | memoryview
    ) -> None:
        self._put(partial(self.writer.write_raw, topic, msgtype, log_time_ns, bytes(cdr_bytes)))

    def stop(self) -> None:
        """Wait until every message is with the writer (it stays open).

        Raises:
            the writer's error, if it had one.
        """
        if self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        self._raise()

    def _put(self, call: Callable[[], None]) -> None:
        self._raise()
        if not self._thread.is_alive():
            msg = f"{self.writer.path}: the recording was stopped; no more messages"
            raise SimulationError(msg)
        self._queue.put(call)

    def _raise(self) -> None:
        if self._error is not None:
            raise self._error

    def _drain(self) -> None:
        while (call := self._queue.get()) is not None:
            if self._error is not None:
                continue
            try:
                call()
            except BaseException as err:  # handed to the frame loop's thread
                self._error = err
