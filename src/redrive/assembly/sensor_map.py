"""Which topic is which sensor: inferred from message types, overridable by a small TOML file.

A sensor map file (all keys optional)::

    driver = "lidar_top"            # the sensor whose samples make the frames, or
                                    # "ground_truth": every ground-truth message makes one (an
                                    # Argoverse 2 log whose sweeps are not all there)
    tolerance_ms = 50               # how far any input's sample may be from a frame (default:
                                    # 50, or half the period of an input slower than ~8 Hz)
    vehicle_state = "/odom"         # ego motion topic (Odometry, PoseStamped, TwistStamped)
    ground_truth = "/carla/objects" # objects topic used as ground truth
    traffic_lights = "/lights"      # traffic-light states topic (Frame.traffic)
    ignore = ["/rosout"]            # topics never mapped

    [sensors.lidar_top]
    topic = "/velodyne_points"
    type = "lidar"                  # lidar, lidar_2d, camera, radar, imu, gnss (default: inferred)
    location = [1.2, 0.0, 1.8]      # metres in base_link, when the log has no tf for it
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from redrive.config.validate import Table, read_toml
from redrive.errors import ConfigError
from redrive.io.base import TopicInfo
from redrive.io.ros.decoders import topic_kind
from redrive.io.ros.decoders.base import DecodedKind
from redrive.types import SensorType

__all__ = ["SensorMap", "SensorSpec", "infer_sensor_map", "load_sensor_map_overrides"]

_DEFAULT_TOLERANCE_NS = 50_000_000
#: the ``driver`` of a sensor map file that makes a frame of every ground-truth message
GROUND_TRUTH_DRIVER = "ground_truth"
_DRIVER_PREFERENCE = (SensorType.LIDAR, SensorType.CAMERA, SensorType.LIDAR_2D, SensorType.RADAR)


@dataclass(frozen=True, slots=True, kw_only=True)
class SensorSpec:
    """One sensor of the log.

    Attributes:
        sensor_id: its name in frames (``Frame.sensors`` key).
        topic: the topic its samples come on.
        sensor_type: what it is.
        rate_hz: messages per second over the log (0.0 when it cannot be told).
        location: (x, y, z) metres in base_link when given by the user, else None.
    """

    sensor_id: str
    topic: str
    sensor_type: SensorType
    rate_hz: float = 0.0
    location: tuple[float, float, float] | None = None


@dataclass(frozen=True, slots=True, kw_only=True)
class SensorMap:
    """How a log's topics feed frames."""

    sensors: tuple[SensorSpec, ...] = ()
    driver: str | None = None
    tolerance_ns: int = _DEFAULT_TOLERANCE_NS
    vehicle_state_topic: str | None = None
    ground_truth_topic: str | None = None
    #: the traffic-light states (``Frame.traffic``), None when the log has none
    traffic_lights_topic: str | None = None
    tf_topics: tuple[str, ...] = ()
    #: per input (sensor id, ``vehicle_state``, ``ground_truth``, ``traffic_lights``): how far its sample may be from
    #: a frame's stamp; inputs not listed use ``tolerance_ns``.  Inferred from each input's rate
    #: over the log: half its period for inputs slower than ~8 Hz (a 2 Hz input: 250 ms) —
    #: unless a sensor map file sets ``tolerance_ms``, which then holds for every input.
    tolerances_ns: Mapping[str, int] = field(default_factory=dict)

    def by_topic(self) -> dict[str, SensorSpec]:
        return {s.topic: s for s in self.sensors}

    def tolerance_for(self, name: str) -> int:
        """The tolerance of input ``name`` (a sensor id, ``vehicle_state``, ``ground_truth``,
        ``traffic_lights``)."""
        return self.tolerances_ns.get(name, self.tolerance_ns)

    @property
    def widest_tolerance_ns(self) -> int:
        """The largest tolerance of any input: how long frames wait for the others' samples."""
        return max([self.tolerance_ns, *self.tolerances_ns.values()])

    def sensor(self, sensor_id: str) -> SensorSpec:
        for spec in self.sensors:
            if spec.sensor_id == sensor_id:
                return spec
        known = ", ".join(s.sensor_id for s in self.sensors) or "none"
        msg = f"no sensor {sensor_id!r} in this log (sensors: {known})"
        raise ConfigError(msg)

    def topics(self) -> tuple[str, ...]:
        """Every topic the frames read."""
        out = [s.topic for s in self.sensors] + list(self.tf_topics)
        out += [
            t
            for t in (self.vehicle_state_topic, self.ground_truth_topic, self.traffic_lights_topic)
            if t
        ]
        return tuple(dict.fromkeys(out))


