"""``redrive bench read`` — redrive's read + decode speed against a raw read of the same log."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli._console import add_command, option, print_json, report_console, spinner

__all__ = ["EPILOG", "add_read_arguments", "add_read_parser", "run_read"]

EPILOG = """\
examples:
  redrive bench read drive.bag                       all PointCloud2 topics, 3 repeats
  redrive bench read drive.bag --topic /velodyne_points --repeat 5 --json
  redrive bench read recording.mcap --tune-malloc    multi-MB clouds: no allocator page faults

Every pass runs in a fresh Python process (so peak RSS is per pass); the page cache is warmed by
reading the log once first. Only the message loop is timed: imports and redrive's once-a-process
decoder lookup come before it, opening is shown apart. The ratio is redrive's throughput over the
raw read's (target ≥ 0.8).
"""

_READ_DESCRIPTION = """\
Time reading every sensor_msgs/PointCloud2 message of a log two ways, in the same run: raw
(rosbags for ROS 1 / ROS 2 bags, mcap for .mcap files, no deserialisation) and redrive (open_log +
decode to a PointCloud). Prints messages/s, MB/s of payload, the redrive/raw ratio and the peak
resident memory of each pass. (A synthetic bag of any size to run it on:
`PYTHONPATH=src python -m benchmarks read-synth SIZE_GB OUT.bag` in a checkout.)
"""


def _mb(n: float) -> str:
    return f"{n / 1e6:,.1f}"


def _print_report(result: Any, *, synth: Any | None) -> None:
    from rich.table import Table

    console = report_console()
    raw, ours = result.raw, result.redrive
    repeats = len(result.redrive_passes)
    console.print(
        f"[bold]log[/]:       {result.path} ({result.log_format}, {_mb(result.file_bytes)} MB)"
    )
    if synth is not None:
        console.print(
            f"[bold]synthetic[/]: {synth.messages} × {synth.points_per_message:,} points, "
            f"{_mb(synth.payload_bytes)} MB payload"
        )
    console.print(f"[bold]topics[/]:    {', '.join(result.topics)}")
    console.print(
        f"[bold]read[/]:      {result.messages} messages, {_mb(result.payload_bytes)} MB payload, "
        f"{result.points:,} points"
    )
    warm = "warmed by one full read first" if result.warmed else "NOT warmed"
    malloc = (
        "tuned (" + " ".join(f"{k}={v}" for k, v in result.pass_env.items()) + ")"
        if result.pass_env
        else "glibc defaults"
    )
    console.print(
        f"[bold]method[/]:    median of {repeats} repeats, each pass a fresh process; page cache {warm}"
    )
    console.print(f"[bold]malloc[/]:    {malloc}")
    table = Table()
    cols = ("msgs/s", "MB/s", "best MB/s", "loop s", "open s", "RSS start MB", "peak RSS MB")
    table.add_column("pass", justify="left")
    for col in cols:
        table.add_column(col, justify="right")
    for name, side in (("raw (baseline)", raw), ("redrive (decode)", ours)):
        table.add_row(
            name, f"{side.msgs_per_s:,.1f}", f"{side.mb_per_s:,.0f}", f"{side.best_mb_per_s:,.0f}",
            f"{side.median_loop_s:.4f}", f"{side.median_open_s:.4f}", _mb(side.rss_start_bytes),
            _mb(side.peak_rss_bytes),
        )  # fmt: skip
    console.print(table)
    from redrive.benchmarks.read import TARGET_RATIO

    verdict = "[green]meets[/]" if result.ratio >= TARGET_RATIO else "[red]misses[/]"
    console.print(
        f"[bold]ratio[/] redrive/raw: {result.ratio:.2f}× (best-of-{repeats}: "
        f"{result.best_ratio:.2f}×) — {verdict} the {TARGET_RATIO}× target"
    )


def run_read(
    args: argparse.Namespace, *, synth: Any | None = None, synth_json: dict[str, Any] | None = None
) -> int:
    """Benchmark ``args.log`` and print the report or JSON; ``synth``: the synthetic log it was
    written as (``python -m benchmarks read-synth``), shown and put in the JSON as ``synth_json``."""
    from redrive.benchmarks.read import TUNED_MALLOC_ENV, bench_read

    with spinner() as progress:
        result = bench_read(
            args.log,
            topics=args.topic,
            repeats=args.repeat,
            pass_env=TUNED_MALLOC_ENV if args.tune_malloc else None,
            warm=not args.no_warm,
            progress=progress,
        )
    if args.json:
        out = result.to_json()
        if synth_json is not None:
            out["synthetic"] = synth_json
        print_json(out)
    else:
        _print_report(result, synth=synth)
    return 0


def add_read_arguments(read: Any) -> None:
    """The options of a read benchmark (``redrive bench read`` and ``read-synth``)."""
    read.add_argument(
        "--topic",
        action="append",
        default=None,
        metavar="T",
        help="a PointCloud2 topic to read (repeatable; default: every PointCloud2 topic)",
    )
    option(read, "--repeat", 3, "N", "passes per side (default 3)")
    read.add_argument(
        "--json", action="store_true", help="print JSON (every pass) instead of a table"
    )
    read.add_argument(
        "--no-warm", action="store_true", help="do not read the log once before measuring"
    )
    read.add_argument(
        "--tune-malloc",
        action="store_true",
        help="run both passes with glibc MALLOC_MMAP_THRESHOLD_=64MiB, MALLOC_TRIM_THRESHOLD_=256MiB "
        "(no page-fault churn on multi-MB messages: measures CPU work, not the allocator)",
    )


def add_read_parser(bench_sub: Any) -> None:
    read = add_command(
        bench_sub, "read", "read + decode PointCloud2 messages against a raw rosbags/mcap read",
        _READ_DESCRIPTION, EPILOG,
    )  # fmt: skip
    read.add_argument("log", type=Path, metavar="LOG", help="a .bag, .mcap or ROS 2 bag directory")
    add_read_arguments(read)
    read.set_defaults(func=run_read)
