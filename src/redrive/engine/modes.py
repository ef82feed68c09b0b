"""The Mode Manager: where frames come from and how fast they are released.

- ``REPLAY``: frames from a log, every frame processed in order.  As fast as possible
  (``rate=None``), or paced at a real-time factor (``rate=1.0`` is real time, ``2.0`` twice as
  fast): a frame is released at ``start + (stamp - first stamp) / rate``; a frame that could only be
  released more than ``late_slack_s`` after that instant — because processing fell behind — is
  counted as *late*, and still processed (replay never drops frames silently).
- ``REALTIME`` (live sources): frames are assembled as the data arrives, in a thread of their
  own; whenever the pipeline is ready for a frame it gets the *newest* one, and the frames that
  were replaced before it could take them are skipped and counted (``skipped_frames``) — an
  algorithm slower than the sensor falls behind by at most one frame, never by a growing queue.
- ``CLOSED_LOOP`` (the outputs move the ego in a simulator) uses the same two hooks —
  :meth:`ModeHooks.before_frame` releases the simulator's observations and
  :meth:`ModeHooks.after_frame` applies each frame's outputs before the next is observed. It
  lives a layer up, in :mod:`redrive.closedloop` (its hooks: ``ClosedLoopMode``), because it
  needs a simulator.
"""

from __future__ import annotations

import enum
import threading
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Protocol

from redrive.errors import ConfigError
from redrive.results import FrameRecord
from redrive.types import Frame

__all__ = ["Mode", "ModeHooks", "PacedFrame", "RealtimeMode", "ReplayMode", "mode_hooks"]


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


class RealtimeMode:
    """Live frames: the newest assembled frame each time the pipeline is ready (see the module
    text); ``received_frames`` were assembled, ``skipped_frames`` of them never processed."""

    mode = Mode.REALTIME

    def __init__(self) -> None:
        self.received_frames = 0
        self.skipped_frames = 0
        self._cond = threading.Condition()
        self._latest: Frame | None = None
        self._done = False
        self._error: BaseException | None = None
        self._closing = False

    def _pump(self, frames: Iterable[Frame]) -> None:
        try:
            for frame in frames:
                with self._cond:
                    if self._closing:
                        return
                    self.received_frames += 1
                    if self._latest is not None:
                        self.skipped_frames += 1
                    self._latest = frame
                    self._cond.notify()
        except BaseException as err:  # handed to the engine's thread
            with self._cond:
                self._error = err
        finally:
            with self._cond:
                self._done = True
                self._cond.notify()

    def before_frame(self, frames: Iterable[Frame]) -> Iterator[PacedFrame]:
        pump = threading.Thread(
            target=self._pump, args=(frames,), name="redrive-live-frames", daemon=True
        )
        pump.start()
        try:
            while True:
                with self._cond:
                    while self._latest is None and not self._done:
                        self._cond.wait()
                    frame, self._latest = self._latest, None
                    if frame is None:
                        if self._error is not None:
                            raise self._error
                        return
                yield PacedFrame(frame, False)
        finally:
            with self._cond:
                self._closing = True

    def after_frame(self, record: FrameRecord) -> None:
        pass


def mode_hooks(mode: Mode | str, *, rate: float | None = None) -> ModeHooks:
    """The hooks of ``mode``."""
    mode = Mode(mode)
    if mode is Mode.REPLAY:
        return ReplayMode(rate=rate)
    if mode is Mode.REALTIME:
        return RealtimeMode()
    msg = (
        f"mode {mode.value} needs a simulator in the loop: run it with `redrive run SCENARIO "
        "--closed-loop` (redrive.closedloop.run_closed_loop), not as a mode of a log replay"
    )
    raise ConfigError(msg)