@dataclass(frozen=True, slots=True, kw_only=True)
class SensorMapOverrides:
    """What a sensor map file says; everything it leaves out is inferred."""

    driver: str | None = None
    tolerance_ns: int | None = None
    vehicle_state_topic: str | None = None
    ground_truth_topic: str | None = None
    traffic_lights_topic: str | None = None
    ignore: frozenset[str] = frozenset()
    sensors: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)


def sensor_id_for(topic: str) -> str:
    """``/kitti/velo/pointcloud`` → ``kitti_velo_pointcloud``."""
    name = re.sub(r"[^0-9A-Za-z]+", "_", topic).strip("_").lower()
    return name or "sensor"


def load_sensor_map_overrides(path: str | Path) -> SensorMapOverrides:
    """Read a sensor map TOML file (see the module docstring).

    Raises:
        ConfigError: unreadable file, unknown key, or a value of the wrong kind.
    """
    doc = Table(read_toml(path, what="sensor map"), source=str(path))
    doc.check_keys(
        {
            "driver",
            "tolerance_ms",
            "vehicle_state",
            "ground_truth",
            "traffic_lights",
            "ignore",
            "sensors",
        }
    )
    types = tuple(t.value for t in SensorType)
    sensors: dict[str, Mapping[str, Any]] = {}
    for sid in (table := doc.table("sensors", {}, fix="write each sensor as [sensors.NAME]")):
        spec = table.table(sid, fix=f'write [sensors.{sid}] with topic = "/some/topic"')
        spec.check_keys({"topic", "type", "location"})
        spec.text("topic", fix=f'[sensors.{sid}] needs topic = "/some/topic"')
        spec.text("type", None, choices=types)
        spec.numbers("location", None, length=3, fix="write location = [x, y, z] in metres")
        sensors[sid] = spec.data
    tol = doc.number("tolerance_ms", None, minimum=0)
    ignore = doc.texts("ignore", (), fix="write ignore = a list of topic names")
    return SensorMapOverrides(
        driver=doc.text("driver", None),
        tolerance_ns=None if tol is None else int(tol * 1_000_000),
        vehicle_state_topic=doc.text("vehicle_state", None),
        ground_truth_topic=doc.text("ground_truth", None),
        traffic_lights_topic=doc.text("traffic_lights", None),
        ignore=frozenset(ignore),
        sensors=sensors,
    )


def _rate_hz(info: TopicInfo, duration_ns: int) -> float:
    if info.count < 2 or duration_ns <= 0:
        return 0.0
    return (info.count - 1) / (duration_ns / 1e9)


