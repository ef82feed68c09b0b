"""Algorithms the engine tests run (importable as ``tests.engine.plugins:Name``, also by spawned
worker processes)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from redrive.algorithms import VEHICLE_STATE, Algorithm, Role, StageOutputs, StepResult
from redrive.types import (
    Box3D,
    ControlCommands,
    DetectedObject,
    Frame,
    ObjectClass,
    PlannedPath,
    PointCloud,
    SensorType,
)


class Centroid(Algorithm):
    """One box around the LiDAR points above the ground, with a running count as its id."""

    role = Role.PERCEPTION
    inputs = (SensorType.LIDAR,)
    defaults: Mapping[str, Any] = {"min_z_m": -1.5}

    def setup(self, config: Mapping[str, Any]) -> None:
        self.count = 0

    def reset(self) -> None:
        self.count = 0

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        cloud = self.sensor(frame, SensorType.LIDAR).data
        assert isinstance(cloud, PointCloud)
        pts = cloud.xyz[cloud.xyz[:, 2] > self.config["min_z_m"]].astype(np.float64)
        self.count += 1
        if len(pts) == 0:
            return []
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        box = Box3D(center=(lo + hi) / 2, size=hi - lo)
        return [DetectedObject(object_id=self.count, object_class=ObjectClass.VEHICLE, box=box)]


class FailEvery10th(Algorithm):
    """Raises on frames 0, 10, 20, …"""

    role = Role.PERCEPTION

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        if frame.index % 10 == 0:
            raise ValueError(f"planned failure on frame {frame.index}")
        return []


class HangOnce(Algorithm):
    """Sleeps far too long on one frame."""

    role = Role.PLANNING
    defaults: Mapping[str, Any] = {"frame": 3, "sleep_s": 60.0}

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        if frame.index == self.config["frame"]:
            time.sleep(self.config["sleep_s"])
        return PlannedPath(stamp_ns=frame.stamp_ns, waypoints=np.zeros((1, 4)))


class WrongType(Algorithm):
    """A control algorithm that returns a dict."""

    role = Role.CONTROL

    def step(self, frame: Frame, upstream: StageOutputs) -> Any:
        return {"throttle": 0.5}


class Slow(Algorithm):
    """Perception that takes ``sleep_s`` per frame."""

    role = Role.PERCEPTION
    defaults: Mapping[str, Any] = {"sleep_s": 0.1}

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        time.sleep(self.config["sleep_s"])
        return []


class Straight(Algorithm):
    """Straight ahead at the current speed, 3 s; the objects' count sets the last waypoint's z."""

    role = Role.PLANNING
    inputs = (VEHICLE_STATE,)

    def step(self, frame: Frame, upstream: StageOutputs) -> PlannedPath:
        assert frame.vehicle_state is not None
        speed = frame.vehicle_state.speed_mps
        t = np.linspace(0.0, 3.0, 7)
        z = np.zeros_like(t)
        z[-1] = len(upstream.objects() or ())
        return PlannedPath(stamp_ns=frame.stamp_ns, waypoints=np.c_[speed * t, 0 * t, z, t])


class FollowSpeed(Algorithm):
    """Throttle from the planned speed (a stand-in controller)."""

    role = Role.CONTROL

    def step(self, frame: Frame, upstream: StageOutputs) -> ControlCommands:
        path = upstream.path()
        if path is None:
            raise RuntimeError("no path upstream")
        wp = path.waypoints
        speed = float(wp[-1, 0] / wp[-1, 3]) if wp[-1, 3] > 0 else 0.0
        return ControlCommands(throttle=min(1.0, speed / 20.0))


class NeedsCamera(Algorithm):
    """Needs a camera (the test logs have none)."""

    role = Role.PERCEPTION
    inputs = (SensorType.CAMERA,)

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        return []


class OnlyDeclared(Algorithm):
    """Fails if the frame holds a sensor it did not declare."""

    role = Role.PERCEPTION
    inputs = (SensorType.LIDAR,)

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        extra = set(frame.sensors) - set(self.bound_inputs.values())
        if extra:
            raise AssertionError(f"undeclared sensors in the frame: {sorted(extra)}")
        return []


class OwnRunStep(Algorithm):
    """Overrides ``run_step``: the engine must keep running it through that."""

    role = Role.CONTROL

    def step(self, frame: Frame, upstream: StageOutputs) -> ControlCommands:
        return ControlCommands(throttle=0.1)

    def run_step(self, frame: Frame, upstream: StageOutputs) -> StepResult:
        return replace(super().run_step(frame, upstream), output=ControlCommands(throttle=0.5))


class Hog(Algorithm):
    """Allocates (and touches) ``mib`` MiB on frame ``frame``; keeps it when ``keep``."""

    role = Role.PERCEPTION
    defaults: Mapping[str, Any] = {"frame": 2, "mib": 1024, "keep": True}

    def setup(self, config: Mapping[str, Any]) -> None:
        self.kept: list[np.ndarray] = []

    def step(self, frame: Frame, upstream: StageOutputs) -> list[DetectedObject]:
        if frame.index == self.config["frame"]:
            block = np.ones(self.config["mib"] << 17)  # float64: 8 bytes each, every page touched
            if self.config["keep"]:
                self.kept.append(block)
            del block
        return []
