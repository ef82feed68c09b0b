"""``redrive bench engine``'s pipelined variant at several hand-off depths, against the bare
loop, interleaved in this process: the median ratio, the ratio two free cores would allow by
CPU time (2 × the bare loop's CPU ÷ the pipelined run's, all threads: load-robust) and the
context switches per frame for each depth (the engine's ``_QUEUE_DEPTH``, 4 in the code).  For a quiet machine: on a
loaded one the ratios swing past any difference the depth makes (BENCHMARKS.md, branch
h-engine5)::

    PYTHONPATH=src .venv/bin/python benchmarks/pipelined_depth.py --depths 2 4 8 --passes 5
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time

from redrive.benchmarks import engine as bench
from redrive.engine import core
from redrive.types import Frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--depths", type=int, nargs="+", default=[2, 4, 8])
    parser.add_argument("--passes", type=int, default=5)
    parser.add_argument("--frames", type=int, default=500)
    args = parser.parse_args()
    bench.calibrate_work(1.0)
    frames = [Frame(stamp_ns=i * 100_000_000, index=i) for i in range(args.frames)]
    ratios: dict[int, list[float]] = {d: [] for d in args.depths}
    switches: dict[int, list[float]] = {d: [] for d in args.depths}
    involuntary: dict[int, list[float]] = {d: [] for d in args.depths}
    cpu_bound: dict[int, list[float]] = {d: [] for d in args.depths}
    for _ in range(args.passes):
        for depth in args.depths:
            core._QUEUE_DEPTH = depth
            bare, bare_cpu = bench._bare(frames, (bench._work,) * 3)
            before = resource.getrusage(resource.RUSAGE_SELF)
            c0, t0 = time.process_time(), time.perf_counter()
            bench._engine(frames, "busy", "pipelined")
            ratios[depth].append(bare / (time.perf_counter() - t0))
            cpu = time.process_time() - c0
            after = resource.getrusage(resource.RUSAGE_SELF)
            switches[depth].append((after.ru_nvcsw - before.ru_nvcsw) / args.frames)
            involuntary[depth].append((after.ru_nivcsw - before.ru_nivcsw) / args.frames)
            # what two free cores would allow: the bare loop's CPU over the pipelined run's
            # CPU (all threads), times two — load-robust, unlike the wall ratio
            cpu_bound[depth].append(2 * bare_cpu / cpu)
    for depth in args.depths:
        shown = " ".join(f"{r:.2f}" for r in ratios[depth])
        print(
            f"depth {depth}: pipelined ÷ bare {statistics.median(ratios[depth]):.2f} ({shown}); "
            f"2 × bare CPU ÷ pipelined CPU {statistics.median(cpu_bound[depth]):.2f}; "
            f"context switches a frame: voluntary {statistics.median(switches[depth]):.1f}, "
            f"involuntary {statistics.median(involuntary[depth]):.1f}"
        )
    print("load", open("/proc/loadavg").read().split()[0])  # noqa: SIM115


if __name__ == "__main__":
    main()
