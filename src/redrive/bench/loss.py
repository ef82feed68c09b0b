"""``redrive bench loss``: the paper's loss experiment, legacy pipes + pickle against redrive.

Four sensor streams are produced by a *collector* process, paced by the wall clock, and handed to
a *core* process (sizes: bytes of sensor data, plus a 16-byte header and an 8-byte trailer):

=============  =========  ============================================================  ==========
stream         rate (1×)  data                                                          bytes
=============  =========  ============================================================  ==========
``lidar3d``    60 Hz      a VLP-16 sweep: 16 rings × 1800 azimuths = 28,800 points of   633,600
                          x, y, z, intensity f32 + ring u16 + time f32 (22 B, packed)
``lidar2d``    15 Hz      1081 ranges f32 (270° at 0.25°), padded to 8 bytes            4,328
``camera``     15 Hz      1280 × 720 rgb8                                               2,764,800
``imu``        15 Hz      10 f64 (orientation xyzw, angular velocity, acceleration)     80
=============  =========  ============================================================  ==========

and again at ``rate_factor`` times those rates (10×: 600 / 150 / 150 / 150 Hz, ≈ 800 MB/s).

Chains (each a fresh set of processes started with ``multiprocessing`` ``spawn``):

- ``legacy`` — the paper's first design: collector → ``multiprocessing.Pipe`` (``send``: pickle)
  → *bridge* (the paper's ROS handler: unpickles, wraps the payload in a ROS-message-like dict
  ``{"topic", "header": {"seq", "stamp_ns", "frame_id"}, "data"}``) → ``multiprocessing.Queue``
  (``maxsize`` :data:`QUEUE_DEPTH`; pickled again by its feeder thread) → core (``get``). One pipe
  and one queue carry all four streams, as one collector and one handler did. The payload is one
  contiguous numpy array, the cheapest thing pickle can carry: a favourable baseline.
- ``redrive`` — one :class:`redrive.transport.Writer` per stream, ``KEEP_LATEST`` (the sensor
  policy), :data:`SLOTS` slots (redrive.live's default); the collector fills the slot in place
  (``loan``); the core has one thread per stream reading with ``Reader.view`` (no copy).
- ``redrive-lossless`` — the same with ``Policy.LOSSLESS`` (the writer waits for the core).

What every process does, the same in every chain:

- **sensor clock**: message ``k`` (IDs 1, 2, … per stream) of a stream at rate ``f`` is *due* at
  ``t0 + (k − 1) / f`` on ``CLOCK_MONOTONIC`` (``time.monotonic_ns``, one clock for all
  processes); the run produces the IDs due before ``t0 + seconds``.
- **collector** (one thread): sleeps until the earliest due message of any stream, copies the
  stream's fixed template into the outgoing buffer (the legacy chain: a preallocated array, then
  ``send``; redrive: the loaned slot), writes the ID and the hand-over time into the header and
  the ID into the trailer. A sensor does not wait for its collector: if the collector falls
  :data:`SENSOR_BUFFER_S` of messages behind a stream (blocked in the transport, or starved of
  CPU), the oldest are overwritten and never sent (*skipped at the collector*), as in a driver's
  ring buffer; short of that, late messages are sent late, in order, also after ``t0 + seconds``
  for up to :data:`DRAIN_S` / 2 (what is left then is *unsent at the end*). Before ``t0`` it
  sends one warm-up message (ID 0, ignored by the core) per stream through the chain.
- **core** ("light work"): reads the ID from the header and from the trailer (they must agree, or
  the message counts as corrupt) and sums one byte per 4 KiB page of the payload, so every page
  is touched; the receipt time is ``monotonic_ns`` when the transport handed the message over,
  before that work. After ``t0 + seconds`` it keeps receiving for up to :data:`DRAIN_S`.

The measures, per stream. ``P(x)`` = the newest ID due at time ``x`` (the last ID the collector
had produced from its sensor by then); ``R(x)`` = the highest ID the core had received by ``x``;
at a receipt ``r``, ``P(r) − R(r)`` is 0 exactly when the core has the newest message and ``n``
when ``n`` newer ones had already been produced.

- **ID difference** of second ``t`` (``[t0 + t, t0 + t + 1)``, one value per second: the paper's
  Figures 10/11) = the largest ``P(r) − R(r)`` over the core's receipts in that second (``P − R``
  at the second's end if it received nothing of the stream). It is evaluated *at receipts*, not
  at an arbitrary instant: a snapshot at the second boundary would count a message merely in
  flight (0.1–1 ms on shared memory) as one ID of difference whenever the boundary falls between
  hand-over and receipt — about latency × rate of the seconds, some 20 over 30 minutes for a
  60 Hz stream, error that is not there. It is the largest rather than the last receipt's value
  so that a lag inside the second is not hidden by a timely last message (``id_diff_last`` in
  the JSON, and ``cumulative_error_last``, is the literal "last ID produced minus last ID
  received" at the last receipt).
- **cumulative error** = the sum of the ID difference over the seconds: the paper's figures plot
  the ID difference per second and its Table 5 accumulates "errors" over 30 minutes (24,889 for
  the legacy path ≈ 14 per second — the size of a lag of a dozen IDs behind a congested pipe,
  not of a count of dropped messages at 60 Hz). It is the lag in IDs, blind to a message lost
  when the next one still arrived on time, so it is always reported with:
- **lost** = messages due but never delivered, split into *skipped at the collector*, *unsent at
  the end* (in the collector's buffer when the run stopped) and *lost in transport* (handed over,
  never received: keep-latest drops, or still queued when the drain ended).
- **late** = delivered messages received after the next message of their stream was due (the
  messages that make the ID difference non-zero).
- **latency** = receipt − due time (capture to core), p50 / p99 / max; split into **collector
  delay** (hand-over − due: the collector itself was late, p99) and **transport** (receipt −
  hand-over, p99 / max).

The target (issue 6) for redrive: cumulative error 0 *and* nothing lost, at 1× and 10×, over 30
minutes: every message delivered, each before the next one of its stream was due. Configurations
run one after the other — for each rate factor, every chain in turn — never at the same time.
"""

