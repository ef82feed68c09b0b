"""Timestamped sensor samples and the synchronised frame."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, Protocol, runtime_checkable

from redrive.types._pickle import reduce_dataclass
from redrive.types.enums import SensorType
from redrive.types.environment import EnvironmentData, TrafficData
from redrive.types.objects import DetectedObject
from redrive.types.sensors import GnssFix, Image, Imu, PointCloud
from redrive.types.vehicle import VehicleState

__all__ = ["ExtensionPayload", "Frame", "SensorData", "SensorPayload"]


@runtime_checkable
class ExtensionPayload(Protocol):
    """A payload type defined outside redrive (a plugin's radar point list, say).

    Any class may be a sensor payload when it says which sensor types may carry it; redrive's own
    payloads are listed in ``_PAYLOADS`` instead.  Make it a frozen dataclass with one array per
    field (CONVENTIONS.md) so that it behaves like the built-in payloads.

    >>> @dataclass(frozen=True)
    ... class RadarPoints:
    ...     sensor_types: ClassVar[frozenset[SensorType]] = frozenset({SensorType.RADAR})
    """

    sensor_types: ClassVar[frozenset[SensorType]]


SensorPayload = PointCloud | Image | Imu | GnssFix | VehicleState | ExtensionPayload

_PAYLOADS: Mapping[SensorType, tuple[type, ...]] = MappingProxyType(
    {
        SensorType.LIDAR: (PointCloud,),
        SensorType.LIDAR_2D: (PointCloud,),
        SensorType.RADAR: (PointCloud,),
        SensorType.CAMERA: (Image,),
        SensorType.IMU: (Imu,),
        SensorType.GNSS: (GnssFix,),
        SensorType.ODOMETRY: (VehicleState,),
    }
)


@dataclass(frozen=True, slots=True, kw_only=True)
class SensorData:
    """One sample of one sensor.

    Attributes:
        sensor_id: the name of the sensor in this log (``lidar_top``, ``cam_front`` …).
        sensor_type: what kind of sensor; fixes which payload ``data`` may hold.
        stamp_ns: acquisition time (the message header stamp), int ns.
        frame_id: the sensor's coordinate frame.
        frame_rate_hz: nominal rate; 0.0 when unknown.
        resolution: (width, height) for cameras, (columns, rows) for organised clouds, else None.
        sensor_location: (x, y, z) metres of the sensor in base_link; zeros when unknown.
        data: the payload: the built-in type of ``sensor_type`` (PointCloud for LiDAR and radar,
            Image, Imu, GnssFix, VehicleState for odometry) or an :class:`ExtensionPayload`
            that names ``sensor_type`` in its ``sensor_types``.
    """

    sensor_id: str
    sensor_type: SensorType
    stamp_ns: int
    frame_id: str = ""
    frame_rate_hz: float = 0.0
    resolution: tuple[int, int] | None = None
    sensor_location: tuple[float, float, float] = (0.0, 0.0, 0.0)
    data: SensorPayload

    def __post_init__(self) -> None:
        allowed = _PAYLOADS[self.sensor_type]
        extension = getattr(type(self.data), "sensor_types", ())
        if not isinstance(self.data, allowed) and self.sensor_type not in extension:
            names = ", ".join(t.__name__ for t in allowed)
            msg = (
                f"SensorData {self.sensor_id!r}: a {self.sensor_type.name} sensor carries "
                f"{names} or a payload class whose `sensor_types` names {self.sensor_type.name}, "
                f"got {type(self.data).__name__}"
            )
            raise ValueError(msg)
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))
        if len(self.sensor_location) != 3:
            msg = f"SensorData.sensor_location must be (x, y, z), got {self.sensor_location!r}"
            raise ValueError(msg)
        loc = tuple(float(v) for v in self.sensor_location)
        object.__setattr__(self, "sensor_location", loc)


@dataclass(frozen=True, slots=True, kw_only=True)
class Frame:
    """One synchronised tick of the log, driven by one sensor.

    Attributes:
        stamp_ns: the driving sensor's stamp.
        index: 0-based position of this frame in the run.
        sensors: sensor_id → the nearest sample of that sensor within the tolerance.
        vehicle_state: ego state interpolated to ``stamp_ns``; None when the log has none.
        ground_truth: objects (in base_link when a transform was known, else in their own
            frame) or None when the log carries no ground truth.
        traffic: the traffic lights' states at ``stamp_ns`` (``TrafficLight.id`` is the
            ``light_id`` of a light of the log's road map); no lights when the log has none.
        missing: what the log provides but had no sample of within the tolerance of this
            frame's stamp (stale or absent here): sensor ids, ``vehicle_state``,
            ``ground_truth``, ``traffic_lights``.  Their fields above are then absent / None
            (empty, for the lights).
    """

    stamp_ns: int
    index: int
    sensors: Mapping[str, SensorData] = field(default_factory=dict)
    vehicle_state: VehicleState | None = None
    environment: EnvironmentData = field(default_factory=EnvironmentData)
    traffic: TrafficData = field(default_factory=TrafficData)
    ground_truth: tuple[DetectedObject, ...] | None = None
    missing: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))
        object.__setattr__(self, "missing", tuple(self.missing))
        if self.index < 0:
            msg = f"Frame.index must be >= 0, got {self.index}"
            raise ValueError(msg)
        object.__setattr__(self, "sensors", MappingProxyType(dict(self.sensors)))
        if self.ground_truth is not None:
            object.__setattr__(self, "ground_truth", tuple(self.ground_truth))

    def __reduce__(self) -> tuple[Any, ...]:
        return reduce_dataclass(self)
