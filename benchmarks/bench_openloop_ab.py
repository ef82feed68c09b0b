"""A/B of the open-loop reference pipeline on one log: two source trees, interleaved, fresh processes.

    .venv/bin/python benchmarks/bench_openloop_ab.py LOG --base OTHER/src [--rounds 3] [--out DIR]

For each side (``--base``, and ``--branch``, default this tree's ``src``) a fresh interpreter with
``PYTHONPATH`` at that tree (1) iterates the frames ``redrive run`` reads for the reference
pipeline (the driver LiDAR, ego state, ground truth) and (2) runs ``redrive run LOG`` twice, the
second (imports warm) measured.  Each gives wall seconds, process CPU seconds and the main
thread's CPU seconds (what the frame loop waits for when a second core is free; a loaded machine
inflates wall time far more).  The load average is printed before each pass.  Every results table
of each round's two runs (timing columns and ``resources`` aside) is compared; a difference is
reported and the exit status is 1.  Used for BENCHMARKS.md's open-loop sections (issue 15).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

_RUNNER = r"""
import contextlib, dataclasses, io, json, shutil, sys, time
from redrive.cli.main import main
from redrive.io import open_log
from redrive.assembly.frames import FrameAssembler

log_path, out = sys.argv[1], sys.argv[2]
with open_log(log_path) as log:
    smap = FrameAssembler(log).sensor_map
    driver_only = tuple(s for s in smap.sensors if s.sensor_id == smap.driver)
    assembler = FrameAssembler(log, sensor_map=dataclasses.replace(smap, sensors=driver_only))
    w, c, t = time.perf_counter(), time.process_time(), time.thread_time()
    n = sum(1 for _ in assembler.frames())
    read = [time.perf_counter() - w, time.process_time() - c, time.thread_time() - t]

def run(d):
    shutil.rmtree(d, ignore_errors=True)
    with contextlib.redirect_stdout(io.StringIO()):
        main(["run", log_path, "-o", d, "--no-progress"])

run(out + "-warm")
w, c, t = time.perf_counter(), time.process_time(), time.thread_time()
run(out)
whole = [time.perf_counter() - w, time.process_time() - c, time.thread_time() - t]
print(json.dumps({"frames": n, "read": read, "run": whole}))
"""

_TIMING = {"wall_ns", "late", "latency_ns", "cpu_ns"}


def _load() -> str:
    return Path("/proc/loadavg").read_text().split()[0] if Path("/proc/loadavg").exists() else "?"


def _side(src: Path, log: Path, out: Path) -> dict[str, list[float]]:
    env = {**os.environ, "PYTHONPATH": str(src)}
    done = subprocess.run(
        [sys.executable, "-c", _RUNNER, str(log), str(out)],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def _tables_equal(a: Path, b: Path) -> list[str]:
    import pyarrow.parquet as pq

    differ = []
    for table in sorted(p.name for p in a.iterdir() if p.is_dir() and p.name != "resources"):
        ta, tb = pq.read_table(a / table), pq.read_table(b / table)
        cols = [c for c in ta.column_names if c not in _TIMING]
        if ta.column_names != tb.column_names or not ta.select(cols).equals(tb.select(cols)):
            differ.append(table)
    return differ


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", type=Path)
    parser.add_argument("--base", type=Path, required=True, help="the other tree's src directory")
    parser.add_argument("--branch", type=Path, default=Path(__file__).resolve().parents[1] / "src")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=None, help="where the runs go (default: temp)")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="redrive-openloop-ab-"))
    ratios: dict[str, list[float]] = {"read": [], "run": []}
    status = 0
    print("round side  load | read: wall cpu main-thread | run: wall cpu main-thread (s)")
    for r in range(1, args.rounds + 1):
        sides = ("base", "branch") if r % 2 else ("branch", "base")
        got = {}
        for side in sides:
            load = _load()
            got[side] = _side(getattr(args, side), args.log, out / f"{side}-{r}")
            rd, rn = got[side]["read"], got[side]["run"]
            print(
                f"{r:5d} {side:6s} {load:>5s} | {rd[0]:6.2f} {rd[1]:6.2f} {rd[2]:6.2f} | "
                f"{rn[0]:6.2f} {rn[1]:6.2f} {rn[2]:6.2f}"
            )
        for part, values in ratios.items():
            values.append(got["branch"][part][2] / got["base"][part][2])
        differ = _tables_equal(out / f"base-{r}", out / f"branch-{r}")
        if differ:
            status = 1
            print(f"round {r}: tables differ: {', '.join(differ)}")
    for part, values in ratios.items():
        print(
            f"main-thread CPU branch/base, {part}: median {statistics.median(values):.2f} "
            f"(min {min(values):.2f}, max {max(values):.2f})"
        )
    print("tables: " + ("all equal" if status == 0 else "DIFFERENT") + f"; runs in {out}")
    return status


if __name__ == "__main__":
    raise SystemExit(main())
