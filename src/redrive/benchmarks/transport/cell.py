"""One run of one side at one size: the publisher and subscriber processes (``spawn``) and
:func:`run_cell`, which starts them, hands out the go and collects what each measured."""

from __future__ import annotations

import contextlib
import logging
import math
import multiprocessing
import os
import time
import uuid
from typing import Any

from redrive.benchmarks.transport.payload import END_SEQ, MIN_SIZE, SLOTS, CellConfig, _Tally
from redrive.benchmarks.transport.results import RunResult
from redrive.benchmarks.transport.sides import (
    _CONNECT_TIMEOUT_S,
    CATALOGUE,
    SideSpec,
    catalogue_sides,
)
from redrive.errors import TransportError

__all__ = ["run_cell"]

logger = logging.getLogger(__name__)

_IDLE_POLL_S = 0.05
_IDLE_POLLS_AFTER_DONE = 4  # 0.2 s without a message once the publisher has finished
_SPAWN_TIMEOUT_S = 60.0


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
    catalogue: str = CATALOGUE,
) -> RunResult:
    """One run of ``side`` (of the module ``catalogue``'s ``SIDES``) at ``size_bytes`` (flat out,
    or paced at ``paced_hz``) in two fresh processes; raises :class:`TransportError` when the
    side fails."""
    spec = catalogue_sides(catalogue)[side]
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
        catalogue=catalogue,
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
        close_shared = getattr(shared, "close", None)  # a queue; a pipe pair has none
        if callable(close_shared):
            close_shared()
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
