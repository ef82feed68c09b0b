"""Metric plugins: the ``redrive.metrics`` entry-point group, ``package.module:Class`` or
``path/to/file.py[:Class]`` — through the one plugin loader, :mod:`redrive.plugins`."""

from __future__ import annotations

from redrive.evaluation.base import Metric
from redrive.plugins import METRICS, PluginRegistry, installed_plugins, load_plugin, subclass_check
from redrive.types import Role

__all__ = ["ENTRY_POINT_GROUP", "installed_metrics", "load_metric_class"]

ENTRY_POINT_GROUP = METRICS.group


def _metric_details(cls: type) -> str | None:
    name = getattr(cls, "name", None)
    if not isinstance(name, str) or not name:
        return "has no name; set name = 'my_metric' in the class body (the entry-point name)"
    if not hasattr(cls, "role"):
        return (
            "has no role; set role = Role.PERCEPTION, Role.PLANNING or Role.CONTROL (the "
            "algorithms it scores), or role = None for the run as a whole"
        )
    role = cls.role
    if role is not None and not isinstance(role, Role):
        return (
            f"has role {role!r}; use the enum: role = Role.PERCEPTION, Role.PLANNING or "
            "Role.CONTROL (from redrive.types), or role = None for the run as a whole"
        )
    return None


_check_metric = subclass_check(
    Metric,
    public="redrive.evaluation.Metric",
    how="class M(Metric): name = 'my_metric'; role = Role.PERCEPTION; def evaluate(self, data) …",
    more=_metric_details,
)


def installed_metrics() -> PluginRegistry[Metric]:
    """Entry-point name → metric class, for every ``redrive.metrics`` entry point.

    An entry point that fails to load is logged and listed in ``.broken``; the others load.

    Raises:
        PluginError: two entry points share a name.
    """
    registry: PluginRegistry[Metric] = installed_plugins(METRICS, _check_metric)
    return registry


def load_metric_class(spec: str) -> type[Metric]:
    """A metric by entry-point name, ``package.module:Class``, ``path/to/file.py:Class`` or
    ``path/to/file.py`` (its one metric class).

    Raises:
        PluginError: what :func:`redrive.plugins.load_plugin` raises.
    """
    cls: type[Metric] = load_plugin(METRICS, _check_metric, spec)
    return cls
