"""What ``redrive bench transport`` measured: one run of a side, a side at a size, the memcpy
ceiling, a target check, and the whole benchmark (all frozen, with ``to_json``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from redrive.benchmarks._json import fields_json

__all__ = ["CellResult", "MemcpyResult", "RunResult", "TargetCheck", "TransportBenchResult"]


@dataclass(frozen=True, slots=True, kw_only=True)
class RunResult:
    """One run of one side at one size, flat out or paced; rates are the subscriber's, measured
    after the warm-up; latencies are one-way (publisher stamp → subscriber consumed), in ms."""

    mode: str  # "flat" | "paced"
    seconds: float  # how long the publisher published
    sent: int
    received: int
    corrupt: int
    out_of_order: int
    msgs_per_s: float
    gb_per_s: float  # 10⁹ bytes of payload per second
    sent_per_s: float
    latency_p50_ms: float
    latency_p99_ms: float
    latency_max_ms: float

    @property
    def lost(self) -> int:
        return max(0, self.sent - self.received)

    @property
    def lost_fraction(self) -> float:
        return self.lost / self.sent if self.sent else 0.0

    def to_json(self) -> dict[str, Any]:
        return fields_json(self, lost=self.lost, lost_fraction=self.lost_fraction)


@dataclass(frozen=True, slots=True, kw_only=True)
class CellResult:
    """One side at one size: ``status`` is ``"ok"``, ``"not installed"`` or ``"error"``."""

    side: str
    size_bytes: int
    status: str
    error: str | None = None
    flat: RunResult | None = None
    paced: RunResult | None = None

    def to_json(self) -> dict[str, Any]:
        return fields_json(self)


@dataclass(frozen=True, slots=True, kw_only=True)
class MemcpyResult:
    """Single-thread ``np.copyto`` GB/s (10⁹ B/s) at ``size_bytes``."""

    size_bytes: int
    hot_gb_per_s: float
    from_memory_gb_per_s: float
    pool_bytes: int

    def to_json(self) -> dict[str, Any]:
        return fields_json(self)


@dataclass(frozen=True, slots=True, kw_only=True)
class TargetCheck:
    """One target of the issue: ``value`` of ``side`` against ``reference`` (a baseline's value, or
    the bound itself); ``met`` is None when a side needed for it did not run."""

    name: str
    side: str
    size_bytes: int
    value: float | None
    reference: float | None
    target: str  # e.g. "≥ 1.0×", "≤ 2 ms"
    met: bool | None
    note: str = ""

    @property
    def ratio(self) -> float | None:
        if self.value is None or self.reference is None or not self.reference:
            return None
        return self.value / self.reference

    def to_json(self) -> dict[str, Any]:
        return fields_json(self, ratio=self.ratio)


@dataclass(frozen=True, slots=True, kw_only=True)
class TransportBenchResult:
    sizes: tuple[int, ...]
    seconds: float
    paced_hz: float
    slots: int
    cells: tuple[CellResult, ...]
    memcpy: tuple[MemcpyResult, ...]
    targets: tuple[TargetCheck, ...]
    machine: Mapping[str, str] = field(default_factory=dict)
    versions: Mapping[str, str] = field(default_factory=dict)

    def cell(self, side: str, size_bytes: int) -> CellResult | None:
        for c in self.cells:
            if c.side == side and c.size_bytes == size_bytes:
                return c
        return None

    def to_json(self) -> dict[str, Any]:
        return fields_json(self)


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None
