"""``velodyne_msgs/msg/VelodyneScan`` → :class:`~redrive.types.PointCloud`: one scan, one cloud.

A VelodyneScan is the packets the driver gathered for one revolution (``ros-drivers/velodyne``
and nebula cut them where the azimuth passes the scan phase).  The packets are read straight
from the serialised bytes — ROS 1 or CDR in either byte order, no deserialising: every packet is
a ``builtin_interfaces/Time`` and 1206 data bytes, so the packet data is one strided numpy view
— and decoded by :func:`~redrive.io.ros.decoders.velodyne_packets.decode_packets` with nebula's
default settings (0.3 m … 300 m, no azimuth crop).  The model (VLP-16, VLP-32C, HDL-32E) and the
return mode come from the packets' factory bytes.

Channels: ``intensity`` (uint8), ``ring`` (uint16, 0 = lowest laser), ``return_type`` (uint8,
nebula's ReturnType), ``azimuth_rad`` (float32), ``distance_m`` (float32), ``t_offset_ns``
(int64: the firing's time after the cloud's stamp, from the packet stamps and nebula's timing
table).  The cloud's stamp is the scan header's (the log time when it is zero); the frame is the
header's ``frame_id``.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.io.base import LogMessage
from redrive.io.ros.decoders._common import unsupported
from redrive.io.ros.decoders.base import Decoded, DecodedKind, Deserialize
from redrive.io.ros.decoders.velodyne_packets import (
    PACKET_SIZE_BYTES,
    VelodynePoints,
    VelodyneSettings,
    decode_packets,
)
from redrive.types import PointCloud, SensorType

__all__ = ["ScanPackets", "VelodyneScanDecoder", "points_cloud", "read_scan_packets"]

_ROS1_PACKET = 8 + PACKET_SIZE_BYTES  # time + data, no padding
_CDR_PACKET = 8 + PACKET_SIZE_BYTES + 2  # the next packet's Time aligns to 4


class ScanPackets:
    """The packets of one serialised VelodyneScan, viewed in place.

    Attributes:
        stamp_ns: the header stamp (0 when unset).
        frame_id: the header frame.
        data: uint8 (P, 1206), a read-only strided view of the message bytes.
        stamps_ns: int64 (P,), each packet's stamp.
    """

    __slots__ = ("data", "frame_id", "stamp_ns", "stamps_ns")

    def __init__(
        self,
        *,
        stamp_ns: int,
        frame_id: str,
        data: npt.NDArray[np.uint8],
        stamps_ns: npt.NDArray[np.int64],
    ) -> None:
        self.stamp_ns = stamp_ns
        self.frame_id = frame_id
        self.data = data
        self.stamps_ns = stamps_ns


def read_scan_packets(raw: bytes | memoryview, encoding: str) -> ScanPackets:
    """Parse a serialised VelodyneScan (``encoding`` ``ros1`` or ``cdr``).

    Raises:
        ValueError: the bytes are truncated, or hold fewer bytes than their packets need.
    """
    buf = raw if isinstance(raw, bytes) else bytes(raw)
    try:
        if encoding == "ros1":
            order, pos = "<", 0
            _seq, sec, nsec, length = struct.unpack_from("<IIII", buf, 0)
            pos = 16
        elif encoding == "cdr":
            if len(buf) < 4 or buf[0] != 0 or buf[1] not in (0, 1):
                msg = "not a plain CDR message (unknown representation header)"
                raise ValueError(msg)
            order = "<" if buf[1] == 1 else ">"
            sec, nsec, length = struct.unpack_from(order + "iII", buf, 4)
            pos = 16
        else:
            msg = f"unknown encoding {encoding!r}"
            raise ValueError(msg)
        end = pos + length
        if end > len(buf):
            msg = f"the frame_id runs past the message's {len(buf)} bytes"
            raise ValueError(msg)
        frame = buf[pos:end]
        if encoding == "cdr":
            frame = frame.rstrip(b"\x00")
            end += -(end - 4) % 4
        (count,) = struct.unpack_from(order + "I", buf, end)
    except struct.error as err:
        msg = f"the message is truncated ({len(buf)} bytes): {err}"
        raise ValueError(msg) from err
    first = end + 4
    stride = _ROS1_PACKET if encoding == "ros1" else _CDR_PACKET
    need = first + (count - 1) * stride + _ROS1_PACKET if count else first
    if need > len(buf):
        msg = (
            f"{count} packets need {need} bytes, the message has {len(buf)}: it is truncated or "
            "its packets are not 1206 bytes"
        )
        raise ValueError(msg)
    data = np.ndarray((count, PACKET_SIZE_BYTES), np.uint8, buf, first + 8, (stride, 1))
    dt = np.dtype([("sec", order + "i4"), ("nsec", order + "u4")])
    times = np.ndarray((count,), dt, buf, first, (stride,))
    stamps = times["sec"].astype(np.int64) * 1_000_000_000 + times["nsec"].astype(np.int64)
    data.flags.writeable = False
    return ScanPackets(
        stamp_ns=int(sec) * 1_000_000_000 + int(nsec),
        frame_id=frame.decode("utf-8", errors="replace"),
        data=data,
        stamps_ns=stamps,
    )


def points_cloud(points: VelodynePoints, t_offset_ns: npt.NDArray[np.int64]) -> PointCloud:
    """A PointCloud of decoded points with the channels the module names."""
    channels: dict[str, npt.NDArray[Any]] = {
        "intensity": points.intensity,
        "ring": points.ring,
        "return_type": points.return_type,
        "azimuth_rad": points.azimuth_rad,
        "distance_m": points.distance_m,
        "t_offset_ns": t_offset_ns,
    }
    return PointCloud(xyz=points.xyz, channels=channels)


class VelodyneScanDecoder:
    """``velodyne_msgs/msg/VelodyneScan`` → PointCloud (see the module docstring).

    Args:
        settings: range limits and azimuth crop; nebula's defaults when None.
    """

    name = "velodyne-scan"
    msgtypes: tuple[str, ...] = ("velodyne_msgs/msg/VelodyneScan",)
    kind = DecodedKind.SENSOR
    sensor_type: SensorType | None = SensorType.LIDAR

    def __init__(self, settings: VelodyneSettings | None = None) -> None:
        self.settings = settings or VelodyneSettings()

    def decode(self, message: LogMessage, deserialize: Deserialize) -> Decoded:
        del deserialize  # the packets are viewed in the serialised bytes
        try:
            scan = read_scan_packets(message.raw, message.encoding)
            if scan.data.shape[0] == 0:
                msg = "the scan holds no packets"
                raise ValueError(msg)
            points = decode_packets(scan.data, settings=self.settings)
        except ValueError as err:
            raise unsupported(
                message,
                f"VelodyneScan cannot be decoded: {err}",
                "check that the topic carries VLP-16, VLP-32C or HDL-32E packets (the factory "
                "bytes name the model), or skip the topic",
            ) from err
        stamp_ns = scan.stamp_ns or int(scan.stamps_ns[0]) or message.log_time_ns
        packet_offset = np.where(scan.stamps_ns > 0, scan.stamps_ns - stamp_ns, 0)
        t_offset = packet_offset[points.packet] + points.firing_offset_ns
        return Decoded(
            stamp_ns=stamp_ns, frame_id=scan.frame_id, value=points_cloud(points, t_offset)
        )
