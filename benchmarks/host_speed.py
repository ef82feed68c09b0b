"""Is a slow pass the code's or the host's? The synthetic world alone — the same instructions
every time — run in one process sample after sample: wall and thread CPU of each sample and the
VM's steal ticks (``/proc/stat``, all vCPUs) over it.

On the 2-core VM of BENCHMARKS.md a sample moved between 0.26 and 0.38 s within seconds, thread
CPU equal to wall and no steal accounted: the host's speed, not the code's.

    python benchmarks/host_speed.py [SAMPLES]   # default 30; four 20-s urban worlds a sample
"""

from __future__ import annotations

import sys
import time

from redrive.benchmarks.closed_loop import _world_alone


def _steal_ticks() -> int:
    with open("/proc/stat", encoding="ascii") as f:
        return int(f.readline().split()[8])


def main(samples: int) -> None:
    _world_alone("urban", 20.0, 10.0)  # numba's kernels loaded, caches warm
    for i in range(samples):
        s0, t0, c0 = _steal_ticks(), time.perf_counter(), time.thread_time()
        for _ in range(4):
            _world_alone("urban", 20.0, 10.0)
        wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
        with open("/proc/loadavg", encoding="ascii") as f:
            load = f.read().split()[0]
        print(
            f"{i:2d} wall {wall:.3f} s  thread CPU {cpu:.3f} s  "
            f"steal {_steal_ticks() - s0} ticks  load {load}",
            flush=True,
        )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 30)
