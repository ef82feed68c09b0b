"""Typed reads of one JSON object of a run manifest (the one validator, :mod:`redrive.config.validate`,
with the manifest's messages), each failure a ConfigError naming the field.

A field ``where`` is the dotted path in the manifest (``pipeline.first_frame``,
``algorithms[2].role``); a message says which file, which field, what was found and what to do.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from redrive.config.validate import REQUIRED, Style, Table, is_integer, is_number
from redrive.errors import ConfigError

__all__ = ["DAMAGED_ADVICE", "Fields", "manifest_error"]

T = TypeVar("T")

#: what to do about a manifest that cannot be read.
DAMAGED_ADVICE = (
    "the manifest is damaged or was not written by redrive; restore it, or re-run "
    "`redrive run LOG --out NEW_DIR` to make the run again"
)


def manifest_error(path: Path, problem: str, advice: str = DAMAGED_ADVICE) -> ConfigError:
    """``PATH: run manifest PROBLEM; ADVICE`` as a ConfigError."""
    return ConfigError(f"{path}: run manifest {problem}; {advice}")


def _manifest_style(source: str, path: str, problem: str, fix: str) -> str:
    return f"{source}: run manifest field `{path}` is {problem}; {fix}"


class Fields(Table):
    """Typed getters over one JSON object ``data`` at ``where`` in the manifest at ``path``: the
    reads of :class:`~redrive.config.validate.Table`, plus JSON's nulls and string maps."""

    MAPPING = "an object"

    def __init__(
        self,
        data: Any,
        *,
        path: Path,
        where: str = "",
        style: Style = _manifest_style,
    ) -> None:
        self.path = path
        super().__init__(data, source=str(path), where=where, style=style)

    def name(self, key: str) -> str:
        return self.at(key)

    def missing(self, key: str, expected: str, fix: str | None = None) -> ConfigError:
        return manifest_error(self.path, f"has no field `{self.at(key)}`")

    def wrong(self, key: str, value: Any, expected: str, fix: str | None = None) -> ConfigError:
        return super().wrong(key, value, expected, fix or DAMAGED_ADVICE)

    def opt_text(self, key: str, default: Any = REQUIRED) -> str | None:
        check = lambda v: v is None or isinstance(v, str)  # noqa: E731
        out: str | None = self.value(key, check, "a string or null", default)
        return out

    def opt_integer(self, key: str, default: Any = REQUIRED) -> int | None:
        check = lambda v: v is None or is_integer(v)  # noqa: E731
        out: int | None = self.value(key, check, "an integer or null", default)
        return out

    def opt_number(self, key: str, default: Any = REQUIRED) -> float | None:
        check = lambda v: v is None or is_number(v)  # noqa: E731
        value = self.value(key, check, "a number or null", default)
        return None if value is None else float(value)

    def obj(self, key: str) -> Fields:
        return self.child(self.mapping(key), self.at(key))

    def opt_obj(self, key: str, default: Any = REQUIRED) -> Fields | None:
        check = lambda v: v is None or isinstance(v, Mapping)  # noqa: E731
        value = self.value(key, check, "an object or null", default)
        return None if value is None else self.child(value, self.at(key))

    def objs(self, key: str, default: Any = REQUIRED) -> list[Fields]:
        return [f for f in self.tables(key, default) if isinstance(f, Fields)]

    def child(self, data: Any, where: str) -> Fields:
        return Fields(data, path=self.path, where=where, style=self.style)

    def text_map(self, key: str, default: Any = REQUIRED) -> dict[str, str]:
        check = lambda v: isinstance(v, Mapping) and all(isinstance(x, str) for x in v.values())  # noqa: E731
        return dict(self.value(key, check, "an object of strings", default))

    def int_map(self, key: str, default: Any = REQUIRED) -> dict[str, int]:
        check = lambda v: isinstance(v, Mapping) and all(is_integer(x) for x in v.values())  # noqa: E731
        return dict(self.value(key, check, "an object of integers", default))

    def number_map(self, key: str, default: Any = REQUIRED) -> dict[str, float]:
        check = lambda v: isinstance(v, Mapping) and all(is_number(x) for x in v.values())  # noqa: E731
        return {
            k: float(v) for k, v in self.value(key, check, "an object of numbers", default).items()
        }

    def object_map(self, key: str, default: Any = REQUIRED) -> dict[str, dict[str, Any]]:
        check = lambda v: isinstance(v, Mapping) and all(isinstance(x, Mapping) for x in v.values())  # noqa: E731
        return {
            k: dict(v) for k, v in self.value(key, check, "an object of objects", default).items()
        }

    def enum(self, key: str, cls: Callable[[Any], T], allowed: str, default: Any = REQUIRED) -> T:
        """``cls(value)`` of a string field; ``allowed`` lists the values in the error."""
        value = self.raw(key, default)
        try:
            return cls(value)
        except (ValueError, TypeError):
            raise self.wrong(key, value, f"one of {allowed}") from None
