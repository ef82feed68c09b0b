"""Instructions per no-op frame, for callgrind: ``K`` runs of the no-op sequential engine over
500 frames (each as ``redrive bench engine``'s no-op pass: 3 no-op stages, the records kept in
a list), after one warm-up run.  Two processes, K = 1 and K = 5, under callgrind; the difference
of their instruction totals over 2000 frames is the engine's cost per frame in a 500-frame run
(imports, set-up and the warm-up cancel out)::

    for k in 1 5; do PYTHONPATH=src valgrind --tool=callgrind --callgrind-out-file=/dev/null \
        .venv/bin/python benchmarks/engine_noop_instructions.py $k 2>&1 | grep Collected; done

Pass ``--writer`` to add the Parquet results writer (its flushes every 2 s make the figure
depend on how slow callgrind runs: not a per-frame cost; see BENCHMARKS.md).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from redrive.benchmarks import engine as bench
from redrive.types import Frame


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=int, help="runs of 500 frames after the warm-up")
    parser.add_argument("--writer", action="store_true", help="with the Parquet writer")
    args = parser.parse_args()
    data = [Frame(stamp_ns=i * 100_000_000, index=i) for i in range(500)]
    tmp = Path(tempfile.mkdtemp(prefix="redrive-noop-instructions-"))
    for r in range(args.runs + 1):
        out = tmp / f"r{r}" if args.writer else None
        bench._engine(data, "noop", "sequential", writer_dir=out)


if __name__ == "__main__":
    main()