from __future__ import annotations

import contextlib
import logging
import math
import multiprocessing
import os
import platform
import queue
import signal
import tempfile
import threading
import time
import traceback
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from redrive.errors import TransportError

__all__ = [
    "CHAINS",
    "STREAMS",
    "ConfigResult",
    "LossBenchResult",
    "StreamLoss",
    "StreamSpec",
    "bench_loss",
    "due_times",
    "measure_stream",
    "plot_loss",
    "run_configuration",
    "table_markdown",
    "wakeup_probe",
    "write_outputs",
]

logger = logging.getLogger(__name__)

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


# ------------------------------------------------------------------------------------------------
# the processes


@dataclass(frozen=True, slots=True, kw_only=True)
class _RunSpec:
    """What every process of one configuration needs (pickled to the spawned children)."""

    chain: str
    rate_factor: float
    seconds: float
    names: tuple[str, ...]  # redrive stream names, one per STREAMS entry
    out_dir: str  # where each process saves its record
    slots: int = SLOTS

    def rate(self, s: int) -> float:
        return STREAMS[s].rate_hz * self.rate_factor

    def dues(self, t0_ns: int) -> list[I64]:
        return [due_times(t0_ns, self.rate(s), self.seconds) for s in range(len(STREAMS))]


def _raise_exit(signum: int, _frame: Any) -> None:
    raise SystemExit(128 + signum)


def _watch_parent(stop: Any) -> None:
    """Set ``stop`` when the parent process dies, so no child outlives it (a thread)."""
    from multiprocessing.connection import wait

    parent = multiprocessing.parent_process()
    if parent is None:
        return

    def watch() -> None:
        wait([parent.sentinel])
        stop.set()

    threading.Thread(target=watch, name="watch-parent", daemon=True).start()


def _wait_go(ipc: dict[str, Any]) -> int:
    """Wait for the parent's go; returns ``t0`` (ns), the start of the run (≈ 0.5 s later)."""
    deadline = time.monotonic() + _START_TIMEOUT_S
    while not ipc["go"].wait(_POLL_S) and not ipc["stop"].is_set():
        if time.monotonic() > deadline:
            break
    if not ipc["go"].is_set() or ipc["stop"].is_set():
        msg = "the parent never started the run"
        raise TransportError(msg)
    return int(ipc["t0"].value)


def _sleep_until(t_ns: int) -> None:
    time.sleep(max(0.0, (t_ns - time.monotonic_ns()) / _NS))


def _collect(spec: _RunSpec, ipc: dict[str, Any], send: Callable[[int, int, int], None]) -> None:
    """The collector's loop; ``send(stream, id, handover_ns)`` hands one message over."""
    t0 = _wait_go(ipc)
    dues = spec.dues(t0)
    for s in range(len(dues)):  # warm-up, before t0: ID 0, which the core ignores
        send(s, 0, time.monotonic_ns())
        np.searchsorted(dues[s], time.monotonic_ns(), side="right")
    _sleep_until(t0)
    t_end = t0 + round((spec.seconds + DRAIN_S / 2) * _NS)  # the dues all end before t0 + seconds
    produced = [np.zeros(d.size, np.int64) for d in dues]
    buffer = [max(1, round(spec.rate(s) * SENSOR_BUFFER_S)) for s in range(len(dues))]
    nxt = [1] * len(dues)  # next ID to hand over, per stream
    stop = ipc["stop"]
    while not stop.is_set():
        live = [s for s in range(len(dues)) if nxt[s] <= dues[s].size]
        if not live:
            break
        s = min(live, key=lambda i: int(dues[i][nxt[i] - 1]))
        now = time.monotonic_ns()
        due = int(dues[s][nxt[s] - 1])
        if now >= t_end:
            break
        if due > now:
            time.sleep(min(due - now, 50_000_000) / _NS)
            continue
        newest = int(np.searchsorted(dues[s], now, side="right"))
        if newest - nxt[s] >= buffer[s]:  # overwritten in the sensor's buffer
            first = newest - buffer[s] + 1
            produced[s][nxt[s] - 1 : first - 1] = _SKIPPED
            nxt[s] = first
        k = nxt[s]
        produced[s][k - 1] = time.monotonic_ns()
        send(s, k, int(produced[s][k - 1]))
        nxt[s] += 1
    for s in range(len(dues)):
        sent = np.nonzero(produced[s] > 0)[0]
        ipc["last_sent"][s] = int(sent[-1]) + 1 if sent.size else 0
    ipc["collector_done"].set()
    record: dict[str, Any] = {f"produced_{s}": p for s, p in enumerate(produced)}
    np.savez(Path(spec.out_dir) / "collector.npz", t0=np.int64(t0), **record)


