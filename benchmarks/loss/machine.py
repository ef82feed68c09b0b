"""The machine a run is on: what it is, and how late it wakes up from a sleep."""

from __future__ import annotations

import contextlib
import os
import platform
import time
from pathlib import Path

import numpy as np

from benchmarks.loss.measures import _pct

__all__ = ["wakeup_probe"]


def _machine() -> dict[str, str]:
    model = platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    load = ""
    with contextlib.suppress(OSError):
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
    return {
        "cpu": model,
        "cpus": str(os.cpu_count()),
        "system": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "numpy": np.__version__,
        "load_average_at_start": load,
    }


def wakeup_probe(seconds: float, *, period_s: float = 1 / 600) -> dict[str, float]:
    """How late ``time.sleep(period_s)`` wakes up on this machine, in ms (p50, p99, p99.9, max)
    and the fraction of sleeps that overshoot by more than ``period_s``: the floor under the
    ``late`` count of a stream at ``1 / period_s`` Hz, whatever the transport (the collector wakes
    up like this before every message)."""
    n = max(1, round(seconds / period_s))
    over = np.empty(n)
    for i in range(n):
        t = time.monotonic_ns()
        time.sleep(period_s)
        over[i] = (time.monotonic_ns() - t) / 1e6 - period_s * 1e3
    return {
        "period_ms": period_s * 1e3,
        "sleeps": float(n),
        "overshoot_p50_ms": _pct(over, 50),
        "overshoot_p99_ms": _pct(over, 99),
        "overshoot_p999_ms": _pct(over, 99.9),
        "overshoot_max_ms": float(over.max()),
        "fraction_over_one_period": float(np.mean(over > period_s * 1e3)),
    }
