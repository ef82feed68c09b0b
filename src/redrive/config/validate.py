"""The one validator of user configuration: typed reads of one table of a parsed TOML/JSON file.

Every configuration redrive reads goes through a :class:`Table`: pipeline files, scenarios, sensor
rigs, sensor maps, batch specs and run manifests.  A read checks the type (``bool`` is never a
number), the range and, with :meth:`Table.check_keys`, that no key is unknown; a failure is a
:class:`~redrive.errors.ConfigError` saying *where* (the file and the key's dotted path,
``agents[2].speed_mps``), *what* (what was found, what was expected) and *what to do*::

    t = Table(tomllib.loads(text), source=str(path))
    t.check_keys({"seed", "stage"})
    seed = t.integer("seed", 0, minimum=0)
    for stage in t.tables("stage", ()):
        name = stage.text("name")

A document lays its messages out with a *style* (``style(source, path, problem, fix)``), so each
file keeps the form its users know (``[rig.lidar] rate_hz: ...``, ``key 'ego.route': ...``); the
default is ``SOURCE: PATH: PROBLEM; FIX``.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Callable, Collection, Iterator, Mapping
from pathlib import Path
from typing import Any, Final

from redrive.errors import ConfigError

__all__ = [
    "REQUIRED",
    "Style",
    "Table",
    "default_style",
    "is_integer",
    "is_number",
    "parse_toml",
    "read_toml",
]

#: The default of a read that has no default: the key must be there.
REQUIRED: Final = object()

#: ``style(source, path, problem, fix)`` → the message of a ConfigError.
Style = Callable[[str, str, str, str], str]


def default_style(source: str, path: str, problem: str, fix: str) -> str:
    """``SOURCE: PATH: PROBLEM; FIX`` (no path: ``SOURCE: PROBLEM; FIX``)."""
    where = f"{source}: {path}" if path else source
    return f"{where}: {problem}; {fix}"


def parse_toml(text: str, *, source: str) -> dict[str, Any]:
    """The TOML document ``text`` (``source`` names it in the error)."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        msg = f"{source}: not valid TOML ({err}); fix the syntax at that line"
        raise ConfigError(msg) from err


def read_toml(path: str | Path, *, what: str) -> dict[str, Any]:
    """The TOML file at ``path``, ``what`` it is named in errors ("pipeline file")."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError as err:
        msg = f"{path}: {what} not found; check the path"
        raise ConfigError(msg) from err
    except (OSError, UnicodeDecodeError) as err:
        msg = f"{path}: cannot read the {what} ({err})"
        raise ConfigError(msg) from err
    return parse_toml(text, source=str(path))


def is_number(value: Any) -> bool:
    """An int or float, not a bool."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def is_integer(value: Any) -> bool:
    """An int, not a bool."""
    return isinstance(value, int) and not isinstance(value, bool)


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


