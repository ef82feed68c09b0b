"""``redrive info LOG`` — what a log holds, like ``rosbag info`` plus decoders and sensors."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from redrive.io import open_log
from redrive.io.summary import LogSummary, summarize_log

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive info drive.bag
  redrive info rosbag2_dir/ --json
  redrive info kitti/training --sensor-map sensors.toml
"""


def _human_bytes(n: int | None) -> str:
    if n is None:
        return "-"
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{n} B"


def _print_table(summary: LogSummary) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=None if sys.stdout.isatty() else 160)
    console.print(f"[bold]path[/]:      {summary.path}")
    console.print(f"[bold]format[/]:    {summary.format}")
    console.print(f"[bold]provides[/]:  {', '.join(summary.provides)}")
    console.print(f"[bold]duration[/]:  {summary.duration_s:.3f} s")
    console.print(f"[bold]start[/]:     {summary.start_utc}  ({summary.start_ns} ns)")
    console.print(f"[bold]end[/]:       {summary.end_utc}  ({summary.end_ns} ns)")
    console.print(f"[bold]messages[/]:  {summary.messages}  ({_human_bytes(summary.size_bytes)})")
    table = Table(show_lines=False)
    for col, just in (
        ("topic", "left"),
        ("type", "left"),
        ("count", "right"),
        ("rate Hz", "right"),
        ("bytes", "right"),
        ("decoder", "left"),
        ("maps to", "left"),
    ):
        table.add_column(col, justify=just)  # type: ignore[arg-type]
    for t in summary.topics:
        decoder = t.decoder or ("raw" if t.has_definition else "raw (no definition)")
        table.add_row(
            t.topic,
            t.msgtype,
            str(t.count),
            "-" if t.rate_hz is None else f"{t.rate_hz:.2f}",
            _human_bytes(t.size_bytes),
            decoder,
            t.maps_to or "",
        )
    console.print(table)
    if summary.damage:
        console.print(f"[bold red]damaged[/]: {summary.damage}")


def _run(args: argparse.Namespace) -> int:
    with open_log(args.log, strict=False) as log:
        summary = summarize_log(log, sensor_map_path=args.sensor_map)
    if args.json:
        json.dump(summary.to_json(), sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        _print_table(summary)
    return 1 if summary.damage else 0


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "info",
        help="summarise a log: topics, types, counts, rates, decoders, sensors",
        description=(
            "Print a log's time range and, per topic, its type, message count, rate, bytes, the "
            "decoder redrive uses and the sensor it maps to. Damaged logs are read up to the "
            "damage; the exit status is then 1."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "log",
        type=Path,
        help="a .bag, .mcap, ROS 2 bag directory, KITTI folder, nuScenes data root or mmdetection3d info file",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument(
        "--sensor-map",
        type=Path,
        default=None,
        help="TOML file that overrides the topic → sensor mapping",
    )
    parser.set_defaults(func=_run)
