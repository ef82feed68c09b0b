"""The one plugin loader: algorithms, metrics, decoders and readers by entry point, module or file.

A *spec* names one plugin class in one of four forms, the same for every kind of plugin:

==================================  ============================================================
``cluster-detector``                the name of an entry point in the kind's group
``mypkg.detectors:FastDetector``    a class in an importable module
``path/to/detector.py:MyDetector``  a class in a Python file (relative paths: from the cwd)
``path/to/detector.py``             the one usable plugin class of that kind the file defines
==================================  ============================================================

The entry-point groups (``[project.entry-points."GROUP"]`` in a plugin's ``pyproject.toml``):

=====================  ==============================================  =========================
group                  value                                           kind
=====================  ==============================================  =========================
``redrive.algorithms`` an :class:`~redrive.algorithms.Algorithm` class  :data:`ALGORITHMS`
``redrive.metrics``    a :class:`~redrive.evaluation.Metric` class      :data:`METRICS`
``redrive.decoders``   a :class:`~redrive.io.ros.decoders.Decoder` class    :data:`DECODERS`
``redrive.readers``    a :class:`~redrive.io.readers.ReaderFormat` class :data:`READERS`
=====================  ==============================================  =========================

Nothing registers itself on import: :func:`installed_plugins` reads a group's entry points once
per process, again when what is installed changes (the same throughout a :func:`discovered_once`
block, such as a run), and refuses two plugins of one name; an entry point that fails to load is reported (as a :class:`BrokenPlugin`) without
stopping the others.  Every failure is a
:class:`~redrive.errors.PluginError` that says which spec, where (file, module, entry point) and
what to do.  What makes a class a usable plugin of a kind (a subclass with a role, a metric with a
name …) is the kind's ``check``, given by the layer that defines the base class; this module is the
bottom layer and imports nothing of redrive but its errors.
"""

from __future__ import annotations

import difflib
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
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from types import MappingProxyType, ModuleType
from typing import Any, Generic, TypeVar

from redrive._entry_points import (
    declared_entry_points,
    discovered_once,
    dist_name,
    forget_entry_points,
)
from redrive.errors import PluginError

__all__ = [
    "ALGORITHMS",
    "DECODERS",
    "METRICS",
    "READERS",
    "BrokenPlugin",
    "PluginKind",
    "PluginRegistry",
    "class_target",
    "discovered_once",
    "forget_entry_points",
    "installed_plugins",
    "load_plugin",
    "subclass_check",
]

logger = logging.getLogger(__name__)

T = TypeVar("T")

#: prefix of the module names user files are imported under (one per file path).
_FILE_MODULE_PREFIX = "redrive_user_"

_DOTTED = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")
_EP_NAME = re.compile(r"^[\w][\w.+-]*$")


@dataclass(frozen=True, slots=True)
class PluginKind:
    """One kind of plugin: its entry-point group and how it is named in messages.

    Attributes:
        noun: ``algorithm``, ``metric`` … (messages: "algorithm spec 'x': …").
        group: the entry-point group.
        base: the class name plugins derive from or follow, for messages
            (``redrive.algorithms.Algorithm``).
        listing: the command that lists the installed plugins of this kind, or "".
    """

    noun: str
    group: str
    base: str
    listing: str = ""

    @property
    def forms(self) -> str:
        see = f" (see `{self.listing}`)" if self.listing else ""
        forms = "package.module:ClassName, path/to/file.py:ClassName or path/to/file.py"
        return f"an installed name{see}, {forms}"


ALGORITHMS = PluginKind(
    "algorithm", "redrive.algorithms", "redrive.algorithms.Algorithm", "redrive algorithms"
)
METRICS = PluginKind(
    "metric", "redrive.metrics", "redrive.evaluation.Metric", "redrive evaluate --list"
)
DECODERS = PluginKind("decoder", "redrive.decoders", "redrive.io.ros.decoders.Decoder")
READERS = PluginKind("reader", "redrive.readers", "redrive.io.readers.ReaderFormat")

#: Checks a candidate: returns None when it is a usable plugin, else what is wrong with it, to
#: follow the class's name ("is abstract: it does not implement step; implement it" or
#: ": inputs must be a tuple …").
Check = Callable[[object], "str | None"]


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
        return asdict(self)


