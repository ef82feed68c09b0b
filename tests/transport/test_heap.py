"""redrive.transport.heap: glibc's thresholds are raised where glibc is the C library."""

from __future__ import annotations

import platform
import sys

import pytest

from redrive.transport.heap import keep_freed_memory


@pytest.mark.skipif(
    not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc",
    reason="mallopt thresholds are glibc's",
)
def test_glibc_takes_the_thresholds() -> None:
    assert keep_freed_memory() is True
    assert keep_freed_memory() is True  # once per process; asking again changes nothing


def test_elsewhere_nothing_happens(monkeypatch: pytest.MonkeyPatch) -> None:
    keep_freed_memory.cache_clear()
    monkeypatch.setattr(sys, "platform", "darwin")
    try:
        assert keep_freed_memory() is False
    finally:
        keep_freed_memory.cache_clear()
