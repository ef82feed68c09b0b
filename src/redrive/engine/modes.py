"""The Mode Manager: where frames come from and how fast they are released.

- ``REPLAY``: frames from a log, every frame processed in order.  As fast as possible
  (``rate=None``), or paced at a real-time factor (``rate=1.0`` is real time, ``2.0`` twice as
  fast): a frame is released at ``start + (stamp - first stamp) / rate``; a frame that could only be
  released more than ``late_slack_s`` after that instant — because processing fell behind — is
  counted as *late*, and still processed (replay never drops frames silently).
- ``REALTIME`` (live ROS topics) and ``CLOSED_LOOP`` (commands fed back into the simulator) use
  the same two hooks — :meth:`ModeHooks.before_frame` to take or wait for the next frame and
  :meth:`ModeHooks.after_frame` to act on the outputs — and arrive with the live sources.
"""

from __future__ import annotations

import enum
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Protocol

from redrive.errors import ConfigError
from redrive.results import FrameRecord
from redrive.types import Frame

__all__ = ["Mode", "ModeHooks", "PacedFrame", "ReplayMode", "mode_hooks"]


class Mode(enum.Enum):
    REPLAY = "replay"
    REALTIME = "realtime"
    CLOSED_LOOP = "closed_loop"


@dataclass(frozen=True, slots=True)
class PacedFrame:
    """A frame as released to the stages, and whether it came later than its due time."""

    frame: Frame
    late: bool


class ModeHooks(Protocol):
    """What a mode plugs into the engine."""

    mode: Mode

    def before_frame(self, frames: Iterable[Frame]) -> Iterator[PacedFrame]:
        """Release the frames to process, in order (pacing, waiting for live data …)."""
        ...

    def after_frame(self, record: FrameRecord) -> None:
        """Called with each finished frame's record, in order (closed loop acts on it here)."""
        ...


class ReplayMode:
    """Replay from a log: as fast as possible, or paced at a real-time factor.

    Args:
        rate: real-time factor (1.0 = real time); None for as fast as possible.
        late_slack_s: how far past its due time a frame may be released and not count as late.
    """

    mode = Mode.REPLAY

    def __init__(self, *, rate: float | None = None, late_slack_s: float = 0.005) -> None:
        if rate is not None and not rate > 0:
            msg = f"--rate must be a positive real-time factor, got {rate}"
            raise ConfigError(msg)
        self.rate = rate
        self.late_slack_ns = int(late_slack_s * 1e9)
        self.late_frames = 0

    def before_frame(self, frames: Iterable[Frame]) -> Iterator[PacedFrame]:
        if self.rate is None:
            for frame in frames:
                yield PacedFrame(frame, False)
            return
        wall0 = stamp0 = None
        for frame in frames:
            now = time.perf_counter_ns()
            if wall0 is None or stamp0 is None:
                wall0, stamp0 = now, frame.stamp_ns
            due = wall0 + int((frame.stamp_ns - stamp0) / self.rate)
            if now < due:
                time.sleep((due - now) / 1e9)
                late = False
            else:
                late = now - due > self.late_slack_ns
            self.late_frames += late
            yield PacedFrame(frame, late)

    def after_frame(self, record: FrameRecord) -> None:
        pass


def mode_hooks(mode: Mode | str, *, rate: float | None = None) -> ModeHooks:
    """The hooks of ``mode``."""
    mode = Mode(mode)
    if mode is Mode.REPLAY:
        return ReplayMode(rate=rate)
    msg = (
        f"mode {mode.value} needs live sources or a simulator in the loop, which this version "
        "of redrive does not have yet; replay a log instead"
    )
    raise ConfigError(msg)
