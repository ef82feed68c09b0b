"""``python -m benchmarks fleet``: many small logs through one executor (Ray by default) with the
driver's memory sampled at every cell event — does the process that runs ``redrive batch`` stay
flat as the fleet grows?

The driver holds the batch's plan (one :class:`~redrive.batch.CellTask` per cell), the records
of the cells finished so far and, on Ray, a reference per task in flight; what must not grow
with the cells done is everything else (results, logs, Ray object refs of finished tasks). The
resident set size (``/proc/self/statm``) is read after every finished cell; the report gives it
at the first finished cell, at a quarter of the cells, at the end and its maximum, and the
least-squares slope over the last three quarters in MB per 100 cells.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from redrive.batch import BatchSpec, expand_logs, make_pipeline_item, run_batch, run_cell
from redrive.errors import ConfigError
from redrive.testing.demo_log import write_demo_bag

__all__ = ["FleetBenchResult", "bench_fleet", "rss_bytes"]

_PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_bytes() -> int:
    """This process's resident set size now (not the peak)."""
    with open("/proc/self/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * _PAGE


@dataclass(frozen=True, slots=True)
class FleetBenchResult:
    cells: int
    log_duration_s: float
    executor: str
    workers: int
    wall_s: float
    failed: int
    rss_mb_start: float  # before the batch (after the logs were written)
    rss_mb_first: float  # after the first finished cell
    rss_mb_quarter: float  # after a quarter of the cells
    rss_mb_end: float
    rss_mb_max: float
    slope_mb_per_100: float  # over the last three quarters of the cells
    samples: tuple[tuple[int, float], ...]  # (cells finished, RSS MB)
    load_before: tuple[float, float, float]
    load_after: tuple[float, float, float]
    ray_version: str | None

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def _slope(points: list[tuple[int, float]]) -> float:
    """Least-squares slope of y over x, ×100 (MB per 100 cells)."""
    if len(points) < 2:
        return 0.0
    n = len(points)
    mx = sum(x for x, _ in points) / n
    my = sum(y for _, y in points) / n
    sxx = sum((x - mx) ** 2 for x, _ in points)
    if sxx == 0:
        return 0.0
    return 100.0 * sum((x - mx) * (y - my) for x, y in points) / sxx


def bench_fleet(
    *,
    cells: int = 200,
    log_duration_s: float = 0.3,
    executor: str = "ray",
    workers: int = 2,
    progress: Callable[[str], None] | None = None,
) -> FleetBenchResult:
    """Run ``cells`` demo bags of ``log_duration_s`` through the cluster detector on
    ``executor`` and sample the driver's memory (see the module doc)."""
    if cells < 4:
        raise ConfigError("bench fleet: at least 4 cells")
    say = progress or (lambda _text: None)
    ray_mod: Any = None
    if executor == "ray":
        try:
            import ray as ray_mod
        except ImportError as err:
            msg = "bench fleet: Ray is not installed (pip install 'redrive[ray]'), or use --executor local"
            raise ConfigError(msg) from err
    load_before = os.getloadavg()
    scratch = Path(tempfile.mkdtemp(prefix="redrive-bench-fleet-"))
    try:
        say(f"writing {cells} logs")
        first = write_demo_bag(scratch / "drive0.bag", duration_s=log_duration_s)
        paths = [first]
        for i in range(1, cells):  # the same bytes under other names: each is its own cell
            path = scratch / f"drive{i}.bag"
            os.link(first, path)
            paths.append(path)
        spec = BatchSpec(
            logs=expand_logs([str(p) for p in paths]),
            pipelines=(make_pipeline_item(name="fleet", perception=("cluster-detector",)),),
            loops=("open",),
        )
        if ray_mod is not None:
            say("starting Ray's local cluster")
            ray_mod.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        try:
            samples: list[tuple[int, float]] = []
            start_mb = rss_bytes() / 1e6

            def on_event(event: str, _record: Any, counts: Any) -> None:
                if event in ("complete", "failed"):
                    samples.append((counts.done + counts.failed, rss_bytes() / 1e6))
                    say(
                        f"{counts.done + counts.failed}/{cells} cells, driver {samples[-1][1]:.0f} MB"
                    )

            t0 = time.perf_counter()
            manifest = run_batch(
                spec,
                scratch / "batch",
                runner=run_cell,
                executor=executor,
                workers=workers,
                progress=on_event,
            )
            wall = time.perf_counter() - t0
        finally:
            if ray_mod is not None:
                ray_mod.shutdown()
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    quarter = max(1, cells // 4)
    tail = [s for s in samples if s[0] >= quarter]
    mbs = [mb for _, mb in samples]
    return FleetBenchResult(
        cells=cells,
        log_duration_s=log_duration_s,
        executor=executor,
        workers=workers,
        wall_s=wall,
        failed=sum(1 for c in manifest.cells if c.error),
        rss_mb_start=start_mb,
        rss_mb_first=mbs[0],
        rss_mb_quarter=next(mb for n, mb in samples if n >= quarter),
        rss_mb_end=mbs[-1],
        rss_mb_max=max(mbs),
        slope_mb_per_100=_slope(tail),
        samples=tuple(samples),
        load_before=load_before,
        load_after=os.getloadavg(),
        ray_version=None if ray_mod is None else str(ray_mod.__version__),
    )
