"""``redrive bench transport``: moving large messages between two processes.

Each *side* is one transport, run as a publisher process and a subscriber process started with
``multiprocessing`` ``spawn`` (fresh interpreters, nothing inherited but the arguments):
``redrive-copy`` (:class:`redrive.transport.Writer` ``publish``, copies in → ``Reader.read``, copies
out into an owned array: the copy is the receiver's work), ``redrive-inplace`` (``Writer.loan``,
the payload written straight into the slot → ``Reader.view``, a read-only view into the slot) and
``pipe-pickle`` (``multiprocessing.Pipe`` ``send(ndarray)`` → ``recv()``: pickle through a pipe,
the legacy path of the paper).  The sides come from a *catalogue*, a module with ``SIDES``
(:mod:`~redrive.benchmarks.transport.sides`); the repository's ``benchmarks/transport_peers.py``
is one with ZeroMQ, eCAL, iceoryx2 and ``multiprocessing.Queue`` added.

What every side does per message, so the numbers compare like with like:

- **payload**: ``size`` bytes; bytes 0–8 the publisher's ``time.monotonic_ns()`` (CLOCK_MONOTONIC,
  the same clock in every process), bytes 8–16 the sequence number, the rest a fixed seeded random
  pattern (``verify=True``: the pattern XOR ``seq % 256``, different in every message).
- **publisher**: takes the stamp *before* any work on the message, then: copy sides write the
  16-byte header into a preallocated source array and hand it to the transport, which copies or
  serialises it; in-place sides loan a slot and write the whole payload into it (``np.copyto``
  from the preallocated pattern: the one write of ``size`` bytes a copy side's transport does for
  it), then commit.
- **subscriber** ("consume"): unpacks the header and sums one byte per 4 KiB page
  (``np.add.reduce`` over ``payload[4095::4096]``), compares the sum with the pattern's (a
  mismatch counts as ``corrupt``; ``verify=True`` compares every byte instead), then stamps
  ``now``. Copy sides do this on the copy the transport delivered; in-place sides on the
  shared-memory view. One-way latency is ``now − stamp``.
- **flat out**: the publisher sends as fast as the transport takes messages for ``seconds``; the
  lossless sides block when the subscriber is ``slots`` (4) messages behind. Throughput is what the
  subscriber received per second, measured by the subscriber from arrival times after a warm-up
  (the first 10 % of the run); ``lost`` is sent − received.
- **paced**: the same at ``paced_hz`` (default 100 Hz); latency p50 / p99 / max over the messages
  after the warm-up.

The memcpy ceiling is single-thread ``np.copyto`` between preallocated, pre-touched buffers:
*cache-hot* (the same two ``size``-byte buffers every time) and *from memory* (source and
destination rotate over two 256 MiB pools, so every copy reads and writes memory, not cache).
Sides whose package is not installed are reported so, never left out silently or faked; a side
that fails reports its error and the others still run.  Every side has 4 slots (redrive
``slots=4``, ``Policy.LOSSLESS``).  Children are started with ``spawn``: a script calling
:func:`run_cell` needs the ``if __name__ == "__main__":`` guard.
"""

from __future__ import annotations

from redrive.benchmarks.transport.cell import run_cell
from redrive.benchmarks.transport.memcpy import bench_memcpy
from redrive.benchmarks.transport.payload import MIN_SIZE, SLOTS, CellConfig
from redrive.benchmarks.transport.results import (
    CellResult,
    MemcpyResult,
    RunResult,
    TargetCheck,
    TransportBenchResult,
)
from redrive.benchmarks.transport.run import (
    DEFAULT_SIZES,
    bench_transport,
    parse_size,
    side_available,
    size_label,
)
from redrive.benchmarks.transport.sides import (
    CATALOGUE,
    DEFAULT_SIDES,
    SIDES,
    SideSpec,
    catalogue_sides,
)
from redrive.benchmarks.transport.spread import TargetSpread, target_spreads
from redrive.benchmarks.transport.targets import (
    INPLACE_VS_ICEORYX2_TARGET,
    PACED_P99_TARGET_MS,
    VS_MEMCPY_TARGET,
    VS_PIPE_PICKLE_TARGET,
    check_targets,
)

__all__ = [
    "CATALOGUE",
    "DEFAULT_SIDES",
    "DEFAULT_SIZES",
    "INPLACE_VS_ICEORYX2_TARGET",
    "MIN_SIZE",
    "PACED_P99_TARGET_MS",
    "SIDES",
    "SLOTS",
    "VS_MEMCPY_TARGET",
    "VS_PIPE_PICKLE_TARGET",
    "CellConfig",
    "CellResult",
    "MemcpyResult",
    "RunResult",
    "SideSpec",
    "TargetCheck",
    "TargetSpread",
    "TransportBenchResult",
    "bench_memcpy",
    "bench_transport",
    "catalogue_sides",
    "check_targets",
    "parse_size",
    "run_cell",
    "side_available",
    "size_label",
    "target_spreads",
]
