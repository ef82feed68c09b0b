"""Instructions of a sequential ``redrive run`` of the reference pipeline over one log, for
callgrind: the run is done once to warm (imports, kernels, caches), then once inside
``functools.reduce``, so callgrind with ``--collect-atstart=no --toggle-collect=functools_reduce``
counts that run alone, on the calling thread (the MCAP reader's prefetch thread and the results
writer's pool threads are not counted: the sequential mode's frame loop is)::

    PYTHONPATH=src valgrind --tool=callgrind --callgrind-out-file=/dev/null \
        --collect-atstart=no --toggle-collect=functools_reduce \
        .venv/bin/python benchmarks/openloop_instructions.py LOG 2>&1 | grep Collected

For before/after, run it with each tree's ``PYTHONPATH`` (a short log: ``redrive synth urban
--duration 2``; callgrind runs ~50× slower).
"""

from __future__ import annotations

import argparse
import functools
import tempfile
from pathlib import Path

from redrive.config import reference_pipeline
from redrive.engine import RunRequest, run_log


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", type=Path, metavar="LOG")
    parser.add_argument("--mode", default="sequential", choices=("sequential", "pipelined"))
    args = parser.parse_args()
    pipeline = reference_pipeline().with_options(mode=args.mode)
    with tempfile.TemporaryDirectory() as tmp:
        run_log(RunRequest(log=args.log, pipeline=pipeline, out=Path(tmp) / "warm"))
        report = functools.reduce(
            lambda _, out: run_log(RunRequest(log=args.log, pipeline=pipeline, out=out)),
            [Path(tmp) / "measured"],
            None,
        )
    assert report is not None
    print(f"{report.frames} frames, status {report.status}")


if __name__ == "__main__":
    main()
