"""``redrive bench transport``: moving large messages between two processes, every way at hand.

Each *side* is one transport, run as a publisher process and a subscriber process started with
``multiprocessing`` ``spawn`` (fresh interpreters, nothing inherited but the arguments):

===================  ==========================================================================
side                 publisher → subscriber
===================  ==========================================================================
``redrive-copy``     :class:`redrive.transport.Writer` ``publish`` (copies in) → ``Reader.read``
                     (copies out into an owned array: the copy is the receiver's work)
``redrive-inplace``  ``Writer.loan`` (the payload is written straight into the slot) →
                     ``Reader.view`` (read-only view into the slot, no copy)
``pipe-pickle``      ``multiprocessing.Pipe`` ``send(ndarray)`` → ``recv()``: pickle through a
                     pipe, the legacy path of the paper
``mp-queue``         ``multiprocessing.Queue(maxsize=4)`` ``put(ndarray)`` → ``get()``
``zmq``              ZeroMQ PUSH → PULL over ``ipc://``, ``send(copy=False)`` /
                     ``recv(copy=False)`` (no copy in Python; the kernel copies through the socket)
``ecal``             eCAL 6 ``Publisher.send(bytes)`` → ``Subscriber`` receive callback, default
                     configuration (shared memory on one host; *lossy*: no back-pressure)
``iceoryx2``         iceoryx2 publish-subscribe of ``Slice[c_uint8]``: ``loan_slice_uninit``
                     (written in place) → ``receive`` (a view into shared memory), one event
                     notification per message to wake the subscriber
===================  ==========================================================================

What every side does per message, so the numbers compare like with like:

- **payload**: ``size`` bytes; bytes 0–8 the publisher's ``time.monotonic_ns()`` (CLOCK_MONOTONIC,
  the same clock in every process), bytes 8–16 the sequence number, the rest a fixed seeded random
  pattern (``verify=True``: the pattern XOR ``seq % 256``, different in every message).
- **publisher**: takes the stamp *before* any work on the message, then: copy sides write the
  16-byte header into a preallocated source array and hand it to the transport, which copies or
  serialises it; in-place sides (``redrive-inplace``, ``iceoryx2``) loan a slot and write the whole
  payload into it (``np.copyto`` from the preallocated pattern: the one write of ``size`` bytes a
  copy side's transport does for it), then commit. ``mp-queue`` and ``zmq`` hand over a reference
  and serialise later, so they rotate over ``slots + 1`` source arrays (``zmq`` also waits on the
  send tracker before reusing one). eCAL's Python ``send`` takes only ``bytes``: the publisher
  passes ``array.tobytes()`` (one more copy, which its API imposes).
- **subscriber** ("consume"): unpacks the header and sums one byte per 4 KiB page
  (``np.add.reduce`` over ``payload[4095::4096]``), compares the sum with the pattern's (a
  mismatch counts as ``corrupt``; ``verify=True`` compares every byte instead), then stamps
  ``now``. Copy sides do this on the copy the transport delivered (the copy is their work); in-place
  sides on the shared-memory view. One-way latency is ``now − stamp``.
- **flat out**: the publisher sends as fast as the transport takes messages for ``seconds``; the
  lossless sides block when the subscriber is ``slots`` (4) messages behind. Throughput is what the
  subscriber received per second, measured by the subscriber from arrival times after a warm-up
  (the first 10 % of the run); ``lost`` is sent − received.
- **paced**: the same at ``paced_hz`` (default 100 Hz); latency p50 / p99 / max over the messages
  after the warm-up.

The memcpy ceiling is single-thread ``np.copyto`` between preallocated, pre-touched buffers:
*cache-hot* (the same two ``size``-byte buffers every time) and *from memory* (source and
destination rotate over two 256 MiB pools, so every copy reads and writes memory, not cache).
Sides whose package is not installed are reported so, never left out silently or faked; a side
that fails reports its error and the others still run.

Set-up details that change the numbers: every side has 4 slots / a queue depth of 4 (redrive
``slots=4``, iceoryx2 ``subscriber_max_buffer_size(4)``, ZeroMQ high-water marks 4, ``Queue(4)``);
lossless sides are lossless (redrive ``Policy.LOSSLESS``; iceoryx2 without safe overflow and
``RetryUntilDelivered``, its publisher created before the subscriber — the other order lost a
block of samples after the first four in about one run in ten); eCAL's publisher waits until it
sees the subscriber, plus 0.2 s, and still usually loses the first message. Children are started
with ``spawn``: a script calling :func:`run_cell` needs the ``if __name__ == "__main__":`` guard.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.metadata
import importlib.util
import logging
import math
import multiprocessing
import os
import platform
import queue
import struct
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from redrive.errors import TransportError

__all__ = [
    "DEFAULT_SIDES",
    "DEFAULT_SIZES",
    "SIDES",
    "CellResult",
    "MemcpyResult",
    "RunResult",
    "SideSpec",
    "TargetCheck",
    "TransportBenchResult",
    "bench_memcpy",
    "bench_transport",
    "check_targets",
    "run_cell",
]

logger = logging.getLogger(__name__)

U8 = npt.NDArray[np.uint8]

HEADER = struct.Struct("<qq")  # stamp_ns, seq
END_SEQ = -1
TOUCH_STRIDE = 4096
MIN_SIZE = TOUCH_STRIDE
SLOTS = 4
WARMUP_FRACTION = 0.1
MEMORY_POOL_BYTES = 256 << 20
DEFAULT_SIZES = (64 << 10, 1 << 20, 4 << 20, 16 << 20)
SEED = 6

# The issue-6 targets.
INPLACE_VS_ICEORYX2_TARGET = 1.0  # redrive in place / iceoryx2 in place, GB/s at 1 and 4 MiB
VS_PIPE_PICKLE_TARGET = 10.0  # redrive / pipe + pickle, GB/s at 4 MiB
VS_MEMCPY_TARGET = 0.5  # redrive / from-memory memcpy, GB/s at 16 MiB
PACED_P99_TARGET_MS = 2.0  # redrive paced p99 one-way latency at 4 MiB

_IDLE_POLL_S = 0.05
_IDLE_POLLS_AFTER_DONE = 4  # 0.2 s without a message once the publisher has finished
_CONNECT_TIMEOUT_S = 20.0
_SPAWN_TIMEOUT_S = 60.0


# ------------------------------------------------------------------------------------------------
# results


@dataclass(frozen=True, slots=True, kw_only=True)
class RunResult:
    """One run of one side at one size, flat out or paced; rates are the subscriber's, measured
    after the warm-up; latencies are one-way (publisher stamp → subscriber consumed), in ms."""

    mode: str  # "flat" | "paced"
    seconds: float  # how long the publisher published
    sent: int
    received: int
    corrupt: int
    out_of_order: int
    msgs_per_s: float
    gb_per_s: float  # 10⁹ bytes of payload per second
    sent_per_s: float
    latency_p50_ms: float
    latency_p99_ms: float
    latency_max_ms: float

    @property
    def lost(self) -> int:
        return max(0, self.sent - self.received)

    @property
    def lost_fraction(self) -> float:
        return self.lost / self.sent if self.sent else 0.0

    def to_json(self) -> dict[str, Any]:
        return {
            "mode": self.mode,
            "seconds": self.seconds,
            "sent": self.sent,
            "received": self.received,
            "lost": self.lost,
            "lost_fraction": self.lost_fraction,
            "corrupt": self.corrupt,
            "out_of_order": self.out_of_order,
            "msgs_per_s": _finite(self.msgs_per_s),
            "gb_per_s": _finite(self.gb_per_s),
            "sent_per_s": _finite(self.sent_per_s),
            "latency_p50_ms": _finite(self.latency_p50_ms),
            "latency_p99_ms": _finite(self.latency_p99_ms),
            "latency_max_ms": _finite(self.latency_max_ms),
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class CellResult:
    """One side at one size: ``status`` is ``"ok"``, ``"not installed"`` or ``"error"``."""

    side: str
    size_bytes: int
    status: str
    error: str | None = None
    flat: RunResult | None = None
    paced: RunResult | None = None

    def to_json(self) -> dict[str, Any]:
        return {
            "side": self.side,
            "size_bytes": self.size_bytes,
            "status": self.status,
            "error": self.error,
            "flat": None if self.flat is None else self.flat.to_json(),
            "paced": None if self.paced is None else self.paced.to_json(),
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class MemcpyResult:
    """Single-thread ``np.copyto`` GB/s (10⁹ B/s) at ``size_bytes``."""

    size_bytes: int
    hot_gb_per_s: float
    from_memory_gb_per_s: float
    pool_bytes: int

    def to_json(self) -> dict[str, Any]:
        return {
            "size_bytes": self.size_bytes,
            "hot_gb_per_s": self.hot_gb_per_s,
            "from_memory_gb_per_s": self.from_memory_gb_per_s,
            "pool_bytes": self.pool_bytes,
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class TargetCheck:
    """One target of the issue: ``value`` of ``side`` against ``reference`` (a baseline's value, or
    the bound itself); ``met`` is None when a side needed for it did not run."""

    name: str
    side: str
    size_bytes: int
    value: float | None
    reference: float | None
    target: str  # e.g. "≥ 1.0×", "≤ 2 ms"
    met: bool | None
    note: str = ""

    @property
    def ratio(self) -> float | None:
        if self.value is None or self.reference is None or not self.reference:
            return None
        return self.value / self.reference

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "side": self.side,
            "size_bytes": self.size_bytes,
            "value": self.value,
            "reference": self.reference,
            "ratio": self.ratio,
            "target": self.target,
            "met": self.met,
            "note": self.note,
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class TransportBenchResult:
    sizes: tuple[int, ...]
    seconds: float
    paced_hz: float
    slots: int
    cells: tuple[CellResult, ...]
    memcpy: tuple[MemcpyResult, ...]
    targets: tuple[TargetCheck, ...]
    machine: Mapping[str, str] = field(default_factory=dict)
    versions: Mapping[str, str] = field(default_factory=dict)

    def cell(self, side: str, size_bytes: int) -> CellResult | None:
        for c in self.cells:
            if c.side == side and c.size_bytes == size_bytes:
                return c
        return None

    def to_json(self) -> dict[str, Any]:
        return {
            "sizes": list(self.sizes),
            "seconds": self.seconds,
            "paced_hz": self.paced_hz,
            "slots": self.slots,
            "machine": dict(self.machine),
            "versions": dict(self.versions),
            "cells": [c.to_json() for c in self.cells],
            "memcpy": [m.to_json() for m in self.memcpy],
            "targets": [t.to_json() for t in self.targets],
        }


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


# ------------------------------------------------------------------------------------------------
# the payload every side sends, and what every subscriber does with it


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


# ------------------------------------------------------------------------------------------------
# the sides


class _Sender(Protocol):
    def wait_connected(self, timeout_s: float) -> None: ...

    def send(self, seq: int, stamp_ns: int) -> None: ...

    def close(self) -> None: ...


class _Receiver(Protocol):
    def recv(self, timeout_s: float) -> bool:
        """Deliver what arrived to the tally's ``consume``; False when nothing came in time."""
        ...

    def close(self) -> None: ...


