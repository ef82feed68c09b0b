"""``redrive bench transport --repeat N``: each target's value over N interleaved repetitions
(every side at every size once per repetition, so load that comes and goes hits all sides alike),
as min / median / max with the verdict taken on the median (:class:`redrive.benchmarks.spread.Spread`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from redrive.benchmarks.spread import Spread
from redrive.benchmarks.transport.results import TargetCheck, TransportBenchResult

__all__ = ["TargetSpread", "target_spreads"]


@dataclass(frozen=True, slots=True, kw_only=True)
class TargetSpread(Spread):
    """One target over the repetitions: ``values`` are ratios (``≥`` targets) or milliseconds
    (``≤`` targets), one per repetition (None where a side did not run)."""

    side: str
    size_bytes: int
    target: str


def _value(t: TargetCheck) -> float | None:
    return t.value if t.target.startswith("≤") else t.ratio


def _bound(t: TargetCheck) -> float:
    return float(t.target.strip("≥≤ ×ms"))


def target_spreads(results: Sequence[TransportBenchResult]) -> tuple[TargetSpread, ...]:
    """Every target of the repetitions ``results``, in the order of the first repetition's."""
    keys: list[tuple[str, str, int]] = []
    first: dict[tuple[str, str, int], TargetCheck] = {}
    values: dict[tuple[str, str, int], list[float | None]] = {}
    for i, result in enumerate(results):
        for t in result.targets:
            key = (t.name, t.side, t.size_bytes)
            if key not in first:
                keys.append(key)
                first[key] = t
                values[key] = [None] * i
            values[key].append(_value(t))
        for key in keys:  # a target this repetition did not check
            values[key] += [None] * (i + 1 - len(values[key]))
    return tuple(
        TargetSpread(
            name=first[k].name,
            side=first[k].side,
            size_bytes=first[k].size_bytes,
            target=first[k].target,
            bound=_bound(first[k]),
            at_most=first[k].target.startswith("≤"),
            values=tuple(values[k]),
        )
        for k in keys
    )
