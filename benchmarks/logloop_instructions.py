"""The object-level closed loop on the Waymo Open Motion scenario of ../shared/data with
``--agents reactive`` (the logged vehicles on the lane graph under IDM) and idm-planner, against
the same scenario replayed without a planner, in the same harness (issue 34: "≥ 50× real time
with reactive agents, measured against the scenario replayed without a planner in the same
run") — as instructions under callgrind (load-robust) or as process CPU seconds.

    export REDRIVE_SHARED_DATA=../shared/data OPENBLAS_NUM_THREADS=1 PYTHONPATH=src
    python benchmarks/logloop_instructions.py --callgrind     # the three counts, the ratios
    python benchmarks/logloop_instructions.py --native --rounds 5   # CPU seconds, the ratios

What is measured (``--what``, one of them per callgrind process):

- ``replay``: the log backend alone (:class:`~redrive.closedloop.logreplay.LogSimulator`,
  ``agents="replay"``, no pipeline: every step the fallback brake), ``observe`` + ``step`` over
  the scenario's 90 steps — the cost floor of reading the scenario frame by frame;
- ``loop``: the frame loop of ``redrive run WOMD --closed-loop --agents reactive --planning
  idm-planner`` (:func:`~redrive.closedloop.run.run_closed_loop`; the engine's ``Engine.run``
  over the frames: observe, the planner, the LQR tracker, the reactive agents, the collision
  check, each frame's record handed to the writer);
- ``call``: that whole call — the setup before the first frame (the scenario read, its map
  converted and written to ``map.json``, the map's index, the route, the tracks read and put on
  their lanes), the loop, and the close (the tables written, the manifest).

Each builds what it measures outside the count, after one warm-up pass (imports, numba's
kernels, plugin discovery).  Under callgrind only what runs inside ``operator.call`` is counted
(``--toggle-collect=_operator_call``; nothing in redrive or its libraries calls it) and only on
the thread that enters it (the writer's file threads are not counted).  ``--callgrind`` runs the
three processes (two at a time) and prints their counts and the ratios.  ``--native`` runs
``--rounds`` rounds of replay then the whole call (the loop timed inside it), alternating, and
prints each round's CPU seconds (``time.process_time``: every thread of the process) and the
medians, the real-time factors (the 9.0 s the loop drives ÷ CPU seconds) and the ratios to the
replay.  On a loaded machine CPU seconds are a hint; the counts are the figure.

Set ``OPENBLAS_NUM_THREADS=1``: a multi-threaded BLAS on a loaded 2-core machine spins for tens
of milliseconds on the tracker's small solves.
"""

from __future__ import annotations

import argparse
import functools
import operator
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import redrive.closedloop.run as closed_loop_run
from redrive.algorithms import StageOutputs
from redrive.closedloop.logreplay import LogSimulator
from redrive.closedloop.run import ClosedLoopRequest, run_closed_loop
from redrive.closedloop.tracker import LqrTracker
from redrive.config import pipeline_from_plugins
from redrive.engine.core import Engine
from redrive.io import open_log
from redrive.results import RunWriter

WOMD = "womd/motion_data_one_scenario.tfrecord"
WHAT = ("replay", "loop", "call")


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


def _replay_loop(sim: LogSimulator) -> tuple[int, float]:
    """Steps and the seconds they drive."""
    steps, driven_s = 0, 0.0
    while not sim.done:
        sim.observe()
        dt = sim.dt_s
        sim.step(StageOutputs(), dt)
        steps, driven_s = steps + 1, driven_s + dt
    return steps, driven_s


def _switch_on() -> None:
    subprocess.run(["callgrind_control", "-i", "on", str(os.getpid())], check=False)


def _wrapped(owner: Any, name: str, around: Callable[..., Any]) -> Callable[[], None]:
    """Replace ``owner.name`` by ``around(original, *args, **kwargs)``; returns the undo."""
    original = getattr(owner, name)

    def call(*args: Any, **kwargs: Any) -> Any:
        return around(original, *args, **kwargs)

    setattr(owner, name, call)
    return lambda: setattr(owner, name, original)


def _counted_pass(what: str, tmp: Path, replay: LogSimulator) -> None:
    """One pass with only ``what`` inside ``operator.call`` (callgrind's toggle)."""
    if what == "replay":
        replay.reset(0)
        _switch_on()
        operator.call(_replay_loop, replay)  # type: ignore[attr-defined]
        return
    _switch_on()
    if what == "call":
        operator.call(_closed, tmp / "counted")  # type: ignore[attr-defined]
        return
    undo = _wrapped(Engine, "run", operator.call)  # type: ignore[attr-defined]
    try:
        _closed(tmp / "counted")
    finally:
        undo()


