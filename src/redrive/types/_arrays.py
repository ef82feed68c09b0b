"""Helpers that check and freeze the arrays of the data model (numpy + stdlib only)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import numpy as np
import numpy.typing as npt

__all__ = ["frozen_array", "frozen_vector"]


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
