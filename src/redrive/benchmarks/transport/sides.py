"""One run of one side at one size: the message every side sends (a stamp, a sequence number, a
seeded pattern) and what every subscriber does with it, the sides (redrive copy-out and in place,
pipe + pickle: :data:`SIDES`), and :func:`run_cell`, which starts the publisher and subscriber
processes (``spawn``), hands out the go and collects what each measured.  Peers (ZeroMQ, eCAL,
iceoryx2, ``multiprocessing.Queue``) are sides of the repository's ``benchmarks/transport_peers.py``,
a catalogue that adds them to these."""

from __future__ import annotations

import contextlib
import importlib
import logging
import math
import multiprocessing
import os
import struct
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from redrive.benchmarks._base import fields_json
from redrive.errors import TransportError

__all__ = [
    "CATALOGUE", "MIN_SIZE", "SIDES", "SLOTS", "CellConfig", "RunResult",
    "SideSpec", "catalogue_sides", "run_cell",
]  # fmt: skip

logger = logging.getLogger(__name__)

U8 = npt.NDArray[np.uint8]
HEADER = struct.Struct("<qq")  # stamp_ns, seq
END_SEQ = -1
TOUCH_STRIDE = 4096
MIN_SIZE = TOUCH_STRIDE
SLOTS = 4
WARMUP_FRACTION = 0.1
SEED = 6
_CONNECT_TIMEOUT_S = 20.0
_IDLE_POLL_S = 0.05
_IDLE_POLLS_AFTER_DONE = 4  # 0.2 s without a message once the publisher has finished
_SPAWN_TIMEOUT_S = 60.0


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
        return fields_json(self, lost=self.lost, lost_fraction=self.lost_fraction)


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
        self.corrupt = self.out_of_order = 0
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
        out: dict[str, Any] = {"received": len(self.seen), "corrupt": self.corrupt}
        out |= {"out_of_order": self.out_of_order, "msgs_per_s": math.nan}
        out |= {f"latency_{k}_ms": math.nan for k in ("p50", "p99", "max")}
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


class _PipeSender(_NoWait):
    """pipe + pickle, the legacy path of the paper."""

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


def _redrive_side(name: str, label: str, *, in_place: bool) -> SideSpec:
    return SideSpec(
        name=name, label=label, module="redrive.transport", package="redrive",
        publisher_first=True, lossy=False, in_place=in_place,
        make_sender=lambda cfg, _sh: _RedriveSender(cfg, in_place=in_place),
        make_receiver=lambda cfg, _sh, t: _RedriveReceiver(cfg, t, in_place=in_place),
        cleanup=_redrive_cleanup,
    )  # fmt: skip


SIDES: Mapping[str, SideSpec] = {
    s.name: s
    for s in (
        _redrive_side("redrive-copy", "redrive copy-out", in_place=False),
        _redrive_side("redrive-inplace", "redrive in place", in_place=True),
        SideSpec(
            name="pipe-pickle", label="pipe + pickle", module="multiprocessing",
            package="(standard library)", publisher_first=False, lossy=False, in_place=False,
            make_sender=_PipeSender, make_receiver=_PipeReceiver,
            make_shared=lambda ctx, cfg: ctx.Pipe(duplex=False),  # (receiving end, sending end)
        ),
    )
}  # fmt: skip
#: the module whose SIDES the spawned children look a side up in (``python -m benchmarks
#: transport`` passes its own, with the peers added)
CATALOGUE = __name__


def catalogue_sides(catalogue: str = CATALOGUE) -> Mapping[str, SideSpec]:
    """The sides of ``catalogue``, a module with a ``SIDES`` mapping."""
    sides: Mapping[str, SideSpec] = importlib.import_module(catalogue).SIDES
    return sides


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
        spec = catalogue_sides(cfg.catalogue)[side]
        main = _publisher_main if role == "pub" else _receiver_main
        conn.send(("result", main(spec, cfg, shared, conn)))
    except BaseException as err:  # reported to the parent, which owns the error handling
        with contextlib.suppress(Exception):
            conn.send(("error", f"{role}: {type(err).__name__}: {err}"))
    finally:
        conn.close()


def _expect(conn: Any, proc: Any, kind: str, timeout_s: float) -> Any:
    if not conn.poll(timeout_s):
        msg = f"no {kind!r} from the {proc.name} process in {timeout_s:g} s (exit code {proc.exitcode})"
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


def check_size(size_bytes: int) -> None:
    """Raise :class:`TransportError` below the benchmark's :data:`MIN_SIZE`."""
    if size_bytes < MIN_SIZE:
        msg = f"message size {size_bytes} B is below the {MIN_SIZE} B minimum of the benchmark"
        raise TransportError(msg)


def run_cell(
    side: str,
    size_bytes: int,
    *,
    seconds: float = 2.0,
    paced_hz: float | None = None,
    verify: bool = False,
    slots: int = SLOTS,
    catalogue: str = CATALOGUE,
) -> RunResult:
    """One run of ``side`` (of the module ``catalogue``'s ``SIDES``) at ``size_bytes`` (flat out,
    or paced at ``paced_hz``) in two fresh processes; raises :class:`TransportError` when the
    side fails.  A script calling it needs the ``if __name__ == "__main__":`` guard (``spawn``)."""
    spec = catalogue_sides(catalogue)[side]
    check_size(size_bytes)
    endpoint = f"{os.getpid()}-{uuid.uuid4().hex[:10]}"
    cfg = CellConfig(
        side=side, size_bytes=size_bytes, seconds=seconds, paced_hz=paced_hz, verify=verify,
        endpoint=endpoint, slots=slots, catalogue=catalogue,
    )  # fmt: skip
    ctx = multiprocessing.get_context("spawn")
    shared = spec.make_shared(ctx, cfg) if spec.make_shared is not None else None
    pub_conn, pub_child = ctx.Pipe()
    rx_conn, rx_child = ctx.Pipe()
    pub, rx = (
        ctx.Process(
            target=_child_main, args=(role, side, cfg, shared, child), name=name, daemon=True
        )
        for role, child, name in (("pub", pub_child, "publisher"), ("sub", rx_child, "subscriber"))
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
        close_shared = getattr(shared, "close", None)  # a queue; a pipe pair has none
        if callable(close_shared):
            close_shared()
        if spec.cleanup is not None:
            try:
                spec.cleanup(cfg)
            except Exception as err:  # a failed clean-up must not hide the result
                logger.warning("clean-up after %s failed: %s", side, err)
    rate, n, seconds = float(got["msgs_per_s"]), int(sent["sent"]), float(sent["seconds"])
    return RunResult(
        mode="flat" if paced_hz is None else "paced", seconds=seconds, sent=n,
        received=int(got["received"]), corrupt=int(got["corrupt"]),
        out_of_order=int(got["out_of_order"]), msgs_per_s=rate, gb_per_s=rate * size_bytes / 1e9,
        sent_per_s=n / seconds if seconds > 0 else math.nan,
        latency_p50_ms=float(got["latency_p50_ms"]), latency_p99_ms=float(got["latency_p99_ms"]),
        latency_max_ms=float(got["latency_max_ms"]),
    )  # fmt: skip
