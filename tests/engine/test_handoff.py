"""The pipelined engine's hand-off between two threads: order, bound, close."""

from __future__ import annotations

import threading

import pytest

from redrive.engine.handoff import Handoff, HandoffClosedError


def test_items_come_out_in_order_across_threads_through_a_short_handoff() -> None:
    handoff = Handoff(2)
    got: list[int] = []

    def consume() -> None:
        while (item := handoff.get()) is not None:
            got.append(item)

    consumer = threading.Thread(target=consume)
    consumer.start()
    for i in range(5000):  # the producer waits whenever two items are in flight
        handoff.put(i)
    handoff.put(None)
    consumer.join(timeout=30)
    assert got == list(range(5000))


def test_close_wakes_a_waiting_consumer_and_refuses_puts() -> None:
    handoff = Handoff(1)
    raised: list[type[BaseException]] = []

    def consume() -> None:
        try:
            handoff.get()  # nothing comes: waits until closed
        except HandoffClosedError as err:
            raised.append(type(err))

    consumer = threading.Thread(target=consume)
    consumer.start()
    handoff.close()
    consumer.join(timeout=30)
    assert raised == [HandoffClosedError]
    with pytest.raises(HandoffClosedError):
        handoff.put(1)


def test_close_wakes_a_producer_waiting_on_a_full_handoff() -> None:
    handoff = Handoff(1)
    handoff.put("first")
    raised: list[type[BaseException]] = []

    def produce() -> None:
        try:
            handoff.put("second")  # full: waits until closed
        except HandoffClosedError as err:
            raised.append(type(err))

    producer = threading.Thread(target=produce)
    producer.start()
    handoff.close()
    producer.join(timeout=30)
    assert raised == [HandoffClosedError]
    with pytest.raises(HandoffClosedError):
        handoff.get()


def test_depth_must_be_positive() -> None:
    with pytest.raises(ValueError, match="depth"):
        Handoff(0)
