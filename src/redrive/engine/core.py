"""The Orchestration Engine: frames through the stage graph, sequentially or pipelined.

- *sequential*: each frame goes through every stage before the next frame starts — one loop,
  :func:`redrive.engine.sequential.run_sequential` (chained at full speed, see there).
- *pipelined*: one thread per stage and one reading the log, joined by short bounded hand-offs
  (:class:`~redrive.engine.handoff.Handoff`), so stage k works on frame t while stage k-1 works
  on frame t+1.  Each stage still sees frames in
  order and the same upstream outputs, so the outputs are identical to a sequential run; the
  stages overlap where their work releases the GIL (numpy, scipy, I/O) or runs in worker
  processes (``executor="processes"``).

Algorithms of one stage run side by side: in worker processes all are sent the frame before any
answer is awaited; in-process, a stage with several algorithms runs them on a thread pool.

Every step is recorded (output, latency, CPU time, error); an algorithm's exception never stops a
run unless ``fail_fast`` is set.  Ctrl-C stops reading, lets nothing half-done be written, and
closes the run directory as ``interrupted``: ``redrive run … --resume`` continues it.  Setting the
``cancel`` event given to :meth:`Engine.run` (the GUI's Cancel button) does the same from another
thread: no frame is read or started after it is set, the frames in flight are finished and
written.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from time import perf_counter_ns
from types import MappingProxyType
from typing import Any

from redrive.algorithms import (
    Algorithm,
    StageOutputs,
    StepResult,
    StepStatus,
)
from redrive.config import PipelineConfig
from redrive.engine._heap import setup_frozen
from redrive.engine.graph import LogInputs, PlannedAlgorithm, StageGraph
from redrive.engine.handoff import Handoff, HandoffClosedError
from redrive.engine.modes import ModeHooks, PacedFrame, ReplayMode
from redrive.engine.sequential import Single, run_sequential, single_step_record
from redrive.engine.stats import RunReport, StatsCollector
from redrive.engine.worker import AlgorithmRunner, InlineRunner, ProcessRunner, frame_for
from redrive.results import FrameRecord, RunStatus, StepRecord
from redrive.results.records import frame_record_unchecked
from redrive.types import Frame, Role

__all__ = ["Engine", "FrameSink"]

logger = logging.getLogger(__name__)

#: frames each hand-off of the pipelined mode holds: 4 (was 2) — its threads wait and wake less
#: often and the run spends ≈ 8–9 % less CPU a frame (BENCHMARKS.md, h-engine6), for at most 16
#: frames in flight in a three-stage pipeline instead of 8
_QUEUE_DEPTH = 4

FrameSink = Callable[[FrameRecord], None]


_NO_UPSTREAM = StageOutputs()  # immutable: every frame starts from it


class _Item:
    """A frame on its way through the stages."""

    __slots__ = ("failed", "frame", "late", "steps", "t0_ns", "upstream")

    def __init__(self, frame: Frame, late: bool, t0_ns: int) -> None:
        self.frame = frame
        self.late = late
        self.upstream = _NO_UPSTREAM
        self.steps: list[StepRecord] = []
        self.failed: tuple[int, StepRecord] | None = None
        self.t0_ns = t0_ns


class _Stage:
    """One stage's runners and how they are driven."""

    def __init__(
        self,
        name: str,
        planned: tuple[PlannedAlgorithm, ...],
        runners: list[Any],
        *,
        roles_before: Mapping[str, Role],
    ):
        self.name = name
        self.planned = planned
        self.runners: list[AlgorithmRunner] = runners
        self.roles = {p.name: p.role for p in planned}
        # the roles every frame's upstream holds after this stage (they do not depend on the
        # frame: a failed step's role is listed too), built once instead of once per frame
        self.roles_after = MappingProxyType({**roles_before, **self.roles})
        self._role_values = [p.role.value for p in planned]
        self.last = False
        self._inline = all(isinstance(r, InlineRunner) for r in runners)
        self._single: Single | None = None
        # the pipelined stage calls Algorithm.timed_step, the sequential loop does what
        # timed_step_from does, inline; an algorithm that overrides run_step or those keeps
        # being run through run_step (run_steps below)
        kind = type(planned[0].instance)
        if (
            self._inline
            and len(runners) == 1
            and kind.run_step is Algorithm.run_step
            and kind.timed_step is Algorithm.timed_step
            and kind.timed_step_from is Algorithm.timed_step_from
        ):
            algo = planned[0].instance
            self._single = (
                algo,
                frozenset(algo.bound_inputs.values()),
                planned[0].spec.name,
                planned[0].stage,
                self._role_values[0],
            )
        self._pool = (
            ThreadPoolExecutor(len(runners), thread_name_prefix=f"redrive-{name}")
            if self._inline and len(runners) > 1
            else None
        )

    def run(self, item: _Item) -> None:
        frame = item.frame
        if self._single is not None:  # the common case, kept short: one algorithm in-process
            algo, sensors = self._single[0], self._single[1]
            if frame.sensors and not frame.sensors.keys() <= sensors:
                frame = frame_for(frame, sensors)
            status, output, latency_ns, cpu_ns, error = algo.timed_step(frame, item.upstream)
            record = single_step_record(self._single, status, output, latency_ns, cpu_ns, error)
            item.steps.append(record)
            ok = status is _OK and output is not None
            if not ok and item.failed is None:
                item.failed = (frame.index, record)
            if not self.last:  # nobody reads the upstream after the last stage
                upstream = item.upstream
                outputs = (
                    MappingProxyType({**upstream.outputs, algo.name: output})
                    if ok
                    else upstream.outputs
                )
                item.upstream = StageOutputs.of_proxies(
                    outputs,  # type: ignore[arg-type]
                    self.roles_after,
                )
            return
        records, failed, item.upstream = self.run_steps(frame, item.upstream)
        item.steps.extend(records)
        if failed is not None and item.failed is None:
            item.failed = (frame.index, failed)

    def run_steps(
        self, frame: Frame, upstream: StageOutputs
    ) -> tuple[list[StepRecord], StepRecord | None, StageOutputs]:
        """The stage's steps of ``frame`` through its runners (several algorithms side by
        side, or worker processes): their records, the first that failed (or None), and the
        upstream outputs after the stage."""
        results: list[StepResult]
        if self._pool is not None:
            futures = [self._pool.submit(_run_inline, r, frame, upstream) for r in self.runners]
            results = [f.result() for f in futures]
        else:
            for runner in self.runners:
                runner.submit(frame, upstream)
            results = [runner.result() for runner in self.runners]
        outputs = {}
        records = []
        failed = None
        for planned, role, result in zip(self.planned, self._role_values, results, strict=True):
            record = _record(planned, role, result)
            records.append(record)
            if result.status is _OK and result.output is not None:
                outputs[planned.name] = result.output
            elif failed is None:
                failed = record
        return records, failed, upstream.merged(outputs, self.roles)

    @property
    def single(self) -> Single | None:
        """``(algorithm, its sensors, name, stage, role)`` of a stage of one in-process
        algorithm run through :meth:`Algorithm.timed_step` (or stepped inline by the
        sequential loop); else None."""
        return self._single

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
        for runner in self.runners:
            runner.close()


