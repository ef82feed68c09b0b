"""The engine's short path: single-algorithm in-process stages replayed as fast as possible.

The same records as the general sequential loop, with less bookkeeping per frame:

- the thread CPU clock (a system call: ≈ 1 µs, unlike the wall clock) is read once after each
  step, and each reading is the start of the next step's CPU time — also across frames, so a
  frame costs one reading per stage instead of one more per frame to start it;
- to keep the work between two frames out of every step's CPU time, the frames are read from
  the log a few at a time before any of them runs (:data:`READ_AHEAD` frames, fewer when
  reading them takes :data:`CHAIN_NS`), and the records of the frames a chain ran are built,
  handed to the sink and counted after its last step (a chain ends after :data:`CHAIN_NS` of
  running, so a slow pipeline's frames reach the sink one by one, as before).

What lies between two readings is the step and the engine's hand-off into it (the upstream
outputs, the next frame of the batch: ≈ 1 µs), as ``docs/results.md`` says of ``cpu_ns``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from time import perf_counter_ns
from types import MappingProxyType
from typing import Any

from redrive.algorithms import AlgorithmOutput, StageOutputs, StepError, StepStatus
from redrive.engine.stats import StatsCollector
from redrive.engine.worker import frame_for
from redrive.results import FrameRecord, StepRecord
from redrive.results.records import frame_record_unchecked, step_record_unchecked
from redrive.types import Frame, Role

__all__ = ["CHAIN_NS", "READ_AHEAD", "Single", "run_short", "single_step_record"]

#: frames read from the log before they run (at most)
READ_AHEAD = 16
#: a batch's reading, and a chain of steps, end once they have taken this long (wall, ns)
CHAIN_NS = 1_000_000

#: a stage of one in-process algorithm: (algorithm, its sensors, name, stage, role value)
Single = tuple[Any, frozenset[str], str, str, str]

_NO_UPSTREAM = StageOutputs()  # immutable: every frame starts from it
_OK = StepStatus.OK
_thread_time_ns = time.thread_time_ns


def single_step_record(  # noqa: PLR0917 (per step: positional is cheaper)
    single: Single,
    status: StepStatus,
    output: AlgorithmOutput | None,
    latency_ns: int,
    cpu_ns: int,
    error: StepError | None,
) -> StepRecord:
    """The record of a step of a single-algorithm stage."""
    if error is None:
        return step_record_unchecked(
            single[2],
            single[3],
            single[4],
            "ok" if status is _OK else status.value,
            latency_ns,
            cpu_ns,
            output,
        )
    return step_record_unchecked(
        single[2],
        single[3],
        single[4],
        status.value,
        latency_ns,
        cpu_ns,
        output,
        error.type,
        error.message,
        error.traceback,
    )


def run_short(
    stages: list[tuple[Single, MappingProxyType[str, Role], bool]],
    frames: Iterator[Frame],
    *,
    sink: Callable[[FrameRecord], None],
    stats: StatsCollector,
    progress: Callable[[int], None] | None,
    fail_fast: bool,
    cancel: threading.Event | None = None,
) -> tuple[int, StepRecord] | None:
    """Run ``frames`` through ``stages`` (``(single, roles after it, last)`` each); hand each
    finished frame's record to ``sink`` and ``stats`` in order.  Returns the first failed
    step with ``fail_fast`` (no frame after it is handed on), else None.

    On KeyboardInterrupt the frames whose steps all ran are handed on before it propagates.
    With ``cancel``, each frame is handed on before the next one runs, and no frame runs once
    it is set (the frames read ahead and not run are dropped): a Cancel pressed at frame n's
    progress leaves frames 0 … n − 1, as the frame-by-frame loop does.
    """
    add = stats.add
    done = 0
    # per stage: (algorithm, its sensors, single, roles after it, last, algorithm name)
    steps = [
        (single[0], single[1], single, roles, last, single[0].name)
        for single, roles, last in stages
    ]
    # the frames a chain ran: (frame, wall ns, raw steps), raw = (single, status, output,
    # latency, cpu, error) per step
    ran: list[tuple[Frame, int, list[tuple[Any, ...]]]] = []

    def hand_on() -> tuple[int, StepRecord] | None:
        nonlocal done
        for frame, wall_ns, raw in ran:
            failed: tuple[int, StepRecord] | None = None
            records = []
            for single, status, output, latency_ns, cpu_ns, error in raw:
                if status is _OK and output is not None:  # the common step, built inline
                    step = step_record_unchecked(
                        single[2], single[3], single[4], "ok", latency_ns, cpu_ns, output
                    )
                else:
                    step = single_step_record(single, status, output, latency_ns, cpu_ns, error)
                    if failed is None:
                        failed = (frame.index, step)
                records.append(step)
            record = frame_record_unchecked(  # Frame and the graph keep its invariants
                int(frame.index),
                frame.stamp_ns,
                tuple(records),
                frame.vehicle_state,
                frame.ground_truth,
                wall_ns,
                False,
                frame.missing,
            )
            sink(record)
            add(record)
            done += 1
            if progress is not None:
                progress(done)
            if fail_fast and failed is not None:
                return failed
        ran.clear()
        return None

    batch: list[Frame] = []
    while True:
        # read ahead: up to READ_AHEAD frames, fewer when reading them is slow
        batch.clear()
        start = perf_counter_ns()
        for frame in frames:
            batch.append(frame)
            if len(batch) >= READ_AHEAD or perf_counter_ns() - start >= CHAIN_NS:
                break
        if not batch:
            return None
        unrun = iter(batch)  # the batch's frames no chain has run yet
        more = True
        while more:  # chains of at most CHAIN_NS over the batch
            more = stop = False
            try:
                cpu = _thread_time_ns()
                start = perf_counter_ns()
                for frame in unrun:
                    if cancel is not None and cancel.is_set():
                        return hand_on()
                    t0_ns = perf_counter_ns()
                    raw: list[tuple[Any, ...]] = []
                    upstream = _NO_UPSTREAM
                    for algo, sensors, single, roles_after, last, name in steps:
                        seen = frame
                        if frame.sensors and not frame.sensors.keys() <= sensors:
                            seen = frame_for(frame, sensors)
                        status, output, latency_ns, cpu1, error = algo.timed_step_from(
                            seen, upstream, cpu
                        )
                        raw.append((single, status, output, latency_ns, cpu1 - cpu, error))
                        cpu = cpu1
                        if status is _OK and output is not None:
                            if not last:  # nobody reads the upstream after the last stage
                                upstream = StageOutputs.of_proxies(
                                    MappingProxyType({**upstream.outputs, name: output}),
                                    roles_after,
                                )
                            continue
                        stop = stop or fail_fast
                        if not last:
                            upstream = StageOutputs.of_proxies(
                                upstream.outputs,  # type: ignore[arg-type]
                                roles_after,
                            )
                    t1_ns = perf_counter_ns()
                    ran.append((frame, t1_ns - t0_ns, raw))
                    if stop:
                        break
                    if t1_ns - start >= CHAIN_NS or cancel is not None:
                        more = True
                        break
            except KeyboardInterrupt:
                hand_on()  # the frames that ran, as a frame-by-frame loop would have
                raise
            failed = hand_on()
            if failed is not None:
                return failed
