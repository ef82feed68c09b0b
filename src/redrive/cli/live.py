"""``redrive live`` — run algorithms on live ROS 1 or ROS 2 topics through shared memory, and
record them."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive live /imu/data /odom /fix --record husky.mcap     record only (as rosbag record)
  redrive live -a -x '/rosout.*' --record all.mcap --split-size 500M
  redrive live -e '/camera/.*' --record cams.mcap --duration 60
  redrive live --topics /velodyne_points --duration 60
  redrive live --master http://127.0.0.1:11311 --topics /velodyne_points /camera/image_raw /imu \\
      --perception cluster-detector --record drive.mcap --out runs/live1
  redrive live --topics /points --pipeline pipeline.toml --frames 500
  redrive live --replay drive.bag --record copy.mcap       a log played as a sensor rig
  redrive live --synthetic urban --duration 20              the simulator in real time
  redrive live --ros2 --topics /points /imu --record out.mcap     ROS 2 (DDS) topics
  redrive live --ros2 -a --record all.mcap --idle-timeout 10
  redrive live --topics /points /imu --perception cluster-detector --foxglove
                                            and watch it in Foxglove: ws://127.0.0.1:8765

One scraper process per topic subscribes with rospy (under /usr/bin/python3) and hands each
message to this process through shared memory. --record writes every message (lossless, in a
thread of its own) to MCAP, each type with the full definition its publisher sent.

With --record and no --pipeline/--perception/--planning/--control, nothing but the recording
runs (no frames, no sensor map needed). Topics: those named, -a/--all, -e/--regex (with these
two, topics that appear later are recorded too), minus -x/--exclude. Such a session ends at the
first of: --duration seconds; --max-size bytes of messages recorded; every publisher of the
recorded topics gone (unregistered from the master and disconnected; the master's own /rosout
node does not count) for --idle-timeout seconds (with -a/-e counted once a first publisher was
there); the replay/synthetic source finished; Ctrl-C or SIGTERM. A status line per topic shows
while it records; the summary gives wall time, messages, bytes and drops per topic.

Otherwise frames are assembled as the data arrives (the highest-rate LiDAR drives them, or the
sensor map's `driver`) and run through the pipeline (the reference one when none is named) in
realtime mode: when an algorithm is slower than the sensor it gets the newest frame and the ones
in between are skipped and counted. That session ends after --duration seconds, --frames frames,
when a replay/synthetic source finished, or on Ctrl-C; the run directory is written as `redrive
run` writes it.

With --ros2 one scraper process reads the ROS 2 topics through Cyclone DDS (ROS_DOMAIN_ID /
--domain, CYCLONEDDS_URI as for ROS 2 nodes) and the results are published back as ROS 2
messages. --ros2 --record without a pipeline records as above: named topics, -a/-e (topics that
appear later on the DDS domain too), -x; it ends on the same conditions, a publisher counting
while the scraper's DDS reader is matched with its writer (a killed publisher leaves when its
DDS lease expires, 10 s by default; the /rosout and /parameter_events publishers every node has
do not count). Unlike ROS 1, a type redrive has no definition of cannot be recorded (ROS 2 sends
none): it is named and left out.

--foxglove also streams the session to Foxglove (foxglove-sdk's WebSocket server, on
127.0.0.1:8765 unless --foxglove-host/--foxglove-port say otherwise): every topic as it arrives,
on the channels `redrive serve` gives its type (LiDARs also as foxglove.PointCloud, cameras as
foxglove.CompressedImage), and with a pipeline each frame's ground truth, detections, tracks,
paths and ego as scene updates. It never slows the session or the recording down: a slow or
absent client misses messages (docs/foxglove.md).

If the ROS master goes away, recording goes on with what still flows; when a master is back at
the same address the scrapers register again. A recording left unfinished by a killed session
(.NAME.PID-RANDOM.part, RANDOM being mkstemp's letters) is named at the next start in that
folder, with the command that recovers it (`redrive repair PART -o FIXED.mcap`).
"""


def _capacities(items: list[str] | None) -> dict[str, int]:
    from redrive.errors import ConfigError

    out = {}
    for item in items or ():
        topic, _, size = item.partition("=")
        try:
            out[topic] = int(float(size.rstrip("MmBb")) * (2**20 if size[-1:] in "Mm" else 1))
        except ValueError as err:
            msg = f"--capacity {item!r}: expected TOPIC=BYTES or TOPIC=NM (MiB)"
            raise ConfigError(msg) from err
    return out


