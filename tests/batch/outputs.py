"""What a cell produced, timing aside: every results table but ``resources``, without the
wall-clock columns (frames.wall_ns, frames.late, steps.latency_ns, steps.cpu_ns)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from redrive.cli.main import main
from redrive.results import open_run

TIMING_COLUMNS = {"wall_ns", "late", "latency_ns", "cpu_ns"}


def cell_outputs(run_dir: Path) -> dict[str, Any]:
    run = open_run(run_dir)
    out: dict[str, Any] = {}
    for name in run.tables():
        if name == "resources":
            continue
        table = run.table(name)
        keep = [c for c in table.column_names if c not in TIMING_COLUMNS]
        out[name] = table.select(keep).to_pylist()
    return out


def batch_outputs(batch_dir: Path) -> dict[str, dict[str, Any]]:
    """cell id → :func:`cell_outputs` of every complete cell's run directory."""
    runs = batch_dir / "runs"
    return {
        str(manifest.parent.relative_to(runs)): cell_outputs(manifest.parent)
        for manifest in sorted(runs.glob("*/*/*/manifest.json"))
    }


def batch(out: Path, *args: str) -> int:
    """``redrive batch ARGS --out OUT --no-progress``; its exit status."""
    return main(["batch", *args, "--out", str(out), "--no-progress"])
