"""Stopping a child started in a session of its own (``start_new_session=True``) and waiting
until every process of its group is gone, not only the one that was started.

Waiting for the leader alone is not enough: ``rosbag record`` is a Python wrapper that leaves on
Ctrl-C at once while its C++ recorder is still closing the bag (it renames ``NAME.bag.active`` to
``NAME.bag`` last), so a test reading the bag right after ``wait()`` raced that rename.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time
from typing import Any

import psutil

__all__ = ["group_members", "stop_group", "wait_group"]


def group_members(pgid: int) -> list[int]:
    """The pids of the processes of group ``pgid`` that still run (zombies left out: in a
    container nobody may reap an orphan, and a zombie holds nothing open)."""
    members = []
    for process in psutil.process_iter(["status"]):
        with contextlib.suppress(psutil.Error, OSError):
            if process.info["status"] == psutil.STATUS_ZOMBIE:
                continue
            if os.getpgid(process.pid) == pgid:
                members.append(process.pid)
    return members


def wait_group(proc: subprocess.Popen[Any], timeout_s: float) -> bool:
    """Wait up to ``timeout_s`` until ``proc`` and every other process of its group have ended."""
    deadline = time.monotonic() + timeout_s
    try:
        proc.wait(timeout=max(deadline - time.monotonic(), 0.0))
    except subprocess.TimeoutExpired:
        return False
    while group_members(proc.pid):
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def stop_group(
    proc: subprocess.Popen[Any], sig: int = signal.SIGTERM, *, wait_s: float = 10.0
) -> bool:
    """``sig`` to the process group of ``proc`` and wait up to ``wait_s`` until the whole group
    has ended; SIGKILL to what is left after that. True when ``sig`` alone ended the group."""
    if proc.poll() is not None and not group_members(proc.pid):
        return True
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, sig)
    if wait_group(proc, wait_s):
        return True
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    wait_group(proc, 10.0)
    return False
