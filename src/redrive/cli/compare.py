"""``redrive compare RUN_A RUN_B`` — A/B comparison of two evaluated runs of the same log;
``redrive compare BATCH_A BATCH_B`` (or two pipelines of one batch) — A/B over a fleet."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from ._gates import gate_type

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive compare runs/a runs/b                         every metric both runs share
  redrive compare runs/a runs/b --worst 20 --html ab.html
  redrive compare runs/a runs/b --algorithm-a clusters --algorithm-b clusters_v2
  redrive compare runs/a runs/b --json > ab.json
  redrive compare runs/open runs/closed                 open loop beside closed loop

Both runs must have replayed the same log (checked by its sha256) and been evaluated
(`redrive evaluate RUN`). Two closed-loop runs of a scenario pair when scenario, seed, duration
and agents agree. An open-loop run of a `redrive synth` log and a closed-loop run of the
scenario it was made from (same name, seed and duration), or of the same recorded log, pair in
either order: the output says which run is open and which closed loop, whether the pipelines
are the same (and how they differ), and lists metrics only one run has with — on the other
side. Δ = B − A; "better"/"worse" follow each value's direction. Metrics
are compared only where name, version and parameters agree; the others are listed as not
compared. Algorithms pair by name; one algorithm of a role that has a different name on each
side (a file plugin named after its class, `RansacCluster`, against `cluster-detector`) pairs
with the other by role — or, where a role has several, by role and stage (`perception_1`) —
and the "paired" line says so; --algorithm-a/--algorithm-b choose a pair. Significance: a paired bootstrap over frames (the frames both runs have are resampled
with replacement). The 95 % CI beside a value is of that value: of the statistic it is — the
mean per-frame difference for a mean, the max over the frames for a max, a sum for a count —
marked with that statistic ("max [..]"); aggregates such as mAP that are none of those get no
CI (their note refers to the metric's per-frame series).
In open-loop runs the values that score the ego's motion (at-fault collisions, comfort,
progress, drivable area, nuPlan's score, the controller's tracking error) score the *logged*
ego: they are listed once, as the log's, apart from the algorithms' comparison.

Batches (each evaluated with `redrive evaluate BATCH`):
  redrive compare batches/ab --pipeline-a a --pipeline-b b     two pipelines of one batch
  redrive compare batches/monday batches/tuesday               two batches (one pipeline each,
                                                               or name them with --pipeline-a/b)
  redrive compare batches/ab --pipeline-a a --pipeline-b b --value clear_mot.MOTA
The pooled values side by side, then the chosen value (--value METRIC.KEY; default the headline
of the first metric that scores an algorithm) per log, B's worst logs first, with a paired
bootstrap over logs (95 % CI of the mean per-log Δ).

CI gate: --max-regression mAP=0.01 (or METRIC.VALUE=X) fails — exit 4, with the table — when B
is worse than A by more than 0.01 in the value's own direction (a batch: on the pooled values).
"""


def _fmt(value: float) -> str:
    return "n/a" if math.isnan(value) else f"{value:.4g}"


def _side(value: float, present: bool) -> str:
    """A run's value, ``—`` when the run has no such value (only the other run has it)."""
    return _fmt(value) if present else "—"


def _pct(value: float) -> str:
    return "" if not math.isfinite(value) else f"{100.0 * value:+.1f}%"


#: rows of the text output unless --all: what fits a screen (the rest: --all, --html, --json).
SCREEN_VALUES = 30
SCREEN_SERIES = 12


def shown_values(cmp: Any, *, everything: bool) -> list[Any]:
    """The values the text output lists: every one with ``everything``; else each metric's
    headline (its first value per algorithm pair) and the values whose per-frame CI excludes
    0, at most :data:`SCREEN_VALUES`."""
    if everything:
        return list(cmp.values)
    seen: set[tuple[str, str, str]] = set()
    keep = []
    for v in cmp.values:
        key = (v.metric, v.algorithm_a, v.algorithm_b)
        headline = key not in seen
        seen.add(key)
        significant = v.bootstrap is not None and v.bootstrap.excludes_zero
        if headline or significant:
            keep.append(v)
    return keep[:SCREEN_VALUES]


