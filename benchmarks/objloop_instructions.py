"""Instructions of one object-level closed-loop pass (``redrive bench closed-loop``'s run) under
callgrind — a load-robust figure: the count does not depend on what else runs on the machine.

    PYTHONPATH=src valgrind --tool=callgrind --instr-atstart=no --collect-atstart=no \\
        --toggle-collect=_operator_call --callgrind-out-file=cg.out \\
        python benchmarks/objloop_instructions.py [--passes 1] [--baseline]
    callgrind_annotate --inclusive=yes cg.out | head -60

One warm-up pass (imports, the compiled kernels loaded, plugin discovery; not instrumented, so
it runs ≈ 5× faster than under full instrumentation), then instrumentation on
(``callgrind_control -i on``, waited for) and ``--passes`` passes of the 20-s ``urban`` scenario
(noisy-oracle → idm-planner → pure-pursuit-pid, results written to a temporary run directory).
Both sides count what the bench times, called through ``operator.call``: that is all callgrind
counts (nothing in redrive or its libraries calls ``operator.call``; ``functools.reduce``, the
usual toggle, is used by numba's compiler and numpy, and a nested toggle switches collection
off):

- the closed loop: the engine's frame loop (``Engine.run``, whose wall time is the bench's
  closed-loop time) — building the two worlds, the algorithms' setup, the run directory's
  opening and its close (the tables flushed, the manifest) are outside it;
- ``--baseline``: the world stepping alone (``step_world_alone``, the bench's timed part) —
  loading the scenario and building the world are outside it.

Only the thread that enters ``operator.call`` (the frame loop's) is counted: the resource
sampler's and the writer's file threads are not.  The results writer flushes once, at the
close, as in a native pass (its 2-s flush interval is lifted: under callgrind a pass takes tens
of seconds).  Run to run the count still varies by about ±1 % (the threads' interplay, the
garbage collector): compare trees over several runs each.  Instructions per second differ
between the two sides (the world is numba-heavy): report the bench's CPU-time ratio beside.
"""

from __future__ import annotations

import argparse
import functools
import operator
import os
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import redrive.closedloop.run as closed_loop_run
from redrive.benchmarks.closed_loop import (
    _world_alone,
    closed_loop_pipeline,
    step_world_alone,
    world_for_alone,
)
from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.engine.core import Engine
from redrive.results import RunWriter


def _one_pass(out: Path) -> None:
    run_closed_loop(
        ClosedLoopRequest(
            scenario="urban",
            pipeline=closed_loop_pipeline("object"),
            out=out,
            duration_s=20.0,
            agents="replay",
        )
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--passes", type=int, default=1, help="counted passes (default 1)")
    parser.add_argument(
        "--no-switch", action="store_true", help="do not call callgrind_control -i on"
    )
    parser.add_argument(
        "--baseline",
        action="store_true",
        help="count `bench closed-loop`'s baseline instead: the world stepped alone (its "
        "step_world_alone, 20 s of urban at 10 Hz; the world built outside the count) — the "
        "closed loop's count over this one is the bench's ratio in instructions",
    )
    args = parser.parse_args()
    if args.baseline:
        _world_alone("urban", 20.0, 10.0)  # warm: imports, the compiled kernels
        worlds = [world_for_alone("urban", 20.0) for _ in range(args.passes)]
        if not args.no_switch:
            subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=False)
        for world in worlds:
            operator.call(step_world_alone, world, 20.0, 10.0)  # type: ignore[attr-defined]
        return
    run = Engine.run
    # a native pass (≈ 0.2 s) flushes its frames once, at close; under callgrind a pass takes
    # tens of seconds and the writer's 2-s flush interval would add flushes (and instructions)
    # that depend on the host's speed: the interval is lifted so the count is one flush's
    closed_loop_run.RunWriter = functools.partial(  # type: ignore[misc]
        RunWriter, flush_interval_s=1e9
    )
    with tempfile.TemporaryDirectory() as tmp:
        _one_pass(Path(tmp) / "warm")

        def counted(*a: Any, **kw: Any) -> Any:
            return operator.call(run, *a, **kw)  # type: ignore[attr-defined]

        if not args.no_switch:  # under callgrind --instr-atstart=no: instrument from here on
            subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=False)
        Engine.run = counted  # type: ignore[method-assign]
        try:
            for p in range(args.passes):
                _one_pass(Path(tmp) / f"run{p}")
        finally:
            Engine.run = run  # type: ignore[method-assign]


if __name__ == "__main__":
    main()
