"""The results writer alone: 500 no-op frames' records written and the run closed (its one
flush: four Parquet parts and the manifest, fsynced), wall, thread CPU and process CPU (every
thread: the parts are written on a pool's threads) per frame, median and minimum of
``--passes`` after a warm-up, in this process.  Alternate two trees in fresh
processes to compare them (BENCHMARKS.md, branch h-engine5)::

    for i in 1 2 3; do for s in /tmp/base/src src; do
        PYTHONPATH=$s .venv/bin/python benchmarks/writer_close.py; done; done
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from redrive.benchmarks import engine as bench
from redrive.engine import Engine, LogInputs, build_graph
from redrive.results import FrameRecord, RunSetup, RunStatus, RunWriter, SourceLog
from redrive.types import Frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500)
    parser.add_argument("--passes", type=int, default=9)
    args = parser.parse_args()
    pipeline = bench._pipeline("noop", "sequential")
    engine = Engine(build_graph(pipeline, LogInputs()), pipeline, inputs=LogInputs())
    records: list[FrameRecord] = []
    engine.run([Frame(stamp_ns=i * 100_000_000, index=i) for i in range(args.frames)],
               sink=records.append)  # fmt: skip
    engine.close()
    setup = RunSetup(log=SourceLog(path="(in memory)", format="bench", sha256=None))
    tmp = Path(tempfile.mkdtemp(prefix="redrive-writer-close-"))
    wall, cpu, proc = [], [], []
    for r in range(args.passes + 1):
        writer = RunWriter(tmp / f"r{r}", setup=setup)
        t0, c0, p0 = time.perf_counter(), time.thread_time(), time.process_time()
        for record in records:
            writer.write_frame(record)
        writer.close(status=RunStatus.COMPLETE)
        if r:  # the first pass warms up
            wall.append((time.perf_counter() - t0) / args.frames * 1e6)
            cpu.append((time.thread_time() - c0) / args.frames * 1e6)
            proc.append((time.process_time() - p0) / args.frames * 1e6)
    load = Path("/proc/loadavg").read_text().split()[0]
    print(
        f"writer µs/frame: wall {statistics.median(wall):.1f} (min {min(wall):.1f}), "
        f"thread CPU {statistics.median(cpu):.1f} (min {min(cpu):.1f}), "
        f"process CPU {statistics.median(proc):.1f} (min {min(proc):.1f}); load {load}"
    )


if __name__ == "__main__":
    main()