class Table:
    """Typed reads of one mapping ``data`` at ``where`` (a dotted path) in the file ``source``.

    Every getter takes the key, a default (:data:`REQUIRED`: the key must be present; a default
    is returned as given, unchecked) and keyword checks; ``fix`` replaces the advice of the
    message.  ``data`` that is not a mapping is refused at once.
    """

    #: how a mapping is named in messages ("a table" in TOML, "an object" in JSON).
    MAPPING = "a table"

    def __init__(
        self, data: Any, *, source: str, where: str = "", style: Style = default_style
    ) -> None:
        self.source, self.where, self.style = source, where, style
        if not isinstance(data, Mapping):
            raise self._fail_at(
                where, f"{self.kind(data)} ({_shown(data)}), expected {self.MAPPING}", "make it one"
            )
        self.data: Mapping[str, Any] = data

    # --- messages -----------------------------------------------------------------------------

    def at(self, key: str) -> str:
        """The dotted path of ``key`` (``agents[0].speed``)."""
        return f"{self.where}.{key}" if self.where else key

    def kind(self, value: Any) -> str:
        """What ``value`` is, in words: "a string", "a number", "a list", "null", ..."""
        if value is None:
            return "null"
        if isinstance(value, Mapping):
            return self.MAPPING
        names = ((bool, "a boolean"), (str, "a string"), (list | tuple, "a list"))
        for cls, name in names:
            if isinstance(value, cls):
                return name
        return "a number" if is_number(value) else type(value).__name__

    def _fail_at(self, path: str, problem: str, fix: str) -> ConfigError:
        return ConfigError(self.style(self.source, path, problem, fix))

    def fail(self, key: str, problem: str, fix: str) -> ConfigError:
        """A ConfigError about ``key`` of this table (a rule the getters do not know)."""
        return self._fail_at(self.at(key) if key else self.where, problem, fix)

    def wrong(self, key: str, value: Any, expected: str, fix: str | None = None) -> ConfigError:
        """``key`` holds ``value``, which is not ``expected``."""
        problem = f"{self.kind(value)} ({_shown(value)}), expected {expected}"
        return self.fail(key, problem, fix or f"give {key.rsplit('.', 1)[-1]} {expected}")

    def missing(self, key: str, expected: str, fix: str | None = None) -> ConfigError:
        """``key`` is required and absent."""
        return self.fail(key, f"missing (expected {expected})", fix or f"add {key} ({expected})")

    # --- keys ---------------------------------------------------------------------------------

    def __contains__(self, key: object) -> bool:
        return key in self.data

    def __iter__(self) -> Iterator[str]:
        return iter(list(self.data))

    def check_keys(self, known: Collection[str], *, fix: str | None = None) -> None:
        """Refuse the first key not in ``known`` (suggesting the closest known one)."""
        for key in self.data:
            if key not in known:
                close = difflib.get_close_matches(str(key), list(known), n=1)
                names = ", ".join(sorted(known))
                hint = f"did you mean '{close[0]}'? known: {names}" if close else f"known: {names}"
                raise self.fail(str(key), "unknown key", fix or f"remove it ({hint})")

    def raw(self, key: str, default: Any = REQUIRED, *, expected: str = "a value") -> Any:
        """The value of ``key`` unchecked (``default`` when absent)."""
        if key in self.data:
            return self.data[key]
        if default is REQUIRED:
            raise self.missing(key, expected)
        return default

    def value(
        self,
        key: str,
        check: Callable[[Any], bool],
        expected: str,
        default: Any = REQUIRED,
        *,
        fix: str | None = None,
    ) -> Any:
        """The value of ``key`` if ``check(value)``; ``default`` when absent."""
        if key not in self.data:
            if default is REQUIRED:
                raise self.missing(key, expected, fix)
            return default
        value = self.data[key]
        if not check(value):
            raise self.wrong(key, value, expected, fix)
        return value

    # --- scalars ------------------------------------------------------------------------------

    def text(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        choices: Collection[str] | None = None,
        fix: str | None = None,
    ) -> Any:
        """A string (one of ``choices`` when given)."""
        if choices is None:
            return self.value(key, lambda v: isinstance(v, str), "a string", default, fix=fix)
        expected = "one of " + ", ".join(choices)
        return self.value(key, lambda v: v in choices, expected, default, fix=fix)

    def flag(self, key: str, default: Any = REQUIRED, *, fix: str | None = None) -> Any:
        """true or false."""
        return self.value(key, lambda v: isinstance(v, bool), "true or false", default, fix=fix)

    def integer(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        minimum: int | None = None,
        expected: str | None = None,
        fix: str | None = None,
    ) -> Any:
        """An integer, ≥ ``minimum`` when given."""
        want = expected or ("an integer" if minimum is None else f"an integer ≥ {minimum}")

        def check(v: Any) -> bool:
            return is_integer(v) and (minimum is None or v >= minimum)

        return self.value(key, check, want, default, fix=fix)

    def number(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        minimum: float | None = None,
        maximum: float | None = None,
        positive: bool = False,
        fix: str | None = None,
    ) -> Any:
        """A finite number as a float, within the bounds (``positive``: > 0)."""
        bounds = ["> 0" if positive else "", "" if minimum is None else f"≥ {minimum}"]
        bounds.append("" if maximum is None else f"≤ {maximum}")
        words = " and ".join(b for b in bounds if b)
        expected = f"a finite number {words}".rstrip()

        def check(v: Any) -> bool:
            return (
                is_number(v)
                and math.isfinite(v)
                and (not positive or v > 0)
                and (minimum is None or v >= minimum)
                and (maximum is None or v <= maximum)
            )

        value = self.value(key, check, expected, default, fix=fix)
        return float(value) if key in self.data else value

    # --- lists and tables ---------------------------------------------------------------------

    def texts(
        self, key: str, default: Any = REQUIRED, *, one_ok: bool = False, fix: str | None = None
    ) -> Any:
        """A list of strings as a tuple (``one_ok``: a single string is a list of one)."""
        if one_ok and isinstance(self.data.get(key), str):
            return (self.data[key],)

        def check(v: Any) -> bool:
            return isinstance(v, list | tuple) and all(isinstance(x, str) for x in v)

        value = self.value(key, check, "a list of strings", default, fix=fix)
        return tuple(value) if key in self.data else value

    def numbers(
        self,
        key: str,
        default: Any = REQUIRED,
        *,
        length: int,
        integers: tuple[int, int] | None = None,
        fix: str | None = None,
    ) -> Any:
        """``length`` finite numbers as a tuple of floats (``integers=(lo, hi)``: integers in
        that range, as ints)."""
        if integers is None:
            expected = f"a list of {length} numbers"

            def check(v: Any) -> bool:
                return all(is_number(x) and math.isfinite(x) for x in v)
        else:
            expected = f"a list of {length} integers in {integers[0]}..{integers[1]}"

            def check(v: Any) -> bool:
                return all(is_integer(x) and integers[0] <= x <= integers[1] for x in v)

        def full(v: Any) -> bool:
            return isinstance(v, list | tuple) and len(v) == length and check(v)

        value = self.value(key, full, expected, default, fix=fix)
        if key not in self.data:
            return value
        return tuple(value) if integers is not None else tuple(float(x) for x in value)

    def mapping(self, key: str, default: Any = REQUIRED, *, fix: str | None = None) -> Any:
        """A mapping, unchecked inside."""
        check = lambda v: isinstance(v, Mapping)  # noqa: E731
        return self.value(key, check, self.MAPPING, default, fix=fix)

    def table(self, key: str, default: Any = REQUIRED, *, fix: str | None = None) -> Table:
        """The sub-table ``key`` as a Table (``default``: a mapping used when absent)."""
        data = self.mapping(key, default, fix=fix)
        return self.child(data, self.at(key))

    def tables(self, key: str, default: Any = REQUIRED, *, fix: str | None = None) -> list[Table]:
        """An array of tables (``[[key]]``), each a Table at ``key[i]``."""
        items = self.value(key, lambda v: isinstance(v, list | tuple), "a list", default, fix=fix)
        return [self.child(item, f"{self.at(key)}[{i}]") for i, item in enumerate(items)]

    def child(self, data: Any, where: str) -> Table:
        """A Table of the same kind, file and style at ``where``."""
        return type(self)(data, source=self.source, where=where, style=self.style)
