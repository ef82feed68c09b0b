"""``redrive evaluate RUN|BATCH`` — score a run (or every cell of a batch, pooled across its
logs) with every installed metric; store the results; optional CI gates."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from ._gates import add_gate_options
from ._map_options import add_map_options, map_option

__all__ = ["print_batch_evaluation", "register"]

_EPILOG = """\
examples:
  redrive evaluate runs/first                          every installed metric
  redrive evaluate runs/first --metric nuscenes_detection --metric latency
  redrive evaluate runs/first --metric my_metrics.py:LaneOffset   a metric of your own
  redrive evaluate runs/first --algorithm clusters     only this algorithm (and run-level metrics)
  redrive evaluate runs/first --map lanelet2_map.osm   give the run a road map first (stored in it)
  redrive evaluate runs/first --no-map                 leave out the metrics that need a road map
  redrive report runs/first                            then: HTML, XLSX and CSV report
  redrive evaluate batches/ab                          a batch: every cell, then pooled per
                                                       pipeline × loop across the logs
  redrive evaluate batches/ab --fail-under nuscenes_detection.mAP=0.40 \
      --fail-over latency.frame_p95_ms=50              CI gates on the pooled values

Metrics score the algorithms of their role (perception, planning, control) or the run as a
whole (latency). The 'scores' column says whose motion or output a headline scores: an
algorithm, the run, or "log": in an open-loop run, values of the ego's motion (at-fault
collisions, comfort, progress, drivable area, nuPlan's score of the ego table, the
controller's tracking error) score the *logged* ego — the same whatever the pipeline did; they
are stored with subject "log" and `redrive report`/`compare` show them as the log's. Each metric is stored on its own under RUN/metrics/ (values, per-frame series,
curves, failure-frame bookmarks, and its name, version and parameters in RUN/metrics/index.json):
evaluating one metric again, or adding one, keeps every other stored metric.
`redrive metrics` lists the installed metrics.

A batch directory (`redrive batch`) is evaluated cell by cell (complete cells; failed ones are
listed with their reason), then each metric is pooled per pipeline × loop across the logs as
its definition demands (`redrive metrics` shows each metric's rule): detection AP, CLEAR MOT,
HOTA, object attributes and latency over all frames of all logs together; the others as the
mean of the logs' values weighted by their frame counts. Stored in BATCH/evaluation/ (Parquet:
cells/pipeline=P/loop=L/log=ID/values.parquet and pooled.parquet); see docs/batch.md.

A log-backed closed loop (`redrive run LOG --closed-loop` on a recorded log) whose driven ego
passed its deviation threshold from the logged one gets a caveat: from there the log's agents
and sensors no longer show what the ego would have met. Each closed-loop metric says how many
of its frames were deviated (`deviated_frames`).

