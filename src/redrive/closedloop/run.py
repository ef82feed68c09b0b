"""``redrive run SCENARIO --closed-loop``: a closed-loop run into an ordinary run directory.

>>> report = run_closed_loop(ClosedLoopRequest(scenario="cut_in", pipeline=planner_only,
...                                            out=Path("runs/cl")))          # doctest: +SKIP

The run directory is the one every command reads (``evaluate``, ``report``, ``export``,
``compare``, the GUI). Its frames table holds the driven ego. The logged ego is stored beside it,
per frame, and progress and deviation are measured against it. ``closed_loop`` holds what moved
the ego after each frame (command, its source, the fallback's reason) and how far the ego was
from the logged one. ``map.json`` holds the road map of the scenario. The manifest's pipeline has
``mode_manager = "closed_loop"``, and the simulator's description (backend, agents, ego limits,
tracker and gains) is under ``closed_loop``.
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from redrive.algorithms import GROUND_TRUTH, VEHICLE_STATE
from redrive.algorithms.discovery import load_algorithm_class
from redrive.closedloop.mode import ClosedLoopMode
from redrive.closedloop.simulator import Simulator
from redrive.closedloop.synthetic import AgentMode, SyntheticSimulator
from redrive.closedloop.tracker import LqrPidTracker
from redrive.config import PipelineConfig
from redrive.engine.graph import LogInputs, build_graph
from redrive.engine.run import execute
from redrive.engine.stats import RunReport
from redrive.errors import ConfigError
from redrive.results import (
    FrameRecord,
    PipelineInfo,
    RunSetup,
    RunWriter,
    SourceLog,
)
from redrive.sim.roadmap import scenario_road_map
from redrive.sim.scenario import list_scenarios, load_scenario
from redrive.types import SensorType

__all__ = ["ClosedLoopRequest", "is_scenario", "run_closed_loop"]


@dataclass(frozen=True, slots=True, kw_only=True)
class ClosedLoopRequest:
    """One closed-loop run.

    Attributes:
        scenario: a scenario of the catalogue (``redrive synth --list``) or a scenario TOML.
        pipeline: what runs (sequential mode).
        out: the run directory.
        agents: ``replay`` (non-reactive) or ``reactive`` (IDM sees the driven ego).
        seed: the scenario's seed (None: the scenario's own).
        duration_s: how long (None: the scenario's duration).
        rate_hz: frames per second.
        delay_steps: 1 to apply each command one frame late.
    """

    scenario: str
    pipeline: PipelineConfig
    out: Path
    agents: AgentMode = "replay"
    seed: int | None = None
    duration_s: float | None = None
    rate_hz: float = 10.0
    delay_steps: int = 0


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
    """Drive the scenario's ego with the pipeline's outputs into ``request.out``.

    ``wrap_simulator`` (benchmarks) wraps the simulator the frame loop calls, e.g. to time its
    ``observe`` and ``step``; it must delegate everything.

    Raises:
        ConfigError, PluginError: the pipeline does not fit (an algorithm reads a sensor the
            object-level backend does not render; the pipelined mode), checked before any frame.
    """
    if request.pipeline.mode == "pipelined":
        msg = (
            "closed loop runs the stages of a frame before the next frame exists (the outputs "
            "move the ego); drop --mode pipelined"
        )
        raise ConfigError(msg)
    scenario = load_scenario(request.scenario)
    if request.duration_s is not None:
        scenario = dataclasses.replace(scenario, duration_s=float(request.duration_s))
    if request.seed is not None:
        scenario = dataclasses.replace(scenario, seed=int(request.seed))
    simulator = SyntheticSimulator(
        scenario,
        tracker=LqrPidTracker(),
        agents=request.agents,
        rate_hz=request.rate_hz,
        delay_steps=request.delay_steps,
    )
    inputs = LogInputs(
        sensors=dict(simulator.sensors),
        has_vehicle_state=simulator.has_vehicle_state,
        has_ground_truth=simulator.has_ground_truth,
    )
    _refuse_sensor_inputs(request.pipeline, simulator.sensors)
    graph = build_graph(request.pipeline, inputs)
    pipeline = request.pipeline
    setup = RunSetup(
        log=SourceLog(
            path=scenario.source
            if scenario.source.endswith(".toml")
            else f"scenario:{scenario.name}",
            format="scenario",
            sha256=None,
            source=scenario.name,
        ),
        sensors=dict(inputs.sensors),
        seed=pipeline.seed,
        pipeline=PipelineInfo(
            mode=pipeline.mode,
            executor=pipeline.executor,
            step_timeout_s=pipeline.step_timeout_s,
            fail_fast=pipeline.fail_fast,
            stages=tuple(name for name, _ in graph.stages),
            mode_manager="closed_loop",
        ),
        algorithms=tuple(p.manifest_entry() for p in graph.algorithms),
        closed_loop={
            **simulator.describe(),
            "seed": scenario.seed,
            "duration_s": scenario.duration_s,
        },
    )
    writer = RunWriter(request.out, setup=setup)
    writer.write_map(scenario_road_map(scenario))
    looped: Simulator = simulator if wrap_simulator is None else wrap_simulator(simulator)
    mode = ClosedLoopMode(looped, write=writer.write_frame)
    if on_start is not None:
        on_start(math.floor(scenario.duration_s * request.rate_hz + 1e-9))

    def stored_after_the_step(record: FrameRecord) -> None:
        """The mode writes each record once the outputs moved the ego (after_frame)."""

    return execute(
        graph,
        pipeline,
        inputs=inputs,
        hooks=mode,
        writer=writer,
        frames=mode.frames(),
        progress=progress,
        cancel=cancel,
        sink=stored_after_the_step,
    )


def _refuse_sensor_inputs(pipeline: PipelineConfig, sensors: Mapping[str, Any]) -> None:
    """An algorithm that reads a sensor the backend does not render is refused before the run,
    with what the frames do carry."""
    for spec in pipeline.algorithms:
        cls = load_algorithm_class(spec.plugin)
        wanted = [
            i.value if isinstance(i, SensorType) else i
            for i in cls.inputs
            if i not in (VEHICLE_STATE, GROUND_TRUTH) and i not in sensors
        ]
        if wanted:
            msg = (
                f"closed loop: {spec.name} ({spec.plugin}) reads {', '.join(wanted)}, but the "
                "object-level synthetic backend renders no sensors: its frames carry the ego "
                "state and the ground-truth objects. Use a perception that reads ground truth "
                "(--perception noisy-oracle) or plan from ground truth directly; sensor-level "
                "closed loop (LiDAR and camera re-rendered from the driven pose) is not built yet"
            )
            raise ConfigError(msg)
