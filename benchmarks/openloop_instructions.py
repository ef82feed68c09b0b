"""Instructions of a sequential ``redrive run`` of the reference pipeline over one log, for
callgrind: the run is done once to warm (imports, kernels, caches), then once inside
``operator.call``, so callgrind with ``--collect-atstart=no --toggle-collect=_operator_call``
counts that run alone (``functools.reduce``, the usual toggle, is used by numba's compiler and
numpy: benchmarks/objloop_instructions.py), on the calling thread (the MCAP reader's prefetch
thread and the results writer's pool threads are not counted: the sequential mode's frame loop
is)::

    PYTHONPATH=src valgrind --tool=callgrind --callgrind-out-file=/dev/null \
        --collect-atstart=no --toggle-collect=_operator_call \
        .venv/bin/python benchmarks/openloop_instructions.py LOG 2>&1 | grep Collected

For before/after, run it with each tree's ``PYTHONPATH`` (a short log: ``redrive synth urban
--duration 2``; callgrind runs ~50× slower).
"""

from __future__ import annotations

import argparse
import operator
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
        request = RunRequest(log=args.log, pipeline=pipeline, out=Path(tmp) / "measured")
        report = operator.call(run_log, request)
    assert report is not None
    print(f"{report.frames} frames, status {report.status}")


if __name__ == "__main__":
    main()
