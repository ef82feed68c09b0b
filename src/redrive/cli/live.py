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
  redrive live --topics /velodyne_points --duration 60
  redrive live --master http://127.0.0.1:11311 --topics /velodyne_points /camera/image_raw /imu \\
      --perception cluster-detector --record drive.mcap --out runs/live1
  redrive live --topics /points --pipeline pipeline.toml --frames 500
  redrive live --replay drive.bag --record copy.mcap       a log played as a sensor rig
  redrive live --synthetic urban --duration 20              the simulator in real time
  redrive live --ros2 --topics /points /imu --record out.mcap     ROS 2 (DDS) topics

One scraper process per topic subscribes with rospy (under /usr/bin/python3) and hands each
message to this process through shared memory; frames are assembled as the data arrives (the
highest-rate LiDAR drives them, or the sensor map's `driver`) and run through the pipeline in
realtime mode: when an algorithm is slower than the sensor it gets the newest frame and the ones
in between are skipped and counted. With --ros2 one scraper process reads the ROS 2 topics
through Cyclone DDS (ROS_DOMAIN_ID / --domain, CYCLONEDDS_URI as for ROS 2 nodes) and the
results are published back as ROS 2 messages. --record writes every message (lossless, in a thread of its
own) to MCAP. Stops after --duration seconds, --frames frames, when every publisher's stream ends,
or on Ctrl-C; the run directory is written as `redrive run` writes it.
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

    from redrive.cli.run import pipeline_from_args, print_run_report
    from redrive.engine import RealtimeMode, RunRequest, run_reader
    from redrive.live import default_master_uri
    from redrive.live.dispatcher import LiveLog
    from redrive.live.recorder import DataLogger
    from redrive.live.session import LiveSession
    from redrive.results import SourceLog

    pipeline = pipeline_from_args(args)
    master = args.master or default_master_uri()
    out = args.out or Path("runs") / f"live-{time.strftime('%Y%m%d-%H%M%S')}"
    console = Console(stderr=True)
    stop = threading.Event()
    previous = signal.signal(signal.SIGINT, lambda *_: stop.set())
    recorder = None
    log = None
    publisher = None
    if args.replay is not None or args.synthetic is not None:
        kind = "replay" if args.replay is not None else "synthetic"
        session_cm = LiveSession.source(
            kind,
            args.replay if args.replay is not None else args.synthetic,
            rate=args.rate,
            topics=args.topics,
            duration_s=args.duration,
            lossless=args.record is not None,
        )
        source_text = f"{kind} source {args.replay or args.synthetic}"
    elif args.ros2:
        from redrive.live.ros2 import ros2_session
        from redrive.live.ros2_dds import default_domain_id

        if not args.topics:
            print("redrive live --ros2: give --topics")
            return 2
        domain = default_domain_id() if args.domain is None else args.domain
        session_cm = ros2_session(
            args.topics,
            domain_id=domain,
            capacity=_capacities(args.capacity),
            wait_for_topics_s=args.wait,
        )
        source_text = f"ROS 2 (DDS domain {domain})"
    else:
        if not args.topics:
            print("redrive live: give --topics (ROS 1), --replay LOG or --synthetic SCENARIO")
            return 2
        session_cm = LiveSession.ros1(
            args.topics,
            master_uri=master,
            capacity=_capacities(args.capacity),
            wait_for_topics_s=args.wait,
        )
        source_text = master
    with session_cm as session:
        try:
            if args.record is not None:
                recorder = DataLogger(session.specs, args.record)
            log = LiveLog(session.specs, session.name, stop=stop)
            if args.duration is not None:
                timer = threading.Timer(args.duration, stop.set)
                timer.daemon = True
                timer.start()
            console.print(
                f"live: session {session.name}, {len(session.specs)} topic(s) from {source_text}; "
                "receiving (Ctrl-C stops)",
                highlight=False,
            )
            hooks = RealtimeMode()
            request = RunRequest(
                log=log.path,
                pipeline=pipeline,
                out=out,
                stop_frame=args.frames,
                sensor_map=args.sensor_map,
            )
            info = SourceLog(
                path=str(log.path),
                format="live",
                sha256=None,
                source=source_text,
                topics={s.topic: s.msgtype for s in session.specs},
                record=None if args.record is None else str(args.record),
            )
            if args.ros2 and not args.no_publish:
                from redrive.live.ros2 import ResultPublisher

                publisher = ResultPublisher(domain)
            report = run_reader(
                request, log, hooks=hooks, log_info=info, lookahead_ns=0, on_frame=publisher
            )
        finally:
            stop.set()
            signal.signal(signal.SIGINT, previous)
            if log is not None:
                log.close()
            if publisher is not None:
                publisher.close()
    recorded = recorder.stop() if recorder is not None else None
    print_run_report(report, out)
    console = Console(width=None if sys.stdout.isatty() else 120)
    console.print(
        f"frames: {hooks.received_frames} assembled, {hooks.skipped_frames} skipped "
        "(pipeline slower than the sensor)"
    )
    assert log is not None
    for topic in log.received:
        used = (
            f"{log.received[topic]} to the pipeline, {log.dropped[topic]} missed"
            if log.received[topic] or log.dropped[topic]
            else "not used by the pipeline"
        )
        kept = f", {recorder.recorded[topic]} recorded" if recorder else ""
        console.print(f"  {topic}: {used}{kept}")
    if publisher is not None:
        for topic, count in sorted(publisher.published.items()):
            console.print(f"  published {topic}: {count}")
    if recorded is not None and recorder is not None:
        console.print(f"recorded: {recorded}")
        for err in recorder.errors[:5]:
            console.print(f"[yellow]recording: {err}[/]")
    return 0


def register(sub: Any) -> None:
    parser = sub.add_parser(
        "live",
        help="run algorithms on live ROS 1 or ROS 2 topics (shared memory), optionally recording",
        description=(
            "Subscribe to ROS 1 (or, with --ros2, ROS 2) topics through scraper processes and "
            "shared memory, assemble "
            "frames as the data arrives, run the pipeline on them in realtime mode into a run "
            "directory, and record the topics to MCAP."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--master", metavar="URI", help="ROS master (default $ROS_MASTER_URI or :11311)"
    )
    parser.add_argument(
        "--topics",
        nargs="+",
        metavar="TOPIC",
        help="ROS 1 (or --ros2) topics (with --replay: only these)",
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
    parser.add_argument("--record", type=Path, metavar="OUT.mcap", help="record the topics")
    parser.add_argument("--out", type=Path, metavar="DIR", help="run directory")
    parser.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    parser.add_argument("--frames", type=int, metavar="N", help="stop after N frames")
    parser.add_argument(
        "--wait",
        type=float,
        default=10.0,
        metavar="S",
        help="wait up to S seconds for topics nobody publishes yet (default 10)",
    )
    parser.add_argument("--sensor-map", type=Path, metavar="TOML", help="which topic is which")
    parser.add_argument(
        "--capacity",
        action="append",
        metavar="TOPIC=SIZE",
        help="largest message of a topic, bytes or NM (default: 32M clouds/images, 1M others)",
    )
    parser.set_defaults(func=_run)
