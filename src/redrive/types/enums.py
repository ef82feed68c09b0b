"""Enumerations of the data model."""

from __future__ import annotations

import enum

__all__ = [
    "LightState",
    "Lighting",
    "ObjectClass",
    "RoadCondition",
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
