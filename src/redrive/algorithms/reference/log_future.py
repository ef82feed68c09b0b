"""The expert as a planner: the logged ego's future, handed over by the run's mission.

nuPlan's ``LogFuturePlanner`` (nuplan-devkit
``nuplan/planning/simulation/planner/log_future_planner.py``) plans, at every step, the
scenario's logged ego trajectory from the current iteration on (``get_ego_future_trajectory``,
``num_poses`` over ``future_time_horizon``), and nuPlan's two-stage controller tracks it.  Here
the logged trajectory is the :class:`~redrive.types.Mission`'s (``Algorithm.use_mission``: a
closed loop on a recorded log hands it over): every frame the plan is the logged ego's positions
at ``stamp + k·dt_s`` (linear between logged states, held at the last one past the log's end),
``k = 0 … horizon_s / dt_s``, in base_link of the frame's (driven) ego.  The built-in tracker follows it, so
the driven ego stays within the tracker's error of the log — "the expert on its own map".

Configuration: ``horizon_s`` (8.0, nuPlan's ``future_time_horizon``), ``dt_s`` (0.1).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

from redrive.algorithms.base import VEHICLE_STATE, Algorithm, Input, Role, StageOutputs
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import Frame, PlannedPath

__all__ = ["LogFuturePlanner"]


class LogFuturePlanner(Algorithm):
    """Plans the logged ego's future (nuPlan's ``LogFuturePlanner``; see the module text)."""

    role: ClassVar[Role] = Role.PLANNING
    inputs: ClassVar[tuple[Input, ...]] = (VEHICLE_STATE,)
    version: ClassVar[str] = "1"
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType({"horizon_s": 8.0, "dt_s": 0.1})

    def setup(self, config: Mapping[str, Any]) -> None:
        try:
            self.horizon_s = float(config["horizon_s"])
            self.dt_s = float(config["dt_s"])
        except (TypeError, ValueError) as err:
            msg = f"LogFuturePlanner: horizon_s and dt_s must be numbers ({err})"
            raise ConfigError(msg) from err
        if not (0.0 < self.dt_s <= self.horizon_s):
            msg = (
                f"LogFuturePlanner: need 0 < dt_s <= horizon_s, got dt_s = {self.dt_s}, "
                f"horizon_s = {self.horizon_s}"
            )
            raise ConfigError(msg)

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        mission = self.mission
        if mission is None or mission.logged_stamps_ns.shape[0] < 2:
            msg = (
                f"{self.name}: no logged ego trajectory was handed over (frame {frame.index}); "
                "the log-future planner drives a closed loop on a recorded log "
                "(`redrive run LOG --closed-loop`), whose mission carries it"
            )
            raise AlgorithmError(msg)
        n = max(1, round(self.horizon_s / self.dt_s))
        t_s = np.arange(n + 1, dtype=np.float64) * self.dt_s
        stamps = mission.logged_stamps_ns
        # relative to the first logged stamp: float64 keeps ns there (log times do not)
        at = (frame.stamp_ns - int(stamps[0])) / 1e9 + t_s
        rel = (stamps - stamps[0]).astype(np.float64) / 1e9
        x = np.interp(at, rel, mission.logged_xy[:, 0])
        y = np.interp(at, rel, mission.logged_xy[:, 1])
        state = frame.vehicle_state
        if state is None or state.frame_id != mission.frame_id:
            msg = (
                f"{self.name}: frame {frame.index} has no ego state in the mission's frame "
                f"{mission.frame_id!r}"
            )
            raise AlgorithmError(msg)
        # into base_link of the frame's (driven) ego, as every planner's plan
        dx, dy = x - float(state.position[0]), y - float(state.position[1])
        c, sn = math.cos(state.heading_rad), math.sin(state.heading_rad)
        waypoints = np.column_stack([c * dx + sn * dy, -sn * dx + c * dy, np.zeros_like(t_s), t_s])
        return PlannedPath(stamp_ns=frame.stamp_ns, waypoints=waypoints, frame_id="base_link")