def _run(args: argparse.Namespace) -> int:
    from rich.console import Console

    from redrive.cli.live_foxglove import open_feed
    from redrive.cli.live_record import record_only, recording_status, warn_orphans
    from redrive.cli.run import pipeline_from_args
    from redrive.cli.run_report import print_run_report
    from redrive.live import default_master_uri
    from redrive.live.run import LiveRequest, LiveSource, SourceKind, run_live

    master = args.master or default_master_uri()
    args.topics = [*(args.topic or ()), *(args.topics or ())] or None
    args.capacities = _capacities(args.capacity)
    named = args.pipeline is not None or args.perception or args.planning or args.control
    if args.record is not None and not named:
        return record_only(args, master)
    for option, given in (
        ("-a/--all", args.all),
        ("-e/--regex", args.regex),
        ("-x/--exclude", args.exclude),
        ("--split-size", args.split_size),
        ("--split-duration", args.split_duration),
        ("--max-size", args.max_size),
    ):
        if given:
            print(
                f"redrive live: {option} is for recording only (--record without a pipeline); "
                "a pipeline session takes named topics and records them to one file"
            )
            return 2
    kind: SourceKind
    if args.replay is not None:
        kind = "replay"
    elif args.synthetic is not None:
        kind = "synthetic"
    else:
        kind = "ros2" if args.ros2 else "ros1"
        if not args.topics:
            hint = (
                "--topics"
                if args.ros2
                else "--topics (ROS 1), --replay LOG or --synthetic SCENARIO"
            )
            print(f"redrive live{' --ros2' if args.ros2 else ''}: give {hint}")
            return 2
    source = LiveSource(
        kind=kind,
        topics=tuple(args.topics or ()),
        target=args.replay if args.replay is not None else args.synthetic,
        master_uri=master,
        domain_id=args.domain,
        rate=args.rate,
        duration_s=args.duration,
        capacities=args.capacities,
        wait_s=args.wait,
    )
    pipeline = pipeline_from_args(args)
    request = LiveRequest(
        source=source,
        pipeline=pipeline,
        out=args.out or Path("runs") / f"live-{time.strftime('%Y%m%d-%H%M%S')}",
        frames=args.frames,
        duration_s=args.duration,
        record=args.record,
        compression=args.compression,
        sensor_map=args.sensor_map,
        publish_ros2=not args.no_publish,
    )
    console = Console(stderr=True)
    if args.record is not None:
        warn_orphans(args.record, console)
    stop = threading.Event()
    previous: list[Any] = []

    def receiving(session: Any) -> None:
        # Ctrl-C ends the frames from here on; restored however the session ends (a refused
        # start before this point leaves the caller's handler untouched)
        previous.append(signal.signal(signal.SIGINT, lambda *_: stop.set()))
        console.print(
            f"live: session {session.name}, {len(session.specs)} topic(s) from "
            f"{source.describe()}; receiving (Ctrl-C stops)",
            highlight=False,
        )

    feeds: list[Any] = []

    def feed(name: str, specs: Any) -> Any:
        feeds.append(open_feed(args, name, specs, pipeline=pipeline))
        return feeds[-1]

    try:
        report = run_live(request, stop=stop, on_receiving=receiving, feed=feed)
    finally:
        if previous:
            signal.signal(signal.SIGINT, previous[0])
    print_run_report(report.run, request.out, live=True)
    out = Console(width=None if sys.stdout.isatty() else 120)
    out.print(
        f"frames: {report.received_frames} assembled, {report.skipped_frames} skipped "
        "(pipeline slower than the sensor)"
    )
    for topic, count in report.received.items():
        missed = report.dropped.get(topic, 0)
        used = (
            f"{count} to the pipeline, {missed} missed"
            if count or missed
            else "not used by the pipeline"
        )
        kept = f", {report.recorded.get(topic, 0)} recorded" if report.recorded is not None else ""
        out.print(f"  {topic}: {used}{kept}")
    for topic, count in sorted(report.published.items()):
        out.print(f"  published {topic}: {count}")
    if feeds and feeds[0] is not None:
        out.print(feeds[0].summary(), highlight=False)
    if report.recorded is None:
        return 0
    for path in report.files or (request.record,):
        out.print(f"recorded: {path}", highlight=False)
    for err in report.recording_errors[:5]:
        out.print(f"[yellow]recording: {err}[/]")
    return recording_status(report.failure)


