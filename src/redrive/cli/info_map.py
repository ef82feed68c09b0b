"""``redrive info MAPFILE`` — what a map file holds (Lanelet2 OSM, Argoverse 2 vector map, a
run's map.json): its source, extent and element counts."""

from __future__ import annotations

import argparse
import json
import sys

from redrive.maps.files import MapSummary, read_map_file, summarize_map
from redrive.maps.lanelet2_osm import first_node

__all__ = ["map_lines", "run_map_info"]


def map_lines(summary: MapSummary) -> list[tuple[str, str]]:
    """(label, text) of what a map holds: its source, extent, lanes and other elements (the
    lines of ``redrive info MAPFILE``, and of ``redrive info LOG`` for a log with a map)."""
    rows = [("source", summary.source or "-")]
    if summary.extent is not None:
        x0, y0, x1, y1 = summary.extent
        rows.append(
            (
                "extent",
                f"x {x0:.1f} … {x1:.1f} m, y {y0:.1f} … {y1:.1f} m "
                f"({x1 - x0:.0f} × {y1 - y0:.0f} m, frame {summary.frame_id})",
            )
        )
    kinds = ", ".join(f"{n} {k}" for k, n in summary.lane_kinds.items())
    rows.append(
        (
            "lanes",
            f"{summary.lanes} ({kinds}), {summary.lane_length_m / 1000:.2f} km; "
            f"{summary.with_successors} with successors, {summary.with_neighbors} with neighbours",
        )
    )
    rows.append(
        (
            "elements",
            f"{summary.roadblocks} roadblocks, {summary.intersections} intersections, "
            f"{summary.areas} drivable areas, {summary.crosswalks} crosswalks, "
            f"{summary.stop_lines} stop lines, {summary.traffic_lights} traffic lights",
        )
    )
    return rows


def _print(summary: MapSummary, note: str | None) -> None:
    from rich.console import Console

    from redrive.output.text import shown

    console = Console(width=None if sys.stdout.isatty() else 160)
    console.print(f"[bold]path[/]:      {shown(summary.path)}")
    console.print(f"[bold]format[/]:    {summary.format} map")
    rows = map_lines(summary)
    console.print(f"[bold]source[/]:    {shown(rows[0][1])}")
    if note:
        console.print(f"[bold]origin[/]:    {shown(note)}")
    for label, text in rows[1:]:
        console.print(f"[bold]{label}[/]:{' ' * (10 - len(label))}{shown(text)}")


def run_map_info(args: argparse.Namespace, fmt: str) -> int:
    """``redrive info`` of a map file of format ``fmt``; 0 (a bad map raises MapError)."""
    origin = args.map_origin
    note = None
    if fmt == "lanelet2" and origin is None:
        lat, lon, tags = first_node(args.log)
        if not ("local_x" in tags and "local_y" in tags):
            origin = (lat, lon)
            note = (
                f"the map gives none: its first node (lat {lat}, lon {lon}); "
                "--map-origin LAT,LON sets it"
            )
    road_map = read_map_file(args.log, origin_lat_lon=origin)
    summary = summarize_map(road_map, path=args.log, fmt=fmt)
    if args.json:
        doc = summary.to_json()
        if note:
            doc["origin_note"] = note
        sys.stdout.write(json.dumps(doc, indent=2) + "\n")
    else:
        _print(summary, note)
    return 0
