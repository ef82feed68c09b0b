"""Running under an address-space limit (``ulimit -v``, ``RLIMIT_AS``; issue 37).

A limit on the address space counts what libraries only *reserve*, and three of ours reserve far
more than they use: pyarrow's default memory pool (mimalloc, pyarrow ≥ 17) reserves a 1 GiB arena
at its first allocation, glibc gives each thread that allocates its own malloc arena (64 MiB of
address space each, up to 8 per core), and each of the two OpenBLAS copies numpy and scipy ship
starts a thread per core, with its stack and buffers.  A ``redrive run`` needs about 2.2 GB of
address space that way while its resident set is about 320 MB, so under a 1 GiB limit it ended
in ``ArrowMemoryError: malloc of size 64 failed``, a SIGSEGV or SIGABRT in C code that does not
survive a failed ``malloc``, or a thread that could not start.

:func:`fit_to_address_space`, called by the command line before it imports any of them, trims
these when a limit below :data:`SMALL_ADDRESS_SPACE` is set, in this process and (through the
environment) in every process it starts: Arrow's system pool (``ARROW_DEFAULT_MEMORY_POOL=
system``), at most 2 malloc arenas (``mallopt(M_ARENA_MAX)``, ``MALLOC_ARENA_MAX``), one OpenBLAS
thread (``OPENBLAS_NUM_THREADS=1``).  A run then needs about 0.8 GB.  A variable the user set is
left as it is.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os
import resource

__all__ = ["SMALL_ADDRESS_SPACE", "fit_to_address_space"]

logger = logging.getLogger(__name__)

#: an address-space limit below this (bytes) is fitted to
SMALL_ADDRESS_SPACE = 8 << 30
_M_ARENA_MAX = -8  # glibc's mallopt parameter
_SETTINGS = (
    ("ARROW_DEFAULT_MEMORY_POOL", "system"),
    ("MALLOC_ARENA_MAX", "2"),
    ("OPENBLAS_NUM_THREADS", "1"),
)


def fit_to_address_space() -> dict[str, str]:
    """When ``RLIMIT_AS`` is below :data:`SMALL_ADDRESS_SPACE`, trim what the libraries reserve
    (see the module text); returns the environment variables it set (none without a limit)."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY or soft >= SMALL_ADDRESS_SPACE:
        return {}
    changed = {key: value for key, value in _SETTINGS if key not in os.environ}
    os.environ.update(changed)
    if "MALLOC_ARENA_MAX" in changed:  # glibc read the variable at start-up: tell it directly
        name = ctypes.util.find_library("c")
        try:
            libc = ctypes.CDLL(name) if name else None
            if libc is not None and hasattr(libc, "mallopt"):
                libc.mallopt(_M_ARENA_MAX, int(changed["MALLOC_ARENA_MAX"]))
        except OSError:
            pass
    if changed:
        logger.debug(
            "address space limited to %d MiB: %s",
            soft >> 20,
            ", ".join(f"{k}={v}" for k, v in changed.items()),
        )
    return changed
