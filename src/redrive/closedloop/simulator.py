"""The closed-loop contract: a :class:`Simulator` backend, and how stage outputs move the ego.

A backend is one class with four methods: :meth:`Simulator.reset` (start over, seeded),
:meth:`Simulator.observe` (the current state as a :class:`~redrive.types.Frame`, as the algorithms
see it), :meth:`Simulator.step` (apply the stage outputs, advance by a time step) and
:meth:`Simulator.describe` (what the run manifest records).  Everything a run needs beyond that —
the frame loop, storage, the fallback when an algorithm fails — is the same for every backend
(:mod:`redrive.closedloop.mode`, :mod:`redrive.closedloop.run`).

How outputs become an actuator command is fixed here, for every backend
(:func:`choose_command`): the last control stage's :class:`~redrive.types.ControlCommands` when it
produced one; else the built-in path tracker on the last planning stage's path (nuPlan's two-stage
controller); else — no output, a failed step, a path that cannot be followed — an emergency brake
with the steering held, recorded with its reason.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from redrive.algorithms import StageOutputs
from redrive.errors import ConfigError
from redrive.types import ControlCommands, Frame, PlannedPath, Role, VehicleState

__all__ = [
    "AGENT_MODES",
    "EgoCommand",
    "PathFollower",
    "Simulator",
    "check_options",
    "choose_command",
]

#: how the other road users behave: replay their log/script, or react to the driven ego.
AGENT_MODES = ("replay", "reactive")


def check_options(*, agents: str, rate_hz: float, delay_steps: int) -> None:
    """The options every backend takes.

    Raises:
        ConfigError: an unknown agents mode, a rate that is not > 0, a delay other than 0 or 1.
    """
    if agents not in AGENT_MODES:
        msg = f"--agents must be one of {', '.join(AGENT_MODES)}, got {agents!r}"
        raise ConfigError(msg)
    if not rate_hz > 0:
        msg = f"the closed-loop rate must be > 0 Hz, got {rate_hz}"
        raise ConfigError(msg)
    if delay_steps not in (0, 1):
        msg = f"the actuation delay is 0 or 1 frame, got {delay_steps}"
        raise ConfigError(msg)


class Simulator(Protocol):
    """A closed-loop backend: the world the ego drives in."""

    #: sensor id → sensor type of the frames it renders; whether frames carry the ego state and
    #: ground truth (the pipeline is checked against these before the run, as against a log).
    sensors: Mapping[str, Any]
    has_vehicle_state: bool
    has_ground_truth: bool

    @property
    def dt_s(self) -> float:
        """The time step to the next frame (seconds): fixed for a scenario, the log's own gap
        for a log."""
        ...

    def reset(self, seed: int) -> None:
        """Start over from the scenario's (or log's) initial state, with ``seed``."""
        ...

    def observe(self) -> Frame:
        """The current state as the algorithms see it (sensors, ego state, ground truth)."""
        ...

    def step(self, outputs: StageOutputs, dt_s: float) -> EgoCommand:
        """Apply ``outputs`` (via :func:`choose_command`) and advance ``dt_s`` seconds; returns
        the command that was applied."""
        ...

    @property
    def done(self) -> bool:
        """True once the scenario (or log) has no further step."""
        ...

    @property
    def logged_state(self) -> VehicleState | None:
        """The logged (expert) ego state at the current time, for deviation and progress."""
        ...

    def describe(self) -> dict[str, Any]:
        """Backend, agents mode, ego model and limits, tracker and gains — for the manifest."""
        ...


class PathFollower(Protocol):
    """The built-in tracker that turns a planned path into commands (no control stage)."""

    def commands(
        self,
        state: VehicleState,
        path: PlannedPath,
        dt_s: float,
        *,
        stamp_ns: int,
        steer_rad: float | None = None,
    ) -> ControlCommands:
        """Commands for the next ``dt_s`` from ``stamp_ns``; ``steer_rad`` is the ego's current
        road-wheel angle (None: not known)."""
        ...

    def reset(self) -> None:
        """Forget what the last run left (integrals, last errors)."""
        ...

    def describe(self) -> dict[str, Any]: ...


@dataclass(frozen=True, slots=True, kw_only=True)
class EgoCommand:
    """What moved the ego over one step.

    Attributes:
        commands: the actuator command applied (after the fallback, if any).
        source: ``control`` (a control stage's output), ``tracker`` (the built-in tracker on
            the planned path) or ``fallback`` (emergency brake).
        algorithm: the algorithm whose output was used ("" for the fallback).
        reason: why the fallback braked ("" otherwise).
    """

    commands: ControlCommands
    source: str
    algorithm: str = ""
    reason: str = ""


def _brake(steer_rad: float, reason: str) -> EgoCommand:
    """The fallback: full brake, the steering held at its current angle."""
    return EgoCommand(
        commands=ControlCommands(throttle=0.0, brake=1.0, steering_angle_rad=steer_rad),
        source="fallback",
        reason=reason,
    )


def choose_command(
    outputs: StageOutputs,
    *,
    state: VehicleState,
    steer_rad: float,
    tracker: PathFollower,
    dt_s: float,
    stamp_ns: int,
) -> EgoCommand:
    """The command that moves the ego after a frame whose stages produced ``outputs``.

    Args:
        outputs: the frame's stage outputs (failed steps are absent).
        state: the ego's true state (map frame) when the frame was observed; a base_link path
            starts at this pose.
        steer_rad: the current steering angle (held by the fallback; the tracker's lateral
            state).
        tracker: follows a planned path when no control stage produced commands.
        dt_s: the step the command is held for.
        stamp_ns: the time the command starts acting.
    """
    controls = [n for n, r in outputs.roles.items() if r is Role.CONTROL]
    planners = [n for n, r in outputs.roles.items() if r is Role.PLANNING]
    for name in reversed(controls):
        command = outputs.outputs.get(name)
        if isinstance(command, ControlCommands):
            return EgoCommand(commands=command, source="control", algorithm=name)
    if controls:
        return _brake(steer_rad, f"the control stage ({', '.join(controls)}) gave no command")
    for name in reversed(planners):
        path = outputs.outputs.get(name)
        if not isinstance(path, PlannedPath):
            continue
        problem = _path_problem(path)
        if problem:
            return _brake(steer_rad, f"{name}: {problem}")
        try:
            command = tracker.commands(state, path, dt_s, stamp_ns=stamp_ns, steer_rad=steer_rad)
        except ValueError as err:
            return _brake(steer_rad, f"{name}: the tracker cannot follow its path: {err}")
        return EgoCommand(commands=command, source="tracker", algorithm=name)
    if planners:
        return _brake(steer_rad, f"the planning stage ({', '.join(planners)}) gave no path")
    return _brake(steer_rad, "the pipeline has no planning or control stage")


def _path_problem(path: PlannedPath) -> str:
    wp = path.waypoints
    if wp.shape[0] == 0:
        return "an empty path"
    if not bool(np.isfinite(wp).all()):
        return "a path with NaN or infinite waypoints"
    if path.frame_id not in ("base_link", "map"):
        return f"a path in frame {path.frame_id!r} (closed loop follows base_link or map paths)"
    return ""
