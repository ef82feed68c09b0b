"""One benchmark target over N interleaved repetitions: min / median / max, verdict on the median.

Shared by ``redrive bench transport --repeat`` (:class:`redrive.benchmarks.transport.TargetSpread`
adds the side and message size) and ``redrive bench engine --repeat``.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from typing import Any

from redrive.benchmarks._json import fields_json

__all__ = ["Spread"]


@dataclass(frozen=True, slots=True, kw_only=True)
class Spread:
    """``values``: one per repetition (None where it was not measured); ``at_most``: the value
    must stay ≤ ``bound`` (a cost), otherwise ≥ ``bound`` (a ratio)."""

    name: str
    bound: float
    at_most: bool
    values: tuple[float | None, ...]

    @property
    def measured(self) -> list[float]:
        return [v for v in self.values if v is not None]

    @property
    def min(self) -> float | None:
        return min(self.measured) if self.measured else None

    @property
    def median(self) -> float | None:
        return statistics.median(self.measured) if self.measured else None

    @property
    def max(self) -> float | None:
        return max(self.measured) if self.measured else None

    @property
    def met(self) -> bool | None:
        """The verdict on the median (None when nothing was measured)."""
        m = self.median
        if m is None:
            return None
        return m <= self.bound if self.at_most else m >= self.bound

    def to_json(self) -> dict[str, Any]:
        return fields_json(self, min=self.min, median=self.median, max=self.max, met=self.met)
