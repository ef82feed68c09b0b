"""What the benchmarks share: results as JSON (what ``--json`` prints and ``make bench``'s summary
reads) and :class:`Spread`, one target over N interleaved repetitions."""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["Spread", "fields_json", "plain"]


def plain(value: Any) -> Any:
    """``value`` JSON-ready: results through their ``to_json``, other dataclasses field by field,
    tuples as lists, paths as text, NaN and infinities as None."""
    if hasattr(value, "to_json"):
        return value.to_json()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return fields_json(value)
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return [plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


def fields_json(obj: Any, **extra: Any) -> dict[str, Any]:
    """Every field of the dataclass ``obj`` (:func:`plain`), then ``extra`` (derived figures)."""
    out = {f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    out.update((k, plain(v)) for k, v in extra.items())
    return out


@dataclass(frozen=True, slots=True, kw_only=True)
class Spread:
    """One target over N interleaved repetitions (``--repeat``): ``values``, one per repetition
    (None where it was not measured), as min / median / max, the verdict on the median;
    ``at_most``: the value must stay ≤ ``bound`` (a cost), otherwise ≥ ``bound`` (a ratio)."""

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