def _collector_legacy(spec: _RunSpec, ipc: dict[str, Any]) -> None:
    conn = ipc["pipe_send"]
    bufs = [_template(st) for st in STREAMS]
    templates = [b.copy() for b in bufs]
    ipc["status"].put(("ready", "collector"))

    def send(s: int, k: int, handover_ns: int) -> None:
        np.copyto(bufs[s], templates[s])
        _stamp(bufs[s], k, handover_ns)
        conn.send((s, k, handover_ns, bufs[s]))  # pickled now, into the pipe

    try:
        _collect(spec, ipc, send)
    finally:
        with contextlib.suppress(OSError):
            conn.send(None)
        conn.close()
    ipc["status"].put(("done", "collector"))


def _collector_redrive(spec: _RunSpec, ipc: dict[str, Any]) -> None:
    from redrive.transport import Policy, Writer

    policy = Policy.LOSSLESS if spec.chain == "redrive-lossless" else Policy.KEEP_LATEST
    templates = [_template(st) for st in STREAMS]
    with contextlib.ExitStack() as stack:
        writers = [
            stack.enter_context(
                Writer(name, capacity_bytes=st.payload_bytes, slots=spec.slots, policy=policy,
                       max_readers=1)
            )
            for name, st in zip(spec.names, STREAMS, strict=True)
        ]  # fmt: skip
        ipc["status"].put(("ready", "collector"))

        def send(s: int, k: int, handover_ns: int) -> None:
            with writers[s].loan(templates[s].size, stamp_ns=handover_ns, timeout_s=10.0) as out:
                np.copyto(out, templates[s])
                _stamp(out, k, handover_ns)

        _collect(spec, ipc, send)
        ipc["status"].put(("done", "collector"))
        ipc["stop"].wait(DRAIN_S + 60.0)  # keep the streams until the core has drained them


def _bridge_legacy(spec: _RunSpec, ipc: dict[str, Any]) -> None:
    conn, out, stop = ipc["pipe_recv"], ipc["queue"], ipc["stop"]
    out.cancel_join_thread()  # never hang at exit on a queue nobody reads (see the end)
    ipc["status"].put(("ready", "bridge"))
    while True:
        if not conn.poll(_POLL_S):
            if stop.is_set():
                break  # the run is over and the collector sends nothing more
            continue
        try:
            item = conn.recv()
        except EOFError:
            break
        if item is None:
            msg: dict[str, Any] | None = None
        elif stop.is_set():
            continue  # the core has finished: drain the pipe so the collector is not stuck
        else:
            s, k, handover_ns, payload = item
            name = STREAMS[s].name
            header = {"seq": k, "stamp_ns": handover_ns, "frame_id": name}
            msg = {"topic": f"/{name}", "stream": s, "header": header, "data": payload}
        while not stop.is_set():
            try:
                out.put(msg, timeout=_POLL_S)
                break
            except queue.Full:
                continue
        if item is None:
            break
    ipc["status"].put(("done", "bridge"))
    stop.wait(DRAIN_S + 60.0)  # the queue's feeder thread must flush before the bridge exits


class _CoreRecord:
    """What the core received of each stream: receipt time per ID (0: never)."""

    def __init__(self, spec: _RunSpec, t0: int) -> None:
        self.dues = spec.dues(t0)
        self.recv = [np.zeros(d.size, np.int64) for d in self.dues]
        self.corrupt = [0] * len(STREAMS)
        self.dropped = [0] * len(STREAMS)  # the transport's own drop counter (keep-latest)
        self.last = [0] * len(STREAMS)
        self.checksum = 0
        self.drain_end = t0 + round((spec.seconds + DRAIN_S) * _NS)

    def got(self, s: int, payload: U8, recv_ns: int) -> None:
        head, tail, pages = _touch(payload)
        self.checksum += pages
        if head == tail == 0:
            return  # the collector's warm-up message
        if head != tail or not 1 <= head <= self.recv[s].size:
            self.corrupt[s] += 1
            return
        self.recv[s][head - 1] = recv_ns
        self.last[s] = max(self.last[s], head)

    def finished(self, s: int, ipc: dict[str, Any]) -> bool:
        if time.monotonic_ns() >= self.drain_end or ipc["stop"].is_set():
            return True
        return bool(ipc["collector_done"].is_set() and self.last[s] >= ipc["last_sent"][s])

    def save(self, spec: _RunSpec) -> None:
        record: dict[str, Any] = {f"recv_{s}": r for s, r in enumerate(self.recv)}
        record.update(corrupt=np.array(self.corrupt), dropped=np.array(self.dropped))
        np.savez(Path(spec.out_dir) / "core.npz", **record)


