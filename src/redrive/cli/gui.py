"""``redrive gui`` — the desktop GUI (needs the ``gui`` extra: PySide6, pyqtgraph, PyOpenGL)."""

from __future__ import annotations

import argparse
import importlib.util
import os
from pathlib import Path
from typing import Any

from redrive.errors import ConfigError

__all__ = ["register", "require_display", "require_gui"]

_EPILOG = """\
examples:
  redrive gui                           an empty window: File → Open log / Open run
  redrive gui drive.bag                 play a log: planview, camera, plots, timeline
  redrive gui runs/a                    a run over its log: detections beside ground truth,
                                        failure bookmarks from `redrive evaluate` on the timeline
  make gui                              installs the extra and opens the demo run

Keys: space plays/pauses, ←/→ step.  The window layout is remembered between sessions.
"""


def require_gui() -> None:
    """Raise a ConfigError saying how to install the GUI when PySide6/pyqtgraph are missing."""
    missing = [m for m in ("PySide6", "pyqtgraph", "OpenGL") if importlib.util.find_spec(m) is None]
    if missing:
        msg = (
            f"the GUI needs {', '.join(missing)}: install redrive's gui extra "
            "(pip install 'redrive[gui]', or `make gui` in the repository)"
        )
        raise ConfigError(msg)


def require_display() -> None:
    """Raise a ConfigError when Qt would find no display (it aborts the process instead)."""
    if os.environ.get("QT_QPA_PLATFORM"):
        return
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        msg = (
            "no display: `redrive gui` needs a desktop session (DISPLAY or WAYLAND_DISPLAY); on "
            "a headless machine run it under Xvfb: xvfb-run -a redrive gui …"
        )
        raise ConfigError(msg)


def _run(args: argparse.Namespace) -> int:
    require_gui()
    require_display()
    from redrive.gui.main import run_gui

    return run_gui(args.path)


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "gui",
        help="the desktop GUI: camera, 2D/3D planview, timeline, plots, re-simulation",
        description=(
            "Open the desktop GUI on a log (ROS 1/2 bag, MCAP, KITTI) or a run directory. "
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
    parser.set_defaults(func=_run)