def register(sub: Any) -> None:
    from redrive.cli.live_foxglove import add_arguments as add_foxglove_arguments

    parser = sub.add_parser(
        "live",
        help="record live ROS 1 topics to MCAP (as rosbag record), or run algorithms on live "
        "ROS 1 or ROS 2 topics",
        description=(
            "Subscribe to ROS 1 topics through scraper processes and shared memory and record "
            "them to MCAP; or assemble frames as the data arrives and run a pipeline on them in "
            "realtime mode into a run directory (and record the topics too); with --ros2, the "
            "same for ROS 2 topics over DDS."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--master", metavar="URI", help="ROS master (default $ROS_MASTER_URI or :11311)"
    )
    parser.add_argument("topic", nargs="*", help="ROS 1 topics (as --topics)")
    parser.add_argument(
        "--topics",
        nargs="+",
        metavar="TOPIC",
        help="ROS 1 (or --ros2) topics (with --replay: only these)",
    )
    parser.add_argument(
        "-a", "--all", action="store_true", help="record every topic, also those that appear later"
    )
    parser.add_argument(
        "-e",
        "--regex",
        action="append",
        metavar="REGEX",
        help="record topics matching REGEX (whole name), also those that appear later (repeat)",
    )
    parser.add_argument(
        "-x", "--exclude", metavar="REGEX", help="leave out topics matching REGEX from -a/-e"
    )
    source = parser.add_mutually_exclusive_group()
    source.add_argument(
        "--ros2",
        action="store_true",
        help="ROS 2 topics over DDS (Cyclone DDS, the default ROS 2 middleware); results are "
        "published back on /redrive/<algorithm>/detections and /path",
    )
    source.add_argument(
        "--replay", type=Path, metavar="LOG", help="a replay source: a log at its recorded rate"
    )
    source.add_argument(
        "--synthetic", metavar="SCENARIO", help="a synthetic source: redrive.sim in real time"
    )
    parser.add_argument(
        "--rate", type=float, default=1.0, help="speed of --replay/--synthetic (default 1.0)"
    )
    parser.add_argument(
        "--domain", type=int, metavar="ID", help="--ros2: DDS domain (default $ROS_DOMAIN_ID or 0)"
    )
    parser.add_argument(
        "--no-publish", action="store_true", help="--ros2: do not publish the results"
    )
    parser.add_argument("--pipeline", type=Path, metavar="TOML", help="a pipeline file")
    for role in ("perception", "planning", "control"):
        parser.add_argument(
            f"--{role}", action="append", metavar="PLUGIN", help=f"a {role} algorithm (repeat)"
        )
    parser.add_argument(
        "--record",
        type=Path,
        metavar="OUT.mcap",
        help="record the topics (only that, unless a pipeline or algorithm is named)",
    )
    parser.add_argument("--out", type=Path, metavar="DIR", help="run directory")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument(
        "--frames", type=int, metavar="N", help="stop after N frames (with a pipeline)"
    )
    parser.add_argument(
        "--idle-timeout",
        type=float,
        default=5.0,
        metavar="S",
        help="recording only: stop when every publisher has been gone S seconds (default 5)",
    )
    parser.add_argument(
        "--max-size",
        metavar="SIZE",
        help="recording only: stop once SIZE of messages is recorded (500M, 2G)",
    )
    parser.add_argument(
        "--split-size",
        metavar="SIZE",
        help="recording only: numbered files NAME_0000.mcap … of about SIZE each (500M, 2G)",
    )
    parser.add_argument(
        "--compression",
        choices=("zstd", "lz4", "none"),
        default="zstd",
        help="the recording's chunk compression (default zstd: the smallest files; none, as "
        "rosbag record writes by default, costs the least CPU). Compression runs on its own "
        "thread; chunks it cannot keep up with are written uncompressed (never dropped)",
    )
    parser.add_argument(
        "--split-duration",
        type=float,
        metavar="S",
        help="recording only: a new numbered file every S seconds",
    )
    parser.add_argument(
        "--wait",
        type=float,
        default=10.0,
        metavar="S",
        help="wait up to S seconds for topics nobody publishes yet (default 10)",
    )
    parser.add_argument("--sensor-map", type=Path, metavar="TOML", help="which topic is which")
    add_foxglove_arguments(parser)
    parser.add_argument(
        "--capacity",
        action="append",
        metavar="TOPIC=SIZE",
        help="largest message of a topic, bytes or NM (default: 32M clouds/images, 1M others)",
    )
    parser.set_defaults(func=_run)
