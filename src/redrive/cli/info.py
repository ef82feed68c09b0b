"""``redrive info LOG`` — what a log holds, like ``rosbag info`` plus decoders and sensors."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from redrive.assembly.summary import LogSummary, summarize_log
from redrive.errors import LogDamagedError, LogError
from redrive.io import open_log

from ._map_options import lat_lon

__all__ = ["EXIT_DAMAGED", "damage_lines", "register"]

#: ``redrive info`` read a damaged log: what is intact is summarised, the damage listed.
EXIT_DAMAGED = 5

_EPILOG = """\
examples:
  redrive info drive.bag
  redrive info rosbag2_dir/ --json
  redrive info kitti/training --sensor-map sensors.toml
  redrive info cut.mcap --strict        exit 1 if the log is damaged at all
  redrive info scenario.tfrecord        what a recorded-traffic log holds (contains: …)
  redrive info map.osm --map-origin 49.0,8.4     a Lanelet2 map: source, extent, lanes …
  redrive info log/map/log_map_archive_X.json    an Argoverse 2 vector map

exit status: 0 intact, 5 damaged (read past the damage; the damage is listed), 1 an error.
"""


#: above this many topics the table is printed as plain aligned text, not with rich.
_RICH_ROWS = 2000


def _human_bytes(n: int | None) -> str:
    if n is None:
        return "-"
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{n} B"


def _print_table(summary: LogSummary) -> None:
    from rich.console import Console
    from rich.table import Table

    from redrive.output.text import shown

    console = Console(width=None if sys.stdout.isatty() else 160)
    console.print(f"[bold]path[/]:      {shown(str(summary.path))}")
    console.print(f"[bold]format[/]:    {summary.format}")
    console.print(f"[bold]provides[/]:  {', '.join(summary.provides)}")
    console.print(f"[bold]duration[/]:  {summary.duration_s:.3f} s")
    console.print(f"[bold]start[/]:     {summary.start_utc}  ({summary.start_ns} ns)")
    console.print(f"[bold]end[/]:       {summary.end_utc}  ({summary.end_ns} ns)")
    console.print(f"[bold]messages[/]:  {summary.messages}  ({_human_bytes(summary.size_bytes)})")
    for name, value in summary.contents:
        what = f"{value} {name}" if isinstance(value, int) else f"{name}: {value}"
        console.print(f"[bold]contains[/]:  {shown(what)}", highlight=False)
    columns = (
        ("topic", "left"),
        ("type", "left"),
        ("count", "right"),
        ("rate Hz", "right"),
        ("bytes", "right"),
        ("decoder", "left"),
        ("maps to", "left"),
    )
    rows = []
    for t in summary.topics:
        decoder = t.decoder or ("raw" if t.has_definition else "raw (no definition)")
        rows.append(
            (
                shown(t.topic),
                shown(t.msgtype),
                str(t.count),
                "-" if t.rate_hz is None else f"{t.rate_hz:.2f}",
                _human_bytes(t.size_bytes),
                shown(decoder),
                shown(t.maps_to or ""),
            )
        )
    if len(rows) > _RICH_ROWS:  # rich lays a table out at ~1 ms a row: 50k topics took minutes
        console.file.write(_plain_table(columns, rows))
    else:
        table = Table(show_lines=False)
        for col, just in columns:
            table.add_column(col, justify=just)  # type: ignore[arg-type]
        for row in rows:
            table.add_row(*row)
        console.print(table)
    if summary.damage_report or summary.damage:
        lines = damage_lines(summary)
        console.print(f"[bold red]damaged[/]: {shown(lines[0])}")
        for line in lines[1:]:
            console.print(f"  {shown(line)}", highlight=False)


def _plain_table(columns: tuple[tuple[str, str], ...], rows: Sequence[tuple[str, ...]]) -> str:
    """The table as aligned plain text (for logs with more than :data:`_RICH_ROWS` topics)."""
    widths = [max(len(name), *(len(r[i]) for r in rows)) for i, (name, _) in enumerate(columns)]

    def line(cells: tuple[str, ...]) -> str:
        return "  ".join(
            c.rjust(w) if just == "right" else c.ljust(w)
            for c, w, (_, just) in zip(cells, widths, columns, strict=True)
        ).rstrip()

    head = line(tuple(name for name, _ in columns))
    return "\n".join([head, "-" * len(head), *(line(r) for r in rows)]) + "\n"


def damage_lines(summary: LogSummary) -> list[str]:
    """The damage of a log in words: a headline, one line per damaged part, what to do."""
    report = summary.damage_report
    if not report:
        return [summary.damage or "", _advice(summary)]
    known, unknown = summary.messages_lost
    lost = f"{known} message{'s' if known != 1 else ''} lost" + (
        " (and an unknown number more)" if unknown and known else ""
    )
    if unknown and not known:
        lost = "an unknown number of messages lost"
    head = (
        f"{len(report)} damaged part{'s' if len(report) != 1 else ''} skipped, {lost}; "
        f"{summary.messages} messages were read"
    )
    return [head, *(str(d) for d in report), _advice(summary)]


def _advice(summary: LogSummary) -> str:
    fixed = Path(summary.path).with_suffix("").name + "-repaired.mcap"
    return (
        f"`redrive repair {summary.path} -o {fixed}` writes what is intact to a valid MCAP; "
        "`redrive run` and `redrive gui` read the intact part"
    )


def _run(args: argparse.Namespace) -> int:
    from redrive.maps.files import map_format  # maps (shapely, scipy): only for `info`

    fmt = map_format(args.log)
    if fmt is not None:
        from redrive.cli.info_map import run_map_info

        return run_map_info(args, fmt)
    io_logger = logging.getLogger("redrive.io")
    level = io_logger.level
    if not args.verbose:  # the damage is listed below: no warning per damaged part
        io_logger.setLevel(logging.ERROR)
    try:
        with open_log(args.log, strict=args.strict) as log:
            summary = summarize_log(log, sensor_map_path=args.sensor_map)
            road_map, map_error = _log_map(log)
    finally:
        io_logger.setLevel(level)
    if args.strict and (summary.damage_report or summary.damage):
        msg = (
            f"{args.log}: damaged at "
            + "; ".join(str(d) for d in summary.damage_report)
            + "; --strict refuses damaged logs (without it redrive reads past the damage)"
            if summary.damage_report
            else str(summary.damage)
        )
        raise LogDamagedError(msg, messages_read=summary.messages)
    # the reader's capability says a map can be asked for (any MCAP file); "provides" says
    # whether this log holds one (a converted bag does not)
    has_map = road_map is not None or map_error is not None
    if summary.capabilities.road_map and not has_map:
        summary = replace(summary, capabilities=replace(summary.capabilities, road_map=False))
    map_summary = None
    if road_map is not None:
        from redrive.maps.files import summarize_map

        map_summary = summarize_map(road_map, path=args.log, fmt=summary.format)
    if args.json:
        doc = summary.to_json()
        if map_summary is not None:
            doc["map"] = map_summary.to_json()
        if map_error is not None:
            doc["map_error"] = map_error
        # one write: json.dump writes each token on its own (2 million writes for 50k topics)
        sys.stdout.write(json.dumps(doc, indent=2) + "\n")
    else:
        _print_table(summary)
        _print_map(map_summary, map_error)
    return EXIT_DAMAGED if summary.damage or summary.damage_report else 0


def _log_map(log: Any) -> tuple[Any, str | None]:
    """The road map a log holds (None when none) and, when it cannot be read, why."""
    from redrive.errors import MapError
    from redrive.io.content import log_road_map

    try:
        return log_road_map(log), None
    except (MapError, LogError) as err:
        return None, str(err)


def _print_map(map_summary: Any, map_error: str | None) -> None:
    """The map lines of a log with a road map (as ``redrive info MAPFILE`` prints them)."""
    if map_summary is None and map_error is None:
        return
    from rich.console import Console

    from redrive.cli.info_map import map_lines
    from redrive.output.text import shown

    console = Console(width=None if sys.stdout.isatty() else 160)
    if map_error is not None:
        console.print(f"[bold red]map[/]:       unreadable: {shown(map_error)}", highlight=False)
        return
    for label, text in map_lines(map_summary):
        head = f"map {label}:"
        pad = " " * max(1, 15 - len(head))
        console.print(f"[bold]{head}[/]{pad}{shown(text)}", highlight=False)


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "info",
        help="summarise a log: topics, types, counts, rates, decoders, sensors",
        description=(
            "Print a log's time range and, per topic, its type, message count, rate, bytes, the "
            "decoder redrive uses and the sensor it maps to. A damaged log (cut off, a corrupt "
            "chunk or record) is read past its damage: what is intact is summarised, each "
            "damaged part is listed with its byte range and the messages it lost, and the exit "
            "status is 5 (1 with --strict, which refuses damaged logs)."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "log",
        type=Path,
        help=(
            "a .bag, .mcap, ROS 2 bag directory, KITTI folder, nuScenes data root, mmdetection3d "
            "info file, Argoverse 2 sensor log folder, Waymo Open Motion .tfrecord or CommonRoad "
            ".xml; or a map file (Lanelet2 .osm, Argoverse 2 log_map_archive_*.json, map.json)"
        ),
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of a table")
    parser.add_argument(
        "--strict",
        action="store_true",
        help="refuse a damaged log: stop at the first damage with an error (exit status 1)",
    )
    parser.add_argument(
        "--sensor-map",
        type=Path,
        default=None,
        help="TOML file that overrides the topic → sensor mapping",
    )
    parser.add_argument(
        "--map-origin",
        type=lat_lon,
        default=None,
        metavar="LAT,LON",
        help="a Lanelet2 map's projection origin, degrees (default: the map's local_x/local_y, "
        "else its first node)",
    )
    parser.set_defaults(func=_run)
