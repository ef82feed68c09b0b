"""``redrive info LOG`` — what a log holds, like ``rosbag info`` plus decoders and sensors."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from redrive.errors import ConfigError, LogTruncatedError
from redrive.io import LogReader, open_log
from redrive.io.calibration import camera_info_topics
from redrive.io.decoders import decoder_for
from redrive.io.sensor_map import SensorSpec, infer_sensor_map, load_sensor_map_overrides

__all__ = ["collect_info", "register"]

_EPILOG = """\
examples:
  redrive info drive.bag
  redrive info rosbag2_dir/ --json
  redrive info kitti/training --sensor-map sensors.toml
"""


@dataclass(slots=True)
class _TopicStats:
    count: int = 0
    size_bytes: int = 0
    first_ns: int | None = None
    last_ns: int = 0


def _stamp(ns: int) -> str:
    return datetime.fromtimestamp(ns / 1e9, tz=UTC).isoformat(timespec="milliseconds")


def _camera_info_roles(log: LogReader, sensors: dict[str, SensorSpec]) -> dict[str, str]:
    """camera info topic → ``camera info of <sensor ids>`` (the cameras of its namespace)."""
    served: dict[str, list[str]] = {}
    for image_topic, info_topic in camera_info_topics(log.topics).items():
        spec = sensors.get(image_topic)
        served.setdefault(info_topic, []).append(spec.sensor_id if spec else image_topic)
    return {topic: f"camera info of {', '.join(names)}" for topic, names in served.items()}


def collect_info(log: LogReader, *, sensor_map_path: Path | None = None) -> dict[str, Any]:
    """Read the whole log once and summarise it (counts, bytes, rates from the real stamps)."""
    stats: dict[str, _TopicStats] = {t: _TopicStats() for t in log.topics}
    damage: str | None = None
    try:
        for message in log.messages():
            st = stats.setdefault(message.topic, _TopicStats())
            st.count += 1
            st.size_bytes += message.size_bytes
            if st.first_ns is None:
                st.first_ns = message.log_time_ns
            st.last_ns = message.log_time_ns
    except LogTruncatedError as err:
        damage = str(err)
    damage = damage or getattr(log, "damage", None)
    overrides = load_sensor_map_overrides(sensor_map_path) if sensor_map_path else None
    try:
        smap = infer_sensor_map(
            log.topics, duration_ns=log.end_ns - log.start_ns, overrides=overrides
        )
        sensors = {s.topic: s for s in smap.sensors}
        driver = smap.driver
        roles = {smap.vehicle_state_topic: "vehicle state", smap.ground_truth_topic: "ground truth"}
        roles.update(dict.fromkeys(smap.tf_topics, "tf"))
        roles.update(_camera_info_roles(log, sensors))
    except ConfigError:
        if sensor_map_path:
            raise
        sensors, driver, roles = {}, None, {}
    topics = []
    for topic, info in log.topics.items():
        st = stats[topic]
        decoder = decoder_for(info.msgtype)
        span_s = (st.last_ns - (st.first_ns or 0)) / 1e9
        spec = sensors.get(topic)
        maps_to = (
            f"{spec.sensor_id} ({spec.sensor_type.value}{', driver' if spec.sensor_id == driver else ''})"
            if spec
            else roles.get(topic, "")
        )
        topics.append(
            {
                "topic": topic,
                "type": info.msgtype,
                "count": st.count,
                "rate_hz": round((st.count - 1) / span_s, 3)
                if st.count > 1 and span_s > 0
                else None,
                "bytes": st.size_bytes if info.encoding != "native" else None,
                "decoder": decoder.name if decoder else None,
                "has_definition": info.has_definition,
                "maps_to": maps_to or None,
            }
        )
    start, end = log.start_ns, log.end_ns
    return {
        "path": str(log.path),
        "format": log.format,
        "start_ns": start,
        "end_ns": end,
        "start": _stamp(start),
        "end": _stamp(end),
        "duration_s": round((end - start) / 1e9, 6),
        "messages": sum(t["count"] for t in topics),
        "bytes": sum(t["bytes"] or 0 for t in topics),
        "topics": topics,
        "damage": damage,
    }


def _human_bytes(n: int | None) -> str:
    if n is None:
        return "-"
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{n} B"


def _print_table(info: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=None if sys.stdout.isatty() else 160)
    console.print(f"[bold]path[/]:      {info['path']}")
    console.print(f"[bold]format[/]:    {info['format']}")
    console.print(f"[bold]duration[/]:  {info['duration_s']:.3f} s")
    console.print(f"[bold]start[/]:     {info['start']}  ({info['start_ns']} ns)")
    console.print(f"[bold]end[/]:       {info['end']}  ({info['end_ns']} ns)")
    console.print(f"[bold]messages[/]:  {info['messages']}  ({_human_bytes(info['bytes'])})")
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
    for t in info["topics"]:
        decoder = t["decoder"] or ("raw" if t["has_definition"] else "raw (no definition)")
        table.add_row(
            t["topic"],
            t["type"],
            str(t["count"]),
            "-" if t["rate_hz"] is None else f"{t['rate_hz']:.2f}",
            _human_bytes(t["bytes"]),
            decoder,
            t["maps_to"] or "",
        )
    console.print(table)
    if info["damage"]:
        console.print(f"[bold red]damaged[/]: {info['damage']}")


def _run(args: argparse.Namespace) -> int:
    with open_log(args.log, strict=False) as log:
        info = collect_info(log, sensor_map_path=args.sensor_map)
    if args.json:
        json.dump(info, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        _print_table(info)
    return 1 if info["damage"] else 0


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
    parser.add_argument("log", type=Path, help="a .bag, .mcap, ROS 2 bag directory or KITTI folder")
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument(
        "--sensor-map",
        type=Path,
        default=None,
        help="TOML file that overrides the topic → sensor mapping",
    )
    parser.set_defaults(func=_run)
