"""The read-ahead thread of the MCAP reader: results in order, errors where they belong, no
thread left behind when the reader stops early."""

from __future__ import annotations

import threading

import pytest

from redrive.io.mcap._prefetch import prefetched


def _prefetch_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith("redrive-prefetch")]


def test_results_in_order_and_an_error_raised_at_its_item() -> None:
    seen: list[int] = []

    def square(x: int) -> int:
        if x == 5:
            raise ValueError("five")
        return x * x

    def take_all() -> None:
        seen.extend(prefetched(square, list(range(8)), ahead=2))

    with pytest.raises(ValueError, match="five"):
        take_all()
    assert seen == [0, 1, 4, 9, 16]
    assert list(prefetched(square, [3])) == [9]
    assert not _prefetch_threads()


def test_stopping_early_ends_the_thread_and_reads_at_most_ahead() -> None:
    started: list[int] = []
    results = prefetched(started.append, list(range(100)), ahead=2)
    next(results)
    assert _prefetch_threads()
    results.close()
    assert not _prefetch_threads()
    assert started == list(range(len(started)))
    assert len(started) <= 4  # the item taken, two ahead, and one the pool had begun