def _print_log_values(cmp: Any, console: Any, *, everything: bool) -> None:
    """The values of the logged ego (open loop, both runs), once, as the log's: not compared."""
    from rich.markup import escape
    from rich.table import Table

    if not cmp.log_values:
        return
    differ = [v for v in cmp.log_values if v.verdict not in ("same",)]
    table = Table(
        title=(
            "the log's values — these score the logged ego of the open-loop runs, the same "
            "whatever the algorithms did; not an algorithm result, not compared"
        ),
        title_justify="left",
    )
    for col in ("metric", "value", "log", "in B"):
        table.add_column(col, justify="right" if col == "log" else "left")
    seen: set[tuple[str, str]] = set()
    shown = 0
    for v in cmp.log_values:
        headline = (v.metric, v.algorithm_a) not in seen
        seen.add((v.metric, v.algorithm_a))
        if not (everything or headline or v in differ):
            continue
        shown += 1
        other = "same" if v.verdict == "same" else f"{_side(v.b, v.in_b)} (Δ {_fmt(v.delta)})"
        value = _side(v.a, v.in_a) if v.in_a else _side(v.b, v.in_b)
        table.add_row(escape(v.metric), escape(v.key), value, other)
    console.print(table)
    if differ:
        console.print(
            f"[yellow]{len(differ)} of the log's values differ between A and B (other frames, "
            "or — the controller's tracking error — another planner's plan): still the logged "
            "ego's, not a result of the compared algorithms[/]"
        )
    if shown < len(cmp.log_values):
        console.print(f"{len(cmp.log_values) - shown} more of the log's values: --all lists them")


def _print(cmp: Any, *, worst: int, everything: bool = False) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = Console(width=None if sys.stdout.isatty() else 140)
    by_role = {(a, b): role for a, b, role in cmp.role_pairs}
    pairs = ", ".join(
        (f"{a} ↔ {b}" + (f" (paired by role: the only unpaired {by_role[a, b]} algorithm on "
                          "each side)" if (a, b) in by_role else ""))
        if a != b else a
        for a, b in cmp.pairs if a or b
    )  # fmt: skip
    p = cmp.pairing
    console.print(
        f"{p.label_a} {cmp.run_a}\n{p.label_b} {cmp.run_b}\nsource {cmp.log_sha256}; paired {pairs}",
        highlight=False,
    )
    if p.open_closed:
        console.print(f"[bold]{escape(p.describe())}[/]")
        for note in p.notes:
            console.print(escape(note))
        if p.pipeline_differences:
            console.print("[yellow]the pipelines differ: the values are not of one pipeline[/]")
    numbers = (p.label_a, p.label_b, "Δ", "Δ %")
    title = "values (Δ = B − A" + (f" = {p.loop_b} − {p.loop_a})" if p.open_closed else ")")
    if p.open_closed:
        title += "; — = the run has no such value"
    table = Table(title=title, title_justify="left")
    for col in ("metric", "algorithm", "value", *numbers, f"{p.label_b} is", "95% CI of Δ"):
        table.add_column(col, justify="right" if col in numbers else "left")
    colour = {"better": "green", "worse": "red"}
    values = shown_values(cmp, everything=everything)
    for v in values:
        algo = (
            v.algorithm_a if v.algorithm_a == v.algorithm_b else f"{v.algorithm_a}→{v.algorithm_b}"
        )
        verdict = f"[{colour[v.verdict]}]{v.verdict}[/]" if v.verdict in colour else v.verdict
        if "log" in v.subject.split("→"):  # open beside closed loop: the log's ego, the driven
            algo = f"{algo or '(run)'} [{v.subject}]"
        table.add_row(
            escape(v.metric), escape(algo or "(run)"), escape(v.key), _side(v.a, v.in_a),
            _side(v.b, v.in_b),
            _fmt(v.delta), _pct(v.relative_delta), verdict, escape(v.significance),
        )  # fmt: skip
    console.print(table)
    _print_log_values(cmp, console, everything=everything)
    series = Table(
        title="per-frame series (paired bootstrap over frames, 95% CI)", title_justify="left"
    )
    for col in ("series", "better", "frames", "mean Δ/frame", "95% CI", "excludes 0"):
        series.add_column(col)
    # a series of an algorithm (or stage) only one run has shares no frame: named below the
    # table, not listed as a row of "n/a" (--all lists it)
    one_sided = [s for s in cmp.series if not s.bootstrap.n_frames and (s.only_a or s.only_b)]
    one_ids = {id(s) for s in one_sided}  # by identity: a delta holds arrays (no == of them)
    paired = list(cmp.series) if everything else [s for s in cmp.series if id(s) not in one_ids]
    series_shown = paired if everything else paired[:SCREEN_SERIES]
    for s in series_shown:
        b = s.bootstrap
        better = {True: "higher", False: "lower", None: "—"}[s.higher_is_better]
        ci = f"[{_fmt(b.ci_low)}, {_fmt(b.ci_high)}]"
        mark = "[bold]yes[/]" if b.excludes_zero else "no"
        series.add_row(escape(s.label), better, str(b.n_frames), _fmt(b.mean_delta), ci, mark)
    console.print(series)
    if one_sided and not everything:
        for side, names in (
            ("A", [s.label for s in one_sided if s.only_a]),
            ("B", [s.label for s in one_sided if s.only_b]),
        ):
            if names:
                console.print(
                    f"only in {side}, so not compared: {escape(', '.join(names))}", highlight=False
                )
    frames = Table(title=f"frames where B is most worse than A (top {worst})", title_justify="left")
    for col in ("#", "frame", "stamp_ns", "score", "what differs", "new in B"):
        frames.add_column(col, justify="right" if col in ("#", "frame", "score") else "left")
    for i, w in enumerate(cmp.worst_frames(worst)):
        frames.add_row(
            str(i + 1), str(w.frame_index), str(w.stamp_ns), f"{w.score:.3g}",
            escape("\n".join(w.differences)), escape("\n".join(w.new_bookmarks[:3])),
        )  # fmt: skip
    console.print(frames)
    if not cmp.worst:
        console.print("B is not worse than A on any frame of any per-frame series.")
    hidden_v = len(cmp.values) - len(values)
    hidden_s = len(cmp.series) - len(series_shown) - (0 if everything else len(one_sided))
    if hidden_v or hidden_s:
        console.print(
            f"{hidden_v} more values and {hidden_s} more series not shown (headlines and "
            "significant changes are): --all lists every row, --html OUT.html writes them all"
        )
    for k in cmp.skipped:
        where = (
            k.algorithm_a if k.algorithm_a == k.algorithm_b else f"{k.algorithm_a}→{k.algorithm_b}"
        )
        console.print(
            f"[yellow]not compared: {escape(k.metric)} [{escape(where)}]: {escape(k.reason)}[/]"
        )


