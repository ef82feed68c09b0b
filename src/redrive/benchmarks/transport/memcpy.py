"""The memcpy ceiling: single-thread ``np.copyto`` GB/s, cache-hot and from memory."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator, Sequence

import numpy as np

from redrive.benchmarks.transport.payload import U8
from redrive.benchmarks.transport.results import MemcpyResult

__all__ = ["MEMORY_POOL_BYTES", "bench_memcpy"]

MEMORY_POOL_BYTES = 256 << 20


def _copy_rate(dst_pool: U8, src_pool: U8, size: int, seconds: float) -> float:
    k = max(1, min(len(src_pool), len(dst_pool)) // size)
    dsts = [dst_pool[i * size : (i + 1) * size] for i in range(k)]
    srcs = [src_pool[i * size : (i + 1) * size] for i in range(k)]
    for i in range(min(k, 2)):
        np.copyto(dsts[i], srcs[i])
    copies = 0
    t0 = time.perf_counter()
    deadline = t0 + seconds
    while True:
        for _ in range(max(1, k)):
            np.copyto(dsts[copies % k], srcs[(copies * 7 + 3) % k] if k > 1 else srcs[0])
            copies += 1
        now = time.perf_counter()
        if now >= deadline and copies >= 4:
            break
    return copies * size / (now - t0) / 1e9


@contextlib.contextmanager
def _pools(nbytes: int) -> Iterator[tuple[U8, U8]]:
    src = np.empty(nbytes, np.uint8)
    dst = np.empty(nbytes, np.uint8)
    src.fill(1)  # pre-touched: no page faults inside the timing
    dst.fill(2)
    try:
        yield src, dst
    finally:
        del src, dst


def bench_memcpy(
    sizes: Sequence[int], *, seconds: float = 1.0, pool_bytes: int = MEMORY_POOL_BYTES
) -> tuple[MemcpyResult, ...]:
    """Single-thread ``np.copyto`` GB/s at each size: cache-hot (the same two buffers) and from
    memory (rotating over two ``pool_bytes`` pools, source and destination; the source index
    strides so consecutive copies do not walk the pool in order)."""
    out = []
    with _pools(max(pool_bytes, 2 * max(sizes, default=0))) as (src_pool, dst_pool):
        for size in sizes:
            hot = _copy_rate(dst_pool[:size], src_pool[:size], size, seconds / 2)
            cold = _copy_rate(dst_pool, src_pool, size, seconds / 2)
            out.append(
                MemcpyResult(
                    size_bytes=size,
                    hot_gb_per_s=hot,
                    from_memory_gb_per_s=cold,
                    pool_bytes=len(src_pool),
                )
            )
    return tuple(out)
