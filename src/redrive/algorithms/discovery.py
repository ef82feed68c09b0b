"""Finding algorithms: installed plugins (entry points), ``package.module:Class`` and
``path/to/file.py:Class``.

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

Nothing registers itself on import: :func:`installed_algorithms` reads the entry points each time
it is called and builds a fresh :class:`AlgorithmRegistry`, which refuses two plugins of one name.
Every failure is a :class:`~redrive.errors.PluginError` that says which spec, where (file, module,
entry point) and what to do.
"""

from __future__ import annotations

import difflib
import enum
import hashlib
import importlib
import importlib.metadata
import importlib.util
import inspect
import logging
import os
import re
import sys
import traceback
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Any

from redrive.algorithms.base import Algorithm, Role
from redrive.errors import PluginError
from redrive.types import SensorType

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

logger = logging.getLogger(__name__)

#: the entry-point group installed algorithms declare themselves in.
ENTRY_POINT_GROUP = "redrive.algorithms"

#: prefix of the module names user files are imported under (one per file path).
_FILE_MODULE_PREFIX = "redrive_user_"

_DOTTED = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")
_EP_NAME = re.compile(r"^[\w][\w.+-]*$")

_FORMS = (
    "an installed name (see `redrive algorithms`), package.module:ClassName, "
    "path/to/file.py:ClassName or path/to/file.py"
)


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
            "defaults": {str(k): _jsonable(v) for k, v in self.defaults.items()},
            "distribution": self.distribution,
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class BrokenPlugin:
    """An entry point that could not be loaded (reported, not fatal for the other plugins).

    Attributes:
        name: the entry-point name.
        target: its value, ``module:Class``.
        distribution: the distribution that declares it, when known.
        error: the :class:`PluginError` message.
    """

    name: str
    target: str
    distribution: str | None
    error: str

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "target": self.target,
            "distribution": self.distribution,
            "error": self.error,
        }


def _jsonable(value: Any) -> Any:
    if isinstance(value, enum.Enum):
        return _jsonable(value.value)
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [_jsonable(v) for v in value]
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return value.tolist()
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return repr(value)


def class_target(cls: type) -> str:
    """``package.module:Class``, or ``/abs/path/file.py:Class`` for a class loaded from a file."""
    module = sys.modules.get(cls.__module__)
    source = getattr(module, "__redrive_source__", None)
    where = str(source) if source is not None else cls.__module__
    return f"{where}:{cls.__qualname__}"


def describe(
    cls: type[Algorithm], *, name: str | None = None, distribution: str | None = None
) -> AlgorithmInfo:
    """The :class:`AlgorithmInfo` of an algorithm class.

    Raises:
        PluginError: ``cls`` is not a usable Algorithm subclass (see :func:`load_algorithm_class`).
    """
    target = class_target(cls)
    _check_class(cls, spec=target, where=f"class {target}")
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


# -- the registry of installed algorithms ---------------------------------------------------------


class AlgorithmRegistry(Mapping[str, type[Algorithm]]):
    """Entry-point name → algorithm class; refuses a second algorithm under a name already taken.

    Entry points that failed to load are kept apart in :attr:`broken`.
    """

    def __init__(self) -> None:
        self._classes: dict[str, type[Algorithm]] = {}
        self._targets: dict[str, str] = {}
        self._distributions: dict[str, str | None] = {}
        self._broken: dict[str, BrokenPlugin] = {}

    def __getitem__(self, name: str) -> type[Algorithm]:
        return self._classes[name]

    def __iter__(self) -> Iterator[str]:
        return iter(sorted(self._classes))

    def __len__(self) -> int:
        return len(self._classes)

    @property
    def broken(self) -> Mapping[str, BrokenPlugin]:
        """Entry points that could not be loaded, by name."""
        return MappingProxyType(self._broken)

    def register(
        self, name: str, cls: type[Algorithm], *, target: str, distribution: str | None = None
    ) -> None:
        """Add ``cls`` under ``name``.

        Raises:
            PluginError: ``name`` is taken (the message names both targets) or ``cls`` is not a
                usable Algorithm subclass.
        """
        self._refuse_duplicate(name, target, distribution)
        _check_class(cls, spec=name, where=f"target {target}")
        self._classes[name] = cls
        self._targets[name] = target
        self._distributions[name] = distribution

    def add_broken(self, broken: BrokenPlugin) -> None:
        """Record an entry point that failed to load."""
        self._refuse_duplicate(broken.name, broken.target, broken.distribution)
        self._broken[broken.name] = broken

    def target(self, name: str) -> str:
        """Where algorithm ``name`` lives (``module:Class``)."""
        return self._targets[name]

    def info(self, name: str) -> AlgorithmInfo:
        """The :class:`AlgorithmInfo` of algorithm ``name``."""
        return describe(self._classes[name], name=name, distribution=self._distributions[name])

    def _refuse_duplicate(self, name: str, target: str, distribution: str | None) -> None:
        if name in self._classes:
            other, other_dist = self._targets[name], self._distributions[name]
        elif name in self._broken:
            other, other_dist = self._broken[name].target, self._broken[name].distribution
        else:
            return
        raise PluginError(_duplicate_message(name, [(other, other_dist), (target, distribution)]))


