"""Synthetic ROS 1 bags of LiDAR sweeps, written in a stream, for read benchmarks.

:func:`write_synthetic_bag` writes ``sensor_msgs/PointCloud2`` messages with the real
``rosbags.rosbag1.Writer`` until the bag holds about ``size_bytes`` of message payload.  Memory
stays bounded while writing (one cloud plus one writer chunk at a time), so a 2 GB log costs no
more memory to make than a 20 MB one.

Two point layouts:

* ``velodyne`` (32 bytes a point) — what the ROS Velodyne driver publishes with per-point time:
  ``x, y, z, intensity`` float32 at 0/4/8/12, ``ring`` uint16 at 16, 6 bytes of padding,
  ``time`` float64 at 24 (seconds since the start of the sweep);
* ``xyzi`` (16 bytes a point) — ``x, y, z, intensity`` float32, the layout of the 320 MB bag in
  NOTES.md.

The sweeps look like a spinning multi-beam sensor over a flat ground with walls: points on a
ring × azimuth grid, ranges that change from sweep to sweep, so lz4/bz2 see realistic data.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from rosbags.rosbag1 import Writer, WriterError
from rosbags.typesys import Stores, get_typestore

from redrive.errors import LogError

__all__ = [
    "LAYOUTS",
    "Compression",
    "Layout",
    "SynthResult",
    "point_dtype",
    "write_synthetic_bag",
]

Compression = Literal["none", "lz4", "bz2"]
Layout = Literal["velodyne", "xyzi"]

#: point layout name → (PointField list as (name, offset, datatype, count), point_step).
LAYOUTS: dict[str, tuple[tuple[tuple[str, int, int, int], ...], int]] = {
    "velodyne": (
        (
            ("x", 0, 7, 1),
            ("y", 4, 7, 1),
            ("z", 8, 7, 1),
            ("intensity", 12, 7, 1),
            ("ring", 16, 4, 1),
            ("time", 24, 8, 1),
        ),
        32,
    ),
    "xyzi": ((("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("intensity", 12, 7, 1)), 16),
}

_NUMPY_TYPES = {4: "<u2", 7: "<f4", 8: "<f8"}
_TOPIC = "/velodyne_points"
_MSGTYPE = "sensor_msgs/msg/PointCloud2"
_FRAME_ID = "velodyne"
_SWEEP_S = 0.1  # 10 Hz
_START_NS = 1_700_000_000_000_000_000


@dataclass(frozen=True, slots=True, kw_only=True)
class SynthResult:
    """What :func:`write_synthetic_bag` wrote.

    Attributes:
        path: the bag.
        topic: its one topic.
        messages: number of PointCloud2 messages.
        points_per_message: N of every cloud.
        payload_bytes: serialised message bytes (what a reader hands out).
        file_bytes: size of the bag on disk.
    """

    path: Path
    topic: str
    messages: int
    points_per_message: int
    payload_bytes: int
    file_bytes: int


def point_dtype(layout: Layout) -> np.dtype[Any]:
    """The numpy structured dtype of one point of ``layout`` (padding included)."""
    fields, step = LAYOUTS[layout]
    return np.dtype(
        {
            "names": [f[0] for f in fields],
            "formats": [_NUMPY_TYPES[f[2]] for f in fields],
            "offsets": [f[1] for f in fields],
            "itemsize": step,
        }
    )


class _SweepMaker:
    """Makes Velodyne-like sweeps: a fixed ring × azimuth grid, ranges varying per sweep."""

    def __init__(self, points: int, layout: Layout, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.points = points
        self.layout = layout
        rings = 64 if points >= 64 * 360 else 16
        azimuths = math.ceil(points / rings)
        idx = np.arange(points)
        self.ring = (idx % rings).astype(np.uint16)
        az = (idx // rings).astype(np.float64) * (2 * math.pi / azimuths)
        el = np.deg2rad(np.linspace(-25.0, 15.0, rings))[self.ring]
        self.dirs = np.stack(
            [np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1
        ).astype(np.float32)
        # ground at z = -1.8 m for beams that point down, else walls 10-60 m away
        down = self.dirs[:, 2] < -0.02
        ground = np.where(down, -1.8 / np.minimum(self.dirs[:, 2], -0.02), np.inf)
        self.base_range = np.minimum(ground, 10.0 + 50.0 * self.rng.random(points)).astype(
            np.float32
        )
        self.time = (idx // rings).astype(np.float64) * (_SWEEP_S / azimuths)
        self.buf = np.zeros(points, dtype=point_dtype(layout))

    def sweep(self) -> npt.NDArray[Any]:
        """The next sweep as a structured array (reused: serialise it before the next call)."""
        noise = self.rng.normal(0.0, 0.03, self.points).astype(np.float32)
        rng_m = self.base_range + noise
        buf = self.buf
        buf["x"] = self.dirs[:, 0] * rng_m
        buf["y"] = self.dirs[:, 1] * rng_m
        buf["z"] = self.dirs[:, 2] * rng_m
        buf["intensity"] = self.rng.integers(0, 256, self.points).astype(np.float32)
        if self.layout == "velodyne":
            buf["ring"] = self.ring
            buf["time"] = self.time
        return buf


def write_synthetic_bag(
    out: str | Path,
    *,
    size_bytes: int,
    points: int = 100_000,
    layout: Layout = "velodyne",
    compression: Compression = "none",
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
) -> SynthResult:
    """Write a ROS 1 bag of PointCloud2 sweeps holding about ``size_bytes`` of messages.

    Args:
        out: the new ``.bag``; it must not exist.
        size_bytes: payload to write; the message count is ``size_bytes / message size``
            rounded, at least 1.
        points: points per sweep.
        layout: ``velodyne`` (32 bytes a point) or ``xyzi`` (16 bytes).
        compression: chunk compression.
        seed: random seed (the bag is reproducible).
        progress: called as ``progress(done, total)`` after every message.

    Raises:
        LogError: ``out`` exists or cannot be written; a bad argument.
    """
    path = Path(out)
    if points <= 0 or size_bytes <= 0:
        msg = f"points ({points}) and size_bytes ({size_bytes}) must be positive"
        raise LogError(msg)
    if layout not in LAYOUTS:
        msg = f"unknown point layout {layout!r}; use one of {', '.join(LAYOUTS)}"
        raise LogError(msg)
    if path.exists():
        msg = f"{path}: cannot create the bag (it exists already); remove it or choose another path"
        raise LogError(msg)
    typestore = get_typestore(Stores.ROS1_NOETIC)
    cls: Any = typestore.types
    fields, step = LAYOUTS[layout]
    point_fields = [
        cls["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=d, count=c)
        for n, o, d, c in fields
    ]
    maker = _SweepMaker(points, layout, seed)

    def message(index: int, stamp_ns: int) -> bytes:
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        header = cls["std_msgs/msg/Header"](
            seq=index,
            stamp=cls["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
            frame_id=_FRAME_ID,
        )
        cloud = cls[_MSGTYPE](
            header=header,
            height=1,
            width=points,
            fields=point_fields,
            is_bigendian=False,
            point_step=step,
            row_step=step * points,
            data=maker.sweep().view(np.uint8),
            is_dense=True,
        )
        return bytes(typestore.serialize_ros1(cloud, _MSGTYPE))

    first = message(0, _START_NS)
    count = max(1, round(size_bytes / len(first)))
    payload = 0
    try:
        writer = Writer(path)
        if compression != "none":
            writer.set_compression(Writer.CompressionFormat[compression.upper()])
        writer.open()
    except (WriterError, OSError) as err:
        msg = f"{path}: cannot create the bag ({err}); remove it or choose another path"
        raise LogError(msg) from err
    try:
        conn = writer.add_connection(_TOPIC, _MSGTYPE, typestore=typestore)
        for i in range(count):
            stamp_ns = _START_NS + round(i * _SWEEP_S * 1e9)
            data = first if i == 0 else message(i, stamp_ns)
            writer.write(conn, stamp_ns, data)
            payload += len(data)
            if progress is not None:
                progress(i + 1, count)
        writer.close()
    except BaseException:
        writer.abort()
        path.unlink(missing_ok=True)
        raise
    return SynthResult(
        path=path,
        topic=_TOPIC,
        messages=count,
        points_per_message=points,
        payload_bytes=payload,
        file_bytes=path.stat().st_size,
    )
