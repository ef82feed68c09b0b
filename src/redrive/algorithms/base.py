"""The algorithm contract: one small base class a researcher subclasses.

>>> class MyDetector(Algorithm):
...     '''Finds nothing, quickly.'''
...     role = Role.PERCEPTION
...     inputs = (SensorType.LIDAR,)
...     def step(self, frame, upstream):
...         return []

``role`` fixes the output type (PERCEPTION → a list of :class:`DetectedObject`, PLANNING → a
:class:`PlannedPath`, CONTROL → :class:`ControlCommands`); ``inputs`` names what the algorithm
reads from a frame and is checked against the log before a run starts.  The engine never calls
``step`` directly: it calls :meth:`Algorithm.run_step`, which times the step, checks the output and
records an exception instead of swallowing it.
"""

from __future__ import annotations

import enum
import time
import traceback
from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar

from redrive.errors import AlgorithmError, ConfigError, MissingInputError
from redrive.types import (
    ControlCommands,
    DetectedObject,
    Frame,
    Mission,
    PlannedPath,
    RoadMap,
    Role,
    SensorData,
    SensorType,
)

__all__ = [
    "GROUND_TRUTH",
    "ROAD_MAP",
    "VEHICLE_STATE",
    "Algorithm",
    "AlgorithmOutput",
    "Input",
    "Role",
    "StageOutputs",
    "StepError",
    "StepResult",
    "StepStatus",
    "check_output",
]

#: an input meaning "the frame's ego state" (``Frame.vehicle_state``).
VEHICLE_STATE = "vehicle_state"
#: an input meaning "the frame's ground-truth objects" (``Frame.ground_truth``).
GROUND_TRUTH = "ground_truth"
#: an input meaning "the log's road map" (:attr:`Algorithm.road_map`, handed over before the
#: first frame: a synthetic log or scenario has one, recorded logs mostly not).
ROAD_MAP = "road_map"

#: what ``inputs`` may name: a sensor id of the log (``"lidar_top"``), any sensor of a type
#: (``SensorType.LIDAR``), :data:`VEHICLE_STATE`, :data:`GROUND_TRUTH` or :data:`ROAD_MAP`.
Input = str | SensorType

AlgorithmOutput = tuple[DetectedObject, ...] | PlannedPath | ControlCommands


_PERCEPTION, _PLANNING, _CONTROL = Role.PERCEPTION, Role.PLANNING, Role.CONTROL


def check_output(role: Role, value: object, *, where: str) -> AlgorithmOutput:
    """``value`` as the output type of ``role``, or :class:`AlgorithmError` saying what came back.

    PERCEPTION accepts any list or tuple of :class:`DetectedObject` and returns a tuple.
    """
    if role is _PERCEPTION:
        if isinstance(value, list | tuple) and all(isinstance(o, DetectedObject) for o in value):
            return tuple(value)
    elif role is _PLANNING:
        if isinstance(value, PlannedPath):
            return value
    elif isinstance(value, ControlCommands):
        return value
    got = type(value).__name__
    if isinstance(value, list | tuple):
        kinds = sorted({type(o).__name__ for o in value if not isinstance(o, DetectedObject)})
        got = f"{got} holding {', '.join(kinds)}"
    msg = f"{where}: a {role.name} algorithm must return {role.output_name}, got {got}"
    raise AlgorithmError(msg)


