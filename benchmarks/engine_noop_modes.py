"""The engine's no-op cost per frame, pass by pass, in this one process.

``redrive bench engine`` measures it interleaved with other variants; this runs only the no-op
engine (3 no-op stages, sequential, 500 frames, the frames kept in a list) minus the bare loop
of the same three calls, in thread CPU time, once to warm up and then ``--passes`` times.
Run it as several fresh processes (and under ``taskset -c N`` or ``setarch -R``) to see
whether the figure depends on the process rather than on the code (BENCHMARKS.md, "The engine's
no-op cost is bimodal by process")::

    for i in 1 2 3 4 5 6; do PYTHONPATH=src .venv/bin/python benchmarks/engine_noop_modes.py; done
"""

from __future__ import annotations

import argparse

from redrive.benchmarks import engine as bench
from redrive.types import Frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500)
    parser.add_argument("--passes", type=int, default=5)
    args = parser.parse_args()
    frames = [Frame(stamp_ns=i * 100_000_000, index=i) for i in range(args.frames)]
    noops = (bench._noop, bench._noop, bench._noop)

    def one() -> float:
        _, engine_cpu = bench._engine(frames, "noop", "sequential")
        _, bare_cpu = bench._bare(frames, noops)
        return (engine_cpu - bare_cpu) / args.frames * 1e6

    one()
    print(" ".join(f"{one():.1f}" for _ in range(args.passes)), "µs a frame (thread CPU)")


if __name__ == "__main__":
    main()
