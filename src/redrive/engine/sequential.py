"""The engine's sequential loop: each frame through every stage before the next frame starts.

:func:`run_sequential` is the one sequential loop (the pipelined mode runs its stages on threads
of their own, :mod:`redrive.engine.core`).  A stage of one in-process algorithm is stepped
inline (what :meth:`Algorithm.timed_step_from` does, one Python call less a step); a stage of
several algorithms or of worker processes runs through the stage's runners (``run_steps``).

It has two regimes.  *Frame by frame* (a paced or live or closed-loop mode, or a stage that is
not one in-process algorithm): each frame is read from the mode's hooks when the one before it
was handed on (and, after the sink, given to ``after_frame``), and the thread CPU clock is read
when its first step starts and after each step (the next step's CPU time runs on from there: the
hand-off of the upstream outputs between two steps of a frame is in it, ≈ 1 µs).  *Chained* (``chained=True``: a replay at full speed with one in-process algorithm per
stage, the common ``redrive run LOG``), with less bookkeeping per frame:

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

In both, a frame's ``wall_ns`` runs from its first step's start to its last step's end.
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
from redrive.engine.modes import PacedFrame
from redrive.engine.stats import StatsCollector
from redrive.engine.worker import frame_for
from redrive.errors import AlgorithmError
from redrive.results import FrameRecord, StepRecord
from redrive.results.records import frame_record_unchecked, step_record_unchecked
from redrive.types import ControlCommands, Frame, PlannedPath, Role

__all__ = ["CHAIN_NS", "READ_AHEAD", "RunSteps", "Single", "run_sequential", "single_step_record"]

#: frames read from the log before they run (at most)
READ_AHEAD = 16
#: a batch's reading, and a chain of steps, end once they have taken this long (wall, ns)
CHAIN_NS = 1_000_000

#: a stage of one in-process algorithm: (algorithm, its sensors, name, stage, role value)
Single = tuple[Any, frozenset[str], str, str, str]
#: any other stage's steps of a frame: ``run_steps(frame, upstream)`` gives its step records,
#: the first that failed (or None) and the upstream outputs after it
RunSteps = Callable[[Frame, StageOutputs], tuple[list[StepRecord], StepRecord | None, StageOutputs]]

_NO_UPSTREAM = StageOutputs()  # immutable: every frame starts from it
_OK, _ERROR = StepStatus.OK, StepStatus.ERROR
_STAGE = object()  # the status of a raw entry that holds a run_steps stage's records
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
    for kept, status, output, *_ in raw:
        if status is _STAGE:  # counted once handed on: nothing to take back
            continue
        single, _lat, _cpu, objects, counts = kept
        if status is _OK and output is not None:
            stats.take_back_ok(single[2])
            if objects:
                counts[1] -= len(output)
        else:
            counts[0] -= 1


def run_sequential(
    stages: list[tuple[Single | None, MappingProxyType[str, Role], bool, RunSteps]],
    frames: Iterator[Frame] | Iterator[PacedFrame],
    *,
    chained: bool,
    sink: Callable[[FrameRecord], None],
    stats: StatsCollector,
    progress: Callable[[int], None] | None,
    fail_fast: bool,
    after_frame: Callable[[FrameRecord], None] | None = None,
    cancel: threading.Event | None = None,
) -> tuple[int, StepRecord] | None:
    r"""Run ``frames`` through ``stages`` (``(single or None, roles after it, last,
    run_steps)`` each: a stage with a ``single`` is stepped inline, any other through its
    ``run_steps``); hand each finished frame's record to ``sink``, ``stats`` and
    ``after_frame`` in order.  Returns the first failed step with ``fail_fast`` (no frame after
    it is handed on), else None.

    ``chained`` (``frames`` are :class:`Frame`\ s, every stage has a ``single``): the chained
    regime of the module text; else ``frames`` are the mode's :class:`PacedFrame`\ s, read one
    at a time, each handed on before the next is read.

    On KeyboardInterrupt the frames whose steps all ran are handed on before it propagates.
    With ``cancel``, each frame is handed on before the next one runs, and no frame runs once
    it is set (the frames read ahead and not run are dropped): a Cancel pressed at frame n's
    progress leaves frames 0 … n − 1, as the frame-by-frame regime does.
    """
    done = 0
    of_proxies = StageOutputs.of_proxies
    # per inline stage, for the records and the statistics: (single, the stats' latency and
    # CPU appends, a perception stage (outputs counted as objects), [steps not ok, objects] of
    # the chain being handed on)
    tally = [
        (single, *stats.ok_lists(single[2]), single[4] == "perception", [0, 0])
        for single, _roles, _last, _run in stages
        if single is not None
    ]
    # per stage: (its algorithm's step, its sensors, roles after it, last, algorithm name,
    # the output type accepted without check_output, role, its tally); for a run_steps stage
    # (None, run_steps, roles after it, last, …)
    steps: list[tuple[Any, ...]] = []
    inline = iter(tally)
    for single, roles, last, run in stages:
        if single is None:
            steps.append((None, run, roles, last, None, None, None, None))
            continue
        algo = single[0]
        steps.append(
            (
                algo.step,
                single[1],
                roles,
                last,
                algo.name,
                _FAST_TYPES[algo.role],
                algo.role,
                next(inline),
            )
        )
    read_ahead = READ_AHEAD if chained else 1
    # the frames a chain ran: (frame, wall ns, raw steps, late), raw = (tally, status, output,
    # latency, cpu, error) per inline stage, (records, _STAGE, the first failed, …) per other
    ran: list[tuple[Frame, int, list[tuple[Any, ...]], bool]] = []
    first: list[int | None] = [None]  # the first stamp handed on

    def hand_on() -> tuple[int, StepRecord] | None:
        nonlocal done
        handed = failed_frames = 0
        last: Frame | None = None
        try:
            for frame, wall_ns, raw, late in ran:
                failed: tuple[int, StepRecord] | None = None
                records = []
                counted: list[StepRecord] | None = None  # run_steps stages' ok steps
                for kept, status, output, latency_ns, cpu_ns, error in raw:
                    if status is _OK and output is not None:  # the common step, built inline
                        single, lat, cpu, objects, counts = kept
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
                    if status is _STAGE:
                        records.extend(kept)
                        counted = [*(counted or ()), *(r for r in kept if r.status == "ok")]
                        if failed is None and output is not None:
                            failed = (frame.index, output)
                        continue
                    single, _lat, _cpu, _objects, counts = kept
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
                    late,
                    frame.missing,
                    frame.traffic.traffic_lights,
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
                if counted is not None:  # counted once handed on
                    for step in counted:
                        stats.add_step(record.frame_index, step)
                if failed is not None and _not_ok(stats, record):
                    failed_frames += 1
                if frame.missing:
                    stats.add_missing(frame.missing)
                if after_frame is not None:
                    after_frame(record)
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

    batch: list[Any] = []
    while True:
        # read ahead: up to READ_AHEAD frames, fewer when reading them is slow (chained); one
        batch.clear()
        start = perf_counter_ns()
        for frame in frames:
            batch.append(frame)
            if len(batch) >= read_ahead or perf_counter_ns() - start >= CHAIN_NS:
                break
        if not batch:
            return None
        unrun = iter(batch)  # the batch's frames no chain has run yet
        more = True
        while more:  # chains of at most CHAIN_NS over the batch (one frame unless chained)
            more = stop = False
            try:
                cpu = _thread_time_ns() if chained else 0
                start = perf_counter_ns()
                for item in unrun:
                    if cancel is not None and cancel.is_set():
                        return hand_on()
                    if chained:
                        frame, late = item, False
                    else:
                        frame, late = item.frame, bool(item.late)
                    t0_ns = 0  # the first step's start: a frame's wall time runs from it
                    raw: list[tuple[Any, ...]] = []
                    upstream = _NO_UPSTREAM
                    outputs: dict[str, Any] = {}  # the dict behind upstream's outputs view
                    for step, sensors, roles_after, last, name, fast, role, kept in steps:
                        if step is None:  # several algorithms or worker processes
                            t0 = perf_counter_ns()
                            if not t0_ns:
                                t0_ns = t0
                            records, failure, upstream = sensors(frame, upstream)
                            t1 = perf_counter_ns()
                            cpu = _thread_time_ns()  # the next inline step's CPU from here
                            raw.append((records, _STAGE, failure, 0, 0, None))
                            outputs = dict(upstream.outputs)
                            if failure is not None:
                                stop = stop or fail_fast
                            continue
                        seen = frame
                        if frame.sensors and not frame.sensors.keys() <= sensors:
                            seen = frame_for(frame, sensors)
                        # Algorithm.timed_step_from, inline (one Python call less a step); a
                        # frame's first step reads the thread's CPU clock (a system call), the
                        # next ones run on from the step before's end, as in a chain
                        if not chained and not t0_ns:
                            cpu = _thread_time_ns()
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
                    ran.append((frame, t1_ns - t0_ns, raw, late))
                    if stop:
                        break
                    if not chained or t1_ns - start >= CHAIN_NS or cancel is not None:
                        more = True
                        break
            except KeyboardInterrupt:
                hand_on()  # the frames that ran, as a frame-by-frame loop would have
                raise
            failed = hand_on()
            if failed is not None:
                return failed
