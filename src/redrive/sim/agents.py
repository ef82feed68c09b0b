"""Agents of the synthetic world: IDM vehicles and cyclists on routes, walking pedestrians, parked cars.

Vehicles use Treiber's Intelligent Driver Model (:mod:`redrive.motion.idm`: the one kernel that
the world's compiled steps and the reference planner call too) with the gap ``s`` to the nearest
obstacle on the route ahead (another agent, the ego, a pedestrian in the lane) or to a stop line
whose light is red (or yellow, when there is room to stop comfortably): a red light is a stopped
virtual leader at the stop line.

Every update is two-phase: all agents *plan* from one :class:`Obstacles` snapshot, then all
*advance*; nothing depends on iteration order of sets or on wall-clock time.  The world moves its
lane followers with compiled kernels (:mod:`redrive.sim.fleet`, :mod:`redrive.sim.gaps`,
:mod:`redrive.sim.stepper`); :class:`LaneFollower` is what it builds them from.  The same
follower in plain Python (gap search, stop lines, IDM, motion), the reference the kernels are
compared with, is ``tests/sim/_reference_agents.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from redrive.motion import IdmParams
from redrive.sim.roads import Route
from redrive.types import ObjectClass

__all__ = [
    "LaneChange",
    "LaneFollower",
    "Obstacles",
    "ParkedObject",
    "Walker",
]

F64 = npt.NDArray[np.float64]
_NO_GAP = math.inf


@dataclass(frozen=True, slots=True, kw_only=True)
class Obstacles:
    """Footprints of everything that can block a route, map frame (arrays share the first axis).

    Attributes:
        ids: (M,) int64; centers: (M, 2) metres; lengths, widths: (M,) metres;
        velocities: (M, 2) m/s.
    """

    ids: npt.NDArray[np.int64]
    centers: F64
    lengths: F64
    widths: F64
    velocities: F64


@dataclass(frozen=True, slots=True, kw_only=True)
class LaneChange:
    """Move onto ``target`` (an adjacent, parallel route) from ``start_time_s`` over ``duration_s``."""

    target: Route
    start_time_s: float
    duration_s: float = 3.0


class LaneFollower:
    """A vehicle or cyclist driving along a route with IDM, optionally braking hard or changing lane:
    the description (and start state) :class:`~redrive.sim.fleet.LaneFleet` is built from.

    The reference point is the box centre, at arclength ``s_m`` of ``route`` and lateral offset
    ``lateral_offset_m`` (plus the fading offset of a lane change).
    """

    def __init__(
        self,
        agent_id: int,
        object_class: ObjectClass,
        *,
        route: Route,
        s_m: float,
        speed_mps: float,
        idm: IdmParams,
        size_lwh_m: tuple[float, float, float],
        color_rgb: tuple[int, int, int],
        reflectivity: float = 0.5,
        lateral_offset_m: float = 0.0,
        obeys_lights: bool = True,
        brake_time_s: float | None = None,
        brake_decel_mps2: float = 6.0,
        lane_change: LaneChange | None = None,
    ) -> None:
        self.agent_id = agent_id
        self.object_class = object_class
        self.route = route
        self.s_m = float(s_m)
        self.speed_mps = float(speed_mps)
        self.accel_mps2 = 0.0
        self.idm = idm
        self.size_lwh_m = size_lwh_m
        self.color_rgb = color_rgb
        self.reflectivity = reflectivity
        self.lateral_offset_m = lateral_offset_m
        self.obeys_lights = obeys_lights
        self.brake_time_s = brake_time_s
        self.brake_decel_mps2 = brake_decel_mps2
        self.lane_change = lane_change


def advance_1d(s_m: float, speed_mps: float, accel_mps2: float, dt_s: float) -> tuple[float, float]:
    """Exact constant-acceleration motion over ``dt_s`` that stops at zero speed."""
    v1 = speed_mps + accel_mps2 * dt_s
    if v1 >= 0.0:
        return s_m + speed_mps * dt_s + 0.5 * accel_mps2 * dt_s * dt_s, v1
    return s_m + speed_mps * speed_mps / (-2.0 * accel_mps2), 0.0


class Walker:
    """A pedestrian walking in a straight line at constant speed once started, then standing.

    ``start_time_s`` may be ``None`` (waiting for a trigger: :meth:`start`).
    """

    def __init__(
        self,
        agent_id: int,
        *,
        start_xy: tuple[float, float],
        end_xy: tuple[float, float],
        speed_mps: float,
        start_time_s: float | None,
        size_lwh_m: tuple[float, float, float] = (0.5, 0.6, 1.75),
        color_rgb: tuple[int, int, int] = (200, 60, 60),
        reflectivity: float = 0.3,
    ) -> None:
        self.agent_id = agent_id
        self.object_class = ObjectClass.PEDESTRIAN
        self.start_xy = start_xy
        self.end_xy = end_xy
        self.speed_mps = speed_mps
        self.start_time_s = start_time_s
        self.size_lwh_m = size_lwh_m
        self.color_rgb = color_rgb
        self.reflectivity = reflectivity
        self.active = True
        dx, dy = end_xy[0] - start_xy[0], end_xy[1] - start_xy[1]
        self.distance_m = math.hypot(dx, dy)
        self.yaw_rad = math.atan2(dy, dx)
        self._time_s = 0.0

    def start(self, time_s: float) -> None:
        """Start walking at ``time_s`` (no effect if already scheduled)."""
        if self.start_time_s is None:
            self.start_time_s = time_s

    def walked_m(self) -> float:
        """Distance walked so far (metres)."""
        if self.start_time_s is None:
            return 0.0
        return min(max(self.speed_mps * (self._time_s - self.start_time_s), 0.0), self.distance_m)

    def is_walking(self) -> bool:
        return self.start_time_s is not None and 0.0 < self.walked_m() < self.distance_m

    def pose(self) -> tuple[float, float, float]:
        f = self.walked_m() / self.distance_m if self.distance_m > 0 else 0.0
        x = self.start_xy[0] + f * (self.end_xy[0] - self.start_xy[0])
        y = self.start_xy[1] + f * (self.end_xy[1] - self.start_xy[1])
        return x, y, self.yaw_rad

    def velocity(self) -> tuple[float, float]:
        if not self.is_walking():
            return 0.0, 0.0
        return self.speed_mps * math.cos(self.yaw_rad), self.speed_mps * math.sin(self.yaw_rad)

    def set_time(self, time_s: float) -> None:
        """Position is a pure function of time: set the clock (seconds since scenario start)."""
        self._time_s = time_s


@dataclass(frozen=True, slots=True, kw_only=True)
class ParkedObject:
    """A parked vehicle (ground truth, never moves): centre (metres), yaw (rad), size l/w/h."""

    agent_id: int
    object_class: ObjectClass
    center_xy: tuple[float, float]
    yaw_rad: float
    size_lwh_m: tuple[float, float, float]
    color_rgb: tuple[int, int, int]
    reflectivity: float = 0.5
