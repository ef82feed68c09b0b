"""Templates of ``redrive new-algorithm``: one algorithm file and one test file per role.

Each is a :class:`string.Template` source with ``$module`` (the module name, ``my_detector``) and
``$cls`` (its class, ``MyDetector``).
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from redrive.algorithms.base import Role
from redrive.cli.templates.control import ALGORITHM as _CONTROL
from redrive.cli.templates.control import TEST as _CONTROL_TEST
from redrive.cli.templates.perception import ALGORITHM as _PERCEPTION
from redrive.cli.templates.perception import TEST as _PERCEPTION_TEST
from redrive.cli.templates.planning import ALGORITHM as _PLANNING
from redrive.cli.templates.planning import TEST as _PLANNING_TEST

__all__ = ["ALGORITHM_TEMPLATES", "IMPORTED_NAMES", "TEST_TEMPLATES"]

ALGORITHM_TEMPLATES: Mapping[Role, str] = MappingProxyType(
    {
        Role.PERCEPTION: _PERCEPTION,
        Role.PLANNING: _PLANNING,
        Role.CONTROL: _CONTROL,
    }
)
TEST_TEMPLATES: Mapping[Role, str] = MappingProxyType(
    {
        Role.PERCEPTION: _PERCEPTION_TEST,
        Role.PLANNING: _PLANNING_TEST,
        Role.CONTROL: _CONTROL_TEST,
    }
)

#: names the generated files import or define at module level; a class may not take one of them.
IMPORTED_NAMES = frozenset(
    {
        "Algorithm",
        "AlgorithmError",
        "Any",
        "Box3D",
        "ConfigError",
        "ControlCommands",
        "DetectedObject",
        "Frame",
        "Mapping",
        "MappingProxyType",
        "ObjectClass",
        "PlannedPath",
        "PointCloud",
        "Role",
        "SensorData",
        "SensorType",
        "StageOutputs",
        "StepStatus",
        "VehicleState",
    }
)