@dataclass(frozen=True, slots=True, kw_only=True)
class SideSpec:
    """One transport: ``module`` must import for it to run (``package`` is what to install)."""

    name: str
    label: str
    module: str
    package: str
    publisher_first: bool  # the subscriber cannot attach before the publisher exists
    lossy: bool
    in_place: bool
    make_sender: Callable[[CellConfig, Any], _Sender]
    make_receiver: Callable[[CellConfig, Any, _Tally], _Receiver]
    make_shared: Callable[[Any, CellConfig], Any] | None = None  # objects both children inherit
    cleanup: Callable[[CellConfig], None] | None = None  # parent side, after the run


class _NoWait:
    def wait_connected(self, timeout_s: float) -> None:
        return None


# -- redrive ---------------------------------------------------------------------------------------


def _segment_name(cfg: CellConfig) -> str:
    return f"bench.{cfg.endpoint}"


class _RedriveSender(_NoWait):
    def __init__(self, cfg: CellConfig, *, in_place: bool) -> None:
        from redrive.transport import Policy, Writer

        self.payload = _Payload(cfg)
        self.in_place = in_place
        self.size = cfg.size_bytes
        self.src = self.payload.new_source()
        self.writer = Writer(
            _segment_name(cfg),
            capacity_bytes=cfg.size_bytes,
            slots=cfg.slots,
            policy=Policy.LOSSLESS,
        )

    def send(self, seq: int, stamp_ns: int) -> None:
        if self.in_place:
            with self.writer.loan(self.size, stamp_ns=stamp_ns) as out:
                self.payload.fill(out, seq, stamp_ns)
        else:
            self.payload.stamp(self.src, seq, stamp_ns)
            self.writer.publish(self.src, stamp_ns=stamp_ns)

    def close(self) -> None:
        self.writer.close()


