"""Keep freed memory in the process: large buffers allocated per message reuse warm pages.

glibc hands out blocks of 128 KiB and more (its default ``M_MMAP_THRESHOLD``, raised by itself up
to 32 MiB as such blocks are freed) as fresh ``mmap`` pages and gives them back on ``free``; the
top of the heap is given back above ``M_TRIM_THRESHOLD``. A loop that allocates a buffer of a few
MiB for each message — rospy's socket reads and message slices in a ROS 1 scraper, the MCAP
writer's chunk buffers in the recorder — then writes into fresh pages every time, which costs a
page fault per 4 KiB (measured here: 0.5–0.8 GB/s against 7–30 GB/s for warm memory; NOTES.md). A
recording of 120k-point clouds spent ~70 % of its write path there.

:func:`keep_freed_memory` raises both thresholds for the calling process, so such blocks come from
the heap and stay there once freed: the process keeps up to about its peak use (a few such
buffers) instead of returning it between messages. Only for processes that move large messages
all the time (the scrapers, a recording session); nothing happens where glibc is not the C library.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import sys

__all__ = ["keep_freed_memory"]

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: blocks up to this size come from the heap (glibc's largest threshold on 64-bit: 32 MiB)
MMAP_THRESHOLD = 32 << 20
#: the heap's free top is given back to the system only above this
TRIM_THRESHOLD = 256 << 20


@functools.cache
def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds for this process; True when that was done."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl has no mallopt)
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    mallopt.restype = ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    )
