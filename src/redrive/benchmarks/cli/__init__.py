"""``redrive bench …``: the argument parsers and reports of the benchmarks, one module per
benchmark; :func:`register` adds the ``bench`` command group to redrive's CLI (which imports this
package only to register it).  Each handler imports its benchmark when it runs."""

from __future__ import annotations

import argparse
from typing import Any

from redrive.benchmarks.cli.batch import add_batch_parser, add_fleet_parser
from redrive.benchmarks.cli.closed_loop import add_closed_loop_parser
from redrive.benchmarks.cli.engine import add_engine_parser
from redrive.benchmarks.cli.eval import add_eval_parser
from redrive.benchmarks.cli.export import add_export_parser
from redrive.benchmarks.cli.gui import add_gui_parser
from redrive.benchmarks.cli.lidar import add_lidar_parser
from redrive.benchmarks.cli.loss import add_loss_parser
from redrive.benchmarks.cli.read import EPILOG as _EPILOG
from redrive.benchmarks.cli.read import add_read_parser
from redrive.benchmarks.cli.record import add_record_parser
from redrive.benchmarks.cli.record_ros2 import add_record_ros2_parser
from redrive.benchmarks.cli.serve import add_serve_parser
from redrive.benchmarks.cli.suite import add_all_parser
from redrive.benchmarks.cli.transport import add_transport_parser

__all__ = ["register"]


def _run_group(args: argparse.Namespace) -> int:
    args.bench_parser.print_help()
    return 2


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "bench",
        help="benchmarks against a baseline measured in the same run",
        description="Benchmarks of redrive against a third-party baseline measured in the same run.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.set_defaults(func=_run_group, bench_parser=parser)
    bench_sub = parser.add_subparsers(dest="bench_command", metavar="BENCHMARK")
    add_read_parser(bench_sub)
    add_lidar_parser(bench_sub)
    add_engine_parser(bench_sub)
    add_closed_loop_parser(bench_sub)
    add_batch_parser(bench_sub)
    add_fleet_parser(bench_sub)
    add_eval_parser(bench_sub)
    add_transport_parser(bench_sub)
    add_loss_parser(bench_sub)
    add_record_parser(bench_sub)
    add_record_ros2_parser(bench_sub)
    add_gui_parser(bench_sub)
    add_export_parser(bench_sub)
    add_serve_parser(bench_sub)
    add_all_parser(bench_sub)
