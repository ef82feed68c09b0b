"""Work on the next items of a sequence in a background thread while the caller uses this one.

Used where the heavy part of each item's work releases the GIL (zstd and lz4 decompression,
the CRC-32 of large buffers): reading a log then runs on a second core beside the decoding
and the algorithms.  Results come back in order; an exception is raised where the caller takes
the result that raised it, as a plain ``map`` would.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Generator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

__all__ = ["prefetched"]

T = TypeVar("T")
R = TypeVar("R")


def prefetched(
    fn: Callable[[T], R], items: Sequence[T], *, ahead: int = 2
) -> Generator[R, None, None]:
    """``fn(item)`` for each item in order, computed up to ``ahead`` items before it is taken.

    With fewer than two items no thread is started.  Closing the iterator early cancels what
    was not started and waits for the item being computed (memory: ``ahead`` results at most).
    """
    if len(items) < 2 or ahead < 1:
        yield from map(fn, items)
        return
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="redrive-prefetch")
    pending: deque[Future[R]] = deque()
    try:
        position = 0
        while position < len(items) or pending:
            while position < len(items) and len(pending) <= ahead:
                pending.append(pool.submit(fn, items[position]))
                position += 1
            yield pending.popleft().result()
    finally:
        for future in pending:
            future.cancel()
        pool.shutdown(wait=True)
