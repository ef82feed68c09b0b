"""Where a local batch cell's time goes: what the local executor's forkserver does (import
``redrive.batch.preload`` and ``redrive.batch.cell``), then a fork that runs one open-loop cell
of a 0.2-s demo bag (2 frames; ``python -m benchmarks batch``'s "empty-ish" cell) — under cProfile
(``--profile``, the top entries by cumulative time) or timed (thread CPU and wall of the cell in
the fork, and of a second cell in the same fork: what a warm process would pay).

    PYTHONPATH=src .venv/bin/python benchmarks/batch_cell_profile.py [--forks 5] [--profile]

Outputs: per fork, ``first`` (a fresh fork's cell, what every local cell pays) and ``second``
(the next cell in that process) in thread-CPU ms and wall ms; the medians at the end.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import tempfile
import time
from pathlib import Path
from statistics import median


def _cell(batch: Path, bag: Path, n: int) -> tuple[float, float]:
    from redrive.batch import BatchSpec, expand_logs, make_pipeline_item, run_cell
    from redrive.batch.run import plan_cells

    spec = BatchSpec(
        logs=expand_logs([str(bag)]),
        pipelines=(
            make_pipeline_item(
                name="bench",
                perception=("cluster-detector",),
                planning=("idm-planner",),
                control=("pure-pursuit-pid",),
            ),
        ),
        loops=("open",),
    )
    (task,) = plan_cells(spec, batch / f"b{n}")
    c0, w0 = time.thread_time(), time.perf_counter()
    record = run_cell(task)
    c1, w1 = time.thread_time(), time.perf_counter()
    if record.error:
        raise SystemExit(f"cell failed: {record.error}")
    return (c1 - c0) * 1e3, (w1 - w0) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--forks", type=int, default=5)
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--top", type=int, default=40)
    args = ap.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="cellprof-"))
    from redrive.testing.demo_log import write_demo_bag

    bag = write_demo_bag(scratch / "tiny.bag", duration_s=0.2)
    # what the forkserver imports (executors.LocalExecutor._run's set_forkserver_preload)
    import redrive.batch.cell
    import redrive.batch.preload  # noqa: F401

    rows = []
    for k in range(args.forks):
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(r)
            batch = scratch / f"f{k}"
            if args.profile:
                prof = cProfile.Profile()
                prof.enable()
                first = _cell(batch, bag, 0)
                prof.disable()
                out = io.StringIO()
                pstats.Stats(prof, stream=out).sort_stats("cumulative").print_stats(args.top)
                print(out.getvalue())
            else:
                first = _cell(batch, bag, 0)
            second = _cell(batch, bag, 1)
            os.write(w, json.dumps([first, second]).encode())
            os._exit(0)
        os.close(w)
        data = b""
        while chunk := os.read(r, 65536):
            data += chunk
        os.waitpid(pid, 0)
        first, second = json.loads(data)
        rows.append((first, second))
        print(
            f"fork {k}: first cell cpu {first[0]:.1f} ms wall {first[1]:.1f} ms; "
            f"second cell cpu {second[0]:.1f} ms wall {second[1]:.1f} ms"
        )
    print(
        f"median: first cpu {median(r[0][0] for r in rows):.1f} ms wall "
        f"{median(r[0][1] for r in rows):.1f} ms; second cpu {median(r[1][0] for r in rows):.1f} "
        f"ms wall {median(r[1][1] for r in rows):.1f} ms; load {os.getloadavg()}"
    )


if __name__ == "__main__":
    main()
