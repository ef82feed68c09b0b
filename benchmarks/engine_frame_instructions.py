"""Instructions of the engine's frame loop only, for callgrind: ``Engine.run`` over 500 no-op
frames (``redrive bench engine``'s no-op pass: 3 no-op stages, sequential, the records kept in a
list), with ``--writer`` the run written by the Parquet results writer and closed, as that
benchmark times it.  Each measured run is called inside ``functools.reduce``, so callgrind with
``--collect-atstart=no --toggle-collect=functools_reduce`` counts those calls alone — no
imports, no graph building, no warm-up run — on the calling thread (the writer's pool threads,
which encode and fsync its parts, are not counted)::

    PYTHONPATH=src valgrind --tool=callgrind --callgrind-out-file=/dev/null \
        --collect-atstart=no --toggle-collect=functools_reduce \
        .venv/bin/python benchmarks/engine_frame_instructions.py [--writer] [--runs 3] \
        2>&1 | grep Collected

The total ÷ (runs × frames) is the instructions a frame, per-run costs (the statistics'
report, the writer's flush and close) included as the benchmark includes them.
"""

from __future__ import annotations

import argparse
import functools
import tempfile
from pathlib import Path

from redrive.benchmarks import engine as bench
from redrive.engine import Engine, LogInputs, build_graph
from redrive.results import FrameRecord, RunSetup, RunStatus, RunWriter, SourceLog
from redrive.types import Frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--writer", action="store_true", help="with the Parquet writer")
    parser.add_argument("--runs", type=int, default=3, help="measured runs (after a warm-up)")
    parser.add_argument("--frames", type=int, default=500)
    args = parser.parse_args()
    data = [Frame(stamp_ns=i * 100_000_000, index=i) for i in range(args.frames)]
    pipeline = bench._pipeline("noop", "sequential")
    tmp = Path(tempfile.mkdtemp(prefix="redrive-frame-instructions-"))
    setup = RunSetup(log=SourceLog(path="(in memory)", format="bench", sha256=None))
    for r in range(args.runs + 1):
        engine = Engine(build_graph(pipeline, LogInputs()), pipeline, inputs=LogInputs())
        kept: list[FrameRecord] = []
        # time-based flushes off: under callgrind their number would depend on its speed
        writer = (
            RunWriter(tmp / f"r{r}", setup=setup, flush_interval_s=1e9) if args.writer else None
        )
        sink = kept.append if writer is None else writer.write_frame

        def run(
            _acc: object, _x: object, engine: Engine = engine, sink=sink, writer=writer
        ) -> None:
            engine.run(data, sink=sink)
            if writer is not None:
                writer.close(status=RunStatus.COMPLETE)

        if r == 0:
            run(None, None)  # warm-up: not counted
        else:
            functools.reduce(run, [0], None)
        engine.close()


if __name__ == "__main__":
    main()
