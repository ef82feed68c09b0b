"""Helpers that check and freeze the arrays of the data model (numpy + stdlib only)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, cast

import numpy as np
import numpy.typing as npt

__all__ = [
    "bbox",
    "column1",
    "column3",
    "finite",
    "finite_nonnegative",
    "frozen_array",
    "frozen_vector",
    "in_unit",
    "int_column",
    "length_msg",
    "minus_ones",
    "ones",
    "zeros",
]


def frozen_array(
    value: Any,
    *,
    name: str,
    dtype: npt.DTypeLike | Sequence[npt.DTypeLike],
    shape: tuple[int | None, ...],
    copy: bool = False,
) -> npt.NDArray[Any]:
    """Return ``value`` as a read-only array of the given dtype(s) and shape.

    ``shape`` uses ``None`` for a free dimension.  ``dtype`` may be a sequence of accepted dtypes;
    an array of another dtype is rejected rather than silently cast (so a float64 cloud never
    hides in a float32 field).  Plain Python sequences are converted to the first dtype.
    """
    # Compare against the given dtype(s) directly: this runs for every array of every decoded
    # message, so no dtype objects are built on the way.
    candidates: Sequence[Any] = (
        cast("Sequence[Any]", dtype) if isinstance(dtype, list | tuple) else (dtype,)
    )
    if isinstance(value, np.ndarray):
        arr = value
        if not any(arr.dtype == d for d in candidates):
            names = ", ".join(str(np.dtype(d)) for d in candidates)
            msg = f"{name}: dtype {arr.dtype} is not accepted (expected {names})"
            raise ValueError(msg)
        if copy:
            arr = arr.copy()
    else:
        arr = np.array(value, dtype=candidates[0])
    have_shape = arr.shape
    ok = len(have_shape) == len(shape)
    if ok:
        for have, want in zip(have_shape, shape, strict=True):
            if want is not None and have != want:
                ok = False
                break
    if not ok:
        want_s = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        msg = f"{name}: shape {arr.shape} does not match {want_s}"
        raise ValueError(msg)
    if arr.flags.writeable:
        # Freeze a view, never the caller's own array object.
        arr = arr.view()
        arr.flags.writeable = False
    return arr


def frozen_vector(value: Any, *, name: str, size: int) -> npt.NDArray[np.float64]:
    """A read-only float64 vector of ``size`` elements (positions, velocities, quaternions)."""
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (size,):
        if value.flags.writeable:  # the common case, kept short: it runs per object per message
            value = value.view()
            value.flags.writeable = False
        return cast("npt.NDArray[np.float64]", value)
    if isinstance(value, np.ndarray) and value.dtype != np.float64:
        value = value.astype(np.float64)
    return frozen_array(value, name=name, dtype=np.float64, shape=(size,))


# -- the columns of ObjectColumns: checks and shared defaults --------------------------------

#: up to this many values a check reads them as Python floats; beyond, numpy's reductions
_SMALL = 96


def finite_nonnegative(values: npt.NDArray[np.float64]) -> bool:
    """Whether every value is finite and ≥ 0 (-0.0 counts)."""
    if values.size <= _SMALL:
        flat = values.ravel().tolist()
        return all(map(math.isfinite, flat)) and min(flat) >= 0.0  # min after: no NaN left
    return bool(_ALL(np.isfinite(values), axis=None) and _MIN(values, axis=None) >= 0.0)


def finite(values: npt.NDArray[np.float64]) -> bool:
    """Whether every value is finite."""
    if values.size <= _SMALL:
        return all(map(math.isfinite, values.ravel().tolist()))
    return bool(_ALL(np.isfinite(values), axis=None))


def in_unit(values: npt.NDArray[np.float64]) -> bool:
    """Whether every value lies in [0, 1] (NaN does not)."""
    if values.size <= _SMALL:
        flat = values.tolist()
        return all(0.0 <= v <= 1.0 for v in flat)
    return bool(_MIN(values) >= 0.0 and _MAX(values) <= 1.0)  # NaN fails both


def bbox(value: Any, where: str) -> tuple[float, float, float, float]:
    if len(value) != 4:
        msg = f"{where}: a bbox_2d must be (x, y, w, h), got {value!r}"
        raise ValueError(msg)
    x, y, w, h = (float(v) for v in value)
    return (x, y, w, h)


def ones(n: int) -> npt.NDArray[np.float64]:
    """A read-only (n,) column of ones (shared: one per n, for the small n)."""
    arr = _ONES.get(n)
    if arr is None:
        arr = np.ones(n, dtype=np.float64)
        arr.flags.writeable = False
        if n <= _SHARED_DEFAULTS_MAX:
            _ONES[n] = arr
    return arr


def zeros(n: int) -> npt.NDArray[np.float64]:
    """A read-only (n, 3) column of zeros (shared: one per n, for the small n)."""
    arr = _ZEROS.get(n)
    if arr is None:
        arr = np.zeros((n, 3), dtype=np.float64)
        arr.flags.writeable = False
        if n <= _SHARED_DEFAULTS_MAX:
            _ZEROS[n] = arr
    return arr


def minus_ones(n: int) -> npt.NDArray[np.int64]:
    """A read-only (n,) int64 column of -1 (shared: one per n, for the small n)."""
    arr = _MINUS_ONES.get(n)
    if arr is None:
        arr = np.full(n, -1, dtype=np.int64)
        arr.flags.writeable = False
        if n <= _SHARED_DEFAULTS_MAX:
            _MINUS_ONES[n] = arr
    return arr


# the default columns are read-only, so batches of the same size share them
_SHARED_DEFAULTS_MAX = 256
_ONES: dict[int, npt.NDArray[np.float64]] = {}
_ZEROS: dict[int, npt.NDArray[np.float64]] = {}
_MINUS_ONES: dict[int, npt.NDArray[np.int64]] = {}


def length_msg(name: str, have: int, n: int, where: str) -> str:
    return f"{where}: {name} has {have} values for {n} objects"


def column3(value: Any, name: str, n: int, where: str) -> npt.NDArray[np.float64]:
    """``value`` as one read-only float64 (n, 3) array (a copy: the caller keeps its own)."""
    arr = np.array(value, dtype=np.float64)
    if arr.shape != (n, 3):
        msg = f"{where}: {name} must have shape ({n}, 3), got {arr.shape}"
        raise ValueError(msg)
    arr.flags.writeable = False
    return arr


def column1(value: Any, name: str, n: int, where: str) -> npt.NDArray[np.float64]:
    """``value`` as one read-only float64 (n,) array (a copy)."""
    arr = np.array(value, dtype=np.float64)
    if arr.shape != (n,):
        msg = f"{where}: {name} must have shape ({n},), got {arr.shape}"
        raise ValueError(msg)
    arr.flags.writeable = False
    return arr


def int_column(value: Any, name: str, n: int, where: str) -> npt.NDArray[np.int64]:
    """``value`` as one read-only int64 (n,) array (a copy)."""
    arr = np.array(value, dtype=np.int64)
    if arr.shape != (n,):
        msg = f"{where}: {name} has {arr.size} values for {n} objects"
        raise ValueError(msg)
    arr.flags.writeable = False
    return arr


_ALL, _MIN, _MAX = np.logical_and.reduce, np.minimum.reduce, np.maximum.reduce
