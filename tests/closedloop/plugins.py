"""Planners for closed-loop tests: one that never moves, one that returns NaNs, one that plans
straight ahead at a fixed speed whatever is in the way; a perception that keeps the clouds it
was given."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from redrive.algorithms import Algorithm, Role, StageOutputs
from redrive.types import ControlCommands, DetectedObject, Frame, PlannedPath, PointCloud


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


class EmptyAfterTwoSeconds(Algorithm):
    """Plans straight at 10 m/s, then from frame 20 a path without waypoints."""

    role = Role.PLANNING

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        path = _straight(frame.stamp_ns, 10.0)
        if frame.index < 20:
            return path
        return PlannedPath(stamp_ns=frame.stamp_ns, waypoints=np.empty((0, 4)))


class CameraFrameAfterTwoSeconds(Algorithm):
    """Plans straight at 10 m/s, then from frame 20 the same path in a camera's frame."""

    role = Role.PLANNING

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        path = _straight(frame.stamp_ns, 10.0)
        if frame.index < 20:
            return path
        return PlannedPath(
            stamp_ns=frame.stamp_ns, waypoints=path.waypoints, frame_id="camera_front"
        )


class LoggedPathFollower(Algorithm):
    """Plans the log's own future: the logged ego poses of the next ``horizon_s`` seconds (read
    from the log named by ``log``), in the driven ego's base_link — a planner that tries to drive
    as the log did."""

    role = Role.PLANNING
    inputs = ("vehicle_state",)
    defaults = MappingProxyType({"log": "", "horizon_s": 4.0})

    def setup(self, config: Mapping[str, Any]) -> None:
        from redrive.assembly.sensor_map import infer_sensor_map
        from redrive.io import open_log
        from redrive.io.ros.decoders import decode
        from redrive.types import VehicleState

        self.horizon_ns = round(float(config["horizon_s"]) * 1e9)
        states: list[VehicleState] = []
        with open_log(str(config["log"])) as log:
            smap = infer_sensor_map(log.topics, duration_ns=log.end_ns - log.start_ns)
            assert smap.vehicle_state_topic is not None
            for message in log.messages(topics=[smap.vehicle_state_topic]):
                value = decode(message, log.deserialize).value
                if isinstance(value, VehicleState):
                    states.append(value)
        states.sort(key=lambda s: s.stamp_ns)
        self.stamps = np.array([s.stamp_ns for s in states], dtype=np.int64)
        self.xy = np.array([s.position[:2] for s in states], dtype=np.float64)

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        ego = frame.vehicle_state
        assert ego is not None
        # the logged positions every 0.5 s (odometry is noisy at 10 Hz: its differences would
        # make a jittery speed and acceleration profile), in the driven ego's base_link
        t = np.arange(0.0, self.horizon_ns / 1e9 + 1e-9, 0.5)
        at = frame.stamp_ns + np.round(t * 1e9).astype(np.int64)
        t = t[at <= self.stamps[-1]]
        if len(t) < 2:  # the end of the log: stand still
            return _straight(frame.stamp_ns, 0.0)
        rel = (at[: len(t)] - self.stamps[0]).astype(np.float64)
        stamps = (self.stamps - self.stamps[0]).astype(np.float64)
        d = np.column_stack(
            [np.interp(rel, stamps, self.xy[:, 0]), np.interp(rel, stamps, self.xy[:, 1])]
        )
        d -= ego.position[:2]
        c, s = np.cos(ego.heading_rad), np.sin(ego.heading_rad)
        x, y = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
        return PlannedPath(
            stamp_ns=frame.stamp_ns, waypoints=np.column_stack([x, y, np.zeros_like(t), t])
        )


#: frame index → the ``lidar_top`` cloud :class:`LidarWitness` was given (threads executor).
SEEN_CLOUDS: dict[int, PointCloud] = {}


class LidarWitness(Algorithm):
    """Detects nothing; keeps each frame's ``lidar_top`` cloud in :data:`SEEN_CLOUDS`."""

    role = Role.PERCEPTION
    inputs = ("lidar_top",)

    def step(self, frame: Frame, upstream: StageOutputs) -> tuple[DetectedObject, ...]:
        cloud = frame.sensors["lidar_top"].data
        assert isinstance(cloud, PointCloud)
        SEEN_CLOUDS[frame.index] = cloud
        return ()


