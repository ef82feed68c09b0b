"""A scenario → an MCAP log: the world stepped in time, every rig sensor fired at its rate.

What the log holds (ROS 2 CDR, standard types, schemas embedded; frames REP-105):

================================  ===========================================  ====================
topic                             type                                         what
================================  ===========================================  ====================
``/<lidar>``                      ``sensor_msgs/msg/PointCloud2``              one sweep per
                                                                               message, stamped at
                                                                               its start; channels
                                                                               intensity, ring,
                                                                               t_offset_ns
``/<lidar_2d>``                   ``sensor_msgs/msg/LaserScan``                one scan
``/<camera>/image_raw``           ``sensor_msgs/msg/Image``                    rgb8
``/<camera>/camera_info``         ``sensor_msgs/msg/CameraInfo``               the true intrinsics,
                                                                               with each image
                                                                               (same stamp, optical
                                                                               frame)
``/<imu>``                        ``sensor_msgs/msg/Imu``                      specific force,
                                                                               rate, orientation
``/<gnss>``                       ``sensor_msgs/msg/NavSatFix``                map = ENU at the
                                                                               reference
``/<odometry>``                   ``nav_msgs/msg/Odometry``                    wheel odometry
                                                                               (noisy, ``odom``)
``/ground_truth/ego_state``       ``nav_msgs/msg/Odometry``                    the true ego state
                                                                               (``map``), at twice
                                                                               the odometry rate
``/ground_truth/objects``         ``redrive_msgs/msg/GroundTruthObjectArray``  every object within
                                                                               range, in
                                                                               ``base_link``, at
                                                                               each sweep of the
                                                                               first LiDAR
``/ground_truth/traffic_lights``  ``redrive_msgs/msg/TrafficLightStateArray``  every signal's state
                                                                               (ids = the road
                                                                               map's ``light_id``),
                                                                               with each objects
                                                                               message (scenarios
                                                                               with lights)
``/tf``                           ``tf2_msgs/msg/TFMessage``                   map→odom→base_link
                                                                               (REP-105), with the
                                                                               ground-truth pose
``/tf_static``                    ``tf2_msgs/msg/TFMessage``                   base_link→sensors
                                                                               (latched: transient
                                                                               local QoS)
================================  ===========================================  ====================

Determinism: one :class:`numpy.random.SeedSequence` of the scenario seed is split into one
generator per sensor, the world has its own, and nothing reads the clock, so the same scenario and
seed give a byte-identical file.
"""

from __future__ import annotations

import dataclasses
import heapq
import math
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import SimulationError
from redrive.geometry import invert
from redrive.geometry.se3 import (
    quaternion_from_rotation_matrix,
)
from redrive.io.content import LogScenario
from redrive.io.mcap.metadata import (
    MAP_METADATA,
    SCENARIO_METADATA,
    road_map_record,
    scenario_record,
)
from redrive.io.mcap.writer import McapWriter
from redrive.sim.camera import CameraFrame, CameraModel
from redrive.sim.ground_truth import ground_truth_objects
from redrive.sim.inertial import GnssModel, ImuModel, OdometryModel
from redrive.sim.lidar import LidarModel, LidarScan
from redrive.sim.lights import traffic_data_of
from redrive.sim.rig import Rig, SensorSpec, rig_from_mapping
from redrive.sim.roadmap import scenario_road_map
from redrive.sim.scenario import Scenario
from redrive.sim.scene import Scene
from redrive.sim.sinks import MessageSink, SensorWorld
from redrive.sim.world import World
from redrive.types import SensorType, Transform, VehicleState

__all__ = [
    "EGO_STATE_TOPIC",
    "GROUND_TRUTH_TOPIC",
    "TRAFFIC_LIGHTS_TOPIC",
    "MessageSink",
    "SensorSimulation",
    "SensorWorld",
    "SynthSummary",
    "camera_info_topic",
    "ground_truth_objects",
    "sensor_topic",
    "synthesize",
]

