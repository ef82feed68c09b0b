"""``python -m benchmarks record-ros2`` — a 10 Hz 120k-point cloud recorded over ROS 2 and over ROS 1."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner, verdict

__all__ = ["add_record_ros2_parser"]

_DESCRIPTION = """\
Publish a synthetic PointCloud2 (x, y, z, intensity float32; 120k points: 1.9 MB) at --rate Hz
for --duration seconds, first over ROS 1 (rosmaster --core and a rospy publisher) recorded by
`redrive live /points --record`, then over ROS 2 (a Cyclone DDS publisher, reliable, on a
loopback-only domain) recorded by `redrive live --ros2 /points --record`; both with
--compression none. Each publisher starts once redrive's reader is connected. Reported per
middleware: clouds sent and recorded (target: none lost), and the CPU of redrive's process tree
(recorder and scraper) over the publishing: seconds, % of one core, ms per cloud. Issue 18's
target: ROS 2 uses at most 1 % of a core more than ROS 1. Needs Debian's ROS 1
(`make system-test-deps`) and cyclonedds (the ros2 extra). The machine may be shared: the load
is reported.
"""


def _run(args: argparse.Namespace) -> int:
    from benchmarks.record_ros2 import TARGET_EXTRA_CPU_PERCENT, bench_record_ros2

    with spinner() as progress:
        r = bench_record_ros2(
            points=args.points,
            rate=args.rate,
            window_s=args.duration,
            workdir=args.keep,
            progress=progress,
        )
    if args.json:
        print_json(r.to_json())
        return 0
    c = report_console()
    c.print(
        f"[bold]{r.points} points at {r.rate:g} Hz[/] for {r.window_s:g} s; {r.cpus} cores; "
        f"load {r.load_before[0]:.2f} before, {r.load_after[0]:.2f} after"
    )
    for run in r.runs:
        c.print(
            f"  {run.middleware}: sent {run.sent}, recorded {run.recorded}, lost {run.lost} "
            f"{verdict(run.lost == 0)} 0; CPU {run.cpu_s:.2f} s over {run.window_s:.1f} s = "
            f"{run.cpu_percent:.1f} % of a core, {run.cpu_ms_per_message:.1f} ms a cloud",
            highlight=False,
        )
        c.print(
            "    by process: "
            + ", ".join(f"{k} {v:.2f} s" for k, v in sorted(run.cpu_by_process.items())),
            highlight=False,
        )
    extra = r.extra_cpu_percent
    c.print(
        f"ROS 2 - ROS 1: {extra:+.1f} % of a core "
        f"{verdict(extra <= TARGET_EXTRA_CPU_PERCENT)} <= +{TARGET_EXTRA_CPU_PERCENT:g} %"
    )
    return 0


def add_record_ros2_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "record-ros2",
        help="a 10 Hz 120k-point cloud recorded over ROS 2 against ROS 1: lost, CPU",
        description=_DESCRIPTION,
        epilog=(
            "examples:\n  python -m benchmarks record-ros2\n"
            "  python -m benchmarks record-ros2 --duration 30 --keep /tmp/r2 --json"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--points", type=int, default=120_000, metavar="N", help="points a cloud (default 120000)"
    )
    parser.add_argument(
        "--rate", type=float, default=10.0, metavar="HZ", help="clouds a second (default 10)"
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=20.0,
        metavar="S",
        help="seconds of publishing (default 20)",
    )
    parser.add_argument(
        "--keep", type=Path, metavar="DIR", help="write the recordings here and keep them"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=_run)
