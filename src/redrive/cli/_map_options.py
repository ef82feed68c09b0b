"""``--map FILE``, ``--map-origin LAT,LON`` and ``--no-map``: the options `run`, `evaluate`,
`gui` and `batch` share (:mod:`redrive.engine.user_map` does the work)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from redrive.engine.user_map import MapOption

__all__ = ["add_map_options", "lat_lon", "map_option"]


def lat_lon(text: str) -> tuple[float, float]:
    """``"49.0,8.4"`` → (49.0, 8.4), checked to be a latitude and a longitude."""
    try:
        lat, lon = (float(v) for v in text.split(","))
    except ValueError as err:
        msg = f"expected LAT,LON in degrees (e.g. 49.0,8.4), got {text!r}"
        raise argparse.ArgumentTypeError(msg) from err
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        msg = f"latitude must be in [-90, 90] and longitude in [-180, 180], got {text!r}"
        raise argparse.ArgumentTypeError(msg)
    return lat, lon


def add_map_options(parser: Any, *, stored: bool, no_map: bool = True) -> None:
    """Add the options (``no_map``: with ``--no-map``); ``stored``: the command writes the map
    into the run (run, batch), else it attaches it to an existing run (evaluate, gui)."""
    where = "the log's" if stored else "the run's log's"
    wins = "a map the log carries" if stored else "a map the run has"
    group = parser.add_mutually_exclusive_group()
    group.add_argument(
        "--map",
        type=Path,
        metavar="FILE",
        dest="map_file",
        help=(
            "a road map: Lanelet2 .osm, Argoverse 2 log_map_archive_*.json, a run's map.json or "
            f"a CommonRoad scenario .xml; placed in {where} frame through its `map` frame (the "
            "ego's poses or its tf) or --map-origin, stored in the run (RUN/map.json; the "
            f"manifest's `map` says where it came from); it wins over {wins} (with a warning)"
        ),
    )
    if no_map:
        group.add_argument(
            "--no-map",
            action="store_true",
            help="no road map at all (not even the log's own): the map metrics are skipped; for "
            "a damaged map, or a log without a frame to place one in",
        )
    parser.add_argument(
        "--map-origin",
        type=lat_lon,
        default=None,
        metavar="LAT,LON",
        help="with --map: a Lanelet2 map's projection origin, degrees (default: the map's own "
        "local_x/local_y); for a log without a `map` frame, the origin of the ego's frame",
    )


def map_option(args: argparse.Namespace) -> MapOption | None:
    """The :class:`~redrive.engine.user_map.MapOption` of the parsed options (None: no option
    given: the log's own map)."""
    from redrive.engine.user_map import MapOption
    from redrive.errors import ConfigError

    path = getattr(args, "map_file", None)
    origin = getattr(args, "map_origin", None)
    disabled = bool(getattr(args, "no_map", False))
    if path is None and origin is None and not disabled:
        return None
    if origin is not None and path is None:
        msg = "--map-origin is the origin of the map given with --map FILE: add --map"
        raise ConfigError(msg)
    return MapOption(path=path, origin_lat_lon=origin, disabled=disabled)