class Weaver(Algorithm):
    """A control stage that steers to full lock, left then right, every ``half_period_s``, with
    the throttle at ``throttle`` — the weaving driver of issue 33 (81.6 m/s² lateral without a
    tyre limit)."""

    role = Role.CONTROL
    inputs = ("vehicle_state",)
    defaults = MappingProxyType({"half_period_s": 1.0, "throttle": 0.4, "steer_rad": 0.6})

    def setup(self, config: Mapping[str, Any]) -> None:
        self.half_period_ns = round(float(config["half_period_s"]) * 1e9)
        self.throttle = float(config["throttle"])
        self.steer_rad = float(config["steer_rad"])
        self.start_ns: int | None = None

    def reset(self) -> None:
        self.start_ns = None

    def step(self, frame: Frame, upstream: StageOutputs) -> ControlCommands:
        if self.start_ns is None:
            self.start_ns = frame.stamp_ns
        left = ((frame.stamp_ns - self.start_ns) // self.half_period_ns) % 2 == 0
        steer = self.steer_rad if left else -self.steer_rad
        return ControlCommands(throttle=self.throttle, steering_angle_rad=steer)


class WeavingPlanner(Algorithm):
    """Plans arcs of curvature ±``curvature_1pm`` at the current speed, turning left then right
    every ``half_period_s`` — a weaver through the built-in tracker."""

    role = Role.PLANNING
    inputs = ("vehicle_state",)
    defaults = MappingProxyType({"half_period_s": 1.0, "curvature_1pm": 0.25})

    def setup(self, config: Mapping[str, Any]) -> None:
        self.half_period_ns = round(float(config["half_period_s"]) * 1e9)
        self.curvature_1pm = float(config["curvature_1pm"])
        self.start_ns: int | None = None

    def reset(self) -> None:
        self.start_ns = None

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        assert frame.vehicle_state is not None
        if self.start_ns is None:
            self.start_ns = frame.stamp_ns
        left = ((frame.stamp_ns - self.start_ns) // self.half_period_ns) % 2 == 0
        kappa = self.curvature_1pm if left else -self.curvature_1pm
        speed = max(frame.vehicle_state.speed_mps, 1.0)
        t = np.arange(0.0, 3.0 + 1e-9, 0.1)
        angle = kappa * speed * t
        x, y = np.sin(angle) / kappa, (1.0 - np.cos(angle)) / kappa
        return PlannedPath(
            stamp_ns=frame.stamp_ns, waypoints=np.column_stack([x, y, np.zeros_like(t), t])
        )


class Jerky(Algorithm):
    """Plans straight ahead, its speed switching between ``slow_mps`` and ``fast_mps`` every
    ``period_s``: the tracker brakes and accelerates hard, again and again."""

    role = Role.PLANNING
    defaults = MappingProxyType({"slow_mps": 12.0, "fast_mps": 20.0, "period_s": 1.0})

    def setup(self, config: Mapping[str, Any]) -> None:
        self.slow_mps = float(config["slow_mps"])
        self.fast_mps = float(config["fast_mps"])
        self.period_ns = round(float(config["period_s"]) * 1e9)
        self.start_ns: int | None = None

    def reset(self) -> None:
        self.start_ns = None

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        if self.start_ns is None:
            self.start_ns = frame.stamp_ns
        phase = ((frame.stamp_ns - self.start_ns) // self.period_ns) % 2
        return _straight(frame.stamp_ns, self.slow_mps if phase else self.fast_mps)


class OffRoad(Algorithm):
    """Plans a left arc of radius ``radius_m`` at ``speed_mps``, blind to the map: on a real
    road it leaves the drivable area within seconds (the off-road planner of the map tests)."""

    role = Role.PLANNING
    defaults = MappingProxyType({"speed_mps": 8.0, "radius_m": 25.0})

    def setup(self, config: Mapping[str, Any]) -> None:
        self.speed_mps = float(config["speed_mps"])
        self.radius_m = float(config["radius_m"])

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        t = np.arange(0.0, 6.0 + 1e-9, 0.1)
        angle = self.speed_mps * t / self.radius_m
        x = self.radius_m * np.sin(angle)
        y = self.radius_m * (1.0 - np.cos(angle))
        return PlannedPath(
            stamp_ns=frame.stamp_ns, waypoints=np.column_stack([x, y, np.zeros_like(t), t])
        )


class MapReader(Algorithm):
    """Plans straight ahead at 8 m/s, and declares the road map as an input (not a sensor)."""

    role = Role.PLANNING
    inputs = ("vehicle_state", "road_map")

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        assert self.road_map is not None
        return _straight(frame.stamp_ns, 8.0)