def _regressions(gates: list[Any], values: list[tuple[str, str, str, float, float, Any]]) -> Any:
    """Each regression gate on each (metric, key, where, a, b, higher_is_better) it names."""
    from redrive.evaluation.gates import check_regression

    checks = []
    for gate in gates:
        found = [v for v in values if v[1] == gate.key and gate.metric in ("", v[0])]
        if not found:
            checks.append(check_regression(gate, math.nan, math.nan, True, where="(no such value)"))
        for metric, _key, where, a, b, hib in found:
            checks.append(check_regression(gate, a, b, hib, where=f"{metric} {where}".rstrip()))
    return checks


def _print_batches(cmp: Any, *, worst: int) -> None:
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    console = Console(width=None if sys.stdout.isatty() else 140)
    console.print(f"A {escape(cmp.side_a)}\nB {escape(cmp.side_b)}")
    table = Table(title="pooled values (Δ = B − A)", title_justify="left")
    for col in ("metric", "loop", "value", "A", "B", "Δ", "B is"):
        table.add_column(col, justify="right" if col in ("A", "B", "Δ") else "left")
    colour = {"better": "green", "worse": "red"}
    of_log = 0
    for v in cmp.pooled:
        verdict = f"[{colour[v.verdict]}]{v.verdict}[/]" if v.verdict in colour else v.verdict
        if v.subject == "log":  # the logged ego's: not a result of A or B
            of_log += 1
            verdict = f"the log's ({v.verdict})"
        table.add_row(
            escape(v.metric), v.loop, escape(v.key), _fmt(v.a), _fmt(v.b), _fmt(v.delta), verdict
        )
    console.print(table)
    if of_log:
        console.print(
            f'{of_log} value(s) marked "the log\'s" score the logged ego of open-loop runs: the '
            "same whatever the pipelines did, not a result of A or B",
            highlight=False,
        )
    logs = Table(
        title=f"{cmp.metric}.{cmp.key} per log, B's worst first (top {worst} of {len(cmp.logs)})",
        title_justify="left",
    )
    for col in ("#", "log", "loop", "A", "B", "Δ", "worse by"):
        logs.add_column(col, justify="left" if col in ("log", "loop") else "right")
    for i, d in enumerate(cmp.logs[:worst]):
        logs.add_row(
            str(i + 1), escape(d.log), d.loop, _fmt(d.a), _fmt(d.b), _fmt(d.delta),
            _fmt(d.worse_by),
        )  # fmt: skip
    console.print(logs)
    b = cmp.bootstrap
    better = {True: "higher is better", False: "lower is better", None: "no direction"}
    console.print(
        f"mean Δ over {b.n_frames} logs {_fmt(b.mean_delta)}, 95% CI [{_fmt(b.ci_low)}, "
        f"{_fmt(b.ci_high)}] ({'excludes' if b.excludes_zero else 'includes'} 0; paired "
        f"bootstrap over logs, {b.resamples} resamples; {better[cmp.higher_is_better]})",
        highlight=False,
    )
    if cmp.unpaired:
        console.print(f"[yellow]logs only one side has: {escape(', '.join(cmp.unpaired))}[/]")