class _RedriveReceiver:
    def __init__(self, cfg: CellConfig, tally: _Tally, *, in_place: bool) -> None:
        from redrive.transport import Reader

        self.tally = tally
        self.in_place = in_place
        self.reader = Reader(_segment_name(cfg), timeout_s=_CONNECT_TIMEOUT_S)
        # copy-out into one reused buffer, as a consumer that keeps the data would do: a fresh
        # array per message pays its page faults (p99 ≈ 6.5 ms for 4 MiB here) in the copy
        self.out = np.empty(max(cfg.size_bytes, 1), np.uint8)

    def recv(self, timeout_s: float) -> bool:
        if self.in_place:
            with self.reader.view(timeout_s=timeout_s) as msg:
                if msg is None:
                    return False
                self.tally.consume(msg.payload)
                return True
        got = self.reader.read(timeout_s=timeout_s, out=self.out)
        if got is None:
            return False
        self.tally.consume(got.payload)
        return True

    def close(self) -> None:
        self.reader.close()


def _redrive_cleanup(cfg: CellConfig) -> None:
    # the writer unlinks its segment on close; this is for a writer that died
    from redrive.transport import segment_path

    with contextlib.suppress(FileNotFoundError):
        segment_path(_segment_name(cfg)).unlink()


# -- pipe + pickle, multiprocessing.Queue ---------------------------------------------------------


class _PipeSender(_NoWait):
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        self.payload = _Payload(cfg)
        self.src = self.payload.new_source()
        _, self.conn = shared

    def send(self, seq: int, stamp_ns: int) -> None:
        self.payload.stamp(self.src, seq, stamp_ns)
        self.conn.send(self.src)  # pickled and written synchronously

    def close(self) -> None:
        self.conn.close()


class _PipeReceiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        self.conn, _ = shared
        self.tally = tally

    def recv(self, timeout_s: float) -> bool:
        if not self.conn.poll(timeout_s):
            return False
        self.tally.consume(self.conn.recv())
        return True

    def close(self) -> None:
        self.conn.close()


class _QueueSender(_NoWait):
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        self.payload = _Payload(cfg)
        # put() pickles later, in the queue's feeder thread: a source array is reused only after
        # more than maxsize later puts succeeded, i.e. after the subscriber got it
        self.ring = [self.payload.new_source() for _ in range(cfg.slots + 1)]
        self.queue = shared

    def send(self, seq: int, stamp_ns: int) -> None:
        src = self.ring[seq % len(self.ring)] if seq >= 0 else self.ring[0].copy()
        self.payload.stamp(src, seq, stamp_ns)
        self.queue.put(src)

    def close(self) -> None:
        self.queue.close()
        self.queue.join_thread()


class _QueueReceiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        self.queue = shared
        self.tally = tally

    def recv(self, timeout_s: float) -> bool:
        try:
            item = self.queue.get(timeout=timeout_s)
        except queue.Empty:
            return False
        self.tally.consume(item)
        return True

    def close(self) -> None:
        self.queue.close()


# -- ZeroMQ ----------------------------------------------------------------------------------------


def _zmq_address(cfg: CellConfig) -> str:
    return f"ipc://{Path(tempfile.gettempdir()) / f'redrive-bench-{cfg.endpoint}.ipc'}"


