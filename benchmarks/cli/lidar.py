"""``python -m benchmarks lidar`` — the simulated LiDAR's sweeps/s against Open3D ray casting; camera
frames/s."""

from __future__ import annotations

import argparse
from typing import Any

from redrive.benchmarks.cli._console import print_json, report_console, spinner

__all__ = ["add_lidar_parser"]

_LIDAR_DESCRIPTION = """\
Time the simulated LiDAR: HDL-32E sweeps (32 x 1800 rays) against 60 moving vehicles, a few
buildings and the ground, the scene rebuilt every sweep, pinned to one CPU core; in the same run
Open3D's RaycastingScene (single thread, static scene) casts the same rays when open3d is
importable, and the ratio redrive/Open3D is printed (target >= 0.5). Also 1280x720 camera frames/s.
"""


def _run_lidar(args: argparse.Namespace) -> int:
    from benchmarks.lidar import TARGET_RATIO, bench_lidar

    with spinner() as progress:
        result = bench_lidar(
            scans=args.scans,
            camera_frames=args.frames,
            preset=args.preset,
            num_boxes=args.boxes,
            one_core=not args.all_cores,
            open3d=not args.no_open3d,
            progress=progress,
        )
    if args.json:
        print_json(result.to_json())
        return 0
    console = report_console()
    core = "one core (pinned)" if result.one_core else "all cores"
    console.print(
        f"[bold]LiDAR[/]:   {result.preset}, {result.rays_per_scan:,} rays/sweep, "
        f"{result.boxes} boxes ({result.triangles} triangles) + ground, {core}"
    )
    console.print(
        f"[bold]redrive[/]: {result.scans_per_s:,.1f} sweeps/s (scene rebuilt every sweep, "
        f"{result.points_per_scan:,.0f} points/sweep) = {result.real_time_factor:.1f}x real time"
    )
    if result.open3d_scans_per_s is None or result.ratio is None:
        console.print(f"[bold]Open3D[/]:  {result.open3d_note}")
    else:
        console.print(
            f"[bold]Open3D[/]:  {result.open3d_scans_per_s:,.1f} sweeps/s "
            f"(open3d {result.open3d_version}; {result.open3d_note})"
        )
        verdict = "[green]meets[/]" if result.ratio >= TARGET_RATIO else "[red]misses[/]"
        console.print(
            f"[bold]ratio[/] redrive/Open3D: {result.ratio:.2f}x — {verdict} the "
            f"{TARGET_RATIO}x target"
        )
    w, h = result.camera_resolution
    console.print(f"[bold]camera[/]:  {w}x{h}: {result.camera_fps:.1f} frames/s")
    return 0


def add_lidar_parser(bench_sub: Any) -> None:
    lidar = bench_sub.add_parser(
        "lidar",
        help="simulated LiDAR sweeps/s against Open3D ray casting; camera frames/s",
        description=_LIDAR_DESCRIPTION,
        epilog="examples:\n  python -m benchmarks lidar\n  python -m benchmarks lidar --scans 100 --json",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    lidar.add_argument("--scans", type=int, default=50, metavar="N", help="sweeps (default 50)")
    lidar.add_argument(
        "--frames", type=int, default=10, metavar="N", help="camera frames (default 10)"
    )
    lidar.add_argument("--preset", default="HDL-32E", help="LiDAR preset (default HDL-32E)")
    lidar.add_argument(
        "--boxes", type=int, default=60, metavar="N", help="moving vehicles (default 60)"
    )
    lidar.add_argument("--all-cores", action="store_true", help="do not pin to one CPU core")
    lidar.add_argument("--no-open3d", action="store_true", help="skip the Open3D baseline")
    lidar.add_argument("--json", action="store_true", help="print JSON instead of text")
    lidar.set_defaults(func=_run_lidar)
