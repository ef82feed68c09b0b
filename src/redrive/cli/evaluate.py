"""``redrive evaluate RUN`` — score a run with every installed metric; store the results."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive evaluate runs/first                          every installed metric
  redrive evaluate runs/first --metric nuscenes_detection --metric latency
  redrive evaluate runs/first --metric my_metrics.py:LaneOffset   a metric of your own
  redrive evaluate runs/first --algorithm clusters     only this algorithm (and run-level metrics)
  redrive report runs/first                            then: HTML, XLSX and CSV report

Metrics score the algorithms of their role (perception, planning, control) or the run as a
whole (latency). Each metric is stored on its own under RUN/metrics/ (values, per-frame series,
curves, failure-frame bookmarks, and its name, version and parameters in RUN/metrics/index.json):
evaluating one metric again, or adding one, keeps every other stored metric.
`redrive metrics` lists the installed metrics.

exit status: 0 every metric scored or was skipped (it does not apply: the reason is printed);
3 a metric raised an error (printed; the other metrics are stored); 1 a redrive error (not a
run, unreadable run …); 2 bad usage.
"""

#: exit status when a metric raised (the other metrics were stored).
EXIT_METRIC_FAILED = 3


def _fmt(value: float) -> str:
    if math.isnan(value):
        return "n/a"
    return f"{value:.4g}"


def _run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    from redrive.evaluation.evaluator import evaluate_run, headline
    from redrive.evaluation.registry import build_metrics, parse_metric_params
    from redrive.results import open_run

    metrics = build_metrics(
        args.metric, parse_metric_params(args.metric_param or []), devkit_compat=args.devkit_compat
    )
    summary = evaluate_run(args.run, metrics=metrics, algorithms=args.algorithm)
    console = Console(width=None if sys.stdout.isatty() else 120)
    partial = open_run(args.run).manifest.partial_note()
    if partial:
        console.print(f"[bold yellow]warning: {partial}[/]", highlight=False)
    table = Table(title=f"evaluation of {args.run}", title_justify="left")
    for col in ("algorithm", "metric", "headline", "value", "unit", "bookmarks"):
        table.add_column(col, justify="right" if col in ("value", "bookmarks") else "left")
    for s in summary.scored:
        key, value, unit = headline(s)
        table.add_row(
            s.algorithm or "(run)", s.metric.name, key, _fmt(value), unit,
            str(len(s.result.bookmarks)),
        )  # fmt: skip
    console.print(table)
    for skip in summary.skipped:
        where = skip.algorithm or "the run"
        console.print(f"[yellow]skipped {skip.metric} on {where}: {skip.reason}[/]")
    for fail in summary.failed:
        where = fail.algorithm or "the run"
        console.print(
            f"[bold red]error: metric {fail.metric} on {where} raised {fail.reason}[/] "
            "(`redrive -v evaluate …` shows the traceback)",
            markup=True,
            highlight=False,
        )
    console.print(
        f"{len(summary.scored)} results, {summary.bookmarks} bookmarked frames → "
        f"{summary.metrics_dir} (`redrive report {args.run}` for the HTML report)"
    )
    if partial:
        console.print(
            f"[bold yellow]these numbers cover part of the log: {partial}[/]", highlight=False
        )
    if summary.failed:
        console.print(
            f"[bold red]{len(summary.failed)} metric result(s) failed; the others are stored[/]"
        )
        return EXIT_METRIC_FAILED
    return 0


def _list(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    from redrive.evaluation.registry import installed_metrics

    table = Table(title="installed metrics (redrive.metrics)", title_justify="left")
    for col in ("name", "role", "version", "unit", "better", "summary"):
        table.add_column(col)
    for name, cls in installed_metrics().items():
        doc = (cls.__doc__ or "").strip().split("\n\n", 1)[0].replace("\n", " ")
        better = "higher" if cls.higher_is_better else "lower"
        table.add_row(name, cls.role_name(), cls.version, cls.unit, better, doc)
    console = Console(width=None if sys.stdout.isatty() else 140)
    console.print(table)
    for name in args.params or []:
        found = installed_metrics().get(name)
        if found is None:
            console.print(f"[red]no installed metric {name!r}[/]")
            return 1
        console.print(f"[bold]{name}[/] parameters (--metric-param {name}.PARAM=VALUE):")
        for param, default in found.defaults.items():
            console.print(f"  {param} = {json.dumps(default, default=repr)}", highlight=False)
    return 0


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "evaluate",
        help="score a run with the installed metrics and store the results",
        description=(
            "Evaluate the outputs of a run against its ground truth (detection, tracking, "
            "planning, control, latency metrics) and store values, per-frame series, curves and "
            "failure-frame bookmarks in the run directory."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run", type=Path, metavar="RUN", help="a run directory")
    parser.add_argument(
        "--metric",
        action="append",
        metavar="NAME",
        help="an installed metric, package.module:Class or file.py:Class (repeat; default: all "
        "installed)",
    )
    parser.add_argument(
        "--algorithm", action="append", metavar="NAME", help="an algorithm (repeat; default: all)"
    )
    parser.add_argument(
        "--metric-param",
        action="append",
        metavar="METRIC.PARAM=VALUE",
        help="set a metric's parameter (repeat), e.g. nuscenes_detection.dist_ths_m=0.5,1,2,4 or "
        "nuscenes_detection.class_mean=devkit; stored with its values, so each number carries the "
        "definition that produced it (`redrive metrics --params NAME` lists a metric's parameters)",
    )
    parser.add_argument(
        "--devkit-compat",
        action="store_true",
        help="the official devkits' conventions where redrive's default differs: nuScenes mAP and "
        "TP errors averaged over its ten classes (absent ones score AP 0, errors 1) and the "
        "official NDS with mAAE (nuscenes_detection.class_mean=devkit)",
    )
    parser.set_defaults(func=_run)
    metrics = sub.add_parser(
        "metrics",
        help="list the installed metrics",
        description="List the metrics of the redrive.metrics entry-point group.",
    )
    metrics.add_argument(
        "--params", action="append", metavar="NAME", help="also list this metric's parameters"
    )
    metrics.set_defaults(func=_list)
