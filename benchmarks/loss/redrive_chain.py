"""The redrive chains' processes: one shared-memory stream per sensor, collector → core."""

from __future__ import annotations

import contextlib
import threading
import time
from typing import Any

import numpy as np

from benchmarks.loss.process import _POLL_S, _collect, _CoreRecord, _RunSpec, _wait_go
from benchmarks.loss.streams import DRAIN_S, STREAMS, _stamp, _template


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
