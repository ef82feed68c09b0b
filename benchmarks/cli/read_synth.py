"""``python -m benchmarks read-synth SIZE_GB OUT.bag``: write a synthetic ROS 1 bag of LiDAR sweeps
(streamed: bounded memory whatever its size), then run ``redrive bench read`` on it."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from redrive.benchmarks.cli import add_read_arguments, run_read

__all__ = ["add_read_synth_parser"]

_DESCRIPTION = """\
Write a ROS 1 bag of about SIZE_GB GB (10^9 bytes) of PointCloud2 sweeps to LOG, then time reading
it as `redrive bench read LOG` does: raw (rosbags, no deserialisation) against redrive (open_log +
decode), every pass a fresh process; the JSON has a "synthetic" section besides.
"""

_EPILOG = """\
examples:
  python -m benchmarks read-synth 2 /tmp/big.bag          a 2 GB bag of 100k-point sweeps
  python -m benchmarks read-synth 0.3 --compression lz4 --points 50000 /tmp/small.bag
"""


def _write_synth(args: argparse.Namespace) -> Any:
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from benchmarks.synth_log import write_synthetic_bag
    from redrive.errors import LogError

    if args.size_gb <= 0:
        msg = f"SIZE_GB must be greater than 0, not {args.size_gb}"
        raise LogError(msg)
    with Progress(
        TextColumn(f"[bold]writing {args.log}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} messages"),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as bar:
        task = bar.add_task("synth", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        return write_synthetic_bag(
            args.log,
            size_bytes=round(args.size_gb * 1e9),
            points=args.points,
            layout=args.layout,
            compression=args.compression,
            progress=progress,
        )


def _run(args: argparse.Namespace) -> int:
    synth = _write_synth(args)
    return run_read(
        args,
        synth=synth,
        synth_json={
            "messages": synth.messages,
            "points_per_message": synth.points_per_message,
            "payload_bytes": synth.payload_bytes,
            "layout": args.layout,
            "compression": args.compression,
        },
    )


def add_read_synth_parser(sub: Any) -> None:
    parser = sub.add_parser(
        "read-synth",
        help="write a synthetic ROS 1 bag of LiDAR sweeps, then `redrive bench read` it",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("size_gb", type=float, metavar="SIZE_GB", help="size of the bag, GB")
    parser.add_argument("log", type=Path, metavar="LOG", help="the new .bag to write")
    parser.add_argument(
        "--points", type=int, default=100_000, metavar="N", help="points per sweep (default 100000)"
    )
    parser.add_argument(
        "--compression",
        choices=("none", "lz4", "bz2"),
        default="none",
        help="chunk compression of the synthetic bag (default none)",
    )
    parser.add_argument(
        "--layout",
        choices=("velodyne", "xyzi"),
        default="velodyne",
        help="velodyne: x,y,z,intensity f32 + ring u16 + time f64, 32 B/point (default); "
        "xyzi: 16 B/point",
    )
    add_read_arguments(parser)
    parser.set_defaults(func=_run)