GROUND_TRUTH_TOPIC = "/ground_truth/objects"
TRAFFIC_LIGHTS_TOPIC = "/ground_truth/traffic_lights"
EGO_STATE_TOPIC = "/ground_truth/ego_state"


@dataclass(frozen=True, slots=True, kw_only=True)
class SynthSummary:
    """What :func:`synthesize` wrote."""

    path: Path
    scenario: str
    seed: int
    duration_s: float
    messages: int
    topics: dict[str, str]  # topic → message type


def sensor_topic(spec: SensorSpec) -> str:
    """The topic a rig sensor's messages go on: ``/<name>``, a camera's ``/<name>/image_raw``."""
    return f"/{spec.name}/image_raw" if spec.kind is SensorType.CAMERA else f"/{spec.name}"


def camera_info_topic(spec: SensorSpec) -> str:
    """The topic of a camera's intrinsics, next to its images: ``/<name>/camera_info``."""
    return f"/{spec.name}/camera_info"


def _transform(
    parent: str, child: str, matrix: npt.NDArray[np.float64], stamp_ns: int
) -> Transform:
    return Transform(
        parent_frame=parent,
        child_frame=child,
        translation=matrix[:3, 3],
        rotation=quaternion_from_rotation_matrix(matrix[:3, :3]),
        stamp_ns=stamp_ns,
    )


def _ticks(start_ns: int, stop_ns: int, rate_hz: float) -> Iterator[int]:
    period_ns = round(1e9 / rate_hz)
    k = 0
    while (t := start_ns + k * period_ns) < stop_ns:
        yield t
        k += 1


