"""Ego motion → :class:`~redrive.types.VehicleState`.

* ``nav_msgs/msg/Odometry``: pose in ``header.frame_id``; the twist is in ``child_frame_id`` (the
  body) and is rotated into ``header.frame_id``, so ``velocity`` is in the state's frame;
  ``yaw_rate_rad_s`` is the z component of the rotated angular velocity.
* ``geometry_msgs/msg/PoseStamped`` / ``PoseWithCovarianceStamped``: position and heading only.
* ``geometry_msgs/msg/TwistStamped``: velocity and yaw rate in ``header.frame_id`` only.

Fields a message does not carry are zero.  A zero quaternion (some publishers' "unset") is read
as the identity.

Odometry (100 Hz in many logs) is read straight from its bytes (ROS 1, or CDR in either byte
order): header, pose and twist without deserialising the two 36-element covariances into message
objects.  A message the byte reader does not take (a string that is not UTF-8, bytes of an
unexpected length) is deserialised as before; both give the same values.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.geometry.quaternion import rotation_matrix_from_quaternion, yaw_from_quaternion
from redrive.io.base import LogMessage
from redrive.io.ros.decoders._common import header_stamp_ns, quat, unsupported, vec3
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.types import SensorType, VehicleState

__all__ = ["OdometryDecoder", "PendingState", "PoseDecoder", "TwistDecoder"]


def _check_orientation(
    message: LogMessage, q: tuple[float, float, float, float]
) -> tuple[float, float, float, float]:
    if q == (0.0, 0.0, 0.0, 0.0):
        return (0.0, 0.0, 0.0, 1.0)
    if not all(np.isfinite(q)):
        raise unsupported(message, f"orientation {q} is not finite", "check the publisher")
    return q


#: A pose and a twist as float64s: position (3), orientation (4), linear (3), angular (3).
_Motion = tuple[
    tuple[float, float, float],
    tuple[float, float, float, float],
    tuple[float, float, float],
    tuple[float, float, float],
]


def _state(
    message: LogMessage,
    msg: Any,
    *,
    pose: Any | None = None,
    twist: Any | None = None,
    twist_in_body: bool = False,
) -> Decoded:
    return _state_of(
        message,
        stamp_ns=header_stamp_ns(msg.header, message),
        frame_id=str(msg.header.frame_id),
        position=None if pose is None else vec3(pose.position),
        orientation=None if pose is None else quat(pose.orientation),
        linear=None if twist is None else vec3(twist.linear),
        angular=None if twist is None else vec3(twist.angular),
        twist_in_body=twist_in_body,
    )


def _state_of(
    message: LogMessage,
    *,
    stamp_ns: int,
    frame_id: str,
    position: tuple[float, float, float] | None,
    orientation: tuple[float, float, float, float] | None,
    linear: tuple[float, float, float] | None,
    angular: tuple[float, float, float] | None,
    twist_in_body: bool,
) -> Decoded:
    heading_rad = 0.0
    yaw_rate_rad_s = 0.0
    rotation: npt.NDArray[np.float64] | None = None
    position_a: npt.NDArray[np.float64] | None = None
    velocity: npt.NDArray[np.float64] | None = None
    if position is not None and orientation is not None:
        q = _check_orientation(message, orientation)
        position_a = np.array(position)
        heading_rad = yaw_from_quaternion(q)
        rotation = rotation_matrix_from_quaternion(q)
    if linear is not None and angular is not None:
        linear_a = np.array(linear)
        angular_a = np.array(angular)
        if twist_in_body:
            if rotation is None:
                rotation = np.eye(3)
            linear_a = rotation @ linear_a
            angular_a = rotation @ angular_a
        velocity = linear_a
        yaw_rate_rad_s = float(angular_a[2])
    if position_a is None:
        position_a = np.zeros(3)
    if velocity is None:
        velocity = np.zeros(3)
    value = VehicleState(
        stamp_ns=stamp_ns,
        frame_id=frame_id,
        position=position_a,
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
        pending = self.read_pending(message)
        if pending is not None:
            return pending.decoded()
        msg: Any = deserialize(message)
        return _state(message, msg, pose=msg.pose.pose, twist=msg.twist.twist, twist_in_body=True)

    def read_pending(self, message: LogMessage) -> PendingState | None:
        """The message's stamp and values read from its bytes, its VehicleState built when
        asked (:class:`PendingState`); None when the bytes are not the plain layout.

        Raises:
            UnsupportedMessageError: what :meth:`decode` raises for it (a non-finite orientation).
        """
        read = _read_odometry(message)
        if read is None:
            return None
        stamp_ns, frame_id, motion = read
        q = _check_orientation(message, motion[1])
        pending = PendingState(message, stamp_ns or message.log_time_ns, frame_id, motion)
        if not _SURELY_USABLE[0] < sum(v * v for v in q) < _SURELY_USABLE[1]:
            pending.decoded()  # near a bound of quaternion_normalized: build it now, so that
            # a ValueError is raised where decode would raise it
        return pending


#: Squared quaternion norms far inside what quaternion_normalized accepts ([1e-12, inf) for the
#: norm), whatever the rounding of the sum.
_SURELY_USABLE = (1e-20, 1e300)


class PendingState:
    """An odometry message read from its bytes whose VehicleState is built on first use.

    The frame assembler reads every ego-state message (100 Hz in many logs) but interpolates
    each frame's state from the two around its stamp: building the others (arrays, rotation
    matrix, data-model checks) would be wasted.  :meth:`decoded` gives what
    :meth:`OdometryDecoder.decode` gives for the message, built once.
    """

    __slots__ = ("_decoded", "_frame_id", "_message", "_motion", "stamp_ns")

    def __init__(self, message: LogMessage, stamp_ns: int, frame_id: str, motion: _Motion) -> None:
        self.stamp_ns = stamp_ns
        self._message: LogMessage | None = message
        self._frame_id = frame_id
        self._motion = motion
        self._decoded: Decoded | None = None

    def decoded(self) -> Decoded:
        if self._decoded is None:
            assert self._message is not None
            position, orientation, linear, angular = self._motion
            self._decoded = _state_of(
                self._message,
                stamp_ns=self.stamp_ns,
                frame_id=self._frame_id,
                position=position,
                orientation=orientation,
                linear=linear,
                angular=angular,
                twist_in_body=True,
            )
            self._message = None  # its bytes (a view of a whole chunk) are no longer held
        return self._decoded

    @property
    def value(self) -> VehicleState:
        state = self.decoded().value
        assert isinstance(state, VehicleState)
        return state


_ROS1_ODOM_HEAD = struct.Struct("<IIII")  # seq, sec, nsec, frame_id length
_CDR_ODOM_HEAD = {False: struct.Struct("<iII"), True: struct.Struct(">iII")}  # sec, nsec, len
_U32 = {False: struct.Struct("<I"), True: struct.Struct(">I")}
# pose.pose: position 3, orientation 4; pose.covariance 36; twist.twist: linear 3, angular 3;
# twist.covariance 36 — all float64.
_ODOM_TAIL = {
    order: struct.Struct(f"{order}7d288x6d288x") for order in ("<", ">")
}  # 288 = 36 × 8 covariance bytes skipped


def _read_odometry(message: LogMessage) -> tuple[int, str, _Motion] | None:
    """(stamp ns, frame id, motion) of a serialised nav_msgs/Odometry, or None when the bytes
    are not the plain layout (the caller then deserialises)."""
    buf = message.raw
    try:
        if message.encoding == "ros1":
            _seq, sec, nanosec, size = _ROS1_ODOM_HEAD.unpack_from(buf, 0)
            pos = 16 + size
            frame_id = str(buf[16:pos], "utf-8")
            (child,) = _U32[False].unpack_from(buf, pos)
            pos += 4 + child
            tail = _ODOM_TAIL["<"]
        elif message.encoding == "cdr":
            if len(buf) < 4 or buf[0] != 0 or buf[1] not in (0, 1):
                return None
            big = buf[1] == 0
            sec, nanosec, size = _CDR_ODOM_HEAD[big].unpack_from(buf, 4)
            if size == 0 or buf[16 + size - 1] != 0:
                return None
            frame_id = str(buf[16 : 16 + size - 1], "utf-8")
            pos = 16 + size
            pos += -(pos - 4) % 4
            (child,) = _U32[big].unpack_from(buf, pos)
            pos += 4 + child
            pos += -(pos - 4) % 8
            tail = _ODOM_TAIL[">" if big else "<"]
        else:
            return None
        if pos + tail.size != len(buf):
            return None
        v = tail.unpack_from(buf, pos)
    except (struct.error, IndexError, UnicodeDecodeError):
        return None
    motion = (
        (v[0], v[1], v[2]),
        (v[3], v[4], v[5], v[6]),
        (v[7], v[8], v[9]),
        (v[10], v[11], v[12]),
    )
    return sec * 1_000_000_000 + nanosec, frame_id, motion


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
