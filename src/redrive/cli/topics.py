"""``redrive topics`` — the topics of a running ROS 1 master, their types and decoders."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from redrive.live.ros1 import DEFAULT_MASTER_URI, TopicInfo, default_master_uri, list_topics

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive topics                                   the master of $ROS_MASTER_URI
  redrive topics --master http://10.0.0.2:11311
  redrive topics --json
"""


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value > 0:
        msg = f"{text!r} is not a positive number of seconds"
        raise argparse.ArgumentTypeError(msg)
    return value


def _uses(topic: TopicInfo) -> str:
    if topic.sensor_type is not None:
        return topic.sensor_type.value
    return topic.kind.value if topic.kind is not None else ""


def _print_table(uri: str, topics: list[TopicInfo]) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=None if sys.stdout.isatty() else 160)
    decodable = sum(t.decodable for t in topics)
    console.print(f"[bold]master[/]:  {uri}")
    console.print(f"[bold]topics[/]:  {len(topics)} ({decodable} decodable by redrive)")
    if not topics:
        return
    table = Table(show_lines=False)
    for col in ("topic", "type", "publishers", "decoder", "feeds"):
        table.add_column(col)
    for t in topics:
        table.add_row(
            t.name,
            t.msg_type,
            ", ".join(t.publishers) or "-",
            t.decoder or "raw",
            _uses(t),
        )
    console.print(table)


def _run(args: argparse.Namespace) -> int:
    uri = args.master or default_master_uri()
    topics = list_topics(uri, timeout_s=args.timeout)
    if args.json:
        json.dump({"master": uri, "topics": [t.to_dict() for t in topics]}, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        _print_table(uri, topics)
    return 0


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "topics",
        help="list the topics of a running ROS 1 master: types, publishers, decoders",
        description=(
            "Ask a running ROS 1 master (its XML-RPC API; rospy is not needed) which topics it "
            "knows and print, per topic, its message type, the nodes publishing it, the redrive "
            "decoder of the type and the sensor it feeds (raw: redrive does not decode it). "
            "The exit status is 1 when no master answers."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--master",
        metavar="URI",
        default=None,
        help=f"the master's http://HOST:PORT (default: $ROS_MASTER_URI or {DEFAULT_MASTER_URI})",
    )
    parser.add_argument(
        "--timeout",
        type=_seconds,
        default=2.0,
        metavar="S",
        help="seconds to wait for the master's answer (default 2)",
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.set_defaults(func=_run)