def _native(rounds: int, tmp: Path, replay: LogSimulator) -> None:
    spent = {"loop": 0.0, "execute": 0.0}

    def timed(key: str) -> Callable[..., Any]:
        def around(f: Callable[..., Any], *a: Any, **kw: Any) -> Any:
            t0 = time.process_time()
            try:
                return f(*a, **kw)
            finally:
                spent[key] += time.process_time() - t0

        return around

    undo = [
        _wrapped(Engine, "run", timed("loop")),
        _wrapped(closed_loop_run, "execute", timed("execute")),
    ]
    rows: list[dict[str, float]] = []
    driven_s = 0.0
    try:
        for k in range(rounds):
            replay.reset(0)
            t0 = time.process_time()
            _, driven_s = _replay_loop(replay)
            t_replay = time.process_time() - t0
            spent.update(loop=0.0, execute=0.0)
            t0 = time.process_time()
            _closed(tmp / f"native{k}")
            t_call = time.process_time() - t0
            rows.append(
                {
                    "replay": t_replay,
                    "loop": spent["loop"],
                    "setup": t_call - spent["execute"],
                    "close": spent["execute"] - spent["loop"],
                    "call": t_call,
                }
            )
            print(
                f"round {k + 1}: replay {t_replay:.3f} s, closed loop: loop {spent['loop']:.3f} s, "
                f"whole call {t_call:.3f} s (setup {rows[-1]['setup']:.3f}, close "
                f"{rows[-1]['close']:.3f}) CPU"
            )
    finally:
        for u in undo:
            u()
    med = {key: statistics.median(r[key] for r in rows) for key in rows[0]}
    print(f"medians of {rounds} rounds, CPU seconds (load {os.getloadavg()[0]:.1f}):")
    for key in ("replay", "loop", "call", "setup", "close"):
        print(f"  {key:6s} {med[key]:.3f} s")
    for key in ("replay", "loop", "call"):
        print(f"  {key:6s} {driven_s / med[key]:6.1f}× real time ({driven_s:.1f} s driven)")
    print(
        f"  loop ÷ replay {med['loop'] / med['replay']:.2f}, call ÷ replay "
        f"{med['call'] / med['replay']:.2f}"
    )


def _callgrind(jobs: int) -> None:
    """The three counts, each in its own callgrind process, and their ratios."""
    script = Path(__file__).resolve()

    def count(what: str) -> int:
        with tempfile.TemporaryDirectory() as tmp:
            done = subprocess.run(
                [
                    "valgrind",
                    "--tool=callgrind",
                    "--instr-atstart=no",
                    "--collect-atstart=no",
                    "--toggle-collect=_operator_call",
                    f"--callgrind-out-file={tmp}/cg.out",
                    sys.executable,
                    str(script),
                    "--what",
                    what,
                ],
                capture_output=True,
                text=True,
                check=False,
            )
        found = re.findall(r"Collected : (\d+)", done.stderr)
        if done.returncode != 0 or not found:
            msg = f"--what {what} under callgrind failed:\n{done.stderr[-2000:]}"
            raise SystemExit(msg)
        print(f"  {what:6s} {int(found[-1]):>15,d} instructions", flush=True)
        return int(found[-1])

    with ThreadPoolExecutor(jobs) as pool:
        counts = dict(zip(WHAT, pool.map(count, WHAT), strict=True))
    print(
        f"loop ÷ replay {counts['loop'] / counts['replay']:.2f}, "
        f"call ÷ replay {counts['call'] / counts['replay']:.2f}, "
        f"setup + close {counts['call'] - counts['loop']:,d} instructions"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--what", choices=WHAT, default="loop")
    parser.add_argument("--native", action="store_true", help="CPU seconds, no callgrind")
    parser.add_argument("--rounds", type=int, default=3, help="--native: rounds (default 3)")
    parser.add_argument(
        "--callgrind", action="store_true", help="run replay, loop and call under callgrind"
    )
    parser.add_argument("--jobs", type=int, default=2, help="--callgrind: processes at a time")
    args = parser.parse_args()
    if args.callgrind:
        _callgrind(args.jobs)
        return
    # the writer flushes once, at the close (under callgrind a pass is slow: see
    # objloop_instructions.py)
    closed_loop_run.RunWriter = functools.partial(  # type: ignore[misc]
        RunWriter, flush_interval_s=1e9
    )
    with tempfile.TemporaryDirectory() as tmp, open_log(_scenario()) as log:
        _closed(Path(tmp) / "warm")
        replay = LogSimulator(log, tracker=LqrTracker(), agents="replay", reads_sensors=False)
        _replay_loop(replay)
        if args.native:
            _native(args.rounds, Path(tmp), replay)
        else:
            _counted_pass(args.what, Path(tmp), replay)


if __name__ == "__main__":
    main()
