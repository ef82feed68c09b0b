"""``redrive bench read`` — redrive's read + decode speed against a raw read of the same log."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from redrive.cli.bench_engine import add_engine_parser
from redrive.cli.bench_eval import add_eval_parser
from redrive.cli.bench_gui import add_gui_parser
from redrive.cli.bench_loss import add_loss_parser
from redrive.cli.bench_transport import add_transport_parser

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive bench read drive.bag                       all PointCloud2 topics, 3 repeats
  redrive bench read drive.bag --topic /velodyne_points --repeat 5 --json
  redrive bench read --synth 2 /tmp/big.bag          write a 2 GB bag of 100k-point sweeps, bench it
  redrive bench read --synth 0.3 --compression lz4 --points 50000 /tmp/small.bag

Every pass runs in a fresh Python process (so peak RSS is per pass); the page cache is warmed by
reading the log once first. The ratio is redrive's throughput over the raw read's (target ≥ 0.8).
"""

_READ_DESCRIPTION = """\
Time reading every sensor_msgs/PointCloud2 message of a log two ways, in the same run: raw
(rosbags for ROS 1 / ROS 2 bags, mcap for .mcap files, no deserialisation) and redrive (open_log +
decode to a PointCloud). Prints messages/s, MB/s of payload, the redrive/raw ratio and the peak
resident memory of each pass. With --synth, first write a synthetic ROS 1 bag of LiDAR sweeps to
LOG (streamed: bounded memory whatever its size) and benchmark that.
"""


def _mb(n: float) -> str:
    return f"{n / 1e6:,.1f}"


def _print_report(result: Any, *, synth: Any | None) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=None if sys.stdout.isatty() else 120)
    raw, ours = result.raw, result.redrive
    repeats = len(result.redrive_passes)
    console.print(
        f"[bold]log[/]:       {result.path} ({result.log_format}, {_mb(result.file_bytes)} MB)"
    )
    if synth is not None:
        console.print(
            f"[bold]synthetic[/]: {synth.messages} × {synth.points_per_message:,} points, "
            f"{_mb(synth.payload_bytes)} MB payload"
        )
    console.print(f"[bold]topics[/]:    {', '.join(result.topics)}")
    console.print(
        f"[bold]read[/]:      {result.messages} messages, {_mb(result.payload_bytes)} MB payload, "
        f"{result.points:,} points"
    )
    warm = "warmed by one full read first" if result.warmed else "NOT warmed"
    malloc = (
        "tuned (" + " ".join(f"{k}={v}" for k, v in result.pass_env.items()) + ")"
        if result.pass_env
        else "glibc defaults"
    )
    console.print(
        f"[bold]method[/]:    median of {repeats} repeats, each pass a fresh process; page cache {warm}"
    )
    console.print(f"[bold]malloc[/]:    {malloc}")
    table = Table()
    for col in (
        "pass",
        "msgs/s",
        "MB/s",
        "best MB/s",
        "loop s",
        "open s",
        "RSS start MB",
        "peak RSS MB",
    ):
        table.add_column(col, justify="left" if col == "pass" else "right")
    for name, side in (("raw (baseline)", raw), ("redrive (decode)", ours)):
        table.add_row(
            name,
            f"{side.msgs_per_s:,.1f}",
            f"{side.mb_per_s:,.0f}",
            f"{side.best_mb_per_s:,.0f}",
            f"{side.median_loop_s:.4f}",
            f"{side.median_open_s:.4f}",
            _mb(side.rss_start_bytes),
            _mb(side.peak_rss_bytes),
        )
    console.print(table)
    from redrive.bench.read import TARGET_RATIO

    verdict = "[green]meets[/]" if result.ratio >= TARGET_RATIO else "[red]misses[/]"
    console.print(
        f"[bold]ratio[/] redrive/raw: {result.ratio:.2f}× (best-of-{repeats}: "
        f"{result.best_ratio:.2f}×) — {verdict} the {TARGET_RATIO}× target"
    )


