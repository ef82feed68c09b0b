"""``python -m benchmarks record`` — redrive's recorder against ``rosbag record`` on the same playback."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from benchmarks.record import DEFAULT_RATE
from redrive.benchmarks.cli._console import print_json, report_console, spinner, verdict

__all__ = ["add_record_parser"]

_DESCRIPTION = """\
Start a ROS 1 master, `rosbag play -l -r RATE` of the KITTI bag of ../shared/data (3 frames of a
120k-point cloud, a 1242x375 image and its PNG: about 2.4 x RATE messages/s per topic), and side by
side the real `rosbag record` (C++) and `redrive live TOPICS --record` (record-only: no pipeline).
Once both are connected to every topic the playback runs for --duration seconds and is paused, so
both are offered the same messages; then both are stopped with SIGINT and the messages are counted
per topic from the files they wrote. Reported: messages per topic by each and how many redrive
lost relative to rosbag record (target 0), and the CPU time of each one's process tree over the
playback (redrive's includes its scraper processes; target <= 1.0x rosbag record's), also per MB
recorded, and how many of redrive's chunks are compressed (with --compression lz4/zstd, chunks the
compressor could not keep up with are written uncompressed). Needs
Debian's ROS 1 (`make system-test-deps`). The machine may be shared: the load is reported.
"""


def _default_data() -> Path:
    env = os.environ.get("REDRIVE_SHARED_DATA")
    return Path(env) if env else Path("../shared/data")


def _run_record(args: argparse.Namespace) -> int:
    from benchmarks.record import TARGET_CPU_RATIO, bench_record

    with spinner() as progress:
        r = bench_record(
            data_dir=args.data,
            rate=args.rate,
            window_s=args.duration,
            topics=args.topics or None,
            compression=args.compression,
            workdir=args.keep,
            progress=progress,
        )
    if args.json:
        print_json(r.to_json())
        return 0
    c = report_console()
    c.print(
        f"[bold]{r.bag}[/] played with -l -r {r.rate:g} for {r.window_s:.1f} s, recorded with "
        f"{r.compression} compression; {r.cpus} cores; "
        f"load {r.load_before[0]:.2f} before, {r.load_after[0]:.2f} after"
    )
    for t in r.topics:
        c.print(
            f"  {t.topic}: rosbag record {t.reference} ({r.hz(t):.1f}/s, "
            f"{t.reference_bytes / 1e6:.1f} MB), redrive {t.redrive} "
            f"({t.redrive_bytes / 1e6:.1f} MB), lost {t.lost}",
            highlight=False,
        )
    c.print(f"lost relative to rosbag record: {r.lost} {verdict(r.lost == 0)} 0")
    more = sum(max(t.redrive - t.reference, 0) for t in r.topics)
    if more:
        c.print(f"  (redrive recorded {more} messages that rosbag record did not)")
    c.print(
        f"CPU over the playback: rosbag record {r.reference_cpu_s:.2f} s, redrive "
        f"{r.redrive_cpu_s:.2f} s ({r.redrive_processes} processes): {r.cpu_ratio:.2f}x "
        f"{verdict(r.cpu_ratio <= TARGET_CPU_RATIO)} <= {TARGET_CPU_RATIO:g}x"
    )
    ref_ms, ours_ms = r.cpu_per_mb
    c.print(f"  per MB recorded: rosbag record {ref_ms:.2f} ms, redrive {ours_ms:.2f} ms")
    if r.redrive_chunks:
        c.print(
            "  redrive's chunks: "
            + ", ".join(f"{n} {kind}" for kind, n in sorted(r.redrive_chunks.items())),
            highlight=False,
        )
    c.print(
        "  redrive by process: "
        + ", ".join(f"{k} {v:.2f} s" for k, v in sorted(r.redrive_cpu_by_process.items())),
        highlight=False,
    )
    c.print(
        f"CPU from start to the end of the playback: rosbag record {r.reference_cpu_total_s:.2f} s, "
        f"redrive {r.redrive_cpu_total_s:.2f} s"
    )
    for note in r.notes:
        c.print(f"[yellow]{note}[/]", highlight=False)
    return 0


def add_record_parser(bench_sub: Any) -> None:
    parser = bench_sub.add_parser(
        "record",
        help="redrive live --record against rosbag record: messages lost, CPU",
        description=_DESCRIPTION,
        epilog=(
            "examples:\n  python -m benchmarks record --data ../shared/data\n"
            "  python -m benchmarks record --rate 14 --duration 20 --keep /tmp/rec --json"
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--data",
        type=Path,
        default=_default_data(),
        metavar="DIR",
        help="the shared data folder (default $REDRIVE_SHARED_DATA or ../shared/data)",
    )
    parser.add_argument(
        "--rate",
        type=float,
        default=DEFAULT_RATE,
        metavar="X",
        help=f"rosbag play -r (default {DEFAULT_RATE:g}: about 33 messages/s per topic)",
    )
    parser.add_argument(
        "--duration", type=float, default=20.0, metavar="S", help="seconds of playback (default 20)"
    )
    parser.add_argument(
        "--compression",
        choices=("none", "lz4", "zstd"),
        default="none",
        help="chunk compression of both recordings (default none, rosbag record's default; "
        "lz4: rosbag record --lz4; zstd: redrive only, rosbag record writes uncompressed)",
    )
    parser.add_argument(
        "--topics", nargs="+", metavar="TOPIC", help="record only these (default: the bag's)"
    )
    parser.add_argument(
        "--keep", type=Path, metavar="DIR", help="write the recordings here and keep them"
    )
    parser.add_argument("--json", action="store_true", help="print JSON instead of text")
    parser.set_defaults(func=_run_record)