def _core_legacy(spec: _RunSpec, ipc: dict[str, Any]) -> None:
    q = ipc["queue"]
    ipc["status"].put(("ready", "core"))
    rec = _CoreRecord(spec, _wait_go(ipc))
    while not all(rec.finished(s, ipc) for s in range(len(STREAMS))):
        try:
            msg = q.get(timeout=_POLL_S)
        except queue.Empty:
            continue
        if msg is None:
            break
        now = time.monotonic_ns()
        rec.got(int(msg["stream"]), msg["data"], now)
    rec.save(spec)
    ipc["status"].put(("done", "core"))


def _core_redrive(spec: _RunSpec, ipc: dict[str, Any]) -> None:
    from redrive.transport import Reader

    with contextlib.ExitStack() as stack:
        readers = [stack.enter_context(Reader(name, timeout_s=30.0)) for name in spec.names]
        ipc["status"].put(("ready", "core"))
        rec = _CoreRecord(spec, _wait_go(ipc))
        errors: list[BaseException] = []

        def loop(s: int) -> None:
            try:
                while not rec.finished(s, ipc):
                    with readers[s].view(_POLL_S) as msg:
                        if msg is None:
                            continue
                        now = time.monotonic_ns()
                        rec.dropped[s] += msg.dropped_before
                        rec.got(s, msg.payload, now)
            except BaseException as err:  # re-raised in the main thread below
                errors.append(err)

        threads = [
            threading.Thread(target=loop, args=(s,), name=f"core-{st.name}", daemon=True)
            for s, st in enumerate(STREAMS)
        ]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        if errors:
            raise errors[0]
        rec.save(spec)
        ipc["status"].put(("done", "core"))


_ROLES: dict[str, Callable[[_RunSpec, dict[str, Any]], None]] = {
    "collector-legacy": _collector_legacy,
    "bridge-legacy": _bridge_legacy,
    "core-legacy": _core_legacy,
    "collector-redrive": _collector_redrive,
    "core-redrive": _core_redrive,
}


def _child_main(role: str, spec: _RunSpec, ipc: dict[str, Any]) -> None:
    """Entry point of every spawned process; each role reports ``("ready", role)`` and
    ``("done", role)`` on the status queue, and this ``("error", role, text)``."""
    signal.signal(signal.SIGTERM, _raise_exit)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C: the parent sets ``stop``
    _watch_parent(ipc["stop"])
    short = role.split("-", 1)[0]
    try:
        _ROLES[role](spec, ipc)
    except BaseException as err:
        if not ipc["stop"].is_set():
            text = f"{type(err).__name__}: {err}\n{traceback.format_exc()}"
            ipc["status"].put(("error", short, text))
        raise SystemExit(1) from None


# ------------------------------------------------------------------------------------------------
# the measures


def _pct(values: npt.NDArray[np.float64], q: float) -> float:
    return float(np.percentile(values, q)) if values.size else math.nan


@dataclass(frozen=True, slots=True, kw_only=True)
class StreamLoss:
    """The measures of one stream in one configuration (see the module docstring).

    ``due = delivered + skipped_at_collector + unsent_at_end + lost_in_transport``. The series have
    one value per second of the run.
    """

    name: str
    rate_hz: float
    payload_bytes: int
    due: int
    delivered: int
    skipped_at_collector: int
    unsent_at_end: int
    lost_in_transport: int
    transport_dropped: int  # the reader's own count of keep-latest drops (redrive)
    corrupt: int
    late: int
    cumulative_error: int
    cumulative_error_last: int  # Σ of the snapshot at the last receipt of each second
    max_id_diff: int
    latency_p50_ms: float
    latency_p99_ms: float
    latency_max_ms: float
    collector_delay_p99_ms: float
    transport_p99_ms: float  # receipt − hand-over: the transport and the core's wake-up
    transport_max_ms: float
    id_diff: tuple[int, ...]
    id_diff_last: tuple[int, ...]
    lost_per_s: tuple[int, ...]

    @property
    def lost(self) -> int:
        return self.due - self.delivered

    def to_json(self, *, series: bool = True) -> dict[str, Any]:
        out: dict[str, Any] = {
            f: _finite(getattr(self, f))
            for f in self.__slots__
            if f not in ("id_diff", "id_diff_last", "lost_per_s")
        }
        out["lost"] = self.lost
        if series:
            out["series"] = {
                "id_diff": list(self.id_diff),
                "id_diff_last": list(self.id_diff_last),
                "lost": list(self.lost_per_s),
            }
        return out


def _finite(x: Any) -> Any:
    return None if isinstance(x, float) and not math.isfinite(x) else x


