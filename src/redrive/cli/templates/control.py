"""``redrive new-algorithm NAME --role control``: a P speed controller and its tests."""

from __future__ import annotations

__all__ = ["ALGORITHM", "TEST"]

ALGORITHM = '''\
"""$cls: a control algorithm for redrive (written by `redrive new-algorithm`).

A baseline to start from: follow the speed of the planned path upstream with a proportional
controller, steering straight.  Replace ``step`` with your controller; keep its signature and its
output type.

    python -m pytest test_$module.py                          its tests
    redrive algorithms $module.py:$cls                  what redrive sees
    redrive run LOG --control $module.py:$cls           run it on a log
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np
from redrive.algorithms import VEHICLE_STATE, Algorithm, Role, StageOutputs
from redrive.errors import AlgorithmError, ConfigError
from redrive.types import ControlCommands, Frame, PlannedPath


class $cls(Algorithm):
    """Follows the upstream path's speed with a P controller; the steering stays at zero.

    Inputs: the ego state (``frame.vehicle_state``) and the :class:`PlannedPath` of the last
    planning algorithm upstream (``upstream.path()``).  Output: :class:`ControlCommands`:
    with the speed error e = v_path - v in m/s (v_path: the path's speed ``lookahead_s`` seconds
    ahead), throttle = ``kp_throttle`` * e when e > 0 and brake = ``kp_brake`` * (-e) when
    e < 0, both clipped to [0, 1]; steering_angle_rad = 0.  Without a path it brakes with
    ``no_path_brake``.  Configuration:

    =============  =======  ===================================================
    key            default  meaning
    =============  =======  ===================================================
    kp_throttle    0.3      throttle per m/s of speed missing
    kp_brake       0.4      brake per m/s of speed too much
    lookahead_s    1.0      where on the path the target speed is read, seconds
    no_path_brake  0.3      brake when no planner produced a path, in [0, 1]
    =============  =======  ===================================================
    """

    role = Role.CONTROL
    inputs = (VEHICLE_STATE,)
    version = "0.1"
    defaults = MappingProxyType(
        {"kp_throttle": 0.3, "kp_brake": 0.4, "lookahead_s": 1.0, "no_path_brake": 0.3}
    )

    def setup(self, config: Mapping[str, Any]) -> None:
        """Check the configuration once per run (``config`` = defaults + the run's values)."""
        if not 0.0 <= float(config["no_path_brake"]) <= 1.0:
            msg = f"{self.name}: no_path_brake must lie in [0, 1], got {config['no_path_brake']}"
            raise ConfigError(msg)

    def reset(self) -> None:
        """Forget all state between runs (a P controller keeps none; a PID's integral would)."""

    def step(self, frame: Frame, upstream: StageOutputs) -> ControlCommands:
        """The commands for this frame."""
        state = frame.vehicle_state
        if state is None:
            msg = f"{self.name}: frame {frame.index} has no vehicle state"
            raise AlgorithmError(msg)
        path = upstream.path()
        if path is None:
            return ControlCommands(brake=float(self.config["no_path_brake"]))
        error_mps = path_speed_mps(path, at_s=float(self.config["lookahead_s"])) - state.speed_mps
        throttle = float(np.clip(self.config["kp_throttle"] * error_mps, 0.0, 1.0))
        brake = float(np.clip(-self.config["kp_brake"] * error_mps, 0.0, 1.0))
        # TODO: steer, e.g. pure pursuit towards the waypoint lookahead_s ahead
        return ControlCommands(throttle=throttle, brake=brake, steering_angle_rad=0.0)


def path_speed_mps(path: PlannedPath, *, at_s: float) -> float:
    """The path's speed (m/s) on the segment whose middle is nearest ``at_s`` seconds ahead."""
    wp = path.waypoints
    if len(wp) < 2:
        return 0.0
    dist_m = np.linalg.norm(np.diff(wp[:, :3], axis=0), axis=1)
    dt_s = np.diff(wp[:, 3])
    speeds = np.divide(dist_m, dt_s, out=np.zeros_like(dist_m), where=dt_s > 0)
    middle_s = (wp[:-1, 3] + wp[1:, 3]) / 2.0
    return float(speeds[np.argmin(np.abs(middle_s - at_s))])
'''

TEST = '''\
"""Tests of $cls on hand-built frames (run: python -m pytest test_$module.py)."""

from __future__ import annotations

import numpy as np
from redrive.algorithms import VEHICLE_STATE, Role, StageOutputs, StepStatus
from redrive.types import ControlCommands, Frame, PlannedPath, VehicleState

# the module under test, apart from the libraries above
# isort: split
from $module import $cls


def _frame(speed_mps: float) -> Frame:
    """A frame whose ego drives along +x of the map at ``speed_mps``."""
    state = VehicleState(
        stamp_ns=3_000_000_000,
        position=np.array([10.0, 5.0, 0.0]),
        velocity=np.array([speed_mps, 0.0, 0.0]),
    )
    return Frame(stamp_ns=3_000_000_000, index=7, vehicle_state=state)


def _upstream(speed_mps: float) -> StageOutputs:
    """What a planner named "planner" produced: straight ahead at ``speed_mps`` for 5 s."""
    t_s = np.arange(0.0, 5.05, 0.1)
    waypoints = np.stack([speed_mps * t_s, np.zeros_like(t_s), np.zeros_like(t_s), t_s], axis=1)
    path = PlannedPath(stamp_ns=3_000_000_000, waypoints=waypoints)
    return StageOutputs({"planner": path}, {"planner": Role.PLANNING})


def _commands(speed_mps: float, upstream: StageOutputs) -> ControlCommands:
    algo = $cls()
    algo.configure({})  # the defaults; a run's config goes here
    algo.bind({}, extras=[VEHICLE_STATE])
    result = algo.run_step(_frame(speed_mps), upstream)
    assert result.status is StepStatus.OK, result.error
    assert isinstance(result.output, ControlCommands)
    return result.output


def test_speeds_up_towards_a_faster_path() -> None:
    cmd = _commands(5.0, _upstream(10.0))
    assert cmd.throttle > 0.0
    assert cmd.brake == 0.0
    assert cmd.steering_angle_rad == 0.0


def test_brakes_towards_a_slower_path() -> None:
    cmd = _commands(10.0, _upstream(5.0))
    assert cmd.throttle == 0.0
    assert cmd.brake > 0.0


def test_holds_on_the_path_speed() -> None:
    cmd = _commands(8.0, _upstream(8.0))
    assert cmd.throttle < 1e-9
    assert cmd.brake < 1e-9


def test_brakes_without_a_path() -> None:
    cmd = _commands(8.0, StageOutputs())
    assert cmd.brake > 0.0
    assert cmd.throttle == 0.0
'''
