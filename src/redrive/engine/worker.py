"""Running one algorithm: in this process, or in a worker process that can be timed out.

A worker process loads the plugin itself from its spec (``module:Class`` / ``file.py:Class`` /
entry-point name), configures and binds it exactly as the engine does, then answers one request
per frame.  When a step runs past the timeout the worker is killed, the step recorded as
``timeout``, and a fresh worker (``setup`` again, state lost) takes the next frame; a worker that
dies (segfault, ``os._exit``) is recorded as an error on that frame and restarted the same way.
With a memory bound (``max_rss_mb``) a worker whose resident set goes past it while a step runs,
or whose peak after the step is past it, is killed the same way and the step recorded as an error
of type ``MemoryLimit`` (:mod:`redrive.engine.memory`).

Frames travel to workers pickled over a pipe, with the sensors the algorithm does not declare
left out.  That is fine for control and planning inputs and for tests; the shared-memory
transport (``redrive.transport``) is what moves LiDAR and camera data at full rate.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing as mp
import signal
import time
from collections.abc import Mapping
from dataclasses import replace
from multiprocessing.connection import Connection
from typing import Any, Protocol

from redrive.algorithms import Algorithm, StageOutputs, StepError, StepResult, StepStatus
from redrive.engine.memory import RssWatch, mib, peak_rss_bytes
from redrive.types import Frame

__all__ = ["AlgorithmRunner", "InlineRunner", "ProcessRunner", "frame_for"]

logger = logging.getLogger(__name__)

_START_TIMEOUT_S = 120.0


class AlgorithmRunner(Protocol):
    name: str

    def submit(self, frame: Frame, upstream: StageOutputs) -> None: ...

    def result(self) -> StepResult: ...

    def reset(self) -> None: ...

    def close(self) -> None: ...

    @property
    def pid(self) -> int | None: ...


def frame_for(frame: Frame, sensor_ids: frozenset[str]) -> Frame:
    """``frame`` with only the sensors in ``sensor_ids`` (the same object when nothing to drop)."""
    if frame.sensors.keys() <= sensor_ids:
        return frame
    return replace(frame, sensors={k: v for k, v in frame.sensors.items() if k in sensor_ids})


def _plain(value: Any) -> Any:
    """``value`` with read-only mappings as dicts (``MappingProxyType`` does not pickle)."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return type(value)(_plain(v) for v in value)
    return value


class InlineRunner:
    """Runs the algorithm in the calling thread; ``submit`` does the work, ``result`` returns it."""

    def __init__(self, algorithm: Algorithm) -> None:
        self.algorithm = algorithm
        self.name = algorithm.name
        self._sensors = frozenset(algorithm.bound_inputs.values())
        self._result: StepResult | None = None

    @property
    def pid(self) -> int | None:
        return None

    def submit(self, frame: Frame, upstream: StageOutputs) -> None:
        self._result = self.algorithm.run_step(frame_for(frame, self._sensors), upstream)

    def result(self) -> StepResult:
        assert self._result is not None, "result() before submit()"
        out, self._result = self._result, None
        return out

    def reset(self) -> None:
        self.algorithm.reset()

    def close(self) -> None:
        self._result = None


