"""What every spawned process of a configuration shares: the run spec, the go signal, the
collector's paced loop and the core's record of receipts."""

from __future__ import annotations

import multiprocessing
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.loss.streams import (
    _NS,
    _SKIPPED,
    DRAIN_S,
    I64,
    SENSOR_BUFFER_S,
    SLOTS,
    STREAMS,
    U8,
    _touch,
    due_times,
)
from redrive.errors import TransportError

_START_TIMEOUT_S = 60.0
_POLL_S = 0.05


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