class _ZmqSender(_NoWait):
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        zmq: Any = importlib.import_module("zmq")
        self.payload = _Payload(cfg)
        self.ring = [self.payload.new_source() for _ in range(cfg.slots + 1)]
        self.trackers: list[Any] = [None] * len(self.ring)
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.PUSH)
        self.sock.setsockopt(zmq.SNDHWM, cfg.slots)
        self.sock.setsockopt(zmq.LINGER, 5000)
        self.sock.bind(_zmq_address(cfg))

    def send(self, seq: int, stamp_ns: int) -> None:
        i = seq % len(self.ring) if seq >= 0 else 0
        if self.trackers[i] is not None:
            self.trackers[i].wait()  # zmq still holds this buffer (copy=False)
        src = self.ring[i]
        self.payload.stamp(src, seq, stamp_ns)
        self.trackers[i] = self.sock.send(src, copy=False, track=True)

    def close(self) -> None:
        self.sock.close()
        self.ctx.term()


class _ZmqReceiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        zmq: Any = importlib.import_module("zmq")
        self.tally = tally
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.PULL)
        self.sock.setsockopt(zmq.RCVHWM, cfg.slots)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.connect(_zmq_address(cfg))

    def recv(self, timeout_s: float) -> bool:
        if not self.sock.poll(round(timeout_s * 1000)):
            return False
        frame = self.sock.recv(copy=False)
        self.tally.consume(np.frombuffer(frame.buffer, np.uint8))
        return True

    def close(self) -> None:
        self.sock.close()
        self.ctx.term()


def _zmq_cleanup(cfg: CellConfig) -> None:
    with contextlib.suppress(FileNotFoundError):
        Path(_zmq_address(cfg).removeprefix("ipc://")).unlink()


# -- eCAL ------------------------------------------------------------------------------------------


def _ecal() -> Any:
    return importlib.import_module("ecal.nanobind_core")