class PluginRegistry(Mapping[str, type[T]], Generic[T]):
    """Entry-point name → plugin class; refuses a second plugin under a name already taken.

    Entry points that failed to load are kept apart in :attr:`broken`.
    """

    def __init__(self, kind: PluginKind, check: Check) -> None:
        self.kind = kind
        self._check = check
        self._classes: dict[str, type[T]] = {}
        self._targets: dict[str, str] = {}
        self._distributions: dict[str, str | None] = {}
        self._broken: dict[str, BrokenPlugin] = {}

    def __getitem__(self, name: str) -> type[T]:
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
        self, name: str, cls: type[T], *, target: str, distribution: str | None = None
    ) -> None:
        """Add ``cls`` under ``name``.

        Raises:
            PluginError: ``name`` is taken (the message names both targets) or ``cls`` is not a
                usable plugin of this kind.
        """
        self._refuse_duplicate(name, target, distribution)
        _checked(self.kind, self._check, cls, spec=name, where=f"target {target}")
        self._classes[name] = cls
        self._targets[name] = target
        self._distributions[name] = distribution

    def add_broken(self, broken: BrokenPlugin) -> None:
        """Record an entry point that failed to load."""
        self._refuse_duplicate(broken.name, broken.target, broken.distribution)
        self._broken[broken.name] = broken

    def target(self, name: str) -> str:
        """Where plugin ``name`` lives (``module:Class``)."""
        return self._targets[name]

    def distribution(self, name: str) -> str | None:
        """The distribution that declares plugin ``name`` (``name version``), when known."""
        return self._distributions[name]

    def _refuse_duplicate(self, name: str, target: str, distribution: str | None) -> None:
        if name in self._classes:
            other, other_dist = self._targets[name], self._distributions[name]
        elif name in self._broken:
            other, other_dist = self._broken[name].target, self._broken[name].distribution
        else:
            return
        raise PluginError(
            _duplicate_message(self.kind, name, [(other, other_dist), (target, distribution)])
        )


def _duplicate_message(kind: PluginKind, name: str, targets: list[tuple[str, str | None]]) -> str:
    listing = " and ".join(
        f"{target!r} (from {dist or 'an unknown distribution'})" for target, dist in targets
    )
    return (
        f"two {kind.noun}s are installed under the name {name!r} (entry-point group "
        f"{kind.group}): {listing}; uninstall one of the distributions or rename its "
        "entry point, or pick one explicitly with its module:Class"
    )


def class_target(cls: type) -> str:
    """``package.module:Class``, or ``/abs/path/file.py:Class`` for a class loaded from a file."""
    module = sys.modules.get(cls.__module__)
    source = getattr(module, "__redrive_source__", None)
    where = str(source) if source is not None else cls.__module__
    return f"{where}:{cls.__qualname__}"


# -- installed plugins ----------------------------------------------------------------------------


def installed_plugins(
    kind: PluginKind, check: Check, *, into: PluginRegistry[Any] | None = None
) -> PluginRegistry[Any]:
    """Every plugin declared in the kind's entry-point group, loaded and checked (into ``into``,
    a fresh registry of a subclass, when given).

    An entry point that fails to load (or fails ``check``) is logged as a warning and listed in
    :attr:`PluginRegistry.broken`; the others still load.

    Raises:
        PluginError: two entry points share a name (the message names both targets).
    """
    eps = declared_entry_points(kind.group)
    by_name: dict[str, list[importlib.metadata.EntryPoint]] = {}
    for ep in eps:
        by_name.setdefault(ep.name, []).append(ep)
    for name, same in sorted(by_name.items()):
        if len(same) > 1:
            targets = [(e.value, dist_name(e)) for e in same]
            raise PluginError(_duplicate_message(kind, name, targets))
    registry: PluginRegistry[Any] = PluginRegistry(kind, check) if into is None else into
    for ep in sorted(eps, key=lambda e: e.name):
        dist = dist_name(ep)
        try:
            cls = _load_entry_point(kind, check, ep)
        except PluginError as err:
            logger.warning("%s", err)
            registry.add_broken(
                BrokenPlugin(name=ep.name, target=ep.value, distribution=dist, error=str(err))
            )
            continue
        registry.register(ep.name, cls, target=ep.value, distribution=dist)
    return registry


