"""``redrive bench …``: the argument parsers and reports of the benchmarks, one module per
benchmark; :func:`register` adds the ``bench`` command group to redrive's CLI (which imports this
package only to register it).  Each handler imports its benchmark when it runs."""

from __future__ import annotations

import argparse
from typing import Any

from redrive.benchmarks.cli.closed_loop import add_closed_loop_parser
from redrive.benchmarks.cli.engine import add_engine_parser
from redrive.benchmarks.cli.eval import add_eval_parser
from redrive.benchmarks.cli.read import EPILOG as _EPILOG
from redrive.benchmarks.cli.read import add_read_parser
from redrive.benchmarks.cli.transport import add_transport_parser

__all__ = ["register"]


def _run_group(args: argparse.Namespace) -> int:
    args.bench_parser.print_help()
    return 2


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "bench",
        help="benchmarks of this machine and your logs against a baseline measured in the same run",
        description="Benchmarks of redrive on this machine and your logs, each against a baseline "
        "measured in the same run: read, engine, closed-loop, transport; and the CPU cost of each metric on a run (eval). (Comparisons against "
        "peers, soak and whole-system benchmarks: benchmarks/ in a checkout, `make bench`.)",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.set_defaults(func=_run_group, bench_parser=parser)
    bench_sub = parser.add_subparsers(dest="bench_command", metavar="BENCHMARK")
    add_read_parser(bench_sub)
    add_engine_parser(bench_sub)
    add_closed_loop_parser(bench_sub)
    add_transport_parser(bench_sub)
    add_eval_parser(bench_sub)
