"""What the engine hands the results store: one record per frame, one per algorithm step.

These are plain frozen dataclasses of the data model's types; the store turns them into the
tables of a run directory (see :mod:`redrive.results`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from redrive.types import (
    ControlCommands,
    DetectedObject,
    PlannedPath,
    Role,
    TrafficLight,
    VehicleState,
)

__all__ = [
    "ROLES",
    "STATUSES",
    "ClosedLoopRecord",
    "FrameRecord",
    "ResourceSample",
    "StepOutput",
    "StepRecord",
    "frame_record_unchecked",
    "step_record_unchecked",
    "with_closed_loop_unchecked",
]

#: the values of ``StepRecord.role`` (the :class:`~redrive.types.Role` values).
ROLES = tuple(role.value for role in Role)
#: the values of ``StepRecord.status`` (``redrive.algorithms.StepStatus`` values).
STATUSES = ("ok", "error", "timeout", "skipped")

StepOutput = tuple[DetectedObject, ...] | PlannedPath | ControlCommands

_OUTPUT_TYPES: dict[str, type] = {
    "perception": tuple,
    "planning": PlannedPath,
    "control": ControlCommands,
}


@dataclass(frozen=True, slots=True, kw_only=True)
class StepRecord:
    """One algorithm on one frame.

    Attributes:
        algorithm: the algorithm's unique name in the run.
        stage: the name of the stage it ran in.
        role: ``"perception"``, ``"planning"`` or ``"control"``; fixes the type of ``output``.
        status: ``"ok"``, ``"error"``, ``"timeout"`` or ``"skipped"``.
        latency_ns: wall time of the step, int ns.
        cpu_ns: CPU time of the step, int ns.
        output: objects (perception; a list is accepted and stored as a tuple), a
            :class:`PlannedPath` (planning) or :class:`ControlCommands` (control); None when
            the step produced nothing.
        error_type, error_message, traceback: why the step failed; empty when it did not.
    """

    algorithm: str
    stage: str
    role: str
    status: str
    latency_ns: int = 0
    cpu_ns: int = 0
    output: StepOutput | None = None
    error_type: str = ""
    error_message: str = ""
    traceback: str = ""

    def __post_init__(self) -> None:
        output = self.output
        if (
            type(output) is _OUTPUT_TYPES.get(self.role)
            and self.status in STATUSES
            and type(self.latency_ns) is int
            and type(self.cpu_ns) is int
            and (type(output) is not tuple or all(type(o) is DetectedObject for o in output))
        ):
            return  # the engine's records: already what they must be (the per-frame path)
        if self.role not in ROLES:
            msg = f"StepRecord {self.algorithm!r}: role {self.role!r} is not one of {ROLES}"
            raise ValueError(msg)
        if self.status not in STATUSES:
            msg = f"StepRecord {self.algorithm!r}: status {self.status!r} is not one of {STATUSES}"
            raise ValueError(msg)
        if isinstance(output, list):
            output = tuple(output)
            object.__setattr__(self, "output", output)
        if output is not None:
            want = _OUTPUT_TYPES[self.role]
            ok = isinstance(output, want)
            if ok and isinstance(output, tuple):
                ok = all(isinstance(obj, DetectedObject) for obj in output)
            if not ok:
                msg = (
                    f"StepRecord {self.algorithm!r}: a {self.role} step's output must be "
                    f"{'a tuple of DetectedObject' if want is tuple else want.__name__}, "
                    f"got {type(output).__name__}"
                )
                raise ValueError(msg)
        object.__setattr__(self, "latency_ns", int(self.latency_ns))
        object.__setattr__(self, "cpu_ns", int(self.cpu_ns))

    @property
    def n_outputs(self) -> int:
        """Objects for perception; 1 for a path or commands; 0 when there is no output."""
        if self.output is None:
            return 0
        if isinstance(self.output, tuple):
            return len(self.output)
        return 1


@dataclass(frozen=True, slots=True, kw_only=True)
class ClosedLoopRecord:
    """What moved the ego after one closed-loop frame, and how far it was from the logged ego.

    Attributes:
        source: ``control`` (a control stage's command), ``tracker`` (the built-in tracker on
            the planned path) or ``fallback`` (an emergency brake).
        algorithm: the algorithm whose output was used ("" for the fallback).
        reason: why the fallback braked ("" otherwise).
        throttle, brake, steering_angle_rad: the command applied.
        deviation_m: distance of the driven from the logged ego (NaN without a logged ego).
        deviation_yaw_rad: |heading difference| of the two (NaN without a logged ego).
        deviated: either deviation passed its threshold (the run manifest's ``closed_loop``
            says which: default 2 m / 10°); None without a logged ego.
        collisions: how many ground-truth objects the ego's footprint touched in this frame.
        collision_object_id, collision_object_class: the one of them with the lowest id (its
            class value, e.g. ``vehicle``); None and "" when it touched none.
    """

    source: str
    algorithm: str = ""
    reason: str = ""
    throttle: float = 0.0
    brake: float = 0.0
    steering_angle_rad: float = 0.0
    deviation_m: float = math.nan
    deviation_yaw_rad: float = math.nan
    deviated: bool | None = None
    collisions: int = 0
    collision_object_id: int | None = None
    collision_object_class: str = ""


@dataclass(frozen=True, slots=True, kw_only=True)
class FrameRecord:
    """Everything one frame produced.

    Attributes:
        frame_index: the frame's 0-based index in the log (``Frame.index``); unique in a run.
        stamp_ns: the frame's stamp, int ns since the epoch.
        steps: one record per algorithm that was scheduled on this frame.
        vehicle_state: the frame's ego state (frame ``map``/``odom``), if the log has one.
        logged_vehicle_state: the ego state the log recorded for this frame when the driven
            ego differs from it (closed loop: the expert the closed-loop metrics compare
            progress against); None in open loop, where ``vehicle_state`` is the logged one.
        closed_loop: closed loop only: what moved the ego after this frame.
        ground_truth: the frame's ground-truth objects (``Frame.ground_truth``), None when the
            log carries none (an empty tuple means "ground truth: nothing there").
        wall_ns: wall time the engine spent on the whole frame, int ns.
        late: real-time pacing only: the frame was processed after its due time.
        missing: the frame's inputs with no sample within the tolerance (``Frame.missing``).
        traffic_lights: the traffic lights' states of the frame (``Frame.traffic``); empty
            when the log has none.
    """

    frame_index: int
    stamp_ns: int
    steps: tuple[StepRecord, ...]
    vehicle_state: VehicleState | None = None
    logged_vehicle_state: VehicleState | None = None
    closed_loop: ClosedLoopRecord | None = None
    ground_truth: tuple[DetectedObject, ...] | None = None
    wall_ns: int = 0
    late: bool = False
    missing: tuple[str, ...] = ()
    traffic_lights: tuple[TrafficLight, ...] = ()

    def __post_init__(self) -> None:
        index = int(self.frame_index)
        if index < 0:
            msg = f"FrameRecord.frame_index must be >= 0, got {index}"
            raise ValueError(msg)
        object.__setattr__(self, "frame_index", index)
        object.__setattr__(self, "stamp_ns", int(self.stamp_ns))
        object.__setattr__(self, "wall_ns", int(self.wall_ns))
        object.__setattr__(self, "late", bool(self.late))
        steps = tuple(self.steps)
        names = [s.algorithm for s in steps]
        if len(set(names)) != len(names):
            msg = f"FrameRecord {index}: an algorithm appears twice in steps ({names})"
            raise ValueError(msg)
        object.__setattr__(self, "steps", steps)
        if self.ground_truth is not None:
            object.__setattr__(self, "ground_truth", tuple(self.ground_truth))
        object.__setattr__(self, "traffic_lights", tuple(self.traffic_lights))


@dataclass(frozen=True, slots=True, kw_only=True)
class ResourceSample:
    """One sample of a process's resource use.

    Attributes:
        t_ns: when it was taken, int ns since the epoch.
        label: what the process is (``engine``, ``worker:detector`` …).
        pid: its process id.
        cpu_percent: CPU use since the previous sample, percent of one core.
        rss_bytes: resident memory, bytes.
    """

    t_ns: int
    label: str
    pid: int
    cpu_percent: float
    rss_bytes: int


# -- the engine's per-frame path -------------------------------------------------------------
# A frozen dataclass's __init__ sets every field through object.__setattr__ and then runs
# __post_init__; for records whose fields the engine has already made what they must be, that
# was a third of its own cost per frame.  The functions below fill an instance of a plain
# builder class with the record's own slots (same names, same order, so the same memory layout)
# with ordinary attribute stores, then make it the record by assigning ``__class__`` — a layout
# check CPython does in C.  That is one call per record instead of one descriptor ``__set__``
# call per field (≈ 6 k instead of ≈ 12 k instructions a step record, callgrind); the result is
# an ordinary record, equal to what the checked constructors make.  They are for callers that
# guarantee the invariants.

assert StepRecord.__slots__ == (
    "algorithm", "stage", "role", "status", "latency_ns", "cpu_ns", "output",
    "error_type", "error_message", "traceback",
)  # fmt: skip
assert FrameRecord.__slots__ == (
    "frame_index", "stamp_ns", "steps", "vehicle_state", "logged_vehicle_state", "closed_loop",
    "ground_truth", "wall_ns", "late", "missing", "traffic_lights",
)  # fmt: skip


class _StepBuilder:
    __slots__ = StepRecord.__slots__
    algorithm: str
    stage: str
    role: str
    status: str
    latency_ns: int
    cpu_ns: int
    output: StepOutput | None
    error_type: str
    error_message: str
    traceback: str


class _FrameBuilder:
    __slots__ = FrameRecord.__slots__
    frame_index: int
    stamp_ns: int
    steps: tuple[StepRecord, ...]
    vehicle_state: VehicleState | None
    logged_vehicle_state: VehicleState | None
    closed_loop: ClosedLoopRecord | None
    ground_truth: tuple[DetectedObject, ...] | None
    wall_ns: int
    late: bool
    missing: tuple[str, ...]
    traffic_lights: tuple[TrafficLight, ...]


def step_record_unchecked(  # noqa: PLR0917 (per step: positional is cheaper)
    algorithm: str,
    stage: str,
    role: str,
    status: str,
    latency_ns: int,
    cpu_ns: int,
    output: StepOutput | None,
    error_type: str = "",
    error_message: str = "",
    traceback: str = "",
) -> StepRecord:
    """A :class:`StepRecord` without its checks (positional: this is called per step).

    The caller guarantees what ``__post_init__`` would check: ``role`` in :data:`ROLES`,
    ``status`` in :data:`STATUSES`, int times, and ``output`` None or of the role's type (a
    tuple of :class:`DetectedObject` for perception).
    """
    record = _StepBuilder()
    record.algorithm = algorithm
    record.stage = stage
    record.role = role
    record.status = status
    record.latency_ns = latency_ns
    record.cpu_ns = cpu_ns
    record.output = output
    record.error_type = error_type
    record.error_message = error_message
    record.traceback = traceback
    record.__class__ = StepRecord  # type: ignore[assignment]
    return record  # type: ignore[return-value]


def frame_record_unchecked(  # noqa: PLR0917 (per frame: positional is cheaper)
    frame_index: int,
    stamp_ns: int,
    steps: tuple[StepRecord, ...],
    vehicle_state: VehicleState | None,
    ground_truth: tuple[DetectedObject, ...] | None,
    wall_ns: int,
    late: bool,
    missing: tuple[str, ...],
    traffic_lights: tuple[TrafficLight, ...] = (),
) -> FrameRecord:
    """A :class:`FrameRecord` of an open-loop frame without its checks (called per frame).

    The caller guarantees int index ≥ 0, stamp and wall time, a bool ``late``, tuples, and
    steps of distinct algorithms.
    """
    record = _FrameBuilder()
    record.frame_index = frame_index
    record.stamp_ns = stamp_ns
    record.steps = steps
    record.vehicle_state = vehicle_state
    record.logged_vehicle_state = None
    record.closed_loop = None
    record.ground_truth = ground_truth
    record.wall_ns = wall_ns
    record.late = late
    record.missing = missing
    record.traffic_lights = traffic_lights
    record.__class__ = FrameRecord  # type: ignore[assignment]
    return record  # type: ignore[return-value]


def with_closed_loop_unchecked(
    record: FrameRecord, logged: VehicleState | None, closed_loop: ClosedLoopRecord
) -> FrameRecord:
    """``dataclasses.replace(record, logged_vehicle_state=logged, closed_loop=closed_loop)``
    without its checks (called per frame: ``record`` was checked or built by the engine, and
    the two fields take any value of their types)."""
    copy = _FrameBuilder()
    copy.frame_index = record.frame_index
    copy.stamp_ns = record.stamp_ns
    copy.steps = record.steps
    copy.vehicle_state = record.vehicle_state
    copy.logged_vehicle_state = logged
    copy.closed_loop = closed_loop
    copy.ground_truth = record.ground_truth
    copy.wall_ns = record.wall_ns
    copy.late = record.late
    copy.missing = record.missing
    copy.traffic_lights = record.traffic_lights
    copy.__class__ = FrameRecord  # type: ignore[assignment]
    return copy  # type: ignore[return-value]
