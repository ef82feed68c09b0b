"""``python -m benchmarks serve`` — ``redrive serve`` of the demo log at 1x to a client on loopback."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner

__all__ = ["add_serve_parser"]

_DESCRIPTION = """\
Make the demo log once (`redrive synth urban --duration 20`; --log takes an existing log), count
what `redrive serve` sends of it, then run `redrive serve LOG --port 0 --rate R` as a child
process and receive it on loopback with a WebSocket client (websockets) subscribed to every
channel. Reports per channel the messages sent and received, the dropped ones (target for issue
18: no dropped frames at 1x), the lag (receive time - log time, less its smallest value: p50,
p99, max), the server's CPU over the playback and the load average.
"""


def _run_serve(args: argparse.Namespace) -> int:
    from rich.table import Table

    from benchmarks.serve import bench_serve

    with spinner() as progress:
        result = bench_serve(
            log=args.log,
            workdir=args.workdir,
            duration_s=args.duration,
            rate=args.rate,
            progress=progress,
        )
    if args.json:
        print_json(result.to_json())
        return 0
    console = report_console()
    table = Table(title=f"redrive serve {result.log} at {result.rate:g}x", title_justify="left")
    for col in ("channel", "schema", "sent", "received", "dropped"):
        table.add_column(col, justify="left" if col in ("channel", "schema") else "right")
    for c in result.channels:
        table.add_row(c.topic, c.schema, str(c.sent), str(c.received), str(c.dropped))
    table.add_row("total", "", str(result.sent), str(result.received), str(result.dropped))
    console.print(table)
    verdict = "[green]meets[/]" if result.dropped_frames == 0 else "[red]misses[/]"
    console.print(
        f"dropped frames (clouds and images): {result.dropped_frames} of {result.frames} "
        f"{verdict} 'no dropped frames at 1x'"
    )
    console.print(
        f"lag p50 {result.lag_p50_ms:.1f} ms, p99 {result.lag_p99_ms:.1f} ms, max "
        f"{result.lag_max_ms:.1f} ms  |  playback {result.play_wall_s:.1f} s for "
        f"{result.log_span_s:.1f} s of log"
    )
    console.print(
        f"server CPU {result.server_cpu_s:.1f} s ({result.server_cpu_percent:.0f} % of a core), "
        f"client CPU {result.client_cpu_s:.1f} s  |  load average {result.load_before:.1f} → "
        f"{result.load_after:.1f}"
    )
    return 0


def add_serve_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "serve",
        help="redrive serve of the demo log at 1x to a WebSocket client: dropped frames, lag, CPU",
        description=_DESCRIPTION,
        epilog="examples:\n  python -m benchmarks serve\n  python -m benchmarks serve --log urban.mcap --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--log", type=Path, metavar="LOG", help="serve this log, not the demo")
    parser.add_argument(
        "--duration",
        type=float,
        default=20.0,
        metavar="S",
        help="seconds of the demo log made when --log is not given (default 20)",
    )
    parser.add_argument(
        "--rate", type=float, default=1.0, help="playback speed, times real time (default 1)"
    )
    parser.add_argument(
        "--workdir",
        type=Path,
        metavar="DIR",
        help="where the demo log is written (default: a temporary directory)",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=_run_serve)
