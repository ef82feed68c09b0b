"""Typed reads of one JSON object of a run manifest, each failure a ConfigError naming the field.

A field ``where`` is the dotted path in the manifest (``pipeline.first_frame``,
``algorithms[2].role``); a message says which file, which field, what was found and what to do.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from redrive.errors import ConfigError

__all__ = ["DAMAGED_ADVICE", "Fields", "manifest_error"]

T = TypeVar("T")

#: what to do about a manifest that cannot be read.
DAMAGED_ADVICE = (
    "the manifest is damaged or was not written by redrive; restore it, or re-run "
    "`redrive run LOG --out NEW_DIR` to make the run again"
)
_ABSENT = object()


def manifest_error(path: Path, problem: str, advice: str = DAMAGED_ADVICE) -> ConfigError:
    """``PATH: run manifest PROBLEM; ADVICE`` as a ConfigError."""
    return ConfigError(f"{path}: run manifest {problem}; {advice}")


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _kind(value: Any) -> str:
    names = {dict: "an object", list: "a list", str: "a string", bool: "a boolean"}
    if value is None:
        return "null"
    for cls, name in names.items():
        if isinstance(value, cls):
            return name
    return "a number" if isinstance(value, int | float) else type(value).__name__


class Fields:
    """Typed getters over one JSON object ``data`` at ``where`` in the manifest at ``path``."""

    def __init__(self, data: Any, *, path: Path, where: str = "") -> None:
        if not isinstance(data, Mapping):
            raise manifest_error(path, f"field `{where}` is {_kind(data)}, expected an object")
        self.data: Mapping[str, Any] = data
        self.path = path
        self.where = where

    def name(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def wrong(self, key: str, value: Any, expected: str) -> ConfigError:
        return manifest_error(
            self.path,
            f"field `{self.name(key)}` is {_kind(value)} ({_shown(value)}), expected {expected}",
        )

    def _get(self, key: str, default: Any) -> Any:
        value = self.data.get(key, _ABSENT)
        if value is _ABSENT:
            if default is not _ABSENT:
                return default
            raise manifest_error(self.path, f"has no field `{self.name(key)}`")
        return value

    def _typed(self, key: str, check: Callable[[Any], bool], expected: str, default: Any) -> Any:
        value = self._get(key, default)
        if value is default and default is not _ABSENT:
            return value
        if not check(value):
            raise self.wrong(key, value, expected)
        return value

    def text(self, key: str, default: Any = _ABSENT) -> str:
        out: str = self._typed(key, lambda v: isinstance(v, str), "a string", default)
        return out

    def opt_text(self, key: str, default: Any = _ABSENT) -> str | None:
        check = lambda v: v is None or isinstance(v, str)  # noqa: E731
        out: str | None = self._typed(key, check, "a string or null", default)
        return out

    def integer(self, key: str, default: Any = _ABSENT) -> int:
        check = lambda v: isinstance(v, int) and not isinstance(v, bool)  # noqa: E731
        out: int = self._typed(key, check, "an integer", default)
        return out

    def opt_integer(self, key: str, default: Any = _ABSENT) -> int | None:
        check = lambda v: v is None or (isinstance(v, int) and not isinstance(v, bool))  # noqa: E731
        out: int | None = self._typed(key, check, "an integer or null", default)
        return out

    def opt_number(self, key: str, default: Any = _ABSENT) -> float | None:
        check = lambda v: v is None or (isinstance(v, int | float) and not isinstance(v, bool))  # noqa: E731
        value = self._typed(key, check, "a number or null", default)
        return None if value is None else float(value)

    def flag(self, key: str, default: Any = _ABSENT) -> bool:
        out: bool = self._typed(key, lambda v: isinstance(v, bool), "true or false", default)
        return out

    def mapping(self, key: str, default: Any = _ABSENT) -> Mapping[str, Any]:
        check = lambda v: isinstance(v, Mapping)  # noqa: E731
        out: Mapping[str, Any] = self._typed(key, check, "an object", default)
        return out

    def obj(self, key: str) -> Fields:
        return Fields(self.mapping(key), path=self.path, where=self.name(key))

    def opt_obj(self, key: str, default: Any = _ABSENT) -> Fields | None:
        value = self._typed(
            key, lambda v: v is None or isinstance(v, Mapping), "an object or null", default
        )
        return None if value is None else Fields(value, path=self.path, where=self.name(key))

    def objs(self, key: str, default: Any = _ABSENT) -> list[Fields]:
        items = self._typed(key, lambda v: isinstance(v, list), "a list", default)
        return [
            Fields(item, path=self.path, where=f"{self.name(key)}[{i}]")
            for i, item in enumerate(items)
        ]

    def texts(self, key: str, default: Any = _ABSENT) -> tuple[str, ...]:
        check = lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v)  # noqa: E731
        return tuple(self._typed(key, check, "a list of strings", default))

    def text_map(self, key: str, default: Any = _ABSENT) -> dict[str, str]:
        check = lambda v: isinstance(v, Mapping) and all(isinstance(x, str) for x in v.values())  # noqa: E731
        return dict(self._typed(key, check, "an object of strings", default))

    def int_map(self, key: str, default: Any = _ABSENT) -> dict[str, int]:
        def check(v: Any) -> bool:
            return isinstance(v, Mapping) and all(
                isinstance(x, int) and not isinstance(x, bool) for x in v.values()
            )

        return dict(self._typed(key, check, "an object of integers", default))

    def enum(self, key: str, cls: Callable[[Any], T], allowed: str, default: Any = _ABSENT) -> T:
        """``cls(value)`` of a string field; ``allowed`` lists the values in the error."""
        value = self._get(key, default)
        try:
            return cls(value)
        except (ValueError, TypeError):
            raise self.wrong(key, value, f"one of {allowed}") from None
