"""Typed payloads: a :class:`~redrive.types.SensorData` as arrays in a slot plus a small binary
header in the slot's meta — no pickle, one copy per array on the way in, none on the way out.

Meta layout (little-endian, ``struct``)::

    u8 version, u8 payload kind, u8 sensor type, u8 number of arrays
    i64 stamp_ns, f64 frame_rate_hz, i32 resolution w, i32 resolution h (−1: none), 3 × f64 location
    strings (u16 length + UTF-8): sensor_id, frame_id, text (image encoding / vehicle frame)
    per array: name (u8 length + ASCII), dtype (u8 length + ``dtype.str``), u8 ndim,
               ndim × i64 shape, u64 offset in the payload (64-byte aligned)

Payload kinds and their arrays: ``PointCloud`` — ``xyz`` and one per channel (``c:<name>``);
``Image`` — ``pixels``; ``Imu`` — ``imu`` (10 float64: acceleration, angular velocity,
orientation); ``GnssFix`` — ``fix`` (4 float64: lat, lon, alt, status) and ``cov`` (3, 3);
``VehicleState`` — ``state`` (12 float64: stamp, position, velocity, acceleration, heading,
yaw rate).

A second kind of message, :data:`KIND_ROS1`, carries one ROS 1 message as its serialised bytes
(what a rospy ``AnyMsg`` subscriber receives) with the topic, type and md5sum in the meta: the
ROS scraper forwards bytes and the core decodes them with redrive's decoders.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import TransportError
from redrive.types import GnssFix, Image, Imu, PointCloud, SensorData, SensorType, VehicleState

__all__ = [
    "KIND_CDR",
    "KIND_RAW",
    "KIND_ROS1",
    "KIND_SENSOR",
    "Ros1Message",
    "decode_ros1",
    "decode_sample",
    "encode_ros1_meta",
    "encoded_size",
    "write_sample",
]

KIND_RAW = 0
KIND_SENSOR = 1
KIND_ROS1 = 2
#: one ROS 2 message as its CDR bytes (the ROS 2 scraper); the stream's spec says its type.
KIND_CDR = 3

_VERSION = 1
_HEAD = struct.Struct("<BBBBqdii3d")
_ALIGN = 64
_P_CLOUD, _P_IMAGE, _P_IMU, _P_GNSS, _P_STATE = 1, 2, 3, 4, 5
_SENSOR_TYPES = list(SensorType)


def _arrays(sample: SensorData) -> tuple[int, str, list[tuple[str, npt.NDArray[Any]]]]:
    data = sample.data
    if isinstance(data, PointCloud):
        arrays = [("xyz", data.xyz)] + [(f"c:{k}", v) for k, v in data.channels.items()]
        return _P_CLOUD, "", arrays
    if isinstance(data, Image):
        return _P_IMAGE, data.encoding, [("pixels", data.pixels)]
    if isinstance(data, Imu):
        vec = np.concatenate([data.linear_acceleration, data.angular_velocity, data.orientation])
        return _P_IMU, "", [("imu", vec)]
    if isinstance(data, GnssFix):
        fix = np.array(
            [data.latitude_deg, data.longitude_deg, data.altitude_m, data.status], np.float64
        )
        return _P_GNSS, "", [("fix", fix), ("cov", data.position_covariance_m2)]
    if isinstance(data, VehicleState):
        state = np.concatenate(
            [
                [float(data.stamp_ns)],
                data.position,
                data.velocity,
                data.acceleration,
                [data.heading_rad, data.yaw_rate_rad_s],
            ]
        )
        extra = np.array([data.stamp_ns], np.int64)
        return _P_STATE, data.frame_id, [("state", state), ("stamp", extra)]
    msg = f"cannot send a {type(data).__name__} through the transport"
    raise TransportError(msg)


def _str16(text: str) -> bytes:
    raw = text.encode()
    return struct.pack("<H", len(raw)) + raw


def _str8(text: str) -> bytes:
    raw = text.encode()
    return struct.pack("<B", len(raw)) + raw


@dataclass(frozen=True, slots=True)
class _Plan:
    meta: bytes
    total: int
    parts: list[tuple[int, npt.NDArray[Any]]]


def _plan(sample: SensorData) -> _Plan:
    kind, text, arrays = _arrays(sample)
    res = sample.resolution or (-1, -1)
    head = _HEAD.pack(
        _VERSION,
        kind,
        _SENSOR_TYPES.index(sample.sensor_type),
        len(arrays),
        sample.stamp_ns,
        sample.frame_rate_hz,
        int(res[0]),
        int(res[1]),
        *sample.sensor_location,
    )
    chunks = [head, _str16(sample.sensor_id), _str16(sample.frame_id), _str16(text)]
    parts, offset = [], 0
    for name, arr in arrays:
        a = np.ascontiguousarray(arr)
        chunks += [_str8(name), _str8(a.dtype.str), struct.pack("<B", a.ndim)]
        chunks.append(struct.pack(f"<{a.ndim}q", *a.shape))
        chunks.append(struct.pack("<Q", offset))
        parts.append((offset, a))
        offset = (offset + a.nbytes + _ALIGN - 1) // _ALIGN * _ALIGN
    return _Plan(meta=b"".join(chunks), total=offset, parts=parts)


def encoded_size(sample: SensorData) -> int:
    """Payload bytes ``sample`` takes in a slot."""
    return _plan(sample).total


def write_sample(loan: Callable[..., Any], sample: SensorData, **kwargs: Any) -> int:
    """Write ``sample`` through ``Writer.loan`` (passed in): one copy per array.

    Returns:
        the payload size written.
    """
    plan = _plan(sample)
    with loan(
        plan.total, stamp_ns=sample.stamp_ns, kind=KIND_SENSOR, meta=plan.meta, **kwargs
    ) as out:
        for offset, arr in plan.parts:
            dst = out[offset : offset + arr.nbytes]
            np.copyto(dst, arr.reshape(-1).view(np.uint8))
    return plan.total


class _Cursor:
    def __init__(self, meta: bytes) -> None:
        self.meta, self.pos = meta, 0

    def take(self, fmt: str) -> tuple[Any, ...]:
        size = struct.calcsize(fmt)
        out = struct.unpack_from(fmt, self.meta, self.pos)
        self.pos += size
        return out

    def text(self, width: str) -> str:
        (n,) = self.take(width)
        raw = self.meta[self.pos : self.pos + n]
        self.pos += n
        return raw.decode()


def decode_sample(meta: bytes, payload: npt.NDArray[np.uint8]) -> SensorData:
    """A :data:`KIND_SENSOR` message back as ``SensorData``; arrays are views of ``payload``
    (an owned copy from ``Reader.read``: keep them; a view from ``Reader.view``: use them only
    inside its ``with``).

    Raises:
        TransportError: the meta is not a sensor sample of this version.
    """
    try:
        cur = _Cursor(meta)
        version, kind, stype, n_arrays, stamp, rate, rw, rh, lx, ly, lz = cur.take(_HEAD.format)
        if version != _VERSION:
            msg = f"sensor sample of codec version {version} (this redrive reads {_VERSION})"
            raise TransportError(msg)
        sensor_id, frame_id, text = cur.text("<H"), cur.text("<H"), cur.text("<H")
        arrays: dict[str, npt.NDArray[Any]] = {}
        for _ in range(n_arrays):
            name, dtype = cur.text("<B"), np.dtype(cur.text("<B"))
            (ndim,) = cur.take("<B")
            shape = cur.take(f"<{ndim}q")
            (offset,) = cur.take("<Q")
            count = int(np.prod(shape)) if ndim else 1
            arr = payload[offset : offset + count * dtype.itemsize].view(dtype).reshape(shape)
            arrays[name] = arr
    except (struct.error, ValueError, IndexError, UnicodeDecodeError) as err:
        msg = f"a sensor message with an unreadable header: {err}"
        raise TransportError(msg) from err
    data: Any
    if kind == _P_CLOUD:
        channels = {k[2:]: v for k, v in arrays.items() if k.startswith("c:")}
        data = PointCloud(xyz=arrays["xyz"], channels=channels)
    elif kind == _P_IMAGE:
        data = Image(pixels=arrays["pixels"], encoding=text)
    elif kind == _P_IMU:
        v = arrays["imu"]
        data = Imu(linear_acceleration=v[0:3], angular_velocity=v[3:6], orientation=v[6:10])
    elif kind == _P_GNSS:
        f = arrays["fix"]
        data = GnssFix(
            latitude_deg=float(f[0]),
            longitude_deg=float(f[1]),
            altitude_m=float(f[2]),
            status=int(f[3]),
            position_covariance_m2=arrays["cov"],
        )
    elif kind == _P_STATE:
        s = arrays["state"]
        data = VehicleState(
            stamp_ns=int(arrays["stamp"][0]),
            frame_id=text,
            position=s[1:4],
            velocity=s[4:7],
            acceleration=s[7:10],
            heading_rad=float(s[10]),
            yaw_rate_rad_s=float(s[11]),
        )
    else:
        msg = f"unknown sensor payload kind {kind}"
        raise TransportError(msg)
    return SensorData(
        sensor_id=sensor_id,
        sensor_type=_SENSOR_TYPES[stype],
        stamp_ns=stamp,
        frame_id=frame_id,
        frame_rate_hz=rate,
        resolution=None if rw < 0 else (rw, rh),
        sensor_location=(lx, ly, lz),
        data=data,
    )


@dataclass(frozen=True, slots=True)
class Ros1Message:
    """A ROS 1 message as received by a rospy ``AnyMsg`` subscriber."""

    topic: str
    msg_type: str
    md5sum: str
    data: bytes | npt.NDArray[np.uint8]


def encode_ros1_meta(topic: str, msg_type: str, md5sum: str) -> bytes:
    """The meta of a :data:`KIND_ROS1` message (stdlib only: usable without numpy)."""
    return _str16(topic) + _str16(msg_type) + _str16(md5sum)


def decode_ros1(meta: bytes, payload: npt.NDArray[np.uint8]) -> Ros1Message:
    cur = _Cursor(meta)
    try:
        topic, msg_type, md5 = cur.text("<H"), cur.text("<H"), cur.text("<H")
    except (struct.error, UnicodeDecodeError) as err:
        msg = f"a ROS 1 message with an unreadable header: {err}"
        raise TransportError(msg) from err
    return Ros1Message(topic=topic, msg_type=msg_type, md5sum=md5, data=payload)
