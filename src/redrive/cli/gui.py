"""``redrive gui`` — the desktop GUI (needs the ``gui`` extra: PySide6, pyqtgraph, PyOpenGL)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ._map_options import add_map_options, map_option

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive gui                           an empty window: File → Open log / Open run
  redrive gui drive.bag                 play a log: planview, camera, plots, timeline
  redrive gui runs/a                    a run over its log: detections beside ground truth,
                                        failure bookmarks from `redrive evaluate` on the timeline
  redrive gui runs/a --map map.osm      give the run a road map first (stored in it): lanes,
                                        boundaries, crosswalks and lights on the planview
  make gui                              installs the extra and opens the demo run

Keys: space plays/pauses, ←/→ step.  The window layout is remembered between sessions.
"""


def _run(args: argparse.Namespace) -> int:
    from redrive.gui.preflight import require_display, require_gui

    require_gui()
    require_display()
    option = map_option(args)
    if option is not None:
        from redrive.engine.user_map import attach_map
        from redrive.errors import ConfigError

        if args.path is None or not (args.path / "manifest.json").is_file():
            msg = "--map gives a run its road map: open a run directory (`redrive run LOG --map`)"
            raise ConfigError(msg)
        attach_map(args.path, option)
    from redrive.gui.main import run_gui

    return run_gui(args.path)


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "gui",
        help="the desktop GUI: camera, 2D/3D planview, timeline, plots, re-simulation",
        description=(
            "Open the desktop GUI on a log (ROS 1/2 bag, MCAP, KITTI, nuScenes) or a run directory. "
            "Logs are streamed: the first frame shows while the timeline is still being indexed. "
            "A run shows its algorithms' outputs beside the ground truth, its per-frame metrics "
            "and its failure bookmarks. Live: connect to a ROS 1 master and pick topics. "
            "Re-simulation: run an installed algorithm over the log, see its result over the "
            "ground truth, export CSV/Excel."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("path", nargs="?", type=Path, help="a log or a run directory")
    add_map_options(parser, stored=False, no_map=False)
    parser.set_defaults(func=_run)
