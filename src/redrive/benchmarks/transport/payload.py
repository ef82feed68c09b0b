"""The message every side sends and what every subscriber does with it: the payload's layout
(stamp, sequence number, a seeded pattern), the publisher's fill and the subscriber's tally."""

from __future__ import annotations

import math
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["MIN_SIZE", "SLOTS", "CellConfig"]

U8 = npt.NDArray[np.uint8]

HEADER = struct.Struct("<qq")  # stamp_ns, seq
END_SEQ = -1
TOUCH_STRIDE = 4096
MIN_SIZE = TOUCH_STRIDE
SLOTS = 4
WARMUP_FRACTION = 0.1
SEED = 6


@dataclass(frozen=True, slots=True, kw_only=True)
class CellConfig:
    """What both processes of one run need (pickled to the spawned children)."""

    side: str
    size_bytes: int
    seconds: float
    paced_hz: float | None  # None: flat out
    verify: bool
    endpoint: str  # a name unique to this run (segment, socket, topic, service)
    slots: int = SLOTS
    catalogue: str = "redrive.benchmarks.transport.sides"  # the module the side is looked up in


def _pattern(size: int) -> U8:
    return np.random.default_rng(SEED).integers(0, 256, size, dtype=np.uint8)


class _Payload:
    """Writes message ``seq`` into a buffer (publisher side)."""

    def __init__(self, cfg: CellConfig) -> None:
        self.size = cfg.size_bytes
        self.verify = cfg.verify
        self.pattern = _pattern(cfg.size_bytes)

    def new_source(self) -> U8:
        return self.pattern.copy()

    def fill(self, out: Any, seq: int, stamp_ns: int) -> None:
        """Write the whole payload into ``out`` (in-place sides)."""
        if self.verify:
            np.bitwise_xor(self.pattern, seq & 0xFF, out=out)
        else:
            np.copyto(out, self.pattern)
        HEADER.pack_into(out, 0, stamp_ns, seq)

    def stamp(self, src: Any, seq: int, stamp_ns: int) -> None:
        """Prepare the preallocated source ``src`` (copy sides: only the header changes)."""
        if self.verify:
            np.bitwise_xor(self.pattern, seq & 0xFF, out=src)
        HEADER.pack_into(src, 0, stamp_ns, seq)


class _Tally:
    """The subscriber's work and bookkeeping for each message; ``consume`` may be called from a
    transport's own thread (eCAL callbacks)."""

    def __init__(self, cfg: CellConfig) -> None:
        self.size = cfg.size_bytes
        self.verify = cfg.verify
        self.pattern = _pattern(cfg.size_bytes)
        self.touch_sum = int(
            np.add.reduce(self.pattern[TOUCH_STRIDE - 1 :: TOUCH_STRIDE], dtype=np.uint64)
        )
        self.arrivals: list[int] = []
        self.latencies: list[int] = []
        self.last_seq = -1
        self.seen: set[int] = set()
        self.corrupt = 0
        self.out_of_order = 0
        self.ended = False
        self.wake = threading.Event()

    def consume(self, buf: Any) -> None:
        stamp_ns, seq = HEADER.unpack_from(buf, 0)
        if seq == END_SEQ:
            self.ended = True
            self.wake.set()
            return
        arr = buf if isinstance(buf, np.ndarray) else np.frombuffer(buf, np.uint8)
        if len(arr) != self.size:
            self.corrupt += 1
        elif self.verify:
            expect = np.bitwise_xor(self.pattern[16:], seq & 0xFF)
            if not np.array_equal(arr[16:], expect):
                self.corrupt += 1
        elif (
            int(np.add.reduce(arr[TOUCH_STRIDE - 1 :: TOUCH_STRIDE], dtype=np.uint64))
            != self.touch_sum
        ):
            self.corrupt += 1
        now = time.monotonic_ns()
        if seq <= self.last_seq:
            self.out_of_order += 1
        self.last_seq = max(self.last_seq, seq)
        self.seen.add(seq)
        self.arrivals.append(now)
        self.latencies.append(now - stamp_ns)
        self.wake.set()

    def summary(self) -> dict[str, Any]:
        n = len(self.arrivals)
        out: dict[str, Any] = {
            "received": len(self.seen),
            "corrupt": self.corrupt,
            "out_of_order": self.out_of_order,
            "msgs_per_s": math.nan,
            "latency_p50_ms": math.nan,
            "latency_p99_ms": math.nan,
            "latency_max_ms": math.nan,
        }
        if n == 0:
            return out
        t = np.asarray(self.arrivals, dtype=np.int64)
        lat = np.asarray(self.latencies, dtype=np.int64)
        start = t[0] + WARMUP_FRACTION * (t[-1] - t[0])
        i0 = int(np.searchsorted(t, start))
        if n - 1 - i0 >= 1 and t[-1] > t[i0]:
            out["msgs_per_s"] = (n - 1 - i0) / ((t[-1] - t[i0]) / 1e9)
        elif n >= 2 and t[-1] > t[0]:
            out["msgs_per_s"] = (n - 1) / ((t[-1] - t[0]) / 1e9)
        steady = lat[i0:] if n - i0 >= 1 else lat
        p50, p99 = np.percentile(steady, [50, 99])
        out["latency_p50_ms"] = float(p50) / 1e6
        out["latency_p99_ms"] = float(p99) / 1e6
        out["latency_max_ms"] = float(steady.max()) / 1e6
        return out
