"""Ego motion → :class:`~redrive.types.VehicleState`.

* ``nav_msgs/msg/Odometry``: pose in ``header.frame_id``; the twist is in ``child_frame_id`` (the
  body) and is rotated into ``header.frame_id``, so ``velocity`` is in the state's frame;
  ``yaw_rate_rad_s`` is the z component of the rotated angular velocity.
* ``geometry_msgs/msg/PoseStamped`` / ``PoseWithCovarianceStamped``: position and heading only.
* ``geometry_msgs/msg/TwistStamped``: velocity and yaw rate in ``header.frame_id`` only.

Fields a message does not carry are zero.  A zero quaternion (some publishers' "unset") is read
as the identity.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.geometry.quaternion import rotation_matrix_from_quaternion, yaw_from_quaternion
from redrive.io.base import LogMessage
from redrive.io.decoders._common import header_stamp_ns, quat, unsupported, vec3
from redrive.io.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.types import SensorType, VehicleState

__all__ = ["OdometryDecoder", "PoseDecoder", "TwistDecoder"]


def _orientation(message: LogMessage, q_msg: Any) -> tuple[float, float, float, float]:
    q = quat(q_msg)
    if q == (0.0, 0.0, 0.0, 0.0):
        return (0.0, 0.0, 0.0, 1.0)
    if not all(np.isfinite(q)):
        raise unsupported(message, f"orientation {q} is not finite", "check the publisher")
    return q


def _state(
    message: LogMessage,
    msg: Any,
    *,
    pose: Any | None = None,
    twist: Any | None = None,
    twist_in_body: bool = False,
) -> Decoded:
    position: npt.NDArray[np.float64] = np.zeros(3)
    velocity: npt.NDArray[np.float64] = np.zeros(3)
    heading_rad = 0.0
    yaw_rate_rad_s = 0.0
    rotation = np.eye(3)
    if pose is not None:
        q = _orientation(message, pose.orientation)
        position = np.array(vec3(pose.position))
        heading_rad = yaw_from_quaternion(q)
        rotation = rotation_matrix_from_quaternion(q)
    if twist is not None:
        linear = np.array(vec3(twist.linear))
        angular = np.array(vec3(twist.angular))
        if twist_in_body:
            linear = rotation @ linear
            angular = rotation @ angular
        velocity = linear
        yaw_rate_rad_s = float(angular[2])
    stamp_ns = header_stamp_ns(msg.header, message)
    frame_id = str(msg.header.frame_id)
    value = VehicleState(
        stamp_ns=stamp_ns,
        frame_id=frame_id,
        position=position,
        velocity=velocity,
        heading_rad=heading_rad,
        yaw_rate_rad_s=yaw_rate_rad_s,
    )
    return Decoded(stamp_ns=stamp_ns, frame_id=frame_id, value=value)


class OdometryDecoder:
    """``nav_msgs/msg/Odometry`` → VehicleState in ``header.frame_id`` (twist rotated from body)."""

    name = "odometry"
    msgtypes: tuple[str, ...] = ("nav_msgs/msg/Odometry",)
    kind = DecodedKind.VEHICLE_STATE
    sensor_type: SensorType | None = SensorType.ODOMETRY

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        return _state(message, msg, pose=msg.pose.pose, twist=msg.twist.twist, twist_in_body=True)


class PoseDecoder:
    """``geometry_msgs/msg/PoseStamped`` and ``PoseWithCovarianceStamped`` → VehicleState."""

    name = "pose"
    msgtypes: tuple[str, ...] = (
        "geometry_msgs/msg/PoseStamped",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
    )
    kind = DecodedKind.VEHICLE_STATE
    sensor_type: SensorType | None = SensorType.ODOMETRY

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        pose = msg.pose.pose if hasattr(msg.pose, "covariance") else msg.pose
        return _state(message, msg, pose=pose)


class TwistDecoder:
    """``geometry_msgs/msg/TwistStamped`` → VehicleState (velocity, yaw rate in its frame)."""

    name = "twist"
    msgtypes: tuple[str, ...] = ("geometry_msgs/msg/TwistStamped",)
    kind = DecodedKind.VEHICLE_STATE
    sensor_type: SensorType | None = SensorType.ODOMETRY

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        return _state(message, msg, twist=msg.twist)
