"""The Algorithm Abstraction Layer (L3): the contract researchers implement, plugin discovery and
the reference algorithms.

>>> from redrive.algorithms import Algorithm, Role
"""

from __future__ import annotations

from redrive.algorithms.base import (
    GROUND_TRUTH,
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

__all__ = [
    "GROUND_TRUTH",
    "VEHICLE_STATE",
    "Algorithm",
    "AlgorithmOutput",
    "Input",
    "Role",
    "StageOutputs",
    "StepError",
    "StepResult",
    "StepStatus",
    "check_output",
]
