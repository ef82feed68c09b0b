"""IMU, GNSS and 2D laser scans: ``sensor_msgs/msg/{Imu,NavSatFix,LaserScan}``.

LaserScan invalid ranges (NaN, ±inf, outside ``[range_min, range_max]``) are **kept as NaN
points**, never dropped: N equals ``len(ranges)`` so beam index ↔ point index holds, exactly as
for non-dense PointCloud2.  The ``range`` channel keeps the raw measured value of every beam.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from redrive.io.base import LogMessage
from redrive.io.ros.decoders._common import header_stamp_ns, quat, vec3
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.types import GnssFix, Imu, PointCloud, SensorType

__all__ = ["ImuDecoder", "LaserScanDecoder", "NavSatFixDecoder"]


class ImuDecoder:
    """``sensor_msgs/msg/Imu`` → Imu; orientation all-NaN when ``orientation_covariance[0] == -1``."""

    name = "imu"
    msgtypes: tuple[str, ...] = ("sensor_msgs/msg/Imu",)
    kind = DecodedKind.SENSOR
    sensor_type: SensorType | None = SensorType.IMU

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        if float(msg.orientation_covariance[0]) == -1.0:
            orientation = np.full(4, np.nan)
        else:
            orientation = np.array(quat(msg.orientation))
        value = Imu(
            linear_acceleration=np.array(vec3(msg.linear_acceleration)),
            angular_velocity=np.array(vec3(msg.angular_velocity)),
            orientation=orientation,
        )
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=value,
        )


#: NavSatFix.position_covariance_type COVARIANCE_TYPE_UNKNOWN.
_COVARIANCE_TYPE_UNKNOWN = 0


class NavSatFixDecoder:
    """``sensor_msgs/msg/NavSatFix`` → GnssFix (covariance NaN when its type is UNKNOWN)."""

    name = "navsatfix"
    msgtypes: tuple[str, ...] = ("sensor_msgs/msg/NavSatFix",)
    kind = DecodedKind.SENSOR
    sensor_type: SensorType | None = SensorType.GNSS

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        if int(msg.position_covariance_type) == _COVARIANCE_TYPE_UNKNOWN:
            cov = np.full((3, 3), np.nan)
        else:
            cov = np.asarray(msg.position_covariance, dtype=np.float64).reshape(3, 3).copy()
        value = GnssFix(
            latitude_deg=float(msg.latitude),
            longitude_deg=float(msg.longitude),
            altitude_m=float(msg.altitude),
            position_covariance_m2=cov,
            status=int(msg.status.status),
        )
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=value,
        )


class LaserScanDecoder:
    """``sensor_msgs/msg/LaserScan`` → PointCloud of 2D points (z = 0), invalid beams NaN.

    Channels: ``range`` (float32 m, the raw value of every beam) and ``intensity`` (float32, only
    when the scan has one intensity per beam).
    """

    name = "laserscan"
    msgtypes: tuple[str, ...] = ("sensor_msgs/msg/LaserScan",)
    kind = DecodedKind.SENSOR
    sensor_type: SensorType | None = SensorType.LIDAR_2D

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        msg: Any = deserialize(message)
        ranges = np.asarray(msg.ranges, dtype=np.float32)
        n = ranges.shape[0]
        angles = float(msg.angle_min) + float(msg.angle_increment) * np.arange(n, dtype=np.float64)
        valid = np.isfinite(ranges) & (ranges >= msg.range_min) & (ranges <= msg.range_max)
        r = np.where(valid, ranges, np.nan).astype(np.float64)
        xyz = np.zeros((n, 3), dtype=np.float32)
        xyz[:, 0] = r * np.cos(angles)
        xyz[:, 1] = r * np.sin(angles)
        xyz[~valid, 2] = np.nan
        channels = {"range": ranges.copy()}
        intensities = np.asarray(msg.intensities, dtype=np.float32)
        if intensities.shape == (n,):
            channels["intensity"] = intensities.copy()
        return Decoded(
            stamp_ns=header_stamp_ns(msg.header, message),
            frame_id=str(msg.header.frame_id),
            value=PointCloud(xyz=xyz, channels=channels),
        )