def _duplicate_message(name: str, targets: list[tuple[str, str | None]]) -> str:
    listing = " and ".join(
        f"{target!r} (from {dist or 'an unknown distribution'})" for target, dist in targets
    )
    return (
        f"two algorithms are installed under the name {name!r} (entry-point group "
        f"{ENTRY_POINT_GROUP}): {listing}; uninstall one of the distributions or rename its "
        "entry point, or pick one explicitly with its module:Class"
    )


def _declared_entry_points() -> list[importlib.metadata.EntryPoint]:
    """The entry points of :data:`ENTRY_POINT_GROUP`, read afresh from the installed metadata."""
    return list(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP))


def _dist_name(ep: importlib.metadata.EntryPoint) -> str | None:
    dist = getattr(ep, "dist", None)
    if dist is None:
        return None
    try:
        return f"{dist.name} {dist.version}"
    except Exception:  # broken metadata: the name is only decoration here
        return None


def _check_unique(eps: list[importlib.metadata.EntryPoint]) -> None:
    by_name: dict[str, list[importlib.metadata.EntryPoint]] = {}
    for ep in eps:
        by_name.setdefault(ep.name, []).append(ep)
    for name, same in sorted(by_name.items()):
        if len(same) > 1:
            raise PluginError(_duplicate_message(name, [(e.value, _dist_name(e)) for e in same]))


def installed_algorithms() -> AlgorithmRegistry:
    """Every algorithm declared in the ``redrive.algorithms`` entry-point group, loaded.

    An entry point that fails to load is logged as a warning and listed in
    :attr:`AlgorithmRegistry.broken`; the others still load.

    Raises:
        PluginError: two entry points share a name (the message names both targets).
    """
    eps = _declared_entry_points()
    _check_unique(eps)
    registry = AlgorithmRegistry()
    for ep in sorted(eps, key=lambda e: e.name):
        dist = _dist_name(ep)
        try:
            cls = _load_entry_point(ep)
        except PluginError as err:
            logger.warning("%s", err)
            registry.add_broken(
                BrokenPlugin(name=ep.name, target=ep.value, distribution=dist, error=str(err))
            )
            continue
        registry.register(ep.name, cls, target=ep.value, distribution=dist)
    return registry


def _load_entry_point(ep: importlib.metadata.EntryPoint) -> type[Algorithm]:
    dist = _dist_name(ep)
    where = f"entry point {ep.name} = {ep.value!r} of {dist or 'an unknown distribution'}"
    fix = f"fix or reinstall {dist or 'the distribution that declares it'}"
    module_name, _, attr = ep.value.partition(":")
    module_name, attr = module_name.strip(), attr.split("[", 1)[0].strip()  # drop [extras]
    if not attr or not _DOTTED.match(module_name) or not _DOTTED.match(attr):
        msg = f"{where}: the value must be 'package.module:ClassName'; {fix}"
        raise PluginError(msg)
    module = _import_module(
        module_name,
        spec=ep.name,
        where=where,
        fix=fix,
        missing_fix=(
            f"{dist or 'its distribution'} declares a module that is not installed; "
            "reinstall it (pip install -e . for a source checkout)"
        ),
    )
    return _class_from(module, attr, spec=ep.name, where=where)


# -- loading one spec -----------------------------------------------------------------------------


def load_algorithm_class(spec: str) -> type[Algorithm]:
    """The Algorithm subclass ``spec`` names (any form of the module docstring).

    Raises:
        PluginError: bad spec syntax; module or file not found; the file or module raises on
            import; no such class (the message lists the Algorithm subclasses that are there);
            not an Algorithm subclass; abstract or without a ``role``.
    """
    text = spec.strip()
    if not text or any(c.isspace() for c in text):
        msg = f"algorithm spec {spec!r}: cannot read it; give {_FORMS}"
        raise PluginError(msg)
    location, colon, attr = text.rpartition(":")
    if not colon:
        location, attr = text, ""
    if colon and not _DOTTED.match(attr):
        msg = (
            f"algorithm spec {spec!r}: after the last ':' comes a class name, got {attr!r}; "
            f"give {_FORMS}"
        )
        raise PluginError(msg)
    if _looks_like_file(location):
        return _load_from_file(location, attr or None, spec=text)
    if not colon:
        return _load_by_name(text)
    if not _DOTTED.match(location):
        msg = (
            f"algorithm spec {spec!r}: {location!r} is neither a module name (dotted "
            f"identifiers) nor a .py file path; give {_FORMS}"
        )
        raise PluginError(msg)
    return _load_from_module(location, attr, spec=text)


