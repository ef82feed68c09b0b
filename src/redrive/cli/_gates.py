"""The CI gates of ``redrive evaluate``, ``batch`` and ``compare``: options, checks, the table."""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from redrive.batch.evaluate import BatchEvaluation
    from redrive.evaluation.evaluator import EvaluationSummary
    from redrive.evaluation.gates import Gate, GateCheck, GateKind

__all__ = [
    "EXIT_GATE_FAILED",
    "add_gate_options",
    "gate_batch",
    "gate_run",
    "gate_type",
    "print_gates",
]

#: the exit status when a CI gate failed (docs/exit_status.md).
EXIT_GATE_FAILED = 4

GATES_HELP = (
    "CI gates: a failed gate exits with status 4 and prints what failed. METRIC.VALUE names a "
    "stored value, e.g. nuscenes_detection.mAP or latency.frame_p95_ms (`redrive metrics`); a "
    "missing or NaN value fails its gate."
)


def gate_type(kind: GateKind) -> Any:
    """An argparse ``type=`` that parses a gate (bad text: exit 2 with the reason)."""

    def parse(text: str) -> Gate:
        from redrive.errors import ConfigError
        from redrive.evaluation.gates import parse_gate

        try:
            return parse_gate(text, kind)
        except ConfigError as err:
            raise argparse.ArgumentTypeError(str(err)) from err

    parse.__name__ = "gate"
    return parse


def add_gate_options(parser: argparse.ArgumentParser, *, on: str) -> None:
    group = parser.add_argument_group("CI gates", GATES_HELP)
    group.add_argument(
        "--fail-under",
        action="append",
        default=[],
        type=gate_type("under"),
        metavar="METRIC.VALUE=X",
        help=f"fail (exit 4) when {on} is below X (repeat)",
    )
    group.add_argument(
        "--fail-over",
        action="append",
        default=[],
        type=gate_type("over"),
        metavar="METRIC.VALUE=X",
        help=f"fail (exit 4) when {on} is above X (repeat)",
    )


def gate_run(gates: Sequence[Gate], summary: EvaluationSummary) -> list[GateCheck]:
    """Each gate on each algorithm of the run that has its value."""
    from redrive.evaluation.gates import check_threshold

    checks = []
    for gate in gates:
        found = [
            s
            for s in summary.scored
            if s.metric.name == gate.metric and gate.key in s.result.values
        ]
        if not found:
            checks.append(check_threshold(gate, None, where=str(summary.run.path)))
        for s in found:
            checks.append(
                check_threshold(gate, s.result.values[gate.key], where=s.algorithm or "(run)")
            )
    return checks


def gate_batch(gates: Sequence[Gate], evaluation: BatchEvaluation) -> list[GateCheck]:
    """Each gate on the pooled value of each pipeline × loop (and algorithm) that has it."""
    from redrive.evaluation.gates import check_threshold

    checks = []
    for gate in gates:
        found = False
        for (pipeline, loop), items in evaluation.pooled.items():
            for p in items:
                if p.metric == gate.metric and gate.key in p.values:
                    found = True
                    where = f"{pipeline}/{loop}" + (f" {p.algorithm}" if p.algorithm else "")
                    checks.append(check_threshold(gate, p.values[gate.key], where=where))
        if not found:
            checks.append(check_threshold(gate, None, where=f"{evaluation.batch_dir} (pooled)"))
    return checks


def _fmt(value: float) -> str:
    return "n/a" if math.isnan(value) else f"{value:.4g}"


def print_gates(checks: Sequence[GateCheck], console: Any) -> int:
    """Print the gates' table; 0 when every gate passed, else :data:`EXIT_GATE_FAILED`."""
    from rich.markup import escape
    from rich.table import Table

    if not checks:
        return 0
    failed = [c for c in checks if not c.passed]
    title = "CI gates: " + (f"{len(failed)} of {len(checks)} FAILED" if failed else "all passed")
    table = Table(title=title, title_justify="left")
    for col in ("metric", "where", "value", "threshold", "result"):
        table.add_column(col, justify="right" if col == "value" else "left")
    for c in checks:
        result = "[green]passed[/]" if c.passed else "[bold red]FAILED[/]"
        if c.note:
            result += f" ({escape(c.note)})"
        table.add_row(
            escape(c.gate.name), escape(c.where), _fmt(c.value), escape(c.threshold_text), result
        )
    console.print(table)
    return EXIT_GATE_FAILED if failed else 0