@dataclass(frozen=True, slots=True)
class StageOutputs:
    """What earlier stages produced for this frame, by algorithm name, in pipeline order.

    Attributes:
        outputs: algorithm name → its output for this frame (failed steps are absent).
        roles: algorithm name → its role.
    """

    outputs: Mapping[str, AlgorithmOutput] = field(default_factory=dict)
    roles: Mapping[str, Role] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "outputs", MappingProxyType(dict(self.outputs)))
        object.__setattr__(self, "roles", MappingProxyType(dict(self.roles)))

    def __reduce__(self) -> tuple[Any, ...]:
        return StageOutputs, (dict(self.outputs), dict(self.roles))

    def _latest(self, role: Role, name: str | None) -> AlgorithmOutput | None:
        if name is not None:
            if self.roles.get(name) not in (role, None):
                msg = f"upstream {name!r} is a {self.roles[name].name} algorithm, not {role.name}"
                raise AlgorithmError(msg)
            return self.outputs.get(name)
        found: AlgorithmOutput | None = None
        for key, value in self.outputs.items():
            if self.roles.get(key) is role:
                found = value
        return found

    def objects(self, name: str | None = None) -> tuple[DetectedObject, ...] | None:
        """The objects of perception algorithm ``name``, or of the last one that ran; None when
        no perception output exists for this frame."""
        value = self._latest(Role.PERCEPTION, name)
        return value if isinstance(value, tuple) else None

    def path(self, name: str | None = None) -> PlannedPath | None:
        """The path of planning algorithm ``name``, or of the last one that ran."""
        value = self._latest(Role.PLANNING, name)
        return value if isinstance(value, PlannedPath) else None

    def commands(self, name: str | None = None) -> ControlCommands | None:
        """The commands of control algorithm ``name``, or of the last one that ran."""
        value = self._latest(Role.CONTROL, name)
        return value if isinstance(value, ControlCommands) else None

    def merged(
        self, more: Mapping[str, AlgorithmOutput], roles: Mapping[str, Role]
    ) -> StageOutputs:
        """These outputs followed by ``more`` (a later stage's)."""
        return StageOutputs.of_proxies(
            MappingProxyType({**self.outputs, **more}), MappingProxyType({**self.roles, **roles})
        )

    @staticmethod
    def of_proxies(
        outputs: MappingProxyType[str, AlgorithmOutput], roles: MappingProxyType[str, Role]
    ) -> StageOutputs:
        """Stage outputs holding these read-only views as they are (no copy): for callers that
        never change the dicts behind them (the engine, per frame)."""
        out = _StageOutputsBuilder()
        out.outputs = outputs
        out.roles = roles
        out.__class__ = StageOutputs  # type: ignore[assignment]
        return out  # type: ignore[return-value]


class _StageOutputsBuilder:
    """:class:`StageOutputs`'s slots in its order, set by plain attribute stores; the instance
    then becomes a StageOutputs by ``__class__`` assignment (the same memory layout, checked
    by CPython) — cheaper than one descriptor call per field (see
    :func:`redrive.results.records.step_record_unchecked`)."""

    __slots__ = StageOutputs.__slots__
    outputs: MappingProxyType[str, AlgorithmOutput]
    roles: MappingProxyType[str, Role]


assert StageOutputs.__slots__ == ("outputs", "roles")


class StepStatus(enum.Enum):
    OK = "ok"
    ERROR = "error"  # the step raised, or returned the wrong type
    TIMEOUT = "timeout"  # the step ran past --step-timeout (its worker was restarted)
    SKIPPED = "skipped"  # not run: a required upstream output or input was missing


# bound once: run_step is on the per-frame path (an enum member lookup is a descriptor call)
_OK, _ERROR = StepStatus.OK, StepStatus.ERROR
_thread_time_ns, _perf_counter_ns = time.thread_time_ns, time.perf_counter_ns


@dataclass(frozen=True, slots=True, kw_only=True)
class StepError:
    """Why a step failed: exception type, message and formatted traceback."""

    type: str
    message: str
    traceback: str = ""

    @classmethod
    def from_exception(cls, err: BaseException) -> StepError:
        tb = "".join(traceback.format_exception(type(err), err, err.__traceback__))
        return cls(type=type(err).__name__, message=str(err), traceback=tb)


@dataclass(frozen=True, slots=True, kw_only=True)
class StepResult:
    """One algorithm on one frame.

    Attributes:
        status: what happened.
        output: the checked output (None unless OK).
        latency_ns: wall time of ``step``, int ns (monotonic clock).
        cpu_ns: CPU time of the thread that ran ``step``, int ns.
        error: set unless OK.
    """

    status: StepStatus
    output: AlgorithmOutput | None = None
    latency_ns: int = 0
    cpu_ns: int = 0
    error: StepError | None = None


