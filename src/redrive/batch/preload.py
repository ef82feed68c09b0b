"""Imported once by the local executor's forkserver, so that every cell — a fresh fork of it —
starts with what a cell imports already in memory: the log readers (and the ROS type stores they
build on), the reference algorithms (and SciPy under them), the engine, and pandas (which a cell
reaches through its readers).  Without it each cell paid ~2 s of imports (``redrive bench
batch``); the server pays them once.  Optional dependencies that are missing are left out.

Then the reference algorithms' numba kernels are loaded here (each algorithm's
``warm_kernels``, what its ``bind`` does before a run), and a few per-process caches filled
(:data:`CACHES`): numba's on-disk cache and its CPU target (registries, the NRT) were the largest
cost a fresh fork still paid per cell — a 2-frame cell forked from the server took 334–351 ms of
thread CPU before, 71–73 ms after; a second cell in one process takes 46–52 ms
(``benchmarks/batch_cell_profile.py``, BENCHMARKS.md).  A forked cell's ``bind`` then finds
the compiled kernels in its dispatchers, the same machine code, so results do not change.  This is
safe across ``fork`` because the kernels are plain ``njit`` (no ``parallel=True``: numba's
threading layer is never started) and loading them starts no thread; a test checks both.  A
kernel that fails to warm here is left to the cell, which loads or compiles it in its ``bind`` as
before (and reports the error there, if it is one).
"""

from __future__ import annotations

import importlib
import logging

__all__ = ["CACHES", "PRELOAD", "WARM"]

logger = logging.getLogger(__name__)

#: what the server imports (in order); a module that fails to import is skipped.
PRELOAD = (
    "redrive.engine.run",
    "redrive.io.recognise",
    "redrive.io.ros.typestore",
    "redrive.io.ros.deserialize",
    "redrive.io.rosbag1.reader",
    "redrive.io.rosbag2.reader",
    "redrive.io.mcap.reader",
    "redrive.io.datasets.kitti",
    "redrive.algorithms.reference.detector",
    "redrive.algorithms.reference.planner",
    "redrive.algorithms.reference.controller",
    "redrive.algorithms.reference.tracker",
    "redrive.algorithms.reference.oracle",
    "pandas",
)

#: (module, class) of the algorithms whose kernels the server loads: default configuration,
#: ``warm_kernels()``.  One whose module is missing or that fails is skipped.
WARM = (
    ("redrive.algorithms.reference.detector", "ClusterDetector"),
    ("redrive.algorithms.reference.planner", "IdmPlanner"),
    ("redrive.algorithms.reference.controller", "PurePursuitPid"),
    ("redrive.algorithms.reference.oracle", "NoisyOracle"),
)

#: (module, function, arguments) of per-process caches filled here (``functools.cache``d, never
#: mutated by their callers): the reader formats (redrive's and the ``redrive.readers`` entry
#: points, read once a process anyway) and the parsed ROS 1 / ROS 2 default type definitions that
#: every log's typestore starts from.  ≈ 45 ms of a forked cell's thread CPU (see above).
CACHES = (
    ("redrive.io.readers", "reader_formats", ()),
    ("redrive.io.ros.typestore", "_default_fielddefs", (1,)),
    ("redrive.io.ros.typestore", "_default_fielddefs", (2,)),
)


def preload(modules: tuple[str, ...] = PRELOAD) -> list[str]:
    """Import ``modules``; the names of those imported."""
    done = []
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as err:  # an optional extra not installed: its cells import it
            logger.debug("preload: %s not imported (%s)", name, err)
        else:
            done.append(name)
    return done


def warm(algorithms: tuple[tuple[str, str], ...] = WARM) -> list[str]:
    """Load the kernels of ``algorithms`` in this process; the class names warmed."""
    done = []
    for module, cls_name in algorithms:
        try:
            cls = getattr(importlib.import_module(module), cls_name)
            algorithm = cls()
            algorithm.configure()
            algorithm.warm_kernels()
        except Exception as err:  # the cell's own bind loads it (or fails) later
            logger.debug("preload: %s.%s not warmed (%s)", module, cls_name, err)
        else:
            done.append(cls_name)
    return done


def fill(caches: tuple[tuple[str, str, tuple[object, ...]], ...] = CACHES) -> int:
    """Call each of ``caches`` once; how many succeeded (a failure is left to the cell)."""
    done = 0
    for module, function, args in caches:
        try:
            getattr(importlib.import_module(module), function)(*args)
        except Exception as err:  # the cell calls it (and reports it) later
            logger.debug("preload: %s.%s%r not filled (%s)", module, function, args, err)
        else:
            done += 1
    return done


preload()
fill()
warm()
