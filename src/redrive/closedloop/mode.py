"""The Mode Manager's ``CLOSED_LOOP`` mode: frames come from a simulator that the outputs move.

The engine calls :meth:`ClosedLoopMode.before_frame` for the frames to process and
:meth:`ClosedLoopMode.after_frame` with each finished frame's record (see
:mod:`redrive.engine.modes`).  Here the frames are :meth:`ClosedLoopMode.frames`: each one is the
simulator's observation *after* the previous frame's outputs were applied, so the engine must run
the stages of one frame before it asks for the next — sequential mode (the pipelined engine reads
ahead and is refused).

``after_frame`` applies the outputs (the simulator steps) and then hands the frame's record —
completed with the logged ego, what moved the car and what the ego touched
(:class:`~redrive.results.ClosedLoopRecord`) — to ``write``: a closed-loop frame is stored once
its consequence is known.

Collisions (:mod:`redrive.closedloop.contact`): every frame, the objects of its ground truth the
ego footprint touches are recorded (``collisions``, ``collision_object_id`` / ``_class``).
``on_collision="continue"`` (nuPlan's behaviour) drives on; ``"stop"`` ends the run after the
first frame with a collision, and :meth:`ClosedLoopMode.collision_summary` says why it ended.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from redrive.algorithms import StageOutputs, StepStatus
from redrive.closedloop.contact import ON_COLLISION, Contact, check_on_collision, contacts
from redrive.closedloop.simulator import EgoCommand, Simulator
from redrive.engine.modes import Mode, PacedFrame
from redrive.results import ClosedLoopRecord, FrameRecord
from redrive.results.records import with_closed_loop_unchecked
from redrive.sim.ego import EgoGeometry
from redrive.types import Frame, Role, VehicleState

__all__ = [
    "DEFAULT_DEVIATION_M",
    "DEFAULT_DEVIATION_RAD",
    "ON_COLLISION",
    "ClosedLoopMode",
    "ClosedLoopStep",
]

_OK = StepStatus.OK.value
#: a step record's role (its value) → the Role
_ROLES = {r.value: r for r in Role}

#: a frame whose driven ego is farther than this from the logged one is flagged ``deviated``.
DEFAULT_DEVIATION_M = 2.0
DEFAULT_DEVIATION_RAD = math.radians(10.0)


@dataclass(frozen=True, slots=True, kw_only=True)
class ClosedLoopStep:
    """One frame of a closed-loop run, as the simulator saw it.

    Attributes:
        frame_index: the frame.
        stamp_ns: its stamp.
        driven: the ego state of the frame (the closed-loop ego).
        logged: the logged (expert) ego state at the same time, if the backend has one.
        command: what moved the ego after the frame.
        collisions: the ground-truth objects the ego's footprint touched in the frame, by id.
    """

    frame_index: int
    stamp_ns: int
    driven: VehicleState | None
    logged: VehicleState | None
    command: EgoCommand
    collisions: tuple[Contact, ...] = ()

    @property
    def deviation(self) -> tuple[float, float]:
        """Distance (m) and |heading difference| (rad) of the driven from the logged ego; NaN
        without a logged ego."""
        a, b = self.driven, self.logged
        if a is None or b is None:
            return math.nan, math.nan
        dist = math.hypot(
            float(a.position[0] - b.position[0]), float(a.position[1] - b.position[1])
        )
        return dist, abs(math.remainder(a.heading_rad - b.heading_rad, math.tau))

    def deviated(
        self,
        *,
        threshold_m: float = DEFAULT_DEVIATION_M,
        threshold_rad: float = DEFAULT_DEVIATION_RAD,
    ) -> bool | None:
        """Whether the driven ego is farther than ``threshold_m`` or turned more than
        ``threshold_rad`` from the logged one; None without a logged ego."""
        dist, dyaw = self.deviation
        if math.isnan(dist):
            return None
        return dist > threshold_m or dyaw > threshold_rad

    def record(
        self,
        *,
        threshold_m: float = DEFAULT_DEVIATION_M,
        threshold_rad: float = DEFAULT_DEVIATION_RAD,
    ) -> ClosedLoopRecord:
        """What the run directory stores of this step (flagged ``deviated`` past either
        threshold)."""
        dist, dyaw = self.deviation
        command = self.command
        deviated = None if math.isnan(dist) else (dist > threshold_m or dyaw > threshold_rad)
        return ClosedLoopRecord(
            source=command.source,
            algorithm=command.algorithm,
            reason=command.reason,
            throttle=command.commands.throttle,
            brake=command.commands.brake,
            steering_angle_rad=command.commands.steering_angle_rad,
            deviation_m=dist,
            deviation_yaw_rad=dyaw,
            deviated=deviated,  # as deviated() says, from the deviation computed once
            collisions=len(self.collisions),
            collision_object_id=self.collisions[0].object_id if self.collisions else None,
            collision_object_class=self.collisions[0].object_class if self.collisions else "",
        )


class ClosedLoopMode:
    """Closed loop over ``simulator``, at most ``max_frames`` frames (None: until it is done);
    every finished frame's completed record goes to ``write`` (the run writer).  A frame farther
    than ``deviation_threshold_m`` or ``deviation_threshold_rad`` from the logged ego is flagged
    ``deviated`` (:meth:`deviation_summary` counts them).  Collisions are those of the ego
    footprint of ``ego_geometry``; ``on_collision`` is ``continue`` or ``stop`` (module text).
    """

    mode = Mode.CLOSED_LOOP

    def __init__(
        self,
        simulator: Simulator,
        *,
        write: Callable[[FrameRecord], None],
        max_frames: int | None = None,
        deviation_threshold_m: float = DEFAULT_DEVIATION_M,
        deviation_threshold_rad: float = DEFAULT_DEVIATION_RAD,
        ego_geometry: EgoGeometry | None = None,
        on_collision: str = ON_COLLISION[0],
    ) -> None:
        check_on_collision(on_collision)
        self.ego_geometry = ego_geometry if ego_geometry is not None else EgoGeometry()
        self.on_collision = on_collision
        #: with ``on_collision="stop"``: the step whose collision ended the run
        self.stopped_at: ClosedLoopStep | None = None
        self.simulator = simulator
        self.deviation_threshold_m = float(deviation_threshold_m)
        self.deviation_threshold_rad = float(deviation_threshold_rad)
        self.write = write
        self.max_frames = max_frames
        self.late_frames = 0
        #: frame index → what happened in it, in order
        self.steps: list[ClosedLoopStep] = []
        self._observed: dict[int, tuple[Frame, VehicleState | None]] = {}
        self._stepped = True

    def frames(self) -> Iterator[Frame]:
        """The simulator's observations, each after the previous frame's outputs moved the ego."""
        count = 0
        while self.max_frames is None or count < self.max_frames:
            if not self._stepped:
                msg = (
                    "closed loop: the next frame was asked for before the outputs of the last "
                    "one were applied; closed loop runs the stages sequentially"
                )
                raise RuntimeError(msg)
            frame = self.simulator.observe()
            self._observed[frame.index] = (frame, self.simulator.logged_state)
            self._stepped = False
            yield frame
            count += 1
            if self.simulator.done or self.stopped_at is not None:
                return

    def before_frame(self, frames: Iterable[Frame]) -> Iterator[PacedFrame]:
        for frame in frames:
            yield PacedFrame(frame, False)

    def after_frame(self, record: FrameRecord) -> None:
        frame, logged = self._observed.pop(record.frame_index)
        ok = _OK
        outputs = StageOutputs(
            outputs={
                s.algorithm: s.output
                for s in record.steps
                if s.status == ok and s.output is not None
            },
            roles={s.algorithm: _ROLES[s.role] for s in record.steps},
        )
        command = self.simulator.step(outputs, self.simulator.dt_s)
        self._stepped = True
        step = ClosedLoopStep(
            frame_index=record.frame_index,
            stamp_ns=record.stamp_ns,
            driven=frame.vehicle_state,
            logged=logged,
            command=command,
            collisions=contacts(frame, self.ego_geometry),
        )
        self.steps.append(step)
        if step.collisions and self.on_collision == "stop" and self.stopped_at is None:
            self.stopped_at = step
        closed_loop = step.record(
            threshold_m=self.deviation_threshold_m, threshold_rad=self.deviation_threshold_rad
        )
        # dataclasses.replace, without the checks of a record the engine built
        self.write(with_closed_loop_unchecked(record, logged, closed_loop))

    def deviation_summary(self) -> dict[str, Any]:
        """For the run summary: the thresholds, how many frames passed them, the first such
        frame and the largest deviations."""
        flags = [
            (
                s.frame_index,
                s.deviated(
                    threshold_m=self.deviation_threshold_m,
                    threshold_rad=self.deviation_threshold_rad,
                ),
            )
            for s in self.steps
        ]
        flagged = [i for i, f in flags if f]
        dists = [s.deviation for s in self.steps if not math.isnan(s.deviation[0])]
        return {
            "deviation_threshold_m": self.deviation_threshold_m,
            "deviation_threshold_rad": self.deviation_threshold_rad,
            "deviated_frames": len(flagged),
            "first_deviated_frame": flagged[0] if flagged else None,
            "max_deviation_m": max((d for d, _ in dists), default=None),
            "max_deviation_yaw_rad": max((y for _, y in dists), default=None),
        }

    def collision_summary(self) -> dict[str, Any]:
        """For the run summary: ``on_collision``, how many frames had the ego touching an
        object, the first of them and — ``stop`` — why and where the run ended."""
        hit = [s for s in self.steps if s.collisions]
        stopped = self.stopped_at
        ended: dict[str, Any] | None = None
        if stopped is not None:
            first = stopped.collisions[0]
            ended = {
                "reason": "collision",
                "frame_index": stopped.frame_index,
                "stamp_ns": stopped.stamp_ns,
                "object_id": first.object_id,
                "object_class": first.object_class,
                "detail": (
                    f"--on-collision stop: the ego touched {first.object_class} "
                    f"{first.object_id} in frame {stopped.frame_index}"
                ),
            }
        return {
            "on_collision": self.on_collision,
            "collision_frames": len(hit),
            "first_collision_frame": hit[0].frame_index if hit else None,
            "stopped": ended,
        }
