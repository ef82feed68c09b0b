"""Planners for closed-loop tests: one that never moves, one that returns NaNs, one that plans
straight ahead at a fixed speed whatever is in the way."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from redrive.algorithms import Algorithm, Role, StageOutputs
from redrive.types import Frame, PlannedPath


def _straight(stamp_ns: int, speed_mps: float, horizon_s: float = 6.0) -> PlannedPath:
    t = np.arange(0.0, horizon_s + 1e-9, 0.1)
    x = speed_mps * t
    return PlannedPath(
        stamp_ns=stamp_ns, waypoints=np.column_stack([x, np.zeros_like(t), np.zeros_like(t), t])
    )


class StandStill(Algorithm):
    """Plans to stand where it is."""

    role = Role.PLANNING

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        return _straight(frame.stamp_ns, 0.0)


class Straight(Algorithm):
    """Plans straight ahead at ``speed_mps``, blind to everything."""

    role = Role.PLANNING
    defaults = MappingProxyType({"speed_mps": 12.0})

    def setup(self, config: Mapping[str, Any]) -> None:
        self.speed_mps = float(config["speed_mps"])

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        return _straight(frame.stamp_ns, self.speed_mps)


class NanAfterTwoSeconds(Algorithm):
    """Plans straight at 10 m/s, then from frame 20 on a path of NaNs."""

    role = Role.PLANNING

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        path = _straight(frame.stamp_ns, 10.0)
        if frame.index < 20:
            return path
        return PlannedPath(stamp_ns=frame.stamp_ns, waypoints=np.full_like(path.waypoints, np.nan))
