"""Imported once by the local executor's forkserver, so that every cell — a fresh fork of it —
starts with what a cell imports already in memory: the log readers (and the ROS type stores they
build on), the reference algorithms (and SciPy under them), the engine, and pandas (which a cell
reaches through its readers).  Without it each cell paid ~2 s of imports (``redrive bench
batch``); the server pays them once.  Optional dependencies that are missing are left out."""

from __future__ import annotations

import importlib
import logging

__all__ = ["PRELOAD"]

logger = logging.getLogger(__name__)

#: what the server imports (in order); a module that fails to import is skipped.
PRELOAD = (
    "redrive.engine.run",
    "redrive.io.recognise",
    "redrive.io.typestore",
    "redrive.io._deserialize",
    "redrive.io.ros1bag",
    "redrive.io.ros2bag",
    "redrive.io.mcapfile",
    "redrive.io.kitti",
    "redrive.algorithms.reference.detector",
    "redrive.algorithms.reference.planner",
    "redrive.algorithms.reference.controller",
    "redrive.algorithms.reference.tracker",
    "redrive.algorithms.reference.oracle",
    "pandas",
)

for _name in PRELOAD:
    try:
        importlib.import_module(_name)
    except ImportError as _err:  # an optional extra not installed: its cells import it themselves
        logger.debug("preload: %s not imported (%s)", _name, _err)
