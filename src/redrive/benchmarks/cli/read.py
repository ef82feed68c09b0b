"""``redrive bench read`` — redrive's read + decode speed against a raw read of the same log."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner

__all__ = ["EPILOG", "add_read_parser"]

EPILOG = """\
examples:
  redrive bench read drive.bag                       all PointCloud2 topics, 3 repeats
  redrive bench read drive.bag --topic /velodyne_points --repeat 5 --json
  redrive bench read --synth 2 /tmp/big.bag          write a 2 GB bag of 100k-point sweeps, bench it
  redrive bench read --synth 0.3 --compression lz4 --points 50000 /tmp/small.bag

Every pass runs in a fresh Python process (so peak RSS is per pass); the page cache is warmed by
reading the log once first. Only the message loop is timed: imports and redrive's once-a-process
decoder lookup come before it, opening is shown apart. The ratio is redrive's throughput over the
raw read's (target ≥ 0.8).
"""

_READ_DESCRIPTION = """\
Time reading every sensor_msgs/PointCloud2 message of a log two ways, in the same run: raw
(rosbags for ROS 1 / ROS 2 bags, mcap for .mcap files, no deserialisation) and redrive (open_log +
decode to a PointCloud). Prints messages/s, MB/s of payload, the redrive/raw ratio and the peak
resident memory of each pass. With --synth, first write a synthetic ROS 1 bag of LiDAR sweeps to
LOG (streamed: bounded memory whatever its size) and benchmark that.
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
    for col in (
        "pass",
        "msgs/s",
        "MB/s",
        "best MB/s",
        "loop s",
        "open s",
        "RSS start MB",
        "peak RSS MB",
    ):
        table.add_column(col, justify="left" if col == "pass" else "right")
    for name, side in (("raw (baseline)", raw), ("redrive (decode)", ours)):
        table.add_row(
            name,
            f"{side.msgs_per_s:,.1f}",
            f"{side.mb_per_s:,.0f}",
            f"{side.best_mb_per_s:,.0f}",
            f"{side.median_loop_s:.4f}",
            f"{side.median_open_s:.4f}",
            _mb(side.rss_start_bytes),
            _mb(side.peak_rss_bytes),
        )
    console.print(table)
    from redrive.benchmarks.read import TARGET_RATIO

    verdict = "[green]meets[/]" if result.ratio >= TARGET_RATIO else "[red]misses[/]"
    console.print(
        f"[bold]ratio[/] redrive/raw: {result.ratio:.2f}× (best-of-{repeats}: "
        f"{result.best_ratio:.2f}×) — {verdict} the {TARGET_RATIO}× target"
    )


def _run_read(args: argparse.Namespace) -> int:
    from rich.console import Console

    from redrive.benchmarks.read import TUNED_MALLOC_ENV, bench_read

    status = Console(stderr=True)
    synth = None
    if args.synth is not None:
        synth = _write_synth(args, status)
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
        if synth is not None:
            out["synthetic"] = {
                "messages": synth.messages,
                "points_per_message": synth.points_per_message,
                "payload_bytes": synth.payload_bytes,
                "layout": args.layout,
                "compression": args.compression,
            }
        print_json(out)
    else:
        _print_report(result, synth=synth)
    return 0


def _write_synth(args: argparse.Namespace, status: Any) -> Any:
    from redrive.benchmarks.synth_log import write_synthetic_bag
    from redrive.errors import LogError
    from redrive.output.progress import ProgressBar

    if args.synth <= 0:
        msg = f"--synth takes a size in GB greater than 0, not {args.synth}"
        raise LogError(msg)
    with ProgressBar(f"writing {args.log}", unit="messages", console=status) as bar:

        def progress(done: int, total: int) -> None:
            bar.update(done, total=total)

        return write_synthetic_bag(
            args.log,
            size_bytes=round(args.synth * 1e9),
            points=args.points,
            layout=args.layout,
            compression=args.compression,
            progress=progress,
        )


def add_read_parser(bench_sub: Any) -> None:
    read = bench_sub.add_parser(
        "read",
        help="read + decode PointCloud2 messages against a raw rosbags/mcap read",
        description=_READ_DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    read.add_argument(
        "log",
        type=Path,
        metavar="LOG",
        help="a .bag, .mcap or ROS 2 bag directory; with --synth, the new .bag to write",
    )
    read.add_argument(
        "--topic",
        action="append",
        default=None,
        metavar="T",
        help="a PointCloud2 topic to read (repeatable; default: every PointCloud2 topic)",
    )
    read.add_argument(
        "--repeat", type=int, default=3, metavar="N", help="passes per side (default 3)"
    )
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
    synth = read.add_argument_group("synthetic log")
    synth.add_argument(
        "--synth",
        type=float,
        default=None,
        metavar="SIZE_GB",
        help="write a ROS 1 bag of about SIZE_GB GB (10⁹ bytes) of PointCloud2 to LOG first",
    )
    synth.add_argument(
        "--points", type=int, default=100_000, metavar="N", help="points per sweep (default 100000)"
    )
    synth.add_argument(
        "--compression",
        choices=("none", "lz4", "bz2"),
        default="none",
        help="chunk compression of the synthetic bag (default none)",
    )
    synth.add_argument(
        "--layout",
        choices=("velodyne", "xyzi"),
        default="velodyne",
        help="velodyne: x,y,z,intensity f32 + ring u16 + time f64, 32 B/point (default); "
        "xyzi: 16 B/point",
    )
    read.set_defaults(func=_run_read)
