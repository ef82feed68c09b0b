"""``python -m benchmarks export`` — the Foxglove MCAP export of the demo run against a plain MCAP copy."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner

__all__ = ["add_export_parser"]

_DESCRIPTION = """\
Make the demo run once (`redrive synth urban --duration 20`, then `redrive run` of it; --run
takes an existing run instead), then time, in this process and interleaved, `redrive export RUN
--format mcap` (the log's chunks copied as they are, the run's SceneUpdates and MarkerArrays; with
--sensor-copies also every cloud and image converted to foxglove.PointCloud / CompressedImage)
against copying the log's messages with the `mcap` library alone (read + write with LZ4 chunks, no
conversion). Reports seconds (median of --repeat), x real time (target >= 20x, issue
18), the ratio export / copy in wall-clock and in CPU seconds, and the load average (the
machine's other work slows both sides).
"""


def _run_export(args: argparse.Namespace) -> int:
    from benchmarks.export import TARGET_REALTIME, bench_export

    with spinner() as progress:
        result = bench_export(
            run=args.run,
            workdir=args.workdir,
            duration_s=args.duration,
            repeats=args.repeat,
            sensor_copies=args.sensor_copies,
            progress=progress,
        )
    if args.json:
        print_json(result.to_json())
        return 0
    console = report_console()
    ok = result.export_realtime >= TARGET_REALTIME
    verdict = "[green]meets[/]" if ok else "[red]misses[/]"
    console.print(
        f"[bold]log[/] {result.log}: {result.log_span_s:.1f} s, {result.log_bytes / 1e6:.0f} MB, "
        f"{result.copy_messages} messages; medians of {len(result.export_s)} passes"
        + ("; export with --sensor-copies" if result.sensor_copies else "")
    )
    console.print(
        f"[bold]export[/] {result.export_median_s:.2f} s = {result.export_realtime:.1f}x real time "
        f"{verdict} {TARGET_REALTIME:g}x  ({result.export_messages} messages, "
        f"{result.export_bytes / 1e6:.0f} MB)"
    )
    console.print(
        f"[bold]copy[/]   {result.copy_median_s:.2f} s = {result.copy_realtime:.1f}x real time  "
        f"(mcap read + write, {result.copy_bytes / 1e6:.0f} MB)"
    )
    console.print(
        f"export / copy: {result.ratio:.2f} wall clock, {result.cpu_ratio:.2f} CPU time  |  "
        f"load average {result.load_before:.1f} → {result.load_after:.1f}"
    )
    return 0


def add_export_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "export",
        help="Foxglove MCAP export of the demo run against an mcap copy of its log",
        description=_DESCRIPTION,
        epilog=(
            "examples:\n  python -m benchmarks export\n"
            "  python -m benchmarks export --run runs/urban --repeat 5 --json\n"
            "  python -m benchmarks export --run runs/urban --sensor-copies"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--run", type=Path, metavar="RUN", help="export this run instead of making the demo"
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=20.0,
        metavar="S",
        help="seconds of the demo log made when --run is not given (default 20)",
    )
    parser.add_argument(
        "--workdir",
        type=Path,
        metavar="DIR",
        help="where the demo and the outputs are written (default: a temporary directory)",
    )
    parser.add_argument(
        "--repeat", type=int, default=3, metavar="N", help="passes of each side (default 3)"
    )
    parser.add_argument(
        "--sensor-copies",
        action="store_true",
        help="time `redrive export --format mcap --sensor-copies` (foxglove.PointCloud and "
        "CompressedImage copies of the sensor data)",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=_run_export)
