"""The redrive data model (layer L0: numpy and the standard library only).

Every type is a frozen, slotted, keyword-only dataclass; arrays are checked for shape and dtype
and made read-only in ``__post_init__``.  Change a value with :func:`dataclasses.replace`.
"""

from __future__ import annotations

from redrive.types.enums import (
    Lighting,
    LightState,
    ObjectClass,
    RoadCondition,
    Role,
    SensorType,
    Weather,
)
from redrive.types.environment import EnvironmentData, TrafficData, TrafficLight
from redrive.types.frame import ExtensionPayload, Frame, SensorData, SensorPayload
from redrive.types.jsonable import to_jsonable
from redrive.types.mission import Mission
from redrive.types.objects import CLASS_CODES, Box3D, DetectedObject, ObjectColumns
from redrive.types.roadmap import (
    BOUNDARY_TYPES,
    Crosswalk,
    DrivableArea,
    Intersection,
    MapLane,
    MapTrafficLight,
    Roadblock,
    RoadMap,
    StopLine,
)
from redrive.types.sensors import IMAGE_ENCODINGS, CameraInfo, GnssFix, Image, Imu, PointCloud
from redrive.types.transforms import Transform
from redrive.types.vehicle import ControlCommands, PlannedPath, VehicleState

__all__ = [
    "BOUNDARY_TYPES",
    "CLASS_CODES",
    "IMAGE_ENCODINGS",
    "Box3D",
    "CameraInfo",
    "ControlCommands",
    "Crosswalk",
    "DetectedObject",
    "DrivableArea",
    "EnvironmentData",
    "ExtensionPayload",
    "Frame",
    "GnssFix",
    "Image",
    "Imu",
    "Intersection",
    "LightState",
    "Lighting",
    "MapLane",
    "MapTrafficLight",
    "Mission",
    "ObjectClass",
    "ObjectColumns",
    "PlannedPath",
    "PointCloud",
    "RoadCondition",
    "RoadMap",
    "Roadblock",
    "Role",
    "SensorData",
    "SensorPayload",
    "SensorType",
    "StopLine",
    "TrafficData",
    "TrafficLight",
    "Transform",
    "VehicleState",
    "Weather",
    "to_jsonable",
]
