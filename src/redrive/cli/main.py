"""``redrive`` — entry point; each subcommand lives in its own module with a ``register``; the
``bench`` group lives in :mod:`redrive.benchmarks.cli` (a layer above the core)."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from redrive import __version__
from redrive.cli._address_space import fit_to_address_space
from redrive.errors import DiskFullError, RedriveError, is_no_space

__all__ = ["EXIT_DISK_FULL", "main"]

#: the exit status of a command that ran out of disk space (docs/exit_status.md)
EXIT_DISK_FULL = 6

#: subcommand modules under redrive.cli, in --help order; each has register(subparsers).
_COMMANDS = (
    "info",
    "topics",
    "live",
    "convert",
    "repair",
    "synth",
    "run",
    "batch",
    "export",
    "serve",
    "evaluate",
    "report",
    "compare",
    "algorithms",
    "new_algorithm",
    "gui",
)

_EPILOG = """\
examples:
  redrive info drive.bag                 topics, counts, rates, decoders of a log
  redrive convert drive.bag drive.mcap   any log (KITTI too) to MCAP or a ROS 1 bag
  redrive repair cut.mcap -o fixed.mcap  what a damaged log still holds, as a valid MCAP
  redrive synth urban -o urban.mcap      simulate a driving scenario into a log
  redrive run urban.mcap                 replay it through perception → planning → control
  redrive run drive.bag --perception my_detector.py:MyDetector --out runs/mine
  redrive batch drives/ --pipeline a.toml --pipeline b.toml --out batches/ab   many logs × pipelines
  redrive export runs/mine --format xlsx results as Excel (or csv, parquet; mcap for Foxglove)
  redrive serve runs/mine                the run over its log live in Foxglove (WebSocket)
  redrive evaluate runs/mine             detection, tracking, planning, control, latency metrics
  redrive report runs/mine               self-contained HTML report, Excel workbook, CSV files
  redrive compare runs/a runs/b          A/B: per-metric deltas, significance, worst frames
  redrive algorithms                     the installed algorithms
  redrive new-algorithm my_planner --role planning   a template to start from
  redrive gui runs/mine                  the desktop GUI: planview, camera, timeline, plots
  redrive bench read drive.bag           decoding speed against a raw read

Logs: ROS 1 .bag, ROS 2 bag directories (sqlite3/mcap), .mcap, KITTI object folders, nuScenes
(v1.0-*/ tables, or mmdetection3d info files).
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="redrive",
        description="Re-drive autonomous-driving algorithms on recorded sensor logs.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"redrive {__version__}")
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _COMMANDS:
        module = importlib.import_module(f"redrive.cli.{name}")
        module.register(sub)
    # `redrive bench …`: the benchmarks sit above the core (pyproject.toml's import contracts);
    # this registration is the one place the CLI imports them.
    from redrive.benchmarks.cli import register as register_bench

    register_bench(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the process exit status (docs/exit_status.md: 0 ok, 1 a redrive
    error, 2 bad usage, …); a Python traceback is printed only with ``-v``."""
    fit_to_address_space()  # before numpy, pyarrow and their threads are loaded
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # for hints that repeat the command
    level = logging.WARNING - 10 * min(int(args.verbose), 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        status: int = args.func(args)
    except DiskFullError as err:
        print(f"redrive: error: {err}", file=sys.stderr)
        return EXIT_DISK_FULL
    except RedriveError as err:
        if args.verbose:
            logging.getLogger("redrive").debug("the error, with its traceback", exc_info=True)
        print(f"redrive: error: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("redrive: interrupted", file=sys.stderr)
        return 130
    except OSError as err:
        if not is_no_space(err) or args.verbose:
            return _internal_error(args, err)
        where = f" writing {err.filename}" if err.filename else ""
        print(
            f"redrive: error: no space left{where} ({err.strerror}) in `redrive "
            f"{args.command}`: files it finished before are intact; free some space and run it "
            "again",
            file=sys.stderr,
        )
        return EXIT_DISK_FULL
    except Exception as err:  # a bug, or an error nothing translated: no traceback without -v
        return _internal_error(args, err)
    return status


def _internal_error(args: argparse.Namespace, err: Exception) -> int:
    if args.verbose:
        raise err
    print(
        f"redrive: internal error: {type(err).__name__}: {err}\n"
        f"  (in `redrive {args.command}`; run it again with -v for the traceback and "
        "report it with that output)",
        file=sys.stderr,
    )
    return 1