def _run_batches(args: argparse.Namespace) -> int:
    from rich.console import Console

    from redrive.batch.compare import compare_batches

    from ._gates import print_gates

    cmp = compare_batches(
        args.run_a,
        args.run_b or args.run_a,
        pipeline_a=args.pipeline_a,
        pipeline_b=args.pipeline_b,
        value=args.value,
        algorithm_a=args.algorithm_a,
        algorithm_b=args.algorithm_b,
        resamples=args.bootstrap,
        seed=args.seed,
    )
    _print_batches(cmp, worst=args.worst)
    values = [
        (v.metric, v.key, f"{v.loop} {v.algorithm_a}".rstrip(), v.a, v.b, v.higher_is_better)
        for v in cmp.pooled
    ]
    console = Console(width=None if sys.stdout.isatty() else 140)
    return int(print_gates(_regressions(args.max_regression, values), console))


def _run(args: argparse.Namespace) -> int:
    from redrive.batch.manifest import BATCH_MANIFEST
    from redrive.errors import ConfigError
    from redrive.evaluation.compare import compare_runs

    if (args.run_a / BATCH_MANIFEST).is_file():
        return _run_batches(args)
    if args.run_b is None:
        msg = "compare needs RUN_B (only a batch compares two of its own pipelines)"
        raise ConfigError(msg)

    cmp = compare_runs(
        args.run_a,
        args.run_b,
        algorithm_a=args.algorithm_a,
        algorithm_b=args.algorithm_b,
        bootstrap=args.bootstrap,
        seed=args.seed,
    )
    if args.json:
        print(cmp.to_json(worst=args.worst))
    else:
        _print(cmp, worst=args.worst, everything=args.all)
    if args.html is not None:
        path = cmp.write_html(args.html, worst=args.worst)
        print(f"HTML: {path}", file=sys.stderr if args.json else sys.stdout)
    if args.max_regression:
        from rich.console import Console

        from ._gates import print_gates

        values = [
            (v.metric, v.key, v.algorithm_b or "(run)", v.a, v.b, v.higher_is_better)
            for v in cmp.values
        ]
        out = sys.stderr if args.json else sys.stdout
        console = Console(file=out, width=None if out.isatty() else 140)
        return int(print_gates(_regressions(args.max_regression, values), console))
    return 0


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "compare",
        help="A/B comparison of two evaluated runs of the same log (or open beside closed loop), or of two batches",
        description=(
            "Compare the evaluation of run B against run A (two runs of one log, or an "
            "open-loop and a closed-loop run of the same scenario): per-metric deltas with a "
            "significance "
            "note (paired bootstrap over frames), per-frame deltas, and the frames where B is "
            "most worse than A, as a table, JSON or a self-contained HTML file."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "run_a", type=Path, metavar="RUN_A", help="the baseline run (or batch) directory"
    )
    parser.add_argument(
        "run_b",
        type=Path,
        nargs="?",
        metavar="RUN_B",
        help="the run (or batch) compared against it (a batch alone: two of its pipelines)",
    )
    parser.add_argument(
        "--algorithm-a", metavar="X", default=None, help="compare only this algorithm of A"
    )
    parser.add_argument(
        "--algorithm-b",
        metavar="Y",
        default=None,
        help="… against this algorithm of B (default: the same name)",
    )
    parser.add_argument(
        "--worst", type=int, default=10, metavar="N", help="frames listed (default 10)"
    )
    parser.add_argument(
        "--html", type=Path, default=None, metavar="OUT.html", help="also write an HTML file"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of tables")
    parser.add_argument(
        "--all",
        action="store_true",
        help="list every value and series (default: each metric's headline and the values "
        "whose change is significant, to fit a screen)",
    )
    parser.add_argument(
        "--bootstrap", type=int, default=2000, metavar="N", help="bootstrap resamples (2000)"
    )
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")
    parser.add_argument("--pipeline-a", metavar="NAME", help="batches: the pipeline of A")
    parser.add_argument("--pipeline-b", metavar="NAME", help="batches: the pipeline of B")
    parser.add_argument(
        "--value",
        metavar="METRIC.KEY",
        help="batches: the value compared per log (default: the first metric's headline)",
    )
    parser.add_argument(
        "--max-regression",
        action="append",
        default=[],
        type=gate_type("regression"),
        metavar="[METRIC.]VALUE=X",
        help="CI gate: fail (exit 4) when B is worse than A by more than X (repeat)",
    )
    parser.set_defaults(func=_run)
