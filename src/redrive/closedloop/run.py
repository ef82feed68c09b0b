"""``redrive run SCENARIO|LOG --closed-loop``: a closed-loop run into an ordinary run directory.

>>> report = run_closed_loop(ClosedLoopRequest(scenario="cut_in", pipeline=planner_only,
...                                            out=Path("runs/cl")))          # doctest: +SKIP

The run directory is the one every command reads (``evaluate``, ``report``, ``export``,
``compare``, the GUI). Its frames table holds the driven ego. The logged ego is stored beside it,
per frame, and progress and deviation are measured against it. ``closed_loop`` holds what moved
the ego after each frame (command, its source, the fallback's reason), how far the ego was
from the logged one and whether that passed the thresholds (``deviated``; counted in the
summary's ``closed_loop``), and which objects the ego touched (``collisions``,
``collision_object_id`` / ``_class``; ``--on-collision stop`` ends the run at the first, the
summary's ``closed_loop.stopped`` says where). ``map.json`` holds the road map of a scenario
or of a ``redrive synth`` log (a recorded log has none). The manifest's pipeline has
``mode_manager = "closed_loop"``, and the simulator's description (backend ``synthetic`` or
``log``, agents, ego limits and tyres, tracker and its parameters, deviation thresholds,
``on_collision``) is under ``closed_loop``.  A log run's source is the log's usual fingerprint (path, sha256), so
``compare`` pairs runs of the same log.

A sensor-level run records the rendered rig in ``RUN/sensors.mcap`` (:data:`SENSOR_LOG`): every
message of the closed-loop world's sensors — the topics ``redrive synth`` writes — as the
algorithms saw them; the manifest's ``closed_loop.sensor_log`` names it (relative to the run),
so the GUI and Foxglove open the run over it.  The file is closed with the run, also when the run
fails or is interrupted (it then holds what was rendered so far).  Its chunks are zstd at level 1
(:data:`SENSOR_LOG_ZSTD_LEVEL`): a third of level 3's CPU for about 6 % more bytes — a 64-beam
sweep is ≈ 60 ms of CPU a frame at level 3, ≈ 18 ms at level 1.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import threading
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from redrive.algorithms import GROUND_TRUTH, ROAD_MAP, VEHICLE_STATE
from redrive.algorithms.discovery import load_algorithm_class
from redrive.assembly.sensor_map import infer_sensor_map, load_sensor_map_overrides
from redrive.closedloop.contact import ON_COLLISION, check_on_collision
from redrive.closedloop.logreplay import LogSimulator
from redrive.closedloop.mode import DEFAULT_DEVIATION_M, DEFAULT_DEVIATION_RAD, ClosedLoopMode
from redrive.closedloop.sensors import RecordingThread
from redrive.closedloop.simulator import Simulator
from redrive.closedloop.synthetic import AgentMode, Level, SyntheticSimulator
from redrive.closedloop.tracker import LqrTracker
from redrive.config import PipelineConfig
from redrive.engine.graph import LogInputs, build_graph
from redrive.engine.run import execute, run_setup, source_log
from redrive.engine.stats import RunReport
from redrive.engine.user_map import MapOption, choose_road_map
from redrive.errors import ConfigError
from redrive.io import LogReader, open_log
from redrive.io.mcap.writer import McapWriter
from redrive.plugins import discovered_once
from redrive.results import (
    FrameRecord,
    RunWriter,
    SourceLog,
)
from redrive.sim.ego import EgoGeometry, TyreLimit
from redrive.sim.roadmap import scenario_road_map
from redrive.sim.scenario import list_scenarios, load_scenario
from redrive.types import Mission, RoadMap, SensorType

__all__ = ["SENSOR_LOG", "ClosedLoopRequest", "is_scenario", "run_closed_loop"]

logger = logging.getLogger(__name__)

#: The recording of a sensor-level run's rendered sensors, in the run directory.
SENSOR_LOG = "sensors.mcap"
#: the zstd level of ``sensors.mcap`` (``redrive synth`` logs: the writer's default, 3)
SENSOR_LOG_ZSTD_LEVEL = 1


@dataclass(frozen=True, slots=True, kw_only=True)
class ClosedLoopRequest:
    """One closed-loop run.

    Attributes:
        scenario: what the ego drives in: a scenario of the catalogue (``redrive synth
            --list``) or a scenario TOML (backend ``synthetic``), else the path of a recorded
            log with the ego's pose (backend ``log``, :mod:`redrive.closedloop.logreplay`).
        pipeline: what runs (sequential mode).
        out: the run directory.
        agents: ``replay`` (non-reactive) or ``reactive`` (IDM sees the driven ego).
        seed: the scenario's seed (None: the scenario's own); a log has none.
        duration_s: how long (None: the scenario's duration, or the whole log).
        rate_hz: frames per second (a log: at most, its frames are the log's).
        delay_steps: 1 to apply each command one frame late.
        level: ``object`` (frames carry the ego state and ground truth) or ``sensor`` (the
            scenario's rig re-rendered from the driven ego as well).
        sensor_map: a log only: a sensor map TOML (which topic is which sensor).
        on_collision: ``continue`` (as nuPlan: drive on, the metrics count it) or ``stop`` (end
            the run after the first frame in which the ego touches an object; the summary's
            ``closed_loop.stopped`` says why).
        friction_coefficient: μ of the ego's tyres (friction circle μ·g; default 0.9, dry
            asphalt — :class:`redrive.sim.ego.TyreLimit`).
    """

    scenario: str
    pipeline: PipelineConfig
    out: Path
    agents: AgentMode = "replay"
    seed: int | None = None
    duration_s: float | None = None
    rate_hz: float = 10.0
    delay_steps: int = 0
    level: Level = "object"
    sensor_map: Path | None = None
    on_collision: str = ON_COLLISION[0]
    friction_coefficient: float = TyreLimit().friction_coefficient
    road_map: MapOption | None = None  # a log only: --map / --no-map (engine.user_map)


def is_scenario(text: str) -> bool:
    """Whether ``text`` names a scenario (of the catalogue, or a ``.toml`` file) rather than a log."""
    return text in list_scenarios() or (text.endswith(".toml") and Path(text).is_file())


def run_closed_loop(
    request: ClosedLoopRequest,
    *,
    on_start: Callable[[int | None], None] | None = None,
    progress: Callable[[int], None] | None = None,
    cancel: threading.Event | None = None,
    wrap_simulator: Callable[[Simulator], Simulator] | None = None,
) -> RunReport:
    """Drive the ego of ``request.scenario`` — a scenario (backend ``synthetic``) or a recorded
    log (backend ``log``) — with the pipeline's outputs into ``request.out``.

    ``wrap_simulator`` (benchmarks) wraps the simulator the frame loop calls, e.g. to time its
    ``observe`` and ``step``; it must delegate everything.

    Raises:
        ConfigError, PluginError: the pipeline does not fit (an algorithm reads a sensor the
            backend does not provide; the pipelined mode), or the log cannot be driven (no ego
            pose; no objects for ``reactive`` agents) — checked before any frame.
    """
    with discovered_once():  # the algorithms are loaded twice (what they read, the graph)
        return _run_closed_loop(
            request,
            on_start=on_start,
            progress=progress,
            cancel=cancel,
            wrap_simulator=wrap_simulator,
        )


def _run_closed_loop(
    request: ClosedLoopRequest,
    *,
    on_start: Callable[[int | None], None] | None,
    progress: Callable[[int], None] | None,
    cancel: threading.Event | None,
    wrap_simulator: Callable[[Simulator], Simulator] | None,
) -> RunReport:
    check_on_collision(request.on_collision)
    if not (math.isfinite(request.friction_coefficient) and request.friction_coefficient > 0.0):
        msg = (
            f"the tyres' friction coefficient must be a positive number (0.9: dry asphalt, "
            f"0.5: wet), got {request.friction_coefficient}"
        )
        raise ConfigError(msg)
    if request.pipeline.mode == "pipelined":
        msg = (
            "closed loop runs the stages of a frame before the next frame exists (the outputs "
            "move the ego); drop --mode pipelined"
        )
        raise ConfigError(msg)
    if is_scenario(request.scenario):
        return _run_scenario(
            request, on_start=on_start, progress=progress, cancel=cancel, wrap=wrap_simulator
        )
    path = Path(request.scenario)
    if not path.exists():
        msg = (
            f"{request.scenario}: no such scenario, scenario TOML or log (`redrive synth --list` "
            "lists the scenarios)"
        )
        raise ConfigError(msg)
    with open_log(path) as log:
        return _run_log(
            request, log, on_start=on_start, progress=progress, cancel=cancel, wrap=wrap_simulator
        )


def _run_scenario(
    request: ClosedLoopRequest,
    *,
    on_start: Callable[[int | None], None] | None,
    progress: Callable[[int], None] | None,
    cancel: threading.Event | None,
    wrap: Callable[[Simulator], Simulator] | None = None,
) -> RunReport:
    if request.sensor_map is not None:
        msg = "--sensor-map applies to a recorded log, not to a scenario; drop it"
        raise ConfigError(msg)
    scenario = load_scenario(request.scenario)
    if request.duration_s is not None:
        scenario = dataclasses.replace(scenario, duration_s=float(request.duration_s))
    if request.seed is not None:
        scenario = dataclasses.replace(scenario, seed=int(request.seed))
    simulator = SyntheticSimulator(
        scenario,
        tracker=LqrTracker(),
        agents=request.agents,
        rate_hz=request.rate_hz,
        tyres=TyreLimit(friction_coefficient=request.friction_coefficient),
        delay_steps=request.delay_steps,
        level=request.level,
    )
    if simulator.level == "object":
        _refuse_sensor_inputs(request.pipeline, simulator.sensors)
    source = SourceLog(
        path=scenario.source if scenario.source.endswith(".toml") else f"scenario:{scenario.name}",
        format="scenario",
        sha256=None,
        source=scenario.name,
    )
    described = {**simulator.describe(), "seed": scenario.seed, "duration_s": scenario.duration_s}
    if simulator.level == "sensor":
        described["sensor_log"] = SENSOR_LOG
    return _drive(
        request,
        simulator,
        source=source,
        described=described,
        road_map=scenario_road_map(scenario),
        ego_geometry=simulator.ego_geometry,
        total=math.floor(
            (scenario.duration_s - (simulator.first_stamp_ns - scenario.start_stamp_ns) / 1e9)
            * request.rate_hz
            + 1e-9
        ),
        on_start=on_start,
        progress=progress,
        cancel=cancel,
        wrap=wrap,
    )


def _run_log(
    request: ClosedLoopRequest,
    log: LogReader,
    *,
    on_start: Callable[[int | None], None] | None,
    progress: Callable[[int], None] | None,
    cancel: threading.Event | None,
    wrap: Callable[[Simulator], Simulator] | None = None,
) -> RunReport:
    if request.seed is not None:
        logger.debug("closed loop on a log: --seed seeds the algorithms only")
    overrides = load_sensor_map_overrides(request.sensor_map) if request.sensor_map else None
    smap = infer_sensor_map(log.topics, duration_ns=log.end_ns - log.start_ns, overrides=overrides)
    # the log's own map (a synthetic or recorded-traffic log's) or --map's, placed in the log's
    # frame: the map metrics, the route and the reactive agents' lanes all use it
    chosen = choose_road_map(log, request.road_map, sensor_map=smap)
    road_map = chosen.road_map
    # the manifest's fingerprint of the log (its sha256) is read in a thread beside the
    # simulator's setup (hashlib releases the GIL); its error, if any, is raised here as before
    with ThreadPoolExecutor(1, thread_name_prefix="redrive-log-sha256") as pool:
        fingerprint = pool.submit(source_log, Path(request.scenario), format=log.format)
        simulator = LogSimulator(
            log,
            tracker=LqrTracker(),
            agents=request.agents,
            rate_hz=request.rate_hz,
            duration_s=request.duration_s,
            overrides=overrides,
            tyres=TyreLimit(friction_coefficient=request.friction_coefficient),
            delay_steps=request.delay_steps,
            reads_sensors=_reads_sensors(request.pipeline),
            road_map=road_map,
        )
        source = fingerprint.result()
    return _drive(
        request,
        simulator,
        source=source,
        described=simulator.describe(),
        road_map=chosen.road_map,  # the log's own or --map's (placed in the log's frame)
        map_record=chosen.record,
        mission=simulator.mission,
        ego_geometry=simulator.geometry,
        total=None,
        on_start=on_start,
        progress=progress,
        cancel=cancel,
        wrap=wrap,
    )


def _drive(
    request: ClosedLoopRequest,
    simulator: Simulator,
    *,
    source: SourceLog,
    described: Mapping[str, Any],
    road_map: RoadMap | None,
    map_record: Mapping[str, Any] | None = None,
    mission: Mission | None = None,
    ego_geometry: EgoGeometry,
    total: int | None,
    on_start: Callable[[int | None], None] | None,
    progress: Callable[[int], None] | None,
    cancel: threading.Event | None,
    wrap: Callable[[Simulator], Simulator] | None = None,
) -> RunReport:
    """The part both backends share: the graph, the run directory, the frame loop."""
    inputs = LogInputs(
        sensors=dict(simulator.sensors),
        has_vehicle_state=simulator.has_vehicle_state,
        has_ground_truth=simulator.has_ground_truth,
        road_map=road_map,
        mission=mission,
    )
    graph = build_graph(request.pipeline, inputs)
    pipeline = request.pipeline
    setup = run_setup(
        request.pipeline,
        graph,
        inputs,
        log=source,
        mode="closed_loop",
        closed_loop={
            **described,
            "deviation_threshold_m": DEFAULT_DEVIATION_M,
            "deviation_threshold_rad": DEFAULT_DEVIATION_RAD,
            "on_collision": request.on_collision,
        },
    )
    if map_record:
        setup = dataclasses.replace(setup, road_map=dict(map_record))
    writer = RunWriter(request.out, setup=setup)
    looped: Simulator = simulator if wrap is None else wrap(simulator)
    mode = ClosedLoopMode(
        looped,
        write=writer.write_frame,
        ego_geometry=ego_geometry,
        on_collision=request.on_collision,
    )
    if road_map is not None:
        writer.write_map(road_map)
    if on_start is not None:
        on_start(total)

    def stored_after_the_step(record: FrameRecord) -> None:
        """The mode writes each record once the outputs moved the ego (after_frame)."""

    recording: McapWriter | None = None
    recorder: RecordingThread | None = None
    if isinstance(simulator, SyntheticSimulator) and simulator.level == "sensor":
        recording = McapWriter(request.out / SENSOR_LOG, zstd_level=SENSOR_LOG_ZSTD_LEVEL)
        recorder = RecordingThread(recording)  # serialised and compressed beside the loop
        simulator.record_sensors(recorder)
    try:
        report = execute(
            graph,
            pipeline,
            inputs=inputs,
            hooks=mode,
            writer=writer,
            frames=mode.frames(),
            progress=progress,
            cancel=cancel,
            sink=stored_after_the_step,
            summary_extra=lambda: {
                "closed_loop": {**mode.deviation_summary(), **mode.collision_summary()}
            },
        )
    except BaseException:
        if recording is not None and recorder is not None:
            _close_after_failure(recording, recorder)
        raise
    if recording is not None and recorder is not None:
        try:
            recorder.stop()
        except BaseException:
            recording.abort()
            raise
        recording.close()
    return report


def _close_after_failure(recording: McapWriter, recorder: RecordingThread) -> None:
    """Close a failed or interrupted run's recording (what was rendered so far, a file that
    opens); if even that fails, drop it rather than hide the run's own error."""
    try:
        recorder.stop()
        recording.close()
    except Exception:
        logger.warning("%s: could not be finished, dropped", recording.path, exc_info=True)
        recording.abort()


def _reads_sensors(pipeline: PipelineConfig) -> bool:
    """Whether an algorithm of ``pipeline`` reads a sensor (not only the ego state, the ground
    truth or the road map)."""
    return any(
        i not in (VEHICLE_STATE, GROUND_TRUTH, ROAD_MAP)
        for spec in pipeline.algorithms
        for i in load_algorithm_class(spec.plugin).inputs
    )


def _refuse_sensor_inputs(pipeline: PipelineConfig, sensors: Mapping[str, Any]) -> None:
    """An algorithm that reads a sensor the backend does not render is refused before the run,
    with what the frames do carry."""
    for spec in pipeline.algorithms:
        cls = load_algorithm_class(spec.plugin)
        wanted = [
            i.value if isinstance(i, SensorType) else i
            for i in cls.inputs
            if i not in (VEHICLE_STATE, GROUND_TRUTH, ROAD_MAP) and i not in sensors
        ]
        if wanted:
            msg = (
                f"closed loop: {spec.name} ({spec.plugin}) reads {', '.join(wanted)}, but the "
                "object-level synthetic backend renders no sensors: its frames carry the ego "
                "state and the ground-truth objects. Use a perception that reads ground truth "
                "(--perception noisy-oracle) or plan from ground truth directly, or add --sensors "
                "(sensor-level closed loop: the scenario's rig rendered from the driven pose)"
            )
            raise ConfigError(msg)
