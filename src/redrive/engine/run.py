"""Open-loop re-simulation of a log: frames → stage graph → run directory.

>>> report = run_log(RunRequest(log=Path("drive.bag"), pipeline=reference_pipeline(),
...                             out=Path("runs/first")))          # doctest: +SKIP
"""

from __future__ import annotations

import itertools
import logging
import signal
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from redrive.assembly.clocks import other_clock_inputs
from redrive.assembly.frames import FrameAssembler
from redrive.assembly.sensor_map import load_sensor_map_overrides
from redrive.config import PipelineConfig
from redrive.engine._heap import setup_frozen
from redrive.engine.core import Engine
from redrive.engine.graph import LogInputs, StageGraph, build_graph
from redrive.engine.modes import ModeHooks, ReplayMode
from redrive.engine.resources import ResourceSampler
from redrive.engine.stats import RunReport
from redrive.engine.user_map import MapOption, choose_road_map
from redrive.errors import ConfigError
from redrive.io import LogReader, open_log
from redrive.io.content import LogScenario, fingerprint_log, log_scenario
from redrive.io.damage import damage_report
from redrive.results import (
    FrameRecord,
    PipelineInfo,
    RunSetup,
    RunStatus,
    RunWriter,
    SourceLog,
)
from redrive.types import Frame, RoadMap

