"""Traffic lights with fixed-time cycles: one signal head per approach of the intersection.

Two phase groups alternate (west/east, then south/north).  One cycle lasts
``2 · (green_s + yellow_s + all_red_s)``; group 0 is green at ``t = -offset_s``, group 1 half a
cycle later.  Time is the simulation time in seconds since the start of the scenario.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from redrive.sim.roads import Signal
from redrive.sim.scene import TrafficLightState
from redrive.types import LightState

__all__ = ["LightTiming", "TrafficLights"]


@dataclass(frozen=True, slots=True, kw_only=True)
class LightTiming:
    """Durations (seconds) of one phase group's green, yellow and all-red, and the cycle offset."""

    green_s: float = 12.0
    yellow_s: float = 3.0
    all_red_s: float = 1.0
    offset_s: float = 0.0

    def __post_init__(self) -> None:
        if self.green_s <= 0 or self.yellow_s < 0 or self.all_red_s < 0:
            msg = f"LightTiming: green_s must be > 0 and yellow_s, all_red_s ≥ 0, got {self}"
            raise ValueError(msg)

    @property
    def cycle_s(self) -> float:
        """Length of one full cycle (both groups), seconds."""
        return 2.0 * (self.green_s + self.yellow_s + self.all_red_s)


class TrafficLights:
    """The signals of a network, all driven by one :class:`LightTiming`."""

    def __init__(self, signals: Sequence[Signal], timing: LightTiming) -> None:
        self.signals = tuple(signals)
        self.timing = timing
        self._by_id = {sig.light_id: sig for sig in self.signals}

    def state(self, light_id: int, time_s: float) -> LightState:
        """The state of signal ``light_id`` at ``time_s`` (UNKNOWN for an unknown id)."""
        sig = self._by_id.get(light_id)
        if sig is None:
            return LightState.UNKNOWN
        tm = self.timing
        half = tm.cycle_s / 2.0
        tau = math.fmod(time_s + tm.offset_s - sig.phase_group * half, tm.cycle_s)
        if tau < 0.0:
            tau += tm.cycle_s
        if tau < tm.green_s:
            return LightState.GREEN
        if tau < tm.green_s + tm.yellow_s:
            return LightState.YELLOW
        return LightState.RED

    def states(self, time_s: float) -> tuple[TrafficLightState, ...]:
        """Every signal head at ``time_s``, in ``light_id`` order of the network."""
        return tuple(
            TrafficLightState(
                light_id=sig.light_id, state=self.state(sig.light_id, time_s), position=sig.position
            )
            for sig in self.signals
        )
