"""``redrive bench eval`` — the CPU seconds of each metric on a run."""

from __future__ import annotations

import argparse
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner

__all__ = ["add_eval_parser"]

_DESCRIPTION = """\
Evaluate RUN's metrics as `redrive evaluate` does (one set of loaded tables per algorithm shared
by the metrics, in the order given; nothing is stored) and report the process CPU seconds of
reading the run's tables and of each metric. A metric's figure is its cost after the metrics
before it: work they share (NAVSIM's PDMS and EPDMS share their simulated proposals) counts for
the first.
"""

_EPILOG = """\
example:
  redrive bench eval RUN --metric navsim_pdms --metric navsim_epdms
"""


def _run_eval(args: argparse.Namespace) -> int:
    from redrive.benchmarks.eval import bench_eval
    from redrive.evaluation.evaluator import default_metrics
    from redrive.evaluation.registry import load_metric_class

    metrics = [load_metric_class(m)() for m in args.metric] if args.metric else default_metrics()
    with spinner():
        result = bench_eval(args.run, metrics)
    if args.json:
        print_json(result.to_json())
        return 0
    console = report_console()
    console.print(f"[bold]{result.run}[/]: reading the tables {result.load_cpu_s:.3f} CPU s")
    for c in result.costs:
        who = f" ({c.algorithm})" if c.algorithm else ""
        note = "" if c.outcome == "scored" else f"  [{c.outcome}]"
        console.print(f"  {c.metric}{who}: {c.cpu_s:.3f} CPU s{note}")
    console.print(f"metrics in all: {result.metrics_cpu_s:.3f} CPU s")
    return 0


def add_eval_parser(sub: Any) -> None:
    parser = sub.add_parser(
        "eval",
        help="the CPU seconds of each metric on a run",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run", metavar="RUN", help="a run directory")
    parser.add_argument(
        "--metric",
        action="append",
        metavar="NAME",
        help="an installed metric, package.module:Class or file.py:Class (repeat; default: all "
        "installed)",
    )
    parser.add_argument("--json", action="store_true", help="the result as JSON on stdout")
    parser.set_defaults(func=_run_eval)
