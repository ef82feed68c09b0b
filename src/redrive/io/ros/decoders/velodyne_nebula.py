"""Re-cut a stream of Velodyne packets into clouds where nebula's driver cuts them.

A VelodyneScan message is the recording driver's scan; nebula's driver, fed the same packets one
at a time, starts a new cloud where the azimuth passes its ``scan_phase``, so its clouds straddle
the messages.  :class:`NebulaScanAssembler` reproduces that stream decoder
(``tier4/nebula``, ``velodyne_scan_decoder.hpp`` ``check_and_handle_scan_complete`` and
``{vlp16,vlp32}_decoder.cpp`` ``get_pointcloud`` / ``reset_pointcloud`` / ``reset_overflow``):

* a packet completes a scan when, phase-shifted, its last block's azimuth is below its first's or
  its first is below the previous packet's (never the first packet of a scan);
* at completion the points at the end of the scan lying within a quarter turn past the phase
  move to the next cloud (the VLP-16 decoder compares whole degrees, the 32-laser decoder
  radians — nebula's two formulas, kept);
* those carried-over points are dropped when the next packet comes more than 0.05 s after the
  first of them (nebula: "probably a packet drop").

Use it to get nebula's clouds from a log (``feed`` the packets of each message in order); the
per-message decoder (:class:`~redrive.io.ros.decoders.velodyne.VelodyneScanDecoder`) gives the
recording driver's scans instead.  Points are decoded with numpy per fed batch; the cut runs once
per packet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.io.ros.decoders.velodyne import points_cloud
from redrive.io.ros.decoders.velodyne_packets import (
    VelodynePoints,
    VelodyneSettings,
    decode_packets,
)
from redrive.types import PointCloud

__all__ = ["NebulaCloud", "NebulaScanAssembler"]

_FULL_TURN = 36000
_OVERFLOW_GAP_S = 0.05


@dataclass(frozen=True, slots=True, kw_only=True)
class NebulaCloud:
    """One cloud nebula's driver emits.

    Attributes:
        stamp_s: nebula's ``scan_timestamp_`` (the packet time it started at), seconds.
        cloud: the points; ``t_offset_ns`` is nebula's per-point ``time_stamp``.
    """

    stamp_s: float
    cloud: PointCloud


@dataclass(slots=True)
class _Chunk:
    points: VelodynePoints
    index: npt.NDArray[np.int64]
    ts_ns: npt.NDArray[np.int64]


class NebulaScanAssembler:
    """nebula's streaming Velodyne decoder (see the module docstring).

    Args:
        scan_phase_deg: where clouds start (nebula's ``scan_phase``).
        settings: range limits and crop (nebula's ``min_range`` … ``cloud_max_angle``).
    """

    def __init__(
        self, *, scan_phase_deg: float = 0.0, settings: VelodyneSettings | None = None
    ) -> None:
        self.settings = settings or VelodyneSettings()
        self.phase_deg = scan_phase_deg
        self._phase = round(scan_phase_deg * 100)
        self._scan: list[_Chunk] = []
        self._overflow: _Chunk | None = None
        self._has_scanned = False
        self._processed = 0
        self._prev_first = 0
        self._scan_ts = -1.0
        self._last_block_ts = 0.0

    def feed(
        self, packets: npt.NDArray[np.uint8], packet_seconds: npt.NDArray[np.float64]
    ) -> list[NebulaCloud]:
        """Feed packets (P, 1206) with their times (P,) in seconds; the clouds they complete.

        Raises:
            ValueError: as :func:`~redrive.io.ros.decoders.velodyne_packets.decode_packets`.
        """
        points = decode_packets(packets, settings=self.settings)
        bounds = np.searchsorted(points.packet, np.arange(packets.shape[0] + 1))
        first_az = packets[:, 2].astype(np.int64) | (packets[:, 3].astype(np.int64) << 8)
        last_az = packets[:, 1102].astype(np.int64) | (packets[:, 1103].astype(np.int64) << 8)
        out: list[NebulaCloud] = []
        for p in range(packets.shape[0]):
            t = float(packet_seconds[p])
            if self._has_scanned:
                self._processed = 0
                self._scan = []
                self._reset_overflow(t)
            self._processed += 1
            first = (_FULL_TURN + int(first_az[p]) - self._phase) % _FULL_TURN
            last = (_FULL_TURN + int(last_az[p]) - self._phase) % _FULL_TURN
            self._has_scanned = self._processed > 1 and (last < first or first < self._prev_first)
            self._prev_first = first
            if self._scan_ts < 0:
                self._scan_ts = t
            index = np.arange(bounds[p], bounds[p + 1], dtype=np.int64)
            if index.size:
                # nebula keeps its timing table in float32 seconds
                offset_s = (
                    (points.firing_offset_ns[index] * 1e-9).astype(np.float32).astype(np.float64)
                )
                ts = np.floor(np.maximum(t - self._scan_ts + offset_s, 0.0) * 1e9)
                self._scan.append(_Chunk(points, index, ts.astype(np.int64)))
                self._last_block_ts = t
            if self._has_scanned:
                out.append(self._emit(sixteen=points.model.firings_per_block == 2))
        return out

    def _reset_overflow(self, t: float) -> None:
        overflow, self._overflow = self._overflow, None
        if overflow is None or overflow.index.size == 0:
            self._scan_ts = -1.0
            return
        last_overflow_s = self._scan_ts + 1e-9 * float(overflow.ts_ns[0])
        if t - last_overflow_s > _OVERFLOW_GAP_S:
            self._scan_ts = -1.0
            return
        shifted = self._scan_ts + 1e-9 * overflow.ts_ns - self._last_block_ts
        overflow.ts_ns = np.floor(np.maximum(shifted, 0.0) * 1e9).astype(np.int64)
        self._scan = [overflow]
        self._scan_ts = self._last_block_ts

    def _emit(self, *, sixteen: bool) -> NebulaCloud:
        """nebula's ``get_pointcloud``: the scan less its tail past the phase (kept)."""
        chunks = self._scan
        azimuth = (
            np.concatenate([c.points.azimuth_rad[c.index] for c in chunks])
            if chunks
            else np.zeros(0, np.float32)
        )
        phase = math.radians(self.phase_deg)
        if sixteen:
            past = np.floor(np.degrees(2 * math.pi + azimuth.astype(np.float64) - phase)) % 360 < 90
        else:
            past = 2 * math.pi + azimuth.astype(np.float64) - phase < math.pi / 2
        # nebula pops points off the end while they lie past the phase: keep up to the last
        # point that does not
        before = np.flatnonzero(~past)
        keep = int(before[-1]) + 1 if before.size else 0
        head = self._take(chunks, 0, keep)
        if keep < azimuth.size:
            self._overflow = self._merged(self._take(chunks, keep, azimuth.size))
        return NebulaCloud(stamp_s=self._scan_ts, cloud=self._cloud(head))

    @staticmethod
    def _take(chunks: list[_Chunk], start: int, stop: int) -> list[_Chunk]:
        out = []
        at = 0
        for c in chunks:
            n = c.index.size
            lo, hi = max(start - at, 0), min(stop - at, n)
            if lo < hi:
                out.append(_Chunk(c.points, c.index[lo:hi], c.ts_ns[lo:hi]))
            at += n
        return out

    @staticmethod
    def _merged(chunks: list[_Chunk]) -> _Chunk:
        """One chunk of the tail (it may span two fed batches: their points are joined)."""
        if len(chunks) == 1:
            return chunks[0]
        parts = [_select(c.points, c.index) for c in chunks]
        joined = _concat(parts)
        n = joined.xyz.shape[0]
        return _Chunk(
            joined, np.arange(n, dtype=np.int64), np.concatenate([c.ts_ns for c in chunks])
        )

    @staticmethod
    def _cloud(chunks: list[_Chunk]) -> PointCloud:
        if not chunks:
            return PointCloud(xyz=np.zeros((0, 3), np.float32))
        joined = _concat([_select(c.points, c.index) for c in chunks])
        return points_cloud(joined, np.concatenate([c.ts_ns for c in chunks]))


_ARRAYS = (
    "xyz",
    "intensity",
    "ring",
    "return_type",
    "azimuth_rad",
    "distance_m",
    "packet",
    "firing_offset_ns",
    "azimuth_centideg",
)


def _select(points: VelodynePoints, index: npt.NDArray[np.int64]) -> VelodynePoints:
    values: dict[str, Any] = {name: getattr(points, name)[index] for name in _ARRAYS}
    return VelodynePoints(model=points.model, return_mode=points.return_mode, **values)


def _concat(parts: list[VelodynePoints]) -> VelodynePoints:
    if len(parts) == 1:
        return parts[0]
    values: dict[str, Any] = {
        name: np.concatenate([getattr(p, name) for p in parts]) for name in _ARRAYS
    }
    return VelodynePoints(model=parts[0].model, return_mode=parts[0].return_mode, **values)
