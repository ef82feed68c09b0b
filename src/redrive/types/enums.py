"""Enumerations of the data model."""

from __future__ import annotations

import enum

__all__ = [
    "LightState",
    "Lighting",
    "ObjectClass",
    "RoadCondition",
    "Role",
    "SensorType",
    "Weather",
]


class SensorType(enum.Enum):
    """What kind of sensor produced a :class:`~redrive.types.SensorData`."""

    LIDAR = "lidar"
    LIDAR_2D = "lidar_2d"
    CAMERA = "camera"
    RADAR = "radar"
    IMU = "imu"
    GNSS = "gnss"
    ODOMETRY = "odometry"


class ObjectClass(enum.Enum):
    """Class of a detected or ground-truth object."""

    UNKNOWN = "unknown"
    VEHICLE = "vehicle"
    TRUCK = "truck"
    PEDESTRIAN = "pedestrian"
    BICYCLE = "bicycle"
    MOTORCYCLE = "motorcycle"
    STATIC = "static"
    OTHER = "other"


class Weather(enum.Enum):
    UNKNOWN = "unknown"
    CLEAR = "clear"
    CLOUDY = "cloudy"
    RAIN = "rain"
    FOG = "fog"
    SNOW = "snow"


class Lighting(enum.Enum):
    UNKNOWN = "unknown"
    DAY = "day"
    DUSK = "dusk"
    NIGHT = "night"


class RoadCondition(enum.Enum):
    UNKNOWN = "unknown"
    DRY = "dry"
    WET = "wet"
    ICY = "icy"


class LightState(enum.Enum):
    UNKNOWN = "unknown"
    RED = "red"
    YELLOW = "yellow"
    GREEN = "green"


class Role(enum.Enum):
    """The Algorithm Role Descriptor: which stage an algorithm belongs to and what it returns.

    Lives in the data model so that every layer (algorithms, metrics, the run manifest) names a
    stage with the same enum.
    """

    PERCEPTION = "perception"
    PLANNING = "planning"
    CONTROL = "control"

    @property
    def output_name(self) -> str:
        """What an algorithm of this role returns, in words (for error messages)."""
        return {
            Role.PERCEPTION: "a list of DetectedObject",
            Role.PLANNING: "a PlannedPath",
            Role.CONTROL: "a ControlCommands",
        }[self]
