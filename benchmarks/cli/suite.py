"""``python -m benchmarks all`` — every benchmark once in a small configuration; one markdown table."""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli._console import spinner

__all__ = ["add_all_parser"]

_DESCRIPTION = """\
Every benchmark once, each in a small documented configuration, in a process of its own with a
time limit; the whole set stays under a budget (default 870 s: 14.5 minutes), a benchmark whose
limit would pass it is skipped and says so. Writes one markdown summary table (--out) and prints
it: per benchmark the command, status, seconds and figures (each target's min/median/max and
verdict where the benchmark repeats, otherwise its ratios, rates and real-time factors).
`make bench` runs this. Wall-clock figures on a loaded machine vary: record `cat /proc/loadavg`.
"""


def _loadavg() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text(encoding="ascii").split()[:3])
    except OSError:
        return ""


def _run_all(args: argparse.Namespace) -> int:
    from benchmarks.suite import SUITE, run_suite, summary_markdown
    from redrive.errors import ConfigError

    names = [e.name for e in SUITE]
    only = [n.strip() for n in args.only.split(",") if n.strip()] if args.only else names
    unknown = [n for n in only if n not in names]
    if unknown:
        msg = f"--only: unknown {', '.join(unknown)} (choose from {', '.join(names)})"
        raise ConfigError(msg)
    if args.budget <= 0:
        msg = "--budget must be greater than 0 seconds"
        raise ConfigError(msg)
    load = _loadavg()
    with spinner() as progress:
        rows = run_suite(
            [e for e in SUITE if e.name in only], budget_s=args.budget, progress=progress
        )
    host = f"{platform.node()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    text = summary_markdown(rows, loadavg=load, host=host)
    if args.out is not None:
        tmp = args.out.with_name(args.out.name + ".tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(args.out)
        print(f"summary written to {args.out}", file=sys.stderr)
    sys.stdout.write(text)
    return 0 if all(r.status == "ok" or r.status.startswith("skipped") for r in rows) else 1


def _epilog() -> str:
    from benchmarks.suite import SUITE

    lines = ["the set (limit in seconds; TMP is a scratch directory of its own):"]
    for e in SUITE:
        lines.append(f"  {e.name:12s} {e.prefix} {' '.join(e.args).replace('{tmp}', 'TMP')}")
        lines.append(f"  {'':12s} {e.why} ({e.timeout_s:g} s)")
    lines += [
        "",
        "examples:",
        "  python -m benchmarks all --out bench-summary.md",
        "  python -m benchmarks all --only engine,eval",
    ]
    return "\n".join(lines)


def add_all_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "all",
        help="every benchmark once in a small configuration; one markdown summary (make bench)",
        description=_DESCRIPTION,
        epilog=_epilog(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--out", type=Path, metavar="FILE", help="write the summary here too")
    parser.add_argument(
        "--only", metavar="NAMES", help="comma-separated benchmarks to run (default: all)"
    )
    parser.add_argument(
        "--budget",
        type=float,
        default=870.0,
        metavar="S",
        help="seconds the whole set may take (default 870)",
    )
    parser.set_defaults(func=_run_all)
