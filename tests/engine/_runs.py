"""What two runs are compared on: their output tables without the timing columns."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa

from redrive.results import open_run

TIMING = {"latency_ns", "cpu_ns", "wall_ns", "late"}
OUTPUT_TABLES = ("frames", "steps", "detections", "paths", "commands", "ego", "ground_truth")


def outputs(run_dir: Path) -> dict[str, pa.Table]:
    """Every output table of the run, timing columns dropped."""
    run = open_run(run_dir)
    out = {}
    for name in OUTPUT_TABLES:
        table = run.table(name)
        out[name] = table.drop_columns([c for c in table.column_names if c in TIMING])
    return out