def _worker_main(conn: Connection, init: Mapping[str, Any]) -> None:
    """Entry point of a worker process."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the engine decides when to stop
    from redrive.algorithms.discovery import load_algorithm_class
    from redrive.engine.graph import LogInputs, instantiate

    try:
        cls = load_algorithm_class(init["plugin"])
        inputs = LogInputs(**init["inputs"])
        algo = instantiate(cls, name=init["name"], config=init["config"], inputs=inputs)
    except Exception as err:
        conn.send(("error", StepError.from_exception(err)))
        return
    conn.send(("ready", sorted(set(algo.bound_inputs.values())), peak_rss_bytes()))
    while True:
        try:
            request = conn.recv()
        except EOFError:
            return
        if request is None:
            return
        if request == "reset":
            algo.reset()
            continue
        frame, upstream = request
        result = algo.run_step(frame, upstream)
        conn.send((result, peak_rss_bytes()))


class ProcessRunner:
    """Runs the algorithm in a worker process (spawned, so any plugin file can be loaded).

    Args:
        plugin, name, config: what the engine built the algorithm from.
        inputs: the log's inputs (a ``LogInputs`` as a plain dict of its fields).
        timeout_s: per-step limit; None waits for ever (a dead worker is still detected).
        max_rss_mb: the bound of the worker's resident set (MiB); None for none.
    """

    def __init__(
        self,
        *,
        plugin: str,
        name: str,
        config: Mapping[str, Any],
        inputs: Mapping[str, Any],
        timeout_s: float | None,
        max_rss_mb: float | None = None,
    ) -> None:
        self.name = name
        self._init = {"plugin": plugin, "name": name, "config": _plain(config), "inputs": inputs}
        self._timeout_s = timeout_s
        self._max_rss_mb = max_rss_mb
        self._limit = None if max_rss_mb is None else int(max_rss_mb * (1 << 20))
        self._watch = None if self._limit is None else RssWatch(self._limit)
        self._ctx = mp.get_context("spawn")
        self._proc: Any = None
        self._conn: Connection | None = None
        self._sensors: frozenset[str] = frozenset()
        self._pending: tuple[int, int] | None = None
        self._frame_index = -1
        self._start_error: StepError | None = None
        self._start()

    @property
    def pid(self) -> int | None:
        return None if self._proc is None else int(self._proc.pid)

    def _start(self) -> None:
        parent, child = self._ctx.Pipe()
        self._proc = self._ctx.Process(
            target=_worker_main, args=(child, self._init), name=f"redrive:{self.name}", daemon=True
        )
        self._proc.start()
        child.close()
        self._conn = parent
        self._start_error = None
        if not parent.poll(_START_TIMEOUT_S):
            self._kill()
            self._start_error = StepError(
                type="WorkerStartTimeout",
                message=f"worker for {self.name!r} did not start within {_START_TIMEOUT_S:g} s",
            )
            return
        try:
            kind, *payload = parent.recv()
        except EOFError:
            kind, payload = "error", [self._died("while starting")]
        if kind == "error":
            self._kill()
            self._start_error = payload[0]
            return
        self._sensors = frozenset(payload[0])
        peak = payload[1]
        if self._limit is not None and peak > self._limit:
            self._kill()
            self._start_error = StepError(
                type="MemoryLimit",
                message=(
                    f"the worker of {self.name!r} used {mib(peak)} resident to start (import and "
                    f"setup), over its bound of {self._max_rss_mb:g} MiB (--max-rss / "
                    "max_rss_mb); raise the bound (the interpreter and its libraries count too)"
                ),
            )

    def _died(self, when: str) -> StepError:
        code = None if self._proc is None else self._proc.exitcode
        if code is None and self._proc is not None:
            self._proc.join(1.0)
            code = self._proc.exitcode
        return StepError(
            type="WorkerDied",
            message=f"the worker process of {self.name!r} died {when} (exit code {code})",
        )

    def _kill(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._proc is not None:
            if self._proc.pid is not None:  # started
                if self._proc.is_alive():
                    self._proc.kill()
                self._proc.join(5.0)
            self._proc = None

    def submit(self, frame: Frame, upstream: StageOutputs) -> None:
        if self._conn is None and self._start_error is None:
            self._start()
        t0 = time.perf_counter_ns()
        if self._conn is None:
            self._pending = (t0, -1)
            return
        try:
            self._conn.send((frame_for(frame, self._sensors), upstream))
        except (BrokenPipeError, OSError):
            self._pending = (t0, -2)
            return
        self._pending = (t0, frame.index)
        if self._watch is not None and self._proc is not None:
            self._watch.arm(int(self._proc.pid))

    def result(self) -> StepResult:
        result = self._result()
        if self._watch is None:
            return result
        killed = self._watch.disarm()
        if killed is None:
            return result
        self._kill()  # killed by the watch: a fresh worker takes the next frame
        return self._over_memory(killed, result.latency_ns, when="while its step ran")

    def _over_memory(self, rss: int, latency_ns: int, *, when: str) -> StepResult:
        frame = self._frame_index
        logger.debug(
            "%s went past its memory bound on frame %d; worker restarted", self.name, frame
        )
        return StepResult(
            status=StepStatus.ERROR,
            latency_ns=latency_ns,
            error=StepError(
                type="MemoryLimit",
                message=(
                    f"{self.name} used {mib(rss)} resident on frame {frame} ({when}), over its "
                    f"bound of {self._max_rss_mb:g} MiB (--max-rss / max_rss_mb); the worker "
                    "was killed and restarted (state lost)"
                ),
            ),
        )

    def _result(self) -> StepResult:
        assert self._pending is not None, "result() before submit()"
        t0, state = self._pending
        self._pending = None
        self._frame_index = state
        if state == -1:
            error = self._start_error
            self._start_error = None  # try a fresh worker on the next frame
            return StepResult(status=StepStatus.ERROR, error=error)
        if state == -2 or self._conn is None:
            error = self._died("before the frame was sent")
            self._kill()
            return StepResult(status=StepStatus.ERROR, error=error)
        wait = None if self._timeout_s is None else self._timeout_s
        ready = self._conn.poll(wait)
        if not ready:
            latency = time.perf_counter_ns() - t0
            self._kill()
            logger.debug("%s timed out on frame %d; worker restarted", self.name, state)
            return StepResult(
                status=StepStatus.TIMEOUT,
                latency_ns=latency,
                error=StepError(
                    type="StepTimeout",
                    message=(
                        f"{self.name} took longer than the step timeout of {self._timeout_s:g} s "
                        f"on frame {state}; the worker was killed and restarted (state lost)"
                    ),
                ),
            )
        try:
            result, peak = self._conn.recv()
        except (EOFError, OSError):
            latency = time.perf_counter_ns() - t0
            if self._watch is not None and self._watch.killed_rss is not None:
                return StepResult(status=StepStatus.ERROR, latency_ns=latency)  # result() says
            error = self._died(f"on frame {state}")
            self._kill()
            return StepResult(status=StepStatus.ERROR, latency_ns=latency, error=error)
        if self._limit is not None and peak > self._limit:
            if self._watch is not None:
                self._watch.disarm()
            self._kill()
            return self._over_memory(peak, result.latency_ns, when="its peak during the step")
        assert isinstance(result, StepResult)
        return result

    def reset(self) -> None:
        if self._conn is not None:
            self._conn.send("reset")

    def close(self) -> None:
        if self._conn is not None:
            with contextlib.suppress(OSError):
                self._conn.send(None)
        if self._proc is not None:
            self._proc.join(2.0)
        self._kill()
        if self._watch is not None:
            self._watch.close()

    def __del__(self) -> None:  # a forgotten runner must not leave a process behind
        if getattr(self, "_proc", None) is not None:
            self._kill()
