"""The four sensor streams, the payload layout (header, data, trailer), the sensor clock and the
settings every chain shares."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = [
    "CHAINS",
    "DRAIN_S",
    "HEADER_BYTES",
    "I64",
    "QUEUE_DEPTH",
    "SENSOR_BUFFER_S",
    "SLOTS",
    "STREAMS",
    "TOUCH_STRIDE",
    "TRAILER_BYTES",
    "U8",
    "StreamSpec",
    "due_times",
]

I64 = npt.NDArray[np.int64]
U8 = npt.NDArray[np.uint8]

CHAINS = ("legacy", "redrive", "redrive-lossless")
#: How many messages of a stream the collector holds before the oldest is overwritten, in seconds.
SENSOR_BUFFER_S = 1.0
#: ``maxsize`` of the legacy bridge → core queue (messages, all streams).
QUEUE_DEPTH = 100
#: How long the core keeps receiving after the last message was due.
DRAIN_S = 5.0
HEADER_BYTES = 16  # ID, hand-over time (int64 each)
TRAILER_BYTES = 8  # ID again
TOUCH_STRIDE = 4096
#: Slots per redrive stream (redrive.live's default).
SLOTS = 8
_START_TIMEOUT_S = 60.0
_JOIN_TIMEOUT_S = 10.0
_POLL_S = 0.05
_NS = 1_000_000_000
_SKIPPED = -1  # produced_ns of a message overwritten in the collector's buffer


@dataclass(frozen=True, slots=True, kw_only=True)
class StreamSpec:
    """One sensor stream at 1×: its name, rate and sensor data size in bytes."""

    name: str
    rate_hz: float
    data_bytes: int

    @property
    def payload_bytes(self) -> int:
        return HEADER_BYTES + -(-self.data_bytes // 8) * 8 + TRAILER_BYTES


_VLP16_DTYPE = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("ring", "<u2"),
     ("time", "<f4")]
)  # fmt: skip
STREAMS = (
    StreamSpec(name="lidar3d", rate_hz=60.0, data_bytes=16 * 1800 * _VLP16_DTYPE.itemsize),
    StreamSpec(name="lidar2d", rate_hz=15.0, data_bytes=1081 * 4),
    StreamSpec(name="camera", rate_hz=15.0, data_bytes=1280 * 720 * 3),
    StreamSpec(name="imu", rate_hz=15.0, data_bytes=10 * 8),
)


def _template(spec: StreamSpec) -> U8:
    """Sensor-like payload bytes of ``spec`` (seeded), header and trailer zero."""
    rng = np.random.default_rng(6)
    if spec.name == "lidar3d":
        cloud = np.zeros(16 * 1800, _VLP16_DTYPE)
        az = np.tile(np.linspace(0, 2 * np.pi, 1800, endpoint=False), 16)
        el = np.repeat(np.deg2rad(np.linspace(-15, 15, 16)), 1800)
        rng_m = rng.uniform(2.0, 60.0, az.size)
        cloud["x"] = rng_m * np.cos(el) * np.cos(az)
        cloud["y"] = rng_m * np.cos(el) * np.sin(az)
        cloud["z"] = rng_m * np.sin(el)
        cloud["intensity"] = rng.uniform(0, 255, az.size)
        cloud["ring"] = np.repeat(np.arange(16), 1800)
        cloud["time"] = np.tile(np.linspace(0.0, 0.1, 1800, endpoint=False), 16)
        data = cloud.view(np.uint8)
    elif spec.name == "camera":
        img = np.add.outer(np.arange(720) // 3, np.arange(1280) // 5)[..., None] + np.arange(3)
        data = (img % 256).astype(np.uint8).reshape(-1)
    else:
        data = rng.standard_normal(-(-spec.data_bytes // 4)).astype(np.float32).view(np.uint8)
    out = np.zeros(spec.payload_bytes, np.uint8)
    out[HEADER_BYTES : HEADER_BYTES + spec.data_bytes] = data[: spec.data_bytes]
    return out


def _stamp(buf: U8, msg_id: int, handover_ns: int) -> None:
    head = buf[:HEADER_BYTES].view(np.int64)
    head[0] = msg_id
    head[1] = handover_ns
    buf[-TRAILER_BYTES:].view(np.int64)[0] = msg_id


def _touch(payload: U8) -> tuple[int, int, int]:
    """The core's light work: (header ID, trailer ID, sum of one byte per 4 KiB page)."""
    head = int(payload[:8].view(np.int64)[0])
    tail = int(payload[-TRAILER_BYTES:].view(np.int64)[0])
    pages = int(np.add.reduce(payload[TOUCH_STRIDE - 1 :: TOUCH_STRIDE], dtype=np.uint64))
    return head, tail, pages


def due_times(t0_ns: int, rate_hz: float, seconds: float) -> I64:
    """Due times (ns) of IDs 1, 2, … of a stream at ``rate_hz``: those before ``t0 + seconds``."""
    n = math.ceil(seconds * rate_hz - 1e-9)
    return t0_ns + np.round(np.arange(n, dtype=np.float64) * (_NS / rate_hz)).astype(np.int64)