exit status: 0 every metric scored or was skipped (it does not apply: the reason is printed);
3 a metric raised an error (printed; the other metrics are stored); 4 a CI gate failed (the
table says which value, and its threshold); 1 a redrive error (not a run, unreadable run …);
2 bad usage.
"""

#: exit status when a metric raised (the other metrics were stored).
EXIT_METRIC_FAILED = 3


def _fmt(value: float) -> str:
    if math.isnan(value):
        return "n/a"
    return f"{value:.4g}"


def _subject_text(subject: str, others: list[str]) -> str:
    """The 'scores' cell: the headline's subject, and the other subjects of the metric's
    values (the controller's command rates beside the log's tracking error)."""
    text = subject
    return text + (f"; also {', '.join(others)}" if others else "")


def _run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    from redrive.batch.manifest import BATCH_MANIFEST
    from redrive.evaluation.closedloop.deviation import deviation_caveat
    from redrive.evaluation.evaluator import evaluate_run, headline, subjects
    from redrive.evaluation.registry import build_metrics, parse_metric_params
    from redrive.results import open_run

    from ._gates import gate_run, print_gates

    metrics = build_metrics(
        args.metric, parse_metric_params(args.metric_param or []), devkit_compat=args.devkit_compat
    )
    if (args.run / BATCH_MANIFEST).is_file():
        if map_option(args) is not None:
            print("redrive evaluate: --map/--no-map are for a run; give a batch's map in its spec")
            return 2
        return _run_batch(args, metrics)
    metrics, map_skipped = _map_choice(args, metrics)
    summary = evaluate_run(args.run, metrics=metrics, algorithms=args.algorithm)
    console = Console(width=None if sys.stdout.isatty() else 120)
    partial = open_run(args.run).manifest.partial_note()
    if partial:
        console.print(f"[bold yellow]warning: {partial}[/]", highlight=False)
    table = Table(title=f"evaluation of {args.run}", title_justify="left")
    for col in ("algorithm", "metric", "headline", "value", "unit", "scores", "bookmarks"):
        table.add_column(col, justify="right" if col in ("value", "bookmarks") else "left")
    closed = summary.closed_loop
    log_results = 0
    for s in summary.scored:
        key, value, unit = headline(s)
        whose = subjects(s, closed_loop=closed)
        subject = whose.get(key, s.algorithm or "run")
        if subject == "log":
            log_results += 1
        others = sorted(set(whose.values()) - {subject})
        table.add_row(
            s.algorithm or ("(log)" if subject == "log" else "(run)"), s.metric.name, key,
            _fmt(value), unit,
            _subject_text(subject, others), str(len(s.result.bookmarks)),
        )  # fmt: skip
    console.print(table)
    if log_results:
        console.print(
            f"[bold]{log_results} result(s) score the log[/] ('scores' log): in an open-loop "
            "run the ego is the logged one, so these values are the same whatever the pipeline "
            "did — the log's, not an algorithm's (`redrive compare` keeps them apart; a "
            "closed-loop run, `redrive run LOG --closed-loop`, scores the pipeline's driving)",
            highlight=False,
        )
    for skip in summary.skipped:
        where = skip.algorithm or "the run"
        console.print(f"[yellow]skipped {skip.metric} on {where}: {skip.reason}[/]")
    for name in map_skipped:
        console.print(f"[yellow]skipped {name}: --no-map (it needs the road map)[/]")
    for fail in summary.failed:
        where = fail.algorithm or "the run"
        console.print(
            f"[bold red]error: metric {fail.metric} on {where} raised {fail.reason}[/] "
            "(`redrive -v evaluate …` shows the traceback)",
            markup=True,
            highlight=False,
        )
    caveat = deviation_caveat(open_run(args.run))
    if caveat:
        console.print(f"[bold yellow]{caveat}[/]", highlight=False)
    console.print(
        f"{len(summary.scored)} results, {summary.bookmarks} bookmarked frames → "
        f"{summary.metrics_dir} (`redrive report {args.run}` for the HTML report)"
    )
    if partial:
        console.print(
            f"[bold yellow]these numbers cover part of the log: {partial}[/]", highlight=False
        )
    gated = print_gates(gate_run([*args.fail_under, *args.fail_over], summary), console)
    if summary.failed:
        console.print(
            f"[bold red]{len(summary.failed)} metric result(s) failed; the others are stored[/]"
        )
        return EXIT_METRIC_FAILED
    return gated


def _map_choice(args: argparse.Namespace, metrics: list[Any] | None) -> tuple[Any, list[str]]:
    """``--map FILE``: the map is attached to the run first (stored, in the manifest);
    ``--no-map``: the metrics that need a road map are left out (their names returned)."""
    option = map_option(args)
    if option is None:
        return metrics, []
    if option.disabled:
        from redrive.evaluation.evaluator import default_metrics

        chosen = list(metrics) if metrics is not None else default_metrics()
        kept = [m for m in chosen if "road_map" not in m.needs]
        return kept, [m.name for m in chosen if "road_map" in m.needs]
    from redrive.engine.user_map import attach_map

    attach_map(args.run, option)
    return metrics, []


def _run_batch(args: argparse.Namespace, metrics: list[Any] | None) -> int:
    from rich.console import Console

    from redrive.batch.evaluate import evaluate_batch

    from ._gates import gate_batch, print_gates

    console = Console(width=None if sys.stdout.isatty() else 120)
    evaluation = evaluate_batch(args.run, metrics=metrics, algorithms=args.algorithm)
    print_batch_evaluation(evaluation, console)
    gated = print_gates(gate_batch([*args.fail_under, *args.fail_over], evaluation), console)
    if evaluation.failed_metrics:
        console.print(
            f"[bold red]{evaluation.failed_metrics} metric result(s) failed; the others are "
            "stored[/]"
        )
        return EXIT_METRIC_FAILED
    return gated


def print_batch_evaluation(evaluation: Any, console: Any) -> None:
    """Per pipeline × loop: the pooled headline of each metric and algorithm, the rule, the
    logs and frames; then the cells left out and the metrics that failed."""
    from rich.markup import escape
    from rich.table import Table

    from redrive.evaluation.pooling import rule_text

    for (pipeline, loop), items in evaluation.pooled.items():
        table = Table(
            title=f"pipeline {pipeline} ({loop} loop): pooled over its logs", title_justify="left"
        )
        cols = ("algorithm", "metric", "headline", "pooled", "unit", "scores", "logs", "frames",
                "rule")  # fmt: skip
        for col in cols:
            table.add_column(
                col, justify="right" if col in ("pooled", "logs", "frames") else "left"
            )
        of_log = 0
        for p in items:
            key = next(iter(p.values), "")
            value = p.values.get(key, math.nan)
            subject = p.subjects.get(key, p.algorithm or "run")
            of_log += subject == "log"
            table.add_row(
                escape(p.algorithm or ("(log)" if subject == "log" else "(run)")),
                escape(p.metric), escape(key), _fmt(value), escape(p.units.get(key, "")),
                escape(subject), str(p.logs), str(p.frames), escape(p.note or p.rule),
            )  # fmt: skip
        console.print(table)
        if of_log:
            console.print(
                f"  {of_log} headline(s) score the log (the logged ego of the open-loop runs): "
                "the same whatever the pipeline did, not its algorithms' result",
                highlight=False,
            )
    rules = sorted({p.rule for items in evaluation.pooled.values() for p in items})
    for rule in rules:
        console.print(f"  {rule}: {rule_text(rule)}", highlight=False)
    for pipeline, loop, metric, algo, error in evaluation.pool_errors:
        console.print(
            f"[bold red]error: pooling {escape(metric)} on {escape(algo or 'the run')} of "
            f"{escape(pipeline)}/{escape(loop)} raised {escape(error)}[/]"
        )
    for ce in evaluation.cells:
        for fail in ce.summary.failed:
            console.print(
                f"[bold red]error: metric {escape(fail.metric)} on cell {escape(ce.cell.cell_id)} "
                f"raised {escape(fail.reason)}[/]"
            )
    for out in evaluation.left_out:
        console.print(
            f"[yellow]not evaluated: cell {escape(out.cell_id)} ({out.status}): "
            f"{escape(out.reason)}[/]"
        )
    console.print(
        f"{len(evaluation.cells)} cells evaluated (each stored in its run directory), "
        f"{len(evaluation.left_out)} left out → {evaluation.folder}"
    )


def _list(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from redrive.evaluation.registry import installed_metrics
    from redrive.output.text import doc_summary

    table = Table(title="installed metrics (redrive.metrics)", title_justify="left")
    for col in ("name", "role", "version", "unit", "better", "pooled by", "summary"):
        table.add_column(col)
    for name, cls in installed_metrics().items():
        doc = escape(doc_summary(cls.__doc__))
        better = "higher" if cls.higher_is_better else "lower"
        table.add_row(name, cls.role_name(), cls.version, cls.unit, better, cls.pooling, doc)
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
        help="score a run (or a batch) with the installed metrics and store the results",
        description=(
            "Evaluate the outputs of a run against its ground truth (detection, tracking, "
            "planning, control, latency metrics) and store values, per-frame series, curves and "
            "failure-frame bookmarks in the run directory. Given a batch directory, evaluate "
            "every complete cell and pool the values per pipeline across its logs."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "run", type=Path, metavar="RUN", help="a run directory, or a batch directory"
    )
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
    add_gate_options(parser, on="the value (a batch: the pooled value)")
    add_map_options(parser, stored=False)
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
