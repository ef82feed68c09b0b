"""The Mode Manager's ``CLOSED_LOOP`` mode: frames come from a simulator that the outputs move.

The engine calls :meth:`ClosedLoopMode.before_frame` for the frames to process and
:meth:`ClosedLoopMode.after_frame` with each finished frame's record (see
:mod:`redrive.engine.modes`).  Here the frames are :meth:`ClosedLoopMode.frames`: each one is the
simulator's observation *after* the previous frame's outputs were applied, so the engine must run
the stages of one frame before it asks for the next — sequential mode (the pipelined engine reads
ahead and is refused).

``after_frame`` applies the outputs (the simulator steps) and then hands the frame's record —
completed with the logged ego and what moved the car (:class:`~redrive.results.ClosedLoopRecord`)
— to ``write``: a closed-loop frame is stored once its consequence is known.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from redrive.algorithms import StageOutputs, StepStatus
from redrive.closedloop.simulator import EgoCommand, Simulator
from redrive.engine.modes import Mode, PacedFrame
from redrive.results import ClosedLoopRecord, FrameRecord
from redrive.types import Frame, Role, VehicleState

__all__ = ["DEFAULT_DEVIATION_M", "DEFAULT_DEVIATION_RAD", "ClosedLoopMode", "ClosedLoopStep"]

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
    """

    frame_index: int
    stamp_ns: int
    driven: VehicleState | None
    logged: VehicleState | None
    command: EgoCommand

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
        )


class ClosedLoopMode:
    """Closed loop over ``simulator``, at most ``max_frames`` frames (None: until it is done);
    every finished frame's completed record goes to ``write`` (the run writer).  A frame farther
    than ``deviation_threshold_m`` or ``deviation_threshold_rad`` from the logged ego is flagged
    ``deviated`` (:meth:`deviation_summary` counts them)."""

    mode = Mode.CLOSED_LOOP

    def __init__(
        self,
        simulator: Simulator,
        *,
        write: Callable[[FrameRecord], None],
        max_frames: int | None = None,
        deviation_threshold_m: float = DEFAULT_DEVIATION_M,
        deviation_threshold_rad: float = DEFAULT_DEVIATION_RAD,
    ) -> None:
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
            if self.simulator.done:
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
        )
        self.steps.append(step)
        self.write(
            dataclasses.replace(
                record,
                logged_vehicle_state=logged,
                closed_loop=step.record(
                    threshold_m=self.deviation_threshold_m,
                    threshold_rad=self.deviation_threshold_rad,
                ),
            )
        )

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
