"""A/B of the engine's own cost per frame, without and with the results writer: two source trees,
interleaved rounds, each side in a fresh process.

    .venv/bin/python benchmarks/bench_engine_ab.py --base OTHER/src [--rounds 3] [--frames 500]

Per side and round, one interpreter with ``PYTHONPATH`` at that tree runs 5 passes of: the bare
loop of three no-op calls, the sequential engine with three no-op stages (records kept in a
list), and the same with the Parquet results writer (``redrive bench engine``'s variants, from
``redrive.benchmarks.engine``).  It prints the median and minimum over the passes of the CPU
per frame beyond the bare loop's (what a loaded machine inflates least: the engine's thread, and
with the writer the whole process — since h-engine5 the writer encodes its parts on a pool's
threads; a tree from before has them on the one thread), then the same in
wall time (what the target is judged on; it holds the writer's fsyncs, which are no CPU time of
this thread), with the load average.  Used for BENCHMARKS.md's "Engine overhead, third pass" (issue 20).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

_RUNNER = r"""
import statistics, sys, tempfile
from pathlib import Path
from redrive.benchmarks import engine as be
from redrive.types import Frame
n = int(sys.argv[1])
data = [Frame(stamp_ns=i * 100_000_000, index=i) for i in range(n)]
tmp = Path(tempfile.mkdtemp(prefix="redrive-engine-ab-"))
be._engine(data, "noop", "sequential", writer_dir=tmp / "warm")
noop, writer, noop_wall, writer_wall = [], [], [], []
for r in range(5):
    bare = be._bare(data, (be._noop,) * 3)
    engine = be._engine(data, "noop", "sequential")
    written = be._engine(data, "noop", "sequential", writer_dir=tmp / f"r{r}")
    noop.append((engine[1] - bare[1]) / n * 1e6)
    writer.append((written[1] - bare[1]) / n * 1e6)
    noop_wall.append((engine[0] - bare[0]) / n * 1e6)
    writer_wall.append((written[0] - bare[0]) / n * 1e6)
print(f"engine {statistics.median(noop):6.1f} (min {min(noop):6.1f})  "
      f"with writer {statistics.median(writer):6.1f} (min {min(writer):6.1f}) us/frame CPU; "
      f"wall {statistics.median(noop_wall):6.1f} (min {min(noop_wall):6.1f}), "
      f"{statistics.median(writer_wall):6.1f} (min {min(writer_wall):6.1f})")
"""


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", type=Path, required=True, help="the other tree's src")
    parser.add_argument("--branch", type=Path, default=Path(__file__).parents[1] / "src")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--frames", type=int, default=500)
    args = parser.parse_args()
    for r in range(args.rounds):
        for side, src in (("base", args.base), ("branch", args.branch)):
            load = Path("/proc/loadavg").read_text().split()[0]
            env = {**os.environ, "PYTHONPATH": str(src.resolve())}
            out = subprocess.run(
                [sys.executable, "-c", _RUNNER, str(args.frames)],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            ).stdout.strip()
            print(f"round {r + 1} {side:6s} load {load:>5s}  {out}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
