"""The fixtures of redrive's test suite that these tests use too (``tests/conftest.py``: the real
data in ../shared/data, the demo log and run, the signal handlers restored; ``tests/interop``:
the 1-s log), so that ``pytest benchmarks/tests`` finds them as ``pytest tests`` does."""

from __future__ import annotations

from tests.conftest import _signal_handlers_restored, demo_log, demo_run, shared_data
from tests.interop.conftest import short_log, short_run

__all__ = [
    "_signal_handlers_restored",
    "demo_log",
    "demo_run",
    "shared_data",
    "short_log",
    "short_run",
]
