"""``sensor_msgs/msg/CameraInfo`` → :class:`~redrive.types.CameraInfo` (kind CAMERA_INFO).

ROS 1 spells the matrices ``D``, ``K``, ``R``, ``P``; ROS 2 ``d``, ``k``, ``r``, ``p`` (rosbags
keeps each store's names); both are read.  Binning and region of interest are not carried: the
matrices describe the full-resolution image.  A camera info is calibration, not a sensor sample:
the sensor map never makes its topic a sensor (see :mod:`redrive.assembly.calibration`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.io.base import LogMessage
from redrive.io.ros.decoders._common import header_stamp_ns, unsupported
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.types import CameraInfo, SensorType

__all__ = ["CameraInfoDecoder"]


def _matrix(msg: Any, name: str, shape: tuple[int, ...]) -> npt.NDArray[np.float64]:
    """Field ``name`` (ROS 2) or ``NAME`` (ROS 1) as a float64 array of ``shape`` (a copy)."""
    value = getattr(msg, name, None)
    if value is None:
        value = getattr(msg, name.upper())
    return np.array(value, dtype=np.float64).reshape(shape)


class CameraInfoDecoder:
    """``sensor_msgs/msg/CameraInfo`` (ROS 1 and ROS 2 field names) → CameraInfo."""

    name = "camera_info"
    msgtypes: tuple[str, ...] = ("sensor_msgs/msg/CameraInfo",)
    kind = DecodedKind.CAMERA_INFO
    sensor_type: SensorType | None = None

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        try:
            value = CameraInfo(
                width=int(msg.width),
                height=int(msg.height),
                k=_matrix(msg, "k", (3, 3)),
                d=_matrix(msg, "d", (-1,)),
                distortion_model=str(msg.distortion_model),
                r=_matrix(msg, "r", (3, 3)),
                p=_matrix(msg, "p", (3, 4)),
            )
        except (AttributeError, ValueError) as err:
            raise unsupported(
                message,
                f"CameraInfo cannot be decoded: {err}",
                "check the message definition (K/k 9, R/r 9, P/p 12 numbers) or skip this topic",
            ) from err
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=value,
        )
