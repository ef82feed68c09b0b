"""Metric plugins: the ``redrive.metrics`` entry-point group, ``package.module:Class`` or
``path/to/file.py[:Class]`` — through the one plugin loader, :mod:`redrive.plugins`."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

from redrive.errors import ConfigError
from redrive.evaluation.base import Metric
from redrive.plugins import METRICS, PluginRegistry, installed_plugins, load_plugin, subclass_check
from redrive.types import Role

__all__ = [
    "DEVKIT_COMPAT",
    "ENTRY_POINT_GROUP",
    "build_metrics",
    "installed_metrics",
    "load_metric_class",
    "parse_metric_params",
]

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


#: what ``--devkit-compat`` sets: the conventions of the official devkits where redrive's
#: default differs (``docs/evaluation.md``).
DEVKIT_COMPAT: Mapping[str, Mapping[str, Any]] = MappingProxyType(
    {"nuscenes_detection": MappingProxyType({"class_mean": "devkit"})}
)


def parse_metric_params(texts: Sequence[str]) -> dict[str, dict[str, Any]]:
    """``METRIC.PARAM=VALUE`` texts → metric name → {param: value}.

    VALUE is read as JSON when it is JSON (``0.5``, ``true``, ``"car"``, ``[1, 2]``,
    ``{"vehicle": "car"}``); else a comma-separated list, each item JSON or text
    (``0.5,1,2,4`` → [0.5, 1, 2, 4]); else text (``devkit``).

    Raises:
        ConfigError: a text not of the form ``METRIC.PARAM=VALUE``.
    """
    out: dict[str, dict[str, Any]] = {}
    for text in texts:
        key, sep, raw = text.partition("=")
        metric, dot, param = key.strip().rpartition(".")
        if not sep or not dot or not metric or not param:
            msg = (
                f"--metric-param {text!r}: give METRIC.PARAM=VALUE, e.g. "
                "nuscenes_detection.dist_ths_m=0.5,1,2,4 (`redrive metrics` lists the metrics)"
            )
            raise ConfigError(msg)
        out.setdefault(metric, {})[param] = _param_value(raw.strip())
    return out


def _param_value(raw: str) -> Any:
    try:
        return json.loads(raw)
    except ValueError:
        pass
    if "," in raw:
        return [_param_value(item.strip()) for item in raw.split(",")]
    return raw


def build_metrics(
    names: Sequence[str] | None,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    *,
    devkit_compat: bool = False,
) -> list[Metric]:
    """The metrics to evaluate: ``names`` (entry-point names or plugin specs; None: every
    installed metric), each with its ``params`` laid over its defaults (and, with
    ``devkit_compat``, :data:`DEVKIT_COMPAT` under them).

    Raises:
        ConfigError: parameters for a metric that is not evaluated, or a parameter the metric
            does not have (the message lists the ones it has).
        PluginError: a metric that does not load.
    """
    classes = [load_metric_class(n) for n in names] if names else list(installed_metrics().values())
    wanted: dict[str, dict[str, Any]] = {}
    if devkit_compat:
        for name, p in DEVKIT_COMPAT.items():
            wanted[name] = dict(p)
    for name, p in (params or {}).items():
        wanted.setdefault(name, {}).update(p)
    given = {cls.name for cls in classes}
    stray = sorted(n for n in (params or {}) if n not in given)
    if stray:
        msg = (
            f"--metric-param for {', '.join(stray)}, which is not among the metrics evaluated "
            f"({', '.join(sorted(given))})"
        )
        raise ConfigError(msg)
    return [cls(**wanted.get(cls.name, {})) for cls in classes]
