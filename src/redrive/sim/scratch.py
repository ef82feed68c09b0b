"""Work arrays a sensor model reuses from one sweep or image to the next.

A 64-beam sweep needs ≈ 9 MB of work arrays and a 1280×720 image ≈ 21 MB.  Allocated afresh
each time, glibc maps them anew and the first write to every page faults: measured ≈ 6–8 ms of
CPU for the sweep's arrays against ≈ 1 ms to write the same arrays reused.  A :class:`Scratch`
keeps them per thread (a model drawn on two threads at once gets two sets), so only what a
model hands out (clouds, images, depth maps) is allocated per call.  The arrays come back with
whatever the last call left in them, as ``np.empty`` would: callers write before they read.
"""

from __future__ import annotations

import threading

import numpy as np
import numpy.typing as npt

__all__ = ["Scratch"]


class Scratch:
    """Named work arrays, one set per thread, kept between calls."""

    def __init__(self) -> None:
        self._local = threading.local()

    def __getstate__(self) -> dict[str, object]:
        return {}  # a copied or unpickled model starts with no work arrays

    def __setstate__(self, state: dict[str, object]) -> None:
        self._local = threading.local()

    def array(self, name: str, shape: tuple[int, ...], dtype: type[np.generic]) -> npt.NDArray:  # type: ignore[type-arg]
        """The array ``name`` of this thread with ``shape`` and ``dtype`` (new when either
        changed), its contents left from the last use."""
        arrays: dict[str, npt.NDArray] | None = getattr(self._local, "arrays", None)  # type: ignore[type-arg]
        if arrays is None:
            arrays = self._local.arrays = {}
        out = arrays.get(name)
        if out is None or out.shape != shape or out.dtype != dtype:
            out = arrays[name] = np.empty(shape, dtype=dtype)
        return out