def measure_stream(
    name: str,
    *,
    rate_hz: float,
    payload_bytes: int,
    due_ns: I64,
    produced_ns: I64,
    recv_ns: I64,
    t0_ns: int,
    seconds: float,
    transport_dropped: int = 0,
    corrupt: int = 0,
) -> StreamLoss:
    """The measures of one stream from its three records, indexed by ID − 1: ``due_ns`` (sensor
    clock), ``produced_ns`` (hand-over time; 0 never handed over, −1 skipped at the collector) and
    ``recv_ns`` (receipt at the core; 0 never)."""
    delivered = recv_ns > 0
    ids = np.nonzero(delivered)[0] + 1
    recv = recv_ns[delivered]
    order = np.argsort(recv, kind="stable")
    ids, recv = ids[order], recv[order]
    high = np.maximum.accumulate(ids) if ids.size else ids  # R at each receipt
    newest = np.searchsorted(due_ns, recv, side="right")  # P at each receipt
    behind = newest - high
    n_sec = max(1, math.ceil(seconds - 1e-9))
    starts = t0_ns + np.arange(n_sec, dtype=np.int64) * _NS
    lo = np.searchsorted(recv, starts, side="left")
    hi = np.searchsorted(recv, starts + _NS, side="left")
    id_diff = np.zeros(n_sec, np.int64)
    id_last = np.zeros(n_sec, np.int64)
    for t in range(n_sec):
        if hi[t] > lo[t]:
            id_diff[t] = behind[lo[t] : hi[t]].max()
            id_last[t] = behind[hi[t] - 1]
        else:  # nothing received this second: P − R at its end
            got = int(high[hi[t] - 1]) if hi[t] > 0 else 0
            end_p = int(np.searchsorted(due_ns, starts[t] + _NS - 1, side="right"))
            id_diff[t] = id_last[t] = max(0, end_p - got)
    lost_sec = np.clip((due_ns[~delivered] - t0_ns) // _NS, 0, n_sec - 1)
    lost_per_s = np.bincount(lost_sec, minlength=n_sec)
    latency_ms = (recv - due_ns[ids - 1]) / 1e6
    sent = produced_ns > 0
    delay_ms = (produced_ns[sent] - due_ns[sent]) / 1e6
    transport_ms = (recv - produced_ns[ids - 1]) / 1e6
    return StreamLoss(
        name=name,
        rate_hz=rate_hz,
        payload_bytes=payload_bytes,
        due=int(due_ns.size),
        delivered=int(ids.size),
        skipped_at_collector=int(np.count_nonzero(produced_ns == _SKIPPED)),
        unsent_at_end=int(np.count_nonzero(produced_ns == 0)),
        lost_in_transport=int(np.count_nonzero(sent & ~delivered)),
        transport_dropped=transport_dropped,
        corrupt=corrupt,
        late=int(np.count_nonzero(newest > ids)),
        cumulative_error=int(id_diff.sum()),
        cumulative_error_last=int(id_last.sum()),
        max_id_diff=int(id_diff.max()),
        latency_p50_ms=_pct(latency_ms, 50),
        latency_p99_ms=_pct(latency_ms, 99),
        latency_max_ms=float(latency_ms.max()) if latency_ms.size else math.nan,
        collector_delay_p99_ms=_pct(delay_ms, 99),
        transport_p99_ms=_pct(transport_ms, 99),
        transport_max_ms=float(transport_ms.max()) if transport_ms.size else math.nan,
        id_diff=tuple(int(x) for x in id_diff),
        id_diff_last=tuple(int(x) for x in id_last),
        lost_per_s=tuple(int(x) for x in lost_per_s),
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class ConfigResult:
    """One chain at one rate factor; ``error`` says why it did not complete (then no streams)."""

    chain: str
    rate_factor: float
    seconds: float
    streams: tuple[StreamLoss, ...]
    error: str | None = None

    @property
    def label(self) -> str:
        return f"{self.chain} {self.rate_factor:g}×"

    @property
    def cumulative_error(self) -> int:
        return sum(s.cumulative_error for s in self.streams)

    @property
    def lost(self) -> int:
        return sum(s.lost for s in self.streams)

    @property
    def meets_target(self) -> bool | None:
        """The issue's target (cumulative error 0 and nothing lost) for redrive chains."""
        if not self.chain.startswith("redrive"):
            return None
        return self.error is None and self.cumulative_error == 0 and self.lost == 0

    def to_json(self, *, series: bool = True) -> dict[str, Any]:
        return {
            "chain": self.chain,
            "rate_factor": self.rate_factor,
            "seconds": self.seconds,
            "error": self.error,
            "cumulative_error": self.cumulative_error,
            "lost": self.lost,
            "late": sum(s.late for s in self.streams),
            "meets_target": self.meets_target,
            "streams": [s.to_json(series=series) for s in self.streams],
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class LossBenchResult:
    """Every configuration of one :func:`bench_loss` run, in the order they ran."""

    seconds: float
    configs: tuple[ConfigResult, ...]
    machine: dict[str, str]
    slots: int = SLOTS
    wakeup: dict[str, float] | None = None  # :func:`wakeup_probe` before the first configuration

    def to_json(self, *, series: bool = True) -> dict[str, Any]:
        return {
            "benchmark": "loss",
            "seconds": self.seconds,
            "order": "sequential: for each rate factor, each chain in turn",
            "streams": [
                {"name": s.name, "rate_hz_1x": s.rate_hz, "payload_bytes": s.payload_bytes}
                for s in STREAMS
            ],
            "settings": {
                "sensor_buffer_s": SENSOR_BUFFER_S,
                "legacy_queue_depth": QUEUE_DEPTH,
                "drain_s": DRAIN_S,
                "redrive_slots": self.slots,
            },
            "definitions": {
                "id_diff": "per second: the largest (newest ID due - highest ID received) "
                "over the core's receipts in that second (at the second's end if none)",
                "id_diff_last": "the same at the core's last receipt in the second",
                "cumulative_error": "sum over the seconds of id_diff",
                "lost": "due but never delivered = skipped at the collector (its 1 s buffer "
                "overran) + unsent at the end + lost in transport (handed over, never received)",
                "late": "delivered after the next message of the stream was due",
                "latency": "receipt at the core - due time",
                "collector_delay": "hand-over by the collector - due time",
                "transport": "receipt at the core - hand-over by the collector",
            },
            "machine": dict(self.machine),
            "wakeup_probe": self.wakeup,
            "configurations": [c.to_json(series=series) for c in self.configs],
        }


# ------------------------------------------------------------------------------------------------
# running one configuration


def _await(
    status: Any,
    procs: dict[str, Any],
    want: set[str],
    kind: str,
    *,
    timeout_s: float,
    tick: Callable[[], None] | None = None,
) -> None:
    """Wait until every role in ``want`` reported ``kind``; TransportError on error/death/timeout."""
    deadline = time.monotonic() + timeout_s
    pending = set(want)
    while pending:
        try:
            item = status.get(timeout=0.5)
        except queue.Empty:
            if tick is not None:
                tick()
            for role, proc in sorted(procs.items()):
                code = proc.exitcode
                if code is not None and (code != 0 or role in pending):
                    msg = f"the {role} process exited (code {code}) before it was {kind}"
                    raise TransportError(msg) from None
            if time.monotonic() > deadline:
                msg = f"timed out after {timeout_s:.0f} s waiting for {', '.join(sorted(pending))}"
                raise TransportError(msg) from None
            continue
        if item[0] == "error":
            msg = f"the {item[1]} process failed: {item[2]}"
            raise TransportError(msg)
        if item[0] == kind:
            pending.discard(item[1])


_PRIVATE = {"collector-legacy": ("pipe_send",), "bridge-legacy": ("pipe_recv", "queue"),
            "core-legacy": ("queue",)}  # fmt: skip


def _role_ipc(ipc: dict[str, Any], role: str) -> dict[str, Any]:
    """What ``role`` gets: each pipe end and the queue go only to their users (a pipe whose other
    end is held by a bystander never reports EOF or a broken pipe when its peer dies)."""
    private = {k for keys in _PRIVATE.values() for k in keys}
    return {k: v for k, v in ipc.items() if k not in private or k in _PRIVATE.get(role, ())}


def _stop(procs: dict[str, Any]) -> None:
    for proc in procs.values():
        proc.join(_JOIN_TIMEOUT_S)
        if proc.is_alive():
            logger.warning("%s did not exit; terminating it", proc.name)
            proc.terminate()
            proc.join(5.0)
        if proc.is_alive():
            proc.kill()
            proc.join(5.0)


def run_configuration(
    chain: str,
    rate_factor: float,
    *,
    seconds: float,
    slots: int = SLOTS,
    progress: Callable[[str], None] | None = None,
) -> ConfigResult:
    """Run ``chain`` at ``rate_factor`` × the sensor rates for ``seconds`` in fresh processes.

    Raises:
        TransportError: a process failed, died or hung (all of them are stopped first).
    """
    if chain not in CHAINS:
        msg = f"unknown chain {chain!r}; known: {', '.join(CHAINS)}"
        raise TransportError(msg)
    ctx = multiprocessing.get_context("spawn")
    tag = f"loss-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    names = tuple(f"{tag}.{st.name}" for st in STREAMS)
    legacy = chain == "legacy"
    label = f"{chain} {rate_factor:g}×"
    with tempfile.TemporaryDirectory(prefix="redrive-loss-") as tmp:
        spec = _RunSpec(
            chain=chain, rate_factor=rate_factor, seconds=seconds, names=names, out_dir=tmp,
            slots=slots,
        )  # fmt: skip
        ipc: dict[str, Any] = {
            "status": ctx.Queue(),
            "go": ctx.Event(),
            "stop": ctx.Event(),
            "collector_done": ctx.Event(),
            "t0": ctx.RawValue("q", 0),
            "last_sent": ctx.RawArray("q", len(STREAMS)),
        }
        roles = ["core-redrive", "collector-redrive"]
        if legacy:
            ipc["pipe_recv"], ipc["pipe_send"] = ctx.Pipe(duplex=False)
            ipc["queue"] = ctx.Queue(maxsize=QUEUE_DEPTH)
            roles = ["core-legacy", "bridge-legacy", "collector-legacy"]
        else:
            roles.reverse()  # the collector creates the streams the core attaches to
        procs: dict[str, Any] = {}
        try:
            for role in roles:
                short = role.split("-", 1)[0]
                proc = ctx.Process(
                    target=_child_main,
                    args=(role, spec, _role_ipc(ipc, role)),
                    name=f"loss-{role}",
                    daemon=True,
                )
                proc.start()
                procs[short] = proc
                _await(ipc["status"], procs, {short}, "ready", timeout_s=_START_TIMEOUT_S)
            if legacy:  # the children hold the pipe now: EOF when one side dies
                ipc["pipe_recv"].close()
                ipc["pipe_send"].close()
            t0 = time.monotonic_ns() + 500_000_000
            ipc["t0"].value = t0
            ipc["go"].set()

            def tick() -> None:
                if progress is not None:
                    now = max(0.0, (time.monotonic_ns() - t0) / _NS)
                    progress(f"{label}: {min(now, seconds):.0f}/{seconds:g} s")

            _await(
                ipc["status"], procs, set(procs) - {"bridge"}, "done",
                timeout_s=seconds + DRAIN_S + 120.0, tick=tick,
            )  # fmt: skip
            coll = np.load(Path(tmp) / "collector.npz")
            core = np.load(Path(tmp) / "core.npz")
        finally:
            ipc["stop"].set()
            ipc["go"].set()
            _stop(procs)
            if not legacy:
                from redrive.transport import remove_stale

                for name in names:
                    remove_stale(name)
            for q in (ipc["status"], ipc.get("queue")):
                if q is not None:
                    q.close()
                    q.cancel_join_thread()
        t0 = int(coll["t0"])
        dues = spec.dues(t0)
        streams = tuple(
            measure_stream(
                st.name,
                rate_hz=spec.rate(s),
                payload_bytes=st.payload_bytes,
                due_ns=dues[s],
                produced_ns=coll[f"produced_{s}"],
                recv_ns=core[f"recv_{s}"],
                t0_ns=t0,
                seconds=seconds,
                transport_dropped=int(core["dropped"][s]),
                corrupt=int(core["corrupt"][s]),
            )
            for s, st in enumerate(STREAMS)
        )
    return ConfigResult(chain=chain, rate_factor=rate_factor, seconds=seconds, streams=streams)


def _machine() -> dict[str, str]:
    model = platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    load = ""
    with contextlib.suppress(OSError):
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    return {
        "cpu": model,
        "cpus": str(os.cpu_count()),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "numpy": np.__version__,
        "load_average_at_start": load,
    }


def wakeup_probe(seconds: float, *, period_s: float = 1 / 600) -> dict[str, float]:
    """How late ``time.sleep(period_s)`` wakes up on this machine, in ms (p50, p99, p99.9, max)
    and the fraction of sleeps that overshoot by more than ``period_s``: the floor under the
    ``late`` count of a stream at ``1 / period_s`` Hz, whatever the transport (the collector wakes
    up like this before every message)."""
    n = max(1, round(seconds / period_s))
    over = np.empty(n)
    for i in range(n):
        t = time.monotonic_ns()
        time.sleep(period_s)
        over[i] = (time.monotonic_ns() - t) / 1e6 - period_s * 1e3
    return {
        "period_ms": period_s * 1e3,
        "sleeps": float(n),
        "overshoot_p50_ms": _pct(over, 50),
        "overshoot_p99_ms": _pct(over, 99),
        "overshoot_p999_ms": _pct(over, 99.9),
        "overshoot_max_ms": float(over.max()),
        "fraction_over_one_period": float(np.mean(over > period_s * 1e3)),
    }


def bench_loss(
    *,
    seconds: float = 1800.0,
    rate_factors: Sequence[float] = (1.0, 10.0),
    chains: Sequence[str] = ("legacy", "redrive"),
    slots: int = SLOTS,
    progress: Callable[[str], None] | None = None,
) -> LossBenchResult:
    """Every chain at every rate factor, one after the other, ``seconds`` each. A configuration
    that fails is reported with its ``error``; the others still run."""
    if seconds <= 0 or not rate_factors or any(f <= 0 for f in rate_factors) or slots < 3:
        msg = (
            "need seconds > 0, rate factors > 0 and at least 3 slots "
            f"(got {seconds}, {list(rate_factors)}, {slots})"
        )
        raise TransportError(msg)
    unknown = [c for c in chains if c not in CHAINS]
    if unknown or not chains:
        msg = f"unknown chain(s) {', '.join(unknown) or '(none given)'}; known: {', '.join(CHAINS)}"
        raise TransportError(msg)
    machine = _machine()
    probe = wakeup_probe(min(3.0, seconds / 10))
    configs: list[ConfigResult] = []
    for factor in rate_factors:
        for chain in chains:
            logger.info("loss benchmark: %s at %g× for %g s", chain, factor, seconds)
            try:
                configs.append(
                    run_configuration(
                        chain, factor, seconds=seconds, slots=slots, progress=progress
                    )
                )
            except TransportError as err:
                logger.warning("loss benchmark: %s at %g× failed: %s", chain, factor, err)
                configs.append(
                    ConfigResult(
                        chain=chain, rate_factor=factor, seconds=seconds, streams=(),
                        error=str(err),
                    )
                )  # fmt: skip
    return LossBenchResult(
        seconds=seconds, configs=tuple(configs), machine=machine, slots=slots, wakeup=probe
    )


# ------------------------------------------------------------------------------------------------
# outputs


def _ms(x: float) -> str:
    return "–" if not math.isfinite(x) else f"{x:.1f}" if x >= 10 else f"{x:.2f}"


def table_markdown(result: LossBenchResult) -> str:
    """The Table-5-like table: one row per stream and configuration, a total per configuration."""
    lines = [
        "| configuration | stream | Hz | due | delivered | lost (skipped at collector / unsent "
        "at end / in transport) | late | **cumulative error** (Σ ID difference) | max ID "
        "difference | latency p50 / p99 / max ms | p99 ms collector / transport |",
        "|---|---|---:|---:|---:|---|---:|---:|---:|---|---|",
    ]
    for c in result.configs:
        if c.error is not None:
            lines.append(f"| {c.label} | failed: {c.error.splitlines()[0]} |||||||||")
            continue
        for s in c.streams:
            lines.append(
                f"| {c.label} | {s.name} | {s.rate_hz:g} | {s.due:,} | {s.delivered:,} | "
                f"{s.lost:,} ({s.skipped_at_collector:,} / {s.unsent_at_end:,} / "
                f"{s.lost_in_transport:,}) | {s.late:,} | {s.cumulative_error:,} | "
                f"{s.max_id_diff:,} | {_ms(s.latency_p50_ms)} / {_ms(s.latency_p99_ms)} / "
                f"{_ms(s.latency_max_ms)} | {_ms(s.collector_delay_p99_ms)} / "
                f"{_ms(s.transport_p99_ms)} |"
            )
        late = sum(s.late for s in c.streams)
        due = sum(s.due for s in c.streams)
        got = sum(s.delivered for s in c.streams)
        lines.append(
            f"| **{c.label}** | **all** | | {due:,} | {got:,} | **{c.lost:,}** | {late:,} | "
            f"**{c.cumulative_error:,}** | | | |"
        )
    return "\n".join(lines) + "\n"


def plot_loss(result: LossBenchResult, path: Path) -> None:
    """The paper's Figures 10/11: ID difference per second, one panel per chain and rate factor
    (a line per stream), and the cumulative error over time of every chain per rate factor."""
    from matplotlib.figure import Figure

    factors = list(dict.fromkeys(c.rate_factor for c in result.configs))
    chains = list(dict.fromkeys(c.chain for c in result.configs))
    fig = Figure(figsize=(4.2 * (len(chains) + 1), 3.0 * len(factors)), layout="constrained")
    axes = fig.subplots(len(factors), len(chains) + 1, squeeze=False)
    for c in result.configs:
        row = factors.index(c.rate_factor)
        ax = axes[row][chains.index(c.chain)]
        cum = axes[row][-1]
        if c.error is not None:
            ax.set_title(f"{c.label}: failed", fontsize=9)
            continue
        total = np.zeros(len(c.streams[0].id_diff), np.int64)
        edges = np.arange(total.size + 1)
        for s in c.streams:
            ax.stairs(s.id_diff, edges, lw=0.9, label=f"{s.name} ({s.rate_hz:g} Hz)")
            total += np.asarray(s.id_diff)
        ax.set_title(
            f"{c.label}: cumulative error {c.cumulative_error:,}, lost {c.lost:,}", fontsize=9
        )
        ax.set_xlabel("time (s)")
        ax.set_ylabel("ID difference (collector − core)")
        ax.set_ylim(bottom=0, top=max(1.0, float(total.max()) * 1.05))
        ax.legend(fontsize=7, loc="upper left")
        cum.plot(edges[1:], np.cumsum(total), lw=1.0, label=c.chain)
        cum.set_yscale("symlog", linthresh=1.0)
        cum.set_ylim(bottom=0, top=max(10.0, 2.0 * cum.get_ylim()[1]))
        cum.set_title(f"{c.rate_factor:g}×: cumulative error (all streams)", fontsize=9)
        cum.set_xlabel("time (s)")
        cum.legend(fontsize=7, loc="upper left")
    fig.savefig(path, dpi=110, format="png")


def write_outputs(result: LossBenchResult, out_dir: Path) -> dict[str, Path]:
    """``loss.json`` (everything, with the per-second series), ``loss.png`` and ``loss_table.md``
    in ``out_dir`` (created); returns their paths by kind."""
    import json

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {
        "json": out_dir / "loss.json",
        "png": out_dir / "loss.png",
        "table": out_dir / "loss_table.md",
    }
    for kind, write in (
        ("json", lambda p: p.write_text(json.dumps(result.to_json(), indent=1) + "\n")),
        ("png", lambda p: plot_loss(result, p)),
        ("table", lambda p: p.write_text(table_markdown(result))),
    ):
        tmp = paths[kind].with_name(paths[kind].name + ".tmp")
        write(tmp)
        tmp.replace(paths[kind])
    return paths
