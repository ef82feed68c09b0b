"""A keep-latest reader with a backlog: it starts, and after being lapped goes on, at the oldest
message the ring still holds instead of the newest (the live dispatcher's ego-state streams)."""

from __future__ import annotations

import threading
import uuid
from collections.abc import Iterator

import numpy as np
import pytest

from redrive.transport import Message, Policy, Reader, Writer, segment_path
from redrive.transport.segment import S_BEGIN, W_ORDER, W_WRITE_SEQ


@pytest.fixture
def name() -> Iterator[str]:
    stream = f"test.{uuid.uuid4().hex[:12]}"
    yield stream
    assert not segment_path(stream).exists(), f"{segment_path(stream)} left behind"


def _read(reader: Reader) -> tuple[int, int, int]:
    msg = reader.read(timeout_s=1.0)
    assert msg is not None
    return msg.seq, msg.dropped_before, int(msg.payload[0])


def test_a_backlog_reader_joins_at_the_oldest_held_and_resumes_there_when_lapped(
    name: str,
) -> None:
    with (
        Writer(name, capacity_bytes=64, slots=6, max_readers=3, policy=Policy.KEEP_LATEST) as w,
        Reader(name) as idle,  # reads nothing: the ring keeps the newest six messages
    ):
        for i in range(1, 11):
            w.publish(np.full(64, i, np.uint8))
        with Reader(name, backlog=True) as backlog, Reader(name) as newest:
            # joined at 5, like a late lossless reader: 6 to 10 are still held
            assert [_read(backlog) for _ in range(5)] == [(i, 0, i) for i in range(6, 11)]
            for i in range(11, 31):
                w.publish(np.full(64, i, np.uint8))
            # a ring behind: the default goes to the newest message ...
            assert _read(newest) == (30, 20, 30)
            # ... a backlog reader to the oldest one still held, and reads on from there
            assert [_read(backlog) for _ in range(6)] == [(25, 14, 25)] + [
                (i, 0, i) for i in range(26, 31)
            ]
            assert backlog.read(timeout_s=0.0) is None
        assert idle.read(timeout_s=0.0) is not None


def test_a_backlog_reader_does_not_spin_past_the_newest_message_being_rewritten(
    name: str,
) -> None:
    """The only message held is being rewritten (its slot's begin mark moved on): the read
    waits for the next one instead of running ahead of the writer."""
    with Writer(name, capacity_bytes=64, slots=4, policy=Policy.KEEP_LATEST) as w:
        w.publish(np.full(64, 1, np.uint8))
        with Reader(name, backlog=True) as r:
            words = r._w
            newest = int(words[W_WRITE_SEQ])
            slot = int(words[W_ORDER + newest % r._n_slots])
            words[r._slot_words[slot] + S_BEGIN] = newest + 1  # as if rewritten from here on
            got: list[Message | None] = []
            reading = threading.Thread(
                target=lambda: got.append(r.read(timeout_s=0.3)), daemon=True
            )
            reading.start()
            reading.join(timeout=10.0)
            assert not reading.is_alive(), "the read never returned"
            assert got == [None]
            w.publish(np.full(64, 2, np.uint8))
            assert _read(r) == (2, 1, 2)
