"""Environment and traffic context of a frame."""

from __future__ import annotations

from dataclasses import dataclass

from redrive.types.enums import Lighting, LightState, RoadCondition, Weather
from redrive.types.objects import DetectedObject

__all__ = ["EnvironmentData", "TrafficData", "TrafficLight"]


@dataclass(frozen=True, slots=True, kw_only=True)
class EnvironmentData:
    """Conditions; ``UNKNOWN`` when the log does not say."""

    weather: Weather = Weather.UNKNOWN
    lighting: Lighting = Lighting.UNKNOWN
    road_condition: RoadCondition = RoadCondition.UNKNOWN


@dataclass(frozen=True, slots=True, kw_only=True)
class TrafficLight:
    id: str
    state: LightState = LightState.UNKNOWN


@dataclass(frozen=True, slots=True, kw_only=True)
class TrafficData:
    traffic_lights: tuple[TrafficLight, ...] = ()
    nearby_vehicles: tuple[DetectedObject, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "traffic_lights", tuple(self.traffic_lights))
        object.__setattr__(self, "nearby_vehicles", tuple(self.nearby_vehicles))
