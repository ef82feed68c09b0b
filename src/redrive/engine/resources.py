"""Per-process CPU and memory, sampled with psutil while a run goes on.

The engine process is sampled as ``engine``; every worker process as ``STAGE/ALGORITHM``.  Per-step
CPU time of algorithms running in the engine's threads is measured exactly by the steps themselves
(``cpu_ns``); memory is a property of a process, so in-process algorithms share the ``engine``
row.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Mapping

import psutil

from redrive.results import ResourceSample

__all__ = ["ResourceSampler"]

logger = logging.getLogger(__name__)


class ResourceSampler:
    """A daemon thread taking a sample of each process every ``interval_s``.

    Args:
        pids: called at every sample: label → pid of the worker processes alive now.
        interval_s: time between samples.
    """

    def __init__(self, pids: Callable[[], Mapping[str, int]], *, interval_s: float = 0.5) -> None:
        self._pids = pids
        self._interval_s = interval_s
        self._stop = threading.Event()
        self._procs: dict[int, psutil.Process] = {}
        self.samples: list[ResourceSample] = []
        self._thread = threading.Thread(target=self._loop, name="redrive-sampler", daemon=True)

    def start(self) -> ResourceSampler:
        self._sample()  # primes cpu_percent (its first call returns 0.0)
        self._thread.start()
        return self

    def stop(self) -> list[ResourceSample]:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(2.0)
        self._sample()
        return self.samples

    def _loop(self) -> None:
        while not self._stop.wait(self._interval_s):
            self._sample()

    def _process(self, pid: int) -> psutil.Process:
        proc = self._procs.get(pid)
        if proc is None:
            proc = self._procs[pid] = psutil.Process(pid)
            proc.cpu_percent(None)
        return proc

    def _sample(self) -> None:
        targets = {"engine": os.getpid(), **dict(self._pids())}
        t_ns = time.time_ns()
        for label, pid in targets.items():
            try:
                proc = self._process(pid)
                with proc.oneshot():
                    cpu = proc.cpu_percent(None)
                    rss = proc.memory_info().rss
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                self._procs.pop(pid, None)
                continue
            self.samples.append(
                ResourceSample(t_ns=t_ns, label=label, pid=pid, cpu_percent=cpu, rss_bytes=rss)
            )
