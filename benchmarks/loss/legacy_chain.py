"""The legacy chain's processes: collector → ``Pipe`` (pickle) → bridge → ``Queue`` → core."""

from __future__ import annotations

import contextlib
import queue
import time
from typing import Any

import numpy as np

from benchmarks.loss.process import _POLL_S, _collect, _CoreRecord, _RunSpec, _wait_go
from benchmarks.loss.streams import DRAIN_S, STREAMS, _stamp, _template


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