class Algorithm(ABC):
    """Base of every perception, planning and control algorithm.

    Subclasses set the class attributes and implement :meth:`step`; :meth:`setup` and
    :meth:`reset` are optional.

    Class attributes:
        role: the stage kind, which fixes the output type.
        inputs: what ``step`` reads from the frame (see :data:`Input`); checked before a run.
        version: the algorithm's own version string, recorded in the run manifest.
        defaults: default configuration; the run's config is laid over it and handed to
            :meth:`setup`.
        upstream: the role whose outputs ``step`` needs from earlier stages (a tracker:
            ``Role.PERCEPTION``, the detections it tracks), None when it needs none; a run that
            skips the stages a log cannot feed skips it too when no earlier stage of that role
            runs.
    """

    role: ClassVar[Role]
    inputs: ClassVar[tuple[Input, ...]] = ()
    upstream: ClassVar[Role | None] = None
    version: ClassVar[str] = "0"
    defaults: ClassVar[Mapping[str, Any]] = MappingProxyType({})

    def __init__(self, *, name: str | None = None) -> None:
        self.name = name or type(self).__name__
        self.config: Mapping[str, Any] = MappingProxyType(dict(self.defaults))
        self.bound_inputs: Mapping[Input, str] = MappingProxyType({})
        #: the log's road map (lanes, stop lines, traffic lights; map frame), None when the log
        #: has none — set by :meth:`use_road_map` before the first frame
        self.road_map: RoadMap | None = None
        #: the run's mission (the route along the lane graph and the logged ego trajectory),
        #: None when it has none — set by :meth:`use_mission` before the first frame
        self.mission: Mission | None = None

    # -- what a researcher writes -------------------------------------------------------------

    def setup(self, config: Mapping[str, Any]) -> None:  # noqa: B027 - optional hook
        """Called once per run with the algorithm's configuration (defaults + user's)."""

    @abstractmethod
    def step(self, frame: Frame, upstream: StageOutputs) -> Any:
        """Process one frame; return the output of :attr:`role`."""

    def reset(self) -> None:  # noqa: B027 - optional hook
        """Forget all state (between runs, and after a worker restart)."""

    def use_road_map(self, road_map: RoadMap | None) -> None:
        """Called once before the first frame with the log's road map (None: it has none); keeps
        it as :attr:`road_map`.  Override (calling this) to prepare what the steps look up."""
        self.road_map = road_map

    def use_mission(self, mission: Mission | None) -> None:
        """Called once before the first frame with the run's mission (None: it has none — only
        a closed loop on a recorded log with a road map has one, nuPlan's
        ``PlannerInitialization``); keeps it as :attr:`mission`.  Override (calling this) to
        prepare what the steps look up."""
        self.mission = mission

    # -- what the engine calls ----------------------------------------------------------------

    def configure(self, config: Mapping[str, Any] | None = None) -> None:
        """Lay ``config`` over :attr:`defaults`, refuse unknown keys, then :meth:`setup`."""
        merged = dict(self.defaults)
        user = dict(config or {})
        if self.defaults:
            # "<type>_sensor" (e.g. lidar_sensor) picks the sensor of a SensorType input
            pickers = {f"{i.value}_sensor" for i in self.inputs if isinstance(i, SensorType)}
            unknown = sorted(set(user) - set(self.defaults) - pickers)
            if unknown:
                msg = (
                    f"algorithm {self.name!r}: unknown config key(s) {', '.join(unknown)}; "
                    f"known: {', '.join(sorted(self.defaults))}"
                )
                raise ConfigError(msg)
        merged.update(user)
        self.config = MappingProxyType(merged)
        self.setup(self.config)

    def bind(self, sensors: Mapping[str, SensorType], *, extras: Iterable[str] = ()) -> None:
        """Resolve :attr:`inputs` against a log's sensors before a run.

        Args:
            sensors: sensor id → type, for the log being replayed.
            extras: which of :data:`VEHICLE_STATE` / :data:`GROUND_TRUTH` / :data:`ROAD_MAP` the
                log provides.

        Raises:
            MissingInputError: an input is not in the log (the message lists what is).
        """
        have = set(extras)
        bound: dict[Input, str] = {}
        for wanted in self.inputs:
            if isinstance(wanted, SensorType):
                ids = sorted(s for s, t in sensors.items() if t is wanted)
                chosen = self.config.get(f"{wanted.value}_sensor")
                if isinstance(chosen, str) and chosen in ids:
                    bound[wanted] = chosen
                elif ids and chosen is None:
                    bound[wanted] = ids[0]
                else:
                    missing = f"a {wanted.name} sensor" + (f" {chosen!r}" if chosen else "")
                    self._missing(missing, sensors, have)
            elif wanted in (VEHICLE_STATE, GROUND_TRUTH, ROAD_MAP):
                if wanted not in have:
                    self._missing(wanted.replace("_", " "), sensors, have)
                bound[wanted] = wanted
            elif wanted in sensors:
                bound[wanted] = wanted
            else:
                self._missing(f"sensor {wanted!r}", sensors, have)
        self.bound_inputs = MappingProxyType(bound)

    def _missing(self, what: str, sensors: Mapping[str, SensorType], have: set[str]) -> None:
        listing = ", ".join(f"{s} ({t.name})" for s, t in sorted(sensors.items())) or "none"
        extra = ", ".join(sorted(have)) or "no ego state or ground truth"
        advice = (
            "give it a log that carries one (a redrive synth log or a scenario does)"
            if what == "road map"
            else "map a topic with a sensor map file"
        )
        msg = (
            f"algorithm {self.name!r} needs {what}, which this log does not have "
            f"(sensors: {listing}; also {extra}); {advice} or pick another algorithm"
        )
        raise MissingInputError(msg)

    def sensor(self, frame: Frame, wanted: Input) -> SensorData:
        """The sample of input ``wanted`` in ``frame`` (a sensor id or type from :attr:`inputs`).

        Raises:
            AlgorithmError: the frame has no sample of it (the sensor dropped out here).
        """
        sensor_id = self.bound_inputs.get(wanted)
        if sensor_id is None and isinstance(wanted, str):
            sensor_id = wanted
        if sensor_id is None:
            msg = f"algorithm {self.name!r}: {wanted!r} is not among its inputs"
            raise AlgorithmError(msg)
        data = frame.sensors.get(sensor_id)
        if data is None:
            msg = f"frame {frame.index} (stamp {frame.stamp_ns} ns) has no {sensor_id!r} sample"
            raise AlgorithmError(msg)
        return data

    def run_step(self, frame: Frame, upstream: StageOutputs) -> StepResult:
        """Time :meth:`step`, check its output, and turn an exception into a recorded error."""
        status, output, latency_ns, cpu_ns, error = self.timed_step(frame, upstream)
        return StepResult(
            status=status, output=output, latency_ns=latency_ns, cpu_ns=cpu_ns, error=error
        )

    def timed_step(
        self, frame: Frame, upstream: StageOutputs
    ) -> tuple[StepStatus, AlgorithmOutput | None, int, int, StepError | None]:
        """:meth:`run_step` as a plain tuple ``(status, output, latency_ns, cpu_ns, error)``:
        what the engine calls on every frame (no result object to build and take apart)."""
        cpu0 = _thread_time_ns()
        status, output, latency_ns, cpu1, error = self.timed_step_from(frame, upstream, cpu0)
        return status, output, latency_ns, cpu1 - cpu0, error

    def timed_step_from(
        self, frame: Frame, upstream: StageOutputs, cpu0_ns: int
    ) -> tuple[StepStatus, AlgorithmOutput | None, int, int, StepError | None]:
        """:meth:`timed_step` reading the thread CPU clock once, after the step: ``cpu0_ns`` is
        the reading the caller already has (the end of the previous step of a sequential run),
        and the fourth item is the clock at the end of this step, not a difference.

        The thread CPU clock is a system call (≈ 1 µs, far more in wall time on a loaded
        machine); chaining the readings of consecutive steps halves them.  The CPU time between
        two readings then also holds the engine's hand-off into this step (≈ 1 µs).
        """
        t0 = _perf_counter_ns()
        try:
            value = self.step(frame, upstream)
        except Exception as err:  # recorded, never swallowed: the engine stores it per frame
            t1 = _perf_counter_ns()
            return _ERROR, None, t1 - t0, _thread_time_ns(), StepError.from_exception(err)
        t1 = _perf_counter_ns()
        cpu1 = _thread_time_ns()
        # the common outputs checked inline (check_output says the same, one call later)
        kind, role = type(value), self.role
        if (
            (kind is PlannedPath and role is _PLANNING)
            or (kind is ControlCommands and role is _CONTROL)
            or (kind is tuple and role is _PERCEPTION and not value)
        ):
            return _OK, value, t1 - t0, cpu1, None
        try:
            output = check_output(role, value, where=self.name)
        except AlgorithmError as err:
            error = StepError(type=type(err).__name__, message=f"frame {frame.index}: {err}")
            return _ERROR, None, t1 - t0, cpu1, error
        return _OK, output, t1 - t0, cpu1, None

    @classmethod
    def describe(cls) -> str:
        """The first paragraph of the class docstring, as one line of plain text."""
        from redrive.output.text import doc_summary

        return doc_summary(cls.__doc__)

    @classmethod
    def input_names(cls) -> Sequence[str]:
        return [i.name.lower() if isinstance(i, SensorType) else i for i in cls.inputs]
