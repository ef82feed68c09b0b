"""The memory bound of an algorithm's worker process (``--max-rss``, ``max_rss_mb``; issue 37).

Two checks, both on the worker's *resident set* (what ``ps`` calls RSS: the interpreter, its
libraries and what the plugin allocated and touched):

- while a step runs, :class:`RssWatch` (a daemon thread of the engine) reads the worker's RSS
  every :data:`WATCH_INTERVAL_S` and kills it with SIGKILL once it is past the bound, so a step
  allocating without end cannot take the machine's memory (it overshoots by at most what it
  touches in one interval);
- after each step the worker reports its peak RSS (:func:`peak_rss_bytes`: Linux's ``VmHWM``), so
  a step that went past the bound and came back between two reads is caught too.  Every step
  over the bound ends its worker, so the peak before a step is always within it and a peak past
  it belongs to the step just done.

Why not ``RLIMIT_AS`` in the worker: it bounds the *address space*, which counts what is only
reserved — thread stacks, malloc arenas (64 MiB each), numba's and Arrow's pools — and makes
allocations fail as ``MemoryError`` inside the plugin (or crash C code that does not expect a
failed ``malloc``), while the resident set is what a machine runs out of.
"""

from __future__ import annotations

import contextlib
import os
import resource
import signal
import sys
import threading
import time

import psutil

__all__ = ["WATCH_INTERVAL_S", "RssWatch", "peak_rss_bytes"]

#: how often the RSS of a worker running a step is read (seconds)
WATCH_INTERVAL_S = 0.01
_MIB = 1 << 20


def peak_rss_bytes() -> int:
    """The peak resident set of this process since it started (its exec: not the parent's).

    Linux: ``VmHWM`` of ``/proc/self/status`` (``ru_maxrss`` is not used there: it keeps the
    parent's peak across the fork + exec that starts a spawned worker).  Elsewhere
    ``ru_maxrss`` (bytes on macOS, KiB on the BSDs)."""
    try:
        with open("/proc/self/status", "rb") as fh:
            for line in fh:
                if line.startswith(b"VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(peak) if sys.platform == "darwin" else int(peak) * 1024


def mib(value: int) -> str:
    """``value`` bytes in MiB, for messages."""
    return f"{value / _MIB:,.0f} MiB"


class RssWatch:
    """Kills the watched process with SIGKILL when its RSS goes past ``limit_bytes``.

    :meth:`arm` before a step, :meth:`disarm` after it: the thread reads the RSS only in
    between (an idle worker is not watched).  After a kill, :attr:`killed_rss` holds the RSS it
    saw (None otherwise) until the next :meth:`arm`.
    """

    def __init__(self, limit_bytes: int, *, interval_s: float | None = None) -> None:
        self.limit_bytes = limit_bytes
        self.interval_s = WATCH_INTERVAL_S if interval_s is None else interval_s
        self.killed_rss: int | None = None
        self._lock = threading.Lock()
        self._armed = threading.Event()
        self._closed = False
        self._proc: psutil.Process | None = None
        self._thread: threading.Thread | None = None

    def arm(self, pid: int) -> None:
        """Watch ``pid`` from now on (a step starts)."""
        with self._lock:
            if self._proc is None or self._proc.pid != pid:
                try:
                    self._proc = psutil.Process(pid)
                except psutil.Error:
                    self._proc = None
                    return
            self.killed_rss = None
            self._armed.set()
            if self._thread is None:
                self._thread = threading.Thread(
                    target=self._loop, name="redrive-rss-watch", daemon=True
                )
                self._thread.start()

    def disarm(self) -> int | None:
        """Stop watching (the step ended); the RSS at which the process was killed, or None."""
        with self._lock:
            self._armed.clear()
            return self.killed_rss

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._armed.set()  # wake the thread so it sees the close
        if self._thread is not None:
            self._thread.join(1.0)

    def _loop(self) -> None:
        while True:
            self._armed.wait()
            with self._lock:
                if self._closed:
                    return
                if self._armed.is_set() and self._proc is not None:
                    self._check(self._proc)
            time.sleep(self.interval_s)

    def _check(self, proc: psutil.Process) -> None:
        try:
            rss = int(proc.memory_info().rss)
        except psutil.Error:
            self._armed.clear()  # gone: nothing to watch until the next arm
            return
        if rss > self.limit_bytes:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(proc.pid, signal.SIGKILL)
            self.killed_rss = rss
            self._armed.clear()
