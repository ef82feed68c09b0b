"""One conversion of configuration values, defaults and summaries to JSON-ready data."""

from __future__ import annotations

import enum
from collections.abc import Mapping
from typing import Any

__all__ = ["to_jsonable"]


def to_jsonable(value: Any) -> Any:
    """``value`` as JSON-ready data: enums become their values, mappings dicts with str keys,
    tuples/lists lists, sets sorted lists, numpy arrays and scalars Python lists and numbers;
    anything else its ``repr``.

    >>> import numpy as np
    >>> from redrive.types import SensorType
    >>> to_jsonable({"mode": SensorType.LIDAR, "gain": np.float64(3.0), "sizes": (1, 2)})
    {'mode': 'lidar', 'gain': 3.0, 'sizes': [1, 2]}
    """
    if isinstance(value, enum.Enum):
        return to_jsonable(value.value)
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [to_jsonable(v) for v in value]
    if isinstance(value, set | frozenset):
        return [to_jsonable(v) for v in sorted(value, key=repr)]
    if hasattr(value, "tolist") and type(value) not in (bool, int, float, str):
        return to_jsonable(value.tolist())  # numpy arrays and scalars
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return repr(value)
