"""CPU and memory of the engine's processes and threads, sampled with psutil during a run.

Labels: ``engine`` (the engine process), ``STAGE/ALGORITHM`` (a worker process), and
``thread:NAME`` for the engine's own threads — ``thread:main``, and in pipelined mode
``thread:reader`` and ``thread:STAGE`` (one per stage): a pipelined run with in-process
algorithms gets its CPU per stage this way.  A thread's ``rss_bytes`` is its process's (memory
belongs to processes).  Per-step CPU time is measured exactly by the steps themselves (``cpu_ns``
in the steps table).
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
        threads: called at every sample: label → native id of engine threads to sample.
        interval_s: time between samples.
    """

    def __init__(
        self,
        pids: Callable[[], Mapping[str, int]],
        *,
        threads: Callable[[], Mapping[str, int]] | None = None,
        interval_s: float = 0.5,
    ) -> None:
        self._pids = pids
        self._threads = threads
        self._thread_cpu: dict[int, tuple[float, float]] = {}  # native id → (cpu s, wall s)
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
        if self._threads is not None:
            self._sample_threads(t_ns)
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

    def _sample_threads(self, t_ns: int) -> None:
        assert self._threads is not None
        wanted = {tid: label for label, tid in self._threads().items()}
        if not wanted:
            return
        try:
            proc = self._process(os.getpid())
            rss = proc.memory_info().rss
            threads = proc.threads()
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            return
        now_s = time.monotonic()
        for th in threads:
            label = wanted.get(th.id)
            if label is None:
                continue
            cpu_s = th.user_time + th.system_time
            last = self._thread_cpu.get(th.id)
            self._thread_cpu[th.id] = (cpu_s, now_s)
            if last is None or now_s <= last[1]:
                continue  # the first sight of a thread primes it
            percent = 100.0 * (cpu_s - last[0]) / (now_s - last[1])
            self.samples.append(
                ResourceSample(
                    t_ns=t_ns, label=label, pid=os.getpid(), cpu_percent=percent, rss_bytes=rss
                )
            )
