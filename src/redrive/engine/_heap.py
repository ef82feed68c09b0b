"""The garbage collector during a run (see :func:`setup_frozen`)."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["setup_frozen"]


@contextmanager
def setup_frozen() -> Iterator[None]:
    """The objects alive when a run starts — imports, plugins and their compiled kernels, the
    log's index — out of the garbage collector's sight for the run (``gc.freeze``), back after
    it (``gc.unfreeze``).

    A run allocates many short-lived objects (records, rows, decoded messages); every so often
    they trigger a full collection, which walks every object of the process — with numba and
    pyarrow loaded a walk of ≈ 0.1–0.2 s, in the frame loop or in the results writer's last
    flush. Frozen, those walks see only what the run made. Nothing is leaked: what was garbage
    at the start is collected after the run. Nested uses, and a process that froze its heap
    itself (a pre-fork server), are left as they are.
    """
    # nested: the outer use froze the heap (asked before gc.get_freeze_count, which walks the
    # whole frozen generation to count it — tens of ms with numba and pyarrow loaded)
    if _frozen[0] or gc.get_freeze_count():
        yield
        return
    gc.freeze()
    _frozen[0] = True
    try:
        yield
    finally:
        _frozen[0] = False
        gc.unfreeze()


#: whether a setup_frozen of this process holds the heap frozen now
_frozen = [False]
