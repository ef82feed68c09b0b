"""The Algorithm Abstraction Layer (L3): the contract researchers implement, plugin discovery and
the reference algorithms.

>>> from redrive.algorithms import Algorithm, Role
"""

from __future__ import annotations

from redrive.algorithms.base import (
    GROUND_TRUTH,
    ROAD_MAP,
    VEHICLE_STATE,
    Algorithm,
    AlgorithmOutput,
    Input,
    Role,
    StageOutputs,
    StepError,
    StepResult,
    StepStatus,
    check_output,
)
from redrive.algorithms.discovery import (
    AlgorithmInfo,
    describe,
    installed_algorithms,
    load_algorithm_class,
)

__all__ = [
    "GROUND_TRUTH",
    "ROAD_MAP",
    "VEHICLE_STATE",
    "Algorithm",
    "AlgorithmInfo",
    "AlgorithmOutput",
    "Input",
    "Role",
    "StageOutputs",
    "StepError",
    "StepResult",
    "StepStatus",
    "check_output",
    "describe",
    "installed_algorithms",
    "load_algorithm_class",
]
