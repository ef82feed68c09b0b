"""Closed-loop re-simulation (layer L6): the ego driven by the algorithms' commands.

``tracker`` holds the built-in path tracker — nuPlan's LQR tracker, its reference fitted in
``profiles`` — that turns a planned path into ``ControlCommands`` when a pipeline has no control
stage; ``contact`` the collisions of the driven ego.  The ego's motion (kinematic bicycle,
actuator limits, tyres' friction circle, pedal model, actuation delay) lives in
``redrive.sim.ego``.
"""

from __future__ import annotations

from redrive.closedloop.tracker import LqrTracker

__all__ = ["LqrTracker"]
