"""Traffic lights with fixed-time cycles: one signal head per approach of the intersection.

Two phase groups alternate (west/east, then south/north).  One cycle lasts
``2 · (green_s + yellow_s + all_red_s)``; group 0 is green at ``t = -offset_s``, group 1 half a
cycle later.  Time is the simulation time in seconds since the start of the scenario.

The ground truth of the signals is :meth:`TrafficLights.traffic_data`: one
:class:`~redrive.types.TrafficLight` per signal head, its ``id`` :func:`light_id_text` of the
signal — the ``light_id`` of the :class:`~redrive.types.MapTrafficLight` the scenario's road map
places for it (:mod:`redrive.sim.roadmap`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from redrive.sim.roads import Signal
from redrive.sim.scene import TrafficLightState
from redrive.types import LightState, TrafficData, TrafficLight

__all__ = ["LightTiming", "TrafficLights", "light_id_text", "traffic_data_of"]


_GREEN, _YELLOW, _RED = LightState.GREEN, LightState.YELLOW, LightState.RED


def _phase_state(  # noqa: PLR0917 (per signal and frame: positional is cheaper)
    time_s: float,
    offset_s: float,
    shift_s: float,
    cycle_s: float,
    green_s: float,
    yellow_end_s: float,
) -> LightState:
    """A signal's state at ``time_s``: its phase in the cycle (offset, less its group's shift of
    ``phase_group · cycle_s / 2``) green until ``green_s``, yellow until ``yellow_end_s``
    (``green_s + yellow_s``), red after."""
    tau = math.fmod(time_s + offset_s - shift_s, cycle_s)
    if tau < 0.0:
        tau += cycle_s
    if tau < green_s:
        return _GREEN
    if tau < yellow_end_s:
        return _YELLOW
    return _RED


def light_id_text(light_id: int) -> str:
    """The text id of signal ``light_id`` in the road map and the ground truth (``"0"``, ``"1"``,
    …: ``TrafficLight.id == MapTrafficLight.light_id``)."""
    return str(int(light_id))


def traffic_data_of(states: Sequence[TrafficLightState]) -> TrafficData:
    """The ground truth of a scene's signal heads (ids :func:`light_id_text`, in their order;
    no nearby vehicles — those are the objects)."""
    return TrafficData(
        traffic_lights=tuple(
            TrafficLight(id=light_id_text(head.light_id), state=head.state) for head in states
        )
    )


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
        self._ids = tuple(light_id_text(sig.light_id) for sig in self.signals)
        #: the last traffic_data: its states and itself (the phases last seconds, frames ~0.1 s)
        self._last: tuple[tuple[LightState, ...], TrafficData] | None = None
        #: :meth:`state`'s operands that depend on the timing alone, for :meth:`traffic_data`
        self._phases: tuple[LightTiming, float, float, float, float, tuple[float, ...]] | None
        self._phases = None

    def _timing_terms(self) -> tuple[LightTiming, float, float, float, float, tuple[float, ...]]:
        """``(timing, offset_s, cycle_s, green_s, green_s + yellow_s, each signal's
        phase_group · cycle_s / 2)``: the values :meth:`state` computes of the timing at every
        call, computed once (again when :attr:`timing` is replaced)."""
        tm = self.timing
        terms = self._phases
        if terms is None or terms[0] is not tm:
            half = tm.cycle_s / 2.0
            shifts = tuple(sig.phase_group * half for sig in self.signals)
            terms = (tm, tm.offset_s, tm.cycle_s, tm.green_s, tm.green_s + tm.yellow_s, shifts)
            self._phases = terms
        return terms

    def state(self, light_id: int, time_s: float) -> LightState:
        """The state of signal ``light_id`` at ``time_s`` (UNKNOWN for an unknown id)."""
        sig = self._by_id.get(light_id)
        if sig is None:
            return LightState.UNKNOWN
        tm = self.timing
        shift = sig.phase_group * (tm.cycle_s / 2.0)
        return _phase_state(
            time_s, tm.offset_s, shift, tm.cycle_s, tm.green_s, tm.green_s + tm.yellow_s
        )

    def states(self, time_s: float) -> tuple[TrafficLightState, ...]:
        """Every signal head at ``time_s``, in ``light_id`` order of the network."""
        return tuple(
            TrafficLightState(
                light_id=sig.light_id, state=self.state(sig.light_id, time_s), position=sig.position
            )
            for sig in self.signals
        )

    def traffic_data(self, time_s: float) -> TrafficData:
        """The ground truth of every signal head at ``time_s`` (:func:`traffic_data_of` of
        :meth:`states`; the same immutable object again while no state changed).  Each state
        is :meth:`state`'s (:func:`_phase_state`), with the timing's terms made once."""
        _tm, offset_s, cycle_s, green_s, yellow_end_s, shifts = self._timing_terms()
        states = tuple(
            [
                _phase_state(time_s, offset_s, shift, cycle_s, green_s, yellow_end_s)
                for shift in shifts
            ]
        )
        last = self._last
        if last is not None and last[0] == states:
            return last[1]
        data = TrafficData(
            traffic_lights=tuple(
                TrafficLight(id=light_id, state=state)
                for light_id, state in zip(self._ids, states, strict=True)
            )
        )
        self._last = (states, data)
        return data
