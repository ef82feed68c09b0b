"""``redrive convert IN OUT`` — any readable log to MCAP (ROS 2 CDR) or a ROS 1 bag."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Any

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive convert drive.bag drive.mcap                  ROS 1 bag → MCAP (ROS 2 CDR)
  redrive convert kitti/training kitti.mcap             KITTI frames → MCAP, opens in Foxglove
  redrive convert rosbag2_dir/ out.bag --topics /imu    ROS 2 bag → ROS 1 bag, one topic
  redrive convert cut.bag saved.mcap --skip-damaged     keep what a damaged log still holds
"""


def _seconds_to_ns(value: float | None, origin_ns: int) -> int | None:
    return None if value is None else origin_ns + round(value * 1e9)


def _run(args: argparse.Namespace) -> int:
    from redrive.io import open_log
    from redrive.io.convert import convert_log
    from redrive.output.progress import ProgressBar

    io_logger = logging.getLogger("redrive.io")
    level = io_logger.level
    io_logger.setLevel(logging.ERROR)  # the conversion opens it again and warns of what it finds
    try:
        with open_log(args.input, strict=not args.skip_damaged, packets="raw") as log:
            origin = log.start_ns
            total = log.message_count
    finally:
        io_logger.setLevel(level)
    start_ns = _seconds_to_ns(args.start, origin)
    stop_ns = _seconds_to_ns(args.end, origin)
    with ProgressBar("converting", total=total, unit="messages") as bar:

        def progress(done: int, total: int) -> None:
            bar.update(done, total=max(total, done))

        stats = convert_log(
            args.input,
            args.output,
            topics=args.topics,
            start_ns=start_ns,
            stop_ns=stop_ns,
            progress=progress,
            strict=not args.skip_damaged,
        )
    print(
        f"wrote {stats.output_path} ({stats.output_format}): {stats.messages_written} messages "
        f"on {len(stats.topics)} topics"
    )
    for topic, why in stats.skipped_topics.items():
        print(f"  left out {topic}: {why}")
    if stats.messages_skipped:
        print(f"  {stats.messages_skipped} messages did not convert (see the warnings above)")
    return 0


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "convert",
        help="convert a log to MCAP (ROS 2 CDR) or a ROS 1 bag",
        description=(
            "Convert any log redrive reads (ROS 1/ROS 2 bag, MCAP, KITTI, nuScenes) to MCAP with ROS 2 CDR "
            "messages and embedded schemas (opens in Foxglove, Lichtblick and ROS 2 tools), or to "
            "a ROS 1 bag; the output format follows OUTPUT's suffix (.mcap or .bag). Messages are "
            "re-encoded field by field, not decoded to redrive's data model, so nothing is lost. "
            "The output is written to a temporary file and renamed when complete."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("input", type=Path, help="the log to read")
    parser.add_argument("output", type=Path, help="the file to write: *.mcap or *.bag")
    parser.add_argument("--topics", nargs="+", default=None, help="only these topics")
    parser.add_argument("--start", type=float, default=None, help="seconds from the log start")
    parser.add_argument("--end", type=float, default=None, help="seconds from the log start")
    parser.add_argument(
        "--skip-damaged",
        action="store_true",
        help="read past damage (corrupt chunks, a cut-off end, a missing index) instead of "
        "stopping with an error (without it any damage `redrive info` lists refuses the log)",
    )
    parser.set_defaults(func=_run)
