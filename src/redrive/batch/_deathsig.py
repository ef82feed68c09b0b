"""Linux: a local batch worker dies with its driver (issue 37: after a killed ``redrive batch``
its workers kept running and overlapped the rerun's workers on the same cells).

The forkserver asks for SIGKILL when the driver (its parent) ends, and each cell — forked from
the forkserver — for SIGKILL when the forkserver ends: so SIGKILL on the driver takes the server
and every running cell with it."""

from __future__ import annotations

import os
import signal
import sys

__all__ = ["die_with_parent", "in_forkserver"]

_PR_SET_PDEATHSIG = 1


def in_forkserver() -> bool:
    """Whether this process is multiprocessing's forkserver (started with ``-c``)."""
    return sys.argv[:1] == ["-c"] and "multiprocessing.forkserver" in sys.modules


def die_with_parent(parent_pid: int) -> None:
    """Ask the kernel to SIGKILL this process when its parent ends; a parent that ended before
    (``parent_pid`` is no longer the parent) ends it at once.  Elsewhere than Linux: nothing."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent_pid:
        os._exit(1)
