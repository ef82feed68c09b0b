"""One conversion of configuration values, summaries and defaults to JSON-ready data."""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from typing import Any

__all__ = ["to_jsonable"]


def to_jsonable(value: Any, *, strict: bool = False) -> Any:
    """``value`` as JSON-ready data: enums become their values, mappings dicts with str keys,
    tuples/lists/sets lists, numpy arrays and scalars Python lists and numbers.

    Anything else becomes its ``repr`` — or, with ``strict``, a :class:`TypeError` naming it; a
    non-finite float is kept unless ``strict`` (JSON has no NaN), then it is a :class:`ValueError`.
    """
    if isinstance(value, enum.Enum):
        return to_jsonable(value.value, strict=strict)
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v, strict=strict) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        items = sorted(value, key=repr) if isinstance(value, set | frozenset) else value
        return [to_jsonable(v, strict=strict) for v in items]
    if hasattr(value, "tolist") and not isinstance(value, bool | int | float | str):
        return to_jsonable(value.tolist(), strict=strict)  # numpy arrays and scalars
    if isinstance(value, float) and strict and not math.isfinite(value):
        msg = f"{value} is not a JSON number (no NaN or infinity)"
        raise ValueError(msg)
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if strict:
        msg = f"{type(value).__name__} {value!r} is not JSON-serialisable"
        raise TypeError(msg)
    return repr(value)