def _load_entry_point(kind: PluginKind, check: Check, ep: importlib.metadata.EntryPoint) -> type:
    dist = dist_name(ep)
    where = f"entry point {ep.name} = {ep.value!r} of {dist or 'an unknown distribution'}"
    fix = f"fix or reinstall {dist or 'the distribution that declares it'}"
    module_name, _, attr = ep.value.partition(":")
    module_name, attr = module_name.strip(), attr.split("[", 1)[0].strip()  # drop [extras]
    if not attr or not _DOTTED.match(module_name) or not _DOTTED.match(attr):
        msg = f"{kind.noun} spec {ep.name!r}: {where}: the value must be 'package.module:ClassName'; {fix}"
        raise PluginError(msg)
    module = _import_module(
        kind,
        module_name,
        spec=ep.name,
        where=where,
        fix=fix,
        missing_fix=(
            f"{dist or 'its distribution'} declares a module that is not installed; "
            "reinstall it (pip install -e . for a source checkout)"
        ),
    )
    return _class_from(kind, check, module, attr, spec=ep.name, where=where)


# -- loading one spec -----------------------------------------------------------------------------


def load_plugin(kind: PluginKind, check: Check, spec: str) -> type:
    """The plugin class ``spec`` names (any form of the module docstring), checked.

    Raises:
        PluginError: bad spec syntax; module or file not found; the file or module raises on
            import; no such class (the message lists the usable classes that are there); not a
            usable plugin of the kind (``check``'s reason).
    """
    text = spec.strip()
    if not text or any(c.isspace() for c in text):
        msg = f"{kind.noun} spec {spec!r}: cannot read it; give {kind.forms}"
        raise PluginError(msg)
    location, colon, attr = text.rpartition(":")
    if not colon:
        location, attr = text, ""
    if colon and not _DOTTED.match(attr):
        msg = (
            f"{kind.noun} spec {spec!r}: after the last ':' comes a class name, got {attr!r}; "
            f"give {kind.forms}"
        )
        raise PluginError(msg)
    if _looks_like_file(location):
        return _load_from_file(kind, check, location, attr or None, spec=text)
    if not colon:
        return _load_by_name(kind, check, text)
    if not _DOTTED.match(location):
        msg = (
            f"{kind.noun} spec {spec!r}: {location!r} is neither a module name (dotted "
            f"identifiers) nor a .py file path; give {kind.forms}"
        )
        raise PluginError(msg)
    where = f"module {location}"
    module = _import_module(kind, location, spec=text, where=where, fix="fix the module")
    return _class_from(kind, check, module, attr, spec=text, where=where)


def _looks_like_file(location: str) -> bool:
    return (
        location.endswith(".py")
        or "/" in location
        or os.sep in location
        or location.startswith(("~", "."))
    )


def _load_by_name(kind: PluginKind, check: Check, name: str) -> type:
    eps = declared_entry_points(kind.group)
    found = [ep for ep in eps if ep.name == name]
    if len(found) > 1:
        targets = [(e.value, dist_name(e)) for e in found]
        raise PluginError(_duplicate_message(kind, name, targets))
    if found:
        return _load_entry_point(kind, check, found[0])
    names = sorted({ep.name for ep in eps})
    if not _EP_NAME.match(name):
        msg = f"{kind.noun} spec {name!r}: cannot read it; give {kind.forms}"
        raise PluginError(msg)
    close = difflib.get_close_matches(name, names, n=3)
    hint = f"did you mean {', '.join(close)}? " if close else ""
    installed = ", ".join(names) if names else "none"
    extra = ""
    if _DOTTED.match(name) and "." in name:
        extra = f"; to load a class from module {name}, give {name}:ClassName"
    msg = (
        f"no installed {kind.noun} is named {name!r} (entry-point group {kind.group}; "
        f"installed: {installed}); {hint}give {kind.forms}{extra}"
    )
    raise PluginError(msg)


def _import_module(
    kind: PluginKind,
    module_name: str,
    *,
    spec: str,
    where: str,
    fix: str,
    missing_fix: str | None = None,
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
            remedy = missing_fix or (
                "install the package that provides it (pip install -e your_project), or give "
                f"a file: path/to/file.py:ClassName{hint}"
            )
            msg = (
                f"{kind.noun} spec {spec!r}: {where}: module {missing} not found (Python: "
                f"{sys.executable}); {remedy}"
            )
            raise PluginError(msg) from err
        raise PluginError(_raised_on_import(kind, spec, where, err, fix=fix)) from err
    except Exception as err:
        raise PluginError(_raised_on_import(kind, spec, where, err, fix=fix)) from err


def _raised_on_import(
    kind: PluginKind, spec: str, where: str, err: BaseException, *, fix: str
) -> str:
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
        f"{kind.noun} spec {spec!r}: importing {where} raised "
        f"{type(err).__name__}: {err}{line}{hint}; {fix}"
    )