def _until_cancelled(
    frames: Iterator[Frame], cancel: threading.Event, cancelled: list[bool]
) -> Iterator[Frame]:
    """``frames`` until ``cancel`` is set (checked before reading each frame); then
    ``cancelled[0]`` is True."""
    while not cancel.is_set():
        frame = next(frames, None)
        if frame is None:
            return
        yield frame
    cancelled[0] = True


def _run_inline(runner: AlgorithmRunner, frame: Frame, upstream: StageOutputs) -> StepResult:
    runner.submit(frame, upstream)
    return runner.result()


_OK = StepStatus.OK
_STATUS_VALUES = {s: s.value for s in StepStatus}


def _record(planned: PlannedAlgorithm, role: str, result: StepResult) -> StepRecord:
    error = result.error
    return StepRecord(
        algorithm=planned.spec.name,
        stage=planned.stage,
        role=role,
        status=_STATUS_VALUES[result.status],
        latency_ns=result.latency_ns,
        cpu_ns=result.cpu_ns,
        output=result.output,
        error_type=error.type if error else "",
        error_message=error.message if error else "",
        traceback=error.traceback if error else "",
    )


class Engine:
    """Runs a :class:`StageGraph` over frames.

    Args:
        graph: the checked algorithms.
        pipeline: mode, executor, timeout, fail-fast.
        inputs: the log's inputs (worker processes bind their algorithms against them).
        hooks: the Mode Manager's hooks (default: replay as fast as possible).
    """

    def __init__(
        self,
        graph: StageGraph,
        pipeline: PipelineConfig,
        *,
        inputs: LogInputs,
        hooks: ModeHooks | None = None,
    ) -> None:
        self.graph = graph
        self.pipeline = pipeline
        self.hooks: ModeHooks = hooks or ReplayMode()
        use_processes = pipeline.isolated
        inputs_dict = {
            "sensors": dict(inputs.sensors),
            "has_vehicle_state": inputs.has_vehicle_state,
            "has_ground_truth": inputs.has_ground_truth,
            "road_map": inputs.road_map,
            "mission": inputs.mission,
        }
        self._stages: list[_Stage] = []
        roles_before: Mapping[str, Role] = {}
        for name, planned in graph.stages:
            runners: list[Any] = []
            for p in planned:
                if use_processes:
                    runners.append(
                        ProcessRunner(
                            plugin=p.spec.plugin,
                            name=p.name,
                            config=p.config,
                            inputs=inputs_dict,
                            timeout_s=pipeline.step_timeout_s,
                            max_rss_mb=pipeline.max_rss_mb_of(name),
                        )
                    )
                else:
                    runners.append(InlineRunner(p.instance))
            stage = _Stage(name, planned, runners, roles_before=roles_before)
            roles_before = stage.roles_after
            self._stages.append(stage)
        self._stages[-1].last = True
        self._threads: dict[str, int] = {"thread:main": threading.get_native_id()}

    def thread_ids(self) -> dict[str, int]:
        """``thread:NAME`` → native id of the engine's threads running now (``main``, and in
        pipelined mode ``reader`` and one per stage), for per-thread CPU sampling."""
        return dict(self._threads)

    def worker_pids(self) -> dict[str, int]:
        """``stage/algorithm`` → pid of each live worker process."""
        out = {}
        for stage in self._stages:
            for runner in stage.runners:
                pid = runner.pid
                if pid is not None:
                    out[f"{stage.name}/{runner.name}"] = pid
        return out

    def close(self) -> None:
        for stage in self._stages:
            stage.close()

    @setup_frozen()
    def run(
        self,
        frames: Iterable[Frame],
        *,
        sink: FrameSink,
        skip: frozenset[int] = frozenset(),
        progress: Callable[[int], None] | None = None,
        cancel: threading.Event | None = None,
    ) -> RunReport:
        """Process ``frames``; hand every finished frame's record to ``sink``, in order.

        Args:
            frames: the frames (from the log), in order.
            sink: receives each finished frame (the results writer).
            skip: frame indices already done (a resumed run); they are read and not processed.
            progress: called with the number of frames finished so far.
            cancel: once set (from any thread), no further frame is read or started; the
                frames in flight are finished and the run ends ``interrupted``, as on Ctrl-C.

        Returns:
            what happened; ``report.status`` is ``complete``, ``interrupted`` (Ctrl-C or
            ``cancel``) or ``failed`` (``fail_fast`` and a step failed — ``report.failure`` says
            which).
        """
        stats = StatsCollector([p for _, planned in self.graph.stages for p in planned])
        pending: Iterator[Frame] = (
            (f for f in frames if f.index not in skip) if skip else iter(frames)
        )
        cancelled = [False]
        if cancel is not None:
            pending = _until_cancelled(pending, cancel, cancelled)
        pipelined = self.pipeline.mode == "pipelined" and len(self._stages) > 1
        # the common replay: as fast as possible, one algorithm in-process per stage, in order —
        # the sequential loop's chained regime (sequential.py)
        short = (
            not pipelined
            and type(self.hooks) is ReplayMode
            and self.hooks.rate is None
            and all(stage.single is not None for stage in self._stages)
        )
        paced = None if short else self.hooks.before_frame(pending)
        done = 0
        after_frame, fail_fast = self.hooks.after_frame, self.pipeline.fail_fast

        def finish(item: _Item) -> tuple[int, StepRecord] | None:
            nonlocal done
            frame = item.frame
            record = frame_record_unchecked(  # Frame and the graph keep its invariants
                int(frame.index),
                frame.stamp_ns,
                tuple(item.steps),
                frame.vehicle_state,
                frame.ground_truth,
                perf_counter_ns() - item.t0_ns,
                bool(item.late),
                frame.missing,
                frame.traffic.traffic_lights,
            )
            sink(record)
            stats.add(record)
            after_frame(record)
            done += 1
            if progress is not None:
                progress(done)
            return item.failed if fail_fast else None

        t0 = time.perf_counter()
        status = RunStatus.COMPLETE
        try:
            if paced is not None and pipelined:
                failure = self._pipelined(paced, finish)
            else:
                failure = run_sequential(
                    [
                        (stage.single, stage.roles_after, stage.last, stage.run_steps)
                        for stage in self._stages
                    ],
                    pending if paced is None else paced,
                    chained=paced is None,
                    sink=sink,
                    stats=stats,
                    progress=progress,
                    fail_fast=fail_fast,
                    after_frame=None if paced is None else after_frame,
                    cancel=cancel if paced is None else None,  # (else: no frame read once set)
                )
        except KeyboardInterrupt:
            status, failure = RunStatus.INTERRUPTED, None
        if failure is not None:
            status = RunStatus.FAILED
        elif cancelled[0] or (paced is None and cancel is not None and cancel.is_set()):
            status = RunStatus.INTERRUPTED  # (the chained regime stops without reading on)
        late = getattr(self.hooks, "late_frames", 0)
        return stats.report(
            status=status, wall_s=time.perf_counter() - t0, late_frames=late, failure=failure
        )

    def _pipelined(
        self, paced: Iterator[PacedFrame], finish: Callable[[_Item], tuple[int, StepRecord] | None]
    ) -> tuple[int, StepRecord] | None:
        end = object()
        # one hand-off into each stage and one out of the last: each has one producer thread
        # and one consumer thread; closing them all stops every thread at its next hand-off
        handoffs = [Handoff(_QUEUE_DEPTH) for _ in range(len(self._stages) + 1)]
        crashed: list[BaseException] = []

        def stop() -> None:
            for handoff in handoffs:
                handoff.close()

        def feed() -> None:
            self._threads["thread:reader"] = threading.get_native_id()
            put = handoffs[0].put
            try:
                for pf in paced:
                    put(_Item(pf.frame, pf.late, perf_counter_ns()))
                put(end)
            except HandoffClosedError:
                pass
            except BaseException as err:  # a log error: hand it to the main thread
                crashed.append(err)
                stop()

        def work(k: int) -> None:
            stage = self._stages[k]
            self._threads[f"thread:{stage.name}"] = threading.get_native_id()
            get, put = handoffs[k].get, handoffs[k + 1].put
            try:
                while True:
                    item = get()
                    if item is end:
                        put(end)
                        return
                    stage.run(item)
                    put(item)
            except HandoffClosedError:
                pass
            except BaseException as err:
                crashed.append(err)
                stop()

        threads = [threading.Thread(target=feed, name="redrive-reader", daemon=True)]
        threads += [
            threading.Thread(target=work, args=(k,), name=f"redrive-{s.name}", daemon=True)
            for k, s in enumerate(self._stages)
        ]
        for t in threads:
            t.start()
        get = handoffs[-1].get
        try:
            while True:
                try:
                    item = get()
                except HandoffClosedError:
                    break
                if item is end:
                    break
                failed = finish(item)
                if failed is not None:
                    return failed
        finally:
            stop()
            for t in threads:  # a stage stuck in a step (no timeout set) is left behind: daemon
                t.join(timeout=10.0)
            for name in [n for n in self._threads if n != "thread:main"]:
                del self._threads[name]
            if hasattr(paced, "close"):
                paced.close()
        if crashed:
            raise crashed[0]
        return None
