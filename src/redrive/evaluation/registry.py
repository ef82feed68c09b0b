"""Metric plugins: the ``redrive.metrics`` entry-point group, or ``package.module:Class``.

Nothing registers itself on import; two entry points with one name are an error.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import logging
import re
import sys
from collections.abc import Mapping
from importlib.metadata import entry_points
from pathlib import Path
from types import MappingProxyType, ModuleType

from redrive.errors import PluginError
from redrive.evaluation.base import ROLES, Metric

__all__ = ["ENTRY_POINT_GROUP", "installed_metrics", "load_metric_class"]

logger = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "redrive.metrics"


def _check(cls: object, where: str) -> type[Metric]:
    if not (inspect.isclass(cls) and issubclass(cls, Metric)):
        msg = f"{where} is not a redrive.evaluation.Metric subclass"
        raise PluginError(msg)
    if inspect.isabstract(cls):
        msg = f"{where}: {cls.__name__} does not implement evaluate()"
        raise PluginError(msg)
    if getattr(cls, "role", None) not in ROLES or not getattr(cls, "name", ""):
        msg = f"{where}: {cls.__name__} must set `name` and `role` (one of {', '.join(ROLES)})"
        raise PluginError(msg)
    return cls


def installed_metrics() -> Mapping[str, type[Metric]]:
    """Entry-point name → metric class, for every ``redrive.metrics`` entry point.

    Raises:
        PluginError: two entry points share a name, or one cannot be loaded.
    """
    found: dict[str, type[Metric]] = {}
    targets: dict[str, str] = {}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in targets and targets[ep.name] != ep.value:
            msg = (
                f"two metrics are named {ep.name!r}: {targets[ep.name]} and {ep.value}; "
                "uninstall one of the packages"
            )
            raise PluginError(msg)
        try:
            cls = ep.load()
        except Exception as err:
            msg = f"metric entry point {ep.name!r} ({ep.value}) failed to load: {err}"
            raise PluginError(msg) from err
        found[ep.name] = _check(cls, f"entry point {ep.name!r} ({ep.value})")
        targets[ep.name] = ep.value
    return MappingProxyType(dict(sorted(found.items())))


def _import_file(path: Path, *, spec: str) -> ModuleType:
    """Import a metric file under a module name unique to its absolute path."""
    path = path.resolve()
    if not path.is_file():
        msg = f"metric {spec!r}: no file {path}"
        raise PluginError(msg)
    digest = hashlib.sha1(str(path).encode(), usedforsecurity=False).hexdigest()[:12]
    stem = re.sub(r"\W", "_", path.stem)
    module_name = f"_redrive_metric_{stem}_{digest}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    import_spec = importlib.util.spec_from_file_location(module_name, path)
    if import_spec is None or import_spec.loader is None:
        msg = f"metric {spec!r}: {path} cannot be imported as Python source"
        raise PluginError(msg)
    module = importlib.util.module_from_spec(import_spec)
    sys.modules[module_name] = module  # dataclasses look their module up while it runs
    try:
        import_spec.loader.exec_module(module)
    except Exception as err:
        sys.modules.pop(module_name, None)
        msg = f"metric {spec!r}: importing {path} raised {type(err).__name__}: {err}"
        raise PluginError(msg) from err
    return module


def load_metric_class(spec: str) -> type[Metric]:
    """A metric by entry-point name, ``package.module:Class`` or ``path/to/file.py:Class``."""
    if ":" not in spec:
        installed = installed_metrics()
        if spec in installed:
            return installed[spec]
        msg = f"no metric named {spec!r}; installed: {', '.join(installed) or 'none'}"
        raise PluginError(msg)
    module_name, _, cls_name = spec.rpartition(":")
    if module_name.endswith(".py"):
        module = _import_file(Path(module_name).expanduser(), spec=spec)
    else:
        try:
            module = importlib.import_module(module_name)
        except ImportError as err:
            msg = f"metric {spec!r}: cannot import {module_name!r}: {err}"
            raise PluginError(msg) from err
    cls = getattr(module, cls_name, None)
    if cls is None:
        msg = f"metric {spec!r}: {module_name} has no {cls_name!r}"
        raise PluginError(msg)
    return _check(cls, spec)
