"""Benchmark results as JSON: a result dataclass's fields as plain values (what ``--json`` prints
and ``make bench``'s summary reads)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["fields_json", "plain"]


def plain(value: Any) -> Any:
    """``value`` JSON-ready: results through their ``to_json``, other dataclasses field by field,
    tuples as lists, paths as text, NaN and infinities as None."""
    if hasattr(value, "to_json"):
        return value.to_json()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return fields_json(value)
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return [plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


def fields_json(obj: Any, **extra: Any) -> dict[str, Any]:
    """Every field of the dataclass ``obj`` (:func:`plain`), then ``extra`` (derived figures)."""
    out = {f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    out.update((k, plain(v)) for k, v in extra.items())
    return out
