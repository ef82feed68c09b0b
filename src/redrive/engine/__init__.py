"""The Orchestration Engine (L5): the perception → planning → control stage graph, run modes
(sequential, pipelined; threads or worker processes), the Mode Manager and open-loop replay of
logs into run directories.

>>> from redrive.engine import RunRequest, run_log
"""

from __future__ import annotations

from redrive.engine.core import Engine
from redrive.engine.graph import LogInputs, StageGraph, build_graph
from redrive.engine.modes import Mode, ModeHooks, RealtimeMode, ReplayMode, mode_hooks
from redrive.engine.run import RunRequest, run_log, run_reader
from redrive.engine.stats import AlgorithmStats, RunReport

__all__ = [
    "AlgorithmStats",
    "Engine",
    "LogInputs",
    "Mode",
    "ModeHooks",
    "RealtimeMode",
    "ReplayMode",
    "RunReport",
    "RunRequest",
    "StageGraph",
    "build_graph",
    "mode_hooks",
    "run_log",
    "run_reader",
]