class _Recorder:
    """Owns the models and the writer; turns sensor events into messages."""

    def __init__(
        self, scenario: Scenario, rig: Rig, writer: MessageSink, world: SensorWorld
    ) -> None:
        self.writer = writer
        self.world = world
        self.rig = rig
        seeds = np.random.SeedSequence(scenario.seed).spawn(len(rig))
        self.rngs = {
            spec.name: np.random.default_rng(s) for spec, s in zip(rig, seeds, strict=True)
        }
        self.lidars = {
            s.name: LidarModel.from_spec(s)
            for s in rig
            if s.kind in (SensorType.LIDAR, SensorType.LIDAR_2D)
        }
        self.cameras = {s.name: CameraModel.from_spec(s) for s in rig.of_kind(SensorType.CAMERA)}
        self.camera_infos = {name: c.intrinsics.camera_info() for name, c in self.cameras.items()}
        self.imus = {s.name: ImuModel.from_spec(s) for s in rig.of_kind(SensorType.IMU)}
        self.gnss = {s.name: GnssModel.from_spec(s) for s in rig.of_kind(SensorType.GNSS)}
        self.odometry = {
            s.name: OdometryModel.from_spec(s) for s in rig.of_kind(SensorType.ODOMETRY)
        }
        lidars3d = rig.of_kind(SensorType.LIDAR)
        self.driver = lidars3d[0].name if lidars3d else None
        self.pending: dict[str, Scene] = {}  # lidar → scene at the start of its sweep
        self.last_camera: dict[str, CameraFrame] = {}
        #: object id → returns in the driver LiDAR's last finished sweep (None before the first)
        self.last_hits: dict[int, int] | None = None
        self.prev_state: VehicleState | None = None
        self._scene_now: Scene | None = None
        #: camera → (stamp, its image being drawn on :attr:`_drawing`), see :meth:`draw_ahead`
        self._drawn: dict[str, tuple[int, Future[CameraFrame]]] = {}
        self._drawing: ThreadPoolExecutor | None = None

    # -- static ---------------------------------------------------------------------------------

    def write_static(self, stamp_ns: int) -> None:
        """``/tf_static``: where every mounted sensor sits on ``base_link`` (and each camera's
        optical frame).  Odometry is not mounted: ``odom`` is the frame its poses are in, a
        parent of ``base_link`` in ``/tf`` (REP-105), never a child."""
        transforms = []
        for spec in self.rig:
            if spec.kind is SensorType.ODOMETRY:
                continue
            transforms.append(_transform("base_link", spec.name, spec.base_from_sensor(), 0))
            if spec.kind is SensorType.CAMERA:
                optical = spec.base_from_optical()
                transforms.append(
                    _transform("base_link", self.cameras[spec.name].frame_id, optical, 0)
                )
        self.writer.write("/tf_static", stamp_ns, tuple(transforms))

    # -- per event ------------------------------------------------------------------------------

    def fire(self, spec: SensorSpec, stamp_ns: int) -> None:
        kind = spec.kind
        rng = self.rngs[spec.name]
        if kind in (SensorType.LIDAR, SensorType.LIDAR_2D):
            self.pending[spec.name] = self._scene()
        elif kind is SensorType.CAMERA:
            camera = self.cameras[spec.name]
            ahead = self._drawn.pop(spec.name, None)
            if ahead is not None and ahead[0] == stamp_ns:
                frame = ahead[1].result()
            else:
                frame = camera.render(self._scene())
            self.last_camera[spec.name] = frame
            self.writer.write(sensor_topic(spec), stamp_ns, frame.image, frame_id=camera.frame_id)
            self.writer.write(
                camera_info_topic(spec),
                stamp_ns,
                self.camera_infos[spec.name],
                frame_id=camera.frame_id,
            )
        elif kind is SensorType.IMU:
            state = self.world.ego_state()
            yaw_accel = self._yaw_accel(state)
            imu = self.imus[spec.name].sample(state, rng, yaw_accel_rad_s2=yaw_accel)
            self.writer.write(sensor_topic(spec), stamp_ns, imu, frame_id=spec.name)
        elif kind is SensorType.GNSS:
            fix = self.gnss[spec.name].fix(self.world.ego_state(), rng)
            self.writer.write(sensor_topic(spec), stamp_ns, fix, frame_id=spec.name)
        elif kind is SensorType.ODOMETRY:
            odom = self.odometry[spec.name].measure(self.world.ego_state(), rng)
            self.writer.write(sensor_topic(spec), stamp_ns, odom)
        else:  # pragma: no cover - the rig parser admits no other kind
            msg = f"sensor {spec.name!r}: kind {kind.value} cannot be simulated"
            raise SimulationError(msg)

    def draw_ahead(self, names: list[str], stamp_ns: int) -> None:
        """Start drawing the images the cameras ``names`` take at ``stamp_ns`` (the world's
        time now) on a thread, so that they are drawn while the LiDAR sweeps that end at the
        same instant are cast; :meth:`fire` then takes them.  The image is the same."""
        if self._drawing is None:
            self._drawing = ThreadPoolExecutor(1, thread_name_prefix="camera-ahead")
        scene = self._scene()
        for name in names:
            self._drawn[name] = (stamp_ns, self._drawing.submit(self.cameras[name].render, scene))

    def _scene(self) -> Scene:
        """The world's scene at its current time, built once per instant (LiDARs and cameras
        firing together share it)."""
        if self._scene_now is None or self._scene_now.stamp_ns != self.world.time_ns:
            self._scene_now = self.world.scene()
        return self._scene_now

    def finish_sweep(self, spec: SensorSpec) -> None:
        """Cast a sweep whose period has elapsed (the pose history now covers all of it)."""
        scene = self.pending.pop(spec.name)
        model = self.lidars[spec.name]
        scan = model.scan(scene, self.rngs[spec.name], map_from_base_at=self.world.map_from_base_at)
        if spec.kind is SensorType.LIDAR_2D:
            self._write_laser_scan(spec, model, scan)
            return
        self.writer.write(sensor_topic(spec), scan.stamp_ns, scan.cloud, frame_id=scan.frame_id)
        if spec.name == self.driver:
            self.last_hits = dict(scan.hits_per_object)
            objects = ground_truth_objects(
                scene, lidar_hits=self.last_hits, camera_pixels=self.camera_pixels()
            )
            self.writer.write(GROUND_TRUTH_TOPIC, scan.stamp_ns, objects, frame_id="base_link")
            if scene.traffic_lights:  # the signals' states at the sweep's start, as its objects
                lights = traffic_data_of(scene.traffic_lights)
                self.writer.write(TRAFFIC_LIGHTS_TOPIC, scan.stamp_ns, lights, frame_id="map")

    def camera_pixels(self) -> dict[int, int] | None:
        """Object id → pixels it covers in the last image of every camera (None before any)."""
        if not self.last_camera:
            return None
        seen: dict[int, int] = {}
        for frame in self.last_camera.values():
            for key, count in frame.pixels_per_object.items():
                seen[key] = seen.get(key, 0) + count
        return seen

    def write_pose(self, stamp_ns: int) -> None:
        """The true ego state, and ``/tf`` as REP-105 has it: ``map → odom → base_link``.

        ``odom → base_link`` is the wheel odometry's dead-reckoned pose (its last reading; the
        true pose while there is none, ``odom`` = ``map`` at the start), ``map → odom`` the
        correction that puts ``base_link`` at its true pose — what a localizer publishes.
        Composed, they give ``map → base_link`` exactly."""
        state = self.world.ego_state()
        self.writer.write(EGO_STATE_TOPIC, stamp_ns, state)
        map_from_base = self.world.map_from_base()
        odom_from_base = next(
            (m for o in self.odometry.values() if (m := o.odom_from_base()) is not None),
            map_from_base,
        )
        map_from_odom = map_from_base @ invert(odom_from_base)
        self.writer.write(
            "/tf",
            stamp_ns,
            (
                _transform("map", "odom", map_from_odom, stamp_ns),
                _transform("odom", "base_link", odom_from_base, stamp_ns),
            ),
        )
        self.prev_state = state

    def _yaw_accel(self, state: VehicleState) -> float:
        prev = self.prev_state
        if prev is None or state.stamp_ns <= prev.stamp_ns:
            return 0.0
        return (state.yaw_rate_rad_s - prev.yaw_rate_rad_s) / (
            (state.stamp_ns - prev.stamp_ns) * 1e-9
        )

    def _write_laser_scan(self, spec: SensorSpec, model: LidarModel, scan: LidarScan) -> None:
        preset = model.preset
        inc = math.radians(preset.azimuth_resolution_deg)
        angle_min = -math.radians(preset.fov_deg) / 2.0
        ranges = np.full(preset.columns, np.inf, dtype=np.float32)
        intensities = np.zeros(preset.columns, dtype=np.float32)
        xyz = scan.cloud.xyz.astype(np.float64)
        if len(xyz):
            angles = np.arctan2(xyz[:, 1], xyz[:, 0])
            col = np.clip(
                np.round((angles - angle_min) / inc).astype(np.int64), 0, preset.columns - 1
            )
            ranges[col] = np.hypot(xyz[:, 0], xyz[:, 1]).astype(np.float32)
            intensities[col] = np.asarray(scan.cloud.channels["intensity"], dtype=np.float32)
        ts = self.writer.typestore
        sec, nanosec = divmod(scan.stamp_ns, 1_000_000_000)
        header = ts.types["std_msgs/msg/Header"](
            stamp=ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
            frame_id=scan.frame_id,
        )
        msg = ts.types["sensor_msgs/msg/LaserScan"](
            header=header,
            angle_min=angle_min,
            angle_max=angle_min + inc * (preset.columns - 1),
            angle_increment=inc,
            time_increment=(1.0 / model.rate_hz) * (inc / math.tau),
            scan_time=1.0 / model.rate_hz,
            range_min=preset.min_range_m,
            range_max=preset.max_range_m,
            ranges=ranges,
            intensities=intensities,
        )
        msgtype = "sensor_msgs/msg/LaserScan"
        self.writer.write_raw(
            sensor_topic(spec), msgtype, scan.stamp_ns, ts.serialize_cdr(msg, msgtype)
        )


