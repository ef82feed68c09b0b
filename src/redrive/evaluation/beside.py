"""``redrive report RUN --beside OTHER``: the values of another run of the same log or situation
next to the report's own — above all an open-loop run beside a closed-loop run of the same
scenario, seed and pipeline — as a section of ``report.html``, the sheet ``beside`` of
``report.xlsx`` and ``beside.csv``.

The pairing and its checks are :func:`redrive.evaluation.compare.compare_runs`'s (the report's run
is A, OTHER is B, so Δ = OTHER − RUN): which run is open and which closed loop, whether the
pipelines differ, and every value either run has, ``—`` on the side that has none.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

from redrive.evaluation import html as h
from redrive.evaluation.comparison import Comparison
from redrive.evaluation.deltas import ValueDelta, pair_label

__all__ = ["REPORT_RESAMPLES", "Beside", "beside_rows", "beside_section"]

#: bootstrap resamples of the comparison behind the section (the report shows no significance).
REPORT_RESAMPLES = 200


class Beside:
    """A report's run (A) and the run beside it (B): their column labels and the comparison."""

    __slots__ = ("cmp", "label_a", "label_b")

    def __init__(self, cmp: Comparison) -> None:
        self.cmp = cmp
        p = cmp.pairing
        self.label_a = f"{cmp.run_a.name} ({p.loop_a})"
        self.label_b = f"{cmp.run_b.name} ({p.loop_b})"

    def better(self, v: ValueDelta) -> str:
        """Which run's value is better by its direction (``same``, ``only in …``, ``n/a``)."""
        verdict = v.verdict
        if verdict == "better":
            return self.label_b
        if verdict == "worse":
            return self.label_a
        if verdict in ("only A", "only B"):
            return f"only in {self.label_a if verdict == 'only A' else self.label_b}"
        return verdict

    def facts(self) -> list[tuple[str, str]]:
        p = self.cmp.pairing
        return [
            ("pairing", p.describe()),
            (self.label_a, str(self.cmp.run_a)),
            (self.label_b, str(self.cmp.run_b)),
            ("source", self.cmp.log_sha256),
            ("same pipeline", "yes" if not p.pipeline_differences else "NO"),
            *(("pipeline difference", d) for d in p.pipeline_differences),
            *(("note", n) for n in p.notes),
            *(
                (f"not compared: {k.metric}{pair_label(k.algorithm_a, k.algorithm_b)}", k.reason)
                for k in self.cmp.skipped
            ),
        ]


def _n(value: float, present: bool) -> str:
    if not present:
        return "—"
    return h.fmt_number(value)


def _direction(v: ValueDelta) -> str:
    return {True: "higher ↑", False: "lower ↓", None: "—"}[v.higher_is_better]


def beside_section(beside: Beside) -> h.Markup:
    """The report's section: the pairing, then one row per value with both runs' numbers."""
    p = beside.cmp.pairing
    facts = h.table(None, beside.facts())
    warn = (
        h.paragraph(
            "The pipelines differ: these are not the values of one pipeline open and closed loop.",
            class_="worse",
        )
        if p.pipeline_differences
        else h.Markup("")
    )
    rows = [
        [v.metric, v.algorithm_a or "(run)", v.key, v.unit, _direction(v),
         _n(v.a, v.in_a), _n(v.b, v.in_b),
         h.fmt_number(v.delta) if v.in_a and v.in_b else "—", beside.better(v)]
        for v in beside.cmp.values
    ]  # fmt: skip
    head = ["metric", "algorithm", "value", "unit", "better", beside.label_a, beside.label_b,
            f"Δ ({beside.cmp.run_b.name} − {beside.cmp.run_a.name})", "better in"]  # fmt: skip
    title = "Open loop beside closed loop" if p.open_closed else f"Beside {beside.cmp.run_b.name}"
    note = h.paragraph(
        "— : the run has no such value (its metric or algorithm was not evaluated there).",
        class_="muted",
    )
    return h.section("beside", title, facts, warn, h.table(head, rows, numeric=[5, 6, 7]), note)


def beside_rows(beside: Beside) -> Iterator[list[Any]]:
    """The sheet ``beside`` of ``report.xlsx``: the pairing facts, then the values (empty cells
    where a run has no such value)."""
    yield from ([k, v] for k, v in beside.facts())
    yield []
    yield ["metric", "algorithm", "value", "unit", "higher_is_better", beside.label_a,
           beside.label_b, "delta", "better in"]  # fmt: skip
    for v in beside.cmp.values:
        a = v.a if v.in_a and math.isfinite(v.a) else None
        b = v.b if v.in_b and math.isfinite(v.b) else None
        delta = v.delta if a is not None and b is not None else None
        yield [v.metric, v.algorithm_a, v.key, v.unit, v.higher_is_better, a, b, delta,
               beside.better(v)]  # fmt: skip
