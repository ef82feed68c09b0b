"""Ouster lidar packets → range image → point cloud, as ouster-sdk decodes them.

The packet layouts are ouster-sdk's (``ouster_core/src/parsing.cpp``, ``PacketFormat::Impl`` and
the ``*_FIELD_INFO`` tables) and the sensor's firmware user manual ("Lidar Data Format"):

* LEGACY: no packet header; each column a 16-byte header (timestamp u64, measurement id u16,
  frame id u16, encoder count u32), H pixels of 12 bytes, a 4-byte status footer;
* every other profile: a 32-byte packet header (packet type u16, frame id u16, init id …), each
  column a 12-byte header (timestamp u64, measurement id u16, status u16) and H pixels, a
  32-byte packet footer.

Pixel fields (bit offset, width, left shift) by profile — only what a cloud needs::

    LEGACY                       12 B  range 0,20   reflectivity 32,8  signal 48,16  near_ir 64,16
    RNG19_RFL8_SIG16_NIR16       12 B  range 0,19   reflectivity 24,8  signal 32,16  near_ir 48,16
    RNG19_RFL8_SIG16_NIR16_DUAL  16 B  range 0,19   reflectivity 24,8  signal 64,16  near_ir 96,16
    RNG15_RFL8_NIR8               4 B  range 0,15≪3 reflectivity 16,8  near_ir 24,8≪4
    RNG15_RFL8_NIR8_DUAL          8 B  range 0,15≪3 reflectivity 16,8  near_ir 24,8≪4

(dual profiles: the first, strongest return only).  As ouster-sdk's ``FrameBatcher``: the
packets of one frame id make one frame; a column goes to the range-image column its measurement
id names (ids ≥ W are dropped); a column whose status bit 0 is clear is no data.  The cloud holds
the pixels with a return (range > 0), in row-major order of the measured range image (row = beam,
``ring``; ``column`` = measurement id), at ``range · direction + offset``
(:func:`~redrive.io.ros.decoders.ouster_metadata.xyz_lut`), in the sensor frame.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.io.ros.decoders.ouster_metadata import OusterSensorInfo, xyz_lut
from redrive.types import PointCloud

__all__ = ["OusterFrame", "OusterPacketFormat"]


@dataclass(frozen=True, slots=True)
class _Field:
    name: str
    bit_start: int
    bit_size: int
    upshift: int = 0

    @property
    def dtype(self) -> type[np.unsignedinteger[Any]]:
        bits = self.bit_size + self.upshift
        return np.uint8 if bits <= 8 else np.uint16 if bits <= 16 else np.uint32


#: profile → (bytes a pixel, fields): ouster-sdk's ``*_FIELD_INFO`` (bit start, bits, upshift)
_PROFILES: dict[str, tuple[int, tuple[_Field, ...]]] = {
    "LEGACY": (
        12,
        (
            _Field("range", 0, 20),
            _Field("reflectivity", 32, 8),
            _Field("signal", 48, 16),
            _Field("near_ir", 64, 16),
        ),
    ),
    "RNG19_RFL8_SIG16_NIR16": (
        12,
        (
            _Field("range", 0, 19),
            _Field("reflectivity", 24, 8),
            _Field("signal", 32, 16),
            _Field("near_ir", 48, 16),
        ),
    ),
    "RNG19_RFL8_SIG16_NIR16_DUAL": (
        16,
        (
            _Field("range", 0, 19),
            _Field("reflectivity", 24, 8),
            _Field("signal", 64, 16),
            _Field("near_ir", 96, 16),
        ),
    ),
    "RNG15_RFL8_NIR8": (
        4,
        (_Field("range", 0, 15, 3), _Field("reflectivity", 16, 8), _Field("near_ir", 24, 8, 4)),
    ),
    "RNG15_RFL8_NIR8_DUAL": (
        8,
        (_Field("range", 0, 15, 3), _Field("reflectivity", 16, 8), _Field("near_ir", 24, 8, 4)),
    ),
}


@dataclass(frozen=True, slots=True, kw_only=True)
class OusterFrame:
    """One frame's range image and the fields beside it.

    Attributes:
        frame_id: the packets' frame id.
        fields: name → (H, W) image (``range`` in mm, ``reflectivity``, ``signal``, ``near_ir``).
        timestamp_ns: (W,) each column's timestamp (the sensor's clock), 0 where no column came.
        packets: how many packets made it.
    """

    frame_id: int
    fields: dict[str, npt.NDArray[Any]]
    timestamp_ns: npt.NDArray[np.uint64]
    packets: int


def _read_field(pixels: npt.NDArray[np.uint8], field: _Field) -> npt.NDArray[Any]:
    """A field of every pixel of (…, pixel bytes) little-endian bytes."""
    first = field.bit_start // 8
    shift = field.bit_start % 8
    n_bytes = (shift + field.bit_size + 7) // 8
    word = np.zeros(pixels.shape[:-1], np.uint32)
    for k in range(n_bytes):
        word |= pixels[..., first + k].astype(np.uint32) << np.uint32(8 * k)
    value = (word >> np.uint32(shift)) & np.uint32((1 << field.bit_size) - 1)
    if field.upshift:
        value <<= np.uint32(field.upshift)
    return value.astype(field.dtype)


class OusterPacketFormat:
    """The layout of one sensor's lidar packets (from its metadata) and their decoding.

    Raises:
        ValueError: a UDP profile or header type redrive does not decode.
    """

    def __init__(self, info: OusterSensorInfo) -> None:
        profile = _PROFILES.get(info.udp_profile_lidar)
        if profile is None:
            msg = (
                f"Ouster UDP profile {info.udp_profile_lidar!r} is not one redrive decodes "
                f"({', '.join(sorted(_PROFILES))})"
            )
            raise ValueError(msg)
        if info.header_type != "STANDARD":
            msg = f"Ouster packet header type {info.header_type!r} is not decoded (only STANDARD)"
            raise ValueError(msg)
        self.info = info
        self.legacy = info.udp_profile_lidar == "LEGACY"
        self.pixel_bytes, self.fields = profile
        self.packet_header = 0 if self.legacy else 32
        self.column_header = 16 if self.legacy else 12
        self.column_footer = 4 if self.legacy else 0
        self.column_bytes = (
            self.column_header + info.pixels_per_column * self.pixel_bytes + self.column_footer
        )
        packet_footer = 0 if self.legacy else 32
        self.packet_size = (
            self.packet_header + info.columns_per_packet * self.column_bytes + packet_footer
        )
        self._lut: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None

    @property
    def packets_per_frame(self) -> int:
        """Packets of a whole frame (of the column window)."""
        first, last = self.info.column_window
        columns = (last - first) % self.info.columns_per_frame + 1
        return -(-columns // self.info.columns_per_packet)

    def check(self, packet: bytes | memoryview | npt.NDArray[np.uint8]) -> str | None:
        """What is wrong with a packet's size, or None."""
        size = len(packet)
        if size == self.packet_size:
            return None
        return (
            f"an Ouster lidar packet of {size} bytes where the metadata's "
            f"{self.info.udp_profile_lidar} profile ({self.info.pixels_per_column} pixels × "
            f"{self.info.columns_per_packet} columns) makes {self.packet_size}"
        )

    def frame_id(self, packet: bytes | memoryview | npt.NDArray[np.uint8]) -> int:
        """The frame id of a packet of the right size."""
        at = 10 if self.legacy else 2
        return int(packet[at]) | (int(packet[at + 1]) << 8)

    def decode(self, packets: Sequence[bytes | memoryview | npt.NDArray[np.uint8]]) -> OusterFrame:
        """The frame of ``packets`` (all of the right size and of one frame id)."""
        info = self.info
        w, h, c = info.columns_per_frame, info.pixels_per_column, info.columns_per_packet
        buf = np.stack([np.frombuffer(p, np.uint8) for p in packets])
        cols = buf[:, self.packet_header : self.packet_header + c * self.column_bytes]
        cols = cols.reshape(len(packets), c, self.column_bytes)
        timestamps = cols[:, :, 0:8].copy().view("<u8")[..., 0]
        m_id = cols[:, :, 8].astype(np.int64) | (cols[:, :, 9].astype(np.int64) << 8)
        if self.legacy:
            status = cols[:, :, -4:].copy().view("<u4")[..., 0]
        else:
            status = cols[:, :, 10].astype(np.uint32) | (cols[:, :, 11].astype(np.uint32) << 8)
        valid = ((status & 1) != 0) & (m_id < w)
        pixels = cols[:, :, self.column_header : self.column_header + h * self.pixel_bytes]
        pixels = pixels.reshape(len(packets), c, h, self.pixel_bytes)[valid]  # (K, H, bytes)
        ids = m_id[valid]
        fields: dict[str, npt.NDArray[Any]] = {}
        for field in self.fields:
            image = np.zeros((h, w), field.dtype)
            image[:, ids] = _read_field(pixels, field).T
            fields[field.name] = image
        stamps = np.zeros(w, np.uint64)
        stamps[ids] = timestamps[valid]
        return OusterFrame(
            frame_id=self.frame_id(packets[0]),
            fields=fields,
            timestamp_ns=stamps,
            packets=len(packets),
        )

    def cloud(self, frame: OusterFrame) -> PointCloud:
        """The points of a frame's returns (see the module docstring) with their channels:
        ``intensity`` (signal where the profile has it, else reflectivity), ``reflectivity``,
        ``signal``, ``near_ir``, ``range_mm``, ``ring``, ``column``, ``t_offset_ns`` (the column's
        time after the frame's first column)."""
        if self._lut is None:
            self._lut = xyz_lut(self.info)
        direction, offset = self._lut
        w = self.info.columns_per_frame
        rng = frame.fields["range"].reshape(-1)
        hit = np.flatnonzero(rng)
        xyz = (rng[hit, None].astype(np.float64) * direction[hit] + offset[hit]).astype(np.float32)
        xyz.flags.writeable = False
        rows = (hit // w).astype(np.uint16)
        columns = (hit % w).astype(np.uint16)
        stamps = frame.timestamp_ns
        seen = stamps[stamps > 0]
        start = int(seen.min()) if seen.size else 0
        t_offset = stamps.astype(np.int64)[columns] - start
        channels: dict[str, npt.NDArray[Any]] = {
            name: image.reshape(-1)[hit] for name, image in frame.fields.items() if name != "range"
        }
        channels["intensity"] = channels.get("signal", channels["reflectivity"])
        channels["range_mm"] = rng[hit]
        channels["ring"] = rows
        channels["column"] = columns
        channels["t_offset_ns"] = t_offset
        return PointCloud(xyz=xyz, channels=channels)