def infer_sensor_map(
    topics: Mapping[str, TopicInfo],
    *,
    duration_ns: int,
    overrides: SensorMapOverrides | None = None,
) -> SensorMap:
    """Map topics to sensors from their message types, then apply ``overrides``.

    The driver is the user's choice, else the highest-rate LiDAR (then camera, 2D LiDAR, radar);
    none (frames from the ground truth) when the user says ``driver = "ground_truth"`` or the log
    has ground truth but none of those; in a log with neither (IMU, GNSS only) the highest-rate
    sensor of any type.
    Camera info topics are calibration, not sensors: they map to nothing here.

    Raises:
        ConfigError: the overrides name a topic or sensor the log does not have.
    """
    ov = overrides or SensorMapOverrides()
    named = (ov.vehicle_state_topic, ov.ground_truth_topic, ov.traffic_lights_topic)
    for topic in [t for t in named if t]:
        if topic not in topics:
            msg = f"sensor map names topic {topic!r}, which is not in the log"
            raise ConfigError(msg)
    specs: dict[str, SensorSpec] = {}
    explicit_topics = {str(s["topic"]) for s in ov.sensors.values()}
    vehicle_state: list[TopicInfo] = []
    objects: list[TopicInfo] = []
    lights: list[TopicInfo] = []
    tf_topics: list[str] = []
    for topic, info in topics.items():
        if topic in ov.ignore or topic in explicit_topics:
            continue
        found = topic_kind(info)
        if found is None:
            continue
        kind, sensor_type = found
        if kind is DecodedKind.SENSOR and sensor_type is not None:
            sid = sensor_id_for(topic)
            while sid in specs:
                sid += "_"
            specs[sid] = SensorSpec(
                sensor_id=sid,
                topic=topic,
                sensor_type=sensor_type,
                rate_hz=_rate_hz(info, duration_ns),
            )
        elif kind is DecodedKind.VEHICLE_STATE:
            vehicle_state.append(info)
        elif kind is DecodedKind.OBJECTS:
            objects.append(info)
        elif kind is DecodedKind.TRANSFORMS:
            tf_topics.append(topic)
        elif kind is DecodedKind.TRAFFIC_LIGHTS:
            lights.append(info)
        # DecodedKind.CAMERA_INFO: calibration, never a sensor (see redrive.assembly.calibration)
    for sid, raw in ov.sensors.items():
        topic = str(raw["topic"])
        if topic not in topics:
            msg = f"sensor map: [sensors.{sid}] topic {topic!r} is not in the log"
            raise ConfigError(msg)
        info = topics[topic]
        found = topic_kind(info)
        if "type" in raw:
            stype = SensorType(raw["type"])
        elif found is not None and found[1] is not None:
            stype = found[1]
        else:
            msg = f"sensor map: [sensors.{sid}] {topic} ({info.msgtype}) needs an explicit type"
            raise ConfigError(msg)
        loc = raw.get("location")
        specs[sid] = SensorSpec(
            sensor_id=sid,
            topic=topic,
            sensor_type=stype,
            rate_hz=_rate_hz(info, duration_ns),
            location=None if loc is None else (float(loc[0]), float(loc[1]), float(loc[2])),
        )
    driver = ov.driver
    by_ground_truth = driver == GROUND_TRUTH_DRIVER and driver not in specs
    if by_ground_truth:
        driver = None
    if driver is not None and driver not in specs:
        msg = f"sensor map: driver {driver!r} is not a sensor of this log ({', '.join(specs)})"
        raise ConfigError(msg)
    gt_topic = ov.ground_truth_topic or _busiest(objects, prefer="groundtruth")
    if driver is None and not by_ground_truth:
        for stype in _DRIVER_PREFERENCE:
            candidates = [s for s in specs.values() if s.sensor_type is stype]
            if candidates:
                driver = max(candidates, key=lambda s: (s.rate_hz, s.sensor_id)).sensor_id
                break
        if driver is None and gt_topic is None and specs:
            # an IMU / GNSS / odometry-sensor log: its busiest sensor paces the frames (as a
            # closed loop over it does), so the stages it can feed (planning on the ego state)
            # run open loop too
            driver = max(specs.values(), key=lambda s: (s.rate_hz, s.sensor_id)).sensor_id
    state_topic = ov.vehicle_state_topic or _busiest(vehicle_state, prefer="odom")
    if by_ground_truth and gt_topic is None:
        msg = f'sensor map: driver = "{GROUND_TRUTH_DRIVER}" but the log has no ground truth'
        raise ConfigError(msg)
    lights_topic = ov.traffic_lights_topic or _busiest(lights, prefer="trafficlight")
    tolerances: dict[str, int] = {}
    if ov.tolerance_ns is None:  # a sensor map file's tolerance_ms holds for every input
        rates = {s.sensor_id: s.rate_hz for s in specs.values()}
        inputs = (
            ("vehicle_state", state_topic),
            ("ground_truth", gt_topic),
            ("traffic_lights", lights_topic),
        )
        for name, input_topic in inputs:
            if input_topic is not None and input_topic in topics:
                rates[name] = _rate_hz(topics[input_topic], duration_ns)
        for name, rate in rates.items():
            half_period = round(0.5e9 / rate) if rate > 0 else 0
            if half_period > 1.2 * _DEFAULT_TOLERANCE_NS:  # slower than ~8 Hz
                tolerances[name] = half_period
    return SensorMap(
        sensors=tuple(sorted(specs.values(), key=lambda s: s.sensor_id)),
        driver=driver,
        tolerance_ns=_DEFAULT_TOLERANCE_NS if ov.tolerance_ns is None else ov.tolerance_ns,
        vehicle_state_topic=state_topic,
        ground_truth_topic=gt_topic,
        traffic_lights_topic=lights_topic,
        tf_topics=tuple(sorted(tf_topics)),
        tolerances_ns=tolerances,
    )


def _busiest(infos: list[TopicInfo], *, prefer: str) -> str | None:
    if not infos:
        return None
    return max(infos, key=lambda i: (prefer in i.msgtype.lower(), i.count, i.topic)).topic
