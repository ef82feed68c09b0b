"""Finding algorithms: installed plugins (entry points), ``package.module:Class`` and
``path/to/file.py:Class`` — through the one plugin loader, :mod:`redrive.plugins`.

A *spec* names one :class:`~redrive.algorithms.Algorithm` subclass in one of four forms:

==================================  ============================================================
``cluster-detector``                the name of an entry point in the ``redrive.algorithms`` group
``mypkg.detectors:FastDetector``    a class in an importable module
``path/to/detector.py:MyDetector``  a class in a Python file (relative paths: from the cwd)
``path/to/detector.py``             the one Algorithm subclass that file defines
==================================  ============================================================

Installed plugins declare themselves in their ``pyproject.toml``::

    [project.entry-points."redrive.algorithms"]
    fast-detector = "mypkg.detectors:FastDetector"

This module adds what is particular to algorithms: what makes a class usable (a role, inputs,
defaults, a version) and what ``redrive algorithms`` shows (:class:`AlgorithmInfo`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from redrive.algorithms.base import Algorithm, Role
from redrive.errors import PluginError
from redrive.plugins import (
    ALGORITHMS,
    BrokenPlugin,
    PluginRegistry,
    class_target,
    installed_plugins,
    load_plugin,
    subclass_check,
)
from redrive.types import SensorType, to_jsonable

__all__ = [
    "ENTRY_POINT_GROUP",
    "AlgorithmInfo",
    "AlgorithmRegistry",
    "BrokenPlugin",
    "class_target",
    "describe",
    "installed_algorithms",
    "load_algorithm_class",
]

#: the entry-point group installed algorithms declare themselves in.
ENTRY_POINT_GROUP = ALGORITHMS.group


# -- what an algorithm is, for listings ------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class AlgorithmInfo:
    """What ``redrive algorithms`` shows about one algorithm class.

    Attributes:
        name: the entry-point name, or the class name for a class given by module or file.
        target: where the class lives: ``package.module:Class`` or ``/abs/path/file.py:Class``.
        role: its stage, which fixes its output type.
        inputs: what it reads from a frame (sensor ids, sensor types in lower case,
            ``vehicle_state``, ``ground_truth``).
        version: the algorithm's own version string.
        summary: the first paragraph of the class docstring ("" when it has none).
        defaults: its default configuration.
        distribution: the installed distribution that declares it (entry points only).
    """

    name: str
    target: str
    role: Role
    inputs: tuple[str, ...]
    version: str
    summary: str
    defaults: Mapping[str, Any] = field(default_factory=dict)
    distribution: str | None = None

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (tuples become lists, enums their values, arrays lists)."""
        return {
            "name": self.name,
            "target": self.target,
            "role": self.role.value,
            "inputs": list(self.inputs),
            "version": self.version,
            "summary": self.summary,
            "defaults": {str(k): to_jsonable(v) for k, v in self.defaults.items()},
            "distribution": self.distribution,
        }


def describe(
    cls: type[Algorithm], *, name: str | None = None, distribution: str | None = None
) -> AlgorithmInfo:
    """The :class:`AlgorithmInfo` of an algorithm class.

    Raises:
        PluginError: ``cls`` is not a usable Algorithm subclass (see :func:`load_algorithm_class`).
    """
    target = class_target(cls)
    reason = _check_algorithm(cls)
    if reason is not None:
        sep = "" if reason.startswith(":") else " "
        msg = f"algorithm spec {target!r}: class {target}{sep}{reason}"
        raise PluginError(msg)
    return AlgorithmInfo(
        name=name or cls.__name__,
        target=target,
        role=cls.role,
        inputs=tuple(cls.input_names()),
        version=str(cls.version),
        summary=cls.describe(),
        defaults=MappingProxyType(dict(cls.defaults)),
        distribution=distribution,
    )


class AlgorithmRegistry(PluginRegistry[Algorithm]):
    """Entry-point name → algorithm class; refuses a second algorithm under a name already taken.

    Entry points that failed to load are kept apart in :attr:`broken`.
    """

    def __init__(self) -> None:
        super().__init__(ALGORITHMS, _check_algorithm)

    def info(self, name: str) -> AlgorithmInfo:
        """The :class:`AlgorithmInfo` of algorithm ``name``."""
        return describe(self[name], name=name, distribution=self.distribution(name))


def installed_algorithms() -> AlgorithmRegistry:
    """Every algorithm declared in the ``redrive.algorithms`` entry-point group, loaded.

    An entry point that fails to load is logged as a warning and listed in
    :attr:`AlgorithmRegistry.broken`; the others still load.

    Raises:
        PluginError: two entry points share a name (the message names both targets).
    """
    registry = AlgorithmRegistry()
    installed_plugins(ALGORITHMS, _check_algorithm, into=registry)
    return registry


def load_algorithm_class(spec: str) -> type[Algorithm]:
    """The Algorithm subclass ``spec`` names (any form of the module docstring).

    Raises:
        PluginError: bad spec syntax; module or file not found; the file or module raises on
            import; no such class (the message lists the Algorithm subclasses that are there);
            not an Algorithm subclass; abstract or without a ``role``.
    """
    cls: type[Algorithm] = load_plugin(ALGORITHMS, _check_algorithm, spec)
    return cls


def _algorithm_details(obj: type) -> str | None:
    """What is wrong with an Algorithm subclass's class attributes, or None."""
    role = getattr(obj, "role", None)
    if not isinstance(role, Role):
        return (
            f"has no role (got {role!r}); set role = Role.PERCEPTION, Role.PLANNING or "
            "Role.CONTROL in the class body"
        )
    inputs = getattr(obj, "inputs", None)
    if not isinstance(inputs, tuple) or not all(isinstance(i, str | SensorType) for i in inputs):
        return (
            ": inputs must be a tuple of sensor ids (str), SensorType members, "
            f"VEHICLE_STATE or GROUND_TRUTH, got {inputs!r} (a single input needs a trailing "
            "comma: inputs = ('lidar_top',))"
        )
    defaults = getattr(obj, "defaults", None)
    if not isinstance(defaults, Mapping):
        return f": defaults must be a mapping of config key → value, got {defaults!r}"
    version = getattr(obj, "version", None)
    if not isinstance(version, str):
        return f": version must be a str, got {version!r}"
    return None


_check_algorithm = subclass_check(
    Algorithm,
    public="redrive.algorithms.Algorithm",
    how="class X(Algorithm): role = Role.PERCEPTION …",
    more=_algorithm_details,
)