class _EcalSender:
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        self.ecal = _ecal()
        self.ecal.initialize(f"redrive-bench-pub-{os.getpid()}")
        self.payload = _Payload(cfg)
        self.src = self.payload.new_source()
        self.pub = self.ecal.Publisher(f"redrive_bench_{cfg.endpoint}")

    def wait_connected(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while self.pub.get_subscriber_count() < 1:
            if time.monotonic() > deadline:
                msg = f"eCAL: no subscriber matched the topic in {timeout_s:g} s"
                raise TransportError(msg)
            time.sleep(0.01)
        time.sleep(0.2)  # registration is seen before the shared-memory connection is up

    def send(self, seq: int, stamp_ns: int) -> None:
        self.payload.stamp(self.src, seq, stamp_ns)
        self.pub.send(self.src.tobytes())  # the Python API takes only bytes

    def close(self) -> None:
        del self.pub
        self.ecal.finalize()


class _EcalReceiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        self.ecal = _ecal()
        self.ecal.initialize(f"redrive-bench-sub-{os.getpid()}")
        self.tally = tally
        self.sub = self.ecal.Subscriber(f"redrive_bench_{cfg.endpoint}")

        def callback(_topic: Any, _datatype: Any, data: Any) -> None:
            tally.consume(data.buffer)

        self.sub.set_receive_callback(callback)

    def recv(self, timeout_s: float) -> bool:
        # the callback (an eCAL thread) consumes; this only waits for it
        got = self.tally.wake.wait(timeout_s)
        self.tally.wake.clear()
        return got

    def close(self) -> None:
        self.sub.remove_receive_callback()
        del self.sub
        self.ecal.finalize()


# -- iceoryx2 --------------------------------------------------------------------------------------


def _iox2_service(cfg: CellConfig) -> tuple[Any, Any, Any, Any]:
    import ctypes

    iox2: Any = importlib.import_module("iceoryx2")
    iox2.set_log_level(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    name = iox2.ServiceName.new(f"redrive/bench/{cfg.endpoint}")
    service = (
        node.service_builder(name)
        .publish_subscribe(iox2.Slice[ctypes.c_uint8])
        .subscriber_max_buffer_size(cfg.slots)
        .history_size(0)
        .enable_safe_overflow(False)  # lossless: back-pressure instead of overwriting
        .max_publishers(1)
        .max_subscribers(1)
        .open_or_create()
    )
    event = node.service_builder(name).event().open_or_create()
    return iox2, node, service, event


def _as_u8(ptr: int, nbytes: int) -> U8:
    import ctypes

    buf: Any = (ctypes.c_uint8 * nbytes).from_address(ptr)
    return np.frombuffer(buf, np.uint8)


class _Iox2Sender:
    def __init__(self, cfg: CellConfig, shared: Any) -> None:
        self.iox2, self.node, self.service, event = _iox2_service(cfg)
        self.payload = _Payload(cfg)
        self.size = cfg.size_bytes
        self.pub = (
            self.service.publisher_builder()
            .initial_max_slice_len(cfg.size_bytes)
            .allocation_strategy(self.iox2.AllocationStrategy.Static)
            .backpressure_strategy(self.iox2.BackpressureStrategy.RetryUntilDelivered)
            .create()
        )
        self.notifier = event.notifier_builder().create()

    def wait_connected(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while self.service.dynamic_config.number_of_subscribers < 1:
            if time.monotonic() > deadline:
                msg = f"iceoryx2: no subscriber connected in {timeout_s:g} s"
                raise TransportError(msg)
            time.sleep(0.01)
        self.pub.update_connections()

    def send(self, seq: int, stamp_ns: int) -> None:
        sample = self.pub.loan_slice_uninit(self.size)
        self.payload.fill(_as_u8(sample.payload_ptr, self.size), seq, stamp_ns)
        sample.assume_init().send()
        self.notifier.notify()

    def close(self) -> None:
        self.notifier.delete()
        self.pub.delete()
        del self.service, self.node


class _Iox2Receiver:
    def __init__(self, cfg: CellConfig, shared: Any, tally: _Tally) -> None:
        self.iox2, self.node, self.service, event = _iox2_service(cfg)
        self.tally = tally
        self.sub = self.service.subscriber_builder().create()
        self.listener = event.listener_builder().create()

    def recv(self, timeout_s: float) -> bool:
        sample = self.sub.receive()
        if sample is None:
            self.listener.timed_wait(self.iox2.Duration.from_secs_f64(timeout_s))
            sample = self.sub.receive()
            if sample is None:
                return False
        self.tally.consume(_as_u8(sample.payload_ptr, sample.payload().len()))
        sample.delete()
        return True

    def close(self) -> None:
        self.listener.delete()
        self.sub.delete()
        del self.service, self.node


def _iox2_cleanup(cfg: CellConfig) -> None:
    # a child that was killed leaves its node's files in /dev/shm and /tmp/iceoryx2
    iox2: Any = importlib.import_module("iceoryx2")
    iox2.set_log_level(iox2.LogLevel.Error)
    node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
    node.try_cleanup_dead_nodes()
    del node


def _pipe_shared(ctx: Any, cfg: CellConfig) -> Any:
    return ctx.Pipe(duplex=False)  # (receiving end, sending end)


def _queue_shared(ctx: Any, cfg: CellConfig) -> Any:
    return ctx.Queue(maxsize=cfg.slots)


SIDES: Mapping[str, SideSpec] = {
    s.name: s
    for s in (
        SideSpec(
            name="redrive-copy", label="redrive copy-out", module="redrive.transport",
            package="redrive", publisher_first=True, lossy=False, in_place=False,
            make_sender=lambda cfg, _sh: _RedriveSender(cfg, in_place=False),
            make_receiver=lambda cfg, _sh, t: _RedriveReceiver(cfg, t, in_place=False),
            cleanup=_redrive_cleanup,
        ),
        SideSpec(
            name="redrive-inplace", label="redrive in place", module="redrive.transport",
            package="redrive", publisher_first=True, lossy=False, in_place=True,
            make_sender=lambda cfg, _sh: _RedriveSender(cfg, in_place=True),
            make_receiver=lambda cfg, _sh, t: _RedriveReceiver(cfg, t, in_place=True),
            cleanup=_redrive_cleanup,
        ),
        SideSpec(
            name="pipe-pickle", label="pipe + pickle", module="multiprocessing",
            package="(standard library)", publisher_first=False, lossy=False, in_place=False,
            make_sender=_PipeSender, make_receiver=_PipeReceiver, make_shared=_pipe_shared,
        ),
        SideSpec(
            name="mp-queue", label="multiprocessing.Queue", module="multiprocessing",
            package="(standard library)", publisher_first=False, lossy=False, in_place=False,
            make_sender=_QueueSender, make_receiver=_QueueReceiver, make_shared=_queue_shared,
        ),
        SideSpec(
            name="zmq", label="ZeroMQ ipc, copy=False", module="zmq", package="pyzmq",
            publisher_first=False, lossy=False, in_place=False,
            make_sender=_ZmqSender, make_receiver=_ZmqReceiver, cleanup=_zmq_cleanup,
        ),
        SideSpec(
            name="ecal", label="eCAL shm (default, lossy)", module="ecal.nanobind_core",
            package="eclipse-ecal", publisher_first=False, lossy=True, in_place=False,
            make_sender=_EcalSender, make_receiver=_EcalReceiver,
        ),
        SideSpec(
            name="iceoryx2", label="iceoryx2, in place", module="iceoryx2", package="iceoryx2",
            # subscriber first lost a block of samples after the first 4 in ~1 run of 10, even
            # with RetryUntilDelivered; publisher first lost none in 36 runs
            publisher_first=True, lossy=False, in_place=True,
            make_sender=_Iox2Sender, make_receiver=_Iox2Receiver, cleanup=_iox2_cleanup,
        ),
    )
}  # fmt: skip
DEFAULT_SIDES = tuple(SIDES)


# ------------------------------------------------------------------------------------------------
# the two child processes


def _publisher_main(spec: SideSpec, cfg: CellConfig, shared: Any, conn: Any) -> dict[str, Any]:
    tx = spec.make_sender(cfg, shared)
    try:
        conn.send(("created", None))
        if conn.recv() != "go":
            return {"sent": 0, "seconds": 0.0}
        tx.wait_connected(_CONNECT_TIMEOUT_S)
        sent = 0
        clock = time.monotonic_ns
        t0 = clock()
        end = t0 + round(cfg.seconds * 1e9)
        if cfg.paced_hz is None:
            while True:
                now = clock()
                if now >= end:
                    break
                tx.send(sent, now)
                sent += 1
        else:
            period = round(1e9 / cfg.paced_hz)
            next_ns = t0
            while next_ns < end:
                wait_ns = next_ns - clock()
                if wait_ns > 0:
                    time.sleep(wait_ns / 1e9)
                now = clock()
                tx.send(sent, now)
                sent += 1
                next_ns = max(next_ns + period, now)  # late: no catch-up burst
        elapsed_s = (clock() - t0) / 1e9
        tx.send(END_SEQ, clock())
        conn.send(("sent", {"sent": sent, "seconds": elapsed_s}))
        conn.recv()  # "close": the subscriber is done with everything it received
        return {}
    finally:
        tx.close()


def _receiver_main(spec: SideSpec, cfg: CellConfig, shared: Any, conn: Any) -> dict[str, Any]:
    tally = _Tally(cfg)
    rx = spec.make_receiver(cfg, shared, tally)
    try:
        conn.send(("ready", None))
        publisher_done = False
        idle = 0
        hard_stop = time.monotonic() + cfg.seconds + _CONNECT_TIMEOUT_S + 60.0
        while not tally.ended and time.monotonic() < hard_stop:
            if rx.recv(_IDLE_POLL_S):
                idle = 0
                continue
            if not publisher_done:
                publisher_done = conn.poll()
                if publisher_done:
                    conn.recv()
            else:
                idle += 1
                if idle >= _IDLE_POLLS_AFTER_DONE:
                    break
        return tally.summary()
    finally:
        rx.close()


def _child_main(role: str, side: str, cfg: CellConfig, shared: Any, conn: Any) -> None:
    """Entry point of both spawned processes; answers ``(kind, payload)`` tuples on ``conn``."""
    # eCAL and iceoryx2 print to stdout / stderr from C++ / Rust: keep them out of the report
    # (``--json`` goes to stdout); failures come back on ``conn``
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    os.close(devnull)
    try:
        spec = SIDES[side]
        main = _publisher_main if role == "pub" else _receiver_main
        conn.send(("result", main(spec, cfg, shared, conn)))
    except BaseException as err:  # reported to the parent, which owns the error handling
        with contextlib.suppress(Exception):
            conn.send(("error", f"{role}: {type(err).__name__}: {err}"))
    finally:
        conn.close()


def _expect(conn: Any, proc: Any, kind: str, timeout_s: float) -> Any:
    if not conn.poll(timeout_s):
        msg = (
            f"no {kind!r} from the {proc.name} process in {timeout_s:g} s "
            f"(exit code {proc.exitcode})"
        )
        raise TransportError(msg)
    try:
        got, payload = conn.recv()
    except EOFError as err:
        msg = f"the {proc.name} process ended before {kind!r} (exit code {proc.exitcode})"
        raise TransportError(msg) from err
    if got == "error":
        raise TransportError(str(payload))
    if got != kind:
        msg = f"expected {kind!r} from the {proc.name} process, got {got!r}"
        raise TransportError(msg)
    return payload


def run_cell(
    side: str,
    size_bytes: int,
    *,
    seconds: float = 2.0,
    paced_hz: float | None = None,
    verify: bool = False,
    slots: int = SLOTS,
) -> RunResult:
    """One run of ``side`` at ``size_bytes`` (flat out, or paced at ``paced_hz``) in two fresh
    processes; raises :class:`TransportError` when the side fails."""
    spec = SIDES[side]
    if size_bytes < MIN_SIZE:
        msg = f"message size {size_bytes} B is below the {MIN_SIZE} B minimum of the benchmark"
        raise TransportError(msg)
    cfg = CellConfig(
        side=side,
        size_bytes=size_bytes,
        seconds=seconds,
        paced_hz=paced_hz,
        verify=verify,
        endpoint=f"{os.getpid()}-{uuid.uuid4().hex[:10]}",
        slots=slots,
    )
    ctx = multiprocessing.get_context("spawn")
    shared = spec.make_shared(ctx, cfg) if spec.make_shared is not None else None
    pub_conn, pub_child = ctx.Pipe()
    rx_conn, rx_child = ctx.Pipe()
    pub = ctx.Process(
        target=_child_main,
        args=("pub", side, cfg, shared, pub_child),
        name="publisher",
        daemon=True,
    )
    rx = ctx.Process(
        target=_child_main,
        args=("sub", side, cfg, shared, rx_child),
        name="subscriber",
        daemon=True,
    )
    started: list[Any] = []
    try:
        for proc, conn, child_end, kind in (
            ((pub, pub_conn, pub_child, "created"), (rx, rx_conn, rx_child, "ready"))
            if spec.publisher_first
            else ((rx, rx_conn, rx_child, "ready"), (pub, pub_conn, pub_child, "created"))
        ):
            proc.start()
            started.append(proc)
            child_end.close()  # so a child that dies shows as EOF, not as silence
            _expect(conn, proc, kind, _SPAWN_TIMEOUT_S)
        pub_conn.send("go")
        sent = _expect(pub_conn, pub, "sent", seconds + _CONNECT_TIMEOUT_S + 60.0)
        with contextlib.suppress(OSError):  # the subscriber may have seen the end and left
            rx_conn.send("publisher done")
        got = _expect(rx_conn, rx, "result", 90.0)
        pub_conn.send("close")
        _expect(pub_conn, pub, "result", 30.0)
    finally:
        for conn in (pub_conn, rx_conn):  # unblocks a child still waiting for the parent
            with contextlib.suppress(OSError, ValueError):
                conn.send("stop")
        for proc in started:
            proc.join(10.0)
            if proc.is_alive():
                logger.warning("%s of %s did not exit; terminating it", proc.name, side)
                proc.terminate()
                proc.join(5.0)
        for c in (pub_conn, rx_conn, pub_child, rx_child):
            c.close()
        if spec.make_shared is _queue_shared and shared is not None:
            shared.close()
        if spec.cleanup is not None:
            try:
                spec.cleanup(cfg)
            except Exception as err:  # a failed clean-up must not hide the result
                logger.warning("clean-up after %s failed: %s", side, err)
    rate = float(got["msgs_per_s"])
    return RunResult(
        mode="flat" if paced_hz is None else "paced",
        seconds=float(sent["seconds"]),
        sent=int(sent["sent"]),
        received=int(got["received"]),
        corrupt=int(got["corrupt"]),
        out_of_order=int(got["out_of_order"]),
        msgs_per_s=rate,
        gb_per_s=rate * size_bytes / 1e9,
        sent_per_s=sent["sent"] / sent["seconds"] if sent["seconds"] > 0 else math.nan,
        latency_p50_ms=float(got["latency_p50_ms"]),
        latency_p99_ms=float(got["latency_p99_ms"]),
        latency_max_ms=float(got["latency_max_ms"]),
    )


# ------------------------------------------------------------------------------------------------
# memcpy


def _copy_rate(dst_pool: U8, src_pool: U8, size: int, seconds: float) -> float:
    k = max(1, min(len(src_pool), len(dst_pool)) // size)
    dsts = [dst_pool[i * size : (i + 1) * size] for i in range(k)]
    srcs = [src_pool[i * size : (i + 1) * size] for i in range(k)]
    for i in range(min(k, 2)):
        np.copyto(dsts[i], srcs[i])
    copies = 0
    t0 = time.perf_counter()
    deadline = t0 + seconds
    while True:
        for _ in range(max(1, k)):
            np.copyto(dsts[copies % k], srcs[(copies * 7 + 3) % k] if k > 1 else srcs[0])
            copies += 1
        now = time.perf_counter()
        if now >= deadline and copies >= 4:
            break
    return copies * size / (now - t0) / 1e9


@contextlib.contextmanager
def _pools(nbytes: int) -> Iterator[tuple[U8, U8]]:
    src = np.empty(nbytes, np.uint8)
    dst = np.empty(nbytes, np.uint8)
    src.fill(1)  # pre-touched: no page faults inside the timing
    dst.fill(2)
    try:
        yield src, dst
    finally:
        del src, dst


def bench_memcpy(
    sizes: Sequence[int], *, seconds: float = 1.0, pool_bytes: int = MEMORY_POOL_BYTES
) -> tuple[MemcpyResult, ...]:
    """Single-thread ``np.copyto`` GB/s at each size: cache-hot (the same two buffers) and from
    memory (rotating over two ``pool_bytes`` pools, source and destination; the source index
    strides so consecutive copies do not walk the pool in order)."""
    out = []
    with _pools(max(pool_bytes, 2 * max(sizes, default=0))) as (src_pool, dst_pool):
        for size in sizes:
            hot = _copy_rate(dst_pool[:size], src_pool[:size], size, seconds / 2)
            cold = _copy_rate(dst_pool, src_pool, size, seconds / 2)
            out.append(
                MemcpyResult(
                    size_bytes=size,
                    hot_gb_per_s=hot,
                    from_memory_gb_per_s=cold,
                    pool_bytes=len(src_pool),
                )
            )
    return tuple(out)


# ------------------------------------------------------------------------------------------------
# the whole benchmark


def side_available(side: str) -> bool:
    module = SIDES[side].module
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a parent package is missing
        return False


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version(), "numpy": np.__version__}
    for dist in ("pyzmq", "eclipse-ecal", "iceoryx2", "redrive"):
        with contextlib.suppress(importlib.metadata.PackageNotFoundError):
            out[dist] = importlib.metadata.version(dist)
    return out


def _machine() -> dict[str, str]:
    model = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    mem = ""
    with contextlib.suppress(OSError, ValueError, IndexError):
        kb = int(Path("/proc/meminfo").read_text().split()[1])
        mem = f"{kb / 2**20:.0f} GiB"
    return {
        "cpu": model,
        "cpus": str(os.cpu_count()),
        "memory": mem,
        "system": f"{platform.system()} {platform.release()}",
    }


def _gb(result: TransportBenchResult, side: str, size: int, *, flat: bool = True) -> float | None:
    c = result.cell(side, size)
    run = None if c is None else (c.flat if flat else c.paced)
    if run is None or not math.isfinite(run.gb_per_s):
        return None
    return run.gb_per_s


def check_targets(result: TransportBenchResult) -> tuple[TargetCheck, ...]:
    """The issue-6 targets against what ran: in place against iceoryx2 (in place) at 1 and 4 MiB;
    both redrive sides against pipe + pickle at 4 MiB, the from-memory copy at 16 MiB and the
    paced 4 MiB p99."""
    checks: list[TargetCheck] = []
    sizes = set(result.sizes)
    mib1, mib4, mib16 = 1 << 20, 4 << 20, 16 << 20
    redrive = ("redrive-copy", "redrive-inplace")

    def ratio(name: str, side: str, *, size: int, ref: float | None, bound: float) -> None:
        value = _gb(result, side, size)
        met = None if value is None or ref is None else value >= bound * ref
        checks.append(
            TargetCheck(
                name=name,
                side=side,
                size_bytes=size,
                value=value,
                reference=ref,
                target=f"≥ {bound:g}×",
                met=met,
                note="GB/s flat out",
            )
        )

    for size in (mib1, mib4):
        if size in sizes:
            ref = _gb(result, "iceoryx2", size)
            bound = INPLACE_VS_ICEORYX2_TARGET
            ratio("vs iceoryx2 in place", "redrive-inplace", size=size, ref=ref, bound=bound)
    if mib4 in sizes:
        ref = _gb(result, "pipe-pickle", mib4)
        for side in redrive:
            ratio("vs pipe + pickle", side, size=mib4, ref=ref, bound=VS_PIPE_PICKLE_TARGET)
    if mib16 in sizes:
        mem = next((m for m in result.memcpy if m.size_bytes == mib16), None)
        ref = None if mem is None else mem.from_memory_gb_per_s
        for side in redrive:
            ratio("vs memcpy from memory", side, size=mib16, ref=ref, bound=VS_MEMCPY_TARGET)
    if mib4 in sizes:
        for side in redrive:
            c = result.cell(side, mib4)
            p99 = None if c is None or c.paced is None else _finite(c.paced.latency_p99_ms)
            checks.append(
                TargetCheck(
                    name=f"paced p99 at {result.paced_hz:g} Hz",
                    side=side,
                    size_bytes=mib4,
                    value=p99,
                    reference=PACED_P99_TARGET_MS,
                    target=f"≤ {PACED_P99_TARGET_MS:g} ms",
                    met=None if p99 is None else p99 <= PACED_P99_TARGET_MS,
                    note="ms one way",
                )
            )
    return tuple(checks)


def bench_transport(
    sizes: Sequence[int] = DEFAULT_SIZES,
    *,
    sides: Sequence[str] = DEFAULT_SIDES,
    seconds: float = 2.0,
    paced_hz: float = 100.0,
    paced: bool = True,
    memcpy: bool = True,
    verify: bool = False,
    progress: Callable[[str], None] | None = None,
) -> TransportBenchResult:
    """Every side at every size, flat out and paced, plus the memcpy ceiling.

    Each run lasts about ``seconds`` (plus process start-up); a side that is not installed or
    fails is recorded as such and the benchmark goes on.
    """
    say = progress or (lambda _text: None)
    unknown = [s for s in sides if s not in SIDES]
    if unknown:
        msg = f"unknown transport side(s) {', '.join(unknown)}; known: {', '.join(SIDES)}"
        raise TransportError(msg)
    for size in sizes:
        if size < MIN_SIZE:
            msg = f"message size {size} B is below the {MIN_SIZE} B minimum of the benchmark"
            raise TransportError(msg)
    cells: list[CellResult] = []
    for side in sides:
        spec = SIDES[side]
        if not side_available(side):
            cells.extend(
                CellResult(
                    side=side,
                    size_bytes=size,
                    status="not installed",
                    error=f"{spec.module} does not import: pip install {spec.package}",
                )
                for size in sizes
            )
            continue
        for size in sizes:
            flat_run = paced_run = None
            try:
                say(f"{spec.label}, {size_label(size)}, flat out")
                flat_run = run_cell(side, size, seconds=seconds, verify=verify)
                if paced:
                    say(f"{spec.label}, {size_label(size)}, paced at {paced_hz:g} Hz")
                    paced_run = run_cell(
                        side, size, seconds=seconds, paced_hz=paced_hz, verify=verify
                    )
            except TransportError as err:
                logger.warning("%s at %s failed: %s", side, size_label(size), err)
                cells.append(
                    CellResult(
                        side=side,
                        size_bytes=size,
                        status="error",
                        error=str(err),
                        flat=flat_run,
                        paced=paced_run,
                    )
                )
                continue
            cells.append(
                CellResult(side=side, size_bytes=size, status="ok", flat=flat_run, paced=paced_run)
            )
    mem: tuple[MemcpyResult, ...] = ()
    if memcpy:
        say("memcpy ceiling")
        mem = bench_memcpy(sizes, seconds=min(2.0, max(0.2, seconds)))
    partial = TransportBenchResult(
        sizes=tuple(sizes),
        seconds=seconds,
        paced_hz=paced_hz,
        slots=SLOTS,
        cells=tuple(cells),
        memcpy=mem,
        targets=(),
        machine=_machine(),
        versions=_versions(),
    )
    return TransportBenchResult(
        sizes=partial.sizes,
        seconds=seconds,
        paced_hz=paced_hz,
        slots=SLOTS,
        cells=partial.cells,
        memcpy=mem,
        targets=check_targets(partial),
        machine=partial.machine,
        versions=partial.versions,
    )


def size_label(size: int) -> str:
    """``65536`` → ``"64 KiB"``, ``4194304`` → ``"4 MiB"``."""
    if size % (1 << 20) == 0:
        return f"{size >> 20} MiB"
    if size % (1 << 10) == 0:
        return f"{size >> 10} KiB"
    return f"{size} B"


def parse_size(text: str) -> int:
    """``"64K"``, ``"64KiB"``, ``"4M"``, ``"4MiB"``, ``"1G"`` or plain bytes → bytes (binary
    units)."""
    t = text.strip().upper().removesuffix("B").removesuffix("I")
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30}
    try:
        if t and t[-1] in units:
            return round(float(t[:-1]) * units[t[-1]])
        return int(t)
    except ValueError as err:
        msg = f"not a message size: {text!r} (write e.g. 64K, 4M or 4MiB)"
        raise TransportError(msg) from err
