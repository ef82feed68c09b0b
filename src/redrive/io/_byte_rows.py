"""The same few bytes at many positions of a buffer, gathered into one array."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["byte_rows"]


def byte_rows(buf: Any, at: npt.NDArray[np.int64], width: int) -> npt.NDArray[np.uint8]:
    """A (len(at), width) uint8 copy: row i is ``buf[at[i] : at[i] + width]``.

    Every ``at[i] + width`` must lie within ``buf`` (the caller checks; numpy raises IndexError
    otherwise).  One ``width``-byte record is copied per row (an index into a view whose element
    j is the ``width`` bytes from byte j), not one element per byte.
    """
    if width == 0:
        return np.zeros((len(at), 0), dtype=np.uint8)
    size = memoryview(buf).nbytes
    every: npt.NDArray[Any] = np.ndarray(
        (size - width + 1,), np.dtype((np.void, width)), buf, 0, (1,)
    )
    return every[at].view(np.uint8).reshape(len(at), width)