def _looks_like_file(location: str) -> bool:
    return (
        location.endswith(".py")
        or "/" in location
        or os.sep in location
        or location.startswith(("~", "."))
    )


def _load_by_name(name: str) -> type[Algorithm]:
    eps = _declared_entry_points()
    found = [ep for ep in eps if ep.name == name]
    if len(found) > 1:
        raise PluginError(_duplicate_message(name, [(e.value, _dist_name(e)) for e in found]))
    if found:
        return _load_entry_point(found[0])
    names = sorted({ep.name for ep in eps})
    if not _EP_NAME.match(name):
        msg = f"algorithm spec {name!r}: cannot read it; give {_FORMS}"
        raise PluginError(msg)
    close = difflib.get_close_matches(name, names, n=3)
    hint = f"did you mean {', '.join(close)}? " if close else ""
    installed = ", ".join(names) if names else "none"
    extra = ""
    if _DOTTED.match(name) and "." in name:
        extra = f"; to load a class from module {name}, give {name}:ClassName"
    msg = (
        f"no installed algorithm is named {name!r} (entry-point group {ENTRY_POINT_GROUP}; "
        f"installed: {installed}); {hint}give {_FORMS}{extra}"
    )
    raise PluginError(msg)


def _load_from_module(module_name: str, attr: str, *, spec: str) -> type[Algorithm]:
    where = f"module {module_name}"
    module = _import_module(module_name, spec=spec, where=where, fix="fix the module")
    return _class_from(module, attr, spec=spec, where=where)


def _import_module(
    module_name: str, *, spec: str, where: str, fix: str, missing_fix: str | None = None
) -> ModuleType:
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        missing = err.name or ""
        if missing and (module_name == missing or module_name.startswith(missing + ".")):
            as_file = Path.cwd() / (module_name.replace(".", os.sep) + ".py")
            hint = (
                f"; there is a file {as_file}: give its path instead, "
                f"./{as_file.relative_to(Path.cwd())}:ClassName"
                if as_file.is_file()
                else ""
            )
            todo = missing_fix or (
                "install the package that provides it (pip install -e your_project), or give "
                f"a file: path/to/file.py:ClassName{hint}"
            )
            msg = (
                f"algorithm spec {spec!r}: {where}: module {missing} not found (Python: "
                f"{sys.executable}); {todo}"
            )
            raise PluginError(msg) from err
        raise PluginError(_raised_on_import(spec, where, err, fix=fix)) from err
    except Exception as err:
        raise PluginError(_raised_on_import(spec, where, err, fix=fix)) from err


def _raised_on_import(spec: str, where: str, err: BaseException, *, fix: str) -> str:
    line = ""
    if isinstance(err, SyntaxError) and err.filename:
        line = f" at {err.filename}:{err.lineno}"
    else:
        frames = traceback.extract_tb(err.__traceback__)
        user = [f for f in frames if "importlib" not in f.filename]
        if user:
            line = f" at {user[-1].filename}:{user[-1].lineno}"
    hint = ""
    if isinstance(err, ModuleNotFoundError):
        hint = (
            f" (module {err.name} is not importable: install it; redrive does not put a "
            "plugin file's directory on sys.path, so import helpers from an installed package)"
        )
    return (
        f"algorithm spec {spec!r}: importing {where} raised "
        f"{type(err).__name__}: {err}{line}{hint}; {fix}"
    )


def _load_from_file(location: str, attr: str | None, *, spec: str) -> type[Algorithm]:
    path = Path(location).expanduser()
    if not path.is_absolute():
        path = Path.cwd() / path
    path = path.resolve()
    where = f"file {path}"
    if not path.is_file():
        what = "is a directory, not a .py file" if path.is_dir() else "not found"
        msg = (
            f"algorithm spec {spec!r}: {where} {what} (relative paths are taken from the "
            f"current directory, {Path.cwd()}); check the path"
        )
        raise PluginError(msg)
    module = _import_file(path, spec=spec)
    if attr is None:
        found = _algorithms_defined_in(module, concrete_only=True)
        if len(found) == 1:
            return _class_from(module, found[0], spec=spec, where=where)
        listing = ", ".join(found) if found else "none"
        msg = (
            f"algorithm spec {spec!r}: {where} defines {len(found)} usable Algorithm "
            f"subclasses ({listing}); name one: {location}:ClassName"
        )
        raise PluginError(msg)
    return _class_from(module, attr, spec=spec, where=where)


