"""A local batch worker dies with its driver (issue 37: after a killed ``redrive batch`` its
workers kept running and overlapped the rerun's workers on the same cells).

A cell is forked from the forkserver, not from the driver, so the kernel's parent-death signal
would follow the server; instead each cell watches the driver's process id from a daemon thread
and SIGKILLs itself within :data:`POLL_S` once the driver is gone."""

from __future__ import annotations

import os
import signal
import threading

__all__ = ["POLL_S", "die_with_driver"]

POLL_S = 0.5


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _watch(driver_pid: int) -> None:
    while _alive(driver_pid):
        threading.Event().wait(POLL_S)
    os.kill(os.getpid(), signal.SIGKILL)


def die_with_driver(driver_pid: int) -> None:
    """SIGKILL this process once process ``driver_pid`` has ended (checked every
    :data:`POLL_S` seconds by a daemon thread; at once when it has already ended)."""
    if not _alive(driver_pid):
        os.kill(os.getpid(), signal.SIGKILL)
    threading.Thread(
        target=_watch, args=(driver_pid,), name="redrive-driver-watch", daemon=True
    ).start()
