"""``redrive repair LOG -o FIXED.mcap`` — what a damaged log still holds, as a valid MCAP."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Any

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive repair cut.mcap -o fixed.mcap          a recording killed mid-write
  redrive repair drive.bag -o drive.mcap         a ROS 1 bag without its index, or with a bad chunk
  redrive repair rosbag2_dir/ -o fixed.mcap      a ROS 2 bag whose storage is damaged
  redrive repair .urban.mcap.k2x9.part -o urban.mcap   what a killed `redrive synth` left

exit status: 0 nothing was damaged, 5 the log was damaged (what was lost is printed), 1 an error.
See docs/damaged_logs.md.
"""


def _run(args: argparse.Namespace) -> int:
    from redrive.cli.info import EXIT_DAMAGED
    from redrive.io.repair import repair_log

    io_logger = logging.getLogger("redrive.io")
    level = io_logger.level
    if not args.verbose:  # the damage is listed below: no warning per damaged part
        io_logger.setLevel(logging.ERROR)
    try:
        stats = repair_log(args.log, args.output, compression=args.compression)
    finally:
        io_logger.setLevel(level)
    print(
        f"wrote {stats.output_path}: {stats.messages_written} messages on {len(stats.topics)} "
        f"topics from the {stats.source_format} log {args.log}"
    )
    if not stats.damage and not stats.messages_dropped:
        print("nothing was damaged: every message was copied")
        return 0
    known, unknown = stats.messages_lost
    print(
        f"lost: {len(stats.damage)} damaged part{'s' if len(stats.damage) != 1 else ''}, "
        + (
            f"{known} messages" + (" and an unknown number more" if unknown else "")
            if known or not unknown
            else "an unknown number of messages"
        ),
        file=sys.stderr,
    )
    for damage in stats.damage:
        print(f"  {damage}", file=sys.stderr)
    if stats.messages_dropped:
        print(
            f"  {stats.messages_dropped} intact messages of channels whose channel or schema "
            "record was in a damaged part",
            file=sys.stderr,
        )
    return EXIT_DAMAGED


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "repair",
        help="save what a damaged log still holds to a valid, indexed MCAP",
        description=(
            "Read a damaged MCAP, ROS 1 bag or ROS 2 bag past its damage (a cut-off end, a "
            "corrupt chunk or record, a missing index) and write every intact message to a "
            "valid, indexed MCAP, keeping its bytes, channels, schemas and encodings. Prints "
            "what was lost; the exit status is 5 when something was, 0 when nothing was damaged."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("log", type=Path, help="the damaged .mcap, .bag or ROS 2 bag directory")
    parser.add_argument(
        "-o", "--output", type=Path, required=True, metavar="FIXED.mcap", help="the MCAP to write"
    )
    parser.add_argument(
        "--compression",
        choices=("zstd", "lz4", "none"),
        default="zstd",
        help="chunk compression of the output (default zstd)",
    )
    parser.set_defaults(func=_run)
