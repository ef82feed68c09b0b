"""``python -m benchmarks batch``: a batch of small logs on the local pool with 1 and 2 workers, on Ray
at the same worker count, and Ray's cost per cell.

Each pass runs :func:`redrive.batch.run_batch` on ``logs`` demo bags (ROS 1, LiDAR + odometry +
IMU + GNSS, :func:`redrive.testing.demo_log.write_demo_bag`) × one pipeline (default
cluster-detector → idm-planner → pure-pursuit-pid) into a fresh batch directory and times the
whole call (planning the cells, hashing the logs, every worker, the records).  The cells are
open-loop runs through :func:`redrive.batch.run_cell`.

* **scaling**: wall(1 worker) / wall(2 workers) (target ≥ 1.7× on 2 cores);
* **Ray vs local**: throughput of Ray over the local pool at the same worker count
  (= wall(local) / wall(Ray); target ≥ 0.9×). Ray's local cluster is started once before the
  Ray passes (its start-up is reported apart: a batch on a cluster does not pay it per run);
* **cost per cell**: ``empty_cells`` cells of a 0.2 s log (2 frames) through one worker: wall
  per cell minus the cell's own run time (its record's ``wall_s``) is what the executor adds
  per cell — process start, task dispatch, records (target for Ray ≤ 0.5 s).

Load averages before and after are recorded: the machine may be shared.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from statistics import median
from typing import Any

from redrive.batch import BatchSpec, expand_logs, make_pipeline_item, run_batch, run_cell
from redrive.errors import ConfigError
from redrive.testing.demo_log import write_demo_bag

__all__ = ["BatchBenchResult", "bench_batch"]

TARGET_SCALING = 1.7
TARGET_RAY_RATIO = 0.9
TARGET_RAY_CELL_S = 0.5
DEFAULT_PIPELINE = ("cluster-detector", "idm-planner", "pure-pursuit-pid")


@dataclass(frozen=True, slots=True, kw_only=True)
class BatchBenchResult:
    """Medians of ``repeats`` passes, seconds."""

    logs: int
    log_duration_s: float
    frames: int
    pipeline: tuple[str, ...]
    repeats: int
    cpus: int
    local1_s: float
    local2_s: float
    ray2_s: float | None
    ray_start_s: float | None
    empty_cells: int
    local_cell_overhead_s: float
    ray_cell_overhead_s: float | None
    local_empty_cell_s: float
    ray_empty_cell_s: float | None
    load_before: tuple[float, float, float]
    load_after: tuple[float, float, float]
    ray_version: str | None
    passes: dict[str, list[float]] = field(default_factory=dict)

    @property
    def scaling(self) -> float:
        return self.local1_s / self.local2_s

    @property
    def ray_ratio(self) -> float | None:
        return None if self.ray2_s is None else self.local2_s / self.ray2_s

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out.update(
            scaling=self.scaling,
            ray_ratio=self.ray_ratio,
            targets={
                "scaling": TARGET_SCALING,
                "ray_ratio": TARGET_RAY_RATIO,
                "ray_cell_overhead_s": TARGET_RAY_CELL_S,
            },
        )
        return out


def _spec(logs: Sequence[Path], pipeline: Sequence[str]) -> BatchSpec:
    """``pipeline``: plugin names in the order perception, planning, control (the defaults')."""
    return BatchSpec(
        logs=expand_logs([str(p) for p in logs]),
        pipelines=(
            make_pipeline_item(
                name="bench",
                perception=pipeline[:1],
                planning=pipeline[1:2],
                control=pipeline[2:3],
            ),
        ),
        loops=("open",),
    )


def _timed_batch(
    spec: BatchSpec, scratch: Path, *, executor: str, workers: int
) -> tuple[float, list[float]]:
    """Wall seconds of one batch into a fresh directory, and each cell's own ``wall_s``."""
    out = Path(tempfile.mkdtemp(prefix=f"{executor}{workers}-", dir=scratch))
    try:
        t0 = time.perf_counter()
        manifest = run_batch(spec, out, runner=run_cell, executor=executor, workers=workers)
        wall = time.perf_counter() - t0
        failed = [c for c in manifest.cells if c.error]
        if failed:
            msg = f"bench batch: cell {failed[0].cell_id} failed: {failed[0].error}"
            raise ConfigError(msg)
        return wall, [float(c.wall_s or 0.0) for c in manifest.cells]
    finally:
        shutil.rmtree(out, ignore_errors=True)


def bench_batch(
    *,
    logs: int = 8,
    log_duration_s: float = 6.0,
    pipeline: Sequence[str] = DEFAULT_PIPELINE,  # perception, planning, control
    repeats: int = 1,
    empty_cells: int = 8,
    ray: bool = True,
    progress: Callable[[str], None] | None = None,
) -> BatchBenchResult:
    """Run the benchmark (see the module doc); ``ray=False`` (or Ray not installed) skips the
    Ray passes."""
    if logs < 1 or repeats < 1 or empty_cells < 1:
        msg = "bench batch: logs, repeats and empty cells must be >= 1"
        raise ConfigError(msg)
    say = progress or (lambda _text: None)
    ray_mod: Any = None
    if ray:
        try:
            import ray as ray_mod
        except ImportError:
            ray_mod = None
    load_before = os.getloadavg()
    scratch = Path(tempfile.mkdtemp(prefix="redrive-bench-batch-"))
    try:
        paths = [
            write_demo_bag(scratch / f"drive{i}.bag", duration_s=log_duration_s + 0.1 * i)
            for i in range(logs)
        ]
        tiny = [
            write_demo_bag(scratch / f"tiny{i}.bag", duration_s=0.2) for i in range(empty_cells)
        ]
        spec, tiny_spec = _spec(paths, pipeline), _spec(tiny, pipeline)
        passes: dict[str, list[float]] = {}
        cell_runs: dict[str, list[float]] = {}

        def timed(key: str, which: BatchSpec, executor: str, workers: int) -> None:
            say(f"{key} pass {len(passes.get(key, [])) + 1}/{repeats}")
            wall, cells = _timed_batch(which, scratch, executor=executor, workers=workers)
            passes.setdefault(key, []).append(wall)
            cell_runs.setdefault(key, []).append(sum(cells))

        say("warm-up: one batch of the tiny logs")
        _timed_batch(tiny_spec, scratch, executor="local", workers=1)
        for _ in range(repeats):  # interleaved: a change of load hits every variant alike
            timed("local1", spec, "local", 1)
            timed("local2", spec, "local", 2)
            timed("local_empty", tiny_spec, "local", 1)
        ray_start = None
        if ray_mod is not None:
            say("starting Ray's local cluster")
            t0 = time.perf_counter()
            ray_mod.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
            ray_start = time.perf_counter() - t0
            try:
                _timed_batch(tiny_spec, scratch, executor="ray", workers=2)  # warm the workers
                for _ in range(repeats):
                    timed("ray2", spec, "ray", 2)
                    timed("ray_empty", tiny_spec, "ray", 1)
            finally:
                ray_mod.shutdown()
        frames = sum(round(p_s * 10) for p_s in (log_duration_s + 0.1 * i for i in range(logs)))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)

    def per_cell(key: str) -> tuple[float, float] | tuple[None, None]:
        if key not in passes:
            return None, None
        walls = passes[key]
        own = cell_runs[key]
        return (
            median(walls) / empty_cells,
            median(w - o for w, o in zip(walls, own, strict=True)) / empty_cells,
        )

    local_cell, local_over = per_cell("local_empty")
    ray_cell, ray_over = per_cell("ray_empty")
    if local_cell is None or local_over is None:  # pragma: no cover - always measured
        msg = "bench batch: the local cost per cell was not measured"
        raise ConfigError(msg)
    return BatchBenchResult(
        logs=logs,
        log_duration_s=log_duration_s,
        frames=frames,
        pipeline=tuple(pipeline),
        repeats=repeats,
        cpus=os.cpu_count() or 0,
        local1_s=median(passes["local1"]),
        local2_s=median(passes["local2"]),
        ray2_s=median(passes["ray2"]) if "ray2" in passes else None,
        ray_start_s=ray_start,
        empty_cells=empty_cells,
        local_cell_overhead_s=local_over,
        ray_cell_overhead_s=ray_over,
        local_empty_cell_s=local_cell,
        ray_empty_cell_s=ray_cell,
        load_before=load_before,
        load_after=os.getloadavg(),
        ray_version=None if ray_mod is None else str(ray_mod.__version__),
        passes=passes,
    )
