"""Instructions of an object-level closed loop on the Waymo Open Motion scenario of
../shared/data with ``--agents reactive`` (the logged vehicles on the lane graph under IDM),
against the same scenario replayed without a planner, in the same process — under callgrind, a
load-robust figure (issue 34: "≥ 50× real time with reactive agents, measured against the
scenario replayed without a planner in the same run").

    REDRIVE_SHARED_DATA=../shared/data OPENBLAS_NUM_THREADS=1 PYTHONPATH=src \\
        valgrind --tool=callgrind --instr-atstart=no --collect-atstart=no \\
        --toggle-collect=_operator_call --callgrind-out-file=cg.%p.out \\
        python benchmarks/logloop_instructions.py --what closed     # or --what replay
    callgrind_annotate cg.PID.out | head -30       # "PROGRAM TOTALS" is the pass's count

``--what closed``: :func:`redrive.closedloop.run.run_closed_loop` on the scenario, idm-planner
(it follows the mission's route, stops at the map's red lights), ``agents="reactive"``, results
written to a temporary run directory as ``redrive run WOMD --closed-loop --agents reactive
--planning idm-planner`` does; the engine's ``execute`` (the frame loop) is what is counted.
``--what replay``: the log backend alone (:class:`~redrive.closedloop.logreplay.LogSimulator`,
``agents="replay"``, no pipeline: every step the fallback brake), ``observe`` + ``step`` over the
same 90 frames — the cost floor of reading the scenario frame by frame; the loop is what is
counted.  Both build their simulator (reading the scenario, the map's index, the route, the
tracks) outside the count, and one warm-up pass runs first (imports, numba's kernels).
``--native`` runs both without callgrind and prints their CPU seconds (``time.process_time``;
on a loaded machine a hint, not a figure).

Set ``OPENBLAS_NUM_THREADS=1``: the built-in LQR tracker's pseudo-inverses are 60×60, and a
multi-threaded BLAS on a loaded 2-core machine spins for tens of milliseconds on each.
"""

from __future__ import annotations

import argparse
import functools
import operator
import os
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import redrive.closedloop.run as closed_loop_run
from redrive.algorithms import StageOutputs
from redrive.closedloop.logreplay import LogSimulator
from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.closedloop.tracker import LqrTracker
from redrive.config import pipeline_from_plugins
from redrive.io import open_log
from redrive.results import RunWriter

WOMD = "womd/motion_data_one_scenario.tfrecord"


def _scenario() -> Path:
    root = Path(os.environ.get("REDRIVE_SHARED_DATA", "../shared/data"))
    path = root / WOMD
    if not path.is_file():
        msg = f"{path}: not found; set REDRIVE_SHARED_DATA to the shared data directory"
        raise SystemExit(msg)
    return path


def _closed(out: Path) -> None:
    run_closed_loop(
        ClosedLoopRequest(
            scenario=str(_scenario()),
            pipeline=pipeline_from_plugins(planning=("idm-planner",)),
            out=out,
            agents="reactive",
        )
    )


def _replay_loop(sim: LogSimulator) -> int:
    steps = 0
    while not sim.done:
        sim.observe()
        sim.step(StageOutputs(), sim.dt_s)
        steps += 1
    return steps


def _switch_on() -> None:
    subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--what", choices=("closed", "replay"), default="closed")
    parser.add_argument("--native", action="store_true", help="both, CPU seconds, no callgrind")
    args = parser.parse_args()
    # the writer flushes once, at the close (under callgrind a pass is slow: see
    # objloop_instructions.py)
    closed_loop_run.RunWriter = functools.partial(  # type: ignore[misc]
        RunWriter, flush_interval_s=1e9
    )
    execute = closed_loop_run.execute
    with tempfile.TemporaryDirectory() as tmp, open_log(_scenario()) as log:
        _closed(Path(tmp) / "warm")
        replay = LogSimulator(log, tracker=LqrTracker(), agents="replay", reads_sensors=False)
        _replay_loop(replay)
        if args.native:
            replay.reset(0)
            t0 = time.process_time()
            steps = _replay_loop(replay)
            t_replay = time.process_time() - t0
            t0 = time.process_time()
            _closed(Path(tmp) / "native")
            t_closed = time.process_time() - t0
            print(f"replay: {steps} steps, {t_replay:.3f} s CPU; closed loop: {t_closed:.3f} s CPU")
            return
        if args.what == "replay":
            replay.reset(0)
            _switch_on()
            operator.call(_replay_loop, replay)  # type: ignore[attr-defined]
            return

        def counted(*a: Any, **kw: Any) -> Any:
            return operator.call(execute, *a, **kw)  # type: ignore[attr-defined]

        _switch_on()
        closed_loop_run.execute = counted  # type: ignore[assignment]
        try:
            _closed(Path(tmp) / "counted")
        finally:
            closed_loop_run.execute = execute


if __name__ == "__main__":
    main()
