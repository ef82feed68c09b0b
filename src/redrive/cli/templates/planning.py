"""``redrive new-algorithm NAME --role planning``: a straight constant-speed planner and its tests."""

from __future__ import annotations

__all__ = ["ALGORITHM", "TEST"]

ALGORITHM = '''\
"""$cls: a planning algorithm for redrive (written by `redrive new-algorithm`).

A baseline to start from: a straight path ahead of the ego at its current speed.  Replace
``step`` with your planner; keep its signature and its output type.

    python -m pytest test_$module.py                          its tests
    redrive algorithms $module.py:$cls                  what redrive sees
    redrive run LOG --planning $module.py:$cls          run it on a log
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np
from redrive.algorithms import VEHICLE_STATE, Algorithm, Role, StageOutputs
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import Frame, PlannedPath


class $cls(Algorithm):
    """A straight path ahead at the ego's current speed (a baseline to build on).

    Input: the ego state (``frame.vehicle_state``, in ``map`` or ``odom``).  Output: a
    :class:`PlannedPath` in base_link of the frame (x forward, y left, z up, metres; t_s seconds
    from ``frame.stamp_ns``): one waypoint every ``dt_s`` over ``horizon_s`` seconds along +x at
    the current speed, or ``min_speed_mps`` if that is higher.

    The objects found by perception upstream are at hand as ``upstream.objects()`` (boxes in
    base_link); this baseline ignores them.  Configuration:

    =============  =======  ===============================================
    key            default  meaning
    =============  =======  ===============================================
    horizon_s      5.0      how far ahead the path reaches, seconds
    dt_s           0.1      time between waypoints, seconds
    min_speed_mps  0.0      the path never goes slower than this, m/s
    =============  =======  ===============================================
    """

    role = Role.PLANNING
    inputs = (VEHICLE_STATE,)
    version = "0.1"
    defaults = MappingProxyType({"horizon_s": 5.0, "dt_s": 0.1, "min_speed_mps": 0.0})

    def setup(self, config: Mapping[str, Any]) -> None:
        """Check the configuration once per run (``config`` = defaults + the run's values)."""
        if not 0.0 < float(config["dt_s"]) <= float(config["horizon_s"]):
            msg = f"{self.name}: need 0 < dt_s <= horizon_s, got {dict(config)}"
            raise ConfigError(msg)

    def reset(self) -> None:
        """Forget all state between runs (this planner keeps none)."""

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        """The path for this frame, waypoints in base_link."""
        state = frame.vehicle_state
        if state is None:
            msg = f"{self.name}: frame {frame.index} has no vehicle state"
            raise AlgorithmError(msg)
        speed_mps = max(state.speed_mps, float(self.config["min_speed_mps"]))
        dt_s = float(self.config["dt_s"])
        t_s = np.arange(0.0, float(self.config["horizon_s"]) + dt_s / 2.0, dt_s)
        # TODO: slow down for obstacles, e.g. the nearest of upstream.objects() with |y| < 1.5 m
        waypoints = np.zeros((len(t_s), 4))
        waypoints[:, 0] = speed_mps * t_s  # x: straight ahead
        waypoints[:, 3] = t_s
        return PlannedPath(stamp_ns=frame.stamp_ns, waypoints=waypoints, frame_id="base_link")
'''

TEST = '''\
"""Tests of $cls on hand-built frames (run: python -m pytest test_$module.py)."""

from __future__ import annotations

import math

import numpy as np
from redrive.algorithms import VEHICLE_STATE, StageOutputs, StepStatus
from redrive.types import Frame, PlannedPath, VehicleState

# the module under test, apart from the libraries above
# isort: split
from $module import $cls


def _frame(speed_mps: float, heading_rad: float = 0.7) -> Frame:
    """A frame whose ego drives at ``speed_mps`` in the map, heading ``heading_rad``."""
    velocity = speed_mps * np.array([math.cos(heading_rad), math.sin(heading_rad), 0.0])
    state = VehicleState(
        stamp_ns=2_000_000_000,
        frame_id="map",
        position=np.array([350.0, -120.0, 0.0]),
        velocity=velocity,
        heading_rad=heading_rad,
    )
    return Frame(stamp_ns=2_000_000_000, index=3, vehicle_state=state)


def _ready() -> $cls:
    algo = $cls()
    algo.configure({})  # the defaults; a run's config goes here
    algo.bind({}, extras=[VEHICLE_STATE])
    return algo


def test_path_goes_straight_ahead_at_the_current_speed() -> None:
    result = _ready().run_step(_frame(8.0), StageOutputs())
    assert result.status is StepStatus.OK, result.error
    path = result.output
    assert isinstance(path, PlannedPath)
    assert path.frame_id == "base_link"
    assert path.stamp_ns == 2_000_000_000
    wp = path.waypoints
    assert wp[0, 3] == 0.0
    assert math.isclose(wp[-1, 3], 5.0)
    assert np.all(wp[:, 1] == 0.0)
    speeds = np.diff(wp[:, 0]) / np.diff(wp[:, 3])
    assert np.allclose(speeds, 8.0)


def test_min_speed_is_kept_when_standing() -> None:
    algo = $cls()
    algo.configure({"min_speed_mps": 2.0})
    path = algo.step(_frame(0.0), StageOutputs())
    assert math.isclose(path.waypoints[-1, 0], 10.0)


def test_a_frame_without_ego_state_is_an_error() -> None:
    result = _ready().run_step(Frame(stamp_ns=0, index=0), StageOutputs())
    assert result.status is StepStatus.ERROR
    assert result.error is not None
    assert "no vehicle state" in result.error.message
'''
