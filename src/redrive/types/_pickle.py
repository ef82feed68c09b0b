"""Pickling for types that hold read-only mappings (``MappingProxyType`` does not pickle).

Used when frames cross a process boundary (worker processes of the engine).  The object is
rebuilt through its constructor, so ``__post_init__`` checks it again on the other side.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from typing import Any

__all__ = ["rebuild", "reduce_dataclass"]


def rebuild(cls: type[Any], kwargs: dict[str, Any]) -> Any:
    return cls(**kwargs)


def reduce_dataclass(obj: Any) -> tuple[Any, tuple[type[Any], dict[str, Any]]]:
    """A ``__reduce__`` value that rebuilds ``obj`` from its fields, mappings as plain dicts."""
    kwargs: dict[str, Any] = {}
    for f in fields(obj):
        value = getattr(obj, f.name)
        kwargs[f.name] = dict(value) if isinstance(value, Mapping) else value
    return rebuild, (type(obj), kwargs)