def _import_file(path: Path, *, spec: str) -> ModuleType:
    """Import ``path`` under a module name unique to its absolute path (two ``detector.py`` files
    do not collide).  The module is reused while the file's mtime and size are unchanged."""
    stat = path.stat()
    stamp = (stat.st_mtime_ns, stat.st_size)
    digest = hashlib.sha1(str(path).encode(), usedforsecurity=False).hexdigest()[:12]
    stem = re.sub(r"\W", "_", path.stem)
    module_name = f"{_FILE_MODULE_PREFIX}{stem}_{digest}"
    cached = sys.modules.get(module_name)
    if cached is not None and getattr(cached, "__redrive_stamp__", None) == stamp:
        return cached
    import_spec = importlib.util.spec_from_file_location(module_name, path)
    if import_spec is None or import_spec.loader is None:
        msg = f"algorithm spec {spec!r}: file {path} cannot be imported as Python source"
        raise PluginError(msg)
    module = importlib.util.module_from_spec(import_spec)
    module.__redrive_source__ = path  # type: ignore[attr-defined]
    module.__redrive_stamp__ = stamp  # type: ignore[attr-defined]
    # in sys.modules while it runs: dataclasses and typing look their module up there
    sys.modules[module_name] = module
    try:
        import_spec.loader.exec_module(module)
    except (Exception, SystemExit) as err:
        sys.modules.pop(module_name, None)
        raise PluginError(
            _raised_on_import(spec, f"file {path}", err, fix="fix the file and try again")
        ) from err
    return module


def _algorithms_defined_in(module: ModuleType, *, concrete_only: bool = False) -> list[str]:
    """Names of the Algorithm subclasses ``module`` itself defines (not imports)."""
    names = []
    for key, value in vars(module).items():
        if (
            isinstance(value, type)
            and issubclass(value, Algorithm)
            and value is not Algorithm
            and value.__module__ == module.__name__
            and not (concrete_only and (inspect.isabstract(value) or not _has_role(value)))
        ):
            names.append(key)
    return sorted(names)


def _has_role(cls: type) -> bool:
    return isinstance(getattr(cls, "role", None), Role)


def _class_from(module: ModuleType, attr: str, *, spec: str, where: str) -> type[Algorithm]:
    obj: Any = module
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            defined = _algorithms_defined_in(module)
            listing = ", ".join(defined) if defined else "none"
            close = difflib.get_close_matches(attr, defined, n=1)
            hint = f"did you mean {close[0]}? " if close else ""
            msg = (
                f"algorithm spec {spec!r}: {where} has no {attr!r}; the Algorithm subclasses "
                f"it defines: {listing}; {hint}check the class name"
            )
            raise PluginError(msg) from None
    _check_class(obj, spec=spec, where=f"{attr} in {where}")
    cls: type[Algorithm] = obj
    return cls


def _check_class(obj: object, *, spec: str, where: str) -> None:
    """Raise :class:`PluginError` unless ``obj`` is a concrete Algorithm subclass with a role."""
    head = f"algorithm spec {spec!r}: {where}"
    if not isinstance(obj, type):
        msg = f"{head} is a {type(obj).__name__}, not a class; give an Algorithm subclass"
        raise PluginError(msg)
    if not issubclass(obj, Algorithm):
        msg = (
            f"{head} is not an Algorithm subclass; derive it from "
            "redrive.algorithms.Algorithm (class X(Algorithm): role = Role.PERCEPTION …)"
        )
        raise PluginError(msg)
    if not _has_role(obj):
        got = getattr(obj, "role", None)
        msg = (
            f"{head} has no role (got {got!r}); set role = Role.PERCEPTION, Role.PLANNING or "
            "Role.CONTROL in the class body"
        )
        raise PluginError(msg)
    if inspect.isabstract(obj):
        missing = ", ".join(sorted(getattr(obj, "__abstractmethods__", ())))
        msg = f"{head} is abstract: it does not implement {missing}; implement it"
        raise PluginError(msg)
    inputs = obj.inputs
    if not isinstance(inputs, tuple) or not all(isinstance(i, str | SensorType) for i in inputs):
        msg = (
            f"{head}: inputs must be a tuple of sensor ids (str), SensorType members, "
            f"VEHICLE_STATE or GROUND_TRUTH, got {inputs!r} (a single input needs a trailing "
            "comma: inputs = ('lidar_top',))"
        )
        raise PluginError(msg)
    if not isinstance(obj.defaults, Mapping):
        msg = f"{head}: defaults must be a mapping of config key → value, got {obj.defaults!r}"
        raise PluginError(msg)
    if not isinstance(obj.version, str):
        msg = f"{head}: version must be a str, got {obj.version!r}"
        raise PluginError(msg)
