"""``redrive bench engine`` — the engine against a bare loop."""

from __future__ import annotations

import argparse
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner

__all__ = ["add_engine_parser"]

_DESCRIPTION = """\
Three stages each doing ~1 ms of numpy work over frames already in memory, run by the engine
(sequential and pipelined) and by a bare Python loop calling the same three functions, in the same
run, interleaved; the ratios are the engine's throughput over the loop's (targets: >= 0.95
sequential, >= 1.5 pipelined on 2 cores). With no-op stages, the engine's own cost per frame
(timing, output checks, records; target <= 20 us), and with the Parquet results writer added
(target <= 50 us), in wall time and in CPU time: of the thread running them, and with the
writer of the whole process, whose pool threads write the Parquet parts (a loaded machine
inflates wall time far more). Every variant runs once per pass, passes interleaved; the figures
are medians, and with --repeat N > 1 a table gives each target's min / median / max over the
N passes (verdict on the median). (The reference pipeline on a log of yours: `redrive run LOG
--mode sequential|pipelined` reports its frames/s and real-time factor.)
"""


def _verdict(ok: bool) -> str:
    return "[green]meets[/]" if ok else "[red]misses[/]"


def _run_engine(args: argparse.Namespace) -> int:
    from redrive.benchmarks.engine import (
        OVERHEAD_TARGET_US,
        PIPELINED_TARGET,
        SEQUENTIAL_TARGET,
        bench_engine,
    )
    from redrive.errors import ConfigError

    if args.repeat < 1 or args.frames < 1:
        msg = "--repeat and --frames must be at least 1"
        raise ConfigError(msg)
    with spinner() as progress:
        result = bench_engine(
            frames=args.frames, work_ms=args.work_ms, repeats=args.repeat, progress=progress
        )
    if args.json:
        print_json({"engine": result.to_json()})
        return 0
    console = report_console()
    console.print(
        f"[bold]frames[/] {result.frames}, 3 stages × {result.work_ms:g} ms of numpy work "
        f"({result.work_elements:,} float64 elements), medians of {args.repeat} passes"
    )
    console.print(
        f"bare loop {result.bare_s:.3f} s | sequential {result.sequential_s:.3f} s → "
        f"{result.sequential_ratio:.2f}x {_verdict(result.sequential_ratio >= SEQUENTIAL_TARGET)} "
        f"{SEQUENTIAL_TARGET}x | pipelined {result.pipelined_s:.3f} s → "
        f"{result.pipelined_ratio:.2f}x {_verdict(result.pipelined_ratio >= PIPELINED_TARGET)} "
        f"{PIPELINED_TARGET}x"
    )
    console.print(
        f"engine cost per frame (3 no-op stages): {result.overhead_us_per_frame:.1f} µs "
        f"{_verdict(result.overhead_us_per_frame <= OVERHEAD_TARGET_US)} {OVERHEAD_TARGET_US:g} µs"
        + (
            f"; with the Parquet writer: {result.writer_us_per_frame:.1f} µs"
            if result.writer_us_per_frame is not None
            else ""
        )
    )
    console.print(
        f"the same in thread CPU time: {result.overhead_cpu_us_per_frame:.1f} µs"
        + (
            f"; with the Parquet writer (process CPU): {result.writer_cpu_us_per_frame:.1f} µs"
            if result.writer_cpu_us_per_frame is not None
            else ""
        )
    )
    if args.repeat > 1:
        _print_spread(result.spreads(), args.repeat, console)
    return 0


def _print_spread(spreads: Any, repeats: int, console: Any) -> None:
    from rich.table import Table

    table = Table(title=f"targets over {repeats} interleaved passes (verdict on the median)")
    for col in ("target", "min", "median", "max", "bound", "verdict"):
        table.add_column(col, justify="left" if col in ("target", "verdict") else "right")
    for t in spreads:
        unit = " µs" if t.at_most else "x"
        fmt = ".1f" if t.at_most else ".2f"
        table.add_row(
            t.name,
            *("—" if v is None else f"{v:{fmt}}{unit}" for v in (t.min, t.median, t.max)),
            f"{'≤' if t.at_most else '≥'} {t.bound:g}{unit}",
            "—" if t.met is None else _verdict(t.met),
        )
    console.print(table)


def add_engine_parser(bench_sub: Any) -> None:
    engine = bench_sub.add_parser(
        "engine",
        help="engine throughput and cost per frame against a bare loop",
        description=_DESCRIPTION,
        epilog=(
            "examples:\n  redrive bench engine\n  redrive bench engine --repeat 5 --frames 2000\n"
            "  redrive bench engine --json"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    engine.add_argument(
        "--frames", type=int, default=500, metavar="N", help="frames per pass (default 500)"
    )
    engine.add_argument(
        "--work-ms", type=float, default=1.0, metavar="MS", help="work per stage (default 1)"
    )
    engine.add_argument(
        "--repeat",
        type=int,
        default=5,
        metavar="N",
        help="interleaved passes per variant; medians, and min/median/max when N > 1 (default 5)",
    )
    engine.add_argument("--json", action="store_true", help="print JSON instead of text")
    engine.set_defaults(func=_run_engine)