def _load_from_file(
    kind: PluginKind, check: Check, location: str, attr: str | None, *, spec: str
) -> type:
    path = Path(location).expanduser()
    if not path.is_absolute():
        path = Path.cwd() / path
    path = path.resolve()
    where = f"file {path}"
    if not path.is_file():
        what = "is a directory, not a .py file" if path.is_dir() else "not found"
        msg = (
            f"{kind.noun} spec {spec!r}: {where} {what} (relative paths are taken from the "
            f"current directory, {Path.cwd()}); check the path"
        )
        raise PluginError(msg)
    module = _import_file(kind, path, spec=spec)
    if attr is None:
        found = [n for n in _defined_in(module) if check(getattr(module, n)) is None]
        if len(found) == 1:
            return _class_from(kind, check, module, found[0], spec=spec, where=where)
        listing = ", ".join(found) if found else "none"
        base = kind.base.rpartition(".")[2]
        msg = (
            f"{kind.noun} spec {spec!r}: {where} defines {len(found)} usable {base} "
            f"subclasses ({listing}); name one: {location}:ClassName"
        )
        raise PluginError(msg)
    return _class_from(kind, check, module, attr, spec=spec, where=where)


def _import_file(kind: PluginKind, path: Path, *, spec: str) -> ModuleType:
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
        msg = f"{kind.noun} spec {spec!r}: file {path} cannot be imported as Python source"
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
            _raised_on_import(kind, spec, f"file {path}", err, fix="fix the file and try again")
        ) from err
    return module


def _defined_in(module: ModuleType) -> list[str]:
    """Names of the classes ``module`` itself defines (not imports)."""
    return sorted(
        key
        for key, value in vars(module).items()
        if isinstance(value, type) and value.__module__ == module.__name__
    )


def _class_from(
    kind: PluginKind, check: Check, module: ModuleType, attr: str, *, spec: str, where: str
) -> type:
    obj: Any = module
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            defined = [n for n in _defined_in(module) if _is_kind(check, getattr(module, n))]
            listing = ", ".join(defined) if defined else "none"
            close = difflib.get_close_matches(attr, defined, n=1)
            hint = f"did you mean {close[0]}? " if close else ""
            base = kind.base.rpartition(".")[2]
            msg = (
                f"{kind.noun} spec {spec!r}: {where} has no {attr!r}; the {base} subclasses "
                f"it defines: {listing}; {hint}check the class name"
            )
            raise PluginError(msg) from None
    return _checked(kind, check, obj, spec=spec, where=f"{attr} in {where}")


def _is_kind(check: Check, obj: object) -> bool:
    """Whether ``obj`` is at least of the kind (perhaps abstract or incomplete)."""
    reason = check(obj)
    return reason is None or not reason.startswith(_NOT_OF_KIND)


#: How a check's reason starts when the object is not of the kind at all (vs. an incomplete one).
_NOT_OF_KIND = "is not "


def _checked(kind: PluginKind, check: Check, obj: object, *, spec: str, where: str) -> type:
    """``obj`` when ``check`` accepts it; else a PluginError with the check's reason."""
    head = f"{kind.noun} spec {spec!r}: {where}"
    if not isinstance(obj, type):
        msg = f"{head} is a {type(obj).__name__}, not a class; give a {kind.base} class"
        raise PluginError(msg)
    reason = check(obj)
    if reason is not None:
        sep = "" if reason.startswith(":") else " "  # ": inputs must be …" or "is abstract …"
        raise PluginError(f"{head}{sep}{reason}")
    return obj


def subclass_check(
    base: type, *, public: str, how: str, more: Callable[[type], str | None] | None = None
) -> Check:
    """A :data:`Check` for plugins that derive from ``base``: a subclass, ``more``, not abstract.

    ``public`` is the import path users derive from (``redrive.algorithms.Algorithm``); ``how``
    shows how (``class X(Algorithm): role = Role.PERCEPTION …``).
    """
    article = "an" if base.__name__[:1].lower() in "aeiou" else "a"

    def check(obj: object) -> str | None:
        if not isinstance(obj, type) or not issubclass(obj, base):
            return (
                f"{_NOT_OF_KIND}{article} {base.__name__} subclass; derive it from {public} ({how})"
            )
        extra = more(obj) if more is not None else None
        if extra is not None:
            return extra
        if inspect.isabstract(obj):
            missing = ", ".join(sorted(getattr(obj, "__abstractmethods__", ())))
            return f"is abstract: it does not implement {missing}; implement it"
        return None

    return check