class SensorSimulation:
    """One scenario's world and sensor rig, stepped event by event (what :func:`synthesize` runs).

    Building it parses the rig, builds the :class:`~redrive.sim.world.World` and schedules every
    event; :meth:`run` then steps the world through them in time order, handing each message to a
    :class:`MessageSink`.  Events: every sensor fires at its rate; a LiDAR's sweep is cast one
    period after it starts (when the pose history covers it) and stamped at its start; the
    ground-truth ego pose and ``/tf`` run at twice the odometry rate.

    :meth:`run` is :meth:`start` then :meth:`advance_to` the end; a closed loop calls
    :meth:`advance_to` one frame at a time instead, rendering from its own ``world`` (the same
    events, random streams and models, so its sensors are what ``redrive synth`` would record of
    the same motion).

    Args:
        scenario: what to simulate.
        duration_s: override the scenario's duration.
        seed: override the scenario's seed.
        world: what the sensors render, at the scenario's start time (default: a new
            :class:`~redrive.sim.world.World` of the scenario, after the overrides).

    Raises:
        ConfigError: the scenario's rig is invalid.
        SimulationError: the scenario cannot be simulated.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        duration_s: float | None = None,
        seed: int | None = None,
        world: SensorWorld | None = None,
    ) -> None:
        changes: dict[str, Any] = {}
        if duration_s is not None:
            if not duration_s > 0:
                msg = f"duration must be > 0 s, got {duration_s}"
                raise SimulationError(msg)
            changes["duration_s"] = float(duration_s)
        if seed is not None:
            changes["seed"] = int(seed)
        self.scenario = dataclasses.replace(scenario, **changes) if changes else scenario
        self.rig = rig_from_mapping(self.scenario.rig, source=self.scenario.source)
        self.world: SensorWorld = World(self.scenario) if world is None else world
        self.start_ns = self.world.time_ns
        self.stop_ns = self.start_ns + round(self.scenario.duration_s * 1e9)
        self._events = self._schedule()
        #: time → the cameras firing then, where a LiDAR sweep ends too (drawn while it is cast)
        self._cameras_at_sweeps: dict[int, list[str]] = {}
        sweeps = {t for t, _, what, _ in self._events if what == "sweep"}
        for t, _, what, name in sorted(self._events):
            if what == "fire" and t in sweeps and self.rig[name].kind is SensorType.CAMERA:
                self._cameras_at_sweeps.setdefault(t, []).append(name)
        self._recorder: _Recorder | None = None

    def _schedule(self) -> list[tuple[int, int, str, str]]:
        rig, start_ns, stop_ns = self.rig, self.start_ns, self.stop_ns
        odom_rates = [s.rate_hz for s in rig.of_kind(SensorType.ODOMETRY)]
        pose_rate_hz = 2.0 * max(odom_rates, default=50.0)
        # Events: (time, order, kind, sensor).  A LiDAR fires at the start of each sweep and is
        # cast one period later, when the pose history covers the whole sweep.
        events: list[tuple[int, int, str, str]] = []
        for order, spec in enumerate(rig):
            for t in _ticks(start_ns, stop_ns, spec.rate_hz):
                events.append((t, order, "fire", spec.name))
                if spec.kind in (SensorType.LIDAR, SensorType.LIDAR_2D):
                    end = t + round(1e9 / spec.rate_hz)
                    if end <= stop_ns:
                        events.append((end, -1, "sweep", spec.name))
        events += [(t, -2, "pose", "") for t in _ticks(start_ns, stop_ns, pose_rate_hz)]
        heapq.heapify(events)
        return events

    def run(self, sink: MessageSink) -> Iterator[int]:
        """Write the static transforms, then step through the events in time order, writing
        their messages to ``sink``; yields each event's time once its messages are written.

        Raises:
            SimulationError: called a second time (the world has moved on).
        """
        self.start(sink)
        yield from self.advance_to(self.stop_ns)

    def start(self, sink: MessageSink) -> None:
        """Write the static transforms to ``sink``, which gets every later message too.

        Raises:
            SimulationError: called a second time (the world has moved on).
        """
        if self._recorder is not None:
            msg = "this SensorSimulation has already run; build a new one to run it again"
            raise SimulationError(msg)
        self._recorder = _Recorder(self.scenario, self.rig, sink, self.world)
        self._recorder.write_static(self.start_ns)

    def advance_to(self, stamp_ns: int) -> Iterator[int]:
        """Step through the events up to and including ``stamp_ns`` (writing their messages),
        then the world to ``stamp_ns``; yields each event's time once its messages are written.

        Raises:
            SimulationError: :meth:`start` was not called.
        """
        recorder = self._recorder
        if recorder is None:
            msg = "SensorSimulation.advance_to: call start(sink) first"
            raise SimulationError(msg)
        rig, world, events = self.rig, self.world, self._events
        while events and events[0][0] <= stamp_ns:
            event_ns, _, what, name = heapq.heappop(events)
            world.step_to(event_ns)
            if what == "pose":
                recorder.write_pose(event_ns)
            elif what == "sweep":
                cameras = self._cameras_at_sweeps.pop(event_ns, None)
                if cameras:
                    recorder.draw_ahead(cameras, event_ns)
                recorder.finish_sweep(rig[name])
            else:
                spec = rig[name]
                if what == "fire" and not (
                    spec.kind in (SensorType.LIDAR, SensorType.LIDAR_2D)
                    and event_ns + round(1e9 / spec.rate_hz) > self.stop_ns
                ):
                    recorder.fire(spec, event_ns)
            yield event_ns
        world.step_to(max(stamp_ns, world.time_ns))

    def visibility(self) -> tuple[dict[int, int] | None, dict[int, int] | None]:
        """What the sensors saw so far, for ground truth: object id → returns in the first
        LiDAR's last finished sweep, and → pixels in every camera's last image (None before
        the first sweep / image)."""
        recorder = self._recorder
        if recorder is None:
            return None, None
        return recorder.last_hits, recorder.camera_pixels()


def synthesize(
    scenario: Scenario,
    output: str | Path,
    *,
    duration_s: float | None = None,
    seed: int | None = None,
    progress: Callable[[float, float], None] | None = None,
) -> SynthSummary:
    """Simulate ``scenario`` and write it to the MCAP file ``output`` (atomically).

    Args:
        duration_s: override the scenario's duration.
        seed: override the scenario's seed.
        progress: called as ``progress(simulated_s, total_s)`` while it runs.

    Raises:
        ConfigError: the scenario's rig is invalid.
        SimulationError: the scenario cannot be simulated.
        LogError: the output cannot be written.
    """
    sim = SensorSimulation(scenario, duration_s=duration_s, seed=seed)
    scenario = sim.scenario
    path = Path(output)
    with McapWriter(path) as writer:
        # the road map travels with the log: a replay stores it in the run (the map metrics)
        writer.add_metadata(MAP_METADATA, road_map_record(scenario_road_map(scenario)))
        # and so does what it was made from: `redrive compare` pairs a replay of the log with a
        # closed-loop run of the same scenario, seed and duration
        made_from = LogScenario(
            name=scenario.name, seed=scenario.seed, duration_s=scenario.duration_s
        )
        writer.add_metadata(SCENARIO_METADATA, scenario_record(made_from))
        total_s = scenario.duration_s
        for stamp_ns in sim.run(writer):
            if progress is not None:
                progress((stamp_ns - sim.start_ns) / 1e9, total_s)
        messages = writer.message_count
        topics = dict(writer.topics)
    return SynthSummary(
        path=path,
        scenario=scenario.name,
        seed=scenario.seed,
        duration_s=scenario.duration_s,
        messages=messages,
        topics=topics,
    )
