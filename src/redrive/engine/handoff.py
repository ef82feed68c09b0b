"""The hand-off between two threads of the pipelined engine: a short bounded FIFO.

``queue.Queue`` (what the engine used before) serves any number of producers and consumers: three
conditions over one lock, task accounting, and — so that a stop request is seen — a get or put
that wakes every 50 ms to look at an event.  Between two stages there is exactly one producer
and one consumer, so one condition is enough: at most one side can be waiting (the producer on a
full hand-off, or the consumer on an empty one, never both), a notify is only sent when a thread
is inside the wait, and :meth:`Handoff.close` wakes it at once — no polling.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any

__all__ = ["Handoff", "HandoffClosedError"]


class HandoffClosedError(Exception):
    """The hand-off was closed (the run is stopping): nothing more goes in or comes out."""


class Handoff:
    """A bounded FIFO between one producer thread and one consumer thread.

    Args:
        depth: how many items it holds before :meth:`put` waits (≥ 1).
    """

    __slots__ = ("_closed", "_cond", "_depth", "_items", "_waiting")

    def __init__(self, depth: int) -> None:
        if depth < 1:
            msg = f"Handoff depth must be >= 1, got {depth}"
            raise ValueError(msg)
        self._depth = depth
        self._items: deque[Any] = deque()
        self._cond = threading.Condition(threading.Lock())
        self._waiting = 0  # threads inside wait(), woken or not (a bool loses a wake-up)
        self._closed = False

    def put(self, item: Any) -> None:
        """Append ``item``, waiting while the hand-off is full.

        Raises:
            HandoffClosedError: it is closed (before or while waiting).
        """
        with self._cond:
            while len(self._items) >= self._depth and not self._closed:
                self._wait()
            if self._closed:
                raise HandoffClosedError
            self._items.append(item)
            if self._waiting:
                self._cond.notify()

    def get(self) -> Any:
        """The oldest item, waiting while the hand-off is empty.

        Raises:
            HandoffClosedError: it is closed (before or while waiting).
        """
        with self._cond:
            while not self._items and not self._closed:
                self._wait()
            if self._closed:
                raise HandoffClosedError
            item = self._items.popleft()
            if self._waiting:
                self._cond.notify()
            return item

    def close(self) -> None:
        """Refuse every further put and get, and wake the side that is waiting."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def _wait(self) -> None:
        self._waiting += 1
        try:
            self._cond.wait()
        finally:
            self._waiting -= 1
