"""Backend 1: a synthetic scenario continued with the ego under the algorithm's control.

Two worlds of the same scenario and seed run in lockstep:

- the *expert* world is the scenario as written (and as ``redrive synth`` records it): its ego is
  the scripted driver, so its ego track is the logged route that progress and deviation are
  measured against;
- the *closed-loop* world is the same scenario with the ego handed to the commands
  (:meth:`redrive.sim.world.World.drive_ego_pedals`): every physics step moves it by the actuated
  bicycle model (:class:`redrive.sim.ego.ActuatedEgo`) under the command of the last frame.

Agents: ``replay`` (non-reactive, as nuPlan's open-loop agents and NAVSIM): what the frames show
are the expert world's agents, who follow their scripted motion whatever the ego does — a follower
may then run into a braking ego (the closed-loop world drops its own copies of them,
:meth:`redrive.sim.world.World.drop_agents`: they could not change what it shows).  ``reactive``:
the closed-loop world's own agents, whose IDM sees the driven ego as an obstacle — a follower
brakes for it.

Levels: ``object`` (the default): frames carry the true ego state (map frame), the
ground-truth objects in ``base_link`` of the driven ego and the signals' states
(``Frame.traffic``), at a fixed rate; an algorithm that
declares a sensor input is refused before the run.  ``sensor``: frames carry as well the
scenario's rig — LiDAR sweeps ray-cast, camera images, IMU, GNSS — rendered from the driven ego's
pose (:mod:`redrive.closedloop.sensors`), exactly as a replay of the ``redrive synth`` log of the
same motion would show them, and the ground truth's LiDAR point counts and visibility.  The first
sensor-level frame comes one LiDAR period after the start (the first finished sweep); the ego is
under the commands from the start (the neutral command — pedals released, the wheel held —
until the first frame's).

Recording (sensor level): :meth:`SyntheticSimulator.record_sensors` tees every message the
rendering writes — sensors, camera info, ``/tf`` and ``/tf_static``, the true ego state, the ground
truth, the topics of ``redrive synth`` — into a sink, such as the run's ``sensors.mcap``: the
closed-loop world as the algorithms saw it.  The rendering starts at the first frame (the
warm-up sweep included), so a sink handed over before then gets every message of the run.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, Literal, cast

from redrive.algorithms import StageOutputs
from redrive.closedloop.sensors import FrameSensors, LockstepWorlds, SensorTee, warmup_ns
from redrive.closedloop.simulator import (
    AGENT_MODES,
    EgoCommand,
    PathFollower,
    check_options,
    choose_command,
)
from redrive.errors import ConfigError, SimulationError
from redrive.sim.ego import ActuatedEgo, EgoGeometry, PedalModel, TyreLimit
from redrive.sim.rig import rig_from_mapping
from redrive.sim.scenario import Scenario
from redrive.sim.sinks import MessageSink
from redrive.sim.synth import SensorSimulation
from redrive.sim.world import World
from redrive.types import (
    ControlCommands,
    DetectedObject,
    EnvironmentData,
    Frame,
    SensorType,
    TrafficData,
    VehicleState,
)
from redrive.types._drafts import draft_class

__all__ = ["AGENT_MODES", "LEVELS", "SyntheticSimulator"]

AgentMode = Literal["replay", "reactive"]
LEVELS = ("object", "sensor")
Level = Literal["object", "sensor"]


class SyntheticSimulator:
    """A scenario of the synthetic catalogue as a closed-loop :class:`~.Simulator`.

    Args:
        scenario: the scenario (its duration bounds the run).
        tracker: follows the planned path when the pipeline has no control stage.
        agents: ``replay`` or ``reactive`` (see the module text).
        rate_hz: frames per second (the step between frames is ``1 / rate_hz``).
        pedal: throttle/brake → acceleration.
        tyres: the friction circle the ego moves within (``TyreLimit()``: μ = 0.9).
        delay_steps: 0, or 1 to act on each command one frame late.
        level: ``object`` or ``sensor`` (see the module text).
    """

    has_vehicle_state = True
    has_ground_truth = True

    def __init__(
        self,
        scenario: Scenario,
        *,
        tracker: PathFollower,
        agents: AgentMode = "replay",
        rate_hz: float = 10.0,
        pedal: PedalModel | None = None,
        tyres: TyreLimit | None = None,
        delay_steps: int = 0,
        level: Level = "object",
    ) -> None:
        if level not in LEVELS:
            msg = f"the closed-loop level is one of {', '.join(LEVELS)}, got {level!r}"
            raise ConfigError(msg)
        check_options(agents=agents, rate_hz=rate_hz, delay_steps=delay_steps)
        self.scenario = scenario
        self.tracker = tracker
        self.agents: AgentMode = agents
        self.dt_s = 1.0 / rate_hz
        self.pedal = pedal or PedalModel()
        self.tyres = tyres or TyreLimit()
        self.delay_steps = delay_steps
        self.level: Level = level
        #: sensor id → type of the frames' sensors (none at object level)
        self.sensors: Mapping[str, SensorType] = {}
        if level == "sensor":
            rig = rig_from_mapping(scenario.rig, source=scenario.source)
            self.sensors = FrameSensors(rig).sensors
        self.reset(scenario.seed)

    # -- the Simulator protocol ---------------------------------------------------------------

    def reset(self, seed: int) -> None:
        scenario = dataclasses.replace(self.scenario, seed=seed)
        self._expert = World(scenario)
        self._world = World(scenario)
        if self.agents == "replay":
            # the frames show the expert world's agents, and nothing of the driven world moves
            # its ego: stepping its own copies of them would only cost time
            self._world.drop_agents()
        self._ego = ActuatedEgo(
            self._world.ego_model, pedals=self.pedal, delay_steps=0, tyres=self.tyres
        )
        self.tracker.reset()  # whatever a tracker keeps belongs to one run
        neutral = ControlCommands(steering_angle_rad=self._world.ego_model.steer_rad)
        self._acting: ControlCommands = neutral  # the command the ego moves under now
        self._queued: ControlCommands = neutral  # with a one-frame delay: the next one
        self._commanding = False  # whether the commands move the ego (_hand_over)
        self._hand_over()
        self._index = 0
        self._end_ns = scenario.start_stamp_ns + round(scenario.duration_s * 1e9)
        self._dt_ns = round(self.dt_s * 1e9)
        self._rendering: SensorSimulation | None = None
        self._lockstep: LockstepWorlds | None = None
        self._frame_sensors: FrameSensors | None = None
        #: sensor level: wall seconds spent rendering so far (the sensor models and handing
        #: their messages to the frames and the recording; the worlds' physics left out)
        self.rendering_s = 0.0
        self._recording: MessageSink | None = None
        self._started = False
        self._first_ns = self._world.time_ns
        if self.level == "sensor":
            worlds = LockstepWorlds(
                scene_world=self._expert if self.agents == "replay" else self._world,
                ego_world=self._world,
                worlds=(self._world, self._expert),
            )
            self._lockstep = worlds
            self._rendering = SensorSimulation(scenario, world=worlds)
            self._frame_sensors = FrameSensors(self._rendering.rig)
            self._first_ns = self._world.time_ns + warmup_ns(self._rendering.rig)

    def record_sensors(self, sink: MessageSink) -> None:
        """Tee every message the sensor-level rendering writes into ``sink`` as well (see the
        module text), until the next :meth:`reset`.

        Raises:
            ConfigError: at object level (nothing is rendered).
            SimulationError: the rendering has already started (the first frame was observed):
                the recording would miss its start.
        """
        if self._rendering is None:
            msg = "closed loop: an object-level run renders no sensors to record; use --sensors"
            raise ConfigError(msg)
        if self._started:
            msg = "closed loop: record the sensors before the first frame, not during the run"
            raise SimulationError(msg)
        self._recording = sink

    def _start_rendering(self) -> None:
        """Start the rig (static transforms, the warm-up to the first finished sweep)."""
        if self._started or self._rendering is None or self._frame_sensors is None:
            return
        self._started = True
        sink: MessageSink = self._frame_sensors
        if self._recording is not None:
            sink = SensorTee(self._frame_sensors, self._recording)
        self._rendering.start(sink)
        self._render_to(self._first_ns)

    def _render_to(self, stamp_ns: int) -> None:
        """Advance the rendering (and both worlds) to ``stamp_ns``, timing the rendering."""
        assert self._rendering is not None
        assert self._lockstep is not None
        t0, physics0 = time.perf_counter(), self._lockstep.step_s
        for _ in self._rendering.advance_to(stamp_ns):  # both worlds, the sensors' events
            pass
        physics = self._lockstep.step_s - physics0
        self.rendering_s += time.perf_counter() - t0 - physics

    def observe(self) -> Frame:
        world = self._world
        source = self._expert if self.agents == "replay" else world
        if self._rendering is None or self._frame_sensors is None:
            objects = source.ground_truth_in_base(world.map_from_base())
            return _object_frame(
                world.time_ns, self._index, world.ego_state(), world.traffic_data(), objects
            )
        self._start_rendering()
        lidar_hits, camera_pixels = self._rendering.visibility()
        objects = source.ground_truth_in_base(
            world.map_from_base(), lidar_hits=lidar_hits, camera_pixels=camera_pixels
        )
        return Frame(
            stamp_ns=world.time_ns,
            index=self._index,
            sensors=self._frame_sensors.sensor_data(),
            vehicle_state=world.ego_state(),
            traffic=world.traffic_data(),
            ground_truth=objects,
        )

    def step(self, outputs: StageOutputs, dt_s: float) -> EgoCommand:
        model = self._world.ego_model
        chosen = choose_command(
            outputs,
            state=self._world.ego_state(),
            steer_rad=model.steer_rad,
            tracker=self.tracker,
            dt_s=dt_s,
            stamp_ns=self._world.time_ns,
        )
        if self.delay_steps:
            self._acting, self._queued = self._queued, chosen.commands
        else:
            self._acting = chosen.commands
        if self._commanding:  # the ego was handed over (a subclass may keep the driver)
            self._command_ego()
        target = self._world.time_ns + round(dt_s * 1e9)
        if self._rendering is None:
            self._world.step_to(target)
            self._expert.step_to(target)
        else:
            self._start_rendering()
            self._render_to(target)
        self._index += 1
        return chosen

    @property
    def done(self) -> bool:
        return self._world.time_ns + self._dt_ns > self._end_ns

    @property
    def logged_state(self) -> VehicleState | None:
        return self._expert.ego_state()

    def describe(self) -> dict[str, Any]:
        return {
            "backend": "synthetic",
            "level": self.level,
            "scenario": self.scenario.name,
            "scenario_source": self.scenario.source,
            "agents": self.agents,
            "rate_hz": 1.0 / self.dt_s,
            "delay_steps": self.delay_steps,
            "ego": self._ego.describe(),
            "tracker": self.tracker.describe(),
            **(
                {
                    "sensors": {sid: stype.value for sid, stype in self.sensors.items()},
                    "first_frame_s": (self._first_ns - self.scenario.start_stamp_ns) / 1e9,
                }
                if self.level == "sensor"
                else {}
            ),
        }

    @property
    def ego_geometry(self) -> EgoGeometry:
        """The driven ego's dimensions and actuator limits."""
        return self._world.ego_geometry

    @property
    def first_stamp_ns(self) -> int:
        """The time of the first frame (sensor level: one LiDAR period after the start)."""
        return self._first_ns

    # -- the ego ------------------------------------------------------------------------------

    def _hand_over(self) -> None:
        """Give the closed-loop world's ego to the commands (at the start of a run)."""
        self._command_ego()

    def _command_ego(self) -> None:
        """Move the closed-loop world's ego under the acting command from now on: each physics
        step is ``self._ego.apply(self._acting, dt_s)``, in the world's compiled step."""
        self._commanding = True
        self._world.drive_ego_pedals(self._acting, self._ego.pedals, tyres=self._ego.tyres)


#: Frame's draft (:mod:`redrive.types._drafts`): the object-level frames are built unchecked
_FrameDraft = draft_class(Frame)
_NO_SENSORS: Mapping[str, Any] = MappingProxyType({})
_ENVIRONMENT = EnvironmentData()


def _object_frame(
    stamp_ns: int,
    index: int,
    state: VehicleState,
    traffic: TrafficData,
    objects: tuple[DetectedObject, ...],
) -> Frame:
    """``Frame(stamp_ns=…, index=…, vehicle_state=…, traffic=…, ground_truth=…)`` of an
    object-level observation (an int stamp, a non-negative index, a tuple of objects): the
    fields its ``__post_init__`` would make of them — no sensors (an empty read-only mapping),
    the default environment (one immutable instance), nothing missing — without the checks."""
    frame = _FrameDraft()
    frame.stamp_ns = stamp_ns
    frame.index = index
    frame.sensors = _NO_SENSORS
    frame.vehicle_state = state
    frame.environment = _ENVIRONMENT
    frame.traffic = traffic
    frame.ground_truth = objects
    frame.missing = ()
    frame.__class__ = Frame
    return cast("Frame", frame)