def _run_read(args: argparse.Namespace) -> int:
    from rich.console import Console

    from redrive.bench.read import TUNED_MALLOC_ENV, bench_read

    status = Console(stderr=True)
    synth = None
    if args.synth is not None:
        synth = _write_synth(args, status)
    with status.status("benchmarking") as spinner:

        def progress(text: str) -> None:
            spinner.update(f"benchmarking: {text}")

        result = bench_read(
            args.log,
            topics=args.topic,
            repeats=args.repeat,
            pass_env=TUNED_MALLOC_ENV if args.tune_malloc else None,
            warm=not args.no_warm,
            progress=progress,
        )
    if args.json:
        out = result.to_json()
        if synth is not None:
            out["synthetic"] = {
                "messages": synth.messages,
                "points_per_message": synth.points_per_message,
                "payload_bytes": synth.payload_bytes,
                "layout": args.layout,
                "compression": args.compression,
            }
        json.dump(out, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        _print_report(result, synth=synth)
    return 0


def _write_synth(args: argparse.Namespace, status: Any) -> Any:
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from redrive.bench.synth_log import write_synthetic_bag
    from redrive.errors import LogError

    if args.synth <= 0:
        msg = f"--synth takes a size in GB greater than 0, not {args.synth}"
        raise LogError(msg)
    with Progress(
        TextColumn(f"[bold]writing {args.log}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} messages"),
        TimeElapsedColumn(),
        console=status,
        transient=True,
    ) as bar:
        task = bar.add_task("synth", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        return write_synthetic_bag(
            args.log,
            size_bytes=round(args.synth * 1e9),
            points=args.points,
            layout=args.layout,
            compression=args.compression,
            progress=progress,
        )


_LIDAR_DESCRIPTION = """\
Time the simulated LiDAR: HDL-32E sweeps (32 x 1800 rays) against 60 moving vehicles, a few
buildings and the ground, the scene rebuilt every sweep, pinned to one CPU core; in the same run
Open3D's RaycastingScene (single thread, static scene) casts the same rays when open3d is
importable, and the ratio redrive/Open3D is printed (target >= 0.5). Also 1280x720 camera frames/s.
"""


def _run_lidar(args: argparse.Namespace) -> int:
    from rich.console import Console

    from redrive.bench.lidar import TARGET_RATIO, bench_lidar

    status = Console(stderr=True)
    with status.status("benchmarking") as spinner:
        result = bench_lidar(
            scans=args.scans,
            camera_frames=args.frames,
            preset=args.preset,
            num_boxes=args.boxes,
            one_core=not args.all_cores,
            open3d=not args.no_open3d,
            progress=lambda text: spinner.update(f"benchmarking: {text}"),
        )
    if args.json:
        json.dump(result.to_json(), sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    console = Console(width=None if sys.stdout.isatty() else 120)
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


def _add_lidar_parser(bench_sub: Any) -> None:
    lidar = bench_sub.add_parser(
        "lidar",
        help="simulated LiDAR sweeps/s against Open3D ray casting; camera frames/s",
        description=_LIDAR_DESCRIPTION,
        epilog="examples:\n  redrive bench lidar\n  redrive bench lidar --scans 100 --json",
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


def _run_group(args: argparse.Namespace) -> int:
    args.bench_parser.print_help()
    return 2


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "bench",
        help="benchmarks against a baseline measured in the same run",
        description="Benchmarks of redrive against a third-party baseline measured in the same run.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.set_defaults(func=_run_group, bench_parser=parser)
    bench_sub = parser.add_subparsers(dest="bench_command", metavar="BENCHMARK")
    read = bench_sub.add_parser(
        "read",
        help="read + decode PointCloud2 messages against a raw rosbags/mcap read",
        description=_READ_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    read.add_argument(
        "log",
        type=Path,
        metavar="LOG",
        help="a .bag, .mcap or ROS 2 bag directory; with --synth, the new .bag to write",
    )
    read.add_argument(
        "--topic",
        action="append",
        default=None,
        metavar="T",
        help="a PointCloud2 topic to read (repeatable; default: every PointCloud2 topic)",
    )
    read.add_argument(
        "--repeat", type=int, default=3, metavar="N", help="passes per side (default 3)"
    )
    read.add_argument(
        "--json", action="store_true", help="print JSON (every pass) instead of a table"
    )
    read.add_argument(
        "--no-warm", action="store_true", help="do not read the log once before measuring"
    )
    read.add_argument(
        "--tune-malloc",
        action="store_true",
        help="run both passes with glibc MALLOC_MMAP_THRESHOLD_=64MiB, MALLOC_TRIM_THRESHOLD_=256MiB "
        "(no page-fault churn on multi-MB messages: measures CPU work, not the allocator)",
    )
    synth = read.add_argument_group("synthetic log")
    synth.add_argument(
        "--synth",
        type=float,
        default=None,
        metavar="SIZE_GB",
        help="write a ROS 1 bag of about SIZE_GB GB (10⁹ bytes) of PointCloud2 to LOG first",
    )
    synth.add_argument(
        "--points", type=int, default=100_000, metavar="N", help="points per sweep (default 100000)"
    )
    synth.add_argument(
        "--compression",
        choices=("none", "lz4", "bz2"),
        default="none",
        help="chunk compression of the synthetic bag (default none)",
    )
    synth.add_argument(
        "--layout",
        choices=("velodyne", "xyzi"),
        default="velodyne",
        help="velodyne: x,y,z,intensity f32 + ring u16 + time f64, 32 B/point (default); "
        "xyzi: 16 B/point",
    )
    read.set_defaults(func=_run_read)
    _add_lidar_parser(bench_sub)
    add_engine_parser(bench_sub)
    add_eval_parser(bench_sub)
    add_transport_parser(bench_sub)
    add_loss_parser(bench_sub)
    add_gui_parser(bench_sub)
