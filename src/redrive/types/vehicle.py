"""Ego motion and the outputs of planning and control."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from redrive.types._arrays import frozen_array, frozen_vector

__all__ = ["ControlCommands", "PlannedPath", "VehicleState"]


def _zeros3() -> npt.NDArray[np.float64]:
    return np.zeros(3, dtype=np.float64)


@dataclass(frozen=True, slots=True, kw_only=True)
class VehicleState:
    """The ego state (rear-axle centre) at one instant.

    Attributes:
        stamp_ns: time, int ns since the epoch.
        frame_id: the frame ``position`` and ``heading_rad`` are expressed in (``map``, ``odom``).
        position: (3,) float64 metres.
        velocity: (3,) float64 m/s, in ``frame_id`` (not the body frame).
        acceleration: (3,) float64 m/s², in ``frame_id``.
        heading_rad: yaw about +z of ``frame_id``.
        yaw_rate_rad_s: rate of ``heading_rad``.
    """

    stamp_ns: int
    frame_id: str = "map"
    position: npt.NDArray[np.float64] = field(default_factory=_zeros3)
    velocity: npt.NDArray[np.float64] = field(default_factory=_zeros3)
    acceleration: npt.NDArray[np.float64] = field(default_factory=_zeros3)
    heading_rad: float = 0.0
    yaw_rate_rad_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))
        for name in ("position", "velocity", "acceleration"):
            vec = frozen_vector(getattr(self, name), name=f"VehicleState.{name}", size=3)
            object.__setattr__(self, name, vec)
        object.__setattr__(self, "heading_rad", float(self.heading_rad))
        object.__setattr__(self, "yaw_rate_rad_s", float(self.yaw_rate_rad_s))

    @property
    def speed_mps(self) -> float:
        # np.linalg.norm's own arithmetic for a float vector (sqrt of x·x; the same bits),
        # without its Python-level dispatch
        xy = self.velocity[:2]
        return math.sqrt(xy.dot(xy))


@dataclass(frozen=True, slots=True, kw_only=True)
class PlannedPath:
    """A planned trajectory.

    Attributes:
        stamp_ns: when the plan was made.
        waypoints: float64 (K, 4): x, y, z in metres (base_link of ``stamp_ns`` unless
            ``frame_id`` says otherwise) and t_s, seconds relative to ``stamp_ns``.
        frame_id: frame of the waypoints.
    """

    stamp_ns: int
    waypoints: npt.NDArray[np.float64]
    frame_id: str = "base_link"

    def __post_init__(self) -> None:
        wp = self.waypoints
        if isinstance(wp, np.ndarray) and wp.dtype != np.float64:
            wp = wp.astype(np.float64)
        wp = frozen_array(wp, name="PlannedPath.waypoints", dtype=np.float64, shape=(None, 4))
        t_s = wp[:, 3]
        # t[i+1] < t[i] exactly when np.diff's t[i+1] - t[i] < 0 (IEEE subtraction keeps the
        # sign; NaN and inf - inf fail both): one ufunc, not np.diff's Python wrapper
        if wp.shape[0] > 1 and (t_s[1:] < t_s[:-1]).any():
            msg = "PlannedPath.waypoints: t_s (column 3) must not decrease"
            raise ValueError(msg)
        object.__setattr__(self, "waypoints", wp)


@dataclass(frozen=True, slots=True, kw_only=True)
class ControlCommands:
    """Actuator commands.

    Attributes:
        throttle: in [0, 1].
        brake: in [0, 1].
        steering_angle_rad: road-wheel angle, positive to the left (REP-103).
    """

    throttle: float = 0.0
    brake: float = 0.0
    steering_angle_rad: float = 0.0

    def __post_init__(self) -> None:
        for name in ("throttle", "brake"):
            value = float(getattr(self, name))
            if not 0.0 <= value <= 1.0:
                msg = f"ControlCommands.{name} must lie in [0, 1], got {value}"
                raise ValueError(msg)
            object.__setattr__(self, name, value)
        if not math.isfinite(self.steering_angle_rad):
            msg = (
                f"ControlCommands.steering_angle_rad must be finite, got {self.steering_angle_rad}"
            )
            raise ValueError(msg)
        object.__setattr__(self, "steering_angle_rad", float(self.steering_angle_rad))
