"""``python -m benchmarks batch`` — a batch of small logs: 1 vs 2 local workers, Ray vs local, Ray's
cost per cell."""

from __future__ import annotations

import argparse
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner, verdict

__all__ = ["add_batch_parser", "add_fleet_parser"]

_DESCRIPTION = """\
Run a batch of LOGS demo bags (ROS 1, LiDAR + odometry + IMU + GNSS, --duration seconds each) ×
one pipeline (cluster-detector -> idm-planner -> pure-pursuit-pid) through redrive.batch.run_batch,
each pass into a fresh batch directory, and report: the local pool with 2 workers against 1
(target >= 1.7x on 2 cores), Ray against the local pool at 2 workers (throughput, target >= 0.9x;
Ray's local cluster is started once beforehand, its start-up reported apart), and the cost per cell
of each executor: cells of a 0.2 s log through one worker, wall per cell minus the cell's own run
time (Ray target <= 0.5 s). Passes interleaved, medians of --repeat; load averages before and
after (the machine may be shared).
"""


def _run_batch(args: argparse.Namespace) -> int:
    from benchmarks.batch import (
        TARGET_RAY_CELL_S,
        TARGET_RAY_RATIO,
        TARGET_SCALING,
        bench_batch,
    )

    with spinner() as progress:
        r = bench_batch(
            logs=args.logs,
            log_duration_s=args.duration,
            repeats=args.repeat,
            empty_cells=args.empty_cells,
            ray=not args.no_ray,
            progress=progress,
        )
    if args.json:
        print_json(r.to_json())
        return 0
    c = report_console()
    c.print(
        f"[bold]{r.logs} logs[/] × {r.log_duration_s:g} s (~{r.frames} frames), pipeline "
        f"{' -> '.join(r.pipeline)}; {r.cpus} cores; medians of {r.repeats} passes; load "
        f"{r.load_before[0]:.2f} before, {r.load_after[0]:.2f} after"
    )
    c.print(
        f"local 1 worker {r.local1_s:.2f} s, 2 workers {r.local2_s:.2f} s: "
        f"{r.scaling:.2f}x {verdict(r.scaling >= TARGET_SCALING)} {TARGET_SCALING:g}x"
    )
    if r.ray2_s is not None and r.ray_ratio is not None:
        c.print(
            f"ray 2 workers {r.ray2_s:.2f} s: {r.ray_ratio:.2f}x the local pool's throughput "
            f"{verdict(r.ray_ratio >= TARGET_RAY_RATIO)} {TARGET_RAY_RATIO:g}x "
            f"(ray {r.ray_version}; its cluster started in {r.ray_start_s:.2f} s, not counted)"
        )
    else:
        c.print("ray: not measured (--no-ray, or Ray not installed: pip install 'redrive\\[ray]')")
    c.print(
        f"cost per cell ({r.empty_cells} cells of a 0.2 s log, 1 worker): local "
        f"{r.local_empty_cell_s:.3f} s per cell, {r.local_cell_overhead_s:.3f} s beyond the run"
    )
    if r.ray_cell_overhead_s is not None and r.ray_empty_cell_s is not None:
        c.print(
            f"  ray {r.ray_empty_cell_s:.3f} s per cell, {r.ray_cell_overhead_s:.3f} s beyond the "
            f"run {verdict(r.ray_cell_overhead_s <= TARGET_RAY_CELL_S)} <= {TARGET_RAY_CELL_S:g} s"
        )
    return 0


def add_batch_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "batch",
        help="batch scaling: 2 local workers vs 1, Ray vs local, Ray's cost per cell",
        description=_DESCRIPTION,
        epilog=(
            "examples:\n  python -m benchmarks batch\n"
            "  python -m benchmarks batch --logs 8 --duration 6 --repeat 3 --json\n"
            "  python -m benchmarks batch --no-ray"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--logs", type=int, default=8, metavar="N", help="logs (default 8)")
    parser.add_argument(
        "--duration", type=float, default=6.0, metavar="S", help="seconds per log (default 6)"
    )
    parser.add_argument(
        "--repeat", type=int, default=1, metavar="N", help="passes of each (default 1)"
    )
    parser.add_argument(
        "--empty-cells",
        type=int,
        default=8,
        metavar="N",
        help="cells of a 0.2 s log for the cost per cell (default 8)",
    )
    parser.add_argument("--no-ray", action="store_true", help="skip the Ray passes")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=_run_batch)


def _run_fleet(args: argparse.Namespace) -> int:
    from benchmarks.fleet import bench_fleet

    with spinner() as progress:
        r = bench_fleet(
            cells=args.cells,
            log_duration_s=args.duration,
            executor=args.executor,
            workers=args.workers,
            progress=progress,
        )
    if args.json:
        print_json(r.to_json())
        return 0
    c = report_console()
    c.print(
        f"[bold]{r.cells} cells[/] ({r.log_duration_s:g}-s logs, cluster detector) on "
        f"{r.executor}{f' {r.ray_version}' if r.ray_version else ''} with {r.workers} workers "
        f"in {r.wall_s:.1f} s ({r.cells / r.wall_s:.1f} cells/s), {r.failed} failed; load "
        f"{r.load_before[0]:.2f} before, {r.load_after[0]:.2f} after"
    )
    c.print(
        f"driver RSS: {r.rss_mb_start:.0f} MB before, {r.rss_mb_first:.0f} MB after the first "
        f"cell, {r.rss_mb_quarter:.0f} MB after a quarter, {r.rss_mb_end:.0f} MB at the end "
        f"(max {r.rss_mb_max:.0f} MB); slope over the last three quarters "
        f"{r.slope_mb_per_100:+.2f} MB per 100 cells"
    )
    return 0


def add_fleet_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "fleet",
        help="many small logs through Ray: does the driver's memory stay flat?",
        description=(
            "Run --cells tiny demo bags through the cluster detector on one executor and read the "
            "driver's resident memory after every finished cell: before, after the first cell, "
            "after a quarter, at the end, the maximum, and the slope over the last three quarters "
            "(MB per 100 cells)."
        ),
        epilog="examples:\n  python -m benchmarks fleet\n  python -m benchmarks fleet --cells 1000 --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--cells", type=int, default=200, metavar="N", help="cells (default 200)")
    parser.add_argument(
        "--duration", type=float, default=0.3, metavar="S", help="seconds per log (default 0.3)"
    )
    parser.add_argument("--executor", choices=("ray", "local"), default="ray", help="default ray")
    parser.add_argument("--workers", type=int, default=2, metavar="N", help="default 2")
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=_run_fleet)