__all__ = [
    "RunRequest",
    "execute",
    "expected_frames",
    "log_inputs",
    "run_log",
    "run_reader",
    "run_setup",
    "source_log",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class RunRequest:
    """One run.

    Attributes:
        log: the log to replay.
        pipeline: what runs, and how.
        out: the run directory.
        first_frame, stop_frame: frame indices ``[first_frame, stop_frame)``; None for the ends.
        sensor_map: a sensor map TOML (which topic is which sensor) or None to infer it.
        rate: real-time factor to pace at, or None for as fast as possible.
        resume: continue the (interrupted) run in ``out``.
        strict: refuse a damaged log (:class:`~redrive.errors.LogDamagedError` at the first
            damage); when False the damaged parts are skipped and listed in the report's
            ``damage``.
        skip_unfed: leave out the algorithms whose inputs the log lacks (a planner on a log
            without ego state), with the reason in the report and the manifest
            (``pipeline.skipped``), instead of refusing the pipeline.
    """

    log: Path
    pipeline: PipelineConfig
    out: Path
    first_frame: int | None = None
    stop_frame: int | None = None
    sensor_map: Path | None = None
    rate: float | None = None
    resume: bool = False
    strict: bool = True
    skip_unfed: bool = False
    road_map: MapOption | None = None


def source_log(path: Path, *, format: str, scenario: LogScenario | None = None) -> SourceLog:
    """The manifest's record of the log at ``path`` (its reader's fingerprint of the files);
    ``format`` is the reader's format name, ``scenario`` what a synthetic log was made from."""
    found = fingerprint_log(path)
    return SourceLog(
        path=found.path,
        format=format,
        sha256=found.sha256,
        size_bytes=found.size_bytes,
        scenario={} if scenario is None else asdict(scenario),
    )


def log_inputs(
    assembler: FrameAssembler,
    *,
    road_map: RoadMap | None = None,
    unusable: Mapping[str, str] | None = None,
) -> LogInputs:
    """What the log of ``assembler`` feeds algorithms; ``unusable``: the inputs whose topics feed
    no frame and why (:func:`redrive.assembly.clocks.other_clock_inputs`)."""
    smap = assembler.sensor_map
    unusable = dict(unusable or {})
    return LogInputs(
        sensors={s.sensor_id: s.sensor_type for s in smap.sensors},
        has_vehicle_state=smap.vehicle_state_topic is not None and "vehicle_state" not in unusable,
        has_ground_truth=smap.ground_truth_topic is not None and "ground_truth" not in unusable,
        road_map=road_map,
        unusable=unusable,
    )


def expected_frames(log: LogReader, assembler: FrameAssembler) -> int | None:
    """How many frames the log makes (messages on the driver topic; on the ground-truth topic
    when no sensor drives the frames)."""
    smap = assembler.sensor_map
    if smap.driver is None:
        topic = smap.ground_truth_topic
        if topic is None:
            return None
    else:
        topic = smap.sensor(smap.driver).topic
    info = log.topics.get(topic)
    return None if info is None else int(info.count)


def _reading_only_inputs(
    log: LogReader, assembler: FrameAssembler, graph: StageGraph, *, lookahead_ns: int
) -> FrameAssembler:
    """An assembler that decodes only the sensors some algorithm declares (and the driver):
    algorithms never see the others, so decoding them (camera images …) is wasted."""
    smap = assembler.sensor_map
    needed = {sid for p in graph.algorithms for sid in p.instance.bound_inputs.values()}
    kept = tuple(s for s in smap.sensors if s.sensor_id in needed or s.sensor_id == smap.driver)
    if len(kept) == len(smap.sensors):
        return assembler
    return FrameAssembler(log, sensor_map=replace(smap, sensors=kept), lookahead_ns=lookahead_ns)


def _select(frames: Iterator[Frame], first: int | None, stop: int | None) -> Iterator[Frame]:
    if first:
        frames = itertools.dropwhile(lambda f: f.index < first, frames)
    if stop is not None:
        frames = itertools.takewhile(lambda f: f.index < stop, frames)
    return frames


def _setup(
    request: RunRequest, graph: StageGraph, inputs: LogInputs, *, log: SourceLog, mode: str
) -> RunSetup:
    return run_setup(  # the map entry is added by run_reader
        request.pipeline,
        graph,
        inputs,
        log=log,
        mode=mode,
        first_frame=request.first_frame,
        stop_frame=request.stop_frame,
        rate=request.rate,
    )


def run_setup(
    pipeline: PipelineConfig,
    graph: StageGraph,
    inputs: LogInputs,
    *,
    log: SourceLog,
    mode: str,
    first_frame: int | None = None,
    stop_frame: int | None = None,
    rate: float | None = None,
    closed_loop: Mapping[str, Any] | None = None,
) -> RunSetup:
    """What the manifest records of a run before its first frame (every mode builds it here)."""
    return RunSetup(
        log=log,
        sensors=dict(inputs.sensors),
        seed=pipeline.seed,
        pipeline=PipelineInfo(
            mode=pipeline.mode,
            executor=pipeline.executor,
            step_timeout_s=pipeline.step_timeout_s,
            max_rss_mb=pipeline.max_rss_by_stage,
            fail_fast=pipeline.fail_fast,
            first_frame=first_frame,
            stop_frame=stop_frame,
            rate=rate,
            stages=tuple(name for name, _ in graph.stages),
            mode_manager=mode,
            skipped=dict(graph.skipped),
            unusable_inputs=dict(inputs.unusable),
        ),
        algorithms=tuple(p.manifest_entry() for p in graph.algorithms),
        closed_loop=dict(closed_loop or {}),
    )


def run_log(
    request: RunRequest,
    *,
    on_start: Callable[[int | None], None] | None = None,
    progress: Callable[[int], None] | None = None,
    cancel: threading.Event | None = None,
) -> RunReport:
    """Replay ``request.log`` through the pipeline into ``request.out``.

    Args:
        on_start: called once the log is open, with the number of frames expected (or None).
        progress: called with the number of frames finished so far.
        cancel: set it (from another thread) to stop reading frames: the frames already read
            are finished and the run directory is closed as ``interrupted`` (``--resume``
            continues it), as on Ctrl-C.

    Raises:
        ConfigError, PluginError: the pipeline does not fit the log (checked before any frame).
        LogError: the log cannot be read (frames before the damage are stored; the run directory
            is closed as ``failed``).
    """
    if request.first_frame is not None and request.first_frame < 0:
        raise ConfigError(f"--frames: the first frame must be >= 0, got {request.first_frame}")
    with open_log(request.log, strict=request.strict) as log:
        report = run_reader(
            request,
            log,
            hooks=ReplayMode(rate=request.rate),
            log_info=source_log(request.log, format=log.format, scenario=log_scenario(log)),
            on_start=on_start,
            progress=progress,
            cancel=cancel,
        )
        return replace(report, damage=damage_report(log))


def run_reader(
    request: RunRequest,
    log: LogReader,
    *,
    hooks: ModeHooks,
    log_info: SourceLog,
    on_start: Callable[[int | None], None] | None = None,
    progress: Callable[[int], None] | None = None,
    lookahead_ns: int | None = None,
    cancel: threading.Event | None = None,
    on_frame: Callable[[FrameRecord], None] | None = None,
    probe_clocks: bool = True,
) -> RunReport:
    """Run the pipeline over the frames of an open ``log`` (a file, or a live session's streams)
    released by ``hooks`` (the Mode Manager: replay pacing, real-time skipping …) into
    ``request.out``; ``log_info`` is what the manifest says of the log; ``lookahead_ns`` how long
    the frame assembler waits past a driver sample for the other sensors (live: 0, a frame is
    released once the tolerance has passed); ``cancel`` as in :func:`run_log`; ``on_frame`` gets
    each finished frame's record once it is stored (live: publishing the results);
    ``probe_clocks``: read the first messages of the log to find a vehicle state or ground truth
    on another clock than the frames' (:func:`redrive.assembly.clocks.other_clock_inputs`),
    which is then no input (an algorithm that needs it is skipped or refused with the reason) —
    a file log; live streams pass False (they have no first messages to read ahead)."""
    overrides = load_sensor_map_overrides(request.sensor_map) if request.sensor_map else None
    assembler = FrameAssembler(log, overrides=overrides)
    if lookahead_ns is not None:
        assembler.lookahead_ns = lookahead_ns
    chosen = choose_road_map(log, request.road_map, sensor_map=assembler.sensor_map)
    road_map = chosen.road_map
    unusable = other_clock_inputs(log, assembler.sensor_map) if probe_clocks else {}
    inputs = log_inputs(assembler, road_map=road_map, unusable=unusable)
    graph = build_graph(request.pipeline, inputs, skip_unfed=request.skip_unfed)
    assembler = _reading_only_inputs(log, assembler, graph, lookahead_ns=assembler.lookahead_ns)
    setup = _setup(request, graph, inputs, log=log_info, mode=hooks.mode.value)
    setup = replace(setup, road_map=dict(chosen.record))
    writer = RunWriter(request.out, setup=setup, resume=request.resume)
    if road_map is not None:  # the map travels with the run: the map metrics read it
        writer.write_map(road_map)
    if on_start is not None:
        total = expected_frames(log, assembler)
        if total is not None and total > 0:
            stop = total if request.stop_frame is None else min(total, request.stop_frame)
            total = max(0, stop - (request.first_frame or 0) - len(writer.done_frames))
        else:
            total = None
        on_start(total)
    frames = _select(assembler.frames(), request.first_frame, request.stop_frame)

    def summary_extra() -> dict[str, Any]:
        extra: dict[str, Any] = {}
        if assembler.undecodable:
            extra["undecodable_messages"] = dict(assembler.undecodable)
        if non_finite := assembler.non_finite.summary():
            extra["non_finite_points"] = non_finite
        return extra

    report = execute(
        graph,
        request.pipeline,
        inputs=inputs,
        hooks=hooks,
        writer=writer,
        frames=frames,
        progress=progress,
        cancel=cancel,
        sink=None if on_frame is None else _then(writer.write_frame, on_frame),
        summary_extra=summary_extra,
    )
    report = replace(report, non_finite_points=assembler.non_finite.summary())
    return replace(report, skipped=dict(graph.skipped)) if graph.skipped else report


def _then(
    first: Callable[[FrameRecord], None], second: Callable[[FrameRecord], None]
) -> Callable[[FrameRecord], None]:
    def both(record: FrameRecord) -> None:
        first(record)
        second(record)

    return both


@setup_frozen()
def execute(
    graph: StageGraph,
    pipeline: PipelineConfig,
    *,
    inputs: LogInputs,
    hooks: ModeHooks,
    writer: RunWriter,
    frames: Iterable[Frame],
    progress: Callable[[int], None] | None = None,
    cancel: threading.Event | None = None,
    sink: Callable[[FrameRecord], None] | None = None,
    summary_extra: Callable[[], Mapping[str, Any]] | None = None,
) -> RunReport:
    """Run the stages over ``frames`` into ``writer`` and close it with the run's summary — the
    part every mode shares (replay, live, closed loop).

    Args:
        sink: what receives each finished frame's record (default: ``writer.write_frame``).
        summary_extra: more summary entries, asked once the frames are done (before closing).

    Raises:
        whatever the engine raises; the run directory is closed first (``interrupted`` on
        Ctrl-C, else ``failed`` with the error in the manifest).
    """
    engine = Engine(graph, pipeline, inputs=inputs, hooks=hooks)
    sampler = ResourceSampler(engine.worker_pids, threads=engine.thread_ids).start()
    try:
        report = engine.run(
            frames,
            sink=sink or writer.write_frame,
            skip=writer.done_frames,
            progress=progress,
            cancel=cancel,
        )
    except BaseException as err:
        with _sigint_deferred():
            writer.write_resources(sampler.stop())
            engine.close()
            interrupted = isinstance(err, KeyboardInterrupt)
            status = RunStatus.INTERRUPTED if interrupted else RunStatus.FAILED
            writer.close(status=status, summary={"error": f"{type(err).__name__}: {err}"})
        raise
    # the frames are done: a Ctrl-C from here on (a batch driver stopping its cells just as the
    # last frame finished) must not leave the manifest `running` — the run is closed with what
    # it did, and a run that processed every frame stays `complete`
    with _sigint_deferred() as pressed:
        writer.write_resources(sampler.stop())
        engine.close()
        summary = report.as_dict()
        del summary["status"]  # the manifest's own status
        if summary_extra is not None:
            summary.update(summary_extra())
        skipped = getattr(hooks, "skipped_frames", None)
        if skipped is not None:
            summary["skipped_frames"] = int(skipped)
        writer.close(status=report.status, summary=summary)
    if pressed:
        logger.warning("Ctrl-C came after the last frame; the run is closed as %s", report.status)
    return report


@contextmanager
def _sigint_deferred() -> Iterator[list[int]]:
    """SIGINT held back while a run directory is closed: the list it yields gets an entry per
    Ctrl-C that came meanwhile.  Off the main thread (where Python delivers no signal) a no-op."""
    pressed: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield pressed
        return
    previous = signal.signal(signal.SIGINT, lambda signum, _frame: pressed.append(signum))
    try:
        yield pressed
    finally:
        signal.signal(signal.SIGINT, previous)
