"""``python -m benchmarks NAME …``: the argument parsers and reports of the benchmarks outside the
package, one module per benchmark (each handler imports its benchmark when it runs)."""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from typing import Any

from benchmarks.cli.batch import add_batch_parser, add_fleet_parser
from benchmarks.cli.eval import add_eval_parser
from benchmarks.cli.export import add_export_parser
from benchmarks.cli.gui import add_gui_parser
from benchmarks.cli.lidar import add_lidar_parser
from benchmarks.cli.loss import add_loss_parser
from benchmarks.cli.read_synth import add_read_synth_parser
from benchmarks.cli.record import add_record_parser
from benchmarks.cli.record_ros2 import add_record_ros2_parser
from benchmarks.cli.serve import add_serve_parser
from benchmarks.cli.suite import add_all_parser
from benchmarks.cli.transport import add_peers_parser
from redrive.errors import RedriveError

__all__ = ["add_commands", "build_parser", "main"]

_EPILOG = """\
examples:
  PYTHONPATH=src python -m benchmarks all --out bench-summary.md     the whole set (make bench)
  PYTHONPATH=src python -m benchmarks transport --sides redrive-inplace,iceoryx2 --repeat 3
  PYTHONPATH=src python -m benchmarks loss --minutes 30

What a user measures on their own machine stays in `redrive bench` (read, engine, closed-loop,
transport); see benchmarks/README.md and BENCHMARKS.md.
"""


def add_commands(sub: Any) -> None:
    """Every benchmark of this package as a subcommand of ``sub``."""
    add_read_synth_parser(sub)
    add_lidar_parser(sub)
    add_batch_parser(sub)
    add_fleet_parser(sub)
    add_eval_parser(sub)
    add_peers_parser(sub)
    add_loss_parser(sub)
    add_record_parser(sub)
    add_record_ros2_parser(sub)
    add_gui_parser(sub)
    add_export_parser(sub)
    add_serve_parser(sub)
    add_all_parser(sub)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks",
        description="redrive against peers, soak and whole-system benchmarks (not installed).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    add_commands(parser.add_subparsers(dest="bench_command", metavar="BENCHMARK"))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one benchmark; 0 ok, 1 a redrive error (printed without a traceback), 2 bad usage."""
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING - 10 * min(int(args.verbose), 2))
    if not getattr(args, "bench_command", None):
        parser.print_help()
        return 2
    try:
        status: int = args.func(args)
    except RedriveError as err:
        print(f"benchmarks: error: {err}", file=sys.stderr)
        return 1
    return status
