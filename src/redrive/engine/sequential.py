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

from redrive.algorithms import (
    AlgorithmOutput,
    StageOutputs,
    StepError,
    StepStatus,
    check_output,
)
from redrive.engine.stats import StatsCollector
from redrive.engine.worker import frame_for
from redrive.errors import AlgorithmError
from redrive.results import FrameRecord, StepRecord
from redrive.results.records import frame_record_unchecked, step_record_unchecked
from redrive.types import ControlCommands, Frame, PlannedPath, Role

__all__ = ["CHAIN_NS", "READ_AHEAD", "Single", "run_short", "single_step_record"]

#: frames read from the log before they run (at most)
READ_AHEAD = 16
#: a batch's reading, and a chain of steps, end once they have taken this long (wall, ns)
CHAIN_NS = 1_000_000

#: a stage of one in-process algorithm: (algorithm, its sensors, name, stage, role value)
Single = tuple[Any, frozenset[str], str, str, str]

_NO_UPSTREAM = StageOutputs()  # immutable: every frame starts from it
_OK, _ERROR = StepStatus.OK, StepStatus.ERROR
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


def _not_ok(stats: StatsCollector, record: FrameRecord) -> bool:
    """Count the steps of ``record`` that were not ok; True when one failed (error, timeout)."""
    failed = False
    for step in record.steps:
        if step.status != "ok" and stats.add_step(record.frame_index, step):
            failed = True
    return failed


#: the output each role's step may return unchecked (a perception tuple only when empty)
_FAST_TYPES = {Role.PERCEPTION: tuple, Role.PLANNING: PlannedPath, Role.CONTROL: ControlCommands}


def _checked(
    value: object, role: Role, name: str, frame: Frame
) -> tuple[StepStatus, AlgorithmOutput | None, StepError | None]:
    """A step's return value other than the common ones (:data:`_FAST_TYPES`) as ``(status,
    output, error)``, checked as :meth:`Algorithm.timed_step_from` checks it."""
    try:
        output = check_output(role, value, where=name)
    except AlgorithmError as err:
        error = StepError(type=type(err).__name__, message=f"frame {frame.index}: {err}")
        return _ERROR, None, error
    return _OK, output, None


def _uncount(stats: StatsCollector, raw: list[tuple[Any, ...]]) -> None:
    """Take back what a frame's steps ``raw`` added to the chain's counts and the statistics'
    lists (the frame was not handed on after all)."""
    for (single, _lat, _cpu, objects, counts), status, output, *_ in raw:
        if status is _OK and output is not None:
            stats.take_back_ok(single[2])
            if objects:
                counts[1] -= len(output)
        else:
            counts[0] -= 1


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
    done = 0
    of_proxies = StageOutputs.of_proxies
    # per stage, for the records and the statistics: (single, the stats' latency and CPU
    # appends, a perception stage (outputs counted as objects), [steps not ok, objects] of the
    # chain being handed on)
    tally = [
        (single, *stats.ok_lists(single[2]), single[4] == "perception", [0, 0])
        for single, _roles, _last in stages
    ]
    # per stage: (its algorithm's step, its sensors, roles after it, last, algorithm name,
    # the output type accepted without check_output, role, its tally)
    steps = [
        (
            single[0].step,
            single[1],
            roles,
            last,
            single[0].name,
            _FAST_TYPES[single[0].role],
            single[0].role,
            tally[k],
        )
        for k, (single, roles, last) in enumerate(stages)
    ]
    # the frames a chain ran: (frame, wall ns, raw steps), raw = (tally, status, output,
    # latency, cpu, error) per stage
    ran: list[tuple[Frame, int, list[tuple[Any, ...]]]] = []
    first: list[int | None] = [None]  # the first stamp handed on

    def hand_on() -> tuple[int, StepRecord] | None:
        nonlocal done
        handed = failed_frames = 0
        last: Frame | None = None
        try:
            for frame, wall_ns, raw in ran:
                failed: tuple[int, StepRecord] | None = None
                records = []
                for (
                    single,
                    lat,
                    cpu,
                    objects,
                    counts,
                ), status, output, latency_ns, cpu_ns, error in raw:
                    if status is _OK and output is not None:  # the common step, built inline
                        records.append(
                            step_record_unchecked(
                                single[2], single[3], single[4], "ok", latency_ns, cpu_ns, output
                            )
                        )
                        lat(latency_ns)
                        cpu(cpu_ns)
                        if objects:
                            counts[1] += len(output)
                        continue
                    step = single_step_record(single, status, output, latency_ns, cpu_ns, error)
                    records.append(step)
                    counts[0] += 1
                    if failed is None:
                        failed = (frame.index, step)
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
                try:
                    sink(record)
                except BaseException:  # not handed on: take back what was counted of it
                    _uncount(stats, raw)
                    raise
                if first[0] is None:
                    first[0] = frame.stamp_ns
                last = frame
                handed += 1
                if failed is not None and _not_ok(stats, record):
                    failed_frames += 1
                if frame.missing:
                    stats.add_missing(frame.missing)
                done += 1
                if progress is not None:
                    progress(done)
                if fail_fast and failed is not None:
                    return failed
            return None
        finally:  # what was handed on is counted, also when the sink or progress raised
            if last is not None:
                stats.add_counted(
                    first_stamp_ns=first[0],  # type: ignore[arg-type]
                    last_stamp_ns=last.stamp_ns,
                    frames=handed,
                    failed_frames=failed_frames,
                    ok=[
                        (
                            single[2],
                            handed - counts[0],
                            counts[1] if objects else handed - counts[0],
                        )
                        for single, _lat, _cpu, objects, counts in tally
                    ],
                )
            for *_, counts in tally:
                counts[0] = counts[1] = 0
            ran.clear()

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
                    t0_ns = 0  # the first step's start: a frame's wall time runs from it
                    raw: list[tuple[Any, ...]] = []
                    upstream = _NO_UPSTREAM
                    outputs: dict[str, Any] = {}  # the dict behind upstream's outputs view
                    for step, sensors, roles_after, last, name, fast, role, kept in steps:
                        seen = frame
                        if frame.sensors and not frame.sensors.keys() <= sensors:
                            seen = frame_for(frame, sensors)
                        # Algorithm.timed_step_from, inline (one Python call less a step)
                        t0 = perf_counter_ns()
                        if not t0_ns:
                            t0_ns = t0
                        try:
                            value = step(seen, upstream)
                        except Exception as err:  # recorded, never swallowed
                            t1 = perf_counter_ns()
                            cpu1 = _thread_time_ns()
                            status, output = _ERROR, None
                            error: StepError | None = StepError.from_exception(err)
                        else:
                            t1 = perf_counter_ns()
                            cpu1 = _thread_time_ns()
                            if type(value) is fast and (fast is not tuple or not value):
                                status, output, error = _OK, value, None
                            else:
                                status, output, error = _checked(value, role, name, seen)
                        raw.append((kept, status, output, t1 - t0, cpu1 - cpu, error))
                        cpu = cpu1
                        if status is _OK and output is not None:
                            if not last:  # nobody reads the upstream after the last stage
                                # a new dict each stage: the views handed on never change
                                outputs = {**outputs, name: output}
                                upstream = of_proxies(MappingProxyType(outputs), roles_after)
                            continue
                        stop = stop or fail_fast
                        if not last:
                            upstream = of_proxies(
                                upstream.outputs,  # type: ignore[arg-type]
                                roles_after,
                            )
                    t1_ns = t1  # the last step's end
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
