"""Closed-loop metrics of the driven ego, as nuPlan and NAVSIM define them (``docs/metrics.md``).

They score a run as a whole (``role = None``) from its ``ego`` table, its ground truth (in the
frame's base_link, put into ``map`` with the frame's ego pose) and, where road geometry is
needed, its road map (``RUN/map.json``; runs of a synthetic scenario or its log store one, others skip those
metrics).  They apply to open-loop runs as well: there the driven ego is the logged one.
"""

from __future__ import annotations

from redrive.evaluation.closedloop.collisions import AtFaultCollisions, TimeToCollision
from redrive.evaluation.closedloop.commands import FallbackCommands
from redrive.evaluation.closedloop.lights import TrafficLightCompliance
from redrive.evaluation.closedloop.motion import Comfort, EgoProgress
from redrive.evaluation.closedloop.nuplan import NuplanScenarioScore
from redrive.evaluation.closedloop.pdm import PdmScore
from redrive.evaluation.closedloop.road import (
    DrivableAreaCompliance,
    DrivingDirectionCompliance,
    SpeedLimitCompliance,
)

__all__ = [
    "AtFaultCollisions",
    "Comfort",
    "DrivableAreaCompliance",
    "DrivingDirectionCompliance",
    "EgoProgress",
    "FallbackCommands",
    "NuplanScenarioScore",
    "PdmScore",
    "SpeedLimitCompliance",
    "TimeToCollision",
    "TrafficLightCompliance",
]
