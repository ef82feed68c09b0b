"""setup_frozen: what is alive when a run starts is frozen for the run, and only for it."""

from __future__ import annotations

import gc

import pytest

from redrive.engine._heap import setup_frozen


@pytest.fixture(autouse=True)
def _unfrozen() -> None:
    if gc.get_freeze_count():
        pytest.skip("the heap is frozen already (by something else in this process)")


def test_the_setup_is_frozen_for_the_run_and_unfrozen_after() -> None:
    before = object()  # noqa: F841 - alive at the start
    with setup_frozen():
        assert gc.get_freeze_count() > 0
        with setup_frozen():  # nested: the outer one stays in charge
            assert gc.get_freeze_count() > 0
        assert gc.get_freeze_count() > 0
    assert gc.get_freeze_count() == 0


def test_an_error_in_the_run_unfreezes_too() -> None:
    try:
        with setup_frozen():
            raise RuntimeError("a stage crashed")
    except RuntimeError:
        pass
    assert gc.get_freeze_count() == 0


def test_a_heap_frozen_by_the_process_is_left_frozen() -> None:
    gc.freeze()
    try:
        count = gc.get_freeze_count()
        with setup_frozen():
            pass
        assert gc.get_freeze_count() == count
    finally:
        gc.unfreeze()


def test_as_a_decorator() -> None:
    @setup_frozen()
    def run() -> int:
        return gc.get_freeze_count()

    assert run() > 0
    assert gc.get_freeze_count() == 0
